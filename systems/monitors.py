"""The grasps during a run: each anchor's pull angle, force and grasp probability P_i
(GRASP_FIELDS; `AnchorLoadMonitor` from the full plant's joint reaction forces,
`GraspMonitor` from the body-only plant's tensions), and the stochastic failures.

`GraspFailures` compares the monitor's P_i with one drawn strength quantile per holding and an
attach draw per regrasp (module `montecarlo` explains the convention) and latches the first
failure (FAILURE_FIELDS, a `Failure` in the run's record), which stops the simulation.
"""

from __future__ import annotations

import math
from enum import IntEnum, nonmember
from typing import Any, NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from rb_drake import geometry, grasp
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.plant import ReachBotPlant
from rb_drake.stance import Stance
from systems.holdings import StrengthDraws
from systems.trajectory import FREE_LIMB_SIZE

GRASP_FIELDS = ("pull_angle", "force", "probability")  # the monitor's output, 4 values each
SLACK_FORCE = 1e-3  # N: below this a grasp's pull angle is its boom's (its pull has no direction)


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

    def __init__(self, rb: ReachBotPlant, robot: RobotParams, gravity: np.ndarray | None = None):
        super().__init__()
        plant = rb.plant
        self._robot = robot
        self._tip_mass = [tip.default_mass() for tip in rb.tips]
        self._g = np.zeros(2) if gravity is None else np.asarray(gravity, dtype=float)[:2]
        self._nq = plant.num_positions()
        self._q_base = rb.base.position_start()
        self._pose_rows = self._q_base + np.arange(3)
        self._q_sh = [j.position_start() for j in rb.shoulders]
        self._joints = [int(j.index()) for j in rb.booms]
        self._state = self.DeclareVectorInputPort(
            "state", plant.num_positions() + plant.num_velocities())
        self._reaction = self.DeclareAbstractInputPort(
            "reaction_forces", plant.get_reaction_forces_output_port().Allocate())
        self._stance = self.DeclareAbstractInputPort("stance", AbstractValue.Make(None))
        self._free_limb = self.DeclareVectorInputPort("free_limb", FREE_LIMB_SIZE)
        self.DeclareVectorOutputPort("grasp", 3 * NUM_BOOMS, self._calc)

    def pulls(self, context: Context) -> np.ndarray:
        """The booms' pulls on their grippers in the world, (4, 2). A boom in a release or
        attach ramp also holds a share of its gripper's weight (and its tip half of the boom,
        `LimbController`): that part does not load the grasp, so it is taken off."""
        q = self._state.Eval(context)[:self._nq]
        reaction = self._reaction.Eval(context)
        phi = float(q[self._q_base + 2])
        out = np.zeros((NUM_BOOMS, 2))
        for i in range(NUM_BOOMS):
            f = reaction[self._joints[i]].translational()  # along (x) and across the boom
            beta = phi + self._robot.shoulder_directions[i] + float(q[self._q_sh[i]])
            c, s = math.cos(beta), math.sin(beta)
            out[i] = (c * f[0] - s * f[1], s * f[0] + c * f[1])
        limb = self._free_limb.Eval(context)
        j = int(limb[5])
        if j >= 0 and self._stance.Eval(context).attached[j]:
            out[j] += (float(limb[6]) * self._tip_mass[j] + 0.5 * float(limb[4])) * self._g
        return out

    def _calc(self, context: Context, output: BasicVector) -> None:
        stance = self._stance.Eval(context)
        pull = self.pulls(context)
        force = np.linalg.norm(pull, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            direction = pull / force[:, None]
        normals = np.where(stance.attached[:, None], stance.normals, 1.0)
        psi = geometry.pull_angles(-direction, normals)  # pull_angles takes shoulder -> anchor
        # A slack boom's pull (a ramp's end) has no direction to speak of: it is the boom's
        slack = stance.attached & (force <= SLACK_FORCE)
        if slack.any():
            geo = geometry.boom_geometry(self._robot, self._state.Eval(context)[self._pose_rows],
                                         np.where(stance.attached[:, None], stance.positions,
                                                  0.0))
            psi = np.where(slack, geometry.pull_angles(geo.u[0], normals), psi)
        p = grasp.prob(force, psi, stance.f_normal, stance.f_lateral, stance.sigma_normal,
                       stance.sigma_lateral)
        out = np.concatenate([psi, force, p])
        out[np.tile(~stance.attached, 3)] = np.nan
        output.SetFromVector(out)


class Cause(IntEnum):
    """Why a grasp failed: its code in GraspFailures' state (0: none), and its `label` in a
    `Failure` and in the trial records."""

    OVERLOAD = 1  # the force exceeded the holding's drawn limit (or |psi| >= pi/2)
    ATTACH = 2    # a new grasp did not take hold on contact
    HANDOVER = 3  # a gripper had to open or close on a loaded boom: it did not, the climb stops

    # code -> label, for code that holds the bare int (GraspFailures' state, FirstFailures)
    NAMES = nonmember({OVERLOAD: "overload", ATTACH: "attach", HANDOVER: "handover"})

    @property
    def label(self) -> str:
        """"overload", "attach" or "handover", as records name the cause."""
        return self.name.lower()


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


class Failure(NamedTuple):
    time: float
    phase: int
    boom: int
    anchor: str
    cause: str
    probability: float
    draw: float
