"""The margins between what the planner verifies and what the execution needs (issue 17): the
pull-angle limit below 90 degrees (robot.max_pull_angle_deg) in the verifier, the controller's
tension floor below the planner's bound, the motion between a plan's steps
(planning.between) and the inertial tensions that slow a phase (planning.easing)."""

from __future__ import annotations

import copy
import itertools
import math
from typing import Any

import numpy as np
import pytest
from conftest import build_shaft

from planning.between import BETWEEN, BETWEEN_DIP, between, between_steps
from planning.check import verify_plan
from planning.easing import _progress, inertial_excess
from planning.ramps import CONTROL_TENSION_FLOOR, RELEASE_TENSION
from rb_drake.feasibility import check_poses
from rb_drake.params import ParamError, RobotParams, robot_from_dict
from rb_drake.scenario import bundled_caves, load_scenario
from rb_drake.statics import statics_problem
from systems.control import TensionProjector, control_bounds

Plan = dict[str, Any]


def test_max_pull_angle_is_a_robot_parameter() -> None:
    robot = robot_from_dict({"max_pull_angle_deg": 85.0})
    assert robot.max_pull_angle == pytest.approx(math.radians(85.0), abs=1e-15)
    assert robot.to_dict()["max_pull_angle_deg"] == 85.0
    assert RobotParams().max_pull_angle_deg < 90.0, "the default leaves a margin below 90 deg"
    for bad in (0.0, 90.5, -3.0, "88"):
        with pytest.raises(ParamError, match="max_pull_angle_deg"):
            robot_from_dict({"max_pull_angle_deg": bad})


def _largest_pull_deg(plan: Plan) -> float:
    """The largest |pull angle| of any grasp at any step of `plan`, in degrees."""
    from rb_drake.scenario import scenario_from_dict

    scenario = dict(plan["scenario"], robot=plan["robot"])
    scn = scenario_from_dict(scenario, "<plan>", check_start=False)
    worst = 0.0
    for phase in plan["phases"]:
        stance = scn.stance(tuple(phase["stance"]))
        poses = np.array([s["pose"] for s in phase["steps"]])
        tips = (np.array([s["free_tip"] for s in phase["steps"]])
                if phase["kind"] == "reach" else None)
        psi = statics_problem(scn.robot, scn.gravity_vector, poses, stance, tips).pull_angles
        worst = max(worst, float(np.degrees(np.abs(psi[:, stance.attached]).max())))
    return worst


def test_planned_grasps_keep_the_margin_and_the_verifier_holds_it(
        cave_plans: dict[str, Plan]) -> None:
    """Every planned grasp is pulled at less than max_pull_angle_deg; the same plan with the
    limit set 0.01 deg below its largest pull angle is rejected by rule `pull-angle`, and
    0.01 deg above it passes."""
    for name, plan in cave_plans.items():
        worst = _largest_pull_deg(plan)
        assert worst < plan["robot"]["max_pull_angle_deg"], f"{name}: {worst} deg"
        for delta, rejected in ((-0.01, True), (0.01, False)):
            changed = copy.deepcopy(plan)
            changed["robot"]["max_pull_angle_deg"] = worst + delta
            if "robot" in changed["scenario"]:
                changed["scenario"]["robot"]["max_pull_angle_deg"] = worst + delta
            rules = {p.rule for p in verify_plan(changed)}
            assert ("pull-angle" in rules) == rejected, (
                f"{name}: limit {worst + delta:.3f} deg, largest pull {worst:.3f} deg: {rules}")
            if not rejected:
                assert rules == set(), f"{name}: {rules}"


def test_controller_goes_below_the_planners_bound_down_to_its_floor() -> None:
    """A wrench that needs a boom below the planner's 0.5 N is made exactly down to
    CONTROL_TENSION_FLOOR (0.1 N, above the slack of a release), and clipped there."""
    robot = RobotParams()
    lo, hi = control_bounds(robot)
    assert (lo, hi) == (CONTROL_TENSION_FLOOR, robot.boom_tension[1])
    assert RELEASE_TENSION < CONTROL_TENSION_FLOOR < robot.boom_tension[0]
    scn = build_shaft()
    four = scn.stance(scn.start_stance)
    stance = four.without(3)
    A = statics_problem(robot, scn.gravity_vector, np.asarray(scn.start_pose, dtype=float),
                        stance, four.positions[3]).A[0]
    projector = TensionProjector(control_bounds(robot), 1e-4)
    for want, made in ((0.3, 0.3), (-1.0, CONTROL_TENSION_FLOOR)):
        f = np.array([5.0, 6.0, want, 0.0])
        got = projector(A, A @ f, f, stance.attached)
        assert got[2] == pytest.approx(made, abs=1e-6), f"wanted {want} N on boom 2: {got}"
        assert got[3] == 0.0 and np.all(got[:3] >= CONTROL_TENSION_FLOOR - 1e-9), got
    held = TensionProjector(robot.boom_tension, 1e-4)  # the planner's bound: no authority
    assert held(A, A @ np.array([5.0, 6.0, 0.3, 0.0]), np.array([5.0, 6.0, 0.5, 0.0]),
                stance.attached)[2] == pytest.approx(0.5, abs=1e-6)


def test_between_interpolates_each_interval() -> None:
    values = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0]])
    got = between(values)
    assert got.shape == (2 * len(BETWEEN), 2)
    np.testing.assert_allclose(got[:len(BETWEEN), 0], BETWEEN, atol=1e-15)
    np.testing.assert_allclose(got[len(BETWEEN):, 0], 1.0 + 2.0 * np.asarray(BETWEEN),
                               atol=1e-15)


def test_between_steps_tests_the_motion_between_feasible_steps() -> None:
    """Two feasible steps either side of a pebble the body would cross between them fail
    `between_steps` with the interval named; a short feasible segment passes, and fails when
    its steps claim grasps stronger by more than BETWEEN_DIP than those between them."""
    pebble = [[-0.02, 0.95], [0.02, 0.95], [0.02, 1.05], [-0.02, 1.05]]
    scn = build_shaft(extra_walls=[pebble])
    stance = scn.stance(scn.start_stance)
    poses = np.array([[-0.25, 1.0, 0.0], [0.25, 1.0, 0.0]])
    check = check_poses(scn, stance, poses)
    assert check.feasible.all(), check.reason
    lp = check.allocation.log_probs
    assert between_steps(scn, stance, poses, lp) == "between steps 0 and 1: BODY_COLLISION"
    good = np.array([[-0.25, 1.0, 0.0], [-0.24, 1.01, 0.0]])
    lp = check_poses(scn, stance, good).allocation.log_probs
    assert between_steps(scn, stance, good, lp) == ""
    claimed = lp + 2.0 * BETWEEN_DIP  # steps claiming more than the grasps between hold
    assert "weaker" in between_steps(scn, stance, good, claimed)


def test_progress_cruises_slower() -> None:
    for intervals, ease, slow in ((10, 4, 1), (10, 4, 2), (7, 2, 3), (8, 4, 4)):
        s = _progress(intervals, ease, slow)
        assert len(s) == slow * intervals + ease
        assert s[-1] == pytest.approx(intervals, abs=1e-12)
        speed = np.diff(np.concatenate([[0.0], s]))
        assert np.all(speed > 0) and speed.max() == pytest.approx(1.0 / slow, abs=1e-12)
        assert speed[0] == pytest.approx(1.0 / (2 * ease * slow), abs=1e-12)


def test_inertial_excess_counts_the_tensions_acceleration_needs() -> None:
    """At rest a feasible 3-stance has no excess; a step pushed off the line makes the body
    accelerate there and back, and the tensions that would do it leave the bounds by more the
    harder the push."""
    scn = load_scenario(bundled_caves()["demo-shaft"])
    four = scn.stance(scn.start_stance)
    start = np.asarray(scn.start_pose, dtype=float)
    j = next(j for j in range(4) if check_poses(scn, four.without(j), start,
                                                four.positions[j]).feasible[0])
    stance = four.without(j)
    poses = np.tile(start, (5, 1))
    tips = np.tile(four.positions[j], (5, 1))
    times = 0.5 * np.arange(len(poses))  # the last step is the phase's dwell
    assert np.all(inertial_excess(scn, stance, times, poses, tips) == 0.0)
    excess = []
    for push in (1e-4, 0.01, 0.1, 1.0):
        moved = poses.copy()
        moved[2, :2] += push
        excess.append(inertial_excess(scn, stance, times, moved, tips).max())
    assert excess[0] == 0.0 and excess[-1] > 1.0, excess
    assert all(x <= y + 1e-12 for x, y in itertools.pairwise(excess)), excess


@pytest.mark.parametrize("name", ["demo-crevasse.json", "rockfall-3.json"])
def test_holding_floors_are_what_p_path_counts(name: str) -> None:
    """Each holding's floor (the log of its least planned P, at every phase it spans) is the
    minimum `planning.probability` counts for it: the same holdings, the same values."""
    from pathlib import Path

    from planning.easing import holding_floors
    from planning.plan_file import read_plan
    from planning.probability import Configuration, path_probability

    plan = read_plan(Path(__file__).parent / "data" / "golden" / name)
    floors = holding_floors(plan)
    ends: list[tuple[int, str, float]] = []
    for k, phase in enumerate(plan.phases):
        for i in range(4):
            anchor = phase.stance[i]
            last = k + 1 == len(plan.phases) or plan.phases[k + 1].stance[i] != anchor
            if anchor is None:
                assert math.isnan(floors[k, i]), (k, i, floors[k, i])
                continue
            for step in phase.steps:  # nothing in the holding is below its floor
                if step.p_grasp[i] is not None:
                    assert math.log(step.p_grasp[i]) >= floors[k, i] - 1e-12, (k, i)
            if last:
                ends.append((i, anchor, math.exp(floors[k, i])))
    counted = path_probability((Configuration(ph.stance, st.p_grasp, st.p_success)
                                for ph in plan.phases for st in ph.steps), 0.0).holdings
    assert len(ends) == len(counted) > 4, (ends, counted)
    for (i, a, p), (j, b, q) in zip(sorted(ends), sorted(counted), strict=True):
        assert (i, a) == (j, b) and abs(p - q) <= 1e-12, ((i, a, p), (j, b, q))
