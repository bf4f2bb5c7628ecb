"""Sound bounds over a lattice CELL of poses (issue 30, a prototype; not used by the search).

A cell is the box of body poses `|x - x_c| <= hx`, `|y - y_c| <= hy`, `|phi - phi_c| <= hphi`
around a centre pose. The complete search decides feasibility at lattice points only; a proof
of "no route" over the continuum needs, per cell, a proof that NO pose of the cell passes the
rules. This module gives two such proofs, each sound (never excludes a cell holding a pose
that `feasibility.check_poses` calls feasible) and never used by the planner:

* `cell_geometry` / `cell_geometry_excluded`: intervals of each boom's length, shoulder angle
  and pull angle over the cell, and the first kinematic or pull-angle rule that no pose of the
  cell can satisfy. Boom i's shoulder moves at most `rho_i = |(hx, hy)| + 2 |s_i| sin(hphi/2)`
  from its position at the centre; its target is fixed, so its length lies within `L_c +- rho_i`
  and its direction turns by at most `asin(rho_i / L_c)` (pi when `rho_i >= L_c`): the angle a
  disc of radius rho_i at distance L_c subtends. The pull angle turns with the direction, the
  shoulder angle by that plus hphi.
* `robustness_bound` / `cell_probability_excluded`: an upper bound U on the robustness
  `r = sum log P_i` of every pose of the cell (with its most robust tensions). Over the cell,
  every entry of the wrench matrix A (a direction's cosine or sine, a shoulder offset's cross
  product with it) and of the load b lies in an interval, `A_c +- Delta`, `b_c +- delta`. For
  tensions f >= 0 the Oettli-Prager theorem makes the set of f that solve `A f = b` for SOME A, b
  of those boxes the polytope `|A_c f - b_c| <= Delta f + delta`; intersected with the tension
  bounds it holds every pose's tensions (`delta` also holds the statics tolerance, the bounds
  their 1e-9 N). The boxes forget that all entries move with the same three pose offsets, so
  the polytope is intersected with a Taylor model's (`cell_taylor`: A = A_0 + J dq + R with a
  proven bound on R; the products f_i dq_k relaxed by McCormick's envelopes, rebuilt with the
  tension ranges each round proves).
  Each grasp's `log P_i = log Phi((mu_i(psi_i) - f_i) / sigma_i(psi_i))` is at
  most `g_i(f_i) = log Phi(zmax_i(f_i))`, `zmax_i = (mu_hi - f) / sigma_lo` for `f <= mu_hi`
  and `(mu_hi - f) / sigma_hi` above, with mu and sigma bounded over the cell's pull-angle
  interval (both are monotone in |psi|): g_i is decreasing in f_i. So
  `U = max over the polytope of sum g_i(f_i)`, bounded two ways, the smaller taken:
  `sum g_i(min f_i)` (one LP per boom), and, where every `f_i <= mu_hi_i` (elsewhere some
  `g_i <= log 1/2`, counted separately), the concave `sum log Phi((mu_hi_i - f_i)/sigma_lo_i)`
  maximised over the polytope by Kelley's cutting planes: an LP over tangent lines, each an
  upper bound of its concave term, so every LP value is itself a sound bound.

* `rb_drake.cell_exclusion` decides cells with these bounds (and, for a 3-stance, a faster
  one without a linear program), splitting where they prove nothing.

Rules left out (which keeps the bounds sound, only looser): collisions, the free limb's
shoulder torque, the conditioning of the wrench matrix. The regulariser of the allocation only
makes its r smaller than the maximum over the tensions, which U bounds.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import linprog
from scipy.special import log_ndtr

from rb_drake import grasp
from rb_drake.feasibility import Reason, World
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.stance import Stance
from rb_drake.statics import STATICS_TOL

TWO_PI = 2.0 * math.pi
# Rounding allowances (far above the few ulps of the quantities they widen).
ANGLE_SLACK = 1e-9     # rad, added to every angle interval's half-width
LENGTH_SLACK = 1e-9    # m, added to every shoulder displacement
TENSION_SLACK = 1e-9   # N, as feasibility's statics test allows beyond the tension bounds
LP_SLACK = 1e-6        # log P (and N): added to LP values, the LP solver's tolerance


def _angle_interval_cos(centre: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact range [lo, hi] of cos over [centre - half, centre + half] (elementwise)."""
    centre = np.asarray(centre, dtype=float)
    half = np.asarray(half, dtype=float)
    a, b = centre - half, centre + half
    ca, cb = np.cos(a), np.cos(b)
    lo, hi = np.minimum(ca, cb), np.maximum(ca, cb)
    # a maximum (2 k pi) or a minimum ((2 k + 1) pi) inside the interval
    has_max = np.floor(b / TWO_PI) >= np.ceil(a / TWO_PI)
    has_min = np.floor((b - math.pi) / TWO_PI) >= np.ceil((a - math.pi) / TWO_PI)
    wide = half >= math.pi
    hi = np.where(has_max | wide, 1.0, hi)
    lo = np.where(has_min | wide, -1.0, lo)
    return lo, hi


def _angle_interval_sin(centre: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact range of sin over [centre - half, centre + half]."""
    return _angle_interval_cos(np.asarray(centre, dtype=float) - 0.5 * math.pi, half)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a, dtype=float) + math.pi) % TWO_PI - math.pi


class CellGeometry(NamedTuple):
    """Per boom (4,), over a cell: bounds on the geometry of every pose in it."""

    used: np.ndarray          # booms with a target (attached, or the free one with its tip)
    attached: np.ndarray
    rho: np.ndarray           # shoulder displacement from the centre pose's, at most
    length_c: np.ndarray      # boom length at the centre
    length_lo: np.ndarray
    length_hi: np.ndarray
    turn: np.ndarray          # |beta - beta_c| at most (boom direction change; pi: unbounded)
    beta_c: np.ndarray        # boom direction at the centre (shoulder -> target)
    theta_c: np.ndarray       # shoulder angle at the centre (wrapped)
    theta_half: np.ndarray    # |theta - theta_c| at most (turn + hphi)
    psi_c: np.ndarray         # pull angle at the centre (wrapped; NaN for a free boom)
    abs_psi_lo: np.ndarray    # |psi| over the cell, within [abs_psi_lo, abs_psi_hi]
    abs_psi_hi: np.ndarray
    shoulder_c: np.ndarray    # (4, 2) shoulders at the centre pose
    targets: np.ndarray       # (4, 2)


def _targets(stance: Stance, free_tip: np.ndarray | None) -> np.ndarray:
    targets = np.where(stance.attached[:, None], stance.positions, np.nan).astype(float)
    j = stance.free_boom
    if j is not None:
        if free_tip is None:
            raise ValueError(f"a 3-stance (boom {j} free) needs the free gripper's position")
        targets[j] = np.asarray(free_tip, dtype=float)
    return targets


def cell_geometry(robot: RobotParams, stance: Stance, centre: np.ndarray, half: np.ndarray,
                  free_tip: np.ndarray | None = None) -> CellGeometry:
    """Bounds on every boom's length, direction, shoulder and pull angles over the cell of
    poses within `half` = (hx, hy, hphi) of `centre` = (x, y, phi) (see the module doc)."""
    x, y, phi = (float(v) for v in centre)
    hx, hy, hphi = (abs(float(v)) for v in half)
    targets = _targets(stance, free_tip)
    used = np.isfinite(targets[:, 0])
    s = robot.shoulder_array
    c, sn = math.cos(phi), math.sin(phi)
    off = np.stack([c * s[:, 0] - sn * s[:, 1], sn * s[:, 0] + c * s[:, 1]], axis=-1)
    shoulder = np.array([x, y]) + off
    d = targets - shoulder
    length_c = np.hypot(d[:, 0], d[:, 1])
    s_norm = np.hypot(s[:, 0], s[:, 1])
    rho = (math.hypot(hx, hy) + 2.0 * s_norm * math.sin(min(hphi, math.pi) / 2.0)) * (
        1.0 + 1e-12) + LENGTH_SLACK
    length_lo = np.maximum(length_c - rho, 0.0)
    length_hi = length_c + rho
    with np.errstate(invalid="ignore", divide="ignore"):
        turn = np.where(rho < length_c, np.arcsin(np.minimum(1.0, rho / length_c)), math.pi)
    turn = np.minimum(turn + ANGLE_SLACK, math.pi)
    beta_c = np.arctan2(d[:, 1], d[:, 0])
    theta_c = _wrap(beta_c - phi - robot.shoulder_directions)
    theta_half = turn + hphi + ANGLE_SLACK
    n = np.where(stance.attached[:, None], stance.normals, np.nan)
    v = -d  # the grasp is pulled towards the shoulder
    psi_c = np.arctan2(n[:, 0] * v[:, 1] - n[:, 1] * v[:, 0], n[:, 0] * v[:, 0] + n[:, 1] * v[:, 1])
    abs_psi_lo = np.maximum(np.abs(psi_c) - turn, 0.0)
    abs_psi_hi = np.minimum(np.abs(psi_c) + turn, math.pi)
    return CellGeometry(used, stance.attached.copy(), rho, length_c, length_lo, length_hi, turn,
                        beta_c, theta_c, theta_half, psi_c, abs_psi_lo, abs_psi_hi, shoulder,
                        targets)


def cell_geometry_excluded(robot: RobotParams, stance: Stance, centre: np.ndarray,
                           half: np.ndarray, free_tip: np.ndarray | None = None,
                           geo: CellGeometry | None = None) -> Reason | None:
    """The first rule (BOOM_LENGTH, SHOULDER_ANGLE, PULL_ANGLE) that no pose of the cell
    satisfies for some one boom, or None when the geometry proves nothing."""
    g = geo if geo is not None else cell_geometry(robot, stance, centre, half, free_tip)
    lo, hi = robot.boom_length
    if np.any(g.used & ((g.length_hi < lo) | (g.length_lo > hi))):
        return Reason.BOOM_LENGTH
    # |theta| >= |theta_c| - theta_half on the circle; feasible needs |theta| <= range + 1e-12
    if np.any(g.used & (np.abs(g.theta_c) - g.theta_half > robot.shoulder_range + 1e-12)):
        return Reason.SHOULDER_ANGLE
    if np.any(g.attached & (g.abs_psi_lo > robot.max_pull_angle)):
        return Reason.PULL_ANGLE
    return None


class CellStatics(NamedTuple):
    """Interval equilibrium over a cell: A in A_c +- A_delta (3, 4), b in b_c +- b_delta (3,)
    (free boom's column zero)."""

    A_c: np.ndarray
    A_delta: np.ndarray
    b_c: np.ndarray
    b_delta: np.ndarray


def _interval_mul(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    p = (a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1])
    return min(p), max(p)


def cell_statics(robot: RobotParams, gravity: np.ndarray, stance: Stance, centre: np.ndarray,
                 half: np.ndarray, geo: CellGeometry) -> CellStatics:
    """The entrywise intervals of A and b (statics.statics_problem) over the cell."""
    x, y, phi = (float(v) for v in centre)
    hx, hy, hphi = (abs(float(v)) for v in half)
    att = stance.attached
    ux = _angle_interval_cos(geo.beta_c, geo.turn)
    uy = _angle_interval_sin(geo.beta_c, geo.turn)
    s = robot.shoulder_array
    s_norm = np.hypot(s[:, 0], s[:, 1])
    alpha = np.arctan2(s[:, 1], s[:, 0])
    # (R s_i) x u_i = |s_i| sin(beta_i - phi - alpha_i); the angle moves by turn + hphi
    tq = _angle_interval_sin(geo.beta_c - phi - alpha, geo.turn + hphi + ANGLE_SLACK)
    lo = np.stack([ux[0], uy[0], s_norm * tq[0]])
    hi = np.stack([ux[1], uy[1], s_norm * tq[1]])
    lo = np.where(att, lo, 0.0)
    hi = np.where(att, hi, 0.0)
    A_c = 0.5 * (lo + hi)
    A_delta = 0.5 * (hi - lo) * (1.0 + 1e-12) + 1e-15
    g = np.asarray(gravity, dtype=float)
    M = robot.body_mass
    b_lo = np.array([-M * g[0], -M * g[1], 0.0])
    b_hi = b_lo.copy()
    j = stance.free_boom
    if j is not None:  # the free limb's load (geometry.limb_load), in interval arithmetic
        m_g = robot.gripper_mass
        mb = (robot.boom_linear_density * geo.length_lo[j],
              robot.boom_linear_density * geo.length_hi[j])
        mass = (mb[0] + m_g, mb[1] + m_g)
        for k in range(2):
            w = _interval_mul(mass, (g[k], g[k]))
            b_lo[k] -= w[1]
            b_hi[k] -= w[0]
        t = geo.targets[j]
        # (t - c) x g = (t_x - x) g_y - (t_y - y) g_x, linear in (x, y)
        tc = (t[0] - x) * g[1] - (t[1] - y) * g[0]
        tc_half = hx * abs(g[1]) + hy * abs(g[0])
        tcx = (tc - tc_half, tc + tc_half)
        # (R s_j) x g = |s_j| |g| sin(angle(g) - phi - alpha_j)
        gn = float(np.hypot(g[0], g[1]))
        sg = _angle_interval_sin(np.array(math.atan2(g[1], g[0]) - phi - alpha[j]),
                                 np.array(hphi + ANGLE_SLACK))
        sxg = (float(s_norm[j] * gn * sg[0]), float(s_norm[j] * gn * sg[1]))
        # tau = m_b / 2 ((R s_j) x g + (t - c) x g) + m_g (t - c) x g
        inner = (sxg[0] + tcx[0], sxg[1] + tcx[1])
        part = _interval_mul((0.5 * mb[0], 0.5 * mb[1]), inner)
        tau = (part[0] + m_g * tcx[0], part[1] + m_g * tcx[1])
        b_lo[2] -= tau[1]
        b_hi[2] -= tau[0]
    b_c = 0.5 * (b_lo + b_hi)
    b_delta = 0.5 * (b_hi - b_lo) * (1.0 + 1e-12) + 1e-12
    return CellStatics(A_c, A_delta, b_c, b_delta)


class GraspBounds(NamedTuple):
    """Per attached boom, over the cell's pull angles: the largest mean limit and the smallest
    and largest spread (inf mu_hi: no bound; -inf: every pose has P = 0)."""

    mu_hi: np.ndarray
    sigma_lo: np.ndarray
    sigma_hi: np.ndarray
    dead: np.ndarray  # |psi| >= pi/2 at every pose of the cell: log P = -inf


def grasp_bounds(stance: Stance, geo: CellGeometry) -> GraspBounds:
    att = stance.attached
    lo = np.where(att, np.minimum(geo.abs_psi_lo, grasp.HALF_PI), 0.0)
    hi = np.where(att, np.minimum(geo.abs_psi_hi, grasp.HALF_PI), 0.0)
    fn = np.where(att, stance.f_normal, 1.0)
    ft = np.where(att, stance.f_lateral, 1.0)
    sn = np.where(att, stance.sigma_normal, 1.0)
    st = np.where(att, stance.sigma_lateral, 1.0)
    # mu and sigma are monotone in |psi| on [0, pi/2]: their extremes are at the ends
    mu = np.stack([grasp.mean_limit(lo, fn, ft), grasp.mean_limit(hi, fn, ft)])
    sg = np.stack([grasp.sigma_limit(lo, sn, st), grasp.sigma_limit(hi, sn, st)])
    mu_hi = mu.max(axis=0) * (1.0 + 1e-12)
    sigma_lo = sg.min(axis=0) * (1.0 - 1e-12)
    sigma_hi = sg.max(axis=0) * (1.0 + 1e-12)
    dead = att & (geo.abs_psi_lo >= grasp.HALF_PI)
    return GraspBounds(mu_hi, sigma_lo, sigma_hi, dead)


def grasp_upper(f: np.ndarray, gb: GraspBounds, k: np.ndarray | int) -> np.ndarray:
    """g_k(f): an upper bound on log P of grasp k at tension f over the cell (decreasing)."""
    mu, slo, shi = gb.mu_hi[k], gb.sigma_lo[k], gb.sigma_hi[k]
    f = np.asarray(f, dtype=float)
    z = np.where(f <= mu, (mu - f) / slo, (mu - f) / shi)
    return np.where(gb.dead[k], -np.inf, log_ndtr(z))


class RobustnessBound(NamedTuple):
    upper: float          # U: every pose of the cell has r <= U (-inf: no pose balances)
    simple: float         # sum g_i(min f_i), the one-LP-per-boom bound (U <= simple)
    f_min: np.ndarray     # (4,) min f_i over the polytope (NaN for a free boom / empty)
    f_max: np.ndarray
    gap: float            # the cutting planes' last LP value less a value they attain
    lps: int              # LPs solved


class TaylorModel(NamedTuple):
    """A(q) = A_0 + sum_k J[:, :, k] (q - q_c)_k + R(q) over the cell, |R| <= E entrywise:
    A_0 (3, 4) at the centre, J (3, 4, 3) its derivatives there, E (3, 4) a bound on the
    second-order remainder (free boom's entries zero)."""

    A0: np.ndarray
    J: np.ndarray
    E: np.ndarray


def cell_taylor(robot: RobotParams, stance: Stance, centre: np.ndarray, half: np.ndarray,
                geo: CellGeometry) -> TaylorModel:
    """The first-order model of the wrench matrix over the cell, with a sound remainder.

    Along q(t) = q_c + t dq, boom i's vector d = a_i - c - R(phi) s_i has |d'| <= v_i =
    |(dx, dy)| + |s_i| |dphi| and |d''| <= |s_i| dphi^2, so its direction beta has
    |beta'| <= v_i / L, |beta''| <= |d''| / L + 2 v_i^2 / L^2 (L >= the cell's least length).
    Then |u''| <= beta'^2 + |beta''| and the moment entry |s_i| sin(beta - phi - alpha_i) has
    second derivative at most |s_i| ((|beta'| + |dphi|)^2 + |beta''|): half of each bounds
    Taylor's remainder."""
    hx, hy, hphi = (abs(float(v)) for v in half)
    phi = float(centre[2])
    att = stance.attached
    s = robot.shoulder_array
    c, sn = math.cos(phi), math.sin(phi)
    off = np.stack([c * s[:, 0] - sn * s[:, 1], sn * s[:, 0] + c * s[:, 1]], axis=-1)
    d = geo.targets - geo.shoulder_c
    L = geo.length_c
    u = d / L[:, None]
    # d d / d q: -(1, 0), -(0, 1), -perp(R s)
    dd = np.zeros((NUM_BOOMS, 2, 3))
    dd[:, 0, 0] = -1.0
    dd[:, 1, 1] = -1.0
    dd[:, 0, 2] = off[:, 1]
    dd[:, 1, 2] = -off[:, 0]
    dbeta = (d[:, 0, None] * dd[:, 1, :] - d[:, 1, None] * dd[:, 0, :]) / (L[:, None] ** 2)
    J = np.zeros((3, NUM_BOOMS, 3))
    J[0] = -u[:, 1, None] * dbeta
    J[1] = u[:, 0, None] * dbeta
    cosg = off[:, 0] * u[:, 0] + off[:, 1] * u[:, 1]  # (R s) . u = |s| cos(gamma)
    dg = dbeta.copy()
    dg[:, 2] -= 1.0
    J[2] = cosg[:, None] * dg
    s_norm = np.hypot(s[:, 0], s[:, 1])
    v = math.hypot(hx, hy) + s_norm * hphi
    acc = s_norm * hphi**2
    with np.errstate(divide="ignore", invalid="ignore"):
        Lm = geo.length_lo
        b1 = v / Lm
        b2 = acc / Lm + 2.0 * v**2 / Lm**2
        e_u = 0.5 * (b1**2 + b2)
        e_t = 0.5 * s_norm * ((b1 + hphi) ** 2 + b2)
    e_u = np.where(Lm > 0, e_u, np.inf)
    e_t = np.where(Lm > 0, e_t, np.inf)
    E = np.stack([e_u, e_u, e_t]) * (1.0 + 1e-9) + 1e-15
    A0 = np.stack([u[:, 0], u[:, 1], off[:, 0] * u[:, 1] - off[:, 1] * u[:, 0]])
    A0 = np.where(att, A0, 0.0)
    J = np.where(att[None, :, None], J, 0.0)
    E = np.where(att, E, 0.0)
    return TaylorModel(A0, J, E)


def _polytope(cs: CellStatics, att: np.ndarray, f_lo: float, f_hi: float,
              tm: TaylorModel | None = None, half: np.ndarray | None = None,
              f_box: tuple[np.ndarray, np.ndarray] | None = None):
    """A_ub, b_ub and bounds of a polytope over z = (f, dq, w) (the attached tensions, then,
    with a Taylor model, the pose offset and w_ik standing for f_i dq_k) whose projection on f
    holds every pose's tensions: the Oettli-Prager polytope of the interval A and b, and the
    Taylor model's `|A_0 f + sum J_k w_k - b| <= E f + delta` with McCormick's envelopes of
    the products f_i dq_k. `f_box` (per attached boom, lo and hi): tighter tension bounds
    already proven for every pose of the cell, which tighten the McCormick envelopes."""
    A_c, D = cs.A_c[:, att], cs.A_delta[:, att]
    m = int(att.sum())
    delta = cs.b_delta + STATICS_TOL  # feasibility calls residuals < STATICS_TOL equilibrium
    lo, hi = f_lo - TENSION_SLACK, f_hi + TENSION_SLACK
    if lo < 0.0:
        raise ValueError("cell bounds assume positive tension bounds (f >= 0)")
    nz = m if tm is None else m + 3 + 3 * m
    rows: list[np.ndarray] = []
    rhs: list[np.ndarray] = []
    # Oettli-Prager, f >= 0: |A_c f - b_c| <= D f + delta
    for sign in (1.0, -1.0):
        R = np.zeros((3, nz))
        R[:, :m] = sign * A_c - D
        rows.append(R)
        rhs.append(sign * cs.b_c + delta)
    flo = np.full(m, lo) if f_box is None else np.maximum(lo, f_box[0])
    fhi = np.full(m, hi) if f_box is None else np.minimum(hi, f_box[1])
    fhi = np.maximum(fhi, flo)
    bounds = [(float(a), float(b)) for a, b in zip(flo, fhi, strict=True)]
    if tm is not None and half is not None:
        A0, E = tm.A0[:, att], tm.E[:, att]
        J = tm.J[:, att, :]  # (3, m, 3)
        h = np.abs(np.asarray(half, dtype=float))
        W = J.reshape(3, 3 * m)  # column i * 3 + k: w_ik
        for sign in (1.0, -1.0):
            R = np.zeros((3, nz))
            R[:, :m] = sign * A0 - E
            R[:, m + 3:] = sign * W
            rows.append(R)
            rhs.append(sign * cs.b_c + delta)
        mc = np.zeros((4 * 3 * m, nz))
        mb = np.zeros(4 * 3 * m)
        r = 0
        for i in range(m):
            for k in range(3):
                col = m + 3 + 3 * i + k
                # w >= lo d - h f + h lo ;  w >= hi d + h f - h hi
                # w <= hi d - h f + h hi ;  w <= lo d + h f - h lo
                a, b = flo[i], fhi[i]
                for cw, cd, cf, cb in ((-1.0, a, -h[k], -h[k] * a),
                                       (-1.0, b, h[k], h[k] * b),
                                       (1.0, -b, h[k], h[k] * b),
                                       (1.0, -a, -h[k], -h[k] * a)):
                    mc[r, col] = cw
                    mc[r, m + k] = cd
                    mc[r, i] = cf
                    mb[r] = cb
                    r += 1
        rows.append(mc)
        rhs.append(mb)
        bounds = bounds + [(-float(v), float(v)) for v in h] + [
            (-h[k] * fhi[i], h[k] * fhi[i]) for i in range(m) for k in range(3)]
    return np.vstack(rows), np.concatenate(rhs), bounds


def _lp(c: np.ndarray, A_ub: np.ndarray, b_ub: np.ndarray, bounds) -> tuple[bool, float,
                                                                             np.ndarray]:
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if res.status == 2:  # infeasible
        return False, math.nan, np.empty(0)
    if res.status != 0:
        raise RuntimeError(f"linprog failed: {res.message}")
    return True, float(res.fun), np.asarray(res.x, dtype=float)


def robustness_bound(world: World, stance: Stance, centre: np.ndarray, half: np.ndarray,
                     free_tip: np.ndarray | None = None, max_cuts: int = 12,
                     gap_tol: float = 1e-4, geo: CellGeometry | None = None,
                     taylor: bool = True, tighten: int = 2) -> RobustnessBound:
    """An upper bound on the robustness r of every pose in the cell (see the module doc);
    `taylor`: intersect the Oettli-Prager polytope with the Taylor model's (`_polytope`);
    `tighten`: rounds that rebuild it with the tension ranges just proven (McCormick's
    envelopes of f_i dq_k shrink with the range of f_i)."""
    robot = world.robot
    g = geo if geo is not None else cell_geometry(robot, stance, centre, half, free_tip)
    att = stance.attached
    idx = [int(i) for i in np.flatnonzero(att)]
    m = len(idx)
    nan4 = np.full(NUM_BOOMS, np.nan)
    gb = grasp_bounds(stance, g)
    if gb.dead.any():
        return RobustnessBound(-math.inf, -math.inf, nan4, nan4, 0.0, 0)
    cs = cell_statics(robot, world.gravity_vector, stance, centre, half, g)
    f_lo, f_hi = robot.boom_tension
    tm = cell_taylor(robot, stance, centre, half, g) if taylor else None
    hv = np.asarray(half, dtype=float)
    f_box: tuple[np.ndarray, np.ndarray] | None = None
    lps = 0
    for _ in range(1 + (tighten if tm is not None else 0)):
        A_ub, b_ub, bounds = _polytope(cs, att, f_lo, f_hi, tm, hv, f_box)
        nz = A_ub.shape[1]
        f_min, f_max = nan4.copy(), nan4.copy()
        for k in range(m):
            c = np.zeros(nz)
            c[k] = 1.0
            ok, val, _ = _lp(c, A_ub, b_ub, bounds)
            lps += 1
            if not ok:  # no tensions balance any pose of the cell: r = -inf throughout
                return RobustnessBound(-math.inf, -math.inf, nan4, nan4, 0.0, lps)
            f_min[idx[k]] = val - LP_SLACK
            ok, val, _ = _lp(-c, A_ub, b_ub, bounds)
            lps += 1
            f_max[idx[k]] = -val + LP_SLACK
        f_box = (f_min[idx], f_max[idx])  # every pose's tensions lie within: tighter envelopes
    gmin = np.array([float(grasp_upper(f_min[i], gb, i)) for i in idx])
    simple = float(gmin.sum())
    # Poses with some f_i above mu_hi_i: that grasp's g_i <= g_i(max(mu_hi_i, f_min_i)).
    upper = -math.inf
    for k, i in enumerate(idx):
        if f_max[i] >= gb.mu_hi[i]:
            gk = float(grasp_upper(max(gb.mu_hi[i], f_min[i]), gb, i))
            upper = max(upper, gk + float(gmin.sum() - gmin[k]))
    # Every f_i <= mu_hi_i: the concave sum of log Phi((mu_hi - f) / sigma_lo), cutting planes.
    mu = gb.mu_hi[idx]
    slo = gb.sigma_lo[idx]
    cap = [(lo, min(hi, float(mu[k]))) for k, (lo, hi) in enumerate(bounds[:m])]
    if all(lo <= hi for lo, hi in cap):
        cuts_A: list[np.ndarray] = []
        cuts_b: list[float] = []

        def add_cut(k: int, a: float) -> None:
            z = (mu[k] - a) / slo[k]
            val = float(log_ndtr(z))
            slope = -float(grasp.mills_ratio(np.array(z))) / slo[k]
            row = np.zeros(nz + m)
            row[nz + k] = 1.0      # t_k - slope f_k <= val - slope a
            row[k] = -slope
            cuts_A.append(row)
            cuts_b.append(val - slope * a)

        for k in range(m):
            a0 = max(cap[k][0], float(f_min[idx[k]]))
            a1 = min(cap[k][1], float(f_max[idx[k]]))
            for a in np.linspace(a0, max(a0, a1), 3):
                add_cut(k, float(a))
        base_A = np.hstack([A_ub, np.zeros((A_ub.shape[0], m))])
        t_bounds: list[tuple[float | None, float]] = [(None, 0.0)] * m  # log P <= 0
        c = np.concatenate([np.zeros(nz), -np.ones(m)])
        best = math.inf
        gap = math.inf
        for _ in range(max_cuts):
            ok, val, sol = _lp(c, np.vstack([base_A, *cuts_A]),
                               np.concatenate([b_ub, cuts_b]), cap + bounds[m:] + t_bounds)
            lps += 1
            if not ok:
                best = -math.inf
                gap = 0.0
                break
            best = min(best, -val + LP_SLACK)
            f = sol[:m]
            attained = float(np.sum(log_ndtr((mu - f) / slo)))
            gap = best - attained
            if gap < gap_tol:
                break
            for k in range(m):
                add_cut(k, float(f[k]))
        upper = max(upper, best)
    else:
        gap = 0.0
    upper = min(upper, simple + LP_SLACK)
    return RobustnessBound(upper, simple, f_min, f_max, gap, lps)
