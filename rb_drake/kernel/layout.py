"""The data the compiled kernels read, and its packing: the robot, gravity and the feasibility
constants as one float array addressed by `Param`, and the states of the flood fill's body
cache (`BodyKnown`).

The constants that decide (limits, MIN_CONDITIONING, REGULARISATION, ...) reach the kernels as
this data, not as globals, so that numba's on-disk cache can never hold stale ones (see
`rb_drake.kernel`). Compiled code reads the plain-int copies of the IntEnum codes (`P_L_LO` for
`Param.L_LO`, `REASON_STATICS` for `feasibility.Reason.STATICS`, `BODY_CLEAR` for
`BodyKnown.CLEAR`): numba compiles an IntEnum member as the constant it stands for, but typing
its uses costs compile time (below).
"""

from __future__ import annotations

import math
from enum import IntEnum
from functools import lru_cache
from statistics import NormalDist

import numpy as np

from rb_drake.collision import ANCHOR_CLEARANCE
from rb_drake.feasibility import MIN_CONDITIONING, Reason
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.statics import REGULARISATION, STATICS_TOL


class Param(IntEnum):
    """Index of each value in the packed parameter array (`robot_params`)."""

    SHOULDER = 0          # 2 NUM_BOOMS values: x0, y0, ..., x3, y3 (body frame)
    DIRECTION = 8         # NUM_BOOMS values: equilibrium directions (rad)
    RANGE = 12            # shoulder range (rad)
    L_LO = 13             # boom length bounds
    L_HI = 14
    F_LO = 15             # boom tension bounds
    F_HI = 16
    TORQUE_MAX = 17
    GRIPPER_MASS = 18
    DENSITY = 19          # boom linear density
    BODY_MASS = 20
    WIDTH = 21            # body size
    HEIGHT = 22
    LOG_P_MIN = 23
    GRAVITY = 24          # 2 values
    MOMENT_SCALE = 26     # 1 / largest shoulder distance, as in wrench_conditioning
    MIN_CONDITIONING = 27
    REGULARISATION = 28
    STATICS_TOL = 29
    CLEARANCE = 30
    Z_FLOOR = 31          # Phi^-1(p_min), less a margin: no grasp of a feasible pose has a lower z
    MAX_PULL = 32         # robot.max_pull_angle (rad): the PULL_ANGLE test's limit


PARAM_COUNT = Param.MAX_PULL + 1  # the packed array's length


class BodyKnown(IntEnum):
    """What the flood fill knows of a pose's body against the rock (the int8 body cache of
    `pose_kernel.score_kernel` and `planning.flood_kernel`): the body's test depends on the
    pose alone, so it is shared by every stance scored there."""

    UNKNOWN = 0
    CLEAR = 1
    IN_ROCK = 2


# Plain-int copies of the codes above and of feasibility.Reason, for compiled code: numba types
# an IntEnum member as a type of its own, and resolving the kernel's hundred or so uses cost 3 %
# of the pose kernel's compile time (measured: 0.97x its CPU seconds with these, the median of
# four runs each, all within 0.96-0.98x), where an int global compiles as a literal does.
P_SHOULDER = int(Param.SHOULDER)
P_DIRECTION = int(Param.DIRECTION)
P_RANGE = int(Param.RANGE)
P_L_LO = int(Param.L_LO)
P_L_HI = int(Param.L_HI)
P_F_LO = int(Param.F_LO)
P_F_HI = int(Param.F_HI)
P_TORQUE_MAX = int(Param.TORQUE_MAX)
P_GRIPPER_MASS = int(Param.GRIPPER_MASS)
P_DENSITY = int(Param.DENSITY)
P_BODY_MASS = int(Param.BODY_MASS)
P_WIDTH = int(Param.WIDTH)
P_HEIGHT = int(Param.HEIGHT)
P_LOG_P_MIN = int(Param.LOG_P_MIN)
P_GRAVITY = int(Param.GRAVITY)
P_MOMENT_SCALE = int(Param.MOMENT_SCALE)
P_MIN_CONDITIONING = int(Param.MIN_CONDITIONING)
P_REGULARISATION = int(Param.REGULARISATION)
P_STATICS_TOL = int(Param.STATICS_TOL)
P_CLEARANCE = int(Param.CLEARANCE)
P_Z_FLOOR = int(Param.Z_FLOOR)
P_MAX_PULL = int(Param.MAX_PULL)
REASON_BOOM_LENGTH = int(Reason.BOOM_LENGTH)
REASON_SHOULDER_ANGLE = int(Reason.SHOULDER_ANGLE)
REASON_BODY_COLLISION = int(Reason.BODY_COLLISION)
REASON_BOOM_COLLISION = int(Reason.BOOM_COLLISION)
REASON_PULL_ANGLE = int(Reason.PULL_ANGLE)
REASON_SHOULDER_TORQUE = int(Reason.SHOULDER_TORQUE)
REASON_SINGULAR = int(Reason.SINGULAR)
REASON_STATICS = int(Reason.STATICS)
REASON_PROBABILITY = int(Reason.PROBABILITY)
BODY_UNKNOWN = int(BodyKnown.UNKNOWN)
BODY_CLEAR = int(BodyKnown.CLEAR)
BODY_IN_ROCK = int(BodyKnown.IN_ROCK)


# `score_rows(collide=)`: bit i boom i's segment, bit NUM_BOOMS the body
BODY_SEGMENT = 1 << NUM_BOOMS
ALL_SEGMENTS = (1 << (NUM_BOOMS + 1)) - 1
ALL_BOOMS = (1 << NUM_BOOMS) - 1  # `score_kernel(release_booms=)`: every boom's release


def robot_params(robot: RobotParams, gravity: np.ndarray) -> np.ndarray:
    """The robot, gravity and the feasibility constants as one float array (`Param`), packed
    once per robot and gravity, keyed by their values (the robot is a frozen dataclass: a
    planner asks for the same one thousands of times, with its gravity for scoring and
    without for the lattice's reach tests). The array is shared: do not write to it."""
    return _pack_robot(robot, float(gravity[0]), float(gravity[1]))


@lru_cache(maxsize=16)
def _pack_robot(robot: RobotParams, g_x: float, g_y: float) -> np.ndarray:
    p = np.empty(PARAM_COUNT)
    p[Param.SHOULDER:Param.SHOULDER + 2 * NUM_BOOMS] = robot.shoulder_array.ravel()
    p[Param.DIRECTION:Param.DIRECTION + NUM_BOOMS] = robot.shoulder_directions
    p[Param.RANGE] = robot.shoulder_range
    p[Param.L_LO], p[Param.L_HI] = robot.boom_length
    p[Param.F_LO], p[Param.F_HI] = robot.boom_tension
    p[Param.TORQUE_MAX] = robot.shoulder_torque_max
    p[Param.GRIPPER_MASS] = robot.gripper_mass
    p[Param.DENSITY] = robot.boom_linear_density
    p[Param.BODY_MASS] = robot.body_mass
    p[Param.WIDTH], p[Param.HEIGHT] = robot.body_size
    p[Param.LOG_P_MIN] = robot.log_p_min
    p[Param.GRAVITY], p[Param.GRAVITY + 1] = g_x, g_y
    p[Param.MOMENT_SCALE] = 1.0 / float(np.linalg.norm(robot.shoulder_array, axis=1).max())
    p[Param.MIN_CONDITIONING] = MIN_CONDITIONING
    p[Param.REGULARISATION] = REGULARISATION
    p[Param.STATICS_TOL] = STATICS_TOL
    p[Param.CLEARANCE] = ANCHOR_CLEARANCE
    # A feasible pose has r = sum_i log P_i >= log p_min with every term <= 0, so each grasp's
    # z is at least Phi^-1(p_min); the margin keeps the bound from deciding a rounding tie.
    p_min = math.exp(robot.log_p_min)
    p[Param.Z_FLOOR] = NormalDist().inv_cdf(p_min) - 1e-6 if 0.0 < p_min < 1.0 else -math.inf
    p[Param.MAX_PULL] = robot.max_pull_angle
    return p
