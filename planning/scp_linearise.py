"""The linearisation of one SCP phase at an iterate: every quantity the convex subproblem needs
(boom lengths, shoulder angles, pull angles, moment arms, the grasp margins z and their log Phi
with slope and curvature, the statics residual, the free limb's shoulder torque) with its
analytic derivatives in the poses and tensions (`planning.scp` explains the method)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rb_drake import geometry
from rb_drake.grasp import (
    HALF_PI,
    log_ndtr_derivatives,
    mean_limit_derivative,
    sigma_limit_derivative,
)
from rb_drake.params import RobotParams
from rb_drake.stance import Stance


class Iterate(NamedTuple):
    poses: np.ndarray       # (N, 3)
    velocities: np.ndarray  # (N, 3)
    tensions: np.ndarray    # (N, n) of the attached booms (`PhaseProgram.att`), in order


class Linearisation(NamedTuple):
    """Values and pose/tension derivatives at an iterate; per boom arrays are (N, 4), their
    pose derivatives (N, 4, 3). Grasp quantities are 0 for a free boom."""

    length: np.ndarray
    length_dq: np.ndarray
    shoulder_angle: np.ndarray
    shoulder_angle_dq: np.ndarray
    pull_angle: np.ndarray
    pull_angle_dq: np.ndarray
    moment_arm: np.ndarray          # (R s_i) x u_i
    moment_arm_dq: np.ndarray
    mu: np.ndarray
    mu_dq: np.ndarray
    sigma: np.ndarray
    sigma_dq: np.ndarray
    z: np.ndarray
    z_dq: np.ndarray
    z_df: np.ndarray                # (N, 4) = -1/sigma
    log_prob: np.ndarray            # log Phi(z)
    slope: np.ndarray               # d log Phi / dz
    curvature: np.ndarray           # -d2 log Phi / dz2 > 0
    wrench: np.ndarray              # (N, 3) statics residual e = A f - b
    wrench_dq: np.ndarray           # (N, 3, 3)
    wrench_df: np.ndarray           # (N, 3, n) = A of the attached booms
    torque: np.ndarray              # (N,) free limb's shoulder torque (0 in a body phase)
    torque_dq: np.ndarray           # (N, 3)


def _perp(v: np.ndarray) -> np.ndarray:
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross_g(X: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Column-wise planar cross product X x g for X (..., 2, k)."""
    return X[..., 0, :] * g[1] - X[..., 1, :] * g[0]


def linearisation(robot: RobotParams, stance: Stance, gravity: np.ndarray, targets: np.ndarray,
                  tips: np.ndarray | None, it: Iterate) -> Linearisation:
    """Every linearised quantity of the subproblem at `it` (analytic derivatives), for booms
    that reach `targets` (N, 4, 2); in a reach phase `tips` (N, 2) is the free gripper's path."""
    st, g = stance, gravity
    held = np.flatnonzero(st.attached)                          # attached booms
    q = it.poses
    N = q.shape[0]
    r = geometry.shoulder_offsets(robot, q)                      # (N, 4, 2)
    d = targets - (q[:, None, :2] + r)
    L = np.linalg.norm(d, axis=-1)
    u = d / L[..., None]
    beta = np.arctan2(d[..., 1], d[..., 0])
    theta = geometry.wrap_angle(beta - q[:, 2, None] - robot.shoulder_directions)
    dd = np.zeros((N, 4, 2, 3))                                  # d d_i / d q
    dd[..., 0, 0] = -1.0
    dd[..., 1, 1] = -1.0
    dd[..., :, 2] = -_perp(r)
    L_dq = np.einsum("nbk,nbkj->nbj", u, dd)
    beta_dq = (d[..., 0, None] * dd[..., 1, :] - d[..., 1, None] * dd[..., 0, :]) / (
        L[..., None] ** 2)
    theta_dq = beta_dq - np.array([0.0, 0.0, 1.0])
    u_dq = _perp(u)[..., :, None] * beta_dq[..., None, :]       # (N, 4, 2, 3)
    arm = geometry.cross2(r, u)
    arm_dq = np.sum(r * u, axis=-1)[..., None] * theta_dq        # d(r x u) = (r.u) d theta

    att = st.attached
    normals = np.where(att[:, None], st.normals, 1.0)
    psi = np.where(att, geometry.pull_angles(u, normals), 0.0)
    psi_dq = np.where(att[:, None], beta_dq, 0.0)                # the normal is fixed
    fn, ft = np.where(att, st.f_normal, 1.0), np.where(att, st.f_lateral, 1.0)
    sn, sl = np.where(att, st.sigma_normal, 1.0), np.where(att, st.sigma_lateral, 1.0)
    psi_v = np.where(np.abs(psi) < HALF_PI, psi, 0.0)
    mu = np.where(att, st.mean_limit(psi_v), 1.0)
    sigma = np.where(att, st.sigma(psi_v), 1.0)
    mu_dq = mean_limit_derivative(psi_v, fn, ft)[..., None] * psi_dq
    sigma_dq = sigma_limit_derivative(psi_v, sn, sl)[..., None] * psi_dq
    f4 = np.zeros((N, 4))
    f4[:, held] = it.tensions
    z = np.where(att, (mu - f4) / sigma, 0.0)
    z_dq = np.where(att[:, None], (mu_dq - z[..., None] * sigma_dq) / sigma[..., None], 0.0)
    z_df = np.where(att, -1.0 / sigma, 0.0)
    lp, lam, d2 = log_ndtr_derivatives(z)
    lp = np.where(att, np.where(np.abs(psi) < HALF_PI, lp, -np.inf), 0.0)

    # statics residual e = A f - b = sum_i f_i [u_i; arm_i] + M g + [W_limb; tau_limb]
    A = np.concatenate([u, arm[..., None]], axis=-1).transpose(0, 2, 1)   # (N, 3, 4)
    A_dq = np.concatenate([u_dq, arm_dq[..., None, :]], axis=-2)         # (N, 4, 3, 3)
    e = np.einsum("nrb,nb->nr", A, f4)
    e[:, :2] += robot.body_mass * g
    e_dq = np.einsum("nbrj,nb->nrj", A_dq, f4)
    torque = np.zeros(N)
    torque_dq = np.zeros((N, 3))
    if st.free_boom is not None:
        j = st.free_boom
        assert tips is not None, "a reach phase (a free boom) has the free gripper's path"
        load = geometry.limb_load(robot, q, j, tips, g)
        e[:, :2] += load.force
        e[:, 2] += load.moment
        torque = load.shoulder_torque
        P = -dd[:, j]                                            # d p_j / d q (N, 2, 3)
        C = np.zeros((N, 2, 3))
        C[:, 0, 0] = C[:, 1, 1] = 1.0
        rho, mg = robot.boom_linear_density, robot.gripper_mass
        ell, ell_dq = L[:, j], L_dq[:, j]
        m_b = rho * ell
        shoulder = q[:, :2] + r[:, j]
        mid_c = 0.5 * (shoulder + tips) - q[:, :2]
        e_dq[:, :2, :] += rho * g[None, :, None] * ell_dq[:, None, :]
        e_dq[:, 2, :] += (rho * ell_dq * geometry.cross2(mid_c, g)[:, None]
                          + m_b[:, None] * _cross_g(0.5 * P - C, g) - mg * _cross_g(C, g))
        arm_tip = geometry.cross2(tips - shoulder, g)
        torque_dq = (0.5 * rho * ell_dq * arm_tip[:, None]
                     - (0.5 * m_b + mg)[:, None] * _cross_g(P, g))
    return Linearisation(
        L, L_dq, theta, theta_dq, psi, psi_dq, arm, arm_dq, mu, mu_dq, sigma, sigma_dq,
        z, z_dq, z_df, lp, lam, -d2, e, e_dq, A[:, :, held], torque, torque_dq)
