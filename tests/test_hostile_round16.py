"""Probe 16: the motion between steps sampled far more densely than rule `between` does.

Rule `between` checked configurations at most 5 mm apart and nothing between them, so a rock
corner that the free gripper's path (or a body corner's) cut between two of them passed: a
rock spike 3 mm wide across the gripper's path of demo-shaft's first reach, added to the
plan's cave, was accepted by `rbp check` while the straight motion `rbp rig-run` commands
and the smooth path `rbp simulate` follows both drove the gripper through it (20 times the
rule's density: 17 and 16 samples in rock). The rule now also tests the paths of those
points between successive checked configurations (`verify_between.travel_failures`).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planning.check import verify_plan
from planning.plan_file import validated
from planning.plan_model import Plan, plan_scenario
from planning.smooth_motion import smooth_path_problems
from planning.verify_between import (
    phase_world,
    step_motion,
    subdivisions,
    travel_failures,
    verification_world,
)
from rb_drake import geometry
from rb_drake.collision import Rock
from rb_drake.feasibility import Reason, body_in_rock, check_poses

DATA = Path(__file__).parent / "data"
PlanFile = dict[str, Any]
REACH, STEP = 1, 29  # demo-shaft-current's first reach phase, an interval mid-reach


@pytest.fixture(scope="module")
def golden() -> PlanFile:
    return json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())


def problems_of(plan: PlanFile) -> list[Any]:
    return verify_plan(validated(json.loads(json.dumps(plan))))


def wedge(apex: np.ndarray, axis: np.ndarray, half: float, depth: float,
          length: float = 0.03) -> list[list[float]]:
    """A rock triangle, counter-clockwise, with its apex at `apex`, opening along `axis`, its
    width 2 `half` at `depth` from the apex."""
    side = np.array([-axis[1], axis[0]])
    wide = half * (depth + length) / depth
    base = apex + (depth + length) * axis
    poly = [apex, base + wide * side, base - wide * side]
    a, b, c = poly
    if (b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0] < 0:
        poly = [a, c, b]
    return [[float(v) for v in p] for p in poly]


def spiked(golden: PlanFile, k: int = REACH, n: int = STEP) -> PlanFile:
    """The plan with a rock spike in its cave that the free gripper's straight path from step
    n to n + 1 of reach phase k cuts 2 mm deep, midway between two of the rule's samples, its
    width there 3 mm (the samples lie 2.5 mm either side of the cut)."""
    plan = Plan.from_dict(golden)
    scn = plan_scenario(plan)
    phase = plan.phases[k]
    q = np.array([s.pose for s in phase.steps], dtype=float)
    g = np.array([s.free_tip for s in phase.steps], dtype=float)
    parts = int(subdivisions(scn.robot, q[n:n + 2], g[n:n + 2])[0])
    w = (parts // 2 + 0.5) / parts
    tip = g[n] + w * (g[n + 1] - g[n])
    pose = q[n] + w * (q[n + 1] - q[n])
    e = (g[n + 1] - g[n]) / np.linalg.norm(g[n + 1] - g[n])
    out_of_reach = np.array([-e[1], e[0]])  # across the path, away from the shoulder
    shoulder = geometry.shoulder_positions(scn.robot, pose[None])[0, phase.free_boom]
    if np.dot(out_of_reach, tip - shoulder) < 0:
        out_of_reach = -out_of_reach
    out = copy.deepcopy(golden)
    out["scenario"]["walls"].append(wedge(tip - 0.002 * out_of_reach, out_of_reach, 0.0015,
                                          0.002))
    return out


def dense_failures(plan_file: PlanFile, k: int, factor: int = 20) -> dict[str, int]:
    """Phase k's straight motion and rbp simulate's smooth path sampled `factor` times as
    densely as the rule: how many samples of each fail `check_poses` (the rule's own test)."""
    from systems.trajectory import PlanTrajectory

    plan = Plan.from_dict(plan_file)
    scn = plan_scenario(plan)
    phase = plan.phases[k]
    world = phase_world(verification_world(scn), phase)
    stance = scn.stance(tuple(phase.stance))
    t = np.array([s.t for s in phase.steps], dtype=float)
    q = np.array([s.pose for s in phase.steps], dtype=float)
    g = np.array([s.free_tip for s in phase.steps], dtype=float) if phase.free_boom is not None \
        else None
    m = factor * int(subdivisions(scn.robot, q, g).sum())
    ts = np.linspace(t[0], t[-1], m + 1)
    traj = PlanTrajectory(plan, scn)
    tip = traj.phases[k].free_tip
    out = {}
    for name, poses, tips in (
            ("straight", step_motion(t, q).vector_values(ts).T,
             None if g is None else step_motion(t, g).vector_values(ts).T),
            ("smooth", traj.pose.vector_values(ts).T,
             None if tip is None else tip.vector_values(ts).T)):
        check = check_poses(world, stance, poses, tips)
        out[name] = int(np.count_nonzero(check.reason == int(Reason.BOOM_COLLISION)))
    return out


def test_the_unspiked_plan_verifies(golden: PlanFile) -> None:
    assert problems_of(copy.deepcopy(golden)) == []


def test_a_spike_cut_by_the_gripper_between_samples_is_refused(golden: PlanFile) -> None:
    """Accepted before: every step and every sample of both motions clear of the spike."""
    plan = spiked(golden)
    dense = dense_failures(plan, REACH)
    assert dense["straight"] > 0 and dense["smooth"] > 0  # the executed motions cross rock
    found = problems_of(plan)
    assert [(p.rule, p.phase, p.step) for p in found] == [("between", REACH, STEP)]
    assert "boom 2: its end crosses rock" in found[0].text


def test_the_smooth_path_alone_sees_the_spike_too(golden: PlanFile) -> None:
    """Rule `between` on rbp simulate's smooth path (run once the rest passes) refuses it too."""
    model = Plan.from_dict(spiked(golden))
    scn = plan_scenario(model)
    seen: list[tuple[int, int, str]] = []
    smooth_path_problems(model, scn, lambda k: scn.stance(tuple(model.phases[k].stance)),
                         lambda k, n, text: seen.append((k, n, text)))
    assert [(k, n) for k, n, _ in seen] == [(REACH, STEP)]
    assert "smooth path" in seen[0][2] and "crosses rock" in seen[0][2]


def test_a_body_corner_cutting_rock_between_two_configurations(golden: PlanFile) -> None:
    """A body corner moving 4 mm across the apex of a rock spike: the body is clear of rock
    at both configurations; the corner's path between them is not."""
    plan = Plan.from_dict(golden)
    base = plan_scenario(plan)
    phase = plan.phases[0]
    stance = base.stance(tuple(phase.stance))
    pose = np.array(phase.steps[5].pose, dtype=float)
    hits = 0
    for c in range(4):
        corner = geometry.body_corners(base.robot, pose[None])[0, c]
        out = (corner - pose[:2]) / np.linalg.norm(corner - pose[:2])
        across = np.array([-out[1], out[0]])
        poses = np.array([pose, pose]) + np.array([[*(-0.002 * across), 0.0],
                                                   [*(0.002 * across), 0.0]])
        spike = wedge(corner - 0.001 * out, out, 0.0015, 0.001)
        rock = Rock([*base.rock.polygons, np.array(spike)])
        world = verification_world(base)._replace(rock=rock)
        assert not body_in_rock(base.robot, rock, poses).any()
        found = travel_failures(world, stance, poses, None, np.array([0]))
        assert found and found[0][2] == -1  # a body corner
        hits += 1
    assert hits == 4

