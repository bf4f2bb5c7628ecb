"""The plan as trajectories: a plan file's phases as trajectories of body pose, feed-forward
tensions and free tip (`PlanTrajectory`, which says how phases become trajectories). Its
holdings and one trial's drawn strengths laid out per phase (`StrengthDraws`) are in
`systems.holdings`, and `PlanSource`, the leaf system that outputs the plan at the current
time, in `systems.plan_source`. A plan file the simulation cannot run raises `PlanError`.
"""

from __future__ import annotations

import functools
import itertools
import math
from typing import Any, NamedTuple

import numpy as np
from pydrake.trajectories import PiecewisePolynomial

from planning.plan_file import content_hash
from planning.plan_model import Phase, Plan, Step, plan_of
from planning.plan_model import plan_scenario as plan_scenario  # re-exported
from planning.smooth_motion import DWELL_MOTION as DWELL_MOTION  # re-exported
from planning.smooth_motion import (
    PhaseKnots,
    join_knots,
    phase_knots,
    ramp_count,
)
from planning.smooth_motion import rest_to_rest as rest_to_rest  # re-exported
from planning.verify_between import smooth_departure, step_motion
from planning.verify_climb import MIN_STEP_GAP, TIME_TOL
from rb_drake.errors import RbpInputError
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import allocate
from systems.holdings import holdings_of

# PlanSource's free_limb output: the limb a shoulder carries (`PlanTrajectory.carried_limb`):
# the planned free tip (x, y), its velocity, the boom's mass in the plant, the boom (-1: none)
# and the share of the limb its shoulder carries (1 for a free boom, less in a ramp)
FREE_LIMB_FIELDS = ("tip_x", "tip_y", "tip_vx", "tip_vy", "boom_mass", "boom", "share")
FREE_LIMB_SIZE = len(FREE_LIMB_FIELDS)


class PlanError(RbpInputError):
    """A plan file the simulation cannot run: `field` (a path in the plan) and `reason`."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


Refine = tuple[int, np.ndarray, np.ndarray]


def _ramp_boom(step: Step) -> int:
    """The boom of a ramp step."""
    if step.ramp is None:
        raise ValueError("a ramp's step without its ramp record")
    return int(step.ramp.boom)


# The most a smooth path may stray from the verified straight motion, in units of rule
# `between`'s resolution (`verify_between.smooth_departure`): every configuration `rbp
# simulate` commands then lies within 2.5 resolutions of a configuration `rbp check` verified.
# The planner's plans of the 100 benchmark caves stray up to 1.27 (docs/formats.md).
DEPARTURE_LIMIT = 2.0


class PhaseTrajectory(NamedTuple):
    kind: str
    start: float
    end: float
    stance: Stance
    tension: PiecewisePolynomial       # (4,) feed-forward, 0 for the free boom
    free_tip: PiecewisePolynomial | None  # (2,) in a reach phase
    free_tip_rate: PiecewisePolynomial | None = None  # its derivative
    # (4,) the share of each boom's limb its shoulder carries: 1 for the free boom, between 0
    # and 1 for a boom in a release or attach ramp (planning.ramps), else 0
    share: PiecewisePolynomial | None = None
    ramps: tuple[tuple[float, float, int], ...] = ()  # (t0, t1, boom) of each ramp in the phase
    # the tensions' grid and values, and what _refine_tensions needs (its first row, the step
    # times and tensions; None: nothing to refine)
    grid: tuple[np.ndarray, np.ndarray, Refine | None] | None = None


def _rate(trajectory: PiecewisePolynomial | None) -> PiecewisePolynomial | None:
    return None if trajectory is None else trajectory.derivative(1)


def _hold(times: np.ndarray, values: np.ndarray) -> PiecewisePolynomial:
    """Linear interpolation of values (K, n) at times (K,); one step holds its value: the
    motion between steps that `rbp check` verifies and `rbp rig-run` executes."""
    return step_motion(times, values)


def _ramp_grid(times: np.ndarray, tensions: np.ndarray, shares: np.ndarray,
               resample: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ramp's tensions and shares between its steps, each interval at minimum-jerk timing
    (the load changes smoothly, at rest at every step): every point lies on the segment
    between two steps, where statics hold exactly and no grasp's P falls below the ends'."""
    if resample is None:
        return times, tensions, shares
    t_out, f_out, s_out = [times[:1]], [tensions[:1]], [shares[:1]]
    for n in range(len(times) - 1):
        t, prog, _ = rest_to_rest(times[n], times[n + 1], resample)
        t_out.append(t[1:])
        f_out.append(tensions[n] + prog[1:, None] * (tensions[n + 1] - tensions[n]))
        s_out.append(shares[n] + prog[1:, None] * (shares[n + 1] - shares[n]))
    return np.concatenate(t_out), np.vstack(f_out), np.vstack(s_out)


def check_phase_form(k: int, phase: Phase) -> None:
    """Refuse (PlanError naming the step) phase k if it cannot become a trajectory: steps less
    than rule time-order's MIN_STEP_GAP apart (the splines need increasing knots: 1e-30 s apart
    raised Drake's RuntimeError) or ramp steps only (rule attach: a ramp ends on a step
    without a ramp). The verifier refuses both; this guards --no-verify and the API."""
    where = f"phases[{k}]"
    times = np.array([s.t for s in phase.steps], dtype=float)
    close = np.flatnonzero(~(np.diff(times) >= MIN_STEP_GAP - TIME_TOL))
    if close.size:  # name the first step out of order, never all times
        n = int(close[0]) + 1
        raise PlanError(f"{where}.steps[{n}].t", f"times must increase from step to step by "
                        f"at least {MIN_STEP_GAP:g} s (got {float(times[n]):g} after "
                        f"{float(times[n - 1]):g})")
    if ramp_count(phase.steps, reverse=False) >= len(phase.steps):
        raise PlanError(f"{where}.steps", f"{len(phase.steps)} ramp step(s) only: a ramp ends "
                        "on a step without a ramp in its phase")


def check_flyable(plan: Plan | dict[str, Any]) -> None:
    """`check_phase_form` for every phase (rbp simulate/rig-run --no-verify, before the run)."""
    for k, phase in enumerate(plan_of(plan).phases):
        check_phase_form(k, phase)


class PlanTrajectory:
    """A plan file's phases as trajectories of pose, feed-forward tensions and free tip.

    Phase k runs over [start_k, start_{k+1}). The body pose passes through every step of the
    plan, but with a continuous velocity, unlike a first-order hold: one cubic Hermite spline
    through all steps, its velocities, where the plan gives none, the slopes of the spline
    with continuous acceleration through the steps
    (`smooth_motion.continuous_acceleration_rates`, at rest at the
    start and the end). A velocity step (at every step of a linear interpolation, and at phase
    boundaries of plans whose phases do not end at rest) is answered by the PD with a jolt of
    the tensions that collapses grasp probabilities for nothing; the spline's acceleration
    feeds the controller forward. A phase of several steps (a full trajectory)
    gets the plan's own tensions and free tip between its steps, tensions interpolated
    linearly. Such a phase ends with a dwell (its last step repeats the one before), and the
    motion into the last configuration is spread over the last interval and most of the dwell
    (`smooth_motion.finish_over_dwell`): stopping within the last interval, as the plan's
    knots have it, brakes the body and the free tip at ~0.4 m/s^2, whose inertial loads (in a
    3-stance a newton or more on one boom) cost the crevasse plans up to 0.1 in a holding's P.
    A phase of exactly two steps, as the footstep stage writes today (its two end
    configurations), is travelled along the straight line between them with a minimum-jerk
    timing (`rest_to_rest`, sampled every `resample` s), and its feed-forward tensions are
    the plan's own model on that line, the most robust allocation (`statics.allocate`, which
    made the plan's tensions and reproduces them at the two ends): linear interpolation of
    the two end allocations is out of equilibrium in between (by ~1 N and 0.1 N m on the
    bundled plans, where the moment direction is weak). Where no tensions hold a
    configuration of that line, the feed-forward is interpolated linearly and the simulation
    shows what follows. Such a phase's body moves along the line at the minimum-jerk rates,
    so it starts and ends at rest. `resample=None` interpolates everything linearly between
    the steps (first-order hold).
    """

    def __init__(self, plan: Plan | dict[str, Any], scn: Scenario,
                 resample: float | None = 0.05):
        self.plan = plan_of(plan)  # the replanners continue it (systems.replanning)
        self.scenario = scn
        self.phases: list[PhaseTrajectory] = []
        knots: list[PhaseKnots] = []
        previous_end = None
        for k, phase in enumerate(self.plan.phases):
            traj, kn = self._phase(k, phase, scn, previous_end, resample)
            self.phases.append(traj)
            knots.append(kn)
            previous_end = traj.end
        if not self.phases:
            raise PlanError("phases", "the plan has no phases")
        times, poses, rates, self.pose = join_knots(knots, resample)
        # every knot of the phase, its ramps' too, as the verifier samples it (`plan_paths`)
        smooth = [(k, kn.t, 0) for k, kn in enumerate(knots) if kn.smooth]
        # how far the smooth path strays from the verified straight motion (resolutions)
        self.departure, self.departure_phase = self._departure(times, poses, rates, smooth)
        if resample is not None:
            self.phases = [self._refine_tensions(p) for p in self.phases]
        self.velocity = self.pose.derivative(1)
        self.acceleration = self.velocity.derivative(1)
        self.starts = np.array([p.start for p in self.phases])
        self.holdings = holdings_of([p.stance.ids for p in self.phases])
        # holding_of[k, i]: the holding of boom i during phase k (-1: free)
        self.holding_of = np.full((len(self.phases), NUM_BOOMS), -1, dtype=int)
        for h, hold in enumerate(self.holdings):
            self.holding_of[hold.first:hold.last + 1, hold.boom] = h

    def _departure(self, times: np.ndarray, poses: np.ndarray, rates: np.ndarray,
                   smooth: list[tuple[int, np.ndarray, int]]) -> tuple[float, int | None]:
        """How far the smooth path of the phases of several steps can be from the straight
        motion `rbp check` verifies, in resolutions (`verify_between.smooth_departure`, a
        bound), at most, and in which phase (None: no such phase)."""
        worst, where = 0.0, None
        for k, knots, _ in smooth:
            idx = np.searchsorted(times, knots)
            tip, tip_rate = self.phases[k].free_tip, self.phases[k].free_tip_rate
            d = float(smooth_departure(
                knots, poses[idx], rates[idx],
                None if tip is None else tip.vector_values(knots).T,
                None if tip_rate is None else tip_rate.vector_values(knots).T).max())
            if d > worst or where is None:
                worst, where = d, k
        return worst, where

    def departure_problem(self) -> str | None:
        """A verifier's line when the smooth path strays further than DEPARTURE_LIMIT from
        the verified straight motion (steps too far apart for their motion), else None."""
        if self.departure <= DEPARTURE_LIMIT or self.departure_phase is None:
            return None
        k = self.departure_phase
        return (f"phases[{k}] ({self.phases[k].kind}): between: rbp simulate's smooth path "
                f"through the steps strays up to {self.departure:.2f} resolutions from the "
                f"verified straight motion (at most {DEPARTURE_LIMIT:g}): the steps are too far "
                f"apart for their motion")

    @functools.cached_property
    def content_key(self) -> str:
        """The plan's content hash (`plan_file.content_hash`): equal for equal plans, for
        caches that outlive a trajectory (`systems.montecarlo`'s replans)."""
        return content_hash(self.plan.to_dict())

    @staticmethod
    def _phase(k: int, phase: Phase, scn: Scenario, previous_end: float | None,
               resample: float | None
               ) -> tuple[PhaseTrajectory, PhaseKnots]:
        """The phase and the knots of its body's path (`smooth_motion.phase_knots`)."""
        where = f"phases[{k}]"
        ids = tuple(phase.stance)
        unknown = [a for a in ids if a is not None and a not in scn.anchor_index]
        if unknown:
            raise PlanError(f"{where}.stance", f"unknown anchor {unknown[0]!r}")
        stance = scn.stance(ids)
        steps = phase.steps
        times = np.array([s.t for s in steps], dtype=float)
        check_phase_form(k, phase)
        if previous_end is not None and abs(times[0] - previous_end) > 1e-6:
            raise PlanError(f"{where}.steps[0].t",
                            f"starts at {times[0]} but the phase before ends at {previous_end}")
        tensions = np.zeros((len(steps), NUM_BOOMS))
        shares = np.zeros((len(steps), NUM_BOOMS))
        for n, s in enumerate(steps):
            for i in range(NUM_BOOMS):
                if stance.attached[i]:
                    if s.tension[i] is None:
                        raise PlanError(f"{where}.steps[{n}].tension[{i}]",
                                        "an attached boom needs a tension")
                    tensions[n, i] = s.tension[i]
            ramp = s.ramp
            if ramp is not None:
                j = int(ramp.boom)
                if not stance.attached[j]:
                    raise PlanError(f"{where}.steps[{n}].ramp",
                                    f"a ramp of boom {j}, which is free here")
                shares[n, j] = float(ramp.share)
        poses = np.array([s.pose for s in steps], dtype=float)
        tips = None
        if stance.free_boom is not None:
            if any(s.free_tip is None for s in steps):
                raise PlanError(f"{where}.steps", "a phase with a free boom needs free_tip")
            tips = np.array([s.free_tip for s in steps], dtype=float)
            shares[:, stance.free_boom] = 1.0
        start, end = float(times[0]), float(times[-1])
        # the ramps at either end (planning.ramps), the motion between them
        lead = ramp_count(steps, reverse=False)
        trail = min(ramp_count(steps, reverse=True), len(steps) - lead - 1)
        kn = phase_knots(times, poses, tips, lead, trail, resample)
        a, b = kn.lead, kn.end
        sections_t, sections_f, sections_s = [], [], []
        if lead:
            t, f, sh = _ramp_grid(times[:a + 1], tensions[:a + 1], shares[:a + 1], resample)
            sections_t.append(t[:-1])
            sections_f.append(f[:-1])
            sections_s.append(sh[:-1])
        m_times, m_poses = kn.motion_times, poses[a:b]
        m_tips = None if tips is None else tips[a:b]
        free_tip = kn.free_tip
        refine = None
        if len(m_times) != 2 or resample is None:
            if resample is None or len(m_times) < 2:
                sections_t.append(m_times)
                sections_f.append(tensions[a:b])
                sections_s.append(shares[a:b])
            else:  # a dense grid, its tensions made once the body's spline exists (refine)
                dense = np.concatenate([m_times[:1]] + [
                    rest_to_rest(t0, t1, resample)[0][1:]
                    for t0, t1 in itertools.pairwise(m_times)])
                start_row = sum(len(x) for x in sections_t)
                sections_t.append(dense)
                sections_f.append(_hold(m_times, tensions[a:b]).vector_values(dense).T)
                sections_s.append(np.repeat(shares[a:a + 1], len(dense), axis=0))
                refine = (start_row, m_times, tensions[a:b])
        else:
            t, prog, _ = rest_to_rest(m_times[0], m_times[1], resample)
            line = m_poses[0] + prog[:, None] * (m_poses[1] - m_poses[0])
            ff = tensions[a] + prog[:, None] * (tensions[a + 1] - tensions[a])
            inner = slice(1, len(t) - 1)
            grid_tips = (None if m_tips is None
                         else m_tips[0] + prog[inner, None] * (m_tips[1] - m_tips[0]))
            alloc = allocate(scn.robot, scn.gravity_vector, line[inner], stance, grid_tips)
            ok = np.flatnonzero(alloc.statics_ok)
            ff[1 + ok] = np.where(stance.attached, np.nan_to_num(alloc.tensions[ok]), 0.0)
            sections_t.append(t)
            sections_f.append(ff)
            sections_s.append(np.repeat(shares[a:a + 1], len(t), axis=0))
        if trail:
            t, f, sh = _ramp_grid(times[b - 1:], tensions[b - 1:], shares[b - 1:], resample)
            sections_t.append(t[1:])
            sections_f.append(f[1:])
            sections_s.append(sh[1:])
        grid = np.concatenate(sections_t)
        ramps = []
        if lead:
            ramps.append((float(times[0]), float(times[a]), _ramp_boom(steps[0])))
        if trail:
            ramps.append((float(times[b - 1]), end, _ramp_boom(steps[-1])))
        traj = PhaseTrajectory(phase.kind, start, end, stance,
                               _hold(grid, np.vstack(sections_f)), free_tip, _rate(free_tip),
                               _hold(grid, np.vstack(sections_s)), tuple(ramps),
                               (grid, np.vstack(sections_f), refine))
        return traj, kn

    def _refine_tensions(self, phase: PhaseTrajectory) -> PhaseTrajectory:
        """A trajectory phase's feed-forward between its steps: the most robust allocation at
        the body's spline (and the free tip) there, plus the plan's own departure from that
        allocation interpolated linearly between the steps, so the plan's tensions are met at
        every step. Linear interpolation of the steps' tensions alone is out of equilibrium
        between them, and the controller's correction nearest it can load one grasp well past
        both ends where a step turns the body (by 0.7 N and 0.007 in P on a shaft plan)."""
        if phase.grid is None:
            return phase
        grid, values, refine = phase.grid
        if refine is None:
            return phase
        row, times, tensions = refine
        n = len(np.flatnonzero((grid >= times[0] - 1e-12) & (grid <= times[-1] + 1e-12)))
        t = grid[row:row + n]
        poses = self.pose.vector_values(t).T
        tips = None if phase.free_tip is None else phase.free_tip.vector_values(t).T
        scn = self.scenario
        alloc = allocate(scn.robot, scn.gravity_vector, poses, phase.stance, tips)
        f = np.where(phase.stance.attached, np.nan_to_num(alloc.tensions), 0.0)
        at_steps = np.searchsorted(t, times - 1e-9)
        ok = alloc.statics_ok[at_steps].all() and alloc.statics_ok.all()
        if not ok:  # keep the linear interpolation where the allocation fails
            return phase
        offset = tensions - f[at_steps]
        f = f + _hold(times, offset).vector_values(t).T
        values = values.copy()
        values[row:row + n] = np.where(phase.stance.attached, f, 0.0)
        return phase._replace(tension=_hold(grid, values))

    @property
    def end_time(self) -> float:
        return self.phases[-1].end

    def carried_limb(self, t: float) -> np.ndarray:
        """The limb a shoulder carries at time t, FREE_LIMB_FIELDS: the free boom's (its planned
        tip and rate) or, in a release or attach ramp, the ramped boom's (its gripper on its
        anchor, at rest); `boom_mass` is boom_linear_density times its planned length (shoulder
        on the planned pose to the tip) times the share its shoulder carries. Zeros and boom -1
        when no shoulder carries a limb."""
        phase = self.phase_at(t)
        out = np.zeros(FREE_LIMB_SIZE)
        out[5] = -1.0
        share = phase.share.value(t).ravel() if phase.share is not None else np.zeros(4)
        j = free_boom(phase.stance)
        if j is not None:
            if phase.free_tip is None or phase.free_tip_rate is None:
                raise ValueError("a reach phase's trajectory without its free tip")
            tip = phase.free_tip.value(t).ravel()
            out[2:4] = phase.free_tip_rate.value(t).ravel()
            s = 1.0
        else:
            j = int(np.argmax(share))
            s = float(share[j])
            if s <= 0.0:
                return out
            tip = phase.stance.positions[j]
        robot = self.scenario.robot
        x, y, phi = (float(v) for v in self.pose.value(t).ravel())
        sx, sy = robot.shoulders[j]
        tx, ty = float(tip[0]), float(tip[1])
        c, si = math.cos(phi), math.sin(phi)
        length = math.hypot(tx - x - c * sx + si * sy, ty - y - si * sx - c * sy)
        out[0:2] = tx, ty
        out[4] = s * robot.boom_linear_density * length
        out[5], out[6] = j, s
        return out

    def free_boom_mass(self, t: float) -> float:
        """The carried limb's boom mass at time t (`carried_limb`; 0 when none)."""
        return float(self.carried_limb(t)[4])

    def phase_index(self, t: float) -> int:
        return max(0, int(np.searchsorted(self.starts, t, side="right")) - 1)

    def phase_at(self, t: float) -> PhaseTrajectory:
        return self.phases[self.phase_index(t)]

    @property
    def regrasps(self) -> int:
        return sum(h.attach for h in self.holdings)


def free_boom(stance: Stance) -> int | None:
    """`stance.free_boom` from the ids, for the per-step systems (the property costs 10 us)."""
    return stance.ids.index(None) if None in stance.ids else None
