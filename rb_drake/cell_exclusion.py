"""Deciding a CELL of poses with the bounds of `rb_drake.cell_bounds` (issue 30; not yet used
by the search).

* `three_stance_bound`: for a 3-stance, whose tensions are unique, an upper bound on r over the
  cell without a linear program: an interval enclosure of the tensions (the Taylor model's
  equilibrium, contracted within the tension bounds) and a tangent of the concave sum of log P
  that keeps their correlation. About 0.5 ms a cell against `robustness_bound`'s 1.7 ms median
  (7.8 ms mean), and looser where the wrench matrix is nearly singular: on the start 3-stances
  of three benchmark caves without a route it proves 86 % of the cells the LP bound proves
  (`python -m experiments.cell_bound_measure --lp-free`, docs/benchmarks.md).
* `four_stance_bound`: for a 4-stance, whose tensions form a line `p + t n` (n the null
  vector of the wrench matrix), the same without a linear program: t bounded by the tension
  limits, r by pieces of t's interval. 0.5 ms a cell against the LP's 1.8 ms median (17.5 ms
  mean), proving 77 % of the cells the LP proves on the same caves' start stances.
* `probability_upper`: the LP-free bound first, the LP bound where that proves nothing.
* `cell_probability_excluded` (with branch and bound over the cell's halves) and
  `cell_excluded` (geometry first): whether no pose of the cell passes.

Each answer is sound: a cell is called excluded only when no pose of it can pass the rule
(tests/test_cell_bounds.py samples poses in cells of eight caves against every bound).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.special import log_ndtr

from rb_drake import grasp
from rb_drake.cell_bounds import (
    LP_SLACK,
    TENSION_SLACK,
    CellGeometry,
    CellStatics,
    GraspBounds,
    cell_geometry,
    cell_geometry_excluded,
    cell_statics,
    cell_taylor,
    grasp_bounds,
    grasp_upper,
    robustness_bound,
)
from rb_drake.feasibility import Reason, World, check_poses
from rb_drake.params import NUM_BOOMS
from rb_drake.stance import Stance
from rb_drake.statics import STATICS_TOL


class ThreeStanceBound(NamedTuple):
    """`three_stance_bound`'s answer: every pose of the cell has r <= upper (-inf: none
    balances; inf: no bound found) and its (unique) tensions within [f_lo, f_hi] (4,), NaN
    for the free boom or where no bound was found."""

    upper: float
    f_lo: np.ndarray
    f_hi: np.ndarray


class _CellModel(NamedTuple):
    """What both LP-free bounds start from, on the attached booms' columns: the grasp bounds,
    the interval load, and the Taylor model A_0 + sum_k J[k] dq_k (+-E) of the wrench matrix."""

    gb: GraspBounds
    cs: CellStatics
    A0: np.ndarray
    J: list[np.ndarray]
    E: np.ndarray


def _cell_model(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                free_tip: np.ndarray | None, geo: CellGeometry | None) -> _CellModel | float:
    """The cell's model, or the bound it already settles: -inf where some grasp is dead at
    every pose (log P = -inf), inf where the Taylor model is not finite (no bound)."""
    robot = world.robot
    g = geo if geo is not None else cell_geometry(robot, stance, centre, half, free_tip)
    gb = grasp_bounds(stance, g)
    if gb.dead.any():
        return -math.inf
    att = stance.attached
    cs = cell_statics(robot, world.gravity_vector, stance, centre, half, g)
    tm = cell_taylor(robot, stance, centre, half, g)
    A0, E = tm.A0[:, att], tm.E[:, att]
    J = [tm.J[:, att, k] for k in range(3)]
    if not (np.isfinite(A0).all() and np.isfinite(E).all()
            and all(np.isfinite(j).all() for j in J)):
        return math.inf
    return _CellModel(gb, cs, A0, J, E)


def three_stance_bound(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                       free_tip: np.ndarray, rounds: int = 8,
                       geo: CellGeometry | None = None) -> ThreeStanceBound:
    """An upper bound on r over the cell for a 3-stance, without a linear program.

    A 3-stance's tensions are unique, f = A(q)^-1 b(q). With the Taylor model
    A(q) = A_0 + sum_k J_k dq_k + R(q), |R| <= E (`cell_taylor`), b(q) = b_c + d, |d| <=
    b_delta + STATICS_TOL (`cell_statics`; feasibility calls residuals under STATICS_TOL
    equilibrium) and C = A_0^-1, every pose's tensions satisfy
    `f = f_0 + C d - sum_k dq_k C J_k f - C R f` with f_0 = C b_c. Over a box f in [lo, hi]
    (at first the tension bounds, which every feasible pose's tensions lie in) each term's
    range is exact or bounded (`|C J_k f| <= |C J_k f_m| + |C J_k| f_r` for the box's middle
    f_m and radius f_r), so f lies in f_0 +- dev; intersected with the box and repeated (a
    Krawczyk-like contraction) it narrows; an empty box proves that no pose balances.
    Then r <= sum g_i(lo_i) (g_i of `grasp_upper`, decreasing), and, where every f_i can stay
    below its largest mean limit (g_i concave there), the tangent bound
    `sum g_i(f_0i) + sum_k h_k |(s^T V)_k| + |s|^T |rho|` with s_i = g_i'(f_0i), V's columns
    -C J_k f_0 (f's first-order change) and rho the rest of f - f_0: the tangent keeps the
    correlation between the tensions that the per-boom bound forgets. About 0.5 ms a cell
    (`robustness_bound` takes 3-15 ms); looser where A_0 is nearly singular."""
    robot = world.robot
    nan4 = np.full(NUM_BOOMS, np.nan)
    idx = np.flatnonzero(stance.attached)
    if len(idx) != 3:
        raise ValueError(f"three_stance_bound needs a 3-stance, this one holds {len(idx)} anchors")
    model = _cell_model(world, stance, centre, half, free_tip, geo)
    if not isinstance(model, _CellModel):
        return ThreeStanceBound(model, nan4, nan4)
    gb, cs, A0, J, E = model
    unbounded = ThreeStanceBound(math.inf, nan4, nan4)
    with np.errstate(all="ignore"):
        try:
            C = np.linalg.inv(A0)
        except np.linalg.LinAlgError:
            return unbounded
    if not np.isfinite(C).all():
        return unbounded
    aC = np.abs(C)
    h = np.abs(np.asarray(half, dtype=float))
    f0 = C @ cs.b_c
    CJ = [C @ j for j in J]
    aCJ = [np.abs(m) for m in CJ]
    aCE = aC @ E
    c_d = aC @ (cs.b_delta + STATICS_TOL)
    t_lo, t_hi = robot.boom_tension
    lo = np.full(3, t_lo - TENSION_SLACK)
    hi = np.full(3, t_hi + TENSION_SLACK)
    for _ in range(rounds):
        fm, fr = 0.5 * (lo + hi), 0.5 * (hi - lo)
        dev = (c_d + sum(h[k] * (np.abs(CJ[k] @ fm) + aCJ[k] @ fr) for k in range(3))
               + aCE @ (np.abs(fm) + fr))
        dev = dev * (1.0 + 1e-9) + TENSION_SLACK
        new_lo, new_hi = np.maximum(lo, f0 - dev), np.minimum(hi, f0 + dev)
        if np.any(new_lo > new_hi):
            return ThreeStanceBound(-math.inf, nan4, nan4)
        settled = np.allclose(new_lo, lo, rtol=0.0, atol=1e-6) and np.allclose(
            new_hi, hi, rtol=0.0, atol=1e-6)
        lo, hi = new_lo, new_hi
        if settled:
            break
    f_lo, f_hi = nan4.copy(), nan4.copy()
    f_lo[idx], f_hi[idx] = lo, hi
    upper = float(sum(float(grasp_upper(lo[k], gb, int(i))) for k, i in enumerate(idx)))
    mu, slo = gb.mu_hi[idx], gb.sigma_lo[idx]
    if np.all(hi <= mu) and np.all(f0 <= mu):
        e = np.maximum(np.abs(lo - f0), np.abs(hi - f0))
        V = -np.stack([CJ[k] @ f0 for k in range(3)], axis=1)
        rho = c_d + sum(h[k] * aCJ[k] for k in range(3)) @ e + aCE @ (np.abs(f0) + e)
        z = (mu - f0) / slo
        s = -grasp.mills_ratio(z) / slo
        tangent = (float(np.sum(log_ndtr(z))) + float(np.abs(s @ V) @ h)
                   + float(np.abs(s) @ rho)) + LP_SLACK
        upper = min(upper, tangent)
    return ThreeStanceBound(upper, f_lo, f_hi)


FOUR_STANCE_GRID = 64  # pieces of the null-space interval over which r is bounded


def four_stance_bound(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                      rounds: int = 8, geo: CellGeometry | None = None) -> float:
    """An upper bound on r over the cell for a 4-stance, without a linear program.

    With the Taylor model of `three_stance_bound`, every pose's tensions satisfy
    `A_0 f = b_c + delta`, |delta| bounded over a box of f (at first the tension bounds); A_0
    (3 x 4) of rank 3 makes them `f = P (b_c + delta) + t n` (P its pseudo-inverse, n its unit
    null vector), so `f_i = p_i + t n_i + d_i` with |d_i| <= (|P| |delta|)_i. The box then
    bounds t (an empty interval: no pose balances) and t the box, repeated while it narrows.
    As f_i >= max(lo_i, p_i + t n_i - D_i) and each g_i (`grasp_upper`) decreases, r <= the
    largest over t of `sum_i g_i(max(lo_i, p_i + t n_i - D_i))`; each term is monotone in t,
    so over each of FOUR_STANCE_GRID pieces of t's interval the sum of its terms' larger end
    values bounds it, and the largest piece's bound is returned. Looser than the LP bound
    (the d_i move independently), far cheaper."""
    robot = world.robot
    if not stance.attached.all():
        raise ValueError("four_stance_bound needs a 4-stance")
    model = _cell_model(world, stance, centre, half, None, geo)
    if not isinstance(model, _CellModel):
        return model
    gb, cs, A0, J, E = model
    u, sing, vt = np.linalg.svd(A0)
    if sing[-1] <= 1e-9 * max(sing[0], 1e-300):
        return math.inf
    P = vt[:3].T @ (u.T / sing[:, None])  # the pseudo-inverse, from the SVD already made
    aP = np.abs(P)
    n = vt[-1]
    p = P @ cs.b_c
    h = np.abs(np.asarray(half, dtype=float))
    t_lo, t_hi = robot.boom_tension
    lo = np.full(NUM_BOOMS, t_lo - TENSION_SLACK)
    hi = np.full(NUM_BOOMS, t_hi + TENSION_SLACK)
    aJ = [np.abs(j) for j in J]
    t_range = (-math.inf, math.inf)
    D = np.zeros(NUM_BOOMS)
    for _ in range(rounds):
        fm, fr = 0.5 * (lo + hi), 0.5 * (hi - lo)
        delta = (cs.b_delta + STATICS_TOL
                 + sum(h[k] * (np.abs(J[k] @ fm) + aJ[k] @ fr) for k in range(3))
                 + E @ (np.abs(fm) + fr))
        D = (aP @ delta) * (1.0 + 1e-9) + TENSION_SLACK
        # lo_j - D_j <= p_j + t n_j <= hi_j + D_j for every j
        a, b = lo - D - p, hi + D - p
        t0, t1 = -math.inf, math.inf
        for j in range(NUM_BOOMS):
            if abs(n[j]) < 1e-12:  # a constraint dropped: a larger set, still sound
                continue
            u, v = sorted((a[j] / n[j], b[j] / n[j]))
            t0, t1 = max(t0, u), min(t1, v)
        if t0 > t1:
            return -math.inf
        t_range = (t0, t1)
        ends = np.array([t0, t1])
        new_lo = np.maximum(lo, p + np.minimum(ends[0] * n, ends[1] * n) - D)
        new_hi = np.minimum(hi, p + np.maximum(ends[0] * n, ends[1] * n) + D)
        if np.any(new_lo > new_hi):
            return -math.inf
        settled = (np.abs(new_lo - lo).max() < 1e-6) and (np.abs(new_hi - hi).max() < 1e-6)
        lo, hi = new_lo, new_hi
        if settled:
            break
    ts = np.linspace(t_range[0], t_range[1], FOUR_STANCE_GRID + 1)
    f_least = np.maximum(lo[None, :], p[None, :] + ts[:, None] * n[None, :] - D[None, :])
    terms = np.stack([grasp_upper(f_least[:, i], gb, i) for i in range(NUM_BOOMS)], axis=1)
    piece = np.maximum(terms[:-1], terms[1:]).sum(axis=1)
    return float(piece.max()) + LP_SLACK


def cell_probability_excluded(world: World, stance: Stance, centre: np.ndarray,
                              half: np.ndarray, free_tip: np.ndarray | None = None,
                              depth: int = 0) -> bool:
    """Whether no pose of the cell has r >= log p_min (the probability rule, or statics).

    `depth` > 0: where the cell's bound does not prove it, split the cell into its 8 halves
    and prove each (branch and bound, to that depth); a sub-cell whose centre pose has
    r >= log p_min stops the search (no bound can prove it)."""
    log_p_min = world.robot.log_p_min
    centre = np.asarray(centre, dtype=float)
    half = np.asarray(half, dtype=float)
    if probability_upper(world, stance, centre, half, free_tip) < log_p_min:
        return True
    if depth <= 0:
        return False
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    subs = centre + signs * (half / 2)
    r = check_poses(world, stance, subs, free_tip=free_tip, full=True).allocation.robustness
    if np.any(r >= log_p_min):
        return False
    return all(cell_probability_excluded(world, stance, c, half / 2, free_tip, depth - 1)
               for c in subs)


def cell_excluded(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                  free_tip: np.ndarray | None = None) -> Reason | None:
    """A rule no pose of the cell passes (geometry first, then the probability bound; a cell
    none of whose poses balances within the tension bounds gives PROBABILITY too, as its r is
    -inf), or None."""
    geo = cell_geometry(world.robot, stance, centre, half, free_tip)
    reason = cell_geometry_excluded(world.robot, stance, centre, half, free_tip, geo)
    if reason is not None:
        return reason
    upper = probability_upper(world, stance, centre, half, free_tip, geo=geo)
    return Reason.PROBABILITY if upper < world.robot.log_p_min else None


def probability_upper(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                      free_tip: np.ndarray | None = None, geo: CellGeometry | None = None
                      ) -> float:
    """An upper bound on r over the cell: `three_stance_bound` or `four_stance_bound` first (no
    LP), `robustness_bound` where that does not already prove r < log p_min; the smaller of
    the two, each sound, is returned."""
    g = geo if geo is not None else cell_geometry(world.robot, stance, centre, half, free_tip)
    fast = math.inf
    if stance.free_boom is not None and free_tip is not None:
        fast = three_stance_bound(world, stance, centre, half, free_tip, geo=g).upper
    elif stance.attached.all():
        fast = four_stance_bound(world, stance, centre, half, geo=g)
    if fast < world.robot.log_p_min:
        return fast
    return min(fast, robustness_bound(world, stance, centre, half, free_tip, geo=g).upper)
