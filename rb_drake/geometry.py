"""Vectorised planar geometry of ReachBot: shoulders, booms, angles, wrenches, free-limb loads.

Conventions (see docs/model.md): world frame x right, y up; pose = (x, y, phi) of the body
centre (which is its centre of mass) with phi counter-clockwise; `cross(a, b) = a_x b_y - a_y b_x`.
Every function takes poses of shape (P, 3) (or (3,), treated as P = 1 and squeezed by the
caller) and works on all P poses and all four booms at once: the planner's hot loops evaluate
thousands of configurations, so there is no Python loop per pose here.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rb_drake.params import RobotParams


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap to [-pi, pi)."""
    w = (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi
    return np.where(w >= np.pi, w - 2.0 * np.pi, w)  # rounding in % can land on +pi


def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z-component of the cross product of planar vectors (last axis of size 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def perp(v: np.ndarray) -> np.ndarray:
    """v rotated by +90 degrees."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def rotate(phi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(phi) v, with phi of shape (P,) and v of shape (..., 2) broadcast as (P, ..., 2)."""
    c, s = np.cos(phi), np.sin(phi)
    extra = (1,) * (v.ndim - 1)
    c = c.reshape(c.shape + extra)
    s = s.reshape(s.shape + extra)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def as_poses(poses: np.ndarray) -> np.ndarray:
    poses = np.asarray(poses, dtype=float)
    return poses.reshape(-1, 3)


def shoulder_offsets(robot: RobotParams, poses: np.ndarray) -> np.ndarray:
    """R(phi) s_i: shoulders relative to the body centre in the world frame, (P, 4, 2)."""
    poses = as_poses(poses)
    return rotate(poses[:, 2], robot.shoulder_array)


def shoulder_positions(robot: RobotParams, poses: np.ndarray) -> np.ndarray:
    """p_i = (x, y) + R(phi) s_i, shape (P, 4, 2)."""
    poses = as_poses(poses)
    return poses[:, None, :2] + shoulder_offsets(robot, poses)


def body_corners(robot: RobotParams, poses: np.ndarray) -> np.ndarray:
    """The body square's corners, counter-clockwise, shape (P, 4, 2)."""
    poses = as_poses(poses)
    w, h = robot.body_size
    local = np.array([[w / 2, h / 2], [-w / 2, h / 2], [-w / 2, -h / 2], [w / 2, -h / 2]])
    return poses[:, None, :2] + rotate(poses[:, 2], local)


class BoomGeometry(NamedTuple):
    """Per pose and boom: the vector shoulder -> target, its length and unit vector, and the
    shoulder angle from the boom's equilibrium direction. Shapes (P, 4, 2) and (P, 4)."""

    shoulders: np.ndarray
    d: np.ndarray
    length: np.ndarray
    u: np.ndarray
    shoulder_angle: np.ndarray


def boom_geometry(robot: RobotParams, poses: np.ndarray, targets: np.ndarray) -> BoomGeometry:
    """Booms from each shoulder to its target point; targets (4, 2) or (P, 4, 2)."""
    poses = as_poses(poses)
    p = shoulder_positions(robot, poses)
    d = np.asarray(targets, dtype=float) - p
    length = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / length[..., None]
    beta = np.arctan2(d[..., 1], d[..., 0])
    retracted = length == 0.0  # the shoulder on its target: the boom points along its shoulder
    if retracted.any():
        axis = np.broadcast_to(poses[:, 2, None] + robot.shoulder_directions, length.shape)
        beta = np.where(retracted, axis, beta)
        u = np.where(retracted[..., None], np.stack([np.cos(axis), np.sin(axis)], axis=-1), u)
    theta = wrap_angle(beta - poses[:, 2, None] - robot.shoulder_directions)
    return BoomGeometry(p, d, length, u, theta)


def pull_angles(u: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """psi: signed angle from the anchor's outward normal to the pull direction anchor -> shoulder.

    `u` points shoulder -> anchor, so the grasp is pulled along v = -u.
    """
    v = -u
    return np.arctan2(cross2(normals, v), np.sum(normals * v, axis=-1))


def wrench_matrix(robot: RobotParams, poses: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Columns [u_i; (R s_i) x u_i]: the body wrench of a unit tension in boom i, (P, 3, 4)."""
    r = shoulder_offsets(robot, poses)
    return np.stack([u[..., 0], u[..., 1], cross2(r, u)], axis=-2)


class LimbLoad(NamedTuple):
    """The free limb's weight as an external load, per pose (shapes (P, 2), (P,), (P,))."""

    force: np.ndarray          # its weight, a world-frame force on the robot
    moment: np.ndarray         # its moment about the body centre
    shoulder_torque: np.ndarray  # its moment about its own shoulder (what the shoulder resists)


def limb_load(robot: RobotParams, poses: np.ndarray, boom: int, tip: np.ndarray,
              gravity: np.ndarray) -> LimbLoad:
    """The cantilevered free boom `boom` with its gripper at `tip` ((2,) or (P, 2)).

    The boom's mass (linear density times length) acts at its midpoint, the gripper's at the tip.
    """
    poses = as_poses(poses)
    g = np.asarray(gravity, dtype=float)
    shoulder = shoulder_positions(robot, poses)[:, boom, :]
    tip = np.broadcast_to(np.asarray(tip, dtype=float), shoulder.shape)
    length = np.linalg.norm(tip - shoulder, axis=-1)
    m_boom = robot.boom_linear_density * length
    m_grip = robot.gripper_mass
    mid = 0.5 * (shoulder + tip)
    force = (m_boom + m_grip)[:, None] * g
    centre = poses[:, :2]
    moment = m_boom * cross2(mid - centre, g) + m_grip * cross2(tip - centre, g)
    torque = m_boom * cross2(mid - shoulder, g) + m_grip * cross2(tip - shoulder, g)
    return LimbLoad(force, moment, torque)


class Reach(NamedTuple):
    """Whether boom booms[k] at each pose can reach targets[k]: shapes (P, K)."""

    length: np.ndarray
    shoulder_angle: np.ndarray
    violation: np.ndarray  # excess over the length and angle limits (m + rad); 0: reachable


def reach(robot: RobotParams, poses: np.ndarray, targets: np.ndarray,
          booms: np.ndarray) -> Reach:
    """Kinematic reach of boom booms[k] to point targets[k] ((K, 2)) at every pose."""
    poses = as_poses(poses)
    d = np.asarray(targets, dtype=float) - shoulder_positions(robot, poses)[:, booms, :]
    length = np.linalg.norm(d, axis=-1)
    theta = wrap_angle(np.arctan2(d[..., 1], d[..., 0]) - poses[:, 2, None]
                       - robot.shoulder_directions[booms])
    lo, hi = robot.boom_length
    excess = (np.maximum(0, length - hi) + np.maximum(0, lo - length)
              + np.maximum(0, np.abs(theta) - robot.shoulder_range))
    return Reach(length, theta, excess)


class PoseJacobians(NamedTuple):
    """Derivatives with respect to the pose (x, y, phi), shapes (P, 4, 3)."""

    length: np.ndarray
    shoulder_angle: np.ndarray
    pull_angle: np.ndarray


def pose_jacobians(robot: RobotParams, poses: np.ndarray, targets: np.ndarray) -> PoseJacobians:
    """d(boom length), d(shoulder angle), d(pull angle) / d pose for booms to fixed targets."""
    poses = as_poses(poses)
    geo = boom_geometry(robot, poses, targets)
    r = shoulder_offsets(robot, poses)
    P = poses.shape[0]
    # d d_i / d pose = -[e_x, e_y, perp(R s_i)], shape (P, 4, 2, 3)
    dd = np.zeros((P, 4, 2, 3))
    dd[..., 0, 0] = -1.0
    dd[..., 1, 1] = -1.0
    dd[..., :, 2] = -perp(r)
    dlength = np.einsum("pbk,pbkj->pbj", geo.u, dd)
    # d atan2(d) = cross(d, dd) / |d|^2
    dbeta = (geo.d[..., 0, None] * dd[..., 1, :] - geo.d[..., 1, None] * dd[..., 0, :]) / (
        geo.length[..., None] ** 2)
    dtheta = dbeta.copy()
    dtheta[..., 2] -= 1.0
    # psi = angle(-d) - angle(n): the normal is fixed, so d psi = d beta.
    return PoseJacobians(dlength, dtheta, dbeta)


def tip_positions(robot: RobotParams, pose: np.ndarray, shoulder_angles: np.ndarray,
                  lengths: np.ndarray) -> np.ndarray:
    """Forward kinematics of the four boom tips from joint values, shape (4, 2)."""
    pose = np.asarray(pose, dtype=float)
    p = shoulder_positions(robot, pose)[0]
    a = pose[2] + robot.shoulder_directions + np.asarray(shoulder_angles)
    return p + np.asarray(lengths)[:, None] * np.stack([np.cos(a), np.sin(a)], axis=-1)
