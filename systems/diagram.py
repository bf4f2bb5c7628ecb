"""A plan file executed as a Drake diagram: plan source, tension controller, the robot's
plant, grasp monitor, stochastic grasp failures and loggers, run by a `Simulator`.

    PlanSource ──desired state, feed-forward tensions, free limb, stance──┐
        │                                                                 ▼
        │         body state (x, y, phi, rates) ─────────────────▶ TensionController
        │                  ▲                   tip push ◀── LimbController │ tensions
        ▼                  │                                 │ free joints ▼
    AnchorLoadMonitor ◀── MultibodyPlant ◀── generalized force = -T on each prismatic joint
        │ probability      (reaction forces, state)            + the free limb's joints
        ▼
    GraspFailures (drawn strengths: latches the first failure)          loggers

The plant (`plant="full"`, the default) is rb_drake's whole robot (`build_plant` with
`hold_tips`): the body on its planar joint, per boom a passive revolute shoulder, a prismatic
boom and a tip carrying the gripper, discrete (PLANT_TIME_STEP) with the SAP solver. Every
attached tip is held at its anchor by a ball constraint, switched per phase; an attached boom's
tension T is its prismatic joint's force -T, so the constraint turns it into the boom's pull
on the body at the shoulder. The free boom of a reach phase follows the planned tip
(`LimbController`); its mass (boom_linear_density times its planned length, half at the tip
and half at the shoulder: the weight and moments of the model's uniform boom) is updated every
BOOM_MASS_PERIOD, and anchored booms are massless as in the model (the plant keeps its 10 g arm
links and the grippers, whose weight the anchors carry). The monitor (`AnchorLoadMonitor`)
reads each anchored boom's pull on its gripper from the plant's joint reaction forces.

`plant="body"` is the body alone on a planar joint (continuous): `BoomForces` applies each
attached boom's tension along its unit vector (as the generalized force of the planar joint)
and, in a reach phase, the free limb's weight (`geometry.limb_load`), as the statics do;
`GraspMonitor` takes the tension along shoulder -> anchor. The two agree where the plan moves
slowly; the full plant adds the free limb's inertia (0.2 kg at 1.5 m: ten times the body's
moment of inertia about its shoulder), which the quasi-static plan does not see.

The controller turns the plan's tensions and poses into boom commands: the wrench the body
needs (statics load at the actual pose plus a PD on the pose error, scaled by the body's mass
and inertia, plus the free limb's push) is made by the tensions nearest the plan's
feed-forward, within the tension bounds, trading a small acceleration error for large tension
changes where the bounds bind (`TensionProjector`). It is a feedthrough system, evaluated once
per plant step (the discrete plant samples its input), and the stance switches at the phase
boundaries, where `ClimbSimulator.run` switches the holds between `AdvanceTo` calls.
`GraspFailures` compares the monitor's P_i with one drawn strength quantile per holding and an
attach draw per regrasp (module `montecarlo` explains the convention) and latches the first
failure, which stops the simulation. How plan phases become trajectories is in
`PlanTrajectory`.

Python `LeafSystem`s are never freed in pydrake 1.51 (STACK.md section 5), so `ClimbSimulator`
builds its diagram once per scenario; the plan and the draws are abstract parameters of the
context, set before each run, so one diagram serves every plan (including replans) on a cave.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PlanarJoint, SpatialInertia
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import (
    BasicVector,
    Context,
    DiagramBuilder,
    EventStatus,
    LeafSystem,
    ValueProducer,
)
from pydrake.systems.primitives import Adder, LogVectorOutput, MatrixGain
from pydrake.trajectories import PiecewisePolynomial

from rb_drake import geometry, grasp
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.plant import ARM_MASS, BODY_THICKNESS, ReachBotPlant, build_plant
from rb_drake.scenario import Scenario, scenario_from_dict
from rb_drake.stance import Stance
from rb_drake.statics import allocate

SAMPLE_PERIOD = 0.02  # s: loggers and the failure check run at this period, on the same grid
PLANT_TIME_STEP = 1e-2  # s, the full (discrete) plant's period
BOOM_MASS_PERIOD = 0.1  # s, how often the free boom's mass follows its length (full plant)
DWELL_MOTION = 0.8  # of a trajectory phase's final dwell spent finishing its last motion


class PlanError(ValueError):
    """A plan file the simulation cannot run: `field` (a path in the plan) and `reason`."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


def plan_scenario(plan: dict[str, Any], source: str = "<plan>") -> Scenario:
    """The scenario a plan was made for, rebuilt from the plan file (its robot included)."""
    data = dict(plan["scenario"])
    data["robot"] = plan["robot"]
    return scenario_from_dict(data, source, check_start=False)


# ---------------------------------------------------------------------------------------------
# The plan as trajectories


class Holding(NamedTuple):
    """Boom `boom` on `anchor` during phases first..last; `attach` when it starts by a regrasp."""

    boom: int
    anchor: str
    first: int
    last: int
    attach: bool


class PhaseTrajectory(NamedTuple):
    kind: str
    start: float
    end: float
    stance: Stance
    tension: PiecewisePolynomial       # (4,) feed-forward, 0 for the free boom
    free_tip: PiecewisePolynomial | None  # (2,) in a reach phase
    free_tip_rate: PiecewisePolynomial | None = None  # its derivative


def _finish_over_dwell(times: np.ndarray, poses: np.ndarray,
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


def _rate(trajectory: PiecewisePolynomial | None) -> PiecewisePolynomial | None:
    return None if trajectory is None else trajectory.derivative(1)


def _hold(times: np.ndarray, values: np.ndarray) -> PiecewisePolynomial:
    """Linear interpolation of values (K, n) at times (K,); one step holds its value."""
    if len(times) == 1:
        times = np.array([times[0], times[0] + 1.0])
        values = np.vstack([values, values])
    return PiecewisePolynomial.FirstOrderHold(times, values.T)


def _smooth(times: np.ndarray, values: np.ndarray, rest: bool) -> PiecewisePolynomial:
    """Shape-preserving cubic ("pchip") through values (K, n): continuous velocity, no
    overshoot; at rest at both ends when `rest`. Fewer than 3 points: linear."""
    if len(times) < 3:
        return _hold(times, values)
    return PiecewisePolynomial.CubicShapePreserving(times, values.T, rest)


def rest_to_rest(t0: float, t1: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grid on [t0, t1] (spacing <= step) with the minimum-jerk progress s (0 -> 1) and its
    rate ds/dt: 10 tau^3 - 15 tau^4 + 6 tau^5, which starts and ends at rest."""
    n = max(1, math.ceil((t1 - t0) / step))
    t = np.linspace(t0, t1, n + 1)
    tau = (t - t0) / (t1 - t0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2 / (t1 - t0)
    return t, s, ds


class PlanTrajectory:
    """A plan file's phases as trajectories of pose, feed-forward tensions and free tip.

    Phase k runs over [start_k, start_{k+1}). The body pose passes through every step of the
    plan, but with a continuous velocity, unlike a first-order hold: one cubic Hermite spline
    through all steps, its velocities shape-preserving estimates ("pchip",
    `PiecewisePolynomial.CubicShapePreserving`, at rest at the start and the end) where the
    plan gives none. A velocity step (at every step of a linear interpolation, and at phase
    boundaries of plans whose phases do not end at rest) is answered by the PD with a jolt of
    the tensions that collapses grasp probabilities for nothing; the spline's acceleration
    feeds the controller forward. A phase of several steps (a full trajectory)
    gets the plan's own tensions and free tip between its steps, tensions interpolated
    linearly. Such a phase ends with a dwell (its last step repeats the one before), and the
    motion into the last configuration is spread over the last interval and most of the dwell
    (`_finish_over_dwell`): stopping within the last interval, as the plan's knots have it,
    brakes the body and the free tip at ~0.4 m/s^2, whose inertial loads (in a 3-stance a
    newton or more on one boom) cost the crevasse plans up to 0.1 in a holding's P. A phase
    of exactly two steps, as the footstep stage writes today (its two end configurations), is
    travelled along the straight line between them with a minimum-jerk
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

    def __init__(self, plan: dict[str, Any], scn: Scenario, resample: float | None = 0.05):
        self.plan = plan
        self.scenario = scn
        self.phases: list[PhaseTrajectory] = []
        knots_t: list[np.ndarray] = []
        knots_q: list[np.ndarray] = []
        knots_v: list[np.ndarray] = []  # NaN: to be estimated (shape-preserving)
        previous_end = None
        for k, phase in enumerate(plan["phases"]):
            traj, t, q, v = self._phase(k, phase, scn, previous_end, resample)
            self.phases.append(traj)
            if knots_t and abs(t[0] - knots_t[-1][-1]) < 1e-9:  # the shared boundary step
                last = knots_v[-1]
                last[-1] = np.where(np.isnan(last[-1]), v[0], last[-1])
                t, q, v = t[1:], q[1:], v[1:]
            knots_t.append(t)
            knots_q.append(q)
            knots_v.append(v)
            previous_end = traj.end
        if not self.phases:
            raise PlanError("phases", "the plan has no phases")
        times, poses, rates = np.concatenate(knots_t), np.vstack(knots_q), np.vstack(knots_v)
        if resample is None or len(times) < 3:
            self.pose = _hold(times, poses)
        else:
            estimate = _smooth(times, poses, True).derivative(1)
            for n in np.flatnonzero(np.isnan(rates).any(axis=1)):
                rates[n] = estimate.value(times[n]).ravel()
            self.pose = PiecewisePolynomial.CubicHermite(times, poses.T, rates.T)
        self.velocity = self.pose.derivative(1)
        self.acceleration = self.velocity.derivative(1)
        self.starts = np.array([p.start for p in self.phases])
        self.holdings = _holdings([p.stance.ids for p in self.phases])
        # holding_of[k, i]: the holding of boom i during phase k (-1: free)
        self.holding_of = np.full((len(self.phases), NUM_BOOMS), -1, dtype=int)
        for h, hold in enumerate(self.holdings):
            self.holding_of[hold.first:hold.last + 1, hold.boom] = h

    @staticmethod
    def _phase(k: int, phase: dict[str, Any], scn: Scenario, previous_end: float | None,
               resample: float | None
               ) -> tuple[PhaseTrajectory, np.ndarray, np.ndarray, np.ndarray]:
        """The phase, and the times, poses and velocities (NaN: not given) of its body."""
        where = f"phases[{k}]"
        ids = tuple(phase["stance"])
        unknown = [a for a in ids if a is not None and a not in scn.anchor_index]
        if unknown:
            raise PlanError(f"{where}.stance", f"unknown anchor {unknown[0]!r}")
        stance = scn.stance(ids)
        steps = phase["steps"]
        times = np.array([s["t"] for s in steps], dtype=float)
        if np.any(np.diff(times) <= 0):
            raise PlanError(f"{where}.steps", f"step times must increase, got {list(times)}")
        if previous_end is not None and abs(times[0] - previous_end) > 1e-6:
            raise PlanError(f"{where}.steps[0].t",
                            f"starts at {times[0]} but the phase before ends at {previous_end}")
        tensions = np.zeros((len(steps), NUM_BOOMS))
        for n, s in enumerate(steps):
            for i in range(NUM_BOOMS):
                if stance.attached[i]:
                    if s["tension"][i] is None:
                        raise PlanError(f"{where}.steps[{n}].tension[{i}]",
                                        "an attached boom needs a tension")
                    tensions[n, i] = s["tension"][i]
        poses = np.array([s["pose"] for s in steps], dtype=float)
        tips = None
        if stance.free_boom is not None:
            if any("free_tip" not in s for s in steps):
                raise PlanError(f"{where}.steps", "a phase with a free boom needs free_tip")
            tips = np.array([s["free_tip"] for s in steps], dtype=float)
        start, end = float(times[0]), float(times[-1])
        if len(steps) > 3 and resample is not None:
            times = _finish_over_dwell(times, poses, tips)
        if len(steps) != 2 or resample is None:
            free_tip = None
            if tips is not None:
                free_tip = _hold(times, tips) if resample is None else _smooth(times, tips, True)
            traj = PhaseTrajectory(phase["kind"], start, end, stance, _hold(times, tensions),
                                   free_tip, _rate(free_tip))
            return traj, times, poses, np.full_like(poses, np.nan)
        t, prog, rate = rest_to_rest(times[0], times[1], resample)
        line = poses[0] + prog[:, None] * (poses[1] - poses[0])
        free_tip = None
        if tips is not None:
            delta = tips[1] - tips[0]
            free_tip = PiecewisePolynomial.CubicHermite(
                t, (tips[0] + prog[:, None] * delta).T, (rate[:, None] * delta).T)
        ff = tensions[0] + prog[:, None] * (tensions[1] - tensions[0])
        inner = slice(1, len(t) - 1)
        grid_tips = None if tips is None else tips[0] + prog[inner, None] * (tips[1] - tips[0])
        alloc = allocate(scn.robot, scn.gravity_vector, line[inner], stance, grid_tips)
        ok = np.flatnonzero(alloc.statics_ok)
        ff[1 + ok] = np.where(stance.attached, np.nan_to_num(alloc.tensions[ok]), 0.0)
        traj = PhaseTrajectory(phase["kind"], start, end, stance, _hold(t, ff),
                               free_tip, _rate(free_tip))
        return traj, t, line, rate[:, None] * (poses[1] - poses[0])

    @property
    def end_time(self) -> float:
        return self.phases[-1].end

    def free_boom_mass(self, t: float) -> float:
        """The free boom's mass at time t (0 when none): boom_linear_density times its planned
        length, shoulder (on the planned pose) to the planned tip."""
        phase = self.phase_at(t)
        j = _free_boom(phase.stance)
        if j is None:
            return 0.0
        robot = self.scenario.robot
        x, y, phi = (float(v) for v in self.pose.value(t).ravel())
        sx, sy = robot.shoulders[j]
        tx, ty = (float(v) for v in phase.free_tip.value(t).ravel())
        c, s = math.cos(phi), math.sin(phi)
        return robot.boom_linear_density * math.hypot(tx - x - c * sx + s * sy,
                                                      ty - y - s * sx - c * sy)

    def phase_index(self, t: float) -> int:
        return max(0, int(np.searchsorted(self.starts, t, side="right")) - 1)

    def phase_at(self, t: float) -> PhaseTrajectory:
        return self.phases[self.phase_index(t)]

    @property
    def regrasps(self) -> int:
        return sum(h.attach for h in self.holdings)


def _holdings(stances: Sequence[tuple[str | None, ...]]) -> list[Holding]:
    """Maximal runs of phases in which a boom stays on one anchor (as planning.probability)."""
    out: list[Holding] = []
    for i in range(NUM_BOOMS):
        k = 0
        while k < len(stances):
            anchor = stances[k][i]
            end = k
            while end + 1 < len(stances) and stances[end + 1][i] == anchor:
                end += 1
            if anchor is not None:
                out.append(Holding(i, anchor, k, end, attach=k > 0))
            k = end + 1
    return sorted(out, key=lambda h: (h.first, h.boom))


class StrengthDraws(NamedTuple):
    """One trial's draws laid out per phase: quantile[k, i] is the strength quantile u of the
    holding of boom i in phase k (NaN when free); attach[k] the attach draw of the boom that
    regrasps at the start of phase k (NaN when none), which fails when below attach_failure."""

    quantile: np.ndarray     # (phases, 4)
    attach: np.ndarray       # (phases,)
    attach_boom: np.ndarray  # (phases,) int, -1 when none
    attach_failure: float

    @staticmethod
    def none(plan: PlanTrajectory) -> StrengthDraws:
        """Draws under which nothing ever fails (u = 0, no attach draws)."""
        n = len(plan.phases)
        return StrengthDraws(np.zeros((n, NUM_BOOMS)), np.full(n, np.nan),
                             np.full(n, -1), 0.0)

    @staticmethod
    def for_trial(plan: PlanTrajectory, quantiles: np.ndarray, attach_draws: np.ndarray,
                  attach_failure: float) -> StrengthDraws:
        """From one draw per holding (`plan.holdings` order) of u and of the attach variable."""
        n = len(plan.phases)
        q = np.full((n, NUM_BOOMS), np.nan)
        attach, boom = np.full(n, np.nan), np.full(n, -1)
        for h, hold in enumerate(plan.holdings):
            q[hold.first:hold.last + 1, hold.boom] = quantiles[h]
            if hold.attach:
                attach[hold.first], boom[hold.first] = attach_draws[h], hold.boom
        return StrengthDraws(q, attach, boom, float(attach_failure))


# ---------------------------------------------------------------------------------------------
# Leaf systems


_PLAN_PLACEHOLDER = AbstractValue.Make(None)
# PlanSource's free_limb output: the planned free tip (x, y), its velocity and the free boom's
# mass in the plant (zeros when every boom is attached)
FREE_LIMB_FIELDS = ("tip_x", "tip_y", "tip_vx", "tip_vy", "boom_mass")
FREE_LIMB_SIZE = len(FREE_LIMB_FIELDS)


class PlanSource(LeafSystem):
    """The plan at the current time: desired state (pose, velocity) and acceleration,
    feed-forward tensions, free limb (FREE_LIMB_FIELDS), phase index and stance. The plan is an
    abstract parameter (`set_plan`)."""

    def __init__(self):
        super().__init__()
        self._plan_index = self.DeclareAbstractParameter(_PLAN_PLACEHOLDER)
        self.DeclareVectorOutputPort("desired_state", 6, self._calc_desired)
        self.DeclareVectorOutputPort("desired_acceleration", 3, self._calc_acceleration)
        self.DeclareVectorOutputPort("feedforward_tension", NUM_BOOMS, self._calc_tension)
        self.DeclareVectorOutputPort("free_limb", FREE_LIMB_SIZE, self._calc_free_limb)
        self.DeclareVectorOutputPort("phase", 1, self._calc_phase)
        self.DeclareAbstractOutputPort("stance", lambda: AbstractValue.Make(None),
                                       self._calc_stance)

    def set_plan(self, context: Context, plan: PlanTrajectory) -> None:
        context.get_mutable_abstract_parameter(self._plan_index).set_value(plan)

    def plan(self, context: Context) -> PlanTrajectory:
        return context.get_abstract_parameter(self._plan_index).get_value()

    def _phase(self, context: Context) -> PhaseTrajectory:
        return self.plan(context).phase_at(context.get_time())

    def _calc_desired(self, context: Context, output: BasicVector) -> None:
        plan, t = self.plan(context), context.get_time()
        output.SetFromVector(np.concatenate([plan.pose.value(t).ravel(),
                                             plan.velocity.value(t).ravel()]))

    def _calc_acceleration(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.plan(context).acceleration.value(context.get_time()).ravel())

    def _calc_tension(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._phase(context).tension.value(context.get_time()).ravel())

    def _calc_free_limb(self, context: Context, output: BasicVector) -> None:
        plan, t = self.plan(context), context.get_time()
        phase = plan.phase_at(t)
        if phase.free_tip is None:
            output.SetFromVector(np.zeros(FREE_LIMB_SIZE))
            return
        output.SetFromVector(np.concatenate([phase.free_tip.value(t).ravel(),
                                             phase.free_tip_rate.value(t).ravel(),
                                             [plan.free_boom_mass(t)]]))

    def _calc_phase(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self.plan(context).phase_index(context.get_time()))

    def _calc_stance(self, context: Context, output: AbstractValue) -> None:
        output.set_value(self._phase(context).stance)


class BodyStatics:
    """The statics of one configuration, in plain floats: the systems evaluate it at every
    integrator stage, where the vectorised `rb_drake.statics.statics_problem` (made for many
    poses at once) costs ten times more. The tests hold the two equal.

    `wrench_matrix` has columns [u_i; (R s_i) x u_i] for attached booms (0 for free ones);
    `load` is the wrench the booms must balance, b = [-M g - W_limb; -tau_limb], plus the
    weight of `shoulder_mass` at each shoulder (the full plant's arm links) if given.

    The free limb's `free_limb` vector (FREE_LIMB_FIELDS) gives its tip and, with
    `fixed_boom_mass`, the boom's mass (the full plant's, fixed per phase, as two halves at
    shoulder and tip: the same weight and moments as a uniform boom); otherwise the boom's
    mass is the model's, boom_linear_density times its length."""

    def __init__(self, robot: RobotParams, gravity: np.ndarray, shoulder_mass: float = 0.0,
                 fixed_boom_mass: bool = False):
        self.robot = robot
        self.shoulder_mass = float(shoulder_mass)
        self.fixed_boom_mass = fixed_boom_mass
        self.gravity = (float(gravity[0]), float(gravity[1]))
        self.shoulders = [(float(x), float(y)) for x, y in robot.shoulders]
        self._anchors: dict[tuple, list[tuple[float, float] | None]] = {}

    def anchors(self, stance: Stance) -> list[tuple[float, float] | None]:
        """Anchor position per boom (None: free), cached per stance."""
        key = (stance.ids, stance.positions.tobytes())
        if key not in self._anchors:
            self._anchors[key] = [(float(p[0]), float(p[1])) if a else None
                                  for a, p in zip(stance.attached, stance.positions,
                                                  strict=True)]
        return self._anchors[key]

    def wrench_matrix(self, pose: np.ndarray, stance: Stance) -> np.ndarray:
        x, y, phi = (float(v) for v in pose[:3])
        c, s = math.cos(phi), math.sin(phi)
        A = np.zeros((3, NUM_BOOMS))
        for i, anchor in enumerate(self.anchors(stance)):
            if anchor is None:
                continue
            sx, sy = self.shoulders[i]
            rx, ry = c * sx - s * sy, s * sx + c * sy
            dx, dy = anchor[0] - x - rx, anchor[1] - y - ry
            length = math.hypot(dx, dy)
            ux, uy = dx / length, dy / length
            A[0, i], A[1, i], A[2, i] = ux, uy, rx * uy - ry * ux
        return A

    def limb_wrench(self, pose: np.ndarray, stance: Stance, free_limb: np.ndarray) -> np.ndarray:
        """The free limb's weight on the body: [W_limb; tau_limb] (zero in a 4-stance)."""
        j = _free_boom(stance)
        if j is None:
            return np.zeros(3)
        x, y, phi = (float(v) for v in pose[:3])
        c, s = math.cos(phi), math.sin(phi)
        sx, sy = self.shoulders[j]
        px, py = x + c * sx - s * sy, y + s * sx + c * sy
        tx, ty = float(free_limb[0]), float(free_limb[1])
        m_boom = (float(free_limb[4]) if self.fixed_boom_mass
                  else self.robot.boom_linear_density * math.hypot(tx - px, ty - py))
        m_grip = self.robot.gripper_mass
        gx, gy = self.gravity
        # the boom's weight at its midpoint, the gripper's at the tip; moments about the centre
        ax = m_boom * (0.5 * (px + tx) - x) + m_grip * (tx - x)
        ay = m_boom * (0.5 * (py + ty) - y) + m_grip * (ty - y)
        m = m_boom + m_grip
        return np.array([m * gx, m * gy, ax * gy - ay * gx])

    def load(self, pose: np.ndarray, stance: Stance, free_limb: np.ndarray) -> np.ndarray:
        b = -self.limb_wrench(pose, stance, free_limb)
        gx, gy = self.gravity
        mass = self.robot.body_mass + NUM_BOOMS * self.shoulder_mass
        b[0] -= mass * gx
        b[1] -= mass * gy
        if self.shoulder_mass:
            phi = float(pose[2])
            c, s = math.cos(phi), math.sin(phi)
            rx = sum(c * sx - s * sy for sx, sy in self.shoulders)
            ry = sum(s * sx + c * sy for sx, sy in self.shoulders)
            b[2] -= self.shoulder_mass * (rx * gy - ry * gx)
        return b


class BoomForces(LeafSystem):
    """The booms as tension members: tensions -> generalized force of the body's planar joint.

    Each attached boom pulls its shoulder towards its anchor; in a reach phase the free limb's
    weight also loads the body. For a planar joint the generalized forces are the world force
    (x, y) and the moment about the body origin (its centre of mass): A f + [W_limb; tau_limb].
    The body's own weight is the plant's gravity."""

    def __init__(self, robot: RobotParams, gravity: np.ndarray):
        super().__init__()
        self._statics = BodyStatics(robot, gravity)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._tension = self.DeclareVectorInputPort("tension", NUM_BOOMS)
        self._free_limb = self.DeclareVectorInputPort("free_limb", FREE_LIMB_SIZE)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self.DeclareVectorOutputPort("generalized_force", 3, self._calc)

    def _calc(self, context: Context, output: BasicVector) -> None:
        pose = self._state.Eval(context)[:3]
        stance = self._stance.Eval(context)
        tension = np.where(stance.attached, self._tension.Eval(context), 0.0)
        wrench = self._statics.wrench_matrix(pose, stance) @ tension
        output.SetFromVector(wrench + self._statics.limb_wrench(pose, stance,
                                                                self._free_limb.Eval(context)))


@dataclasses.dataclass(frozen=True)
class ControlGains:
    """Pose PD as a critically damped (by default) second-order error response per axis."""

    frequency_hz: float = 2.0
    damping_ratio: float = 1.0
    # rho of TensionProjector: a newton of tension off the feed-forward costs as much as 0.01 N
    # (or N m) of wrench error; small, so the wrench comes first where the bounds allow it
    tension_weight: float = 1e-4
    # The free limb's joints (full plant): PD towards the planned tip, faster than the body
    limb_frequency_hz: float = 2.0
    limb_damping_ratio: float = 1.0

    @property
    def kp(self) -> float:
        return (2.0 * math.pi * self.frequency_hz) ** 2

    @property
    def kd(self) -> float:
        return 2.0 * self.damping_ratio * 2.0 * math.pi * self.frequency_hz

    @property
    def limb_kp(self) -> float:
        return (2.0 * math.pi * self.limb_frequency_hz) ** 2

    @property
    def limb_kd(self) -> float:
        return 2.0 * self.limb_damping_ratio * 2.0 * math.pi * self.limb_frequency_hz


def _free_boom(stance: Stance) -> int | None:
    """`stance.free_boom` from the ids, for the per-step systems (the property costs 10 us)."""
    return stance.ids.index(None) if None in stance.ids else None


class TensionProjector:
    """Boom tensions that make a wanted body wrench w as far as it is worth it: the attached
    booms within the tension bounds, free booms at 0, minimising

        |A f - w|^2 + rho |f - f_ref|^2    (wrench in N and N m, tensions in N),

    the wrench error plus the departure from the plan's (feed-forward) tensions f_ref, rho =
    ControlGains.tension_weight. Without bounds this is one small linear solve, and with rho
    small the wrench is made almost exactly (to ~1 % in the weak moment direction, whose
    singular value is ~0.08 m, and 1e-4 in force) nearest f_ref, so the pose is tracked; where
    the bounds bind it is a QP on one reused Clarabel program. The weight is what keeps the
    grasps safe where the plan's tensions sit on a bound (the most robust allocation puts safe
    booms at the minimum tension) and the wanted wrench leaves the feasible set: making it
    exactly would need every tension raised along the 4-stance's null vector, by tens of
    newtons for a hundredth of a newton metre, which the old controller did (rho 1e-6 and an
    exact solve first) and collapsed the crevasse plans' P. A small acceleration error, which
    the pose PD takes back once the geometry allows, costs nothing. (Weighting the rows by the
    body's inverse inertia instead trades position for heading, and a body in a 3-stance on a
    bound then drifts off its pose: it fell on one crevasse.)"""

    def __init__(self, bounds: tuple[float, float], rho: float):
        self.lo, self.hi = bounds
        self.rho = rho
        self.prog = MathematicalProgram()
        self.f = self.prog.NewContinuousVariables(NUM_BOOMS, "tension")
        self.cost = self.prog.AddQuadraticCost(np.eye(NUM_BOOMS), np.zeros(NUM_BOOMS), self.f,
                                               is_convex=True)
        self.box = self.prog.AddBoundingBoxConstraint(np.zeros(NUM_BOOMS), np.zeros(NUM_BOOMS),
                                                      self.f)
        self.solver = ClarabelSolver()
        self.options = SolverOptions()
        for name in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
            self.options.SetOption(self.solver.id(), name, 1e-9)

    def __call__(self, A: np.ndarray, w: np.ndarray, f_ref: np.ndarray,
                 attached: np.ndarray) -> np.ndarray:
        mask = attached.astype(float)
        lo, hi = self.lo * mask, self.hi * mask
        f_ref = f_ref * mask
        H = A.T @ A
        H.flat[::NUM_BOOMS + 1] += self.rho
        g = A.T @ w + self.rho * f_ref
        f = np.linalg.solve(H, g) * mask  # the free boom's column is zero: its f is 0
        if (f >= lo - 1e-12).all() and (f <= hi + 1e-12).all():
            return np.minimum(np.maximum(f, lo), hi)
        self.cost.evaluator().UpdateCoefficients(2.0 * H, -2.0 * g, 0.0, is_convex=True)
        self.box.evaluator().set_bounds(lo, hi)
        guess = np.minimum(np.maximum(f_ref, lo), hi)
        result = self.solver.Solve(self.prog, guess, self.options)
        if not result.is_success():  # keep the booms pulling: the feed-forward, clipped
            return guess
        return np.minimum(np.maximum(result.GetSolution(self.f), lo), hi)


class TensionController(LeafSystem):
    """Boom tensions from the plan's feed-forward and a PD on the body pose.

    The wanted wrench is the statics load at the actual pose (body and free-limb weight)
    plus diag(m, m, I) (a_d + kp e + kd de), a_d the desired acceleration, e the pose error;
    the tensions nearest the feed-forward that make it, within the bounds, go to the booms
    (`TensionProjector`). With `tip_push` (the full plant) an input of that name is the force
    the free limb's joints push its tip with beyond holding it (`LimbController`); its
    reaction on the body, at the planned tip, joins the load."""

    def __init__(self, robot: RobotParams, gravity: np.ndarray, inertia: np.ndarray,
                 gains: ControlGains, shoulder_mass: float = 0.0, fixed_boom_mass: bool = False,
                 tip_push: bool = False):
        super().__init__()
        self._statics = BodyStatics(robot, gravity, shoulder_mass, fixed_boom_mass)
        self._inertia = np.asarray(inertia, dtype=float)
        self._gains = gains
        self.projector = TensionProjector(robot.boom_tension, gains.tension_weight)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._desired = self.DeclareVectorInputPort("desired_state", 6)
        self._acceleration = self.DeclareVectorInputPort("desired_acceleration", 3)
        self._feedforward = self.DeclareVectorInputPort("feedforward_tension", NUM_BOOMS)
        self._free_limb = self.DeclareVectorInputPort("free_limb", FREE_LIMB_SIZE)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self._tip_push = self.DeclareVectorInputPort("tip_push", 2) if tip_push else None
        self.DeclareVectorOutputPort("tension", NUM_BOOMS, self._calc)

    def _calc(self, context: Context, output: BasicVector) -> None:
        x = self._state.Eval(context)
        xd = self._desired.Eval(context)
        stance = self._stance.Eval(context)
        pose = x[:3]
        error = xd[:3] - pose
        error[2] = (error[2] + math.pi) % (2.0 * math.pi) - math.pi
        g = self._gains
        free_limb = self._free_limb.Eval(context)
        wanted = (self._statics.load(pose, stance, free_limb)
                  + self._inertia * (self._acceleration.Eval(context) + g.kp * error
                                     + g.kd * (xd[3:] - x[3:])))
        if self._tip_push is not None and _free_boom(stance) is not None:
            px, py = (float(a) for a in self._tip_push.Eval(context))
            ax, ay = float(free_limb[0] - pose[0]), float(free_limb[1] - pose[1])
            wanted += (px, py, ax * py - ay * px)
        output.SetFromVector(self.projector(self._statics.wrench_matrix(pose, stance), wanted,
                                            self._feedforward.Eval(context), stance.attached))


GRASP_FIELDS = ("pull_angle", "force", "probability")  # the monitor's output, 4 values each


def grasp_state(robot: RobotParams, pose: np.ndarray, stance: Stance,
                tension: np.ndarray) -> np.ndarray:
    """Pull angles, forces and probabilities of the grasps (GRASP_FIELDS, 4 each; NaN for a
    free boom), by the model of `rb_drake.geometry` and `rb_drake.grasp`."""
    targets = np.where(stance.attached[:, None], stance.positions, 0.0)
    geo = geometry.boom_geometry(robot, pose, targets)
    normals = np.where(stance.attached[:, None], stance.normals, 1.0)
    psi = geometry.pull_angles(geo.u[0], normals)
    p = grasp.prob(tension, psi, stance.f_normal, stance.f_lateral, stance.sigma_normal,
                   stance.sigma_lateral)
    out = np.concatenate([psi, tension, p])
    out[np.tile(~stance.attached, 3)] = np.nan
    return out


class GraspMonitor(LeafSystem):
    """Each anchor's pull angle, force (its boom's tension) and grasp probability P_i, from the
    simulated body pose and the applied tensions: output `grasp`, GRASP_FIELDS x 4 booms."""

    def __init__(self, robot: RobotParams):
        super().__init__()
        self._robot = robot
        self._state = self.DeclareVectorInputPort("state", 6)
        self._tension = self.DeclareVectorInputPort("tension", NUM_BOOMS)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self.DeclareVectorOutputPort("grasp", 3 * NUM_BOOMS, self._calc)

    def _calc(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(grasp_state(self._robot, self._state.Eval(context)[:3],
                                         self._stance.Eval(context), self._tension.Eval(context)))


class LimbController(LeafSystem):
    """The free limb of the full plant (a reach phase): its joints steered to the planned tip.

    A PD on the free boom's shoulder angle and length towards the inverse kinematics of the
    planned tip at the actual body pose (and the rates of that target), scaled by the joints'
    inertia (tip mass m_t: m_t L^2 and m_t), plus the feed-forward that holds the limb against
    gravity: the weight of its tip mass about the shoulder, -L (e x m_t g), and along the boom,
    -m_t g.e (the half of the boom at the shoulder loads only the body). Output
    `generalized_force`: those two joints' forces (the rest zero: attached shoulders are
    passive, the tensions come from `TensionController`). Output `tip_push`: the world force
    the PD part pushes the tip with, Delta_t = dF e + (dtau / L) e_perp; the body feels -Delta_t
    at the tip, which the body's controller counters (the limb's inertia about its shoulder,
    m_t L^2 ~ 0.3 kg m^2, is ten times the body's)."""

    def __init__(self, rb: ReachBotPlant, robot: RobotParams, gravity: np.ndarray,
                 gains: ControlGains):
        super().__init__()
        plant = rb.plant
        self._nv = plant.num_velocities()
        self._nq = plant.num_positions()
        self._q_base, self._v_base = rb.base.position_start(), rb.base.velocity_start()
        self._q_sh = [j.position_start() for j in rb.shoulders]
        self._v_sh = [j.velocity_start() for j in rb.shoulders]
        self._q_boom = [j.position_start() for j in rb.booms]
        self._v_boom = [j.velocity_start() for j in rb.booms]
        self._tip_mass = [tip.default_mass() for tip in rb.tips]
        self._shoulders = [(float(x), float(y)) for x, y in robot.shoulders]
        self._alpha = [float(a) for a in robot.shoulder_directions]
        self._g = (float(gravity[0]), float(gravity[1]))
        self._kp, self._kd = gains.limb_kp, gains.limb_kd
        self._state = self.DeclareVectorInputPort("state", self._nq + self._nv)
        self._free_limb = self.DeclareVectorInputPort("free_limb", FREE_LIMB_SIZE)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        # both outputs come from one computation, cached per step
        self._command = self.DeclareCacheEntry(
            "command", ValueProducer(lambda: AbstractValue.Make(np.zeros(4)),
                                     self._calc_command),
            {self.all_input_ports_ticket()})
        self.DeclareVectorOutputPort("generalized_force", self._nv, self._calc_force,
                                     {self._command.ticket()})
        self.DeclareVectorOutputPort("tip_push", 2, self._calc_push, {self._command.ticket()})

    def _calc_force(self, context: Context, output: BasicVector) -> None:
        u = np.zeros(self._nv)
        j = _free_boom(self._stance.Eval(context))
        if j is not None:
            torque, force = self._command.Eval(context)[:2]
            u[self._v_sh[j]], u[self._v_boom[j]] = torque, force
        output.SetFromVector(u)

    def _calc_push(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._command.Eval(context)[2:])

    def _calc_command(self, context: Context, value: AbstractValue) -> None:
        """[shoulder torque, boom force, push_x, push_y] of the free boom (zeros if none)."""
        j = _free_boom(self._stance.Eval(context))
        if j is None:
            value.set_value(np.zeros(4))
            return
        x = self._state.Eval(context)
        q, v = x[:self._nq], x[self._nq:]
        b, vb = self._q_base, self._v_base
        phi, vx, vy, w = float(q[b + 2]), float(v[vb]), float(v[vb + 1]), float(v[vb + 2])
        c, s = math.cos(phi), math.sin(phi)
        sx, sy = self._shoulders[j]
        rx, ry = c * sx - s * sy, s * sx + c * sy
        tx, ty, tvx, tvy, boom_mass = (float(a) for a in self._free_limb.Eval(context))
        dx, dy = tx - float(q[b]) - rx, ty - float(q[b + 1]) - ry
        length_d = math.hypot(dx, dy)
        ux, uy = dx / length_d, dy / length_d
        ddx, ddy = tvx - (vx - w * ry), tvy - (vy + w * rx)  # tip rate less the shoulder's
        rate_length_d = ux * ddx + uy * ddy
        rate_theta_d = (ux * ddy - uy * ddx) / length_d - w
        theta_d = math.atan2(dy, dx) - phi - self._alpha[j]
        theta, length = float(q[self._q_sh[j]]), float(q[self._q_boom[j]])
        e_theta = (theta_d - theta + math.pi) % (2.0 * math.pi) - math.pi
        m_tip = self._tip_mass[j] + 0.5 * boom_mass
        beta = phi + self._alpha[j] + theta
        ex, ey = math.cos(beta), math.sin(beta)
        gx, gy = self._g
        pd_torque = m_tip * length * length * (
            self._kp * e_theta + self._kd * (rate_theta_d - float(v[self._v_sh[j]])))
        pd_force = m_tip * (self._kp * (length_d - length)
                            + self._kd * (rate_length_d - float(v[self._v_boom[j]])))
        hold_torque = -length * m_tip * (ex * gy - ey * gx)
        hold_force = -m_tip * (ex * gx + ey * gy)
        across = pd_torque / length
        value.set_value(np.array([pd_torque + hold_torque, pd_force + hold_force,
                                  pd_force * ex - across * ey, pd_force * ey + across * ex]))


class AnchorLoadMonitor(LeafSystem):
    """The grasp monitor of the full plant: each anchored boom's pull on its gripper, from the
    simulated dynamics, and the grasp probability it gives (output `grasp` as GraspMonitor's).

    The pull is the reaction force of the boom's prismatic joint on the tip body (the plant's
    reaction-forces port, expressed along the boom, rotated into the world): the tension the
    boom carries plus whatever the joint transmits across the boom, at the simulated pose. Its
    magnitude is the grasp's force and its direction (anchor -> shoulder in statics) gives
    the pull angle. It is the load of the model, a massless tension member pulling the
    anchor; the ball constraint's force would add the gripper's own weight and inertia, which
    the model (and the plan's P) leave out."""

    def __init__(self, rb: ReachBotPlant, robot: RobotParams):
        super().__init__()
        plant = rb.plant
        self._robot = robot
        self._nq = plant.num_positions()
        self._q_base = rb.base.position_start()
        self._q_sh = [j.position_start() for j in rb.shoulders]
        self._joints = [int(j.index()) for j in rb.booms]
        self._state = self.DeclareVectorInputPort(
            "state", plant.num_positions() + plant.num_velocities())
        self._reaction = self.DeclareAbstractInputPort(
            "reaction_forces", plant.get_reaction_forces_output_port().Allocate())
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self.DeclareVectorOutputPort("grasp", 3 * NUM_BOOMS, self._calc)

    def pulls(self, context: Context) -> np.ndarray:
        """The booms' pulls on their grippers in the world, (4, 2)."""
        q = self._state.Eval(context)[:self._nq]
        reaction = self._reaction.Eval(context)
        phi = float(q[self._q_base + 2])
        out = np.zeros((NUM_BOOMS, 2))
        for i in range(NUM_BOOMS):
            f = reaction[self._joints[i]].translational()  # along (x) and across the boom
            beta = phi + self._robot.shoulder_directions[i] + float(q[self._q_sh[i]])
            c, s = math.cos(beta), math.sin(beta)
            out[i] = (c * f[0] - s * f[1], s * f[0] + c * f[1])
        return out

    def _calc(self, context: Context, output: BasicVector) -> None:
        stance = self._stance.Eval(context)
        pull = self.pulls(context)
        force = np.linalg.norm(pull, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            direction = pull / force[:, None]
        normals = np.where(stance.attached[:, None], stance.normals, 1.0)
        psi = geometry.pull_angles(-direction, normals)  # pull_angles takes shoulder -> anchor
        p = grasp.prob(force, psi, stance.f_normal, stance.f_lateral, stance.sigma_normal,
                       stance.sigma_lateral)
        out = np.concatenate([psi, force, p])
        out[np.tile(~stance.attached, 3)] = np.nan
        output.SetFromVector(out)


class Cause:
    """Why a grasp failed (codes in GraspFailures' state)."""

    OVERLOAD = 1  # the force exceeded the holding's drawn limit (or |psi| >= pi/2)
    ATTACH = 2    # a new grasp did not take hold on contact
    NAMES: ClassVar[dict[int, str]] = {1: "overload", 2: "attach"}


FAILURE_FIELDS = ("failed", "time", "phase", "boom", "cause", "probability", "draw",
                  "last_phase")


class GraspFailures(LeafSystem):
    """Stochastic grasps: latches the first failure under the drawn strengths (a parameter).

    Every `period` (the loggers' grid), in phase k: a boom that regrasps at the start of k
    fails on its first sample if its attach draw is below attach_failure; then every attached
    boom i fails if P_i < u, u its holding's quantile (the lowest boom first). The state
    (FAILURE_FIELDS) changes only in this periodic event."""

    def __init__(self, period: float):
        super().__init__()
        self._draws_index = self.DeclareAbstractParameter(AbstractValue.Make(None))
        self._grasp = self.DeclareVectorInputPort("grasp", 3 * NUM_BOOMS)
        self._phase = self.DeclareVectorInputPort("phase", 1)
        initial = np.zeros(len(FAILURE_FIELDS))
        initial[-1] = -1.0
        self._state_index = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareStateOutputPort("failure", self._state_index)

    def set_draws(self, context: Context, draws: StrengthDraws) -> None:
        context.get_mutable_abstract_parameter(self._draws_index).set_value(draws)
        initial = np.zeros(len(FAILURE_FIELDS))
        initial[-1] = -1.0
        context.SetDiscreteState(self._state_index, initial)

    def failed(self, context: Context) -> bool:
        return context.get_discrete_state(self._state_index).GetAtIndex(0) > 0

    def state(self, context: Context) -> np.ndarray:
        """FAILURE_FIELDS."""
        return context.get_discrete_state(self._state_index).CopyToVector()

    def _update(self, context: Context, discrete: Any) -> None:
        state = context.get_discrete_state(self._state_index).CopyToVector()
        if state[0] > 0:
            return
        k = int(self._phase.Eval(context)[0])
        draws: StrengthDraws = context.get_abstract_parameter(self._draws_index).get_value()
        p = self._grasp.Eval(context)[2 * NUM_BOOMS:]
        fail = None
        boom = draws.attach_boom[k]
        if k != int(state[-1]) and boom >= 0 and draws.attach[k] < draws.attach_failure:
            fail = (boom, Cause.ATTACH, p[boom], draws.attach[k])
        if fail is None:
            u = draws.quantile[k]
            weak = np.flatnonzero(~np.isnan(p) & (p < u))
            if len(weak):
                fail = (weak[0], Cause.OVERLOAD, p[weak[0]], u[weak[0]])
        state[-1] = k
        if fail is not None:
            boom, cause, prob, draw = fail
            state[:7] = [1.0, context.get_time(), k, boom, cause, prob, draw]
        discrete.get_mutable_vector(self._state_index).SetFromVector(state)


# ---------------------------------------------------------------------------------------------
# The diagram and its runs


class Failure(NamedTuple):
    time: float
    phase: int
    boom: int
    anchor: str
    cause: str
    probability: float
    draw: float


class SimulationRecord(NamedTuple):
    """One run, sampled every SAMPLE_PERIOD (times (N,), arrays (N, ...))."""

    plan: PlanTrajectory
    times: np.ndarray
    phase: np.ndarray         # (N,) int
    state: np.ndarray         # (N, 6) x, y, phi, vx, vy, omega
    desired: np.ndarray       # (N, 6)
    tension: np.ndarray       # (N, 4) commanded = applied (0 for a free boom)
    pull_angle: np.ndarray    # (N, 4), NaN for a free boom
    force: np.ndarray         # (N, 4), NaN for a free boom
    probability: np.ndarray   # (N, 4), NaN for a free boom
    failure: Failure | None
    joints: np.ndarray | None = None  # (N, 8) theta_0, L_0, ..., theta_3, L_3 (full plant)

    def tip_positions(self) -> np.ndarray:
        """The simulated boom tips in the world, (N, 4, 2) (full plant only)."""
        if self.joints is None:
            raise ValueError("the body-only plant has no boom tips")
        robot = self.plan.scenario.robot
        return np.stack([geometry.tip_positions(robot, x[:3], j[0::2], j[1::2])
                         for x, j in zip(self.state, self.joints, strict=True)])

    @property
    def position_error(self) -> np.ndarray:
        return np.linalg.norm(self.state[:, :2] - self.desired[:, :2], axis=1)

    @property
    def heading_error(self) -> np.ndarray:
        return np.abs(geometry.wrap_angle(self.state[:, 2] - self.desired[:, 2]))

    def holding_minimum(self) -> np.ndarray:
        """min_t P_i(t) of each holding (plan.holdings order) over the recorded samples."""
        out = np.ones(len(self.plan.holdings))
        for h, hold in enumerate(self.plan.holdings):
            rows = (self.phase >= hold.first) & (self.phase <= hold.last)
            if rows.any():
                out[h] = float(np.min(self.probability[rows, hold.boom]))
        return out

    def implied_p_path(self) -> float:
        """The climb's success probability implied by the simulated forces: the product of the
        holdings' smallest P_i times (1 - attach_failure) per regrasp."""
        af = self.plan.scenario.robot.attach_failure
        return float(np.prod(self.holding_minimum()) * (1.0 - af) ** self.plan.regrasps)


class ClimbSimulator:
    """The diagram for one scenario, built once; `run` executes a plan on it.

    `plant="full"` (the default) simulates rb_drake's whole robot (`build_plant` with
    `hold_tips`, discrete, SAP, period `time_step`): every anchored tip is held at its anchor
    by a ball constraint, the tensions drive the prismatic joints (a C++ gain), the free
    limb follows the planned tip (`LimbController`), and `AnchorLoadMonitor` reads the grasps'
    loads from the simulated joint reaction forces. `plant="body"` is the body alone on a
    planar joint (continuous), each boom's tension applied at its shoulder (`BoomForces`,
    `GraspMonitor`).

    `run` resets the context (time 0, the plan and draws as parameters, the body at the plan's
    first pose at rest unless `initial_state` is given, loggers cleared) and advances phase by
    phase, so integration steps end on the phase boundaries where the stance switches; the
    full plant's holds and free-boom mass are switched there, between `AdvanceTo` calls (the
    mass also every BOOM_MASS_PERIOD within a reach phase). Measured on the demo plan (200 s
    of climb): 11-14 s wall for the full plant at 10 ms, 10-13 s for the body plant; 5 ms
    and 2 ms steps change the implied p_path by < 2e-4 (its first 8 phases) at 2x and 4.5x.
    """

    def __init__(self, scn: Scenario, gains: ControlGains | None = None,
                 sample_period: float = SAMPLE_PERIOD, plant: str = "full",
                 time_step: float = PLANT_TIME_STEP):
        if plant not in ("full", "body"):
            raise ValueError(f"plant must be 'full' or 'body', got {plant!r}")
        robot, g = scn.robot, scn.gravity_vector
        gains = gains or ControlGains()
        self.scenario = scn
        self.sample_period = sample_period
        self.kind = plant
        builder = DiagramBuilder()
        w, h = robot.body_size
        izz = robot.body_mass * (w**2 + h**2) / 12.0
        self.source = builder.AddSystem(PlanSource())
        self.failures = builder.AddSystem(GraspFailures(sample_period))
        src = self.source
        connect = builder.Connect
        self.robot_plant: ReachBotPlant | None = None
        if plant == "full":
            rb = build_plant(robot, g, time_step, hold_tips=True, live_outputs=True,
                             joint_limits=False)
            self.robot_plant = rb
            self.plant = builder.AddSystem(rb.plant)
            # the arm links ride on the shoulders: the body carries them
            self.controller = builder.AddSystem(TensionController(
                robot, g, np.array([robot.body_mass + NUM_BOOMS * ARM_MASS] * 2 + [
                    izz + ARM_MASS * float(np.sum(np.asarray(robot.shoulders) ** 2))]),
                gains, ARM_MASS, fixed_boom_mass=True, tip_push=True))
            limb = builder.AddSystem(LimbController(rb, robot, g, gains))
            # an attached boom's tension T is its prismatic joint's force -T
            booms = np.zeros((self.plant.num_velocities(), NUM_BOOMS))
            for i, joint in enumerate(rb.booms):
                booms[joint.velocity_start(), i] = -1.0
            tensions = builder.AddSystem(MatrixGain(booms))
            total = builder.AddSystem(Adder(2, self.plant.num_velocities()))
            self.monitor = builder.AddSystem(AnchorLoadMonitor(rb, robot))
            full_state = self.plant.get_state_output_port()
            body_selector = builder.AddSystem(_selector(
                self.plant, rb.base.position_start() + np.arange(3),
                rb.base.velocity_start() + np.arange(3)))
            joint_selector = builder.AddSystem(_selector(self.plant, rb.q_order[3:], []))
            body_selector.set_name("body_state")
            joint_selector.set_name("joints")
            for selector in (body_selector, joint_selector):
                connect(full_state, selector.get_input_port())
            body_state, joints = body_selector.get_output_port(), joint_selector.get_output_port()
            connect(full_state, limb.GetInputPort("state"))
            connect(src.GetOutputPort("free_limb"), limb.GetInputPort("free_limb"))
            connect(src.GetOutputPort("stance"), limb.GetInputPort("stance"))
            connect(limb.GetOutputPort("tip_push"), self.controller.GetInputPort("tip_push"))
            connect(self.controller.GetOutputPort("tension"), tensions.get_input_port())
            connect(tensions.get_output_port(), total.get_input_port(0))
            connect(limb.GetOutputPort("generalized_force"), total.get_input_port(1))
            connect(total.get_output_port(), self.plant.get_applied_generalized_force_input_port())
            connect(full_state, self.monitor.GetInputPort("state"))
            connect(self.plant.get_reaction_forces_output_port(),
                    self.monitor.GetInputPort("reaction_forces"))
            limb.set_name("limb")
            tensions.set_name("boom_forces")
            total.set_name("generalized_force")
        else:
            self.plant = builder.AddSystem(MultibodyPlant(0.0))
            body = self.plant.AddRigidBody("body", SpatialInertia.SolidBoxWithMass(
                robot.body_mass, w, h, BODY_THICKNESS))
            self.plant.AddJoint(PlanarJoint("base", self.plant.world_frame(),
                                            body.body_frame()))
            self.plant.mutable_gravity_field().set_gravity_vector([g[0], g[1], 0.0])
            self.plant.Finalize()
            self.controller = builder.AddSystem(TensionController(
                robot, g, np.array([robot.body_mass, robot.body_mass, izz]), gains))
            booms = builder.AddSystem(BoomForces(robot, g))
            self.monitor = builder.AddSystem(GraspMonitor(robot))
            body_state, joints = self.plant.get_state_output_port(), None
            connect(body_state, booms.GetInputPort("state"))
            connect(self.controller.GetOutputPort("tension"), booms.GetInputPort("tension"))
            connect(src.GetOutputPort("free_limb"), booms.GetInputPort("free_limb"))
            connect(src.GetOutputPort("stance"), booms.GetInputPort("stance"))
            connect(booms.GetOutputPort("generalized_force"),
                    self.plant.get_applied_generalized_force_input_port())
            connect(body_state, self.monitor.GetInputPort("state"))
            connect(self.controller.GetOutputPort("tension"),
                    self.monitor.GetInputPort("tension"))
            booms.set_name("booms")
        self.plant.set_name("plant")
        for name, system in (("plan", self.source), ("controller", self.controller),
                             ("monitor", self.monitor), ("failures", self.failures)):
            system.set_name(name)
        ctl = self.controller
        for port in ("desired_state", "desired_acceleration", "feedforward_tension", "free_limb",
                     "stance"):
            connect(src.GetOutputPort(port), ctl.GetInputPort(port))
        connect(body_state, ctl.GetInputPort("state"))
        connect(src.GetOutputPort("stance"), self.monitor.GetInputPort("stance"))
        connect(self.monitor.GetOutputPort("grasp"), self.failures.GetInputPort("grasp"))
        connect(src.GetOutputPort("phase"), self.failures.GetInputPort("phase"))
        logged = {"phase": src.GetOutputPort("phase"), "state": body_state,
                  "desired": src.GetOutputPort("desired_state"),
                  "tension": ctl.GetOutputPort("tension"),
                  "grasp": self.monitor.GetOutputPort("grasp")}
        if joints is not None:
            logged["joints"] = joints
        self.loggers = {name: LogVectorOutput(port, builder, sample_period)
                        for name, port in logged.items()}
        self.diagram = builder.Build()
        self.diagram.set_name("climb")
        self.simulator = Simulator(self.diagram)
        self.simulator.set_monitor(self._stop_on_failure)
        self.context = self.simulator.get_mutable_context()
        self._stop = True

    def _stop_on_failure(self, root: Context) -> EventStatus:
        if self._stop and self.failures.failed(self.failures.GetMyContextFromRoot(root)):
            return EventStatus.ReachedTermination(self.failures, "grasp failure")
        return EventStatus.Succeeded()

    def run(self, plan: PlanTrajectory, draws: StrengthDraws | None = None,
            initial_state: np.ndarray | None = None,
            progress: Callable[[int, int, float], None] | None = None,
            stop_on_failure: bool = True) -> SimulationRecord:
        """Execute `plan`; with `draws`, grasps fail stochastically (the run stops at the first
        failure when `stop_on_failure`). `initial_state` is the body's (x, y, phi and rates;
        the plan's first pose at rest by default; the rest of the robot follows, `place`).
        `progress(phase, phases, t)` after each phase."""
        if plan.scenario.robot != self.scenario.robot or not np.array_equal(
                plan.scenario.gravity_vector, self.scenario.gravity_vector):
            raise ValueError("the plan's robot or gravity differs from the simulator's")
        ctx = self.context
        self.diagram.SetDefaultContext(ctx)
        ctx.SetTime(0.0)
        self.source.set_plan(self.source.GetMyMutableContextFromRoot(ctx), plan)
        self.failures.set_draws(self.failures.GetMyMutableContextFromRoot(ctx),
                                draws if draws is not None else StrengthDraws.none(plan))
        if initial_state is None:
            initial_state = np.concatenate([plan.pose.value(plan.phases[0].start).ravel(),
                                            np.zeros(3)])
        self.place(plan, plan.phases[0].start, initial_state)
        for logger in self.loggers.values():
            logger.FindMutableLog(ctx).Clear()
        self._stop = stop_on_failure
        self.simulator.Initialize()
        ends = [p.end for p in plan.phases]
        for k, end in enumerate(ends):
            if end > ctx.get_time():
                if k > 0 and self.robot_plant is not None:
                    self._enter_phase(plan, k)
                if not self._advance(plan, k, end):
                    break
            if progress is not None:
                progress(k + 1, len(ends), ctx.get_time())
        return self._record(plan)

    def _advance(self, plan: PlanTrajectory, k: int, end: float) -> bool:
        """Advance to `end` (in phase k); False when a grasp failure stopped the run. With the
        full plant in a reach phase, in steps of BOOM_MASS_PERIOD, after each of which the
        free boom's mass follows its planned length."""
        free = self.robot_plant is not None and plan.phases[k].stance.free_boom is not None
        while True:
            t = self.context.get_time()
            if free:
                self._set_free_boom_mass(plan, k, t)
            stop = min(end, t + BOOM_MASS_PERIOD) if free else end
            status = self.simulator.AdvanceTo(stop)
            if status.reason() == status.ReturnReason.kReachedTerminationCondition:
                return False
            if stop >= end:
                return True

    def _set_free_boom_mass(self, plan: PlanTrajectory, k: int, t: float,
                            context: Context | None = None) -> None:
        """The free boom's mass at its planned length at t, half at its tip and half at its
        shoulder (the weight and moments of the uniform boom of the model); others massless."""
        masses = np.zeros(NUM_BOOMS)
        j = plan.phases[k].stance.free_boom
        if j is not None:
            masses[j] = plan.free_boom_mass(t)
        self.robot_plant.set_boom_masses(
            self.plant.GetMyMutableContextFromRoot(context or self.context), masses)

    def _enter_phase(self, plan: PlanTrajectory, k: int, t: float | None = None,
                     context: Context | None = None) -> None:
        """The full plant in phase k (at its start, or at t): each attached tip held at its
        anchor, the free boom's mass (if any) at its planned length."""
        phase = plan.phases[k]
        context = context or self.context
        self.robot_plant.hold_tips(self.plant.GetMyMutableContextFromRoot(context), [
            p if a else None for a, p in zip(phase.stance.attached, phase.stance.positions,
                                             strict=True)])
        self._set_free_boom_mass(plan, k, phase.start if t is None else t, context)

    def place(self, plan: PlanTrajectory, t: float, body_state: np.ndarray,
              context: Context | None = None) -> None:
        """Put the robot in the plan's configuration at time t with the body's state (pose,
        rates): the full plant in the phase at t (its holds and free-boom mass), attached tips
        on their anchors and still, the free tip on its planned position at its planned rate.
        `context`: the diagram's (the simulator's by default)."""
        context = context or self.context
        body_state = np.asarray(body_state, dtype=float)
        plant_ctx = self.plant.GetMyMutableContextFromRoot(context)
        rb = self.robot_plant
        if rb is None:
            self.plant.SetPositionsAndVelocities(plant_ctx, body_state)
            return
        k = plan.phase_index(t)
        phase = plan.phases[k]
        self._enter_phase(plan, k, t, context)
        robot = self.scenario.robot
        targets = phase.stance.positions.copy()
        tip_rates = np.zeros((NUM_BOOMS, 2))
        j = phase.stance.free_boom
        if j is not None:
            targets[j] = phase.free_tip.value(t).ravel()
            tip_rates[j] = phase.free_tip_rate.value(t).ravel()
        pose, rates = body_state[:3], body_state[3:6]
        geo = geometry.boom_geometry(robot, pose, targets)
        u = geo.u[0]
        offsets = geo.shoulders[0] - pose[:2]
        d_rate = tip_rates - rates[:2] - rates[2] * np.stack([-offsets[:, 1], offsets[:, 0]],
                                                             axis=1)  # tip's less shoulder's
        length_rate = np.sum(u * d_rate, axis=1)
        angle_rate = geometry.cross2(u, d_rate) / geo.length[0] - rates[2]
        q = self.plant.GetPositions(plant_ctx)  # keeps the anchor bodies where hold_tips put them
        q[rb.q_order] = rb.canonical_q(pose, geo.shoulder_angle[0], geo.length[0])
        v = np.zeros(self.plant.num_velocities())
        v[rb.q_order] = rb.canonical_q(rates, angle_rate, length_rate)  # v = qdot here
        self.plant.SetPositions(plant_ctx, q)
        self.plant.SetVelocities(plant_ctx, v)

    def _record(self, plan: PlanTrajectory) -> SimulationRecord:
        logs = {name: logger.FindLog(self.context) for name, logger in self.loggers.items()}
        times = logs["state"].sample_times().copy()
        data = {name: log.data().T.copy() for name, log in logs.items()}
        n = min(len(times), *(len(d) for d in data.values()))
        data = {name: d[:n] for name, d in data.items()}
        state = self.failures.state(self.failures.GetMyContextFromRoot(self.context))
        failure = None
        if state[0] > 0:
            k, boom = int(state[2]), int(state[3])
            failure = Failure(float(state[1]), k, boom, plan.phases[k].stance.ids[boom] or "",
                              Cause.NAMES[int(state[4])], float(state[5]), float(state[6]))
        grasp_log = data["grasp"]
        return SimulationRecord(plan, times[:n], np.rint(data["phase"][:, 0]).astype(int),
                                data["state"], data["desired"], data["tension"],
                                grasp_log[:, :NUM_BOOMS], grasp_log[:, NUM_BOOMS:2 * NUM_BOOMS],
                                grasp_log[:, 2 * NUM_BOOMS:], failure, data.get("joints"))


def _selector(plant: MultibodyPlant, rows_q: Sequence[int], rows_v: Sequence[int]) -> MatrixGain:
    """A (C++) gain picking entries of the plant's state [q; v]: q[rows_q], then v[rows_v]."""
    nq = plant.num_positions()
    rows = [*map(int, rows_q), *(nq + int(r) for r in rows_v)]
    D = np.zeros((len(rows), nq + plant.num_velocities()))
    D[np.arange(len(rows)), rows] = 1.0
    return MatrixGain(D)
