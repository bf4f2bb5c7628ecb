"""A Drake MultibodyPlant of the planar ReachBot, generated from `RobotParams`.

The robot is described by a URDF string built from the parameters (so scenario overrides change
the plant): a `body` link on a planar joint `base` (q = x, y, phi in the world x-y plane) and,
per boom i, a revolute `shoulder{i}` (angle 0 = equilibrium direction) followed by a prismatic
`boom{i}` whose child link `tip{i}` carries the gripper mass at the boom tip.

Drake's q order is whatever the parser gives; `ReachBotPlant.q_order` maps it to the canonical
order q = [x, y, phi, theta_0, L_0, ..., theta_3, L_3] used by `rb_drake.geometry`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import (
    JacobianWrtVariable,
    ModelInstanceIndex,
    PlanarJoint,
    PrismaticJoint,
    RevoluteJoint,
    RigidBody,
)
from pydrake.systems.framework import Context, DiagramBuilder

from rb_drake.params import NUM_BOOMS, RobotParams

MODEL_NAME = "reachbot"
BODY_THICKNESS = 0.05   # m, out of plane; only enters the body's inertia
ARM_MASS = 0.01         # kg, the small shoulder link between the revolute and prismatic joints
ARM_RADIUS = 0.02       # m, inertia of the arm link as a solid sphere
TIP_RADIUS = 0.03       # m, inertia (and visual) of the gripper as a solid sphere
MIN_MASS = 1e-6         # kg, stands in for a zero gripper mass (Drake needs positive masses)


def _f(x: float) -> str:
    """A float written with full precision (repr round-trips exactly)."""
    return repr(float(x))


def _sphere_inertial(mass: float, radius: float) -> str:
    i = 0.4 * mass * radius**2
    return (f'<inertial><origin xyz="0 0 0"/><mass value="{_f(mass)}"/>'
            f'<inertia ixx="{_f(i)}" ixy="0" ixz="0" iyy="{_f(i)}" iyz="0" izz="{_f(i)}"/>'
            f"</inertial>")


def robot_urdf(robot: RobotParams) -> str:
    """The URDF of `robot`: links body, arm0..3, tip0..3; joints base, shoulder0..3, boom0..3."""
    w, h = robot.body_size
    t = BODY_THICKNESS
    m = robot.body_mass
    ixx, iyy, izz = m * (h**2 + t**2) / 12, m * (w**2 + t**2) / 12, m * (w**2 + h**2) / 12
    tip_mass = robot.gripper_mass if robot.gripper_mass > 0 else MIN_MASS
    rng = robot.shoulder_range
    lo, hi = robot.boom_length
    parts = [
        f'<?xml version="1.0"?>\n<robot name="{MODEL_NAME}">',
        '<link name="body">'
        f'<inertial><origin xyz="0 0 0"/><mass value="{_f(m)}"/>'
        f'<inertia ixx="{_f(ixx)}" ixy="0" ixz="0" iyy="{_f(iyy)}" iyz="0" izz="{_f(izz)}"/>'
        "</inertial>"
        f'<visual><geometry><box size="{_f(w)} {_f(h)} {_f(t)}"/></geometry></visual>'
        "</link>",
        '<joint name="base" type="planar"><parent link="world"/><child link="body"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>',
    ]
    for i in range(NUM_BOOMS):
        sx, sy = robot.shoulders[i]
        yaw = math.radians(robot.shoulder_directions_deg[i])
        parts += [
            f'<link name="arm{i}">{_sphere_inertial(ARM_MASS, ARM_RADIUS)}</link>',
            f'<link name="tip{i}">{_sphere_inertial(tip_mass, TIP_RADIUS)}'
            f'<visual><geometry><sphere radius="{_f(TIP_RADIUS)}"/></geometry></visual></link>',
            f'<joint name="shoulder{i}" type="revolute"><parent link="body"/>'
            f'<child link="arm{i}"/><origin xyz="{_f(sx)} {_f(sy)} 0" rpy="0 0 {_f(yaw)}"/>'
            f'<axis xyz="0 0 1"/><limit lower="{_f(-rng)}" upper="{_f(rng)}" effort="'
            f'{_f(robot.shoulder_torque_max)}" velocity="10"/></joint>',
            f'<joint name="boom{i}" type="prismatic"><parent link="arm{i}"/>'
            f'<child link="tip{i}"/><origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>'
            f'<limit lower="{_f(lo)}" upper="{_f(hi)}" effort="'
            f'{_f(robot.boom_tension[1])}" velocity="10"/></joint>',
        ]
    parts.append("</robot>\n")
    return "\n".join(parts)


@dataclasses.dataclass(frozen=True)
class ReachBotPlant:
    """A finalized ReachBot plant with handles to its joints and tip bodies.

    `q_order[k]` is the index in Drake's q of the k-th canonical coordinate
    [x, y, phi, theta_0, L_0, ..., theta_3, L_3].
    """

    plant: MultibodyPlant
    scene_graph: object | None
    model: ModelInstanceIndex
    base: PlanarJoint
    shoulders: list[RevoluteJoint]
    booms: list[PrismaticJoint]
    tips: list[RigidBody]
    q_order: np.ndarray

    def q_from(self, pose: Sequence[float], shoulder_angles: Sequence[float],
               lengths: Sequence[float]) -> np.ndarray:
        """Drake's q vector for pose (x, y, phi), shoulder angles (4,) and boom lengths (4,)."""
        q = np.zeros(self.plant.num_positions())
        q[self.q_order] = self.canonical_q(pose, shoulder_angles, lengths)
        return q

    @staticmethod
    def canonical_q(pose: Sequence[float], shoulder_angles: Sequence[float],
                    lengths: Sequence[float]) -> np.ndarray:
        """The canonical q = [x, y, phi, theta_0, L_0, ..., theta_3, L_3]."""
        joints = np.stack([np.asarray(shoulder_angles, dtype=float),
                           np.asarray(lengths, dtype=float)], axis=-1).reshape(-1)
        return np.concatenate([np.asarray(pose, dtype=float).reshape(3), joints])

    def tip_positions(self, context: Context) -> np.ndarray:
        """World x-y positions of the four boom tips, shape (4, 2)."""
        world = self.plant.world_frame()
        return np.array([
            self.plant.CalcPointsPositions(context, tip.body_frame(), np.zeros(3), world)[:2, 0]
            for tip in self.tips])

    def tip_jacobian(self, context: Context, boom: int) -> np.ndarray:
        """d tip_boom / d q (x-y rows), columns in the canonical q order, shape (2, nq)."""
        world = self.plant.world_frame()
        J = self.plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kQDot, self.tips[boom].body_frame(), np.zeros(3),
            world, world)
        return J[:2, self.q_order]


def build_plant(robot: RobotParams, gravity: Sequence[float] = (0.0, -3.71),
                time_step: float = 0.0, builder: DiagramBuilder | None = None) -> ReachBotPlant:
    """Parse `robot_urdf(robot)` into a new plant, set the in-plane gravity and Finalize it.

    With `builder`, the plant and a SceneGraph are added to it (AddMultibodyPlantSceneGraph);
    otherwise a standalone plant (cheap to scalar-convert) is made and `scene_graph` is None.
    Default boom lengths are the middle of their range (Drake's default 0 may violate it).
    """
    if builder is None:
        plant, scene_graph = MultibodyPlant(time_step), None
    else:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step)
    (model,) = Parser(plant).AddModelsFromString(robot_urdf(robot), "urdf")
    gx, gy = (float(g) for g in gravity)
    plant.mutable_gravity_field().set_gravity_vector([gx, gy, 0.0])
    base = plant.GetJointByName("base", model)
    shoulders = [plant.GetJointByName(f"shoulder{i}", model) for i in range(NUM_BOOMS)]
    booms = [plant.GetJointByName(f"boom{i}", model) for i in range(NUM_BOOMS)]
    tips = [plant.GetBodyByName(f"tip{i}", model) for i in range(NUM_BOOMS)]
    lo, hi = robot.boom_length
    for boom in booms:
        boom.set_default_translation(0.5 * (lo + hi))
    plant.Finalize()
    order = [base.position_start() + k for k in range(3)]
    for sh, boom in zip(shoulders, booms, strict=True):
        order += [sh.position_start(), boom.position_start()]
    return ReachBotPlant(plant, scene_graph, model, base, shoulders, booms, tips,
                         np.asarray(order, dtype=int))
