"""Fault class `between-cut`: intermediate steps of a phase removed, so that the straight motion
between the steps that remain leaves feasibility (cuts through rock, sweeps a boom across
rock, passes a pose no tensions hold or a grasp below p_min) while every remaining step holds.

The damaged plan becomes a continuation (`start`, set to the scenario's own start: the same
climb) and the phase holds its end configurations and ramps only, without its trajectory
record (`motion`), as a continuation may: every rule but `between` is then satisfied (time
increases, the joins, ramps and recorded values are untouched, the summary is rescored), so
only the motion between steps is wrong. Between none and three of the phase's intermediate
motion steps are kept at random. A candidate is kept only if the straight motion between two
remaining steps fails (the rule's own feasibility, `TENSION_SLACK` included) over a stretch
longer than the rule's sample spacing in that interval: a fault large enough to be a real one.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from planning.plan_model import Plan, plan_scenario
from planning.verify_between import subdivisions, verification_world
from rb_drake.feasibility import check_poses

PlanFile = dict[str, Any]
FINE = 64         # samples per interval of the fault's own check (finer than the rule's)
TRIES = 8         # (phase, kept steps) tried per call
MAX_KEPT = 3      # intermediate motion steps kept at most


def _motion_span(steps: list[dict]) -> tuple[int, int]:
    """The first and last step of a phase that are not ramp steps."""
    n = len(steps)
    lead = next((i for i, s in enumerate(steps) if "ramp" not in s), n)
    trail = next((i for i, s in enumerate(reversed(steps)) if "ramp" not in s), n)
    return lead, n - 1 - trail


def _fails_long(world, stance, a: np.ndarray, b: np.ndarray, ta, tb, parts: int) -> bool:
    """Whether the linear motion a -> b (poses, tips ta -> tb or None) fails over a stretch of
    more than 1/parts of it, so that one of the rule's samples must land in it."""
    w = np.linspace(0.0, 1.0, FINE + 1)[1:-1]
    poses = a + w[:, None] * (b - a)
    tips = None if ta is None else ta + w[:, None] * (tb - ta)
    bad = ~check_poses(world, stance, poses, tips).feasible
    if not bad.any():
        return False
    # the longest run of failing samples, as a fraction of the interval
    edges = np.diff(np.concatenate([[0], bad.astype(int), [0]]))
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    return bool((runs.max() + 1) / FINE > 1.0 / parts + 1.0 / FINE)


def between_cut(plan: PlanFile, rng: np.random.Generator
                ) -> tuple[PlanFile, int, int, str] | None:
    """The damaged copy (its summary not yet rescored), the phase, the step (in the damaged
    phase) that starts an interval whose motion leaves feasibility, and the fault in words;
    None when no tried cut leaves feasibility."""
    if not plan["success"] or not plan["phases"] or "time_step" not in plan:
        return None  # a footstep plan's motion between steps is not verified
    scn = plan_scenario(Plan.from_dict(plan))
    robot = scn.robot
    world = verification_world(scn)
    spans = {k: _motion_span(p["steps"]) for k, p in enumerate(plan["phases"])}
    choices = [k for k, (a, b) in spans.items() if b - a >= 2]
    if not choices:
        return None
    for _ in range(TRIES):
        k = int(rng.choice(choices))
        a, b = spans[k]
        phase = plan["phases"][k]
        inner = np.arange(a + 1, b)
        kept = np.sort(rng.choice(inner, size=int(rng.integers(0, min(MAX_KEPT, len(inner)) + 1)),
                                  replace=False))
        remain = [a, *(int(i) for i in kept), b]
        steps = [phase["steps"][i] for i in remain]
        poses = np.array([s["pose"] for s in steps], dtype=float)
        tips = (np.array([s["free_tip"] for s in steps], dtype=float)
                if phase["kind"] == "reach" else None)
        stance = scn.stance(tuple(phase["stance"]))
        parts = subdivisions(robot, poses, tips)
        for m in range(len(remain) - 1):
            ta, tb = (None, None) if tips is None else (tips[m], tips[m + 1])
            if _fails_long(world, stance, poses[m], poses[m + 1], ta, tb, int(parts[m])):
                out = copy.deepcopy(plan)
                out.setdefault("start", copy.deepcopy(plan["scenario"]["start"]))
                cut = out["phases"][k]
                removed = [i for i in range(a + 1, b) if i not in remain]
                cut["steps"] = [s for i, s in enumerate(cut["steps"]) if i not in removed]
                cut.pop("motion", None)
                n = remain[m] - sum(i < remain[m] for i in removed)  # its index now
                return out, k, n, (f"phases[{k}]: steps {a + 1} to {b - 1} removed but "
                                f"{[int(i) for i in kept]}; the straight motion from step "
                                f"{remain[m]} to step {remain[m + 1]} leaves feasibility")
    return None
