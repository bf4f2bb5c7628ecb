"""A plan file executed as a Drake diagram: plan source, tension controller, body plant, booms,
grasp monitor, stochastic grasp failures and loggers, run by a `Simulator`.

    PlanSource ──desired state, feed-forward tensions, free tip, stance──┐
        │                                                                ▼
        │            plant state ──────────────────────────────▶ TensionController
        ▼                  ▲                                             │ tensions
    GraspMonitor ◀─────────┼──────────────── BoomForces ◀────────────────┤
        │ probability      │                     │ generalized force     │
        ▼                  └─── MultibodyPlant ◀─┘                       │
    GraspFailures (drawn strengths: latches the first failure)   loggers ◀┘

The plant is the body alone on a planar joint (q = x, y, phi; mass and inertia of the body box
of `rb_drake.plant`), not the full robot of `rb_drake.plant.build_plant`: in the model an
anchored boom is a massless tension member, so its only effect is its tension pulling the body
at the shoulder towards the anchor, and the full plant would need kinematic loops to hold the
tips at their anchors. `BoomForces` applies each attached boom's tension along its unit vector
(as the generalized force of the planar joint: world force and moment about the body centre)
and, in a reach phase, the free limb's weight (`geometry.limb_load`), as the statics do.

The controller turns the plan's tensions and poses into boom commands: the wrench the body
needs (statics load at the actual pose plus a PD on the pose error, scaled by the body's mass
and inertia) is made by the plan's feed-forward tensions plus the smallest correction through
the wrench matrix, kept within the tension bounds (`TensionProjector`; least squares where
the bounds make the wrench impossible). It is a feedthrough system (continuous time), so the
stance switches at the phase boundaries exactly. The monitor computes each anchor's pull
angle, force and probability (`rb_drake.grasp`) from the simulated state; `GraspFailures`
compares them with one drawn strength quantile per holding and an attach draw per regrasp
(module `montecarlo` explains the convention) and latches the first failure, which stops the
simulation. How plan phases become trajectories is in `PlanTrajectory`.

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
)
from pydrake.systems.primitives import LogVectorOutput
from pydrake.trajectories import PiecewisePolynomial

from rb_drake import geometry, grasp
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.plant import BODY_THICKNESS
from rb_drake.scenario import Scenario, scenario_from_dict
from rb_drake.stance import Stance
from rb_drake.statics import allocate, null_vector

SAMPLE_PERIOD = 0.02  # s: loggers and the failure check run at this period, on the same grid


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
    linearly. A phase of exactly two steps, as the footstep stage writes today (its two end
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
        if len(steps) != 2 or resample is None:
            free_tip = None
            if tips is not None:
                free_tip = _hold(times, tips) if resample is None else _smooth(times, tips, True)
            return (PhaseTrajectory(phase["kind"], start, end, stance, _hold(times, tensions),
                                    free_tip), times, poses, np.full_like(poses, np.nan))
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
        return (PhaseTrajectory(phase["kind"], start, end, stance, _hold(t, ff), free_tip), t,
                line, rate[:, None] * (poses[1] - poses[0]))

    @property
    def end_time(self) -> float:
        return self.phases[-1].end

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


class PlanSource(LeafSystem):
    """The plan at the current time: desired state (pose, velocity) and acceleration,
    feed-forward tensions, free tip, phase index and stance. The plan is an abstract parameter
    (`set_plan`)."""

    def __init__(self):
        super().__init__()
        self._plan_index = self.DeclareAbstractParameter(_PLAN_PLACEHOLDER)
        self.DeclareVectorOutputPort("desired_state", 6, self._calc_desired)
        self.DeclareVectorOutputPort("desired_acceleration", 3, self._calc_acceleration)
        self.DeclareVectorOutputPort("feedforward_tension", NUM_BOOMS, self._calc_tension)
        self.DeclareVectorOutputPort("free_tip", 2, self._calc_free_tip)
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

    def _calc_free_tip(self, context: Context, output: BasicVector) -> None:
        tip = self._phase(context).free_tip
        output.SetFromVector(np.zeros(2) if tip is None else tip.value(context.get_time()).ravel())

    def _calc_phase(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self.plan(context).phase_index(context.get_time()))

    def _calc_stance(self, context: Context, output: AbstractValue) -> None:
        output.set_value(self._phase(context).stance)


class BodyStatics:
    """The statics of one configuration, in plain floats: the systems evaluate it at every
    integrator stage, where the vectorised `rb_drake.statics.statics_problem` (made for many
    poses at once) costs ten times more. The tests hold the two equal.

    `wrench_matrix` has columns [u_i; (R s_i) x u_i] for attached booms (0 for free ones);
    `load` is the wrench the booms must balance, b = [-M g - W_limb; -tau_limb]."""

    def __init__(self, robot: RobotParams, gravity: np.ndarray):
        self.robot = robot
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

    def limb_wrench(self, pose: np.ndarray, stance: Stance, free_tip: np.ndarray) -> np.ndarray:
        """The free limb's weight on the body: [W_limb; tau_limb] (zero in a 4-stance)."""
        j = stance.free_boom
        if j is None:
            return np.zeros(3)
        x, y, phi = (float(v) for v in pose[:3])
        c, s = math.cos(phi), math.sin(phi)
        sx, sy = self.shoulders[j]
        px, py = x + c * sx - s * sy, y + s * sx + c * sy
        tx, ty = float(free_tip[0]), float(free_tip[1])
        m_boom = self.robot.boom_linear_density * math.hypot(tx - px, ty - py)
        m_grip = self.robot.gripper_mass
        gx, gy = self.gravity
        # the boom's weight at its midpoint, the gripper's at the tip; moments about the centre
        ax = m_boom * (0.5 * (px + tx) - x) + m_grip * (tx - x)
        ay = m_boom * (0.5 * (py + ty) - y) + m_grip * (ty - y)
        m = m_boom + m_grip
        return np.array([m * gx, m * gy, ax * gy - ay * gx])

    def load(self, pose: np.ndarray, stance: Stance, free_tip: np.ndarray) -> np.ndarray:
        b = -self.limb_wrench(pose, stance, free_tip)
        b[0] -= self.robot.body_mass * self.gravity[0]
        b[1] -= self.robot.body_mass * self.gravity[1]
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
        self._free_tip = self.DeclareVectorInputPort("free_tip", 2)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self.DeclareVectorOutputPort("generalized_force", 3, self._calc)

    def _calc(self, context: Context, output: BasicVector) -> None:
        pose = self._state.Eval(context)[:3]
        stance = self._stance.Eval(context)
        tension = np.where(stance.attached, self._tension.Eval(context), 0.0)
        wrench = self._statics.wrench_matrix(pose, stance) @ tension
        output.SetFromVector(wrench + self._statics.limb_wrench(pose, stance,
                                                                self._free_tip.Eval(context)))


@dataclasses.dataclass(frozen=True)
class ControlGains:
    """Pose PD as a critically damped (by default) second-order error response per axis."""

    frequency_hz: float = 2.0
    damping_ratio: float = 1.0
    # How strongly the tensions stay near the feed-forward where the wrench leaves them free
    # (the null space of a 4-stance); small, so the wrench comes first.
    feedforward_weight: float = 1e-6

    @property
    def kp(self) -> float:
        return (2.0 * math.pi * self.frequency_hz) ** 2

    @property
    def kd(self) -> float:
        return 2.0 * self.damping_ratio * 2.0 * math.pi * self.frequency_hz


class TensionProjector:
    """Boom tensions that make a wanted body wrench w, nearest the feed-forward f_ref, the
    attached booms within the tension bounds and free booms at 0.

    Where the bounds allow it, w is made exactly: the minimum-norm correction
    f = f_ref + A^+ (w - A f_ref), then, in a 4-stance (a line of solutions f + t n, n the null
    vector of A), the point of the line nearest f_ref within the bounds, t = clip(0, t_lo,
    t_hi). Where no tensions within the bounds make w (the body must then accelerate), the
    least-squares tensions min |A f - w|^2 + rho |f - f_ref|^2 over the box: a QP on one
    reused Clarabel program."""

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

    def exact(self, A: np.ndarray, w: np.ndarray, f_ref: np.ndarray, attached: np.ndarray,
              lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
        """The tensions making w exactly nearest f_ref within the bounds, or None."""
        Aa = A[:, attached]
        r = w - A @ f_ref
        f = f_ref.copy()
        if Aa.shape[1] == 3:
            if abs(np.linalg.det(Aa)) < 1e-12:
                return None
            f[attached] += np.linalg.solve(Aa, r)
            ok = (f >= lo - 1e-12).all() and (f <= hi + 1e-12).all()
            return np.minimum(np.maximum(f, lo), hi) if ok else None
        AAt = Aa @ Aa.T
        if Aa.shape[1] != 4 or abs(np.linalg.det(AAt)) < 1e-14:
            return None
        f += Aa.T @ np.linalg.solve(AAt, r)
        n = null_vector(A[None])[0]
        n /= np.linalg.norm(n)
        t_lo, t_hi = -math.inf, math.inf
        for i in range(NUM_BOOMS):
            if abs(n[i]) > 1e-12:
                a, b = (lo[i] - f[i]) / n[i], (hi[i] - f[i]) / n[i]
                t_lo, t_hi = max(t_lo, min(a, b)), min(t_hi, max(a, b))
            elif not lo[i] - 1e-12 <= f[i] <= hi[i] + 1e-12:
                return None
        if t_lo > t_hi + 1e-12:
            return None
        f += min(max(0.0, t_lo), t_hi) * n
        return np.minimum(np.maximum(f, lo), hi)

    def __call__(self, A: np.ndarray, w: np.ndarray, f_ref: np.ndarray,
                 attached: np.ndarray) -> np.ndarray:
        mask = attached.astype(float)
        lo, hi = self.lo * mask, self.hi * mask
        f_ref = f_ref * mask
        f = self.exact(A, w, f_ref, attached, lo, hi)
        if f is not None:
            return f
        H = A.T @ A
        H.flat[::NUM_BOOMS + 1] += self.rho
        g = A.T @ w + self.rho * f_ref
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
    (`TensionProjector`)."""

    def __init__(self, robot: RobotParams, gravity: np.ndarray, inertia: np.ndarray,
                 gains: ControlGains):
        super().__init__()
        self._statics = BodyStatics(robot, gravity)
        self._inertia = np.asarray(inertia, dtype=float)
        self._gains = gains
        self.projector = TensionProjector(robot.boom_tension, gains.feedforward_weight)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._desired = self.DeclareVectorInputPort("desired_state", 6)
        self._acceleration = self.DeclareVectorInputPort("desired_acceleration", 3)
        self._feedforward = self.DeclareVectorInputPort("feedforward_tension", NUM_BOOMS)
        self._free_tip = self.DeclareVectorInputPort("free_tip", 2)
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self.DeclareVectorOutputPort("tension", NUM_BOOMS, self._calc)

    def _calc(self, context: Context, output: BasicVector) -> None:
        x = self._state.Eval(context)
        xd = self._desired.Eval(context)
        stance = self._stance.Eval(context)
        pose = x[:3]
        error = xd[:3] - pose
        error[2] = (error[2] + math.pi) % (2.0 * math.pi) - math.pi
        g = self._gains
        wanted = (self._statics.load(pose, stance, self._free_tip.Eval(context))
                  + self._inertia * (self._acceleration.Eval(context) + g.kp * error
                                     + g.kd * (xd[3:] - x[3:])))
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

    `run` resets the context (time 0, the plan and draws as parameters, the body at the plan's
    first pose at rest unless `initial_state` is given, loggers cleared) and advances phase by
    phase, so integration steps end on the phase boundaries where the stance switches.
    """

    def __init__(self, scn: Scenario, gains: ControlGains | None = None,
                 sample_period: float = SAMPLE_PERIOD):
        robot, g = scn.robot, scn.gravity_vector
        self.scenario = scn
        self.sample_period = sample_period
        builder = DiagramBuilder()
        plant = builder.AddSystem(MultibodyPlant(0.0))
        plant.set_name("plant")
        w, h = robot.body_size
        body = plant.AddRigidBody("body", SpatialInertia.SolidBoxWithMass(
            robot.body_mass, w, h, BODY_THICKNESS))
        self.joint = plant.AddJoint(PlanarJoint("base", plant.world_frame(), body.body_frame()))
        plant.mutable_gravity_field().set_gravity_vector([g[0], g[1], 0.0])
        plant.Finalize()
        izz = robot.body_mass * (w**2 + h**2) / 12.0
        self.plant = plant
        self.source = builder.AddSystem(PlanSource())
        self.controller = builder.AddSystem(
            TensionController(robot, g, np.array([robot.body_mass, robot.body_mass, izz]),
                              gains or ControlGains()))
        booms = builder.AddSystem(BoomForces(robot, g))
        self.monitor = builder.AddSystem(GraspMonitor(robot))
        self.failures = builder.AddSystem(GraspFailures(sample_period))
        for name, system in (("plan", self.source), ("controller", self.controller),
                             ("booms", booms), ("monitor", self.monitor),
                             ("failures", self.failures)):
            system.set_name(name)
        state = plant.get_state_output_port()
        src, ctl = self.source, self.controller
        connect = builder.Connect
        for port in ("desired_state", "desired_acceleration", "feedforward_tension", "free_tip",
                     "stance"):
            connect(src.GetOutputPort(port), ctl.GetInputPort(port))
        connect(state, ctl.GetInputPort("state"))
        connect(state, booms.GetInputPort("state"))
        connect(ctl.GetOutputPort("tension"), booms.GetInputPort("tension"))
        connect(src.GetOutputPort("free_tip"), booms.GetInputPort("free_tip"))
        connect(src.GetOutputPort("stance"), booms.GetInputPort("stance"))
        connect(booms.GetOutputPort("generalized_force"),
                plant.get_applied_generalized_force_input_port())
        connect(state, self.monitor.GetInputPort("state"))
        connect(ctl.GetOutputPort("tension"), self.monitor.GetInputPort("tension"))
        connect(src.GetOutputPort("stance"), self.monitor.GetInputPort("stance"))
        connect(self.monitor.GetOutputPort("grasp"), self.failures.GetInputPort("grasp"))
        connect(src.GetOutputPort("phase"), self.failures.GetInputPort("phase"))
        logged = {"phase": src.GetOutputPort("phase"), "state": state,
                  "desired": src.GetOutputPort("desired_state"),
                  "tension": ctl.GetOutputPort("tension"),
                  "grasp": self.monitor.GetOutputPort("grasp")}
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
        failure when `stop_on_failure`). `progress(phase, phases, t)` after each phase."""
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
        plant_ctx = self.plant.GetMyMutableContextFromRoot(ctx)
        self.plant.SetPositionsAndVelocities(plant_ctx, np.asarray(initial_state, dtype=float))
        for logger in self.loggers.values():
            logger.FindMutableLog(ctx).Clear()
        self._stop = stop_on_failure
        self.simulator.Initialize()
        ends = [p.end for p in plan.phases]
        for k, end in enumerate(ends):
            if end > ctx.get_time():
                status = self.simulator.AdvanceTo(end)
                if status.reason() == status.ReturnReason.kReachedTerminationCondition:
                    break
            if progress is not None:
                progress(k + 1, len(ends), ctx.get_time())
        return self._record(plan)

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
                                grasp_log[:, 2 * NUM_BOOMS:], failure)
