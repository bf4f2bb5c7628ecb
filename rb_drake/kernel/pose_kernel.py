"""The compiled scoring loop: `feasibility.check_poses(..., full=True)` and `violation` for
each row of a batch, every row a pose in one of several stances (`score_kernel`). The Python
entry points are `scoring.score_poses` and `scoring.score_rows`; the lattice search's compiled
flood fill and moves call it directly, through `threads.score_threads`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rb_drake.grasp import HALF_PI
from rb_drake.kernel.algebra3 import singular_value_above, smallest_singular_value, solve_without
from rb_drake.kernel.allocation import allocate4, limb_load, mean_limit, release_r
from rb_drake.kernel.collision import body_collision, collision_code, near_edges
from rb_drake.kernel.layout import (
    ALL_SEGMENTS,
    BODY_CLEAR,
    BODY_IN_ROCK,
    BODY_SEGMENT,
    BODY_UNKNOWN,
    P_BODY_MASS,
    P_CLEARANCE,
    P_DIRECTION,
    P_F_HI,
    P_F_LO,
    P_GRAVITY,
    P_HEIGHT,
    P_L_HI,
    P_L_LO,
    P_LOG_P_MIN,
    P_MAX_PULL,
    P_MIN_CONDITIONING,
    P_MOMENT_SCALE,
    P_RANGE,
    P_REGULARISATION,
    P_SHOULDER,
    P_STATICS_TOL,
    P_TORQUE_MAX,
    P_WIDTH,
    P_Z_FLOOR,
    REASON_BODY_COLLISION,
    REASON_BOOM_COLLISION,
    REASON_BOOM_LENGTH,
    REASON_PROBABILITY,
    REASON_PULL_ANGLE,
    REASON_SHOULDER_ANGLE,
    REASON_SHOULDER_TORQUE,
    REASON_SINGULAR,
    REASON_STATICS,
)
from rb_drake.kernel.special import log_ndtr
from rb_drake.params import NUM_BOOMS

_TWO_PI = 2.0 * math.pi

# Threads take rows in chunks this long (`threads.score_threads`): interleaved row by row, two
# threads wrote to the same cache lines of every output (a flood fill ran 6 % slower on two
# threads).
ROW_CHUNK = 16


@njit(cache=True, error_model="numpy")
def _wrap(a: float) -> float:
    w = (a + math.pi) % _TWO_PI - math.pi
    return w - _TWO_PI if w >= math.pi else w


@njit(cache=True, error_model="numpy")
def _reject(row, code, reason_out, r_out, lp_out, f_out, v_out) -> None:
    """decide_only: row `row` is infeasible for `code`; nothing else of it is computed."""
    reason_out[row] = code
    r_out[row] = -math.inf
    for i in range(NUM_BOOMS):
        lp_out[row, i] = math.nan
        f_out[row, i] = math.nan
    v_out[row] = math.nan


@njit(cache=True, error_model="numpy")
def score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                 sigma_lateral, attached, tips, pose_row, stance_row, tip_row, tip_clearance,
                 edges, owner, vertices, ignore_grasps, decide_only, collide, reason_out, r_out,
                 lp_out, f_out, v_out, release_out, body_known, release_booms, first,
                 stride) -> None:
    """check_poses(full=True) and violation for each row (see score_rows), into the outputs.

    `tip_clearance` (T,) or (0,): how far short of each tip of `tips` a free boom is tested for
    rock (collision.free_clearance); (0,): every free gripper sits at an anchor
    (ANCHOR_CLEARANCE, as the lattice's moves and costs have it).

    `release_out` (R, 4) or (0, 4): with decide_only, for each feasible 4-stance row, the r of
    the 3-stance with boom j's gripper still at its anchor, for the booms j of the bits of
    `release_booms` (NaN where infeasible, and for the other booms): what
    score_rows gives for that row with collide=0, from this row's geometry (`release_r`).
    `body_known` (R,) int8 or (0,): with decide_only, whether each row's body is known clear
    of rock, known in it or not known (`BodyKnown`; unknown ones are tested where needed and
    filled in): the
    body's test depends on the pose alone, so the flood fill shares it across stances.
    Rows of chunks `first`, `first + stride`, ... of ROW_CHUNK rows are scored (0 and 1: all;
    `threads.score_interleaved` gives each thread its share), the others' outputs left as
    they are.

    With `decide_only` a row stops at its first failing test (kinematics, collisions, then the
    allocation's tests, the conditioning last) and its violation is NaN: feasibility, and the
    robustness, log-probabilities and tensions of feasible rows, are as without it; the
    reason of an infeasible row is one failing test, not always the first."""
    L_lo, L_hi, rng = prm[P_L_LO], prm[P_L_HI], prm[P_RANGE]
    f_lo, f_hi = prm[P_F_LO], prm[P_F_HI]
    gx, gy = prm[P_GRAVITY], prm[P_GRAVITY + 1]
    reg = prm[P_REGULARISATION]
    log_p_min = prm[P_LOG_P_MIN]
    half_w, half_h = prm[P_WIDTH] / 2, prm[P_HEIGHT] / 2
    corner_x = np.array([half_w, -half_w, -half_w, half_w])
    corner_y = np.array([half_h, half_h, -half_h, -half_h])
    has_rock = edges.shape[0] > 0
    shoulder_reach = 0.0
    for i in range(NUM_BOOMS):
        sx, sy = prm[P_SHOULDER + 2 * i], prm[P_SHOULDER + 2 * i + 1]
        shoulder_reach = max(shoulder_reach, math.sqrt(sx * sx + sy * sy))
    # Every segment tested for collision lies within this distance of its pose's centre (a
    # boom is tested only once its length is within bounds).
    reach = max(shoulder_reach + L_hi, math.sqrt(half_w * half_w + half_h * half_h)) + 1.0
    dir_cos = np.empty(NUM_BOOMS)
    dir_sin = np.empty(NUM_BOOMS)
    for i in range(NUM_BOOMS):
        direction = prm[P_DIRECTION + i]
        dir_cos[i], dir_sin[i] = math.cos(direction), math.sin(direction)
    # the shoulder test's limit as a cosine (-2: every direction is within a range of pi)
    cos_range = math.cos(rng + 1e-12) if rng + 1e-12 < math.pi else -2.0
    near_hit, near_ray = near_edges(poses, edges, reach)
    parity = np.zeros(vertices.shape[0], dtype=np.int64)
    # Per-pose scratch.
    L = np.empty(NUM_BOOMS)
    theta = np.empty(NUM_BOOMS)
    sh = np.empty((NUM_BOOMS, 2))     # shoulders in the world
    off = np.empty((NUM_BOOMS, 2))    # R(phi) s_i
    tg = np.empty((NUM_BOOMS, 2))     # targets
    u = np.empty((NUM_BOOMS, 2))
    psi = np.empty(NUM_BOOMS)
    A = np.empty((3, NUM_BOOMS))
    b = np.empty(3)
    b3 = np.empty(3)  # a release 3-stance's load (release_r)
    f = np.empty(NUM_BOOMS)
    fp = np.empty(NUM_BOOMS)
    minors = np.empty(NUM_BOOMS)
    vec = np.empty((4, NUM_BOOMS))  # allocate4's null vector, mu, sigma, dz
    lp = np.empty(NUM_BOOMS)
    work = np.empty((3, 3))
    rhs = np.empty(3)
    w = np.empty(3)
    B = np.empty((3, NUM_BOOMS))
    cx = np.empty(4)
    cy = np.empty(4)
    for row in range(pose_row.shape[0]):
        if (row // ROW_CHUNK) % stride != first:  # another thread's (threads.score_interleaved)
            continue
        if release_out.shape[0]:
            for j in range(NUM_BOOMS):
                release_out[row, j] = math.nan
        k, sk, tk = pose_row[row], stance_row[row], tip_row[row]
        att = attached[sk]
        free = -1
        for i in range(NUM_BOOMS):
            if not att[i]:
                free = i
        if free >= 0 and not (math.isfinite(tips[tk, 0]) and math.isfinite(tips[tk, 1])):
            raise ValueError("a 3-stance row needs a finite free-gripper position")
        # the free boom is tested this far short of its tip (collision.free_clearance); no
        # clearances given: every tip sits at an anchor (the lattice's moves)
        free_short = tip_clearance[tk] if tip_clearance.shape[0] else prm[P_CLEARANCE]
        x, y, phi = poses[k, 0], poses[k, 1], poses[k, 2]
        c, s = math.cos(phi), math.sin(phi)
        fn, ft = f_normal[sk], f_lateral[sk]
        sn, st = sigma_normal[sk], sigma_lateral[sk]
        # -- geometry (geometry.boom_geometry, statics.statics_problem)
        reach_code = 0
        for i in range(NUM_BOOMS):
            sx, sy = prm[P_SHOULDER + 2 * i], prm[P_SHOULDER + 2 * i + 1]
            off[i, 0], off[i, 1] = c * sx - s * sy, s * sx + c * sy
            sh[i, 0], sh[i, 1] = x + off[i, 0], y + off[i, 1]
            if att[i]:
                tg[i, 0], tg[i, 1] = positions[sk, i, 0], positions[sk, i, 1]
            else:
                tg[i, 0], tg[i, 1] = tips[tk, 0], tips[tk, 1]
            dx, dy = tg[i, 0] - sh[i, 0], tg[i, 1] - sh[i, 1]
            L[i] = math.sqrt(dx * dx + dy * dy)
            u[i, 0], u[i, 1] = dx / L[i], dy / L[i]
            if decide_only:  # a boom out of reach decides the row: the rest is not needed
                if L[i] < L_lo or L[i] > L_hi:
                    reach_code = REASON_BOOM_LENGTH
                    break
                # The shoulder angle's cosine, clear of the limit's by 1e-9 (far beyond its
                # rounding), decides without atan2; near the limit, atan2 as below.
                cos_w = (dx * (c * dir_cos[i] - s * dir_sin[i])
                         + dy * (s * dir_cos[i] + c * dir_sin[i])) / L[i]
                if cos_w > cos_range + 1e-9:
                    theta[i] = 0.0  # within range: its value is not needed with decide_only
                elif cos_w < cos_range - 1e-9:
                    reach_code = REASON_SHOULDER_ANGLE
                    break
                else:
                    theta[i] = _wrap(math.atan2(dy, dx) - phi - prm[P_DIRECTION + i])
                    if abs(theta[i]) > rng + 1e-12:
                        reach_code = REASON_SHOULDER_ANGLE
                        break
            else:
                theta[i] = _wrap(math.atan2(dy, dx) - phi - prm[P_DIRECTION + i])
            if att[i]:
                nx, ny = normals[sk, i, 0], normals[sk, i, 1]
                vx, vy = -u[i, 0], -u[i, 1]
                psi[i] = math.atan2(nx * vy - ny * vx, nx * vx + ny * vy)
                A[0, i], A[1, i] = u[i, 0], u[i, 1]
                A[2, i] = off[i, 0] * u[i, 1] - off[i, 1] * u[i, 0]
            else:
                psi[i] = math.nan
                A[0, i] = A[1, i] = A[2, i] = 0.0
        if reach_code:
            _reject(row, reach_code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        b[0] = -prm[P_BODY_MASS] * gx
        b[1] = -prm[P_BODY_MASS] * gy
        b[2] = 0.0
        torque = 0.0
        if free >= 0:  # the cantilevered free limb
            torque = limb_load(x, y, L, sh, tg, free, prm, b)
        # -- kinematic limits
        code = 0
        for i in range(NUM_BOOMS):
            if L[i] < L_lo or L[i] > L_hi:
                code = REASON_BOOM_LENGTH
                break
        if code == 0:
            for i in range(NUM_BOOMS):
                if abs(theta[i]) > rng + 1e-12:
                    code = REASON_SHOULDER_ANGLE
                    break
        if decide_only and code == 0:  # the grasp tests that need no tensions, first
            if not ignore_grasps:
                for i in range(NUM_BOOMS):
                    if att[i] and not abs(psi[i]) < prm[P_MAX_PULL]:  # as below
                        code = REASON_PULL_ANGLE
                        break
            if code == 0 and free >= 0 and abs(torque) > prm[P_TORQUE_MAX]:
                code = REASON_SHOULDER_TORQUE
        # -- collisions (only where they decide the reason; with decide_only after the
        # allocation's tests, which reject more poses for less)
        if code == 0 and has_rock and not decide_only:
            code = collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh,
                                  prm[P_CLEARANCE], free, free_short, edges, owner, near_hit,
                                  near_ray, parity, vertices, ALL_SEGMENTS)
        if decide_only and code != 0:
            _reject(row, code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        # -- force allocation (statics.allocate, statics._finish)
        if free >= 0:
            for r in range(3):
                rhs[r] = b[r]
            det = solve_without(A, free, rhs, w)
            ok = abs(det) > 1e-12
            m = 0
            for i in range(NUM_BOOMS):
                if att[i]:
                    f[i] = w[m] if ok else math.nan
                    m += 1
                else:
                    f[i] = math.nan
            ten = 0.0  # violation: the unique tensions' excess over the bounds
            if abs(det) > 1e-9:
                for i in range(NUM_BOOMS):
                    if att[i]:
                        ten += max(0.0, f_lo - f[i]) + max(0.0, f[i] - f_hi)
            else:
                ten = 100.0
        else:
            z_floor = prm[P_Z_FLOOR] if decide_only and not ignore_grasps else -math.inf
            ok, regular, short = allocate4(A, b, psi, fn, ft, sn, st, f_lo, f_hi, reg, f, fp,
                                            minors, vec, work, rhs, w, z_floor)
            ten = 100.0
            if regular and not decide_only:  # violation: the least violating member
                ten = math.inf
                for bound in (f_lo, f_hi):
                    for q in range(NUM_BOOMS):
                        tq = (bound - fp[q]) / minors[q]
                        if not math.isfinite(tq):
                            tq = 0.0
                        total = 0.0
                        for i in range(NUM_BOOMS):
                            fi = fp[i] + tq * minors[i]
                            total += max(0.0, f_lo - fi) + max(0.0, fi - f_hi)
                        ten = min(ten, total)
            if short:  # decide_only: no member of the family is robust enough
                code = REASON_PROBABILITY
        if decide_only and code == 0:  # tensions out of bounds fail statics whatever follows
            for i in range(NUM_BOOMS):
                if att[i] and not (math.isfinite(f[i]) and f_lo - 1e-9 <= f[i] <= f_hi + 1e-9):
                    code = REASON_STATICS
                    break
        if decide_only and code != 0:
            _reject(row, code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        residual = 0.0
        for r in range(3):
            acc = 0.0
            for i in range(NUM_BOOMS):
                acc += A[r, i] * (f[i] if math.isfinite(f[i]) else 0.0)
            residual = max(residual, abs(acc - b[r]))
        statics_ok = residual < prm[P_STATICS_TOL]
        r_sum = 0.0
        for i in range(NUM_BOOMS):
            if att[i]:
                fi = f[i] if math.isfinite(f[i]) else 0.0
                statics_ok = statics_ok and math.isfinite(f[i]) and (
                    f_lo - 1e-9 <= f[i] <= f_hi + 1e-9)
                if abs(psi[i]) < HALF_PI and free < 0:  # allocate4's mu and sigma: the same
                    lp[i] = log_ndtr((vec[1, i] - fi) / vec[2, i])
                elif abs(psi[i]) < HALF_PI:
                    sig = sn[i] + (abs(psi[i]) / HALF_PI) * (st[i] - sn[i])
                    lp[i] = log_ndtr((mean_limit(psi[i], fn[i], ft[i]) - fi) / sig)
                else:
                    lp[i] = -math.inf
            else:
                lp[i] = 0.0
            r_sum += lp[i]
            lp_out[row, i] = lp[i]
            f_out[row, i] = f[i]
        robustness = r_sum if statics_ok else -math.inf
        r_out[row] = robustness
        # -- the grasp and statics tests (feasibility.check_poses' order)
        if code == 0 and not ignore_grasps:
            for i in range(NUM_BOOMS):
                if att[i] and not abs(psi[i]) < prm[P_MAX_PULL]:  # feasibility.pull_within
                    code = REASON_PULL_ANGLE
                    break
        if code == 0 and free >= 0 and abs(torque) > prm[P_TORQUE_MAX]:
            code = REASON_SHOULDER_TORQUE
        if decide_only:  # the cheap tests first, the conditioning only where they all pass
            if code == 0 and not statics_ok:
                code = REASON_STATICS
            if code == 0 and not ignore_grasps and robustness < log_p_min:
                code = REASON_PROBABILITY
            if code == 0 and has_rock:
                segments = collide
                if body_known.shape[0] and collide & BODY_SEGMENT:  # shared by stances
                    if body_known[row] == BODY_UNKNOWN:
                        body_known[row] = BODY_IN_ROCK if body_collision(
                            x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit,
                            near_ray, parity, vertices) else BODY_CLEAR
                    if body_known[row] == BODY_IN_ROCK:
                        code = REASON_BODY_COLLISION
                    segments = collide & ~BODY_SEGMENT
                if code == 0:
                    code = collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh,
                                          prm[P_CLEARANCE], free, free_short, edges, owner,
                                          near_hit, near_ray, parity, vertices, segments)
            if code != 0:
                reason_out[row] = code
                v_out[row] = math.nan
                continue
        m = 0
        for i in range(NUM_BOOMS):
            if att[i]:
                B[0, m] = A[0, i]
                B[1, m] = A[1, i]
                B[2, m] = A[2, i] * prm[P_MOMENT_SCALE]
                m += 1
        if decide_only:  # only kappa < MIN_CONDITIONING matters: decided cheaply if clear-cut
            above = singular_value_above(B, m, prm[P_MIN_CONDITIONING])
            if above < 0:
                above = int(smallest_singular_value(B, m) >= prm[P_MIN_CONDITIONING])
            kappa = math.inf if above else 0.0
        else:
            kappa = smallest_singular_value(B, m)
        if code == 0 and kappa < prm[P_MIN_CONDITIONING]:
            code = REASON_SINGULAR
        if code == 0 and not statics_ok:
            code = REASON_STATICS
        if code == 0 and not ignore_grasps and robustness < log_p_min:
            code = REASON_PROBABILITY
        reason_out[row] = code
        if decide_only:
            v_out[row] = math.nan
            if release_out.shape[0] and code == 0 and free < 0:
                for j in range(NUM_BOOMS):
                    if not release_booms & (1 << j):
                        continue
                    release_out[row, j] = release_r(
                        j, x, y, L, sh, tg, u, psi, A, prm, vec[1], vec[2], f_lo, f_hi,
                        ignore_grasps, rhs, w, f, lp, B, b3)
            continue
        # -- feasibility.violation
        v = 0.0
        for i in range(NUM_BOOMS):
            v += (max(0.0, L[i] - L_hi) + max(0.0, L_lo - L[i])
                  + max(0.0, abs(theta[i]) - rng))
        if code in (REASON_BODY_COLLISION, REASON_BOOM_COLLISION):
            v += 1.0
        v += ten / 10.0
        if free >= 0:
            v += max(0.0, abs(torque) - prm[P_TORQUE_MAX]) / max(prm[P_TORQUE_MAX], 1e-9)
        v += max(0.0, prm[P_MIN_CONDITIONING] - kappa) / prm[P_MIN_CONDITIONING]
        if not ignore_grasps:
            pull = 0.0
            for i in range(NUM_BOOMS):
                if att[i]:
                    pull += max(0.0, abs(psi[i]) - (prm[P_MAX_PULL] - 1e-3))
            v += pull
            rob = robustness if math.isfinite(robustness) else log_p_min - 1.0
            if statics_ok:
                v += max(0.0, log_p_min - rob)
        v_out[row] = 0.0 if code == 0 else max(v, 1e-6)
