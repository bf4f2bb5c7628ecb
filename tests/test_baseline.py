"""The naive baseline (`planning.baseline.plan_naive`): greedy, grasp-blind, but its motions must
still be valid (kinematics, collisions, statics within tension bounds), and its plans are scored
with the same probability model as RBP's. Short generated shafts with the goal 0.6 m up.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from planning.baseline import plan_naive
from planning.check import check_plan
from planning.footsteps import FootstepConfig, FootstepPlan, goal_pose_in
from planning.plan import build_plan, plan_configurations, validate
from planning.plan_model import plan_dict, plan_of
from planning.probability import path_probability
from rb_drake.feasibility import REASON_TEXT, Reason, check_poses
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario

# The same small scenario as tests/test_plan.py (shaft seed 4); seed 2 gives a naive plan with
# one regrasp, seed 3 one with two regrasps through improbable grasps (P = 0 at some steps).
SEED = 4
SHORT = CaveConfig(length=(3.0, 3.2))
CONFIG = FootstepConfig(max_expansions=40)
PROBABILITY_WORDS = ("p_min", "pull-angle:")  # the grasp rules the naive baseline ignores



def small_shaft(seed: int = SEED) -> Scenario:
    scn = generate_cave("shaft", seed, SHORT)
    x, y, _ = scn.start_pose
    return dataclasses.replace(scn, goal_position=(x, y + 0.6), goal_tolerance=0.4)


_CACHE: dict[int, tuple[Scenario, FootstepPlan, dict[str, Any]]] = {}


def naive(seed: int) -> tuple[Scenario, FootstepPlan, dict[str, Any]]:
    """Scenario, naive footstep plan and its plan file, computed once per seed."""
    if seed not in _CACHE:
        scn = small_shaft(seed)
        fp = plan_naive(scn, CONFIG)
        _CACHE[seed] = scn, fp, plan_dict(build_plan(scn, fp, "naive"))
    return _CACHE[seed]


SEEDS = [pytest.param(SEED, id=f"seed{SEED}"),
         pytest.param(2, id="seed2"), pytest.param(3, id="seed3")]


def test_naive_returns_a_plan() -> None:
    scn, fp, _ = naive(SEED)
    assert isinstance(fp, FootstepPlan)
    assert fp.success, f"the naive planner failed on the small shaft: {fp.reason}"
    assert fp.stances[0] == scn.start_stance
    assert len(fp.stances) == len(fp.steps) + 1
    assert fp.goal_pose is not None
    d = math.dist(fp.goal_pose[:2], scn.goal_position)
    assert d <= scn.goal_tolerance + 1e-9, f"goal pose {d:.3f} m from the goal"
    for a, b, step in zip(fp.stances[:-1], fp.stances[1:], fp.steps, strict=True):
        changed = [i for i in range(4) if a[i] != b[i]]
        assert changed == [step.boom], f"one boom per step: {a} -> {b}"
        assert (a[step.boom], b[step.boom]) == (step.from_anchor, step.to_anchor)


@pytest.mark.parametrize("seed", [SEED, 2, 3])
def test_naive_plan_file_validates(seed: int) -> None:
    _, fp, plan = naive(seed)
    validate(plan)
    assert plan["planner"] == "naive"
    assert plan["success"] is fp.success is True
    assert plan["regrasps"] == len(fp.steps)
    kinds = [ph["kind"] for ph in plan["phases"]]
    assert kinds == ["body", "reach"] * len(fp.steps) + ["body"], kinds


@pytest.mark.parametrize("seed", SEEDS)
def test_naive_motions_are_valid_even_when_improbable(seed: int) -> None:
    scn, _, plan = naive(seed)
    problems = check_plan(plan)
    other = [p for p in problems if not any(w in p for w in PROBABILITY_WORDS)]
    assert other == [], "the naive plan breaks more than grasp probability:\n" + "\n".join(other)
    # Independently of check_plan: every configuration is feasible when grasps are ignored.
    for k, phase in enumerate(plan["phases"]):
        stance = scn.stance(tuple(phase["stance"]))
        for n, step in enumerate(phase["steps"]):
            tip = np.array(step["free_tip"]) if "free_tip" in step else None
            check = check_poses(scn, stance, np.array(step["pose"]), tip, ignore_grasps=True)
            assert check.feasible[0], (
                f"phases[{k}] step {n}: {REASON_TEXT[Reason(int(check.reason[0]))]}")
            lo, hi = scn.robot.boom_tension
            tensions = [f for f in step["tension"] if f is not None]
            assert len(tensions) == int(stance.attached.sum()), (
                f"phases[{k}] step {n}: tensions {step['tension']} for stance {phase['stance']}")
            ramped = step.get("ramp", {}).get("boom")  # a release or attach ramp: down to 0
            assert all((0.0 if i == ramped else lo) - 1e-9 <= f <= hi + 1e-9
                       for i, f in enumerate(step["tension"]) if f is not None), tensions


def test_an_improbable_naive_plan_is_reported_as_such() -> None:
    """Seed 3: the naive climb goes through grasps below p_min; check_plan says so."""
    scn, _, plan = naive(3)
    assert plan["success"] is True
    assert plan["p_min"] < scn.robot.p_min, f"p_min {plan['p_min']}: expected an improbable plan"
    problems = check_plan(plan)
    assert any("p_min" in p for p in problems), problems


@pytest.mark.parametrize("seed", [SEED, 2, 3])
def test_naive_plan_scored_with_the_same_model(seed: int) -> None:
    scn, _, plan = naive(seed)
    prob = path_probability(plan_configurations(plan_of(plan)), scn.robot.attach_failure)
    assert plan["p_path"] == pytest.approx(prob.p_path, rel=1e-12, abs=1e-15), (
        f"plan p_path {plan['p_path']}, recomputed from its steps {prob.p_path}")
    assert plan["p_min"] == pytest.approx(prob.p_min, rel=1e-12, abs=1e-15)
    assert plan["regrasps"] == prob.regrasps
    # Each step's P is the robust allocation's, as for RBP's plans (a release or attach
    # ramp's steps blend two of them; rbp check verifies those).
    for k, phase in enumerate(plan["phases"]):
        stance = scn.stance(tuple(phase["stance"]))
        for n, step in enumerate(phase["steps"]):
            if "ramp" in step:
                continue
            tip = np.array(step["free_tip"]) if "free_tip" in step else None
            p = float(check_poses(scn, stance, np.array(step["pose"]), tip,
                                  full=True).probability[0])
            assert math.isclose(step["p_success"], p, rel_tol=1e-9, abs_tol=1e-12), (
                f"phases[{k}] step {n}: plan P {step['p_success']}, model {p}")


@pytest.mark.parametrize("seed", [SEED, 3])
def test_naive_is_deterministic(seed: int) -> None:
    scn, first, plan = naive(seed)
    again = plan_naive(small_shaft(seed), CONFIG)
    assert again.success == first.success and again.reason == first.reason
    assert again.stances == first.stances
    assert [(s.boom, s.from_anchor, s.to_anchor) for s in again.steps] == [
        (s.boom, s.from_anchor, s.to_anchor) for s in first.steps]
    for a, b in zip(again.steps, first.steps, strict=True):
        np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(again.goal_pose, first.goal_pose)
    rebuilt = plan_dict(build_plan(scn, again, "naive"))
    assert rebuilt["phases"] == plan["phases"]
    assert rebuilt["p_path"] == plan["p_path"]


def test_goal_pose_in_ignoring_grasps_returns_a_feasible_pose() -> None:
    scn = small_shaft(SEED)
    stance = tuple(scn.start_stance)
    pose = goal_pose_in(scn, stance, np.random.default_rng([CONFIG.seed, 2]),
                        CONFIG.goal_samples, ignore_grasps=True)
    assert pose is not None
    check = check_poses(scn, scn.stance(stance), pose, ignore_grasps=True)
    assert check.feasible[0], (
        f"goal pose {pose.tolist()} infeasible: {REASON_TEXT[Reason(int(check.reason[0]))]}")
