"""The kernel on several threads: how many the compiled searches use (`kernel_threads`,
`held_kernel_threads`), and rows scored on them (`score_threads`) by the complete search's
flood fills and moves (`planning.flood_kernel`, `planning.lattice_kernels`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numba
import numpy as np
from numba import njit, prange

from rb_drake.environment import threads_adapt_setting, threads_setting
from rb_drake.kernel.free_cores import FreeCores
from rb_drake.kernel.pose_kernel import score_kernel

MIN_ROWS_PER_THREAD = 12  # fewer: one thread scores them (a launch and join cost a few us)


def allowed_threads() -> int:
    """The most threads the compiled searches may use: RBP_THREADS if set, else numba's count
    (this machine's cores unless NUMBA_NUM_THREADS says fewer); a worker pool gives each worker
    its share of the cores (`experiments.sweep`)."""
    setting = threads_setting()
    threads = numba.config.NUMBA_NUM_THREADS if setting is None else setting
    return max(1, min(threads, numba.config.NUMBA_NUM_THREADS))


_FREE: list[FreeCores] = []


def kernel_threads() -> int:
    """Threads the complete search's compiled flood fills and moves use now: of the
    `allowed_threads()` (inside `held_kernel_threads`, the count read as the block began),
    as many as there are cores other processes leave free (`rb_drake.kernel.free_cores`),
    at least one. Results are the same, row for row, on any number of threads."""
    allowed = _HELD_THREADS[-1] if _HELD_THREADS else allowed_threads()
    if allowed <= 1:
        return 1
    if not _FREE:
        _FREE.append(FreeCores(enabled=threads_adapt_setting()))
    return _FREE[0].threads(allowed)


_HELD_THREADS: list[int] = []


def run_conditions() -> dict[str, Any]:
    """The threads and the load a run had, for its record (a plan's provenance, a sweep
    worker's record): the most threads the compiled kernels may use (`allowed_threads`; fewer
    while other processes hold cores), the machine's cores,
    and the load average over the last minute when the record is made (None where the system
    has none), so that a time is read against what else ran."""
    try:
        load: float | None = round(os.getloadavg()[0], 2)
    except OSError:
        load = None
    return {"threads": allowed_threads(), "cores": os.cpu_count() or 1, "load": load}


def worker_threads(workers: int, cores: int | None = None) -> int:
    """Kernel threads for each of `workers` processes sharing the machine's `cores`: their
    share, at least 1, so that workers times threads never exceed the cores; RBP_THREADS, if
    set, lowers it further but never raises it."""
    cores = cores or os.cpu_count() or 1
    share = max(1, cores // max(1, workers))
    setting = threads_setting()
    if setting is not None:
        share = min(share, setting)
    return share


@contextmanager
def held_kernel_threads() -> Iterator[int]:
    """`allowed_threads()` read once and held for a block: a search asks for it thousands of
    times, and reading the environment each time cost 1 % of a proof."""
    _HELD_THREADS.append(allowed_threads())
    try:
        yield _HELD_THREADS[-1]
    finally:
        _HELD_THREADS.pop()


@njit(cache=True, parallel=True, error_model="numpy")
def score_interleaved(threads, poses, prm, positions, normals, f_normal, f_lateral,
                      sigma_normal, sigma_lateral, attached, tips, pose_row, stance_row,
                      tip_row, tip_clearance, edges, owner, vertices, ignore_grasps, decide_only,
                      collide, reason_out, r_out, lp_out, f_out, v_out, release_out, body_known,
                      release_booms) -> None:  # pragma: no cover - compiled
    """`score_kernel` with thread t scoring chunks t, t + threads, t + 2 threads, ... of
    ROW_CHUNK rows: the same outputs, row for row (each row is scored on its own and writes its
    own entries), and feasible and infeasible rows, which differ fivefold in cost, shared
    evenly."""
    for t in prange(threads):
        score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                     sigma_lateral, attached, tips, pose_row, stance_row, tip_row, tip_clearance,
                     edges, owner, vertices, ignore_grasps, decide_only, collide, reason_out,
                     r_out, lp_out, f_out, v_out, release_out, body_known, release_booms,
                     np.int64(t), threads)


@njit(cache=True, error_model="numpy")
def score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                  sigma_lateral, attached, tips, pose_row, stance_row, tip_row, tip_clearance,
                  edges, owner, vertices, ignore_grasps, decide_only, collide, reason_out, r_out,
                  lp_out, f_out, v_out, release_out, body_known,
                  release_booms) -> None:  # pragma: no cover - compiled
    """`score_kernel`, on up to `threads` threads where the rows are many enough."""
    use = min(threads, pose_row.shape[0] // MIN_ROWS_PER_THREAD)
    if use > 1:
        score_interleaved(use, poses, prm, positions, normals, f_normal, f_lateral,
                          sigma_normal, sigma_lateral, attached, tips, pose_row, stance_row,
                          tip_row, tip_clearance, edges, owner, vertices, ignore_grasps,
                          decide_only, collide, reason_out, r_out, lp_out, f_out, v_out,
                          release_out, body_known, release_booms)
    else:
        score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                     sigma_lateral, attached, tips, pose_row, stance_row, tip_row, tip_clearance,
                     edges, owner, vertices, ignore_grasps, decide_only, collide, reason_out,
                     r_out, lp_out, f_out, v_out, release_out, body_known, release_booms,
                     np.int64(0), np.int64(1))
