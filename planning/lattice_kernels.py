"""The lattice search's compiled reach tests and moves (`planning.lattice`,
`planning.lattice_moves`, `planning.search_cost` call them): how far booms are from reaching
anchors (`reach_violation`), which anchors a boom reaches from a component's release poses and
from which poses (`lattice_reach_rows`, `lattice_reached_anchors`, `lattice_move_table`), and
a move's new configurations and a transition's boom costs scored by the pose kernel
(`lattice_move_kernel`, `transition_boom_costs`). Poses come as packed lattice keys
(`planning.lattice.pack`), decoded here as `lattice.poses_of(unpack(...))` does; the reach test
is `_reach_kernel`'s, to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rb_drake.kernel.cache_stamp import stamp_with_kernel
from rb_drake.kernel.collision import segment_hits
from rb_drake.kernel.layout import (
    ALL_BOOMS,
    P_CLEARANCE,
    P_DIRECTION,
    P_L_HI,
    P_L_LO,
    P_RANGE,
    P_SHOULDER,
    robot_params,
)
from rb_drake.kernel.pose_kernel import score_kernel
from rb_drake.kernel.threads import score_threads
from rb_drake.params import NUM_BOOMS, RobotParams

_TWO_PI = 2.0 * math.pi
_LARGEST_FLOAT = np.finfo(np.float64).max
_CONFIGS = 4  # a transition's configurations: old 4-stance, 3-stance at either anchor, new

stamp_with_kernel(__file__)  # its cached code holds the pose kernel's


def reach_violation(robot: RobotParams, poses: np.ndarray, targets: np.ndarray,
                    booms: np.ndarray) -> np.ndarray:
    """`geometry.reach(robot, poses, targets, booms).violation`, compiled: per pose and k, how
    far boom booms[k] is from reaching targets[k] (m + rad; 0 where it reaches), (P, K).
    The transition search ranks thousands of random poses by it per stance."""
    poses = np.ascontiguousarray(poses, dtype=float).reshape(-1, 3)
    targets = np.ascontiguousarray(targets, dtype=float).reshape(-1, 2)
    booms = np.ascontiguousarray(booms, dtype=np.int64).reshape(-1)
    if len(booms) != len(targets):
        raise ValueError(f"{len(booms)} booms for {len(targets)} targets")
    return _reach_kernel(poses, targets, booms, robot_params(robot, np.zeros(2)))


@njit(cache=True)
def _reach_kernel(poses, targets, booms, params):  # pragma: no cover - compiled
    P, K = poses.shape[0], targets.shape[0]
    out = np.empty((P, K))
    lo, hi, rng = params[P_L_LO], params[P_L_HI], params[P_RANGE]
    for p in range(P):
        x, y, phi = poses[p, 0], poses[p, 1], poses[p, 2]
        c, s = math.cos(phi), math.sin(phi)
        for k in range(K):
            i = booms[k]
            sx, sy = params[P_SHOULDER + 2 * i], params[P_SHOULDER + 2 * i + 1]
            dx = targets[k, 0] - (x + (c * sx - s * sy))
            dy = targets[k, 1] - (y + (s * sx + c * sy))
            length = math.sqrt(dx * dx + dy * dy)
            w = ((math.atan2(dy, dx) - phi - params[P_DIRECTION + i] + math.pi) % _TWO_PI
                 - math.pi)
            if w >= math.pi:
                w -= _TWO_PI
            out[p, k] = (max(0.0, length - hi) + max(0.0, lo - length)
                         + max(0.0, abs(w) - rng))
    return out



@njit(cache=True)
def _decode(key, span, dx, dphi, n_phi):  # pragma: no cover - compiled
    rest = key // n_phi
    return ((rest // span - span // 2) * dx, (rest % span - span // 2) * dx,
            (key % n_phi - n_phi // 2) * dphi)


@njit(cache=True)
def _reaches(x, y, c, s, phi, tx, ty, i, params):  # pragma: no cover - compiled
    """Whether _reach_kernel's violation of boom i to (tx, ty) at pose (x, y, phi) is 0."""
    sx, sy = params[P_SHOULDER + 2 * i], params[P_SHOULDER + 2 * i + 1]
    dx = tx - (x + (c * sx - s * sy))
    dy = ty - (y + (s * sx + c * sy))
    length = math.sqrt(dx * dx + dy * dy)
    # The violation, a sum of non-negative terms, is 0 exactly when each term is: the length's
    # first, so that a boom out of reach costs no atan2.
    if length > params[P_L_HI] or length < params[P_L_LO]:
        return False
    w = (math.atan2(dy, dx) - phi - params[P_DIRECTION + i] + math.pi) % _TWO_PI - math.pi
    if w >= math.pi:
        w -= _TWO_PI
    return abs(w) <= params[P_RANGE]


@njit(cache=True)
def _keep_clear(rows, shoulders, tx, ty, edges, clearance, out, n_out):  # pragma: no cover
    """Append to out[n_out:] those of `rows` whose boom, from its shoulder (`shoulders`, one
    (x, y) per row) to (tx, ty), is clear of the rock's `edges` (`score_kernel`'s test of
    that segment, to the bit); returns the new n_out. Edges apart from the box of every
    shoulder and the target are left out first (collision.Rock culls the same way): they
    cannot change a result."""
    lo_x = hi_x = tx
    lo_y = hi_y = ty
    for q in range(rows.shape[0]):
        lo_x, hi_x = min(lo_x, shoulders[q, 0]), max(hi_x, shoulders[q, 0])
        lo_y, hi_y = min(lo_y, shoulders[q, 1]), max(hi_y, shoulders[q, 1])
    near = np.empty(edges.shape[0], dtype=np.int64)
    m = 0
    for e in range(edges.shape[0]):
        if (max(edges[e, 0], edges[e, 2]) >= lo_x and min(edges[e, 0], edges[e, 2]) <= hi_x
                and max(edges[e, 1], edges[e, 3]) >= lo_y
                and min(edges[e, 1], edges[e, 3]) <= hi_y):
            near[m] = e
            m += 1
    near = near[:m]
    for q in range(rows.shape[0]):
        px, py = shoulders[q, 0], shoulders[q, 1]
        ddx, ddy = tx - px, ty - py
        length = math.sqrt(ddx * ddx + ddy * ddy)
        ux, uy = ddx / length, ddy / length
        ux = ux if math.isfinite(ux) else 0.0
        uy = uy if math.isfinite(uy) else 0.0
        if not segment_hits(px, py, tx - clearance * ux, ty - clearance * uy, edges, near):
            out[n_out] = rows[q]
            n_out += 1
    return n_out


@njit(cache=True)
def lattice_reach_rows(keys, rows, tx, ty, boom, params, span, dx, dphi, n_phi,
                       edges):  # pragma: no cover - compiled
    """Those of `rows` (rows of `keys`, ascending) whose pose boom `boom` reaches (tx, ty)
    from, its segment to there clear of the rock's `edges` (`score_kernel`'s test of that
    segment, to the bit: half of a move's poses fail it, and no other test is cheaper),
    ascending."""
    out = np.empty(rows.shape[0], dtype=np.int64)
    shoulders = np.empty((rows.shape[0], 2))
    n = 0
    sx, sy = params[P_SHOULDER + 2 * boom], params[P_SHOULDER + 2 * boom + 1]
    for q in range(rows.shape[0]):
        r = rows[q]
        x, y, phi = _decode(keys[r], span, dx, dphi, n_phi)
        c, s = math.cos(phi), math.sin(phi)
        if _reaches(x, y, c, s, phi, tx, ty, boom, params):
            out[n] = r
            shoulders[n, 0], shoulders[n, 1] = x + (c * sx - s * sy), y + (s * sx + c * sy)
            n += 1
    kept = _keep_clear(out[:n].copy(), shoulders[:n], tx, ty, edges, params[P_CLEARANCE], out,
                       0)
    return out[:kept].copy()


@njit(cache=True)
def lattice_reached_anchors(keys, release_rows, starts, targets, params, span, dx, dphi,
                            n_phi):  # pragma: no cover - compiled
    """(4, K) bool: whether boom j reaches targets[k] from some row of `keys` at which it may
    let go: release_rows[starts[j]:starts[j + 1]] (boom j's release rows, concatenated)."""
    K = targets.shape[0]
    found = np.zeros((NUM_BOOMS, K), dtype=np.bool_)
    for j in range(NUM_BOOMS):
        left = K
        for q in range(starts[j], starts[j + 1]):
            if left == 0:
                break
            x, y, phi = _decode(keys[release_rows[q]], span, dx, dphi, n_phi)
            c, s = math.cos(phi), math.sin(phi)
            for k in range(K):
                if not found[j, k] and _reaches(x, y, c, s, phi, targets[k, 0], targets[k, 1],
                                                j, params):
                    found[j, k] = True
                    left -= 1
    return found


@njit(cache=True)
def lattice_move_table(keys, release_rows, starts, targets, params, span, dx, dphi, n_phi,
                       edges):  # pragma: no cover - compiled
    """Every move of a component in one pass: for boom j and target k, the rows of boom j's
    release rows (release_rows[starts[j]:starts[j + 1]], ascending) from which it reaches
    targets[k] with its segment there clear of `edges`: `lattice_reach_rows` of each (j, k),
    row for row and to the bit (the same tests, in the same arithmetic). Returns (rows,
    offsets): the rows of (j, k) are rows[offsets[j * K + k]:offsets[j * K + k + 1]]. Each
    pose is decoded once for all targets, where one call per move decoded it per target."""
    K = targets.shape[0]
    offsets = np.zeros(NUM_BOOMS * K + 1, dtype=np.int64)
    out = np.empty(0, dtype=np.int64)
    n_out = 0
    clearance = params[P_CLEARANCE]
    L_lo, L_hi, rng = params[P_L_LO], params[P_L_HI], params[P_RANGE]
    # Clear-cut cases decided without the square root or atan2, by margins (1e-9) far beyond
    # their rounding; the rest by _reaches' own arithmetic, so the answer is its.
    far2 = (L_hi * (1.0 + 1e-9)) ** 2
    near2 = (L_lo * (1.0 - 1e-9)) ** 2
    cos_rng = math.cos(rng) if rng < math.pi else -2.0
    for j in range(NUM_BOOMS):
        sx, sy = params[P_SHOULDER + 2 * j], params[P_SHOULDER + 2 * j + 1]
        direction = params[P_DIRECTION + j]
        first, last = starts[j], starts[j + 1]
        # (target, row, shoulder) of every reaching pair, rows ascending within a target
        cap = 64
        pair_k = np.empty(cap, dtype=np.int64)
        pair_r = np.empty(cap, dtype=np.int64)
        pair_p = np.empty((cap, 2))
        n_pair = 0
        count = np.zeros(K, dtype=np.int64)
        for q in range(first, last):
            r = release_rows[q]
            x, y, phi = _decode(keys[r], span, dx, dphi, n_phi)
            c, s = math.cos(phi), math.sin(phi)
            px, py = x + (c * sx - s * sy), y + (s * sx + c * sy)
            cu, su = math.cos(phi + direction), math.sin(phi + direction)
            for k in range(K):
                # _reaches' test, the shoulder computed once per pose
                ddx, ddy = targets[k, 0] - px, targets[k, 1] - py
                d2 = ddx * ddx + ddy * ddy
                if d2 > far2 or d2 < near2:
                    continue
                length = math.sqrt(d2)
                if length > L_hi or length < L_lo:
                    continue
                cos_w = (ddx * cu + ddy * su) / length
                if cos_w < cos_rng - 1e-9:
                    continue
                if cos_w <= cos_rng + 1e-9:  # near the shoulder's limit: atan2 decides
                    w = (math.atan2(ddy, ddx) - phi - direction + math.pi) % _TWO_PI - math.pi
                    if w >= math.pi:
                        w -= _TWO_PI
                    inside = abs(w) <= rng
                else:
                    inside = True
                if inside:
                    if n_pair == cap:
                        cap *= 2
                        grown_k = np.empty(cap, dtype=np.int64)
                        grown_r = np.empty(cap, dtype=np.int64)
                        grown_p = np.empty((cap, 2))
                        grown_k[:n_pair] = pair_k[:n_pair]
                        grown_r[:n_pair] = pair_r[:n_pair]
                        grown_p[:n_pair] = pair_p[:n_pair]
                        pair_k, pair_r, pair_p = grown_k, grown_r, grown_p
                    pair_k[n_pair] = k
                    pair_r[n_pair] = r
                    pair_p[n_pair, 0] = px
                    pair_p[n_pair, 1] = py
                    n_pair += 1
                    count[k] += 1
        # grouped by target, rows ascending (a stable counting sort)
        at = np.zeros(K + 1, dtype=np.int64)
        for k in range(K):
            at[k + 1] = at[k] + count[k]
        order = np.empty(n_pair, dtype=np.int64)
        fill = at[:K].copy()
        for p in range(n_pair):
            order[fill[pair_k[p]]] = p
            fill[pair_k[p]] += 1
        if out.shape[0] < n_out + n_pair:
            grown = np.empty(max(2 * out.shape[0], n_out + n_pair), dtype=np.int64)
            grown[:n_out] = out[:n_out]
            out = grown
        for k in range(K):
            offsets[j * K + k] = n_out
            if count[k] == 0:
                continue
            group = order[at[k]:at[k + 1]]
            n_out = _keep_clear(pair_r[group], pair_p[group], targets[k, 0], targets[k, 1],
                                edges, clearance, out, n_out)
    offsets[NUM_BOOMS * K] = n_out
    return out[:n_out].copy(), offsets


@njit(cache=True, error_model="numpy")
def _gathered(rows, tips, table_positions, table_normals, table_f_normal, table_f_lateral,
              table_sigma_normal, table_sigma_lateral):  # pragma: no cover - compiled
    """Kernel stances (PackedStances' arrays) of `rows` (S, 4) anchor-table indices (the
    table's last row leaves a boom free) and tip points of `tips` (T,) table indices:
    `planning.transition_score.pack_rows`, compiled."""
    free = table_positions.shape[0] - 1
    S = rows.shape[0]
    positions = np.empty((S, NUM_BOOMS, 2))
    normals = np.empty((S, NUM_BOOMS, 2))
    f_normal = np.empty((S, NUM_BOOMS))
    f_lateral = np.empty((S, NUM_BOOMS))
    sigma_normal = np.empty((S, NUM_BOOMS))
    sigma_lateral = np.empty((S, NUM_BOOMS))
    attached = np.empty((S, NUM_BOOMS), dtype=np.bool_)
    for q in range(S):
        for i in range(NUM_BOOMS):
            a = rows[q, i]
            positions[q, i, 0], positions[q, i, 1] = table_positions[a, 0], table_positions[a, 1]
            normals[q, i, 0], normals[q, i, 1] = table_normals[a, 0], table_normals[a, 1]
            f_normal[q, i], f_lateral[q, i] = table_f_normal[a], table_f_lateral[a]
            sigma_normal[q, i], sigma_lateral[q, i] = table_sigma_normal[a], table_sigma_lateral[a]
            attached[q, i] = a != free
    tip_points = np.empty((tips.shape[0], 2))
    for q in range(tips.shape[0]):
        tip_points[q, 0] = table_positions[tips[q], 0]
        tip_points[q, 1] = table_positions[tips[q], 1]
    return (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
            tip_points)


@njit(cache=True, error_model="numpy")
def transition_boom_costs(pose, prm, table_positions, table_normals, table_f_normal,
                          table_f_lateral, table_sigma_normal, table_sigma_lateral, rows, tips,
                          edges, owner, vertices, ignore_grasps, decide_only,
                          collide):  # pragma: no cover - compiled
    """Per boom, the worst -log P_i over a transition's four configurations at `pose` (3,):
    `rows` (3, 4) anchor-table indices of the old 4-stance, the 3-stance and the new 4-stance
    (the table's last row leaves a boom free), `tips` (2,) the free gripper's table rows (at
    the old anchor, at the new). `planning.footsteps.boom_costs`, the stances gathered from
    the table here and scored by `score_kernel` as `score_rows` scores them (full mode):
    the same numbers, without a dozen numpy calls around one compiled one. `ignore_grasps`
    and `decide_only` (False) and `collide` (ALL_SEGMENTS) come in as arguments, not
    literals, so that `score_kernel` is called with the types Python calls it with."""
    (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
     tip_points) = _gathered(rows, tips, table_positions, table_normals, table_f_normal,
                             table_f_lateral, table_sigma_normal, table_sigma_lateral)
    poses = np.empty((1, 3))
    poses[0, 0], poses[0, 1], poses[0, 2] = pose[0], pose[1], pose[2]
    stance_row = np.array([0, 1, 1, 2])
    tip_row = np.array([0, 0, 1, 0])
    lp = np.empty((_CONFIGS, NUM_BOOMS))
    score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                 sigma_lateral, attached, tip_points, np.zeros(_CONFIGS, dtype=np.int64),
                 stance_row, tip_row, np.empty(0), edges, owner, vertices, ignore_grasps,
                 decide_only, collide, np.empty(_CONFIGS, dtype=np.int64), np.empty(_CONFIGS), lp,
                 np.empty((_CONFIGS, NUM_BOOMS)), np.empty(_CONFIGS), np.empty((0, NUM_BOOMS)),
                 np.empty(0, dtype=np.int8), np.int64(ALL_BOOMS), np.int64(0), np.int64(1))
    costs = np.empty(NUM_BOOMS)
    for i in range(NUM_BOOMS):  # nan_to_num's values: a free boom's NaN as 0, -inf as the largest
        worst = math.inf
        for q in range(_CONFIGS):
            v = lp[q, i]
            if math.isnan(v):
                v = 0.0
            elif v == -math.inf:
                v = -_LARGEST_FLOAT
            worst = min(worst, v)
        costs[i] = max(0.0, -worst)
    return costs



@njit(cache=True, error_model="numpy")
def lattice_move_kernel(keys, rows, boom, span, dx, dphi, n_phi, prm, table_positions,
                        table_normals, table_f_normal, table_f_lateral, table_sigma_normal,
                        table_sigma_lateral, stance_rows, tip_rows, edges, owner, vertices,
                        ignore_grasps, decide_only, collide,
                        threads):  # pragma: no cover - compiled
    """A move's two new configurations at rows `rows` of a component (keys: its lattice keys),
    in one call (planning.complete's scored transitions): stance row 0 is the 3-stance with
    the freed boom's gripper at the new anchor tips[0], tested for the segments of `collide`
    (the freed boom's: the others are the old 4-stance's, clear); where it holds, stance row 1,
    the new 4-stance, with its release r of `boom` (`release_r`). Returns the rows where both hold,
    the new 4-stance's release r of `boom` there (the attach ramp's start) and its r: what
    `score_rows` gives for the same rows (decide_only), in two calls. The two stances come as
    anchor-table rows (`stance_rows` (2, 4), `tip_rows` (2,): `_gathered`)."""
    (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
     tips) = _gathered(stance_rows, tip_rows, table_positions, table_normals, table_f_normal,
                       table_f_lateral, table_sigma_normal, table_sigma_lateral)
    n = rows.shape[0]
    poses = np.empty((n, 3))
    for q in range(n):
        x, y, phi = _decode(keys[rows[q]], span, dx, dphi, n_phi)
        poses[q, 0] = x
        poses[q, 1] = y
        poses[q, 2] = phi
    zeros = np.zeros(n, dtype=np.int64)
    reason = np.empty(n, dtype=np.int64)
    score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                  sigma_lateral, attached, tips, np.arange(n), zeros, zeros, np.empty(0),
                  edges, owner,
                  vertices, ignore_grasps, decide_only, collide, reason, np.empty(n),
                  np.empty((n, NUM_BOOMS)), np.empty((n, NUM_BOOMS)), np.empty(n),
                  np.empty((0, NUM_BOOMS)), np.empty(0, dtype=np.int8), np.int64(0))
    m = 0
    for q in range(n):
        if reason[q] == 0:
            m += 1
    ok = np.empty(m, dtype=np.int64)
    second = np.empty((m, 3))
    m = 0
    for q in range(n):
        if reason[q] == 0:
            ok[m] = q
            second[m] = poses[q]
            m += 1
    if m == 0:
        return np.empty(0, dtype=np.int64), np.empty(0), np.empty(0)
    ones = np.ones(m, dtype=np.int64)
    reason2 = np.empty(m, dtype=np.int64)
    r2 = np.empty(m)
    rel = np.empty((m, NUM_BOOMS))
    score_threads(threads, second, prm, positions, normals, f_normal, f_lateral,
                  sigma_normal, sigma_lateral, attached, tips, np.arange(m), ones, ones,
                  np.empty(0), edges,
                  owner, vertices, ignore_grasps, decide_only, np.int64(0), reason2, r2,
                  np.empty((m, NUM_BOOMS)), np.empty((m, NUM_BOOMS)), np.empty(m), rel,
                  np.empty(0, dtype=np.int8), np.int64(1) << boom)
    k = 0
    for q in range(m):
        if reason2[q] == 0 and not math.isnan(rel[q, boom]):
            k += 1
    kept = np.empty(k, dtype=np.int64)
    arrive = np.empty(k)
    r_new = np.empty(k)
    k = 0
    for q in range(m):
        if reason2[q] == 0 and not math.isnan(rel[q, boom]):
            kept[k] = rows[ok[q]]
            arrive[k] = rel[q, boom]
            r_new[k] = r2[q]
            k += 1
    return kept, arrive, r_new
