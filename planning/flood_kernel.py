"""The complete search's flood fill, compiled (`planning.flood` grows its components with it):
the lattice poses 26-connected to a seed that are feasible in one stance, scored in waves by
the pose kernel, each with the r of releasing each boom; and the fill's output arranged as
`planning.components` keeps it (`component_arrays`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rb_drake.kernel.cache_stamp import stamp_with_kernel
from rb_drake.kernel.layout import ALL_BOOMS
from rb_drake.kernel.threads import score_threads
from rb_drake.params import NUM_BOOMS

stamp_with_kernel(__file__)  # its cached code holds the pose kernel's


@njit(cache=True, error_model="numpy")
def flood_kernel(seed, box, dx, dphi, n_phi, prm, positions, normals, f_normal, f_lateral,
                  sigma_normal, sigma_lateral, attached, tips, edges, owner, vertices,
                  ignore_grasps, decide_only, collide, body, body_origin,
                  threads):  # pragma: no cover - compiled
    """The lattice poses 26-connected to `seed` that are feasible in stance row 0, inside
    `box` (planning.flood.grow_component): (indices, robustness, release r (F, 4; NaN where
    boom j may not let go), indices scored infeasible). Waves of poses, each scored in one
    `rb_drake.kernel.pose_kernel.score_kernel` call (decide_only), which also scores the four
    release 3-stances of each feasible pose (`rb_drake.kernel.allocation.release_r`).
    `decide_only` (True) and `collide` (ALL_SEGMENTS) come in as arguments, not literals, so
    that `score_kernel` is called with the types Python calls it with: one compilation serves
    both. `body` (I, K, n_phi) int8, lattice index (i, k, m) at [i - body_origin[0],
    k - body_origin[1], m + n_phi // 2]: the body's collision test of each pose (`BodyKnown`),
    read and filled in (`score_kernel`'s body_known); poses outside it are tested each
    time."""
    i0, k0, m0 = box[0, 0], box[0, 1], -(n_phi // 2)
    ni, nk = box[1, 0] - i0 + 1, box[1, 1] - k0 + 1
    state = np.zeros((ni, nk, n_phi), dtype=np.int8)  # 0 unseen, 1 queued
    wave = np.empty((64, 3), dtype=np.int64)
    wave[0] = seed
    n_wave = 1
    state[seed[0] - i0, seed[1] - k0, seed[2] - m0] = 1
    out = np.empty((256, 3), dtype=np.int64)
    out_r = np.empty(256)
    out_rel = np.empty((256, NUM_BOOMS))
    n_out = 0
    bad = np.empty((256, 3), dtype=np.int64)
    n_bad = 0
    nxt = np.empty((256, 3), dtype=np.int64)
    while n_wave:
        poses = np.empty((n_wave, 3))
        for w in range(n_wave):
            poses[w, 0] = wave[w, 0] * dx
            poses[w, 1] = wave[w, 1] * dx
            poses[w, 2] = wave[w, 2] * dphi
        rows = np.arange(n_wave)
        zeros = np.zeros(n_wave, dtype=np.int64)
        reason = np.empty(n_wave, dtype=np.int64)
        r = np.empty(n_wave)
        rel = np.empty((n_wave, NUM_BOOMS))
        known = np.zeros(n_wave, dtype=np.int8)
        for w in range(n_wave):
            a = wave[w, 0] - body_origin[0]
            b = wave[w, 1] - body_origin[1]
            if 0 <= a < body.shape[0] and 0 <= b < body.shape[1]:
                known[w] = body[a, b, wave[w, 2] - m0]
        score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral,
                      sigma_normal, sigma_lateral, attached, tips, rows, zeros, zeros,
                      np.empty(0), edges,
                      owner, vertices, ignore_grasps, decide_only, collide, reason, r,
                      np.empty((n_wave, NUM_BOOMS)), np.empty((n_wave, NUM_BOOMS)),
                      np.empty(n_wave), rel, known, np.int64(ALL_BOOMS))
        for w in range(n_wave):
            a = wave[w, 0] - body_origin[0]
            b = wave[w, 1] - body_origin[1]
            if known[w] and 0 <= a < body.shape[0] and 0 <= b < body.shape[1]:
                body[a, b, wave[w, 2] - m0] = known[w]
        n_next = 0
        for w in range(n_wave):
            if reason[w] != 0:
                if n_bad == bad.shape[0]:
                    bad = _grown(bad)
                bad[n_bad] = wave[w]
                n_bad += 1
                continue
            if n_out == out.shape[0]:
                out = _grown(out)
                out_rel = _grown(out_rel)
                grown_r = np.empty(2 * out_r.shape[0])
                grown_r[:n_out] = out_r
                out_r = grown_r
            out[n_out] = wave[w]
            out_r[n_out] = r[w]
            out_rel[n_out] = rel[w]
            n_out += 1
            for di in range(-1, 2):
                a = wave[w, 0] + di - i0
                if a < 0 or a >= ni:
                    continue
                for dk in range(-1, 2):
                    b = wave[w, 1] + dk - k0
                    if b < 0 or b >= nk:
                        continue
                    for dm in range(-1, 2):
                        c = wave[w, 2] + dm - m0
                        if c < 0 or c >= n_phi or state[a, b, c]:
                            continue
                        state[a, b, c] = 1
                        if n_next == nxt.shape[0]:
                            nxt = _grown(nxt)
                        nxt[n_next, 0] = a + i0
                        nxt[n_next, 1] = b + k0
                        nxt[n_next, 2] = c + m0
                        n_next += 1
        wave, nxt = nxt, wave
        n_wave = n_next
    return out[:n_out].copy(), out_r[:n_out].copy(), out_rel[:n_out].copy(), bad[:n_bad].copy()


@njit(cache=True)
def component_arrays(idx, r, release_r, bad, span, n_phi):  # pragma: no cover - compiled
    """A flood fill's output as planning.components keeps it: the component's lattice keys
    (planning.lattice.pack) ascending, with its r, whether each boom may let go and that
    3-stance's r (-inf where it may not) in the same order; the rows at which boom j may let
    go, ascending, concatenated (boom j's from starts[j] to starts[j + 1]); the smallest and
    largest lattice (i, k); and the keys of the infeasible poses scored."""
    F = idx.shape[0]
    keys = np.empty(F, dtype=np.int64)
    for q in range(F):
        keys[q] = _pack(idx[q, 0], idx[q, 1], idx[q, 2], span, n_phi)
    order = np.argsort(keys)  # keys are distinct: one order, whatever the sort
    keys = keys[order]
    r_out = np.empty(F)
    release = np.empty((F, NUM_BOOMS), dtype=np.bool_)
    rel_out = np.empty((F, NUM_BOOMS))
    counts = np.zeros(NUM_BOOMS, dtype=np.int64)
    box = np.empty((2, 2), dtype=np.int64)
    box[0, 0] = box[0, 1] = np.iinfo(np.int64).max
    box[1, 0] = box[1, 1] = np.iinfo(np.int64).min
    for q in range(F):
        o = order[q]
        r_out[q] = r[o]
        for j in range(NUM_BOOMS):
            ok = not math.isnan(release_r[o, j])
            release[q, j] = ok
            rel_out[q, j] = release_r[o, j] if ok else -math.inf
            counts[j] += ok
        for d in range(2):
            box[0, d] = min(box[0, d], idx[o, d])
            box[1, d] = max(box[1, d], idx[o, d])
    starts = np.zeros(NUM_BOOMS + 1, dtype=np.int64)
    for j in range(NUM_BOOMS):
        starts[j + 1] = starts[j] + counts[j]
    rows = np.empty(starts[NUM_BOOMS], dtype=np.int64)
    fill = starts[:NUM_BOOMS].copy()
    for j in range(NUM_BOOMS):
        for q in range(F):
            if release[q, j]:
                rows[fill[j]] = q
                fill[j] += 1
    bad_keys = np.empty(bad.shape[0], dtype=np.int64)
    for q in range(bad.shape[0]):
        bad_keys[q] = _pack(bad[q, 0], bad[q, 1], bad[q, 2], span, n_phi)
    return keys, r_out, release, rel_out, rows, starts, box, bad_keys


@njit(cache=True)
def _pack(i, k, m, span, n_phi):  # pragma: no cover - compiled
    """planning.lattice.pack of one index."""
    return ((i + span // 2) * span + (k + span // 2)) * n_phi + (m + n_phi // 2)


@njit(cache=True, error_model="numpy")
def _grown(a):  # pragma: no cover - compiled
    b = np.empty((2 * a.shape[0], a.shape[1]), dtype=a.dtype)
    b[:a.shape[0]] = a
    return b
