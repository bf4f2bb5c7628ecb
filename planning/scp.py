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

The convex subproblem is `planning.scp_program`, the linearisation `planning.scp_linearise`;
this module holds the exact merit and feasibility, the trust-region loop and the entry points.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from planning.between import between_steps
from planning.scp_linearise import Iterate
from planning.scp_linearise import Linearisation as Linearisation  # re-exported
from planning.scp_program import Margins, ScpConfig, Subproblem, SubproblemProgram
from rb_drake import geometry
from rb_drake.collision import boom_clearances
from rb_drake.feasibility import (
    MIN_CONDITIONING,
    Reason,
    check_poses,
    pull_within,
    reach_world,
    rock_inside_body,
    wrench_conditioning,
)
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import allocate, null_vector

BOUND_TOL = 1e-9  # N, m, rad: slack on limits when checking an iterate exactly


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


class Evaluation(NamedTuple):
    merit: float
    robustness: np.ndarray   # (N,) r_k
    dynamics: np.ndarray     # (N-1, 6) residual D_k
    feasible: bool
    reason: str


class PhaseProgram(SubproblemProgram):
    """The SCP of one phase: the convex subproblem (a Drake MathematicalProgram built once),
    the linearisation, the exact merit and the trust-region loop."""

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
            clearance = boom_clearances(self.world.anchor_positions, len(it.poses),
                                        self.stance.free_boom, self.tips)
            end = self.targets - clearance[..., None] * geo.u
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
            margins = (None if cand is None or cev is None or cev.feasible
                       else self.violations(cand))
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
                assert cand is not None and cev is not None  # accepted: a feasible trial point
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
    assert tips is not None, "a reach phase (a free boom) has the free gripper's path"
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
    world = reach_world(scn, tips)  # a free gripper touches rock only near its own anchors
    program = PhaseProgram(world, stance, N, dt, cfg, tips)

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
    check = check_poses(world, stance, it.poses, tips)  # the library's own verdict, once
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
