"""Grow one connected component of a stance's feasible lattice poses from a seed pose.

The complete search needs, for each 4-stance it enters, the connected component (26-neighbours
on the pose lattice of `planning.lattice`) of feasible poses that holds the poses it entered
at. Scoring the stance's whole reachable lattice and labelling it (the tests' `stance_lattice`)
gives every component, but most of those poses are infeasible (booms through rock, tensions
out of bounds) and many lie in components the search never enters. A flood fill from the
seed scores only the component and its one-step boundary: 2.5-5x fewer poses on benchmark
caves, and the same component, pose for pose (tests/test_complete_search.py holds the two
equal).

The fill runs in waves, all inside one compiled call: each wave's poses are scored together by
the feasibility kernel (`decide_only`), and the unvisited lattice neighbours of its feasible
poses make the next wave. A dense grid over the box every reachable pose lies in (each
anchor's disc of radius boom length plus shoulder offset, every orientation) records what is
visited. The compiled fill is `planning.flood_kernel.flood_kernel`; its cached code holds the
pose kernel's, so its cache entries are stamped with the kernel's sources
(`rb_drake.kernel.cache_stamp`).
"""

from __future__ import annotations

import weakref

import numpy as np

from planning.flood_kernel import flood_kernel
from planning.lattice import LatticeConfig
from rb_drake.kernel.collision import packed_rock
from rb_drake.kernel.layout import ALL_SEGMENTS, robot_params
from rb_drake.kernel.scoring import PackedStances
from rb_drake.kernel.threads import kernel_threads
from rb_drake.scenario import Scenario


def reach_box(anchors: np.ndarray, max_reach: float, cfg: LatticeConfig) -> np.ndarray:
    """Lattice index bounds [[i_lo, k_lo], [i_hi, k_hi]] of every body position from which
    all of `anchors` (4, 2) are within `max_reach` (boom length plus shoulder offset)."""
    lo = np.ceil((anchors.max(axis=0) - max_reach) / cfg.position_step - 1e-9)
    hi = np.floor((anchors.min(axis=0) + max_reach) / cfg.position_step + 1e-9)
    return np.array([lo, hi], dtype=np.int64)


_BODY_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
MAX_BODY_CELLS = 1 << 32  # int8 cells: 4 GiB of address space, of which the search touches little


def body_cache(scn: Scenario, cfg: LatticeConfig) -> tuple[np.ndarray, np.ndarray]:
    """The body's collision test at every lattice pose a stance of `scn` can hold (0 not yet
    known, 1 clear, 2 in rock), filled in by the flood fills and shared by every stance (it
    depends on the pose alone), and the lattice index of its [0, 0] cell. One per rock, robot
    body and lattice: a search of thousands of stances tests each pose's body once."""
    per_rock = _BODY_CACHE.setdefault(scn.rock, {})
    key = (tuple(scn.robot.body_size), cfg)
    hit = per_rock.get(key)
    if hit is None:
        pts, dx = scn.anchor_positions, cfg.position_step
        lo = np.floor((pts.min(axis=0) - scn.robot.max_reach) / dx) - 1
        hi = np.ceil((pts.max(axis=0) + scn.robot.max_reach) / dx) + 1
        # Only poses near rock need the test cached (the kernel tests a pose outside the cache
        # itself): the cache spans the rock's box, not the booms' reach (a 1 km boom asked for
        # 1.3 TiB), and at most MAX_BODY_CELLS (untouched pages cost no memory, but the
        # address space is finite); a cave larger than that tests every pose afresh.
        if scn.rock.polygons:
            margin = 0.5 * float(np.hypot(*scn.robot.body_size)) + dx
            lo = np.maximum(lo, np.floor((scn.rock.edge_lo.min(axis=0) - margin) / dx))
            hi = np.minimum(hi, np.ceil((scn.rock.edge_hi.max(axis=0) + margin) / dx))
        else:
            hi = lo - 1  # nothing to collide with
        sides = np.maximum(hi - lo + 1, 0).astype(np.int64)
        if int(sides[0]) * int(sides[1]) * cfg.angle_count > MAX_BODY_CELLS:
            sides[:] = 0
        shape = (int(sides[0]), int(sides[1]), cfg.angle_count)
        hit = per_rock[key] = (np.zeros(shape, dtype=np.int8), lo.astype(np.int64))
    return hit


def grow_component(scn: Scenario, stances: PackedStances, seed: np.ndarray,
                   box: np.ndarray, cfg: LatticeConfig,
                   ignore_grasps: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The feasible lattice poses 26-connected to lattice index `seed` in the 4-stance
    `stances` (row 0), inside `box` (`reach_box`): their indices (F, 3), robustness (F,) and
    release r (F, 4: r of the 3-stance with boom j's gripper still at its anchor, NaN where
    boom j may not let go), and the indices of the infeasible poses scored on the way (the
    component's boundary in the box). Empty when the seed itself is infeasible or outside
    the box."""
    seed = np.asarray(seed, dtype=np.int64).reshape(3)
    n = cfg.angle_count
    if (seed[:2] < box[0]).any() or (seed[:2] > box[1]).any() or not -n // 2 <= seed[2] < n // 2:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4)), seed[None]
    edges, owner, vertices = packed_rock(scn.rock)
    prm = robot_params(scn.robot, scn.gravity_vector)
    body, origin = body_cache(scn, cfg)
    return flood_kernel(seed, np.ascontiguousarray(box), float(cfg.position_step),
                         float(cfg.angle_step), int(n), prm, *stances,
                         np.full((1, 2), np.nan), edges, owner, vertices, bool(ignore_grasps),
                         True, int(ALL_SEGMENTS), body, origin, kernel_threads())
