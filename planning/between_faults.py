"""Fault classes of the motion between steps. `between-cut`: intermediate steps of a phase
removed, so that the straight motion between the steps that remain leaves feasibility (cuts
through rock, sweeps a boom across rock, passes a pose no tensions hold or a grasp below
p_min) while every remaining step holds. `between-smooth` (`between_excursion`): the
straight motion holds too, but the smooth path `rbp simulate` follows does not.

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
from planning.verify_climb import TURN_SPEED_MAX, speed_problems
from rb_drake.feasibility import check_poses

PlanFile = dict[str, Any]
FINE = 64         # samples per interval of the fault's own check (finer than the rule's)
TRIES = 8         # (phase, kept steps) tried per call
MAX_KEPT = 3      # intermediate motion steps kept at most


def splice_through(plan: dict, k: int) -> None:
    """Make `plan` (a continuation: its `start` set) hold phases 0 to k as a continuation's
    spliced-in first phases do: without their motion record, so that a damaged phase k
    needs no trajectory at `time_step` (a phase without one is allowed only among the first)."""
    for phase in plan["phases"][:k + 1]:
        phase.pop("motion", None)


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
                splice_through(out, k)
                n = remain[m] - sum(i < remain[m] for i in removed)  # its index now
                return out, k, n, (f"phases[{k}]: steps {a + 1} to {b - 1} removed but "
                                f"{[int(i) for i in kept]}; the straight motion from step "
                                f"{remain[m]} to step {remain[m + 1]} leaves feasibility")
    return None


def _first_failing(world, stance, poses: np.ndarray, tips: np.ndarray | None,
                   interval: np.ndarray, parts: np.ndarray) -> tuple[int, bool] | None:
    """The first interval in which configurations (`poses`, `tips`, FINE per interval, each
    with its `interval`) fail, and whether they fail over a stretch longer than 1/parts of
    it (so that one of the rule's samples must land in it); None when none fails."""
    bad = ~check_poses(world, stance, poses, tips).feasible
    if not bad.any():
        return None
    n = int(interval[np.argmax(bad)])
    run = bad[interval == n]
    edges = np.diff(np.concatenate([[0], run.astype(int), [0]]))
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    return n, bool((runs.max() + 1) / FINE > 1.0 / parts[n] + 1.0 / FINE)


def between_excursion(plan: PlanFile, rng: np.random.Generator
                      ) -> tuple[PlanFile, int, int, str] | None:
    """Fault class `between-smooth`: two intermediate motion steps of a phase replaced by an
    excursion of the body's angle to the edge of feasibility (found by bisection: the step
    holds, P at p_min or a limit reached) and part of the way back. Every step holds, and so
    does the straight motion between them (checked FINE times per interval), but the smooth
    path `rbp simulate` follows through the steps (`smooth_motion`) overshoots the edge. The
    damaged plan is a continuation whose phase has lost its trajectory record, as in
    `between_cut`. A candidate is kept only if the smooth path fails over a stretch longer
    than the rule's sample spacing in its first failing interval. The damaged copy (summary
    not yet rescored), the phase, the step that starts that interval, and the fault in
    words; None when no tried excursion qualifies."""
    from planning.plan_model import Step
    from planning.plan_steps import allocation_step
    from planning.smooth_motion import phase_path, spline_parts

    if not plan["success"] or not plan["phases"] or "time_step" not in plan:
        return None
    scn = plan_scenario(Plan.from_dict(plan))
    world = verification_world(scn)
    spans = {k: _motion_span(p["steps"]) for k, p in enumerate(plan["phases"])}
    choices = [k for k, (a, b) in spans.items() if b - a >= 6]
    if not choices:
        return None
    w = np.arange(1, FINE) / FINE
    for _ in range(TRIES):
        k = int(rng.choice(choices))
        a, b = spans[k]
        phase = plan["phases"][k]
        n = int(rng.integers(a + 1, b - 3))  # steps n + 1 and n + 2 replaced
        stance = scn.stance(tuple(phase["stance"]))
        reach = phase["kind"] == "reach"
        base = np.array(phase["steps"][n]["pose"], dtype=float)
        sign = float(rng.choice([-1.0, 1.0]))
        back = float(rng.uniform(0.2, 0.6))

        def holds(turn: float, base=base, n=n, phase=phase, stance=stance, reach=reach) -> bool:
            tip = (np.array(phase["steps"][n + 1]["free_tip"], dtype=float)[None]
                   if reach else None)
            return bool(check_poses(scn, stance, (base + np.array([0.0, 0.0, turn]))[None],
                                    tip).feasible[0])

        lo, hi = 0.0, sign * 0.5
        if holds(hi) or not holds(lo):
            continue
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if holds(mid) else (lo, mid)
        # a turn within rule `speed`, so that only `between` can refuse the fault
        t = [float(phase["steps"][m]["t"]) for m in range(n, n + 4)]
        turns = [abs(lo), abs(lo) * (1.0 - back), abs(lo) * back]
        if any(d > TURN_SPEED_MAX * (t1 - t0) for d, t0, t1 in zip(turns, t[:-1], t[1:],
                                                                    strict=True)):
            continue
        out = copy.deepcopy(plan)
        out.setdefault("start", copy.deepcopy(plan["scenario"]["start"]))
        damaged = out["phases"][k]
        splice_through(out, k)
        for m, share in ((n + 1, 1.0), (n + 2, back)):
            old = damaged["steps"][m]
            pose = base + np.array([0.0, 0.0, share * lo])
            tip = np.array(old["free_tip"], dtype=float) if reach else None
            check = check_poses(scn, stance, pose[None], None if tip is None else tip[None],
                                full=True)
            if not check.feasible[0]:
                break
            damaged["steps"][m] = allocation_step(stance, check.allocation, 0, old["t"], pose,
                                                  tip).to_dict()
        else:
            steps = [Step.from_dict(s) for s in damaged["steps"][a:b + 1]]
            times = np.array([s.t for s in steps], dtype=float)
            poses = np.array([s.pose for s in steps], dtype=float)
            tips = np.array([s.free_tip for s in steps], dtype=float) if reach else None
            interval = np.repeat(np.arange(len(steps) - 1), FINE - 1)
            frac = np.tile(w, len(steps) - 1)
            straight = poses[interval] + frac[:, None] * (poses[interval + 1] - poses[interval])
            straight_tips = (None if tips is None else
                             tips[interval] + frac[:, None] * (tips[interval + 1]
                                                                - tips[interval]))
            if _first_failing(world, stance, straight, straight_tips, interval,
                              np.ones(len(steps), dtype=int)) is not None:
                continue
            path = phase_path(times, poses, tips)
            knots = path.knots
            t = knots[interval] + frac * (knots[interval + 1] - knots[interval])
            smooth_tips = None if path.tip is None else path.tip.vector_values(t).T
            first = _first_failing(world, stance, path.pose.vector_values(t).T, smooth_tips,
                                   interval, spline_parts(scn.robot, path))
            if first is None or not first[1]:
                continue
            # rule `speed` on the damaged plan itself: the steps replaced stand at step n's
            # position, so the body's own travel and turn into step n + 3 count too (a test
            # of the injected turn alone let 5 of 1000 faults through that `speed` refused)
            over: list[Any] = []
            speed_problems(Plan.from_dict(out), lambda *problem, found=over: found.append(problem))
            if over:
                continue
            step = a + first[0]
            return out, k, step, (
                f"phases[{k}]: steps {n + 1} and {n + 2} replaced by a turn of "
                f"{np.degrees(lo):+.2f} deg to the edge of feasibility and {back:.2f} of the way "
                f"back; the smooth path from step {step} to step {step + 1} overshoots it")
    return None
