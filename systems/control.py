"""The controllers: boom tensions for the body (`TensionController`), the free limb's joints
(`LimbController`, full plant) and, for the body-only plant, the booms as forces on the body
(`BoomForces`), all on the statics of one configuration in plain floats (`BodyStatics`).

The controller turns the plan's tensions and poses into boom commands: the wrench the body
needs (statics load at the actual pose plus a PD on the pose error, scaled by the body's mass
and inertia, plus the free limb's push) is made by the tensions nearest the plan's
feed-forward, within the tension bounds, trading a small acceleration error for large tension
changes where the bounds bind (`TensionProjector`). It is a feedthrough system, evaluated once
per plant step (the discrete plant samples its input).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions
from pydrake.systems.framework import BasicVector, Context, LeafSystem, ValueProducer

from planning.ramps import CONTROL_TENSION_FLOOR
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.plant import ReachBotPlant
from rb_drake.stance import Stance
from systems.trajectory import FREE_LIMB_SIZE, free_boom


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
        """The carried limb's weight on the body: [W_limb; tau_limb], times the share its
        shoulder carries (1 for the free boom, less in a release or attach ramp; zero when no
        shoulder carries a limb)."""
        j = int(free_limb[5])
        if j < 0:
            return np.zeros(3)
        share = float(free_limb[6])
        x, y, phi = (float(v) for v in pose[:3])
        c, s = math.cos(phi), math.sin(phi)
        sx, sy = self.shoulders[j]
        px, py = x + c * sx - s * sy, y + s * sx + c * sy
        tx, ty = float(free_limb[0]), float(free_limb[1])
        # free_limb's boom mass is already the share's (the plant's, in the full diagram)
        m_boom = (float(free_limb[4]) if self.fixed_boom_mass
                  else share * self.robot.boom_linear_density * math.hypot(tx - px, ty - py))
        m_grip = share * self.robot.gripper_mass
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


def control_bounds(robot: RobotParams) -> tuple[float, float]:
    """The tensions the controller may command to an anchored boom: the planner's upper bound,
    and below the planner's lower bound down to CONTROL_TENSION_FLOOR. The most robust
    allocation puts safe booms on the planner's bound; a controller held to it can only pull
    more on them, and in a 3-stance cannot make the wrench the pose loop asks for: crevasse
    seed 6's body turned until the geometry balanced, 18 mm off (docs/model.md, "The
    controller's tension floor")."""
    lo, hi = robot.boom_tension
    return min(lo, CONTROL_TENSION_FLOOR), hi


RAMP_WEIGHT = 1.0  # N of wrench error per N of a ramped boom's tension off its feed-forward


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
                 attached: np.ndarray, ramped: int = -1) -> np.ndarray:
        """`ramped`: a boom in a release or attach ramp (planning.ramps), which may go slack
        (lower bound 0) and keeps to its feed-forward (weight RAMP_WEIGHT): its gripper opens
        only on a slack boom, and the other three can make any wrench."""
        mask = attached.astype(float)
        lo, hi = self.lo * mask, self.hi * mask
        rho = np.full(NUM_BOOMS, self.rho)
        if ramped >= 0:
            lo[ramped], rho[ramped] = 0.0, RAMP_WEIGHT
        f_ref = f_ref * mask
        H = A.T @ A
        H.flat[::NUM_BOOMS + 1] += rho
        g = A.T @ w + rho * f_ref
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
        self.projector = TensionProjector(control_bounds(robot), gains.tension_weight)
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
        if self._tip_push is not None and free_boom(stance) is not None:
            px, py = (float(a) for a in self._tip_push.Eval(context))
            ax, ay = float(free_limb[0] - pose[0]), float(free_limb[1] - pose[1])
            wanted += (px, py, ax * py - ay * px)
        j = int(free_limb[5])
        ramped = j if j >= 0 and stance.attached[j] else -1
        output.SetFromVector(self.projector(self._statics.wrench_matrix(pose, stance), wanted,
                                            self._feedforward.Eval(context), stance.attached,
                                            ramped))


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
        j = int(self._free_limb.Eval(context)[5])
        if j >= 0:
            torque, force = self._command.Eval(context)[:2]
            u[self._v_sh[j]], u[self._v_boom[j]] = torque, force
        output.SetFromVector(u)

    def _calc_push(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._command.Eval(context)[2:])

    def _calc_command(self, context: Context, value: AbstractValue) -> None:
        """[shoulder torque, boom force, push_x, push_y] of the carried limb (zeros if none).
        A boom in a release or attach ramp has its gripper on its anchor: its joints only hold
        the share of its limb's weight (no PD: the gripper holds the tip, no push)."""
        limb = self._free_limb.Eval(context)
        j = int(limb[5])
        if j < 0:
            value.set_value(np.zeros(4))
            return
        x = self._state.Eval(context)
        if self._stance.Eval(context).attached[j]:
            value.set_value(self._ramp_hold(x, j, float(limb[4]), float(limb[6])))
            return
        q, v = x[:self._nq], x[self._nq:]
        b, vb = self._q_base, self._v_base
        phi, vx, vy, w = float(q[b + 2]), float(v[vb]), float(v[vb + 1]), float(v[vb + 2])
        c, s = math.cos(phi), math.sin(phi)
        sx, sy = self._shoulders[j]
        rx, ry = c * sx - s * sy, s * sx + c * sy
        tx, ty, tvx, tvy, boom_mass = (float(a) for a in limb[:5])
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

    def _ramp_hold(self, x: np.ndarray, j: int, boom_mass: float, share: float) -> np.ndarray:
        """The joints of boom j, gripper on its anchor, holding `share` of its gripper and the
        tip half of its boom (the plant's boom mass, already the share's): the body then
        carries that share of the limb's cantilevered weight, as the ramp's statics have it,
        and the gripper's anchor the rest of the gripper's weight."""
        q = x[:self._nq]
        phi = float(q[self._q_base + 2])
        theta, length = float(q[self._q_sh[j]]), float(q[self._q_boom[j]])
        beta = phi + self._alpha[j] + theta
        ex, ey = math.cos(beta), math.sin(beta)
        gx, gy = self._g
        m_tip = share * self._tip_mass[j] + 0.5 * boom_mass
        return np.array([-length * m_tip * (ex * gy - ey * gx), -m_tip * (ex * gx + ey * gy),
                         0.0, 0.0])
