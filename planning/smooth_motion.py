"""The smooth path through a phase's steps, as `rbp simulate` follows it, and its test.

`systems.trajectory.PlanTrajectory` joins the steps of a phase of several steps by a cubic
Hermite spline of the body pose whose knot velocities are those of the spline with continuous
acceleration through each run of steps between two rests (`continuous_acceleration_rates`),
with the motion into the last configuration spread over most of the final dwell
(`finish_over_dwell`), and the free gripper by a shape-preserving cubic (`shape_preserving`).
Those definitions live here, so that the planner tests the path the simulation will follow
(`smooth_problem`) and the verifier checks it (`systems.plan_check`).

The path is sampled interval by interval finely enough that successive samples lie within
rule `between`'s resolution (`planning.verify_between`: TRANSLATION, ROTATION, TRAVEL), and
the sampling is proven fine enough: on an interval of length T a cubic's rate in each
coordinate is a quadratic in the fraction s, whose largest magnitude on [0, 1] is found
exactly (at its ends or its vertex), so successive samples are no further apart than that
rate over the number of parts (`spline_parts`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from pydrake.trajectories import PiecewisePolynomial

from planning.plan_model import Phase, Plan, Step
from planning.verify_between import (
    MAX_PARTS,
    MAX_PHASE_SAMPLES,
    MAX_PLAN_SAMPLES,
    Samples,
    failing_intervals,
    first_failure,
    parts_for,
    phase_world,
    travel_failures,
    travel_text,
    verification_world,
)
from planning.verify_climb import TIME_TOL
from rb_drake.feasibility import World
from rb_drake.params import RobotParams
from rb_drake.stance import Stance

DWELL_MOTION = 0.8  # of a trajectory phase's final dwell spent finishing its last motion
RESAMPLE = 0.05     # s: the grid of a two-step phase's minimum-jerk line (`rest_to_rest`)
# Grid points per interval at most: the minimum-jerk curve's shape does not depend on its
# duration, and 400 points resolve it (progress error under 1e-5); past 20 s (400 x RESAMPLE)
# the spacing grows instead, so that a plan's grids scale with its steps, not its duration
# (a plan of 1e7 s would otherwise ask 2e8 points per interval).
MAX_GRID = 400


def rest_to_rest(t0: float, t1: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grid on [t0, t1] (spacing <= step) with the minimum-jerk progress s (0 -> 1) and its
    rate ds/dt: 10 tau^3 - 15 tau^4 + 6 tau^5, which starts and ends at rest. At most
    MAX_GRID + 1 points: a long interval's spacing is (t1 - t0) / MAX_GRID."""
    n = min(max(1, math.ceil((t1 - t0) / step)), MAX_GRID)
    t = np.linspace(t0, t1, n + 1)
    tau = (t - t0) / (t1 - t0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2 / (t1 - t0)
    return t, s, ds


def ramp_count(steps: Sequence[Step], reverse: bool) -> int:
    """How many steps at the start (end) of a phase are ramp steps."""
    n = 0
    for step in (reversed(steps) if reverse else steps):
        if step.ramp is None:
            break
        n += 1
    return n


def finish_over_dwell(times: np.ndarray, poses: np.ndarray,
                      tips: np.ndarray | None) -> np.ndarray:
    """The step times of a phase whose last step repeats the one before it (the plan's
    dwell), with the motion into the last configuration ending DWELL_MOTION of the way into
    the dwell: the braking spread over more time, and the robot still rests a while in the
    last configuration, in that stance, as the plan has it."""
    same = np.allclose(poses[-1], poses[-2], rtol=0, atol=1e-12) and (
        tips is None or np.allclose(tips[-1], tips[-2], rtol=0, atol=1e-12))
    if not same:
        return times
    times = times.copy()
    times[-2] += DWELL_MOTION * (times[-1] - times[-2])
    return times


def shape_preserving(times: np.ndarray, values: np.ndarray, rest: bool) -> PiecewisePolynomial:
    """Shape-preserving cubic ("pchip") through values (K, n): continuous velocity, no
    overshoot; at rest at both ends when `rest`. Fewer than 3 points: linear."""
    if len(times) < 3:
        return PiecewisePolynomial.FirstOrderHold(times, values.T)
    return PiecewisePolynomial.CubicShapePreserving(times, values.T, rest)


def continuous_acceleration_rates(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Velocities (K, n) at the knots of values (K, n): zero where the body rests (a knot equal
    to its neighbour, as a dwell or a ramp has it, and at both ends), elsewhere the slopes of
    the cubic spline with continuous second derivatives through each run of knots between
    two rests, at rest at the run's ends. A shape-preserving ("pchip") estimate sets a slope
    to zero wherever a coordinate turns, so the acceleration jumps at that knot, and the
    controller's feed-forward with it: where a body phase turned from rotating to
    translating, a grasp at P 0.969 at both neighbouring steps fell to 0.952 between them
    (crevasse-s6), a loss p_path, a product over the steps, cannot see. Within a run the
    acceleration is continuous, and its peaks are about half pchip's on the calibration
    plans; the path stays within 5 mm and 0.3 deg of pchip's."""
    K = len(times)
    rates = np.zeros_like(values, dtype=float)
    still = np.all(np.abs(np.diff(values, axis=0)) <= 1e-12, axis=1)
    rest = np.zeros(K, dtype=bool)
    rest[[0, -1]] = True
    rest[1:] |= still
    rest[:-1] |= still
    ends = np.flatnonzero(rest)
    zero = np.zeros((values.shape[1], 1))
    for i, j in itertools.pairwise(ends):
        if j - i < 2:
            continue
        spline = PiecewisePolynomial.CubicWithContinuousSecondDerivatives(
            times[i:j + 1], values[i:j + 1].T, zero, zero).derivative(1)
        rates[i + 1:j] = spline.vector_values(times[i + 1:j]).T
    return rates


class SmoothPath(NamedTuple):
    """A phase's smooth path: knot times (K,), the body pose and (in a reach phase) the free
    gripper as trajectories with their derivatives, and the phase's step at the first knot."""

    knots: np.ndarray
    pose: PiecewisePolynomial
    velocity: PiecewisePolynomial
    tip: PiecewisePolynomial | None
    tip_rate: PiecewisePolynomial | None
    first_step: int = 0


def phase_path(times: np.ndarray, poses: np.ndarray, tips: np.ndarray | None) -> SmoothPath:
    """The smooth path through a phase's motion steps (`times` (K,), `poses` (K, 3), `tips`
    (K, 2) or None; K >= 3; the last step its dwell) alone, at rest at both ends: what
    `PlanTrajectory` builds for a phase whose ends are rests, as the planner's phases are
    (a dwell ends each, and the next starts where it ends)."""
    kn = phase_knots(np.asarray(times, dtype=float), np.asarray(poses, dtype=float),
                     None if tips is None else np.asarray(tips, dtype=float), 0, 0)
    pose = join_knots([kn])[3]
    return SmoothPath(kn.motion_times, pose, pose.derivative(1), kn.free_tip,
                      None if kn.free_tip is None else kn.free_tip.derivative(1))


class PhaseKnots(NamedTuple):
    """A phase's knots of the body's path (times, poses, velocities: NaN where the joined
    path estimates them), its motion between the ramps (steps lead to end - 1, at
    `motion_times`), whether that motion follows the smooth path (a phase of several steps)
    and the free gripper's path in a reach phase."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    lead: int
    end: int
    motion_times: np.ndarray
    smooth: bool
    free_tip: PiecewisePolynomial | None


def phase_knots(times: np.ndarray, poses: np.ndarray, tips: np.ndarray | None, lead: int,
                trail: int, resample: float | None = RESAMPLE) -> PhaseKnots:
    """The knots of a phase (step `times` (K,), `poses` (K, 3), free gripper `tips` (K, 2) or
    None, `lead` and `trail` ramp steps): ramps at rest; a motion of several steps on the
    smooth path (its velocities estimated once the phases are joined, `join_knots`; the last
    motion spread over the dwell); a motion of two steps along its straight line at
    minimum-jerk timing sampled every `resample` s; `resample=None`: first-order hold."""
    a, b = lead, len(times) - trail
    ts, qs, vs = [], [], []
    if lead:
        ts.append(times[:a])
        qs.append(poses[:a])
        vs.append(np.zeros((a, 3)))
    m_times, m_poses = times[a:b], poses[a:b]
    m_tips = None if tips is None else tips[a:b]
    if len(m_times) > 3 and resample is not None:
        m_times = finish_over_dwell(m_times, m_poses, m_tips)
    free_tip = None
    smooth = False
    if len(m_times) != 2 or resample is None:
        if m_tips is not None:
            free_tip = (PiecewisePolynomial.FirstOrderHold(m_times, m_tips.T)
                        if resample is None or len(m_times) < 3
                        else shape_preserving(m_times, m_tips, True))
        ts.append(m_times)
        qs.append(m_poses)
        vs.append(np.full_like(m_poses, np.nan))
        smooth = resample is not None and len(m_times) > 2
    else:
        t, prog, rate = rest_to_rest(m_times[0], m_times[1], resample)
        if m_tips is not None:
            delta = m_tips[1] - m_tips[0]
            free_tip = PiecewisePolynomial.CubicHermite(
                t, (m_tips[0] + prog[:, None] * delta).T, (rate[:, None] * delta).T)
        ts.append(t)
        qs.append(m_poses[0] + prog[:, None] * (m_poses[1] - m_poses[0]))
        vs.append(rate[:, None] * (m_poses[1] - m_poses[0]))
    if trail:
        ts.append(times[b:])
        qs.append(poses[b:])
        vs.append(np.zeros((trail, 3)))
    return PhaseKnots(np.concatenate(ts), np.vstack(qs), np.vstack(vs), a, b, m_times, smooth,
                      free_tip)


def join_knots(phases: Sequence[PhaseKnots], resample: float | None = RESAMPLE
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, PiecewisePolynomial]:
    """The phases' knots joined (a phase's first step shared with the last of the one before
    when at the same time; a velocity given by either wins) and the body's path through them:
    a cubic Hermite with the velocities not given estimated (`continuous_acceleration_rates`),
    or a first-order hold (`resample=None`, or fewer than 3 knots). Times, poses, velocities
    and the path."""
    ts: list[np.ndarray] = []
    qs: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    for kn in phases:
        t, q, v = kn.t, kn.q, kn.v.copy()
        # the shared boundary step: rule `phase-join` lets the times differ by TIME_TOL, and
        # `time-order` keeps other steps MIN_STEP_GAP apart, so the spline's knots increase
        if ts and abs(t[0] - ts[-1][-1]) <= TIME_TOL:
            last = vs[-1]
            last[-1] = np.where(np.isnan(last[-1]), v[0], last[-1])
            t, q, v = t[1:], q[1:], v[1:]
        ts.append(t)
        qs.append(q)
        vs.append(v)
    times, poses, rates = np.concatenate(ts), np.vstack(qs), np.vstack(vs)
    if resample is None or len(times) < 3:
        if len(times) == 1:
            return times, poses, rates, PiecewisePolynomial.FirstOrderHold(
                np.array([times[0], times[0] + 1.0]), np.vstack([poses, poses]).T)
        return times, poses, rates, PiecewisePolynomial.FirstOrderHold(times, poses.T)
    estimate = continuous_acceleration_rates(times, poses)
    for n in np.flatnonzero(np.isnan(rates).any(axis=1)):
        rates[n] = estimate[n]
    return times, poses, rates, PiecewisePolynomial.CubicHermite(times, poses.T, rates.T)


def plan_knots(plan: Plan, resample: float | None = RESAMPLE) -> list[PhaseKnots]:
    """`phase_knots` of every phase of a plan whose phases are well formed (times increase,
    a reach phase's steps have their free tip)."""
    out = []
    for phase in plan.phases:
        steps = phase.steps
        times = np.array([s.t for s in steps], dtype=float)
        poses = np.array([s.pose for s in steps], dtype=float)
        tips = (np.array([s.free_tip for s in steps], dtype=float)
                if None in tuple(phase.stance) else None)
        lead = ramp_count(steps, reverse=False)
        trail = min(ramp_count(steps, reverse=True), len(steps) - lead - 1)
        out.append(phase_knots(times, poses, tips, lead, trail, resample))
    return out


def plan_paths(plan: Plan) -> list[tuple[int, SmoothPath]]:
    """(phase, its smooth path over all its steps' knots) of every phase of several steps of
    a motion plan: the path `rbp simulate` follows between those steps
    (`systems.trajectory.PlanTrajectory` builds its body's path with the same `plan_knots`
    and `join_knots`)."""
    knots = plan_knots(plan)
    if not knots:
        return []
    pose = join_knots(knots)[3]
    velocity = pose.derivative(1)
    # every knot of the phase, its ramps' too: the spline's interval from the last attach
    # ramp step to the first motion step (and from the dwell to the release ramp) moves
    # unless the two poses are equal to 1e-12 (`continuous_acceleration_rates`), which rule
    # `attach` does not require (1e-9); a smooth phase has one knot per step
    return [(k, SmoothPath(kn.t, pose, velocity, kn.free_tip,
                           None if kn.free_tip is None else kn.free_tip.derivative(1), 0))
            for k, kn in enumerate(knots) if kn.smooth]


def _largest_rate(q0: np.ndarray, q1: np.ndarray, r0: np.ndarray, r1: np.ndarray,
                  T: np.ndarray) -> np.ndarray:
    """Per interval and coordinate, the largest |dq/ds| on s in [0, 1] of the cubic Hermite
    from q0 (rate r0, per second) to q1 (rate r1) over an interval of length T: dq/ds is
    6 s (1 - s) D + (1 - 4 s + 3 s^2) T r0 + (3 s^2 - 2 s) T r1 with D = q1 - q0, a quadratic
    a s^2 + b s + c; its extremes lie at s = 0, 1 or its vertex."""
    D, m0, m1 = q1 - q0, T * r0, T * r1
    a = -6.0 * D + 3.0 * m0 + 3.0 * m1
    b = 6.0 * D - 4.0 * m0 - 2.0 * m1
    c = m0
    with np.errstate(all="ignore"):
        vertex = np.where(np.abs(a) > 1e-300, -b / (2.0 * a), 0.0)
    vertex = np.clip(np.nan_to_num(vertex), 0.0, 1.0)
    at_vertex = (a * vertex + b) * vertex + c
    return np.maximum.reduce([np.abs(c), np.abs(a + b + c), np.abs(at_vertex)])


def spline_parts(robot: RobotParams, path: SmoothPath) -> np.ndarray:
    """Per interval of the path's knots, how many equal parts in time it is cut into so that
    successive samples lie within the resolution, as `subdivisions` does for the straight
    line: a boom's length changes at most by its shoulder's travel plus its gripper's."""
    knots = path.knots
    T = np.diff(knots)[:, None]
    q, v = path.pose.vector_values(knots).T, path.velocity.vector_values(knots).T
    body = _largest_rate(q[:-1], q[1:], v[:-1], v[1:], T)
    move = np.hypot(body[:, 0], body[:, 1])
    tip = np.zeros_like(move)
    if path.tip is not None and path.tip_rate is not None:
        g, w = path.tip.vector_values(knots).T, path.tip_rate.vector_values(knots).T
        gripper = _largest_rate(g[:-1], g[1:], w[:-1], w[1:], T)
        tip = np.hypot(gripper[:, 0], gripper[:, 1])
    return parts_for(robot, move, body[:, 2], tip)


def path_samples(robot: RobotParams, path: SmoothPath) -> tuple[Samples, int]:
    """The path's samples strictly inside its knots' intervals, each cut into `spline_parts`
    (intervals numbered by the phase's steps, from `path.first_step`), and how many intervals
    are too long to sample (over MAX_PARTS parts: left out; all of them when the phase needs
    over MAX_PHASE_SAMPLES samples)."""
    knots = path.knots
    parts = spline_parts(robot, path)
    too_long = int(np.count_nonzero(parts > MAX_PARTS))
    parts = np.where(parts > MAX_PARTS, 1, parts)
    if np.sum(parts - 1) > MAX_PHASE_SAMPLES:  # a hostile file: every interval left out
        empty = np.zeros(0)
        return Samples(empty, np.zeros((0, 3)), None if path.tip is None else np.zeros((0, 2)),
                       np.zeros(0, dtype=int), empty), len(parts)
    interval = np.repeat(np.arange(len(parts)), parts - 1)
    first = np.concatenate([[0], np.cumsum(parts - 1)])[interval]
    fraction = (np.arange(len(interval)) - first + 1) / parts[interval]
    t = knots[interval] + fraction * (knots[interval + 1] - knots[interval])
    poses = path.pose.vector_values(t).T if len(t) else np.zeros((0, 3))
    tips = None
    if path.tip is not None:
        tips = path.tip.vector_values(t).T if len(t) else np.zeros((0, 2))
    return Samples(t, poses, tips, interval + path.first_step, fraction), too_long


def smooth_problem(world: World, stance: Stance, poses: np.ndarray,
                   tips: np.ndarray | None = None, times: np.ndarray | None = None,
                   dwell: bool = True) -> str:
    """Why the smooth path through a phase's motion steps fails rule `between`'s test ('' when
    it does not): `poses` (N, 3) and `tips` at `times` (default one per unit of time, the
    path's shape does not depend on the time's scale), with the final dwell added when
    `dwell` (the planner's steps before the plan is built)."""
    poses = np.asarray(poses, dtype=float)
    if len(poses) < 2:
        return ""
    times = np.arange(len(poses), dtype=float) if times is None else np.asarray(times, float)
    if dwell:
        poses = np.vstack([poses, poses[-1:]])
        times = np.append(times, times[-1] + (times[-1] - times[-2]))
        if tips is not None:
            tips = np.vstack([tips, tips[-1:]])
    if len(poses) < 3:
        return ""
    s, too_long = path_samples(world.robot, phase_path(times, poses, tips))
    if too_long:
        return "between steps: an interval of the smooth path too long to sample"
    return first_failure(verification_world(world), stance, s, "smooth path")


def smooth_path_problems(plan: Plan, world: World, stance_of, fail) -> int:
    """Rule `between` on the smooth path of every phase of several steps of a motion plan
    whose phases are well formed: `fail(phase, n, text)` once per failing interval (n: its
    first step), `stance_of(k)` the stance of phase k. Returns the configurations checked."""
    checked = 0
    vworld = verification_world(world)
    for k, path in plan_paths(plan):
        s, too_long = path_samples(world.robot, path)
        if checked + len(s.t) > MAX_PLAN_SAMPLES:
            fail(k, path.first_step, f"rbp simulate's smooth path is too long to verify: with "
                 f"this phase it needs over {MAX_PLAN_SAMPLES} samples at the resolution "
                 "(phases after it are not verified on it)")
            break
        if too_long:
            fail(k, path.first_step, f"{too_long} interval(s) of rbp simulate's smooth path too "
                 f"long to verify (over {MAX_PARTS} samples an interval, or "
                 f"{MAX_PHASE_SAMPLES} a phase, at the resolution)")
        checked += len(s.t)
        found = failing_intervals(vworld, stance_of(k), plan.phases[k], s,
                                  " on rbp simulate's smooth path")
        if not too_long:  # a phase with intervals left unsampled is refused above
            bad = {n for n, _ in found}
            found += path_travel(vworld, stance_of(k), plan.phases[k], path, s, bad)
        for n, text in found:
            fail(k, n, text)
    return checked


def path_travel(world: World, stance: Stance, phase: Phase, path: SmoothPath, s: Samples,
                skip: set[int]) -> list[tuple[int, str]]:
    """`verify_between.travel_failures` on the smooth path: its knots and samples in time
    order, intervals in `skip` (already failing) left out."""
    knots = path.knots
    t = np.concatenate([knots, s.t])
    order = np.argsort(t, kind="stable")
    t = t[order]
    q = path.pose.vector_values(t).T
    g = None if path.tip is None else path.tip.vector_values(t).T
    pair = np.clip(np.searchsorted(knots, t[:-1], side="right") - 1, 0, len(knots) - 2)
    pair[np.isin(pair + path.first_step, list(skip))] = -1  # failing already: not tested again
    out = []
    for j, n, boom in travel_failures(phase_world(world, phase), stance, q, g, pair):
        if n + path.first_step in skip:
            continue
        w = (t[j] - knots[n]) / (knots[n + 1] - knots[n])
        out.append((n + path.first_step, travel_text(n + path.first_step, float(t[j]), q[j], w,
                                                     boom, " on rbp simulate's smooth path")))
    return out
