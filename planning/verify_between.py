"""Rule `between`: the motion between successive steps of a plan, verified densely.

A plan is verified at its steps but executed everywhere between them: `rbp rig-run` commands
the straight line from each step to the next (`planning.between.step_motion`, linear in time:
body pose and free tip, so each boom's length follows), and this rule verifies that same
motion. Every interval is sampled so that successive checked configurations (the steps
included) lie at most `TRANSLATION` apart in body position, `ROTATION` in body angle and
`TRAVEL` in each boom's length and in the free gripper's position, and every sample must be
what a step must be (`rb_drake.feasibility.check_poses`, vectorised over all samples of a
phase): booms within their length and shoulder limits, body and booms clear of rock, the free
boom's shoulder torque within its limit, the booms' wrench not degenerate, and tensions (the
most robust allocation, the planner's model of them, which `rbp simulate`'s feed-forward
follows between steps) within the tension limits that balance gravity with every grasp pulled
within max_pull_angle_deg and P at least p_min. `TENSION_SLACK` is the one tolerance, on the
lower tension bound only (docs/formats.md says why). An interval in which neither the body
nor the free gripper moves (a release or attach ramp, a dwell) has nothing between its steps
to sample: a ramp moves the load linearly at one pose, where the statics hold exactly.

`rbp simulate` follows a smooth path through the steps instead (a cubic through each phase of
several steps, for a continuous velocity); `systems.trajectory.PlanTrajectory` verifies that
path at the same resolution with the same test (`spline_subdivisions`, `failing_intervals`)
as it builds it, and slows its velocity at the knots of any interval that fails until the
interval passes or, at velocity zero at both knots, runs along this straight motion. So the
configurations both commands execute are the ones verified here, at the stated resolution.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection
from typing import NamedTuple

import numpy as np

from planning.between import step_motion
from planning.plan_model import Phase
from rb_drake.collision import Rock
from rb_drake.feasibility import REASON_TEXT, PoseCheck, Reason, check_poses
from rb_drake.params import RobotParams
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import balance

TRANSLATION = 0.005            # m: body translation between successive checked configurations
ROTATION = math.radians(0.5)   # rad: body rotation between them
TRAVEL = 0.005                 # m: each boom's length, and the free gripper, between them
# N below the lower tension bound that a boom may reach between steps (not at a step): the
# bound keeps a boom taut, and where a plan's tensions sit on it the planner's own test
# between steps (three points, planning.between) leaves dips of a few tenths of a newton
# between its samples (demo-crevasse: 0.2 N). Any other limit is exact.
TENSION_SLACK = 0.25
# Intervals longer than this many samples (50 m of travel) are not sampled but reported: no
# step of a climb moves that far, and a hostile file must not make the verifier allocate
# without bound. Samples are checked in chunks of CHUNK to bound memory.
MAX_PARTS = 10_000
CHUNK = 20_000


def resolution_text() -> str:
    """The resolution `between` verifies at, in words (for `rbp check`'s output)."""
    return (f"every {TRANSLATION * 1e3:g} mm, {math.degrees(ROTATION):g} deg of body motion "
            f"and {TRAVEL * 1e3:g} mm of boom or gripper travel (the straight motion rbp "
            f"rig-run commands; rbp simulate's smooth path is verified at this resolution as "
            f"it is built and slowed onto the straight motion where it would fail)")


class Samples(NamedTuple):
    """Configurations strictly inside a phase's step intervals."""

    t: np.ndarray               # (S,) plan time
    poses: np.ndarray           # (S, 3)
    tips: np.ndarray | None     # (S, 2) the free gripper in a reach phase
    interval: np.ndarray        # (S,) n: the sample lies between steps n and n + 1


def subdivisions(robot: RobotParams, poses: np.ndarray, tips: np.ndarray | None) -> np.ndarray:
    """Per interval (K - 1,), how many equal parts the linear motion from step to step is cut
    into so that the resolution holds: translation and rotation are linear in the interval's
    fraction; a boom's length changes at most by its shoulder's travel (translation plus the
    shoulder's radius times the rotation) plus its gripper's (the free tip's travel)."""
    d = np.diff(poses, axis=0)
    move = np.hypot(d[:, 0], d[:, 1])
    turn = np.abs(d[:, 2])
    tip = (np.zeros_like(move) if tips is None
           else np.linalg.norm(np.diff(tips, axis=0), axis=1))
    radius = float(np.linalg.norm(robot.shoulder_array, axis=1).max())
    travel = move + radius * turn + tip
    with np.errstate(all="ignore"):
        need = np.maximum.reduce([move / TRANSLATION, turn / ROTATION, tip / TRAVEL,
                                  travel / TRAVEL])
    need = np.where(np.isfinite(need), need, np.inf)
    return np.clip(np.ceil(need - 1e-12), 1, MAX_PARTS + 1).astype(int)


def spline_subdivisions(robot: RobotParams, times: np.ndarray, poses: np.ndarray,
                        rates: np.ndarray, tips: np.ndarray | None = None,
                        tip_rates: np.ndarray | None = None) -> np.ndarray:
    """`subdivisions` for a piecewise cubic Hermite motion (`rbp simulate`'s smooth path):
    body `poses` (K, 3) and their `rates` at knot `times` (K,), in a reach phase the free
    gripper's `tips` (K, 2) and `tip_rates`. On an interval of length T the derivative with
    respect to its fraction s is a quadratic Bezier curve with control points T v0,
    3 (q1 - q0) - T (v0 + v1) and T v1, so its norm never exceeds the largest of theirs (the
    convex hull): a bound on each interval's travel per unit of s, cut as `subdivisions` cuts
    the straight motion."""
    T = np.diff(np.asarray(times, dtype=float))[:, None]

    def speed_bound(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        return np.stack([T * v[:-1], 3.0 * np.diff(q, axis=0) - T * (v[:-1] + v[1:]),
                         T * v[1:]])  # (3, K - 1, n)

    c = speed_bound(poses, rates)
    move = np.hypot(c[..., 0], c[..., 1]).max(axis=0)
    turn = np.abs(c[..., 2]).max(axis=0)
    tip = np.zeros_like(move)
    if tips is not None and tip_rates is not None:
        tip = np.linalg.norm(speed_bound(tips, tip_rates), axis=-1).max(axis=0)
    radius = float(np.linalg.norm(robot.shoulder_array, axis=1).max())
    travel = move + radius * turn + tip
    with np.errstate(all="ignore"):
        need = np.maximum.reduce([move / TRANSLATION, turn / ROTATION, tip / TRAVEL,
                                  travel / TRAVEL])
    need = np.where(np.isfinite(need), need, np.inf)
    return np.clip(np.ceil(need - 1e-12), 1, MAX_PARTS + 1).astype(int)


def failing_intervals(world: _World, stance: Stance, times: np.ndarray, parts: np.ndarray,
                      intervals: Collection[int], pose_at: Callable[[np.ndarray], np.ndarray],
                      tip_at: Callable[[np.ndarray], np.ndarray] | None = None) -> list[int]:
    """Which of `intervals` (n: between knots n and n + 1 at `times`) of a motion
    (`pose_at(t)` (S, 3), in a reach phase `tip_at(t)` (S, 2)) fail rule `between`'s test at
    a sample, each cut into `parts[n]` equal parts in time; an interval too long to sample
    (over MAX_PARTS) fails."""
    chosen = np.array(sorted(intervals), dtype=int)
    if not len(chosen):
        return []
    n_parts = parts[chosen]
    failed = set(map(int, chosen[n_parts > MAX_PARTS]))
    n_parts = np.where(n_parts > MAX_PARTS, 1, n_parts)
    interval = np.repeat(chosen, n_parts - 1)
    first = np.concatenate([[0], np.cumsum(n_parts - 1)])[np.repeat(np.arange(len(chosen)),
                                                                     n_parts - 1)]
    j = np.arange(len(interval)) - first + 1
    w = j / np.repeat(n_parts, n_parts - 1)
    t = times[interval] + w * (times[interval + 1] - times[interval])
    for lo in range(0, len(t), CHUNK):
        rows = slice(lo, lo + CHUNK)
        with np.errstate(all="ignore"):
            check = check_poses(world, stance, pose_at(t[rows]),
                                None if tip_at is None else tip_at(t[rows]))
        failed.update(map(int, interval[rows][~check.feasible]))
    return sorted(failed)


def samples(robot: RobotParams, times: np.ndarray, poses: np.ndarray,
            tips: np.ndarray | None = None) -> Samples:
    """The samples strictly inside the intervals of steps at `times` (K,) with body `poses`
    (K, 3) and, in a reach phase, free gripper `tips` (K, 2), on `step_motion` (the motion the
    rig executes and this rule verifies): interval n cut into `subdivisions` equal parts."""
    times = np.asarray(times, dtype=float)
    poses = np.asarray(poses, dtype=float)
    parts = subdivisions(robot, poses, tips)
    parts = np.where(parts > MAX_PARTS, 1, parts)  # too long to sample: `too_long` reports it
    interval = np.repeat(np.arange(len(parts)), parts - 1)
    first = np.concatenate([[0], np.cumsum(parts - 1)])[interval]
    j = np.arange(len(interval)) - first + 1  # 1 .. parts - 1 within each interval
    w = j / parts[interval]
    t = times[interval] + w * (times[interval + 1] - times[interval])
    out_poses = step_motion(times, poses).vector_values(t).T if len(t) else np.zeros((0, 3))
    out_tips = None
    if tips is not None:
        out_tips = step_motion(times, tips).vector_values(t).T if len(t) else np.zeros((0, 2))
    return Samples(t, out_poses, out_tips, interval)


def _arrays(phase: Phase) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A phase's step times, poses and (in a reach phase) free gripper positions."""
    times = np.array([s.t for s in phase.steps], dtype=float)
    poses = np.array([s.pose for s in phase.steps], dtype=float)
    tips = (np.array([s.free_tip for s in phase.steps], dtype=float)
            if phase.kind == "reach" else None)
    return times, poses, tips


def phase_samples(robot: RobotParams, phase: Phase) -> Samples:
    """`samples` of a phase's steps."""
    return samples(robot, *_arrays(phase))


class _World(NamedTuple):
    robot: RobotParams
    rock: Rock
    gravity_vector: np.ndarray


def verification_world(scn: Scenario) -> _World:
    """The cave and robot the rule checks samples in: the robot's lower tension bound
    TENSION_SLACK lower, all else as it is."""
    robot = scn.robot
    lo, hi = robot.boom_tension
    slack = dataclasses.replace(robot, boom_tension=(max(0.0, lo - TENSION_SLACK), hi))
    return _World(slack, scn.rock, scn.gravity_vector)


Fail = Callable[[int, int, str], None]


def between_problems(phases: tuple[Phase, ...], scn: Scenario, skip: Collection[int | None],
                     fail: Fail) -> int:
    """Verifies the motion inside every step interval of every phase but those in `skip`
    (reported by other rules); `fail(phase, n, text)` once per failing interval (n: its first
    step). Returns the number of configurations checked between steps."""
    robot = scn.robot
    world = verification_world(scn)
    checked = 0
    for k, phase in enumerate(phases):
        if k in skip or len(phase.steps) < 2 or not _well_formed(phase):
            continue
        stance = scn.stance(tuple(phase.stance))
        for long in np.flatnonzero(subdivisions(robot, *_arrays(phase)[1:]) > MAX_PARTS):
            fail(k, int(long), f"between steps {long} and {long + 1}: the motion is too long to "
                 f"verify (over {MAX_PARTS} samples at the resolution)")
        s = phase_samples(robot, phase)
        checked += len(s.t)
        failed: set[int] = set()
        for lo in range(0, len(s.t), CHUNK):
            rows = slice(lo, lo + CHUNK)
            tips = None if s.tips is None else s.tips[rows]
            with np.errstate(all="ignore"):
                check = check_poses(world, stance, s.poses[rows], tips)
            for i in map(int, np.flatnonzero(~check.feasible)):
                n = int(s.interval[lo + i])
                if n in failed:  # one problem per interval: its first failing sample
                    continue
                failed.add(n)
                fail(k, n, _text(phase, s, lo + i, check, i, robot.p_min))
        if stance.free_boom is None:
            for n, text in _commanded_tension_problems(world, stance, phase, s, failed):
                fail(k, n, text)
    return checked


def _commanded_tension_problems(world: _World, stance: Stance, phase: Phase, s: Samples,
                                failed: set[int]) -> list[tuple[int, str]]:
    """A 4-stance's tensions as `rbp rig-run` commands them between steps (the plan's step
    tensions joined linearly, `step_motion`), brought into equilibrium by the least change
    (`statics.balance`): within the tension bounds and every grasp's P at least p_min at each
    sample of intervals not already failed. The feasibility test above checks the most robust
    tensions; these are the ones the plan asks for (a 3-stance has no choice)."""
    rows = np.flatnonzero(~np.isin(s.interval, list(failed))) if failed else np.arange(len(s.t))
    if not len(rows):
        return []
    times, _, _ = _arrays(phase)
    steps = np.array([[np.nan if f is None else f for f in st.tension] for st in phase.steps],
                     dtype=float)
    if not np.all(np.isfinite(steps[:, stance.attached])):
        return []  # a step without its tensions: rule `steps` reports it
    out: list[tuple[int, str]] = []
    robot = world.robot
    log_min = math.log(robot.p_min)
    for lo in range(0, len(rows), CHUNK):
        part = rows[lo:lo + CHUNK]
        commanded = step_motion(times, steps).vector_values(s.t[part]).T
        with np.errstate(all="ignore"):
            held = balance(robot, world.gravity_vector, s.poses[part], stance, commanded)
        weak = held.log_probs[:, stance.attached].min(axis=1) < log_min
        for i in map(int, np.flatnonzero(~held.statics_ok | weak)):
            n = int(s.interval[part[i]])
            if n in failed:
                continue
            failed.add(n)
            t0, t1 = phase.steps[n].t, phase.steps[n + 1].t
            w = (s.t[part[i]] - t0) / (t1 - t0)
            why = ("out of the tension bounds" if not held.statics_ok[i] else
                   f"a grasp at P = {math.exp(held.log_probs[i, stance.attached].min()):.5f} "
                   f"< {robot.p_min}")
            out.append((n, f"between steps {n} and {n + 1}, at {w:.3f} of the way "
                        f"(t={s.t[part[i]]:.4f}): the plan's tensions, joined linearly and "
                        f"balanced, are {why}"))
    return out


def _text(phase: Phase, s: Samples, j: int, check: PoseCheck, i: int, p_min: float) -> str:
    """What failed at sample j (row i of `check`), in words."""
    n = int(s.interval[j])
    t0, t1 = phase.steps[n].t, phase.steps[n + 1].t
    w = (s.t[j] - t0) / (t1 - t0)
    reason = Reason(int(check.reason[i]))
    what = REASON_TEXT[reason]
    if check.boom[i] >= 0:
        what = f"boom {int(check.boom[i])}: {what}"
    if reason == Reason.PROBABILITY:
        what += f" (P = {float(check.probability[i]):.5f} < {p_min})"
    pose = ", ".join(f"{v:.4f}" for v in s.poses[j])
    return (f"between steps {n} and {n + 1}, at {w:.3f} of the way (t={s.t[j]:.4f}, "
            f"pose [{pose}]): {what}")


def _well_formed(phase: Phase) -> bool:
    """Whether a phase's motion can be sampled (else other rules report why it cannot)."""
    times = np.array([s.t for s in phase.steps], dtype=float)
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
        return False
    if phase.kind == "reach" and any(s.free_tip is None for s in phase.steps):
        return False
    poses = np.array([s.pose for s in phase.steps], dtype=float)
    tips = _arrays(phase)[2]
    return bool(np.all(np.isfinite(poses)) and (tips is None or np.all(np.isfinite(tips))))
