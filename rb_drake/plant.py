"""A Drake MultibodyPlant of the planar ReachBot, generated from `RobotParams`.

The robot is described by a URDF string built from the parameters (so scenario overrides change
the plant): a `body` link on a planar joint `base` (q = x, y, phi in the world x-y plane) and,
per boom i, a revolute `shoulder{i}` (angle 0 = equilibrium direction) followed by a prismatic
`boom{i}` whose child link `tip{i}` carries the gripper mass at the boom tip.

Drake's q order is whatever the parser gives; `ReachBotPlant.q_order` maps it to the canonical
order q = [x, y, phi, theta_0, L_0, ..., theta_3, L_3] used by `rb_drake.geometry`.

With `hold_tips=True` (a discrete plant, SAP solver) every tip can be held at an anchor: per boom
an `anchor{i}` body on a planar joint from the world, kept locked, and a ball constraint between
`tip{i}` and it, switched on and off per stance (`ReachBotPlant.hold_tips`). The anchor bodies
move with the stance, so four constraints serve every anchor of a cave. Why not a constraint to
the world body: in pydrake 1.51 any SAP constraint (ball, weld) with the world body as one side
crashes the first discrete step (a segmentation fault); a body welded to the world works, and a
locked joint also lets the anchor move between stances.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.multibody.tree import (
    ModelInstanceIndex,
    MultibodyConstraintId,
    PlanarJoint,
    PrismaticJoint,
    RevoluteJoint,
    RigidBody,
    SpatialInertia,
)
from pydrake.systems.framework import Context, DiagramBuilder

from rb_drake import geometry
from rb_drake.params import NUM_BOOMS, RobotParams

MODEL_NAME = "reachbot"
BODY_THICKNESS = 0.05   # m, out of plane; only enters the body's inertia
ARM_MASS = 0.01         # kg, the small shoulder link between the revolute and prismatic joints
ARM_RADIUS = 0.02       # m, inertia of the arm link as a solid sphere
TIP_RADIUS = 0.03       # m, inertia (and visual) of the gripper as a solid sphere
MIN_MASS = 1e-6         # kg, stands in for a zero gripper mass (Drake needs positive masses)
ANCHOR_MASS = 1e-3      # kg, the anchor bodies of `hold_tips` (always locked: it never matters)


def _f(x: float) -> str:
    """A float written with full precision (repr round-trips exactly)."""
    return repr(float(x))


def _sphere_inertial(mass: float, radius: float) -> str:
    i = _sphere_moment(mass, radius)
    return (f'<inertial><origin xyz="0 0 0"/><mass value="{_f(mass)}"/>'
            f'<inertia ixx="{_f(i)}" ixy="0" ixz="0" iyy="{_f(i)}" iyz="0" izz="{_f(i)}"/>'
            f"</inertial>")


def _sphere_moment(mass: float, radius: float) -> float:
    return 0.4 * mass * radius**2


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
    arms: list[RigidBody] = dataclasses.field(default_factory=list)
    anchors: list[PlanarJoint] = dataclasses.field(default_factory=list)  # with hold_tips
    holds: list[MultibodyConstraintId] = dataclasses.field(default_factory=list)

    @staticmethod
    def canonical_q(pose: npt.ArrayLike, shoulder_angles: npt.ArrayLike,
                    lengths: npt.ArrayLike) -> np.ndarray:
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

    def hold_tips(self, context: Context, anchors: Sequence[Sequence[float] | None]) -> None:
        """Hold tip i at anchors[i] (x, y), or let it go (None): moves and locks the anchor
        body of boom i and switches its ball constraint. Only for a plant with `hold_tips`;
        changes the context, so call it between simulation steps (at a stance change)."""
        if not self.holds:
            raise ValueError("this plant was built without hold_tips")
        for joint, hold, anchor in zip(self.anchors, self.holds, anchors, strict=True):
            if anchor is not None:
                joint.set_translation(context, np.asarray(anchor, dtype=float)[:2])
                joint.set_rotation(context, 0.0)
            joint.Lock(context)
            self.plant.SetConstraintActiveStatus(context, hold, anchor is not None)

    def set_boom_masses(self, context: Context, masses: Sequence[float] | np.ndarray) -> None:
        """Give boom i the mass masses[i] (kg), half at its tip (with the gripper) and half at
        its shoulder (with the arm link): the weight, its moment about the shoulder and about
        any point equal a uniform boom's of that length (and mass). 0 restores the URDF's."""
        for arm, tip, m in zip(self.arms, self.tips, masses, strict=True):
            for body, radius in ((arm, ARM_RADIUS), (tip, TIP_RADIUS)):
                body.SetSpatialInertiaInBodyFrame(context, SpatialInertia.SolidSphereWithMass(
                    body.default_mass() + 0.5 * float(m), radius))



def build_plant(robot: RobotParams, gravity: Sequence[float] | np.ndarray = (0.0, -3.71),
                time_step: float = 0.0, builder: DiagramBuilder | None = None, *,
                hold_tips: bool = False, live_outputs: bool = False,
                joint_limits: bool = True) -> ReachBotPlant:
    """Parse `robot_urdf(robot)` into a new plant, set the in-plane gravity and Finalize it.

    With `builder`, the plant and a SceneGraph are added to it (AddMultibodyPlantSceneGraph);
    otherwise a standalone plant (cheap to scalar-convert) is made and `scene_graph` is None.
    Default boom lengths are the middle of their range (Drake's default 0 may violate it).
    `hold_tips` adds the anchor bodies and ball constraints of the module docstring (all
    active by default, holding the tips of the default configuration; `hold_tips` on a context
    locks the anchors and moves them); it needs a discrete plant (`time_step` > 0) and selects
    SAP. `live_outputs` makes a discrete plant's output ports (reaction forces, ...) reflect the
    context's state rather than the last step (Drake's default samples them; see
    `MultibodyPlant.SetUseSampledOutputPorts`). `joint_limits=False` removes the shoulder
    and boom limits from the dynamics (a discrete plant enforces them as constraints): the
    simulation uses it, since plans may sit on a limit, which in the model is a kinematic
    bound carrying no load, where a hard stop would take up the tracking error with torque.
    """
    if hold_tips and time_step <= 0.0:
        raise ValueError("hold_tips needs a discrete plant (time_step > 0): SAP constraints")
    if builder is None:
        plant, scene_graph = MultibodyPlant(time_step), None
    else:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step)
    if hold_tips:
        plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
    if live_outputs and time_step > 0.0:
        plant.SetUseSampledOutputPorts(False)
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
    if not joint_limits:
        for joint in (*shoulders, *booms):
            joint.set_position_limits([-np.inf], [np.inf])
    anchors, holds = [], []
    if hold_tips:
        inertia = SpatialInertia.SolidSphereWithMass(ANCHOR_MASS, ARM_RADIUS)
        # at the tips of the default configuration, so a default context is consistent
        default_tips = geometry.tip_positions(robot, np.zeros(3), np.zeros(NUM_BOOMS),
                                              np.full(NUM_BOOMS, 0.5 * (lo + hi)))
        for i, tip in enumerate(tips):
            body = plant.AddRigidBody(f"anchor{i}", model, inertia)
            joint = plant.AddJoint(PlanarJoint(f"anchor{i}", plant.world_frame(),
                                               body.body_frame()))
            joint.set_default_translation(default_tips[i])
            anchors.append(joint)
            holds.append(plant.AddBallConstraint(tip, np.zeros(3), body, np.zeros(3)))
    plant.Finalize()
    order = [base.position_start() + k for k in range(3)]
    for sh, boom in zip(shoulders, booms, strict=True):
        order += [sh.position_start(), boom.position_start()]
    arms = [plant.GetBodyByName(f"arm{i}", model) for i in range(NUM_BOOMS)]
    return ReachBotPlant(plant, scene_graph, model, base, shoulders, booms, tips,
                         np.asarray(order, dtype=int), arms, anchors, holds)
