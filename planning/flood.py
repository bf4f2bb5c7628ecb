"""Grow one connected component of a stance's feasible lattice poses from a seed pose.

The complete search needs, for each 4-stance it enters, the connected component (26-neighbours
on the pose lattice of `planning.lattice`) of feasible poses that holds the poses it entered
at. Scoring the stance's whole reachable lattice and labelling it (`lattice.stance_lattice`)
gives every component, but most of those poses are infeasible (booms through rock, tensions
out of bounds) and many lie in components the search never enters. A flood fill from the
seed scores only the component and its one-step boundary: 2.5-5x fewer poses on benchmark
caves, and the same component, pose for pose (tests/test_complete_search.py holds the two
equal).

The fill runs in waves, all inside one compiled call: each wave's poses are scored together by
the feasibility kernel (`decide_only`), and the unvisited lattice neighbours of its feasible
poses make the next wave. A dense grid over the box every reachable pose lies in (each
anchor's disc of radius boom length plus shoulder offset, every orientation) records what is
visited. The compiled fill lives beside the kernel (`feasibility_kernel.flood_kernel`): numba's
on-disk cache notices changes to a compiled function's own file only.
"""

from __future__ import annotations

import numpy as np

from planning.lattice import LatticeConfig
from rb_drake.feasibility_kernel import (
    ALL_SEGMENTS,
    PackedStances,
    _packed_rock,
    _robot_params,
    flood_kernel,
)
from rb_drake.scenario import Scenario


def reach_box(anchors: np.ndarray, max_reach: float, cfg: LatticeConfig) -> np.ndarray:
    """Lattice index bounds [[i_lo, k_lo], [i_hi, k_hi]] of every body position from which
    all of `anchors` (4, 2) are within `max_reach` (boom length plus shoulder offset)."""
    lo = np.ceil((anchors.max(axis=0) - max_reach) / cfg.position_step - 1e-9)
    hi = np.floor((anchors.min(axis=0) + max_reach) / cfg.position_step + 1e-9)
    return np.array([lo, hi], dtype=np.int64)


def grow_component(scn: Scenario, stances: PackedStances, seed: np.ndarray,
                   box: np.ndarray, cfg: LatticeConfig,
                   ignore_grasps: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The feasible lattice poses 26-connected to lattice index `seed` in the 4-stance
    `stances` (row 0), inside `box` (`reach_box`): their indices (F, 3) and robustness (F,),
    and the indices of the infeasible poses scored on the way (the component's boundary in
    the box). Empty when the seed itself is infeasible or outside the box."""
    seed = np.asarray(seed, dtype=np.int64).reshape(3)
    n = cfg.angle_count
    if (seed[:2] < box[0]).any() or (seed[:2] > box[1]).any() or not -n // 2 <= seed[2] < n // 2:
        return np.zeros((0, 3), np.int64), np.zeros(0), seed[None]
    edges, owner, vertices = _packed_rock(scn.rock)
    prm = _robot_params(scn.robot, scn.gravity_vector)
    return flood_kernel(seed, np.ascontiguousarray(box), float(cfg.position_step),
                         float(cfg.angle_step), int(n), prm, *stances,
                         np.full((1, 2), np.nan), edges, owner, vertices, bool(ignore_grasps),
                         True, int(ALL_SEGMENTS))
