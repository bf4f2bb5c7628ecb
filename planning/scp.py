"""Sequential convex programming (SCP) for a body phase and a reach phase (paper IV-B, IV-C).

Over N steps the state is s_k = (q_k, v_k), pose q = (x, y, phi) and its velocity, and the
controls are the attached booms' tensions f_k. The phase maximises the merit

    kappa sum_k r(q_k, f_k)  -  alpha/2 sum_k |D_k|^2  -  beta sum_c max_k |q_{k+1,c} - q_{k,c}|

(r = sum_i log Phi(z_i), z_i = (mu(psi_i) - f_i) / sigma(psi_i)) with the start and goal
states fixed (the seed's first and last poses, zero velocity), boom lengths, shoulder angles
and tensions within their limits, r_k >= r_floor at every step and, in a reach phase, the free
limb's shoulder torque within its limit. D_k is the rigid-body dynamics residual between steps
k and k+1 (trapezoidal, in newtons): the velocity defect (M/dt) ((q_{k+1} - q_k)/dt - mean v)
and the Newton-Euler defect (M/dt) (v_{k+1} - v_k) - mean(A f - b), with M = diag(m, m, I),
I = m (w^2 + h^2) / 12, A f the tensions' wrench along u_i at the shoulders and b gravity plus,
in a reach phase, the cantilevered limb's load (`geometry.limb_load`).

Quasi-statics. A plan's tensions must hold each pose statically (`rbp check`: A f = b to
1e-6 N; paper IV-C keeps the motion slow enough to neglect inertia), so A(q_k) f_k = b(q_k) is
a constraint, not a penalty: every iterate satisfies it exactly (a minimum-norm correction of
the tensions after each step), and the subproblem keeps its linearisation. What remains of the
dynamics penalty is the body's inertial wrench, M times its acceleration: the penalty keeps the
motion gentle and the velocities consistent with the poses. In a reach phase the free boom's
axial force and shoulder torque are not free either: with its tip path prescribed they follow
from the pose (the limb's statics), so they are reported, and the torque limit is a constraint
on the pose.

Each iteration linearises the geometry (pull angles, moment arms, mu, sigma, boom lengths and
shoulder angles, the wrench) at the current iterate and replaces log Phi by its concave
quadratic (Newton) model in z: a convex QP, built once per phase as a Drake
MathematicalProgram in matrix form and updated in place (`UpdateCoefficients`, `set_bounds`).
Infinity-norm trust regions on poses and tensions (and velocities, if `radius_velocity` is
finite) grow on good steps and shrink on poor or rejected ones. A step is accepted only when
the exact merit (log_ndtr) rises by at least `accept_ratio` of the predicted gain and the new
trajectory is feasible: the tests of `check_poses` with the iterate's own tensions, and
r_k >= r_floor. When a trial point breaks a limit, the same model is solved once more with that
limit tightened by the violation (a second-order correction), and the curvature of the log Phi
model adapts: relaxed after steps that beat the prediction, restored after poor ones. r_floor
is log(p_min), raised to the seed's weakest step by default, so the result is never less
robust than the seed where it matters; a result that is not better is replaced by the seed.
"""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from planning.between import between_steps
from rb_drake import geometry
from rb_drake.collision import ANCHOR_CLEARANCE
from rb_drake.feasibility import (
    MIN_CONDITIONING,
    Reason,
    World,
    check_poses,
    pull_within,
    rock_inside_body,
    wrench_conditioning,
)
from rb_drake.grasp import (
    HALF_PI,
    log_ndtr_derivatives,
    mean_limit_derivative,
    sigma_limit_derivative,
)
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import allocate, null_vector, statics_problem

BOUND_TOL = 1e-9  # N, m, rad: slack on limits when checking an iterate exactly


@dataclasses.dataclass(frozen=True)
class ScpConfig:
    """Weights of the merit, trust-region schedule and solver of the SCP (see module doc)."""

    solver: str = "clarabel"          # or "osqp"
    max_iterations: int = 25
    robustness_weight: float = 1.0    # kappa, per unit of log-probability
    dynamics_weight: float = 0.05     # alpha, per N^2 of dynamics residual
    smoothness_weight: float = 0.05   # beta, per m (or rad) of the largest pose increment
    radius_pose: float = 0.05         # m, initial trust radius on x, y
    radius_angle: float = 0.1         # rad, on phi
    radius_velocity: float = np.inf   # m/s, rad/s; none by default: velocities enter only the
    #                                   dynamics penalty, which the model holds exactly
    radius_tension: float = 5.0       # N
    radius_min: float = 1e-3          # trust radii stay within [min, max] x the initial ones
    radius_max: float = 8.0
    grow: float = 2.0
    shrink: float = 0.5
    accept_ratio: float = 0.1         # accept when actual gain >= this x predicted gain
    grow_ratio: float = 0.75          # grow the radii when actual >= this x predicted
    shrink_ratio: float = 0.25        # shrink them when actual < this x predicted (or rejected)
    curvature_floor: float = 1e-5     # damped Newton: least curvature of the log Phi model
    curvature_scale_min: float = 0.125  # the model's curvature adapts within [this, 1] x exact
    tolerance: float = 1e-4           # converged when the predicted gain is below this
    keep_seed_floor: bool = True      # r_floor = max(log p_min, the seed's least r_k)


class IterationRecord(NamedTuple):
    merit: float           # exact merit of the iterate after this iteration
    predicted_gain: float  # of the subproblem's step, by the convex model
    actual_gain: float     # exact merit change of the step (nan if not evaluated)
    radius: float          # trust-region scale used (x the initial radii)
    accepted: bool
    note: str = ""         # why a step was rejected, or that a second-order correction helped


class ScpResult(NamedTuple):
    poses: np.ndarray              # (N, 3)
    velocities: np.ndarray         # (N, 3)
    tensions: np.ndarray           # (N, 4), NaN for the free boom
    free_force: np.ndarray | None  # (N,) free boom's axial tension (reach phase)
    shoulder_torque: np.ndarray | None  # (N,) free limb's moment about its shoulder (reach)
    log_probs: np.ndarray          # (N,) exact robustness r_k of the returned trajectory
    seed_log_probs: np.ndarray     # (N,) the seed's, with its tensions from `allocate`
    seed_tensions: np.ndarray      # (N, 4)
    improved: bool                 # False: the seed is returned
    status: str
    iterations: int
    history: list[IterationRecord]
    infeasible_constraints: list[str]
    seconds: float

    @property
    def effort(self) -> np.ndarray:
        """Control effort per step: the sum of the attached booms' tensions (N)."""
        return np.nansum(self.tensions, axis=1)

    @property
    def seed_effort(self) -> np.ndarray:
        return np.nansum(self.seed_tensions, axis=1)


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


class Evaluation(NamedTuple):
    merit: float
    robustness: np.ndarray   # (N,) r_k
    dynamics: np.ndarray     # (N-1, 6) residual D_k
    feasible: bool
    reason: str


class Margins(NamedTuple):
    """How far the subproblem tightens each linearised limit (a second-order correction: the
    violation the previous trial point showed); per step (N,) or per step and boom."""

    floor: np.ndarray        # (N,) robustness floor
    tension_lo: np.ndarray   # (N, n)
    tension_hi: np.ndarray   # (N, n)
    length_lo: np.ndarray    # (N, 4)
    length_hi: np.ndarray    # (N, 4)
    angle: np.ndarray        # (N, 4) |shoulder angle| limit
    torque: np.ndarray       # (N,) |shoulder torque| limit

    def scaled(self, factor: float) -> Margins:
        return Margins(*(factor * m for m in self))


class Subproblem(NamedTuple):
    iterate: Iterate | None
    predicted_gain: float
    status: str               # "ok", "infeasible", "failed: ..."
    infeasible: list[str]


def _perp(v: np.ndarray) -> np.ndarray:
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross_g(X: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Column-wise planar cross product X x g for X (..., 2, k)."""
    return X[..., 0, :] * g[1] - X[..., 1, :] * g[0]


class _Pattern:
    """A sparse matrix with a fixed pattern: values come in the order of (rows, cols)."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]):
        order = sp.csc_matrix((np.arange(1.0, len(rows) + 1.0), (rows, cols)), shape=shape)
        self.matrix = order
        self.perm = order.data.astype(int) - 1
        self.rows, self.cols = np.asarray(rows), np.asarray(cols)

    def with_values(self, values: np.ndarray) -> sp.csc_matrix:
        self.matrix.data = np.ascontiguousarray(values[self.perm], dtype=float)
        return self.matrix

    def row_range(self, values: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The least and greatest value of each row of the matrix over the box [lo, hi]."""
        pos, neg = np.maximum(values, 0.0), np.minimum(values, 0.0)
        n = self.matrix.shape[0]
        least = np.bincount(self.rows, pos * lo[self.cols] + neg * hi[self.cols], minlength=n)
        most = np.bincount(self.rows, pos * hi[self.cols] + neg * lo[self.cols], minlength=n)
        return least, most


class PhaseProgram:
    """The SCP of one phase: the convex subproblem (a Drake MathematicalProgram built once),
    the linearisation, the exact merit and the trust-region loop."""

    def __init__(self, world: World, stance: Stance, steps: int, dt: float,
                 config: ScpConfig | None = None, tips: np.ndarray | None = None):
        from pydrake.solvers import ClarabelSolver, MathematicalProgram, OsqpSolver, SolverOptions

        cfg = config or ScpConfig()
        self.config, self.world, self.stance = cfg, world, stance
        self.robot = robot = world.robot
        self.gravity = np.asarray(world.gravity_vector, dtype=float)
        self.N, self.dt = N, dt = int(steps), float(dt)
        if N < 2 or dt <= 0.0:
            raise ValueError(f"need at least 2 steps and dt > 0, got N={N}, dt={dt}")
        self.att = np.flatnonzero(stance.attached)
        self.free = stance.free_boom
        n = len(self.att)
        if self.free is not None and (tips is None or np.shape(tips) != (N, 2)):
            raise ValueError(f"a reach phase needs the free tip at each of the {N} steps")
        self.tips = None if tips is None else np.asarray(tips, dtype=float)
        targets = np.where(stance.attached[:, None], stance.positions, 0.0)
        self.targets = np.broadcast_to(targets, (N, 4, 2)).copy()
        if self.free is not None:
            self.targets[:, self.free] = self.tips
        w, h = robot.body_size
        m = robot.body_mass
        self.inertia = np.array([m, m, m * (w * w + h * h) / 12.0])
        self.floor = robot.log_p_min
        self.curvature_scale = 1.0
        self.radii = np.array([cfg.radius_pose, cfg.radius_pose, cfg.radius_angle])

        prog = MathematicalProgram()
        self.q = prog.NewContinuousVariables(N, 3, "pose")
        self.v = prog.NewContinuousVariables(N, 3, "velocity")
        self.f = prog.NewContinuousVariables(N, n, "tension")
        self.w = prog.NewContinuousVariables(3, "largest_increment")
        qf = np.concatenate([self.q.ravel(), self.f.ravel()])
        nq, nf = 3 * N, n * N
        k3 = np.arange(N)

        def named(binding, name):
            binding.evaluator().set_description(name)
            return binding

        # statics, linearised: G_k q_k + A_k f_k = G_k qbar_k + A_k fbar_k - e_k  (3N rows)
        r, c = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        rows_g = (3 * k3[:, None, None] + r).ravel()
        cols_g = (3 * k3[:, None, None] + c).ravel()
        r, c = np.meshgrid(np.arange(3), np.arange(n), indexing="ij")
        rows_a = (3 * k3[:, None, None] + r).ravel()
        cols_a = (nq + n * k3[:, None, None] + c).ravel()
        self._statics_pattern = _Pattern(np.concatenate([rows_g, rows_a]),
                                         np.concatenate([cols_g, cols_a]), (3 * N, nq + nf))
        self.statics = named(prog.AddLinearEqualityConstraint(
            self._statics_pattern.matrix, np.zeros(3 * N), qf), "statics")
        # step k's pose and tensions within qf: the margins z_k depend on these only
        self._step_index = np.concatenate(
            [3 * k3[:, None] + np.arange(3), nq + n * k3[:, None] + np.arange(n)], axis=1)
        # robustness floor, linearised: r_k + sum_i slope_i dz_i >= floor  (N rows)
        self._floor_pattern = _Pattern(np.repeat(k3, 3 + n), self._step_index.ravel(),
                                       (N, nq + nf))
        self.robust_floor = named(prog.AddLinearConstraint(
            self._floor_pattern.matrix, np.full(N, -np.inf), np.zeros(N), qf),
            "robustness_floor")
        # kinematic limits, linearised in the pose: boom length and shoulder angle (4N rows)
        kb, bb, cb = np.meshgrid(k3, np.arange(4), np.arange(3), indexing="ij")
        self._kin_pattern = _Pattern((4 * kb + bb).ravel(), (3 * kb + cb).ravel(), (4 * N, nq))
        self.lengths = named(prog.AddLinearConstraint(
            self._kin_pattern.matrix, np.zeros(4 * N), np.zeros(4 * N), self.q.ravel()),
            "boom_length")
        self.angles = named(prog.AddLinearConstraint(
            self._kin_pattern.matrix, np.zeros(4 * N), np.zeros(4 * N), self.q.ravel()),
            "shoulder_angle")
        self.torque = None
        if self.free is not None:
            self._torque_pattern = _Pattern(np.repeat(k3, 3), np.arange(nq), (N, nq))
            self.torque = named(prog.AddLinearConstraint(
                self._torque_pattern.matrix, np.zeros(N), np.zeros(N), self.q.ravel()),
                "shoulder_torque")
        # smoothness epigraph: |q_{k+1,c} - q_{k,c}| <= w_c
        diff = sp.kron(sp.eye(N - 1, N, 1) - sp.eye(N - 1, N), sp.eye(3))
        pick = sp.kron(np.ones((N - 1, 1)), sp.eye(3))
        A_s = sp.vstack([sp.hstack([diff, -pick]), sp.hstack([diff, pick])]).tocsc()
        M = 3 * (N - 1)
        named(prog.AddLinearConstraint(
            A_s, np.concatenate([np.full(M, -np.inf), np.zeros(M)]),
            np.concatenate([np.zeros(M), np.full(M, np.inf)]),
            np.concatenate([self.q.ravel(), self.w])), "smoothness")
        # trust regions (intersected with the fixed boundary states and the tension bounds)
        self.box_q = named(prog.AddBoundingBoxConstraint(
            np.zeros(nq), np.zeros(nq), self.q.ravel()), "trust_region_pose")
        lo_v = np.full((N, 3), -np.inf)
        lo_v[[0, -1]] = 0.0
        self.box_v = named(prog.AddBoundingBoxConstraint(
            lo_v.ravel(), -lo_v.ravel(), self.v.ravel()), "trust_region_velocity")
        self.box_f = named(prog.AddBoundingBoxConstraint(
            np.zeros(nf), np.zeros(nf), self.f.ravel()), "trust_region_tension")
        # costs (the negated merit model): the Newton model of log Phi in the margins (dense
        # (3+n)-blocks per step, updated), the dynamics penalty (constant: with the statics
        # linearised the wrench term vanishes) and the smoothness terms
        self.robust_cost = named(prog.AddQuadraticCost(
            np.eye(nq + nf), np.zeros(nq + nf), 0.0, qf, is_convex=True), "robustness_model")
        self._dyn_matrix = self._dynamics_matrix()
        named(prog.AddQuadraticCost(
            cfg.dynamics_weight * (self._dyn_matrix.T @ self._dyn_matrix).toarray(),
            np.zeros(6 * N), 0.0, np.concatenate([self.q.ravel(), self.v.ravel()]),
            is_convex=True), "dynamics_penalty")
        named(prog.AddLinearCost(np.full(3, cfg.smoothness_weight), 0.0, self.w), "smoothness")
        self.prog = prog

        self.options = SolverOptions()
        if cfg.solver == "clarabel":
            self.solver = ClarabelSolver()
            for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
                self.options.SetOption(self.solver.solver_id(), key, 1e-9)
        elif cfg.solver == "osqp":
            self.solver = OsqpSolver()
            for key, val in (("eps_abs", 1e-5), ("eps_rel", 1e-5), ("max_iter", 20000),
                             ("polishing", 1)):
                self.options.SetOption(self.solver.solver_id(), key, val)
            for var in self.f.ravel():  # tensions in units of 10 N: ADMM needs similar scales
                prog.SetVariableScaling(var, 10.0)
        else:
            raise ValueError(f"solver must be 'clarabel' or 'osqp', got {cfg.solver!r}")
        if not self.solver.available() or not self.solver.AreProgramAttributesSatisfied(prog):
            raise RuntimeError(f"{cfg.solver} cannot solve the SCP subproblem here")

    # ------------------------------------------------------------------ model pieces

    def _dynamics_matrix(self) -> sp.csc_matrix:
        """D_lin = Dmat [q; v] with the wrench term dropped, rows (step k, 6): the kinematic
        defect (M/dt)((q_{k+1} - q_k)/dt - (v_k + v_{k+1})/2), then (M/dt)(v_{k+1} - v_k)."""
        N, dt = self.N, self.dt
        D = np.zeros((N - 1, 6, 2, N, 3))         # (step, row, [q|v], knot, coordinate)
        k, c = np.arange(N - 1)[:, None], np.arange(3)[None, :]
        scale = self.inertia / dt
        D[k, c, 0, k + 1, c] = scale / dt
        D[k, c, 0, k, c] = -scale / dt
        D[k, c, 1, k + 1, c] = D[k, c, 1, k, c] = -0.5 * scale
        D[k, 3 + c, 1, k + 1, c] = scale
        D[k, 3 + c, 1, k, c] = -scale
        return sp.csc_matrix(D.reshape(6 * (N - 1), 6 * N))

    def dynamics_residual(self, it: Iterate, wrench: np.ndarray) -> np.ndarray:
        """D_k (N-1, 6): (M/dt) velocity defect, then Newton-Euler defect minus the wrench."""
        x = np.concatenate([it.poses.ravel(), it.velocities.ravel()])
        D = (self._dyn_matrix @ x).reshape(self.N - 1, 6)
        D[:, 3:] -= 0.5 * (wrench[:-1] + wrench[1:])
        return D

    def statics_at(self, poses: np.ndarray):
        return statics_problem(self.robot, self.gravity, poses, self.stance, self.tips)

    def tensions4(self, tensions: np.ndarray) -> np.ndarray:
        out = np.full((tensions.shape[0], 4), np.nan)
        out[:, self.att] = tensions
        return out

    def linearise(self, it: Iterate) -> Linearisation:
        """Every linearised quantity of the subproblem at `it` (analytic derivatives)."""
        robot, st, g = self.robot, self.stance, self.gravity
        q = it.poses
        N = q.shape[0]
        r = geometry.shoulder_offsets(robot, q)                      # (N, 4, 2)
        d = self.targets - (q[:, None, :2] + r)
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
        f4[:, self.att] = it.tensions
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
        if self.free is not None:
            j = self.free
            load = geometry.limb_load(robot, q, j, self.tips, g)
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
            mid_c = 0.5 * (shoulder + self.tips) - q[:, :2]
            e_dq[:, :2, :] += rho * g[None, :, None] * ell_dq[:, None, :]
            e_dq[:, 2, :] += (rho * ell_dq * geometry.cross2(mid_c, g)[:, None]
                              + m_b[:, None] * _cross_g(0.5 * P - C, g) - mg * _cross_g(C, g))
            arm_tip = geometry.cross2(self.tips - shoulder, g)
            torque_dq = (0.5 * rho * ell_dq * arm_tip[:, None]
                         - (0.5 * m_b + mg)[:, None] * _cross_g(P, g))
        return Linearisation(
            L, L_dq, theta, theta_dq, psi, psi_dq, arm, arm_dq, mu, mu_dq, sigma, sigma_dq,
            z, z_dq, z_df, lp, lam, -d2, e, e_dq, A[:, :, self.att], torque, torque_dq)

    def evaluate(self, it: Iterate) -> Evaluation:
        """The exact merit (log_ndtr) and feasibility of an iterate."""
        cfg = self.config
        prob = self.statics_at(it.poses)
        f4 = self.tensions4(it.tensions)
        e = np.einsum("nrb,nb->nr", prob.A, np.nan_to_num(f4)) - prob.b
        lp = self.stance.log_prob(np.nan_to_num(f4), np.nan_to_num(prob.pull_angles))
        r = lp[:, self.att].sum(axis=1)
        D = self.dynamics_residual(it, e)
        increments = np.abs(np.diff(it.poses, axis=0)).max(axis=0)
        merit = (cfg.robustness_weight * r.sum() - 0.5 * cfg.dynamics_weight * np.sum(D * D)
                 - cfg.smoothness_weight * increments.sum())
        reason = self._infeasibility(it, prob, e, r)
        return Evaluation(float(merit), r, D, reason == "", reason)

    def _infeasibility(self, it: Iterate, prob, e: np.ndarray, r: np.ndarray) -> str:
        """Why `it` is not feasible ('' when it is): the tests of `check_poses`, but with the
        iterate's own tensions, the robustness floor, and the configurations between the
        steps (`between_steps`)."""
        robot = self.robot
        f_lo, f_hi = robot.boom_tension
        f = it.tensions
        if not np.isfinite(f).all() or np.abs(e).max() > 1e-6:
            return f"statics residual {np.abs(e).max():.2e} N"
        if np.any(f < f_lo - BOUND_TOL) or np.any(f > f_hi + BOUND_TOL):
            return "tension out of bounds"
        weak = np.flatnonzero(~(r >= self.floor - 1e-12))
        if len(weak):
            return f"robustness below the floor {self.floor:.6f} at steps {weak.tolist()}"
        geo = prob.geometry
        L_lo, L_hi = robot.boom_length
        if np.any(geo.length < L_lo) or np.any(geo.length > L_hi):
            return "boom length out of range"
        if np.any(np.abs(geo.shoulder_angle) > robot.shoulder_range + 1e-12):
            return "shoulder angle out of range"
        if np.any(np.abs(prob.shoulder_torque) > robot.shoulder_torque_max):
            return "shoulder torque over the limit"
        if not pull_within(robot, prob.pull_angles[:, self.stance.attached]).all():
            return f"a grasp pulled at {robot.max_pull_angle_deg} deg or more from its normal"
        if np.any(wrench_conditioning(robot, prob.A, self.stance.attached) < MIN_CONDITIONING):
            return "booms nearly meet in one point (wrench conditioning)"
        rock = self.world.rock
        if rock.polygons:
            corners = geometry.body_corners(robot, it.poses)
            if (rock.segments_hit(corners, np.roll(corners, -1, axis=1)).any()
                    or rock_inside_body(rock, corners).any()):
                return "body collides with rock"
            end = self.targets - ANCHOR_CLEARANCE * geo.u
            if rock.segments_hit(geo.shoulders, end).any():
                return "boom collides with rock"
        lp = self.stance.log_prob(np.nan_to_num(self.tensions4(it.tensions)),
                                  np.nan_to_num(prob.pull_angles))
        return between_steps(self.world, self.stance, it.poses, lp, self.tips)

    def violations(self, it: Iterate) -> Margins:
        """By how much `it` exceeds each limit the subproblem linearises (0 where within)."""
        robot = self.robot
        prob = self.statics_at(it.poses)
        f4 = np.nan_to_num(self.tensions4(it.tensions))
        r = self.stance.log_prob(f4, np.nan_to_num(prob.pull_angles))[:, self.att].sum(axis=1)
        f_lo, f_hi = robot.boom_tension
        L_lo, L_hi = robot.boom_length
        L, theta = prob.geometry.length, prob.geometry.shoulder_angle
        pos = np.maximum
        return Margins(pos(self.floor - r, 0.0), pos(f_lo - it.tensions, 0.0),
                       pos(it.tensions - f_hi, 0.0), pos(L_lo - L, 0.0), pos(L - L_hi, 0.0),
                       pos(np.abs(theta) - robot.shoulder_range, 0.0),
                       pos(np.abs(prob.shoulder_torque) - robot.shoulder_torque_max, 0.0))

    def no_margins(self) -> Margins:
        N, n = self.N, len(self.att)
        return Margins(np.zeros(N), np.zeros((N, n)), np.zeros((N, n)), np.zeros((N, 4)),
                       np.zeros((N, 4)), np.zeros((N, 4)), np.zeros(N))

    def linear_dynamics(self, lin: Linearisation, it: Iterate, x: Iterate) -> np.ndarray:
        """The dynamics residual linearised at `it`, evaluated at `x` (N-1, 6)."""
        dq, df = x.poses - it.poses, x.tensions - it.tensions
        e = lin.wrench + np.einsum("nrj,nj->nr", lin.wrench_dq, dq) + np.einsum(
            "nrb,nb->nr", lin.wrench_df, df)
        return self.dynamics_residual(x, e)

    def model_merit(self, lin: Linearisation, it: Iterate, x: Iterate) -> float:
        """The convex model of the merit built at `it`, evaluated at `x`."""
        cfg = self.config
        a = self.att
        dz = (np.einsum("nbj,nj->nb", lin.z_dq[:, a], x.poses - it.poses)
              + lin.z_df[:, a] * (x.tensions - it.tensions))
        H = np.maximum(self.curvature_scale * lin.curvature[:, a], cfg.curvature_floor)
        robust = np.sum(lin.log_prob[:, a] + lin.slope[:, a] * dz - 0.5 * H * dz * dz)
        D = self.linear_dynamics(lin, it, x)
        increments = np.abs(np.diff(x.poses, axis=0)).max(axis=0)
        return float(cfg.robustness_weight * robust - 0.5 * cfg.dynamics_weight * np.sum(D * D)
                     - cfg.smoothness_weight * increments.sum())

    # ------------------------------------------------------------------ the subproblem

    def update(self, lin: Linearisation, it: Iterate, scale: float, floor: np.ndarray,
               margins: Margins | None = None) -> None:
        """Write the linearisation at `it` and the trust radii (x `scale`) into the program,
        with the limits tightened by `margins` (a second-order correction).

        Inequality rows that cannot become active anywhere in the trust region get infinite
        bounds, which the solver interfaces drop: the subproblem is the same, only smaller."""
        cfg, robot, N = self.config, self.robot, self.N
        a = self.att
        m = margins if margins is not None else self.no_margins()
        q0, f0 = it.poses, it.tensions
        # trust regions; the boundary states stay where the seed put them
        rq = scale * self.radii
        lo_q, hi_q = q0 - rq, q0 + rq
        lo_q[[0, -1]] = hi_q[[0, -1]] = q0[[0, -1]]
        self.box_q.evaluator().set_bounds(lo_q.ravel(), hi_q.ravel())
        if np.isfinite(cfg.radius_velocity):
            v0 = it.velocities
            rv = scale * cfg.radius_velocity
            lo_v, hi_v = v0 - rv, v0 + rv
            lo_v[[0, -1]] = hi_v[[0, -1]] = 0.0
            self.box_v.evaluator().set_bounds(lo_v.ravel(), hi_v.ravel())
        f_lo, f_hi = robot.boom_tension
        rf = scale * cfg.radius_tension
        lo_f = np.maximum(np.minimum(np.maximum(f0 - rf, f_lo), f0), f_lo + m.tension_lo)
        hi_f = np.maximum(np.minimum(np.maximum(np.minimum(f0 + rf, f_hi), f0),
                                     f_hi - m.tension_hi), lo_f)
        self.box_f.evaluator().set_bounds(lo_f.ravel(), hi_f.ravel())
        box_lo = np.concatenate([lo_q.ravel(), lo_f.ravel()])
        box_hi = np.concatenate([hi_q.ravel(), hi_f.ravel()])

        def set_rows(binding, pattern, values, lb, ub):
            bottom, top = pattern.row_range(values, box_lo, box_hi)
            binding.evaluator().UpdateCoefficients(pattern.with_values(values),
                                                   np.where(bottom >= lb, -np.inf, lb),
                                                   np.where(top <= ub, np.inf, ub))

        G, Af = lin.wrench_dq, lin.wrench_df
        self.statics.evaluator().UpdateCoefficients(
            self._statics_pattern.with_values(np.concatenate([G.ravel(), Af.ravel()])),
            (np.einsum("nrj,nj->nr", G, q0) + np.einsum("nrb,nb->nr", Af, f0)
             - lin.wrench).ravel())
        # margins per step over (q_k, f_k): dz_i = J_i dx_k
        n = len(a)
        J = np.zeros((N, n, 3 + n))
        J[:, :, :3] = lin.z_dq[:, a]
        J[:, np.arange(n), 3 + np.arange(n)] = lin.z_df[:, a]
        x0 = np.concatenate([q0, f0], axis=1)
        lam = lin.slope[:, a]
        grad = np.einsum("na,naj->nj", lam, J)                  # d r_k / d x_k (model)
        r0 = lin.log_prob[:, a].sum(axis=1)
        lb = floor + m.floor - r0 + np.einsum("nj,nj->n", grad, x0)
        set_rows(self.robust_floor, self._floor_pattern, grad.ravel(), lb, np.full(N, np.inf))
        kappa = cfg.robustness_weight
        H = kappa * np.maximum(self.curvature_scale * lin.curvature[:, a], cfg.curvature_floor)
        blocks = np.einsum("nai,na,naj->nij", J, H, J)
        Q = np.zeros((len(box_lo), len(box_lo)))
        idx = self._step_index
        Q[idx[:, :, None], idx[:, None, :]] = blocks
        b = np.zeros(len(box_lo))
        b[idx] = -kappa * grad - np.einsum("nij,nj->ni", blocks, x0)
        self.robust_cost.evaluator().UpdateCoefficients(Q, b, 0.0, is_convex=True)
        lo, hi = robot.boom_length
        base = np.einsum("nbj,nj->nb", lin.length_dq, q0) - lin.length
        set_rows(self.lengths, self._kin_pattern, lin.length_dq.ravel(),
                 (lo + m.length_lo + base).ravel(), (hi - m.length_hi + base).ravel())
        base = np.einsum("nbj,nj->nb", lin.shoulder_angle_dq, q0) - lin.shoulder_angle
        rng = robot.shoulder_range - m.angle
        set_rows(self.angles, self._kin_pattern, lin.shoulder_angle_dq.ravel(),
                 (base - rng).ravel(), (base + rng).ravel())
        if self.torque is not None:
            base = np.einsum("nj,nj->n", lin.torque_dq, q0) - lin.torque
            tmax = robot.shoulder_torque_max - m.torque
            set_rows(self.torque, self._torque_pattern, lin.torque_dq.ravel(), base - tmax,
                     base + tmax)

    def solve_subproblem(self, lin: Linearisation, it: Iterate, scale: float,
                         floor: np.ndarray, margins: Margins | None = None) -> Subproblem:
        """Solve the convex model at `it` within the trust region scaled by `scale`."""
        from pydrake.solvers import SolutionResult

        self.update(lin, it, scale, floor, margins)
        guess = np.zeros(self.prog.num_vars())
        for var, value in ((self.q, it.poses), (self.v, it.velocities), (self.f, it.tensions),
                           (self.w, np.abs(np.diff(it.poses, axis=0)).max(axis=0))):
            self.prog.SetDecisionVariableValueInVector(var, value, guess)
        result = self.solver.Solve(self.prog, guess, self.options)
        status = result.get_solution_result()
        if status in (SolutionResult.kInfeasibleConstraints,
                      SolutionResult.kInfeasibleOrUnbounded):
            # The solver's point is meaningless here; the current iterate (zero step, inside
            # every trust region) shows which linearised constraints cannot be met.
            result.set_x_val(guess)
            names = list(result.GetInfeasibleConstraintNames(self.prog, 1e-9))
            return Subproblem(None, 0.0, "infeasible", names)
        x = Iterate(result.GetSolution(self.q), result.GetSolution(self.v),
                    result.GetSolution(self.f).reshape(self.N, -1))
        x.poses[[0, -1]] = it.poses[[0, -1]]  # fixed: exactly, not to the solver's tolerance
        x.velocities[[0, -1]] = 0.0
        if not result.is_success() and not (
                status == SolutionResult.kIterationLimit and np.isfinite(x.poses).all()):
            return Subproblem(None, 0.0, f"failed: {status}", [])
        predicted = self.model_merit(lin, it, x) - self.model_merit(lin, it, it)
        return Subproblem(x, predicted, "ok", [])

    def restore(self, x: Iterate) -> Iterate | None:
        """The tensions corrected (minimum norm, then along the null space to stay within
        bounds) so that A(q) f = b(q) holds exactly at the new poses; None if impossible."""
        prob = self.statics_at(x.poses)
        A, b = prob.A[:, :, self.att], prob.b
        f = x.tensions.copy()
        residual = b - np.einsum("nrb,nb->nr", A, f)
        lo, hi = self.robot.boom_tension
        if len(self.att) == 3:
            try:
                f = np.linalg.solve(A, b[..., None])[..., 0]
            except np.linalg.LinAlgError:
                return None
        else:
            AAt = A @ A.transpose(0, 2, 1)
            try:
                f = f + np.einsum("nrb,nr->nb", A, np.linalg.solve(AAt, residual[..., None])[
                    ..., 0])
            except np.linalg.LinAlgError:
                return None
            out = (f < lo) | (f > hi)
            if out.any():  # shift along the null vector by the least amount that fits
                n = null_vector(A)
                n /= np.linalg.norm(n, axis=1, keepdims=True)
                with np.errstate(divide="ignore", invalid="ignore"):
                    t1, t2 = (lo - f) / n, (hi - f) / n
                t_lo = np.where(np.abs(n) > 1e-12, np.minimum(t1, t2), -np.inf).max(axis=1)
                t_hi = np.where(np.abs(n) > 1e-12, np.maximum(t1, t2), np.inf).min(axis=1)
                t = np.clip(0.0, t_lo, t_hi)
                f = f + t[:, None] * n
        if not np.isfinite(f).all():
            return None
        return Iterate(x.poses, x.velocities, f)

    # ------------------------------------------------------------------ the SCP loop

    def run(self, seed: Iterate, floor: float) -> tuple[Iterate, Evaluation, list, str, list]:
        """Trust-region SCP from `seed`: (best iterate, its evaluation, history, status,
        infeasible constraint names)."""
        cfg = self.config
        floors = np.full(self.N, floor)
        self.floor, self.curvature_scale = floor, 1.0
        it, ev = seed, self.evaluate(seed)
        scale, history, status, infeasible = 1.0, [], "max_iterations", []
        for _ in range(cfg.max_iterations):
            used = scale
            lin = self.linearise(it)
            sub = self.solve_subproblem(lin, it, used, floors)
            if sub.status == "infeasible":
                status, infeasible = "infeasible subproblem", sub.infeasible
                history.append(IterationRecord(ev.merit, 0.0, np.nan, used, False))
                break
            if sub.iterate is not None and sub.predicted_gain <= cfg.tolerance:
                history.append(IterationRecord(ev.merit, sub.predicted_gain, np.nan, used,
                                               False))
                status = "converged"
                break
            cand, cev = self._trial(sub)
            corrected = False
            margins = None if cev is None or cev.feasible else self.violations(cand)
            if margins is not None and all(np.isfinite(m).all() for m in margins):
                # Second-order correction: tighten the limits the trial point broke by twice
                # its violation and solve the same model once more.
                soc = self.solve_subproblem(lin, it, used, floors, margins.scaled(2.0))
                soc_cand, soc_ev = self._trial(soc)
                if soc_ev is not None and soc_ev.feasible:
                    sub, cand, cev, corrected = soc, soc_cand, soc_ev, True
            gain = np.nan if cev is None else cev.merit - ev.merit
            accept = bool(cev is not None and cev.feasible and gain >= 0.0
                          and gain >= cfg.accept_ratio * sub.predicted_gain)
            # log Phi flattens as z grows, so its Newton model is often too cautious: relax its
            # curvature after steps that beat the prediction, restore it after poor ones.
            ratio = gain / sub.predicted_gain if sub.predicted_gain > 0 else np.nan
            if accept and ratio > 1.0:
                self.curvature_scale = max(cfg.curvature_scale_min, 0.5 * self.curvature_scale)
            elif not accept or ratio < 0.5:
                self.curvature_scale = min(1.0, 2.0 * self.curvature_scale)
            if accept:
                it, ev = cand, cev
                note = "second-order correction" if corrected else ""
                if gain >= cfg.grow_ratio * sub.predicted_gain:
                    scale = min(scale * cfg.grow, cfg.radius_max)
                elif gain < cfg.shrink_ratio * sub.predicted_gain:
                    scale *= cfg.shrink
            else:
                note = "rejected: " + ("no trial point" if cev is None else cev.reason
                                       or "too little gain")
                scale *= cfg.shrink
            history.append(IterationRecord(ev.merit, sub.predicted_gain, float(gain), used,
                                           accept, note))
            if scale < cfg.radius_min:
                status = "trust region below its minimum"
                break
        return it, ev, history, status, infeasible

    def _trial(self, sub: Subproblem) -> tuple[Iterate | None, Evaluation | None]:
        """The subproblem's solution with its tensions restored, and its exact evaluation."""
        cand = None if sub.iterate is None else self.restore(sub.iterate)
        return cand, None if cand is None else self.evaluate(cand)

    def velocities_for(self, poses: np.ndarray) -> np.ndarray:
        """The velocities that minimise the dynamics penalty for these poses (zero at the ends,
        quasi-static tensions): the seed's velocities."""
        N = self.N
        Dq, Dv = self._dyn_matrix[:, :3 * N], self._dyn_matrix[:, 3 * N:]
        interior = np.arange(3, 3 * (N - 1))
        v = np.zeros(3 * N)
        if len(interior):
            v[interior] = np.linalg.lstsq(Dv[:, interior].toarray(), -(Dq @ poses.ravel()),
                                          rcond=None)[0]
        return v.reshape(N, 3)


def optimise_body(scn: Scenario, stance_ids: tuple[str, ...], seed_poses: np.ndarray, dt: float,
                  config: ScpConfig | None = None) -> ScpResult:
    """SCP of a body phase: the body moves in a 4-stance from the seed's first pose to its last.
    `seed_poses` (N, 3) should be feasible in the stance (e.g. from the body seed planner)."""
    stance = scn.stance(stance_ids)
    if not stance.attached.all():
        raise ValueError(f"a body phase needs a 4-stance, got {stance_ids}")
    return _optimise(scn, stance, seed_poses, None, dt, config)


def optimise_reach(scn: Scenario, stance_ids3: tuple[str | None, ...], boom: int,
                   seed_poses: np.ndarray, tips: np.ndarray, dt: float,
                   config: ScpConfig | None = None) -> ScpResult:
    """SCP of a reach phase: boom `boom` is free and its gripper follows the prescribed path
    `tips` (N, 2) while the other three hold; `stance_ids3` names their anchors (the free
    boom's entry is ignored)."""
    ids = tuple(None if i == boom else a for i, a in enumerate(stance_ids3))
    if sum(a is None for a in ids) != 1:
        raise ValueError(f"a reach phase frees exactly boom {boom}, got {stance_ids3}")
    tips = np.asarray(tips, dtype=float)
    if tips.shape != (len(seed_poses), 2):
        raise ValueError(f"tips must be ({len(seed_poses)}, 2), got {tips.shape}")
    return _optimise(scn, scn.stance(ids), seed_poses, tips, dt, config)


def _limb_controls(scn: Scenario, stance: Stance, poses: np.ndarray,
                   tips: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The free boom's axial tension and its limb's moment about the shoulder, from its statics."""
    j = stance.free_boom
    if j is None:
        return None, None
    robot, g = scn.robot, scn.gravity_vector
    load = geometry.limb_load(robot, poses, j, tips, g)
    d = tips - geometry.shoulder_positions(robot, poses)[:, j]
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.einsum("nk,nk->n", load.force, u), load.shoulder_torque


def _optimise(scn: Scenario, stance: Stance, seed_poses: np.ndarray, tips: np.ndarray | None,
              dt: float, config: ScpConfig | None) -> ScpResult:
    start = time.perf_counter()
    cfg = config or ScpConfig()
    robot = scn.robot
    poses = np.array(seed_poses, dtype=float)
    N = poses.shape[0]
    seed_alloc = allocate(robot, scn.gravity_vector, poses, stance, tips)
    seed_r = seed_alloc.robustness
    program = PhaseProgram(scn, stance, N, dt, cfg, tips)

    def result(it: Iterate, r: np.ndarray, improved: bool, status: str, history: list,
               infeasible: list[str]) -> ScpResult:
        free_force, torque = _limb_controls(scn, stance, it.poses, tips)
        return ScpResult(it.poses, it.velocities, program.tensions4(it.tensions), free_force,
                         torque, r, seed_r, seed_alloc.tensions, improved, status, len(history),
                         history, infeasible, time.perf_counter() - start)

    seed = Iterate(poses, program.velocities_for(poses), seed_alloc.tensions[:, program.att])
    if not np.isfinite(seed_r).all():  # nothing to linearise about
        bad = np.flatnonzero(~np.isfinite(seed_r)).tolist()
        return result(seed, seed_r, False, "seed returned: no tensions hold the seed (or a "
                      f"grasp is pulled at 90 degrees or more) at steps {bad}", [], [])
    floor = robot.log_p_min
    if cfg.keep_seed_floor:
        floor = max(floor, float(seed_r.min()))
    it, ev, history, status, infeasible = program.run(seed, floor)
    accepted = any(h.accepted for h in history)
    check = check_poses(scn, stance, it.poses, tips)  # the library's own verdict, once
    if (accepted and ev.feasible and check.feasible.all()
            and ev.robustness.min() >= seed_r.min() - 1e-12):
        return result(it, ev.robustness, True, status, history, infeasible)
    if not accepted:
        why = "no step improved the merit" if not infeasible else status
    elif not ev.feasible or not check.feasible.all():
        k = int(np.argmin(check.feasible))
        why = ev.reason or f"check_poses: step {k} {Reason(int(check.reason[k])).name}"
    else:
        why = "the optimum is less robust than the seed"
    return result(seed, seed_r, False, f"seed returned: {why} ({status})", history, infeasible)
