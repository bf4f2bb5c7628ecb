"""Rule `between` on the smooth path `rbp simulate` follows between a plan's steps (issue 28):
the path is sampled within the rule's resolution (proven, and checked here against dense
evaluation), it is the simulator's own path, the planner's plans pass it, and a plan whose
steps and straight motion hold but whose smooth path leaves feasibility is refused by `rbp
check` and `rbp simulate`, phase and step named."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import MUTATION_CAVES

from planning.plan_model import Plan
from planning.smooth_motion import path_samples, phase_path, plan_paths
from planning.verify_between import ROTATION, TRANSLATION, TRAVEL
from rb_drake import geometry
from rbp.cli import main

PlanFile = dict[str, Any]


@pytest.mark.parametrize("seed", range(6))
def test_smooth_samples_meet_the_resolution(seed: int, robot) -> None:
    """Every configuration of the smooth path (evaluated 400 times per interval) lies within
    the resolution of the checked configuration before it (a knot or a sample): body within
    TRANSLATION and ROTATION, gripper within TRAVEL, every boom's length within TRAVEL."""
    rng = np.random.default_rng(seed)
    K = 8
    times = np.cumsum(rng.uniform(0.2, 1.0, K))
    poses = np.cumsum(rng.uniform(-0.06, 0.06, (K, 3)), axis=0)
    tips = np.cumsum(rng.uniform(-0.08, 0.08, (K, 2)), axis=0)
    poses[-1], tips[-1] = poses[-2], tips[-2]  # the dwell
    path = phase_path(times, poses, tips)
    s, too_long = path_samples(robot, path)
    assert too_long == 0
    checked_t = np.concatenate([path.knots, s.t])
    order = np.argsort(checked_t, kind="stable")
    checked_t = checked_t[order]
    assert np.all(np.diff(checked_t) > 0), "samples lie strictly inside their intervals"
    dense = np.concatenate([np.linspace(a, b, 401)[:-1]
                            for a, b in zip(path.knots[:-1], path.knots[1:], strict=True)])
    before = checked_t[np.searchsorted(checked_t, dense, side="right") - 1]
    q, q0 = path.pose.vector_values(dense).T, path.pose.vector_values(before).T
    g, g0 = path.tip.vector_values(dense).T, path.tip.vector_values(before).T
    d = q - q0
    assert np.hypot(d[:, 0], d[:, 1]).max() <= TRANSLATION + 1e-12
    assert np.abs(d[:, 2]).max() <= ROTATION + 1e-12
    assert np.linalg.norm(g - g0, axis=1).max() <= TRAVEL + 1e-12
    anchors = rng.uniform(-3, 3, (4, 2))
    ends = np.broadcast_to(anchors, (len(dense), 4, 2)).copy()
    ends0 = ends.copy()
    ends[:, 1], ends0[:, 1] = g, g0  # boom 1 free: its gripper moves
    length = np.stack([geometry.boom_geometry(robot, a, e).length[0]
                       for a, e in zip(q, ends, strict=True)])
    length0 = np.stack([geometry.boom_geometry(robot, a, e).length[0]
                        for a, e in zip(q0, ends0, strict=True)])
    assert np.abs(length - length0).max() <= TRAVEL + 1e-12


@pytest.mark.parametrize("cave", MUTATION_CAVES)
def test_the_verified_path_is_the_one_the_simulation_follows(
        cave_plans: dict[str, PlanFile], cave: str) -> None:
    """The path rule `between` samples in each phase of several steps is the body pose and
    free gripper `rbp simulate`'s trajectory commands at the same times."""
    from systems.trajectory import PlanTrajectory, plan_scenario

    plan = cave_plans[cave]
    traj = PlanTrajectory(plan, plan_scenario(plan))
    paths = plan_paths(Plan.from_dict(plan))
    assert len(paths) >= 10, f"{cave}: only {len(paths)} smooth phases"
    rng = np.random.default_rng(1)
    for k, path in paths:
        t = rng.uniform(path.knots[0], path.knots[-1], 20)
        np.testing.assert_allclose(path.pose.vector_values(t), traj.pose.vector_values(t),
                                   rtol=0, atol=1e-12, err_msg=f"{cave} phase {k}")
        tip = traj.phases[k].free_tip
        assert (path.tip is None) == (tip is None), f"{cave} phase {k}"
        if tip is not None:
            np.testing.assert_allclose(path.tip.vector_values(t), tip.vector_values(t),
                                       rtol=0, atol=1e-12, err_msg=f"{cave} phase {k}")


def _excursion(plan: PlanFile) -> tuple[int, PlanFile]:
    """A fault of class between-smooth in `plan` whose only problems are on the smooth path
    (its steps and straight motion verify), and whose path strays less than DEPARTURE_LIMIT
    from the straight motion: the departure bound alone would have accepted it."""
    from planning.check import verify_plan
    from planning.plan_faults import random_fault
    from systems.plan_check import smooth_path_check

    rng = np.random.default_rng(11)
    for _ in range(20):
        fault = random_fault(plan, rng, "between-smooth")
        problems = verify_plan(fault.plan)
        if (problems and all(p.rule == "between" and "smooth path" in p.text for p in problems)
                and smooth_path_check(fault.plan)[0] == []):
            return fault.phase, fault.plan
    raise AssertionError("no excursion whose smooth path alone fails in 20 faults")


def test_a_plan_whose_smooth_path_leaves_feasibility_is_refused(
        cave_plans: dict[str, PlanFile], tmp_path: Path, capsys) -> None:
    """Two steps turned to the edge of feasibility and part of the way back: each step holds,
    the straight motion between them holds, and the smooth path strays within the departure
    limit, but it overshoots the edge: `rbp check` and `rbp simulate` refuse the plan naming
    the phase, rule between and the smooth path."""
    k, plan = _excursion(cave_plans["demo-shaft"])
    path = tmp_path / "excursion.json"
    path.write_text(json.dumps(plan))
    assert main(["check", "-q", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"phases[{k}]" in out and ": between: " in out and "smooth path" in out, out
    assert main(["simulate", "--trials", "0", str(path)]) == 1
    err = capsys.readouterr().err
    assert "smooth path" in err and "refused" in err, err


def test_a_smooth_path_too_long_in_all_is_left_out_not_sampled(robot) -> None:
    """150 knots 40 m apart (a hostile file): each interval is under the per-interval cap but
    the phase needs over MAX_PHASE_SAMPLES samples: none is made, every interval reported."""
    times = np.arange(152, dtype=float)
    poses = np.array([[40.0 * min(n, 150), 1.0, 0.0] for n in range(152)])  # the dwell last
    s, too_long = path_samples(robot, phase_path(times, poses, None))
    assert len(s.t) == 0 and too_long == 151, (len(s.t), too_long)
