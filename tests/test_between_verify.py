"""Rule `between` (issue 28): `rbp check` verifies the motion between successive steps, the
straight motion `rbp rig-run` executes, at a stated resolution. Two valid steps whose motion
crosses rock are rejected with the rule, phase and step named; the planner's plans are
accepted (tests/test_verify.py); samples are as dense as the resolution says; `rbp simulate`
and `rbp rig-run` refuse such a plan."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import build_shaft

from planning.between_faults import splice_through
from planning.check import verify_plan
from planning.plan import score_plan
from planning.plan_model import Phase, Plan, plan_scenario
from planning.verify_between import (
    ROTATION,
    TRANSLATION,
    TRAVEL,
    between_problems,
    resolution_text,
    samples,
    step_motion,
)
from rb_drake import geometry
from rb_drake.feasibility import Reason, check_poses
from rbp.cli import main

PlanFile = dict[str, Any]


def _body_phase(poses: list[list[float]], stance: list[str]) -> Phase:
    """A body phase of these poses one second apart in the test shaft, each step with its most
    robust tensions (the rule reads times, poses, the stance and the tensions)."""
    from rb_drake.statics import allocate

    shaft = build_shaft()
    tensions = allocate(shaft.robot, shaft.gravity_vector, np.array(poses),
                        shaft.stance(tuple(stance))).tensions
    steps = [{"t": float(n), "pose": p, "tension": [float(f) for f in tensions[n]],
              "p_grasp": [1.0] * 4, "p_success": 1.0} for n, p in enumerate(poses)]
    return Phase.from_dict({"kind": "body", "stance": stance, "free_boom": None,
                            "steps": steps})


def test_a_boom_sweeping_across_a_thin_rock_sliver_between_two_valid_steps() -> None:
    """Two poses 8 cm apart, each feasible; between them boom 0 sweeps across a 4 mm rock
    sliver at half its length. A check at the steps sees nothing; `between` names the
    interval."""
    plain = build_shaft()
    stance = plain.stance(plain.start_stance)
    a, b = np.array([-0.04, 1.0, 0.0]), np.array([0.04, 1.0, 0.0])
    geo = geometry.boom_geometry(plain.robot, (a + b) / 2, stance.positions)
    p = (geo.shoulders[0, 0] + stance.positions[0]) / 2
    d = 0.002
    cave = build_shaft(extra_walls=[[[p[0] - d, p[1] - d], [p[0] + d, p[1] - d],
                                     [p[0], p[1] + d]]])
    ends = check_poses(cave, stance, np.stack([a, b]))
    assert ends.feasible.all(), f"both steps must hold: {ends.reason}"
    found: list[tuple[int, int, str]] = []
    phase = _body_phase([a.tolist(), b.tolist()], list(plain.start_stance))
    checked = between_problems((phase,), cave, set(), lambda k, n, text: found.append((k, n,
                                                                                        text)))
    assert checked >= 0.08 / TRANSLATION - 1, f"only {checked} samples between the steps"
    assert [(k, n) for k, n, _ in found] == [(0, 0)], found
    assert "boom 0" in found[0][2] and "collides with rock" in found[0][2], found
    nothing: list = []
    between_problems((phase,), plain, set(), lambda *x: nothing.append(x))
    assert nothing == [], f"without the sliver the motion holds: {nothing}"


def _motion_span(steps: list[dict]) -> tuple[int, int]:
    lead = next(i for i, s in enumerate(steps) if "ramp" not in s)
    trail = next(i for i, s in enumerate(reversed(steps)) if "ramp" not in s)
    return lead, len(steps) - 1 - trail


def _straight_crosses_rock(plan: PlanFile, k: int) -> bool:
    """Whether the straight motion from phase k's first to its last motion step crosses rock
    (checked at 200 points, independently of the rule's sampling)."""
    model = Plan.from_dict(plan)
    scn = plan_scenario(model)
    phase = plan["phases"][k]
    a, b = _motion_span(phase["steps"])
    w = np.linspace(0.0, 1.0, 201)[:, None]
    pa, pb = (np.array(phase["steps"][i]["pose"]) for i in (a, b))
    tips = None
    if phase["kind"] == "reach":
        ta, tb = (np.array(phase["steps"][i]["free_tip"]) for i in (a, b))
        tips = ta + w * (tb - ta)
    check = check_poses(scn, scn.stance(tuple(phase["stance"])), pa + w * (pb - pa), tips)
    return bool(np.isin(check.reason, (Reason.BODY_COLLISION, Reason.BOOM_COLLISION)).any())


def test_a_phase_cut_to_its_ends_whose_straight_motion_crosses_rock(
        cave_plans: dict[str, PlanFile]) -> None:
    """A hand-made fault in the demo plan: a phase whose straight motion from its first to its
    last motion step crosses rock keeps those two steps only (a continuation's first phases,
    spliced in, may hold end configurations only: so do the phases before it). Every other
    rule accepts it; `between` names phase and step."""
    plan = copy.deepcopy(cave_plans["demo-shaft"])
    k = next(k for k in range(len(plan["phases"])) if _straight_crosses_rock(plan, k))
    phase = plan["phases"][k]
    a, b = _motion_span(phase["steps"])
    phase["steps"] = phase["steps"][:a + 1] + phase["steps"][b:]
    splice_through(plan, k)
    plan["start"] = copy.deepcopy(plan["scenario"]["start"])
    scored = score_plan(Plan.from_dict(plan), plan["robot"]["attach_failure"])
    plan.update(p_path=scored.p_path, p_grasps=scored.p_grasps, p_min=scored.p_min)
    problems = verify_plan(plan)
    assert {p.rule for p in problems} == {"between"}, "\n".join(map(str, problems[:5]))
    assert any(p.phase == k and p.step == a and "collides with rock" in p.text
               for p in problems), "\n".join(map(str, problems))
    text = str(problems[0])
    assert text.startswith(f"phases[{k}] ({phase['kind']}) step {a}") and ": between: " in text


@pytest.mark.parametrize("seed", range(6))
def test_samples_meet_the_resolution(seed: int, robot) -> None:
    """Between successive checked configurations (the steps and the samples between them) the
    body moves at most TRANSLATION and turns at most ROTATION, the free gripper moves at most
    TRAVEL and every boom's length (to any anchor or the gripper) changes by at most TRAVEL;
    the samples lie on the rig's motion (`step_motion`)."""
    rng = np.random.default_rng(seed)
    K = 8
    times = np.cumsum(rng.uniform(0.1, 1.0, K))
    poses = np.cumsum(rng.uniform(-0.15, 0.15, (K, 3)), axis=0)
    tips = np.cumsum(rng.uniform(-0.2, 0.2, (K, 2)), axis=0)
    poses[3] = poses[2]  # an interval that does not move has no samples
    tips[3] = tips[2]
    s = samples(robot, times, poses, tips)
    assert not np.any(s.interval == 2), "an interval without motion was sampled"
    order = np.argsort(np.concatenate([times, s.t]), kind="stable")
    t = np.concatenate([times, s.t])[order]
    q = np.concatenate([poses, s.poses])[order]
    tip = np.concatenate([tips, s.tips])[order]
    assert np.all(np.diff(t) > 0), "samples lie strictly inside their intervals"
    np.testing.assert_allclose(q, step_motion(times, poses).vector_values(t).T, atol=1e-12)
    d = np.diff(q, axis=0)
    assert np.hypot(d[:, 0], d[:, 1]).max() <= TRANSLATION + 1e-12
    assert np.abs(d[:, 2]).max() <= ROTATION + 1e-12
    assert np.linalg.norm(np.diff(tip, axis=0), axis=1).max() <= TRAVEL + 1e-12
    anchors = rng.uniform(-3, 3, (4, 2))
    for targets in (anchors, np.where(np.arange(4)[:, None] == 1, np.nan, anchors)):
        ends = np.broadcast_to(targets, (len(q), 4, 2)).copy()
        ends[:, 1] = np.where(np.isnan(targets[1]), tip, ends[:, 1])
        length = np.stack([geometry.boom_geometry(robot, qi, ei).length[0]
                           for qi, ei in zip(q, ends, strict=True)])
        assert np.abs(np.diff(length, axis=0)).max() <= TRAVEL + 1e-12


def test_rbp_check_states_the_resolution(cave_plans: dict[str, PlanFile], tmp_path: Path,
                                         capsys) -> None:
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(cave_plans["demo-shaft"]))
    assert main(["check", "-q", str(path)]) == 0
    out = capsys.readouterr().out
    assert resolution_text() in out, out
    for value in (f"{TRANSLATION * 1e3:g} mm", f"{math.degrees(ROTATION):g} deg"):
        assert value in resolution_text()


@pytest.mark.parametrize("command", [["simulate", "--trials", "0"], ["rig-run", "--sim-rig"]])
def test_simulate_and_rig_run_refuse_a_plan_whose_motion_between_steps_fails(
        cave_plans: dict[str, PlanFile], tmp_path: Path, capsys, command: list[str]) -> None:
    from planning.plan_faults import judge, random_fault

    fault = random_fault(cave_plans["demo-shaft"], np.random.default_rng(3), "between-cut")
    assert judge(fault).rules == {"between"}
    path = tmp_path / "cut.json"
    path.write_text(json.dumps(fault.plan))
    args = [command[0], str(path), *command[1:]]
    if command[0] == "rig-run":
        args += ["--log", str(tmp_path / "rig.lcm")]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert ": between: " in err and "refused" in err, err
    assert not (tmp_path / "rig.lcm").exists(), "the rig ran a refused plan"


def test_an_interval_too_long_to_sample_is_reported_not_sampled(shaft) -> None:
    """A hostile file's steps 100 m apart: reported (without allocating 20,000 samples per
    metre), never accepted."""
    found: list[tuple[int, int, str]] = []
    phase = _body_phase([[0.0, 1.0, 0.0], [100.0, 1.0, 0.0], [100.0, 1.0, 0.0]],
                        list(shaft.start_stance))
    checked = between_problems((phase,), shaft, set(), lambda k, n, t: found.append((k, n, t)))
    assert checked == 0, checked
    assert [(k, n) for k, n, _ in found] == [(0, 0)] and "too long" in found[0][2], found


def test_a_phase_of_many_long_intervals_is_reported_not_sampled(shaft) -> None:
    """A hostile file's 150 steps 40 m apart, each interval under the per-interval cap but
    1.2 million samples in all: the phase is reported once, and nothing is sampled."""
    from planning.verify_between import MAX_PHASE_SAMPLES

    found: list[tuple[int, int, str]] = []
    phase = _body_phase([[40.0 * n, 1.0, 0.0] for n in range(151)], list(shaft.start_stance))
    checked = between_problems((phase,), shaft, set(), lambda k, n, t: found.append((k, n, t)))
    assert checked == 0, checked
    assert len(found) == 1 and found[0][:2] == (0, 0), found
    assert f"over {MAX_PHASE_SAMPLES} samples" in found[0][2], found


def test_a_footstep_plan_says_its_motion_between_steps_is_not_verified(tmp_path: Path,
                                                                       capsys) -> None:
    """A footstep plan (no time_step) states end configurations only: rule `between` does not
    apply, and `rbp check` says the motion between them was not verified."""
    import rbp
    from rb_drake.scenario import bundled_caves, load_scenario

    plan = rbp.plan(load_scenario(bundled_caves()["demo-shaft"]), footsteps_only=True)
    assert plan.time_step is None
    path = tmp_path / "footsteps.json"
    path.write_text(json.dumps(plan.to_dict()))
    assert main(["check", "-q", str(path)]) == 0
    out = capsys.readouterr().out
    assert "not the motion between them" in out and resolution_text() not in out, out


def test_smooth_departure_bounds_the_distance_to_the_straight_segment(rng) -> None:
    """The bound on how far a cubic Hermite interval strays from its chord holds on random
    intervals (sampled densely, distances in resolution units), and is not vacuous."""
    from planning.verify_between import TRAVEL, smooth_departure

    scale = np.array([TRANSLATION, TRANSLATION, ROTATION, TRAVEL, TRAVEL])
    s = np.linspace(0.0, 1.0, 2001)[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    ratios = []
    for trial in range(300):
        times = np.cumsum(rng.uniform(0.1, 1.0, 4))
        q = rng.normal(0.0, 0.02, (4, 5)) * [1, 1, 0.1, 1, 1]
        v = rng.normal(0.0, 0.03, (4, 5)) * [1, 1, 0.1, 1, 1]
        if trial % 3 == 0:
            v[1] = 0.0  # a rest at a knot
        bound = smooth_departure(times, q[:, :3], v[:, :3], q[:, 3:], v[:, 3:])
        for n in range(3):
            T = times[n + 1] - times[n]
            H = (h00 * q[n] + h10 * T * v[n] + h01 * q[n + 1] + h11 * T * v[n + 1]) / scale
            p0, d = q[n] / scale, (q[n + 1] - q[n]) / scale
            lam = np.clip((H - p0) @ d / (d @ d), 0.0, 1.0)
            far = np.linalg.norm(H - (p0 + lam[:, None] * d), axis=1).max()
            assert far <= bound[n] * (1 + 1e-9) + 1e-12, f"sampled {far} > bound {bound[n]}"
            ratios.append(far / bound[n])
    assert np.median(ratios) > 0.5, f"the bound is loose: median ratio {np.median(ratios)}"
    line = smooth_departure(np.arange(3.0), np.outer(np.arange(3.0), [0.01, 0.02, 0.001]),
                            np.tile([0.01, 0.02, 0.001], (3, 1)))
    assert np.all(line < 1e-9), f"a straight motion at constant speed strays {line}"


@pytest.mark.parametrize("cave", ["demo-shaft", "demo-crevasse", "rockfall-3"])
def test_the_planner_plans_smooth_path_stays_near_the_verified_motion(
        cave_plans: dict[str, PlanFile], cave: str, tmp_path: Path, capsys) -> None:
    """rbp simulate's smooth path through the planner's steps strays less than the limit from
    the straight motion rule between verifies, and rbp check says by how much."""
    from systems.trajectory import DEPARTURE_LIMIT, PlanTrajectory, plan_scenario

    plan = cave_plans[cave]
    traj = PlanTrajectory(plan, plan_scenario(plan))
    assert 0.0 < traj.departure <= DEPARTURE_LIMIT, f"{cave}: strays {traj.departure}"
    assert traj.departure_problem() is None
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    assert main(["check", "-q", str(path)]) == 0
    out = capsys.readouterr().out
    stated = re.search(r"smooth path through the steps within ([0-9.]+) of that resolution", out)
    assert "the straight line rbp rig-run commands and the smooth path rbp simulate follows" \
        in out, out
    assert stated is not None, out
    assert abs(float(stated.group(1)) - traj.departure) <= 0.006, (stated.group(1),
                                                                   traj.departure)


def test_a_plan_whose_smooth_path_strays_is_refused_though_its_straight_motion_holds(
        cave_plans: dict[str, PlanFile], tmp_path: Path, capsys) -> None:
    """Every eighth motion step of a long phase kept (a continuation, as a converter or a hand
    edit might write it): the straight motion between the remaining steps still passes every
    rule, but the smooth path rbp simulate would follow through them strays past
    DEPARTURE_LIMIT; rbp check and rbp simulate refuse it, naming the phase."""
    from planning.between_faults import _motion_span
    from planning.check import check_plan
    from systems.trajectory import DEPARTURE_LIMIT, PlanTrajectory, plan_scenario

    plan = cave_plans["demo-shaft"]
    scn = plan_scenario(plan)
    found = None
    for k, phase in enumerate(plan["phases"]):
        a, b = _motion_span(phase["steps"])
        if b - a < 16:
            continue
        cut = copy.deepcopy(plan)
        cut.setdefault("start", copy.deepcopy(plan["scenario"]["start"]))
        keep = set(range(a + 1)) | set(range(b, len(phase["steps"]))) | set(range(a, b, 8))
        cut["phases"][k]["steps"] = [s for i, s in enumerate(phase["steps"]) if i in keep]
        splice_through(cut, k)
        traj = PlanTrajectory(cut, scn)
        if (traj.departure > DEPARTURE_LIMIT and traj.departure_phase == k
                and check_plan(cut) == []):
            found = k, cut
            break
    assert found is not None, "no long phase whose thinned steps make the smooth path stray"
    k, cut = found
    path = tmp_path / "thinned.json"
    path.write_text(json.dumps(cut))
    assert main(["check", "-q", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"phases[{k}]" in out and "strays up to" in out, out
    assert main(["simulate", "--trials", "0", str(path)]) == 1
    err = capsys.readouterr().err
    assert "strays up to" in err and "refused" in err, err
