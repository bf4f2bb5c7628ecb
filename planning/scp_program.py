"""The convex subproblem of one SCP phase: a Drake MathematicalProgram in matrix form, built once
per phase (`SubproblemProgram`) and updated in place at each iterate (`UpdateCoefficients`,
`set_bounds`) with the linearisation (`planning.scp_linearise`) and the trust radii; its solution
and the convex model of the merit (`planning.scp` explains the method, `ScpConfig` its
settings)."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from planning.scp_linearise import Iterate, Linearisation, linearisation
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import World
from rb_drake.params import NUM_BOOMS
from rb_drake.stance import Stance
from rb_drake.statics import quiet_solver_log, statics_problem


@dataclasses.dataclass(frozen=True)
class ScpConfig:
    """Weights of the merit, trust-region schedule and solver of the SCP (see the module doc of
    planning.scp)."""

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


class SubproblemProgram:
    """One phase's data and its convex subproblem: the Drake program built once, the
    linearisation, the model of the merit and the update and solution of the subproblem
    (`planning.scp.PhaseProgram` adds the exact merit and the trust-region loop)."""

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
        kb, bb, cb = np.meshgrid(k3, np.arange(NUM_BOOMS), np.arange(3), indexing="ij")
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
            raise RbpInputError(f"must be 'clarabel' or 'osqp', got {cfg.solver!r}",
                                field="solver")
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
        return linearisation(self.robot, self.stance, self.gravity, self.targets, self.tips, it)

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
        with quiet_solver_log():  # its status is handled below
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
