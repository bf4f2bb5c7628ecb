"""Statics and force allocation: which boom tensions hold a pose, and the most robust of them.

Equilibrium of the body (and, in a 3-stance, the cantilevered free limb it carries):

    sum_i f_i u_i + M g + W_limb = 0,      sum_i (R s_i) x (f_i u_i) + tau_limb = 0,

three equations in the attached booms' tensions. A 3-stance has a unique solution (a 3x3
system); a 4-stance has a one-parameter family f = f_p + t n, with n spanning the null space of
the 3x4 wrench matrix. Allocation maximises the robustness r = sum_i log Phi(z_i) (minus a tiny
regulariser `REGULARISATION/2 |f|^2` that makes the optimum unique where every grasp is so safe
that log Phi is flat) subject to the tension bounds. Two implementations share that objective:

* `allocate` - vectorised over poses: a closed-form 3x3 solve, or root finding on the derivative
  of the concave one-dimensional objective along the family (safeguarded Newton). For the
  planner's hot loops.
* `ForceAllocator` - a Newton-SQP on a reused Drake `MathematicalProgram` solved with OSQP or
  Clarabel, for any stance; the general reference the tests hold `allocate` against.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from rb_drake import geometry
from rb_drake.errors import RbpInputError
from rb_drake.grasp import HALF_PI, log_ndtr_derivatives, mills_ratio
from rb_drake.params import RobotParams
from rb_drake.stance import Stance

REGULARISATION = 1e-8  # N^-2; decides only where every grasp has z > ~5 (P_i > 1 - 1e-7)
STATICS_TOL = 1e-6     # N (and N m): the largest residual we call equilibrium


@contextlib.contextmanager
def quiet_solver_log() -> Iterator[None]:
    """Drake's solver messages below a warning kept off stderr while a solve runs: its status
    is read and handled by the caller (`scp.dynamics_weight: 1e6` printed "INFO:drake:Clarabel
    returns InsufficientProgress" among rbp plan's lines)."""
    log = logging.getLogger("drake")
    level = log.level
    log.setLevel(logging.WARNING)
    try:
        yield
    finally:
        log.setLevel(level)

class Allocation(NamedTuple):
    """Force allocation for P poses. Tensions are NaN for a free boom and where statics fail."""

    tensions: np.ndarray        # (P, 4)
    pull_angles: np.ndarray     # (P, 4)
    log_probs: np.ndarray       # (P, 4), 0 for a free boom
    robustness: np.ndarray      # (P,) r = sum log P_i; -inf when infeasible
    statics_ok: np.ndarray      # (P,) tensions within bounds balance the load
    residual: np.ndarray        # (P,) max |A f - b|
    shoulder_torque: np.ndarray  # (P,) the free limb's moment about its shoulder (0 if none)


class StaticsProblem(NamedTuple):
    """A f = b for P poses: A (P, 3, 4) with zero columns for a free boom, b (P, 3)."""

    A: np.ndarray
    b: np.ndarray
    geometry: geometry.BoomGeometry
    pull_angles: np.ndarray
    shoulder_torque: np.ndarray

    def take(self, rows: np.ndarray) -> StaticsProblem:
        """The problem at a subset of the poses."""
        geo = geometry.BoomGeometry(*(a[rows] for a in self.geometry))
        return StaticsProblem(self.A[rows], self.b[rows], geo, self.pull_angles[rows],
                              self.shoulder_torque[rows])


def statics_problem(robot: RobotParams, gravity: np.ndarray, poses: np.ndarray, stance: Stance,
                    free_tip: np.ndarray | None = None) -> StaticsProblem:
    """The equilibrium equations at each pose; `free_tip` is where a 3-stance's free gripper is."""
    poses = geometry.as_poses(poses)
    g = np.asarray(gravity, dtype=float)
    targets = np.where(stance.attached[:, None], stance.positions, 0.0)
    j = stance.free_boom
    if j is not None:
        if free_tip is None:
            raise ValueError(f"a 3-stance (boom {j} free) needs the free gripper's position")
        targets = np.broadcast_to(targets, (poses.shape[0], 4, 2)).copy()
        targets[:, j, :] = free_tip
    geo = geometry.boom_geometry(robot, poses, targets)
    psi = geometry.pull_angles(geo.u, np.where(stance.attached[:, None], stance.normals, 0.0))
    A = geometry.wrench_matrix(robot, poses, geo.u) * stance.attached
    P = poses.shape[0]
    b = np.zeros((P, 3))
    b[:, :2] = -robot.body_mass * g
    torque = np.zeros(P)
    if j is not None:
        assert free_tip is not None  # a 3-stance without it raised above
        load = geometry.limb_load(robot, poses, j, free_tip, g)
        b[:, :2] -= load.force
        b[:, 2] -= load.moment
        torque = load.shoulder_torque
    return StaticsProblem(A, b, geo, np.where(stance.attached, psi, np.nan), torque)


def _objective_terms(stance: Stance, f: np.ndarray, psi: np.ndarray):
    """Per boom: log Phi(z), d/df, d2/df2 of the regularised objective (valid pull angles)."""
    valid = stance.attached & (np.abs(psi) < HALF_PI)
    psi_v = np.where(valid, psi, 0.0)
    sigma = np.where(stance.attached, stance.sigma(psi_v), 1.0)
    z = np.where(valid, (stance.mean_limit(psi_v) - f) / sigma, 40.0)
    lp, d1, d2 = log_ndtr_derivatives(z)
    grad = -d1 / sigma - REGULARISATION * f
    hess = d2 / sigma**2 - REGULARISATION
    return np.where(valid, lp, 0.0), np.where(stance.attached, grad, 0.0), hess, valid


def null_vector(A: np.ndarray) -> np.ndarray:
    """The null space of 3x4 matrices (P, 3, 4), by signed 3x3 minors (unnormalised)."""
    cols = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]
    minors = np.stack([np.linalg.det(A[:, :, c]) for c in cols], axis=-1)
    return minors * np.array([1.0, -1.0, 1.0, -1.0])


def allocate(robot: RobotParams, gravity: np.ndarray, poses: np.ndarray, stance: Stance,
             free_tip: np.ndarray | None = None, newton_steps: int = 12,
             problem: StaticsProblem | None = None) -> Allocation:
    """The most robust tensions within bounds at every pose (vectorised; see module doc).
    `problem`, when given, is `statics_problem` at these poses, already computed."""
    prob = problem if problem is not None else statics_problem(robot, gravity, poses, stance,
                                                               free_tip)
    A, b, psi = prob.A, prob.b, prob.pull_angles
    P = A.shape[0]
    f_lo, f_hi = robot.boom_tension
    att = stance.attached
    f = np.zeros((P, 4))
    if att.sum() == 3:
        A3 = A[:, :, att]
        det = np.linalg.det(A3)
        ok = np.abs(det) > 1e-12
        A3 = np.where(ok[:, None, None], A3, np.eye(3))
        f[:, att] = np.linalg.solve(A3, b[..., None])[..., 0]
        f[~ok] = np.nan
    elif att.sum() == 4:
        n = null_vector(A)
        n_norm = np.linalg.norm(n, axis=-1)
        n = n / np.maximum(n_norm, 1e-300)[:, None]
        # Particular (minimum-norm) solution A^T (A A^T)^-1 b.
        AAt = A @ np.swapaxes(A, 1, 2)
        ok = np.abs(np.linalg.det(AAt)) > 1e-14
        AAt = np.where(ok[:, None, None], AAt, np.eye(3))
        fp = (np.swapaxes(A, 1, 2) @ np.linalg.solve(AAt, b[..., None]))[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (f_lo - fp) / n
            t2 = (f_hi - fp) / n
        tiny = np.abs(n) < 1e-12
        inside = (fp >= f_lo - 1e-9) & (fp <= f_hi + 1e-9)
        t_lo = np.where(tiny, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=1)
        t_hi = np.where(tiny, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=1)
        ok &= (t_lo <= t_hi) & (n_norm > 1e-12)
        t_lo = np.where(ok, t_lo, 0.0)
        t_hi = np.where(ok, t_hi, 0.0)

        # mu and sigma depend on the pose only: compute them once, outside the bisection.
        valid = att & (np.abs(psi) < HALF_PI)
        psi_v = np.where(valid, psi, 0.0)
        sigma = np.where(valid, stance.sigma(psi_v), 1.0)
        mu = np.where(valid, stance.mean_limit(psi_v), 1e6)
        dz = np.where(valid, -n / sigma, 0.0)  # dz_i / dt

        def slope(t: np.ndarray, curvature: bool = False):
            f_t = fp + t[:, None] * n
            z = (mu - f_t) / sigma
            lam = mills_ratio(z)
            d1 = np.sum(lam * dz, axis=1) - REGULARISATION * np.sum(f_t * n, axis=1)
            if not curvature:
                return d1
            d2 = np.sum(-lam * (z + lam) * dz * dz, axis=1) - REGULARISATION * np.sum(n * n, 1)
            return d1, d2

        # The objective is concave in t: find the root of its slope in [t_lo, t_hi] by Newton
        # steps kept inside a shrinking bracket (bisection where Newton would leave it).
        lo, hi = t_lo.copy(), t_hi.copy()
        at_lo = slope(lo) <= 0.0
        at_hi = slope(hi) >= 0.0
        t = 0.5 * (lo + hi)
        for _ in range(newton_steps):
            d1, d2 = slope(t, curvature=True)
            lo = np.where(d1 > 0.0, t, lo)
            hi = np.where(d1 > 0.0, hi, t)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = t - d1 / d2
            inside = np.isfinite(step) & (step >= lo) & (step <= hi)
            t = np.where(inside, step, 0.5 * (lo + hi))
        t = np.where(at_lo, t_lo, np.where(at_hi, t_hi, t))
        f = fp + t[:, None] * n
        f[~ok] = np.nan
    else:
        raise ValueError(f"a stance holds 3 or 4 anchors, this one holds {int(att.sum())}")
    return _finish(robot, stance, prob, f)


def _finish(robot: RobotParams, stance: Stance, prob: StaticsProblem, f: np.ndarray) -> Allocation:
    f_lo, f_hi = robot.boom_tension
    att = stance.attached
    f = np.where(att, f, np.nan)
    residual = np.abs(np.einsum("pij,pj->pi", prob.A, np.nan_to_num(f)) - prob.b).max(axis=1)
    fa = f[:, att]
    statics_ok = (np.isfinite(fa).all(axis=1) & (fa >= f_lo - 1e-9).all(axis=1)
                  & (fa <= f_hi + 1e-9).all(axis=1) & (residual < STATICS_TOL))
    lp = np.where(att, stance.log_prob(np.nan_to_num(f), np.nan_to_num(prob.pull_angles)), 0.0)
    r = np.where(statics_ok, lp.sum(axis=1), -np.inf)
    return Allocation(f, prob.pull_angles, lp, r, statics_ok, residual, prob.shoulder_torque)


class ForceAllocator:
    """Force allocation through a Drake MathematicalProgram, built once and updated per solve.

    Each Newton-SQP iteration replaces the objective by its local concave-quadratic model (exact
    gradient and curvature of log Phi), solves that QP with the chosen open solver, and
    backtracks on the exact objective (Armijo), so every accepted step raises the true r.
    """

    def __init__(self, robot: RobotParams, solver: str = "osqp", max_iterations: int = 50):
        from pydrake.solvers import (
            ClarabelSolver,
            MathematicalProgram,
            OsqpSolver,
            SolverOptions,
        )

        self.robot = robot
        self.max_iterations = max_iterations
        prog = MathematicalProgram()
        self.f = prog.NewContinuousVariables(4, "tension")
        self.statics = prog.AddLinearEqualityConstraint(np.zeros((3, 4)), np.zeros(3), self.f)
        self.statics.evaluator().set_description("statics")
        lo, hi = robot.boom_tension
        self.bounds = prog.AddBoundingBoxConstraint(np.full(4, lo), np.full(4, hi), self.f)
        self.bounds.evaluator().set_description("tension_bounds")
        self.cost = prog.AddQuadraticCost(np.eye(4), np.zeros(4), 0.0, self.f, is_convex=True)
        self.cost.evaluator().set_description("robustness_model")
        self.prog = prog
        if solver == "osqp":
            self.solver = OsqpSolver()
            self.options = SolverOptions()
            for key, val in (("eps_abs", 1e-10), ("eps_rel", 1e-10), ("max_iter", 20000)):
                self.options.SetOption(self.solver.solver_id(), key, val)
            self.options.SetOption(self.solver.solver_id(), "polishing", 1)
        elif solver == "clarabel":
            self.solver = ClarabelSolver()
            self.options = SolverOptions()
            for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
                self.options.SetOption(self.solver.solver_id(), key, 1e-10)
        else:
            raise RbpInputError(f"must be 'osqp' or 'clarabel', got {solver!r}", field="solver")
        if not self.solver.available() or not self.solver.AreProgramAttributesSatisfied(prog):
            raise RuntimeError(f"{solver} cannot solve the force-allocation QP here")
        self.last_infeasible: list[str] = []

    def _solve_qp(self, H: np.ndarray, q: np.ndarray, guess: np.ndarray) -> np.ndarray | None:
        self.cost.evaluator().UpdateCoefficients(np.diag(H), q, 0.0, is_convex=True)
        with quiet_solver_log():
            result = self.solver.Solve(self.prog, guess, self.options)
        if not result.is_success():
            from pydrake.solvers import SolutionResult

            status = result.get_solution_result()
            if status in (SolutionResult.kInfeasibleConstraints,
                          SolutionResult.kInfeasibleOrUnbounded):
                self.last_infeasible = list(result.GetInfeasibleConstraintNames(self.prog))
            if status == SolutionResult.kIterationLimit:
                # OSQP can stall on its own tolerances with an iterate that already satisfies
                # the constraints as tightly as the statics ask: keep that one.
                f = result.GetSolution(self.f)
                if self._satisfies_constraints(f):
                    return f
            return None
        return result.GetSolution(self.f)

    def _satisfies_constraints(self, f: np.ndarray) -> bool:
        A, b = self.statics.evaluator().GetDenseA(), self.statics.evaluator().lower_bound()
        lo, hi = self.bounds.evaluator().lower_bound(), self.bounds.evaluator().upper_bound()
        return bool(np.all(np.isfinite(f)) and np.abs(A @ f - b).max() < STATICS_TOL
                    and np.all(f >= lo - 1e-9) and np.all(f <= hi + 1e-9))

    def solve(self, gravity: np.ndarray, pose: np.ndarray, stance: Stance,
              free_tip: np.ndarray | None = None) -> Allocation:
        prob = statics_problem(self.robot, gravity, pose, stance, free_tip)
        A, b, psi = prob.A[0], prob.b[0], prob.pull_angles[0]
        att = stance.attached
        lo, hi = self.robot.boom_tension
        self.statics.evaluator().UpdateCoefficients(A, b)
        self.bounds.evaluator().set_bounds(np.where(att, lo, 0.0), np.where(att, hi, 0.0))
        self.last_infeasible = []
        # Feasible start: the least-effort tensions; where the solver cannot find them (OSQP
        # stalls on ill-conditioned statics), the vectorised allocation's, if they hold.
        f = self._solve_qp(np.ones(4), np.zeros(4), np.full(4, lo))
        if f is None:
            start = allocate(self.robot, gravity, pose, stance, free_tip, problem=prob)
            f = np.where(att, start.tensions[0], 0.0) if start.statics_ok[0] else None
        if f is None:
            return _finish(self.robot, stance, prob, np.full((1, 4), np.nan))

        def value(x: np.ndarray) -> float:
            lp, _, _, _ = _objective_terms(stance, x, psi)
            return float(lp.sum() - 0.5 * REGULARISATION * np.sum(x[att] ** 2))

        current = value(f)
        for _ in range(self.max_iterations):
            _, grad, hess, _ = _objective_terms(stance, f, psi)
            H = np.where(att, -hess, 1.0)
            scale = 1.0 / max(np.max(H[att]), 1e-300)  # normalise: OSQP tolerances are absolute
            # A small floor on the curvature (damped Newton) keeps the QP well conditioned where
            # log Phi is flat; the line search on the exact objective keeps every step honest.
            H = H * scale + 1e-3
            q = -(grad * scale) - H * f
            f_qp = self._solve_qp(H, q, f)
            if f_qp is None:
                break
            step = np.where(att, f_qp - f, 0.0)
            if np.max(np.abs(step)) < 1e-10:
                break
            slope = float(grad @ step)
            alpha, accepted = 1.0, False
            while alpha > 1e-6:
                candidate = f + alpha * step
                new = value(candidate)
                if new >= current + 1e-4 * alpha * slope:
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted:
                break
            f, improvement, current = candidate, new - current, new
            if improvement < 1e-15 and alpha * np.max(np.abs(step)) < 1e-7:
                break
        return _finish(self.robot, stance, prob, f[None, :])
