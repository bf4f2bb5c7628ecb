"""Force allocation for compiled code: `statics.allocate`'s most robust tensions of a 4-stance
(`allocate4`), the load and shoulder torque of a free limb (`limb_load`), and the r of releasing
a boom from a feasible 4-stance (`release_r`), which the flood fill decides for every pose.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rb_drake.grasp import HALF_PI
from rb_drake.kernel.algebra3 import (
    det3,
    singular_value_above,
    smallest_singular_value,
    solve3,
    solve_without,
)
from rb_drake.kernel.layout import (
    P_BODY_MASS,
    P_DENSITY,
    P_GRAVITY,
    P_GRIPPER_MASS,
    P_LOG_P_MIN,
    P_MAX_PULL,
    P_MIN_CONDITIONING,
    P_MOMENT_SCALE,
    P_STATICS_TOL,
    P_TORQUE_MAX,
    P_Z_FLOOR,
)
from rb_drake.kernel.special import log_ndtr, mills_ratio
from rb_drake.params import NUM_BOOMS

NEWTON_STEPS = 12  # statics.allocate's default
NEWTON_EXIT = 1e-12  # stop once a Newton step is this small (relative to 1 + |t|)


@njit(cache=True, error_model="numpy")
def slope(t, fp, n, mu, sigma, dz, reg, curvature) -> tuple[float, float]:
    """d/dt (and d2/dt2) of the allocation objective along the tension family fp + t n."""
    d1 = 0.0
    reg1 = 0.0
    d2 = 0.0
    reg2 = 0.0
    for i in range(NUM_BOOMS):
        f = fp[i] + t * n[i]
        z = (mu[i] - f) / sigma[i]
        lam = mills_ratio(z)
        d1 += lam * dz[i]
        reg1 += f * n[i]
        if curvature:
            d2 += -lam * (z + lam) * dz[i] * dz[i]
            reg2 += n[i] * n[i]
    return d1 - reg * reg1, d2 - reg * reg2



@njit(cache=True, error_model="numpy")
def without_column(A: np.ndarray, c: int, work: np.ndarray) -> None:
    """work = A with column c left out (the other three, in order): a 3-stance's matrix."""
    m = 0
    for j in range(NUM_BOOMS):
        if j != c:
            for r in range(3):
                work[r, m] = A[r, j]
            m += 1



@njit(cache=True, error_model="numpy")
def limb_load(x, y, L, sh, tg, j, prm, b):
    """geometry.limb_load: the cantilevered free limb j (its boom from the shoulder sh[j] to the
    gripper at tg[j]) added to the body's load b (in place); returns its shoulder torque."""
    gx, gy = prm[P_GRAVITY], prm[P_GRAVITY + 1]
    m_boom = prm[P_DENSITY] * L[j]
    m_grip = prm[P_GRIPPER_MASS]
    tx, ty = tg[j, 0], tg[j, 1]
    px, py = sh[j, 0], sh[j, 1]
    mx, my = 0.5 * (px + tx), 0.5 * (py + ty)
    b[0] -= (m_boom + m_grip) * gx
    b[1] -= (m_boom + m_grip) * gy
    b[2] -= (m_boom * ((mx - x) * gy - (my - y) * gx)
             + m_grip * ((tx - x) * gy - (ty - y) * gx))
    return (m_boom * ((mx - px) * gy - (my - py) * gx)
            + m_grip * ((tx - px) * gy - (ty - py) * gx))



@njit(cache=True, error_model="numpy")
def allocate4(A, b, psi, fn, ft, sn, st, f_lo, f_hi, reg, f, fp, minors, vec, work, rhs,
               w, z_floor) -> tuple[bool, bool, bool]:
    """statics.allocate for four attached booms: the most robust member of the family
    fp + t n within the tension bounds, into f (NaN where there is none). Leaves fp and the
    unnormalised null vector (minors) for the violation; returns (ok, A A^T regular, short):
    `short` when no member within the bounds gives every grasp z >= z_floor, so that none
    can be robust enough (then f is not computed; z_floor = -inf never stops it)."""
    for c in range(NUM_BOOMS):  # null vector by signed 3x3 minors
        without_column(A, c, work)
        minors[c] = det3(work) * (1.0 if c % 2 == 0 else -1.0)
    n_norm = math.sqrt(minors[0] * minors[0] + minors[1] * minors[1] + minors[2] * minors[2]
                       + minors[3] * minors[3])
    n, mu, sigma, dz = vec[0], vec[1], vec[2], vec[3]
    for i in range(NUM_BOOMS):
        n[i] = minors[i] / max(n_norm, 1e-300)
    for r in range(3):  # particular (minimum-norm) solution A^T (A A^T)^-1 b
        for c in range(3):
            s = 0.0
            for j in range(NUM_BOOMS):
                s += A[r, j] * A[c, j]
            work[r, c] = s
        rhs[r] = b[r]
    regular = abs(det3(work)) > 1e-14
    if not regular:
        for r in range(3):
            for c in range(3):
                work[r, c] = 1.0 if r == c else 0.0
    solve3(work, rhs, w)
    for i in range(NUM_BOOMS):
        fp[i] = A[0, i] * w[0] + A[1, i] * w[1] + A[2, i] * w[2]
    t_lo, t_hi = -math.inf, math.inf
    for i in range(NUM_BOOMS):
        if abs(n[i]) < 1e-12:
            inside = fp[i] >= f_lo - 1e-9 and fp[i] <= f_hi + 1e-9
            lo_i, hi_i = (-math.inf, math.inf) if inside else (math.inf, -math.inf)
        else:
            t1 = (f_lo - fp[i]) / n[i]
            t2 = (f_hi - fp[i]) / n[i]
            lo_i, hi_i = min(t1, t2), max(t1, t2)
        t_lo, t_hi = max(t_lo, lo_i), min(t_hi, hi_i)
    ok = regular and t_lo <= t_hi and n_norm > 1e-12
    if not ok:
        t_lo = t_hi = 0.0
    for i in range(NUM_BOOMS):
        if abs(psi[i]) < HALF_PI:
            sigma[i] = sn[i] + (abs(psi[i]) / HALF_PI) * (st[i] - sn[i])
            mu[i] = mean_limit(psi[i], fn[i], ft[i])
            dz[i] = -n[i] / sigma[i]
        else:
            sigma[i], mu[i], dz[i] = 1.0, 1e6, 0.0
    if ok and z_floor > -math.inf:  # each grasp's z >= z_floor: f_i <= mu_i - z_floor sigma_i
        c_lo, c_hi = t_lo, t_hi
        for i in range(NUM_BOOMS):
            if abs(psi[i]) < HALF_PI and abs(n[i]) >= 1e-12:
                bound = (mu[i] - z_floor * sigma[i] - fp[i]) / n[i]
                if n[i] > 0.0:
                    c_hi = min(c_hi, bound)
                else:
                    c_lo = max(c_lo, bound)
            elif abs(psi[i]) < HALF_PI and fp[i] > mu[i] - z_floor * sigma[i]:
                c_lo, c_hi = math.inf, -math.inf
        if not c_lo <= c_hi:
            return ok, regular, True
    # The concave objective's slope has one root in [t_lo, t_hi]: safeguarded Newton steps
    # inside a shrinking bracket, as statics.allocate (same start, steps and order). allocate
    # always takes NEWTON_STEPS steps; here they stop once a Newton step moves t by less than
    # NEWTON_EXIT (relative), where allocate's remaining steps move it by rounding errors only.
    if not ok:
        t = math.nan
    elif slope(t_lo, fp, n, mu, sigma, dz, reg, False)[0] <= 0.0:
        t = t_lo
    elif slope(t_hi, fp, n, mu, sigma, dz, reg, False)[0] >= 0.0:
        t = t_hi
    else:
        lo, hi = t_lo, t_hi
        t = 0.5 * (lo + hi)
        for _ in range(NEWTON_STEPS):
            d1, d2 = slope(t, fp, n, mu, sigma, dz, reg, True)
            if d1 > 0.0:
                lo = t
            else:
                hi = t
            step = t - d1 / d2
            inside = math.isfinite(step) and lo <= step <= hi
            if inside and abs(step - t) <= NEWTON_EXIT * (1.0 + abs(t)):
                t = step
                break
            t = step if inside else 0.5 * (lo + hi)
    for i in range(NUM_BOOMS):
        f[i] = fp[i] + t * n[i]
    return ok, regular, False



@njit(cache=True, error_model="numpy")
def mean_limit(psi, fn, ft):
    c, s = math.cos(psi), math.sin(psi)
    return fn * ft / math.sqrt((ft * c) ** 2 + (fn * s) ** 2)



# inline="always": numba, not LLVM, inlines it; a call passing its many arrays costs as much
# as its arithmetic (the flood fill scores a feasible pose 20 % faster)
@njit(cache=True, error_model="numpy", inline="always")
def release_r(j, x, y, L, sh, tg, u, psi, A, prm, mu, sigma, f_lo, f_hi, ignore_grasps, rhs,
               w, f, lp, B, b3) -> float:
    """r of the 3-stance with boom j's gripper at its anchor, at a pose feasible in the
    4-stance whose geometry (L, sh, tg, u, psi, A) is given; NaN where it is infeasible
    (r itself may be -inf with ignore_grasps).
    The same operations, in the same order, as `pose_kernel.score_kernel` on that 3-stance's
    row with decide_only and collide=0 (its boom lengths, shoulder angles, pull angles and segments
    are the 4-stance's, all passed), so the decision and r are bitwise the same, but for one
    term: the freed grasp j counts with its P at zero tension (log_ndtr(mu_j / sigma_j)), as
    at the end of the release ramp (planning.ramps), where it is unloaded but still attached
    and `rbp check` counts it; the 3-stance alone does not. `mu`
    and `sigma` are the 4-stance's allocation's (`allocate4`): each grasp's mean limit and
    spread."""
    b3[0] = -prm[P_BODY_MASS] * prm[P_GRAVITY]
    b3[1] = -prm[P_BODY_MASS] * prm[P_GRAVITY + 1]
    b3[2] = 0.0
    torque = limb_load(x, y, L, sh, tg, j, prm, b3)
    if abs(torque) > prm[P_TORQUE_MAX]:  # the cheap tests first
        return math.nan
    rhs[0], rhs[1], rhs[2] = b3[0], b3[1], b3[2]
    ok = abs(solve_without(A, j, rhs, w)) > 1e-12
    m = 0
    for i in range(NUM_BOOMS):
        if i != j:
            f[i] = w[m] if ok else math.nan
            m += 1
        else:
            f[i] = math.nan
    for i in range(NUM_BOOMS):  # tensions out of bounds fail statics whatever follows
        if i != j and not (math.isfinite(f[i]) and f_lo - 1e-9 <= f[i] <= f_hi + 1e-9):
            return math.nan
    if not ignore_grasps:  # every grasp's z >= Phi^-1(p_min), else r < log p_min (exact)
        for i in range(NUM_BOOMS):
            if i != j and abs(psi[i]) < HALF_PI and (mu[i] - f[i]) / sigma[i] < prm[P_Z_FLOOR]:
                return math.nan
        if mu[j] / sigma[j] < prm[P_Z_FLOOR]:  # the freed grasp, unloaded (below)
            return math.nan
    residual = 0.0
    for r in range(3):
        acc = 0.0
        for i in range(NUM_BOOMS):
            acc += (A[r, i] if i != j else 0.0) * (f[i] if math.isfinite(f[i]) else 0.0)
        residual = max(residual, abs(acc - b3[r]))
    statics_ok = residual < prm[P_STATICS_TOL]
    r_sum = 0.0
    for i in range(NUM_BOOMS):
        if i != j:
            fi = f[i] if math.isfinite(f[i]) else 0.0
            statics_ok = statics_ok and math.isfinite(f[i]) and (
                f_lo - 1e-9 <= f[i] <= f_hi + 1e-9)
            if abs(psi[i]) < HALF_PI:
                lp[i] = log_ndtr((mu[i] - fi) / sigma[i])
            else:
                lp[i] = -math.inf
        else:  # the freed grasp at zero tension: still attached at the release ramp's end
            lp[i] = log_ndtr(mu[i] / sigma[i]) if not ignore_grasps else 0.0
        r_sum += lp[i]
    robustness = r_sum if statics_ok else -math.inf
    if not ignore_grasps:
        for i in range(NUM_BOOMS):
            if i != j and not abs(psi[i]) < prm[P_MAX_PULL]:  # feasibility.pull_within
                return math.nan
    if abs(torque) > prm[P_TORQUE_MAX]:
        return math.nan
    if not statics_ok:
        return math.nan
    if not ignore_grasps and robustness < prm[P_LOG_P_MIN]:
        return math.nan
    m = 0
    for i in range(NUM_BOOMS):
        if i != j:
            B[0, m] = A[0, i]
            B[1, m] = A[1, i]
            B[2, m] = A[2, i] * prm[P_MOMENT_SCALE]
            m += 1
    above = singular_value_above(B, m, prm[P_MIN_CONDITIONING])
    if above < 0:
        above = int(smallest_singular_value(B, m) >= prm[P_MIN_CONDITIONING])
    if not above:
        return math.nan
    return robustness
