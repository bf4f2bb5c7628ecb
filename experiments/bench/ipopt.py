"""One phase as a single nonlinear program solved by IPOPT, the scp section's comparison (see
the package doc): the exact geometry written independently of rb_drake, differentiated by
Drake (AutoDiffXd)."""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np
from scipy.special import log_ndtr

from experiments.bench.phases import Segment
from rb_drake.grasp import mills_ratio
from rb_drake.params import NUM_BOOMS

POSE_BOX = np.array([0.5, 0.5, 0.5])  # m, m, rad: IPOPT's box around the seed's extent
SPEED_BOX = 1.0          # m/s, rad/s: IPOPT's bound on velocities (seeds move at 0.1 m/s)


def _log_ndtr_any(z: Any) -> Any:
    """log Phi for floats and for Drake's AutoDiffXd (value by log_ndtr, slope the Mills
    ratio), so that Drake can differentiate the exact objective."""
    from pydrake.autodiffutils import AutoDiffXd

    if isinstance(z, AutoDiffXd):
        v = z.value()
        return AutoDiffXd(float(log_ndtr(v)), float(mills_ratio(v)) * z.derivatives())
    return log_ndtr(z)


class NonlinearPhase:
    """One phase as a single nonlinear program for IPOPT (see the package doc).

    Variables per step k: pose q_k, velocity v_k, attached tensions f_k and r_k (the step's
    robustness, tied to the geometry by an equality, so that the cost is linear and the floor
    a bound); w bounds the largest pose increment per coordinate (smoothness epigraph, as in
    planning.scp). Per step one vector constraint, exact and smooth away from the kinks of
    |psi| and of the limits: statics residual A f - b = 0, boom lengths and shoulder angles
    within limits, cos psi_i >= 1e-3 (a grasp pulled at 90 degrees has P = 0), r_k equal to
    sum log Phi(z_i) and, in a reach phase, the free limb's shoulder torque within its limit.
    The cost is planning.scp's merit, negated."""

    def __init__(self, segment: Segment, dt: float, config: Any, floor: float,
                 max_iterations: int = 1000):
        from pydrake.solvers import IpoptSolver, MathematicalProgram, SolverOptions

        scn, stance = segment.scn, segment.stance
        self.robot = robot = scn.robot
        self.g = np.asarray(scn.gravity_vector, dtype=float)
        self.stance, self.free, self.tips = stance, stance.free_boom, segment.tips
        self.att = np.flatnonzero(stance.attached)
        N, n = len(segment.poses), len(self.att)
        self.N, self.n = N, n
        self.targets = np.broadcast_to(np.where(stance.attached[:, None], stance.positions, 0.0),
                                       (N, 4, 2)).copy()
        if self.free is not None:
            self.targets[:, self.free] = segment.tips
        prog = MathematicalProgram()
        self.q = prog.NewContinuousVariables(N, 3, "pose")
        self.v = prog.NewContinuousVariables(N, 3, "velocity")
        self.f = prog.NewContinuousVariables(N, n, "tension")
        self.r = prog.NewContinuousVariables(N, "robustness")
        self.w = prog.NewContinuousVariables(3, "largest_increment")
        start, goal = segment.poses[0], segment.poses[-1]
        prog.AddBoundingBoxConstraint(start, start, self.q[0])
        prog.AddBoundingBoxConstraint(goal, goal, self.q[-1])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), self.v[0])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), self.v[-1])
        lo, hi = robot.boom_tension
        prog.AddBoundingBoxConstraint(lo, hi, self.f.ravel())
        prog.AddBoundingBoxConstraint(floor, 0.0, self.r)
        # Interior-point methods need bounded variables: a box far from anything optimal
        # (the seed's extent grown by POSE_BOX, speeds up to SPEED_BOX).
        low = segment.poses.min(axis=0) - POSE_BOX
        high = segment.poses.max(axis=0) + POSE_BOX
        prog.AddBoundingBoxConstraint(np.tile(low, N), np.tile(high, N), self.q.ravel())
        prog.AddBoundingBoxConstraint(-SPEED_BOX, SPEED_BOX, self.v.ravel())
        prog.AddBoundingBoxConstraint(0.0, 2.0 * POSE_BOX.max(), self.w)
        lb, ub = self._limits()
        for k in range(N):
            prog.AddConstraint(lambda x, k=k: self._timed_step_values(k, x), lb, ub,
                               np.concatenate([self.q[k], self.f[k], [self.r[k]]]))
        for k in range(N - 1):  # |q_{k+1,c} - q_{k,c}| <= w_c
            d = np.hstack([-np.eye(3), np.eye(3)])
            x = np.concatenate([self.q[k], self.q[k + 1], self.w])
            prog.AddLinearConstraint(np.hstack([d, -np.eye(3)]), np.full(3, -np.inf),
                                     np.zeros(3), x)
            prog.AddLinearConstraint(np.hstack([d, np.eye(3)]), np.zeros(3),
                                     np.full(3, np.inf), x)
        self.config = cfg = config
        self.dynamics = dynamics_matrix(robot, N, dt)
        prog.AddQuadraticCost(cfg.dynamics_weight * self.dynamics.T @ self.dynamics,
                              np.zeros(6 * N), np.concatenate([self.q.ravel(), self.v.ravel()]),
                              is_convex=True)
        prog.AddLinearCost(np.full(N, -cfg.robustness_weight), 0.0, self.r)
        prog.AddLinearCost(np.full(3, cfg.smoothness_weight), 0.0, self.w)
        self.prog = prog
        self.callback_seconds = 0.0  # spent in step_values called by IPOPT (Python, AutoDiff)
        self.solver = IpoptSolver()
        self.options = SolverOptions()
        # Stop on a small gradient, or once the merit stalls (it changes by less than 1e-6 for
        # 10 acceptable iterations; SCP stops when its model predicts a gain below 1e-4).
        for key, val in (("tol", 1e-6), ("acceptable_tol", 1e-4), ("acceptable_iter", 10),
                         ("acceptable_obj_change_tol", 1e-6), ("constr_viol_tol", 1e-9),
                         ("max_iter", int(max_iterations)), ("print_level", 0)):
            self.options.SetOption(IpoptSolver.id(), key, val)
        self.options.SetOption(IpoptSolver.id(), "sb", "yes")

    def _limits(self) -> tuple[np.ndarray, np.ndarray]:
        robot = self.robot
        L_lo, L_hi = robot.boom_length
        rng = robot.shoulder_range
        lb = [0.0] * 3 + [L_lo] * 4 + [-rng] * 4 + [1e-3] * self.n + [0.0]
        ub = [0.0] * 3 + [L_hi] * 4 + [rng] * 4 + [1.0] * self.n + [0.0]
        if self.free is not None:
            lb.append(-robot.shoulder_torque_max)
            ub.append(robot.shoulder_torque_max)
        return np.array(lb), np.array(ub)

    def _timed_step_values(self, k: int, x: np.ndarray) -> np.ndarray:
        t = time.perf_counter()
        out = self.step_values(k, x)
        self.callback_seconds += time.perf_counter() - t
        return out

    def step_values(self, k: int, x: np.ndarray) -> np.ndarray:
        """Step k's constraint values from [q_k, f_k, r_k] (floats or AutoDiffXd): written out
        boom by boom from docs/model.md, independently of rb_drake.geometry."""
        robot, st, g = self.robot, self.stance, self.g
        X, Y, phi = x[0], x[1], x[2]
        c, s = np.cos(phi), np.sin(phi)
        ex, ey, mz = robot.body_mass * g[0], robot.body_mass * g[1], 0.0
        r, torque = 0.0, 0.0
        lengths, angles, pulls = [], [], []
        a = 0
        for i in range(NUM_BOOMS):
            sx, sy = robot.shoulders[i]
            rx, ry = c * sx - s * sy, s * sx + c * sy           # R(phi) s_i
            tx, ty = self.targets[k, i]
            dx, dy = tx - X - rx, ty - Y - ry                   # shoulder -> target
            length = np.sqrt(dx * dx + dy * dy)
            ca, sa = math.cos(robot.shoulder_directions[i]), math.sin(robot.shoulder_directions[i])
            axis_x, axis_y = c * ca - s * sa, s * ca + c * sa   # equilibrium direction
            lengths.append(length)
            angles.append(np.arctan2(axis_x * dy - axis_y * dx, axis_x * dx + axis_y * dy))
            if i == self.free:
                # the cantilevered limb: boom mass at its midpoint, gripper at the tip
                m_b, m_g = robot.boom_linear_density * length, robot.gripper_mass
                px, py = X + rx, Y + ry
                mx, my = 0.5 * (px + tx), 0.5 * (py + ty)
                ex, ey = ex + (m_b + m_g) * g[0], ey + (m_b + m_g) * g[1]
                mz = mz + m_b * ((mx - X) * g[1] - (my - Y) * g[0]) + m_g * (
                    (tx - X) * g[1] - (ty - Y) * g[0])
                torque = m_b * ((mx - px) * g[1] - (my - py) * g[0]) + m_g * (
                    (tx - px) * g[1] - (ty - py) * g[0])
                continue
            f = x[3 + a]
            a += 1
            ux, uy = dx / length, dy / length
            ex, ey, mz = ex + f * ux, ey + f * uy, mz + f * (rx * uy - ry * ux)
            nx, ny = st.normals[i]
            cos_psi, sin_psi = -(nx * ux + ny * uy), -(nx * uy - ny * ux)  # pulled along -u
            psi = np.arctan2(sin_psi, cos_psi)
            fn, ft = st.f_normal[i], st.f_lateral[i]
            mu = fn * ft / np.sqrt((ft * cos_psi) ** 2 + (fn * sin_psi) ** 2)
            sigma = st.sigma_normal[i] + abs(psi) / (0.5 * math.pi) * (
                st.sigma_lateral[i] - st.sigma_normal[i])
            r = r + _log_ndtr_any((mu - f) / sigma)
            pulls.append(cos_psi)
        out = [ex, ey, mz, *lengths, *angles, *pulls, r - x[3 + self.n]]
        if self.free is not None:
            out.append(torque)
        return np.array(out)

    def robustness(self, poses: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """r_k = sum log Phi(z_i) at every step, by this program's own model."""
        # the row "sum log Phi - r_k" (before the torque row), evaluated with r_k = 0
        row = len(self._limits()[0]) - (2 if self.free is not None else 1)
        return np.array([self.step_values(k, np.concatenate([poses[k], tensions[k], [0.0]]))[
            row] for k in range(self.N)])

    def merit(self, poses: np.ndarray, velocities: np.ndarray, tensions: np.ndarray) -> float:
        """This program's merit (negated cost) at a trajectory whose statics hold."""
        x = np.concatenate([poses.ravel(), velocities.ravel()])
        D = self.dynamics @ x
        r = self.robustness(poses, tensions)
        cfg = self.config
        return float(cfg.robustness_weight * r.sum() - 0.5 * cfg.dynamics_weight * D @ D
                     - cfg.smoothness_weight * np.abs(np.diff(poses, axis=0)).max(axis=0).sum())

    def solve(self, poses: np.ndarray, velocities: np.ndarray,
              tensions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
        """IPOPT from the guess: poses, velocities, attached tensions and its status."""
        guess = np.zeros(self.prog.num_vars())
        for var, value in ((self.q, poses), (self.v, velocities), (self.f, tensions),
                           (self.r, self.robustness(poses, tensions)),
                           (self.w, np.abs(np.diff(poses, axis=0)).max(axis=0))):
            self.prog.SetDecisionVariableValueInVector(var, value, guess)
        # Drake logs IPOPT's stops (an iteration cap met) as warnings, one per phase: the
        # status below reports them, in the benchmark's table, not as stray stderr lines
        drake_log = logging.getLogger("drake")
        level = drake_log.level
        drake_log.setLevel(logging.ERROR)
        try:
            result = self.solver.Solve(self.prog, guess, self.options)
        finally:
            drake_log.setLevel(level)
        status = result.get_solution_result().name
        details = result.get_solver_details().ConvertStatusToString()
        if details:
            status = f"{status}: {details}"
        return (result.GetSolution(self.q), result.GetSolution(self.v),
                result.GetSolution(self.f).reshape(self.N, self.n), status)


def dynamics_matrix(robot: Any, N: int, dt: float) -> np.ndarray:
    """D = Dmat [q; v] with the statics holding (planning.scp's dynamics residual): per step
    the kinematic defect (M/dt)((q_{k+1} - q_k)/dt - (v_k + v_{k+1})/2), then the
    Newton-Euler defect (M/dt)(v_{k+1} - v_k); M = diag(m, m, m (w^2 + h^2) / 12)."""
    w, h = robot.body_size
    m = robot.body_mass
    scale = np.array([m, m, m * (w * w + h * h) / 12.0]) / dt
    D = np.zeros((N - 1, 6, 2, N, 3))
    for k in range(N - 1):
        for c in range(3):
            D[k, c, 0, k + 1, c], D[k, c, 0, k, c] = scale[c] / dt, -scale[c] / dt
            D[k, c, 1, k + 1, c] = D[k, c, 1, k, c] = -0.5 * scale[c]
            D[k, 3 + c, 1, k + 1, c], D[k, 3 + c, 1, k, c] = scale[c], -scale[c]
    return D.reshape(6 * (N - 1), 6 * N)
