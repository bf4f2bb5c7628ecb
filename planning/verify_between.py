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
lower tension bound only (docs/formats.md says why). Between successive checked
configurations, the paths of the points that move farthest, each boom's end and each body
corner, are tested for rock too (`travel_failures`): a rock corner they cut between two
samples passed before. An interval in which neither the body
nor the free gripper moves (a release or attach ramp, a dwell) has nothing between its steps
to sample: a ramp moves the load linearly at one pose, where the statics hold exactly.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from planning.plan_model import Phase
from rb_drake import geometry
from rb_drake.collision import Rock, boom_clearances
from rb_drake.feasibility import (
    REASON_TEXT,
    PoseCheck,
    ReachWorld,
    Reason,
    World,
    _targets,
    check_poses,
    reach_world,
)
from rb_drake.params import RobotParams
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

if TYPE_CHECKING:
    from pydrake.trajectories import PiecewisePolynomial

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
# A phase needing more samples than this in all (5 km of travel) is reported, not sampled: a
# hostile file of many long intervals, each under MAX_PARTS, must not allocate without bound
# either (400,000 steps 40 m apart fit in a 64 MiB file).
MAX_PHASE_SAMPLES = 1_000_000
# And a plan needing more than this in all (10 km of travel; a 20 m climb needs about 10^5) is
# reported from the phase that passes it: many phases each under MAX_PHASE_SAMPLES made an
# 8 MiB file take minutes to verify.
MAX_PLAN_SAMPLES = 2_000_000


def step_motion(times: np.ndarray, values: np.ndarray) -> PiecewisePolynomial:
    """values (K, n) at step times (K,) joined linearly in time (a first-order hold): the
    motion between a plan's steps as `rbp rig-run` commands it (pose and tensions of a body
    phase) and as `rbp check` verifies it (rule `between`), and the simulation's without
    resampling; a single step holds its value for a second."""
    from pydrake.trajectories import PiecewisePolynomial

    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    if len(times) == 1:
        times = np.array([times[0], times[0] + 1.0])
        values = np.vstack([values, values])
    return PiecewisePolynomial.FirstOrderHold(times, values.T)


def resolution_text() -> str:
    """The resolution `between` verifies at, in words (for `rbp check`'s output)."""
    return (f"every {TRANSLATION * 1e3:g} mm, {math.degrees(ROTATION):g} deg of body motion "
            f"and {TRAVEL * 1e3:g} mm of boom or gripper travel")


class Samples(NamedTuple):
    """Configurations strictly inside a phase's step intervals."""

    t: np.ndarray               # (S,) plan time
    poses: np.ndarray           # (S, 3)
    tips: np.ndarray | None     # (S, 2) the free gripper in a reach phase
    interval: np.ndarray        # (S,) n: the sample lies between steps n and n + 1
    # (S,) how far along its interval each sample lies, where not in proportion to the steps'
    # times (a smooth path whose last motion is spread over the dwell); None: in proportion
    fraction: np.ndarray | None = None


def subdivisions(robot: RobotParams, poses: np.ndarray, tips: np.ndarray | None) -> np.ndarray:
    """Per interval (K - 1,), how many equal parts the linear motion from step to step is cut
    into so that the resolution holds: translation and rotation are linear in the interval's
    fraction; a boom's length changes at most by its shoulder's travel (translation plus the
    shoulder's radius times the rotation) plus its gripper's (the free tip's travel)."""
    d = np.diff(poses, axis=0)
    move = np.hypot(d[:, 0], d[:, 1])
    tip = (np.zeros_like(move) if tips is None
           else np.linalg.norm(np.diff(tips, axis=0), axis=1))
    return parts_for(robot, move, np.abs(d[:, 2]), tip)


def parts_for(robot: RobotParams, move: np.ndarray, turn: np.ndarray,
              tip: np.ndarray) -> np.ndarray:
    """Per interval, how many equal parts keep successive samples within the resolution, from
    bounds on the interval's body translation `move`, rotation `turn` and gripper travel
    `tip`: a boom's length changes at most by its shoulder's travel (translation plus the
    shoulder's radius times the rotation) plus its gripper's. Capped at MAX_PARTS + 1."""
    radius = float(np.linalg.norm(robot.shoulder_array, axis=1).max())
    travel = move + radius * turn + tip
    with np.errstate(all="ignore"):
        need = np.maximum.reduce([move / TRANSLATION, turn / ROTATION, tip / TRAVEL,
                                  travel / TRAVEL])
    need = np.where(np.isfinite(need), need, np.inf)
    return np.clip(np.ceil(need - 1e-12), 1, MAX_PARTS + 1).astype(int)


def first_failure(world: _World | World, stance: Stance, s: Samples, label: str) -> str:
    """'' when every sample of `s` passes `check_poses` in `world`, else where the first fails
    and why, in the planner's words: "between steps N and N+1 (label): REASON". The planner's
    test, so compiled (`score_poses`: check_poses' decisions without its numpy overhead, 10 to
    90 times faster on the few dozen samples of an interval); `rbp check` keeps check_poses."""
    if not len(s.t):
        return ""
    # here, not at the top: `rbp check` reads this module and needs no compiled kernel (numba)
    from rb_drake.kernel.scoring import score_poses

    check = score_poses(world, stance, s.poses, s.tips)
    if check.feasible.all():
        return ""
    k = int(np.argmin(check.feasible))
    n = int(s.interval[k])
    return f"between steps {n} and {n + 1} ({label}): {Reason(int(check.reason[k])).name}"


def smooth_departure(times: np.ndarray, poses: np.ndarray, rates: np.ndarray,
                     tips: np.ndarray | None = None,
                     tip_rates: np.ndarray | None = None) -> np.ndarray:
    """Per interval (K - 1,), a bound on how far a piecewise cubic Hermite motion (knot
    `times` (K,), body `poses` (K, 3) and their `rates`; in a reach phase the free gripper's
    `tips` (K, 2) and `tip_rates`) strays from the straight segment between the same knots,
    in units of the resolution (a configuration scaled by TRANSLATION in position, ROTATION in
    angle and TRAVEL in the gripper's position; 1 is one resolution).

    At fraction s of an interval of length T, with chord velocity c = (q1 - q0) / T, the
    cubic less the straight line at the same fraction is T (h10(s) (v0 - c) + h11(s) (v1 - c)).
    Along the chord it only moves the configuration along the segment, except where it
    overshoots an end (the along-chord coordinate, a cubic in s, is maximised exactly); across
    it, |h10| and |h11| never exceed 4/27. The bound is the hypotenuse of the two."""
    times = np.asarray(times, dtype=float)
    T = np.diff(times)[:, None]
    scale = [TRANSLATION, TRANSLATION, ROTATION]
    q, v = np.asarray(poses, dtype=float) / scale, np.asarray(rates, dtype=float) / scale
    if tips is not None and tip_rates is not None:
        q = np.hstack([q, np.asarray(tips, dtype=float) / TRAVEL])
        v = np.hstack([v, np.asarray(tip_rates, dtype=float) / TRAVEL])
    delta = np.diff(q, axis=0)
    length = np.linalg.norm(delta, axis=1)
    unit = delta / np.maximum(length, 1e-300)[:, None]
    u0, u1 = T * v[:-1] - delta, T * v[1:] - delta  # T (v - c)
    a0, a1 = np.sum(u0 * unit, axis=1), np.sum(u1 * unit, axis=1)
    across = (4.0 / 27.0) * (np.linalg.norm(u0 - a0[:, None] * unit, axis=1)
                             + np.linalg.norm(u1 - a1[:, None] * unit, axis=1))
    # along(s) = s L + a0 h10(s) + a1 h11(s), with h10 = s^3 - 2 s^2 + s, h11 = s^3 - s^2
    c3, c2, c1 = a0 + a1, -2.0 * a0 - a1, length + a0
    s = [np.zeros_like(length), np.ones_like(length)]
    disc = (2.0 * c2) ** 2 - 12.0 * c3 * c1
    root = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(all="ignore"):
        for sign in (-1.0, 1.0):
            r = np.where(np.abs(c3) > 1e-12, (-2.0 * c2 + sign * root) / (6.0 * c3),
                         -c1 / (2.0 * c2))
            s.append(np.where((disc >= 0) & np.isfinite(r), np.clip(r, 0.0, 1.0), 0.0))
    along = np.stack([c3 * x**3 + c2 * x**2 + c1 * x for x in s])
    beyond = np.maximum(np.maximum(-along.min(axis=0), along.max(axis=0) - length), 0.0)
    return np.hypot(across, beyond)


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


def phase_arrays(phase: Phase) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A phase's step times, poses and (in a reach phase) free gripper positions."""
    times = np.array([s.t for s in phase.steps], dtype=float)
    poses = np.array([s.pose for s in phase.steps], dtype=float)
    tips = (np.array([s.free_tip for s in phase.steps], dtype=float)
            if phase.kind == "reach" else None)
    return times, poses, tips


def phase_samples(robot: RobotParams, phase: Phase) -> Samples:
    """`samples` of a phase's steps."""
    return samples(robot, *phase_arrays(phase))


class _World(NamedTuple):
    robot: RobotParams
    rock: Rock
    gravity_vector: np.ndarray
    anchor_positions: np.ndarray  # (A, 2): a free gripper may touch rock only near these


def verification_world(scn: Scenario | World) -> _World:
    """The cave and robot the rule checks samples in: the robot's lower tension bound
    TENSION_SLACK lower, all else as it is."""
    robot = scn.robot
    lo, hi = robot.boom_tension
    slack = dataclasses.replace(robot, boom_tension=(max(0.0, lo - TENSION_SLACK), hi))
    return _World(slack, scn.rock, scn.gravity_vector, scn.anchor_positions)


def phase_world(world: _World | World, phase: Phase) -> _World | World:
    """`world` for the configurations of `phase`: in a reach phase its free gripper may touch
    rock only near its own anchors, where its steps start and end (rule reach-ends puts them
    on from_anchor and to_anchor; rb_drake.feasibility.reach_world)."""
    if phase.kind != "reach" or not phase.steps:
        return world
    ends = [phase.steps[0].free_tip, phase.steps[-1].free_tip]
    if any(e is None for e in ends):  # other rules report it; no allowance meanwhile
        return ReachWorld(world.robot, world.rock, world.gravity_vector, np.zeros((0, 2)))
    return reach_world(world, np.array(ends, dtype=float))


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
        parts = subdivisions(robot, *phase_arrays(phase)[1:])
        for long in np.flatnonzero(parts > MAX_PARTS):
            fail(k, int(long), f"between steps {long} and {long + 1}: the motion is too long to "
                 f"verify (over {MAX_PARTS} samples at the resolution)")
        needed = int(np.sum(np.where(parts > MAX_PARTS, 0, parts - 1)))
        if needed > MAX_PHASE_SAMPLES:
            fail(k, 0, f"the phase's motion is too long to verify (over {MAX_PHASE_SAMPLES} "
                 f"samples at the resolution)")
            continue
        if checked + needed > MAX_PLAN_SAMPLES:
            fail(k, 0, f"the plan's motion is too long to verify: with this phase it needs "
                 f"over {MAX_PLAN_SAMPLES} samples at the resolution (phases after it are "
                 "not verified between steps)")
            break
        s = phase_samples(robot, phase)
        checked += len(s.t)
        found = failing_intervals(world, stance, phase, s)
        # intervals failing already, or too long to sample (reported above), are not tested
        bad = {n for n, _ in found} | {int(n) for n in np.flatnonzero(parts > MAX_PARTS)}
        times, poses, tips = phase_arrays(phase)
        for n, text in found + straight_travel(world, phase, stance, s, times, poses, tips, bad):
            fail(k, n, text)
    return checked


def straight_travel(world: _World | World, phase: Phase, stance: Stance, s: Samples,
                    times: np.ndarray, poses: np.ndarray, tips: np.ndarray | None,
                    skip: Collection[int]) -> list[tuple[int, str]]:
    """`travel_failures` on the straight motion: the steps and the samples between them in
    time order, intervals in `skip` (already failing) left out."""
    t = np.concatenate([times, s.t])
    order = np.argsort(t, kind="stable")
    t = t[order]
    q = np.vstack([poses, s.poses])[order]
    g = None if tips is None or s.tips is None else np.vstack([tips, s.tips])[order]
    pair = np.clip(np.searchsorted(times, t[:-1], side="right") - 1, 0, len(times) - 2)
    pair[np.isin(pair, list(skip))] = -1  # failing already: not tested again
    out = []
    for j, n, boom in travel_failures(phase_world(world, phase), stance, q, g, pair):
        w = (t[j] - times[n]) / (times[n + 1] - times[n])
        out.append((n, travel_text(n, float(t[j]), q[j], w, boom)))
    return out


def failing_intervals(world: _World | World, stance: Stance, phase: Phase, s: Samples,
                      what: str = "") -> list[tuple[int, str]]:
    """The step intervals (n: the first step) of `phase` in which a sample of `s` fails
    `check_poses` in `world`, each once with its first failing sample in words (`what`
    names the motion sampled, e.g. rbp simulate's smooth path; empty: the straight one)."""
    out: list[tuple[int, str]] = []
    failed: set[int] = set()
    world = phase_world(world, phase)
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
            out.append((n, _text(phase, s, lo + i, check, i, world.robot.p_min, what)))
    return out


def travel_failures(world: _World | World, stance: Stance, poses: np.ndarray,
                    tips: np.ndarray | None, pair: np.ndarray
                    ) -> list[tuple[int, int, int]]:
    """Rock crossed between successive checked configurations: (j, n, boom) for each interval n
    whose motion from configuration j to j + 1 (`poses`, `tips` in time order, the steps at
    the intervals' ends included; `pair` (J - 1,): the interval of each pair, -1 to skip it)
    moves a boom's end (its gripper, or a held boom's end ANCHOR_CLEARANCE short
    of its anchor, as `check_poses` tests it) or a body corner (boom -1) across a rock edge.
    Those points move farthest between configurations, and the samples alone let a rock
    corner that their path cuts between two of them pass (a spike 3 mm wide across a free
    gripper's path: tests/test_hostile_round16.py); their paths between configurations are the
    chords between them (exactly on the straight motion; on the smooth path and where the body
    turns, within micrometres of them at the rule's resolution). One per interval, the first."""
    rock = world.rock
    if not rock.polygons or len(poses) < 2:
        return []
    out: list[tuple[int, int, int]] = []
    seen: set[int] = set()
    # in chunks of CHUNK configurations (each chunk's last is the next one's first), as
    # `failing_intervals` checks samples: a phase of 10^6 samples, within MAX_PHASE_SAMPLES,
    # took 1.9 GB here in one batch (a 0.5 MB plan turning 3 full turns a step)
    for lo in range(0, len(poses) - 1, CHUNK):
        hi = min(lo + CHUNK + 1, len(poses))
        for j, n, boom in _travel_chunk(world, stance, poses[lo:hi],
                                        None if tips is None else tips[lo:hi], pair[lo:hi - 1]):
            if n not in seen:
                seen.add(n)
                out.append((lo + j, n, boom))
    return out


def _travel_chunk(world: _World | World, stance: Stance, poses: np.ndarray,
                  tips: np.ndarray | None, pair: np.ndarray) -> list[tuple[int, int, int]]:
    """`travel_failures` on consecutive configurations `poses` (P, 3) and `tips` with their
    pairs' intervals `pair` (P - 1,): (j, n, boom), j numbered within the chunk."""
    rock = world.rock
    moving = np.any(poses[1:] != poses[:-1], axis=1)
    if tips is not None:
        moving |= np.any(tips[1:] != tips[:-1], axis=1)
    pairs = np.flatnonzero(moving & (pair >= 0))
    if not len(pairs):
        return []
    P = len(poses)
    targets = _targets(stance, tips, P)
    used = np.isfinite(targets[..., 0])
    geo = geometry.boom_geometry(world.robot, poses, targets)
    clearance = boom_clearances(world.anchor_positions, P, stance.free_boom, tips)
    with np.errstate(invalid="ignore"):
        ends = targets - clearance[:, :, None] * np.nan_to_num(geo.u)
    corners = geometry.body_corners(world.robot, poses)
    boom_hit = rock.segments_hit(ends[pairs], ends[pairs + 1], inside=False)
    boom_hit &= used[pairs] & used[pairs + 1]
    body_hit = rock.segments_hit(corners[pairs], corners[pairs + 1], inside=False)
    out: list[tuple[int, int, int]] = []
    seen: set[int] = set()
    for i in map(int, np.flatnonzero(boom_hit.any(axis=1) | body_hit.any(axis=1))):
        n = int(pair[pairs[i]])
        if n in seen:
            continue
        seen.add(n)
        boom = int(np.argmax(boom_hit[i])) if boom_hit[i].any() else -1
        out.append((int(pairs[i]), n, boom))
    return out


def travel_text(n: int, t0: float, pose: np.ndarray, w: float, boom: int,
                motion: str = "") -> str:
    """`travel_failures`' finding in words."""
    where = ", ".join(f"{v:.4f}" for v in pose)
    what = (f"boom {boom}: its end crosses rock" if boom >= 0
            else "a body corner crosses rock")
    return (f"between steps {n} and {n + 1}{motion}, from {w:.3f} of the way (t={t0:.4f}, "
            f"pose [{where}]) to the next configuration checked: {what}")


def _text(phase: Phase, s: Samples, j: int, check: PoseCheck, i: int, p_min: float,
          motion: str = "") -> str:
    """What failed at sample j (row i of `check`), in words."""
    n = int(s.interval[j])
    t0, t1 = phase.steps[n].t, phase.steps[n + 1].t
    w = (s.t[j] - t0) / (t1 - t0) if s.fraction is None else float(s.fraction[j])
    reason = Reason(int(check.reason[i]))
    what = REASON_TEXT[reason]
    if check.boom[i] >= 0:
        what = f"boom {int(check.boom[i])}: {what}"
    if reason == Reason.PROBABILITY:
        what += f" (P = {float(check.probability[i]):.5f} < {p_min})"
    pose = ", ".join(f"{v:.4f}" for v in s.poses[j])
    return (f"between steps {n} and {n + 1}{motion}, at {w:.3f} of the way (t={s.t[j]:.4f}, "
            f"pose [{pose}]): {what}")


def _well_formed(phase: Phase) -> bool:
    """Whether a phase's motion can be sampled (else other rules report why it cannot)."""
    times = np.array([s.t for s in phase.steps], dtype=float)
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
        return False
    if phase.kind == "reach" and any(s.free_tip is None for s in phase.steps):
        return False
    poses = np.array([s.pose for s in phase.steps], dtype=float)
    tips = phase_arrays(phase)[2]
    return bool(np.all(np.isfinite(poses)) and (tips is None or np.all(np.isfinite(tips))))
