"""The kernel's Python entry points: `score_poses` (check_poses(..., full=True) and violation at
P poses in one stance) and `score_rows` (rows that each pair a pose with one of several stances,
as a transition's four configurations), which pack their arguments into the arrays the compiled
loop (`pose_kernel.score_kernel`) reads and return what the searches need: feasibility, the
first failing `Reason`, the allocation's robustness, log-probabilities and tensions, and the
violation.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rb_drake.collision import free_clearance
from rb_drake.feasibility import World
from rb_drake.kernel.collision import packed_rock
from rb_drake.kernel.layout import ALL_BOOMS, ALL_SEGMENTS, robot_params
from rb_drake.kernel.pose_kernel import score_kernel
from rb_drake.params import NUM_BOOMS
from rb_drake.stance import Stance


class KernelCheck(NamedTuple):
    """`check_poses(..., full=True)` and `violation` at P poses, in one."""

    feasible: np.ndarray    # (P,) bool
    reason: np.ndarray      # (P,) Reason codes (first failing test)
    robustness: np.ndarray  # (P,) allocated r; -inf where statics fail
    log_probs: np.ndarray   # (P, 4) log P_i (0 for a free boom)
    tensions: np.ndarray    # (P, 4) allocated; NaN for a free boom and where none exist
    violation: np.ndarray   # (P,) feasibility.violation: 0 where feasible
    # score_rows(release=True) only: per 4-stance row feasible, r of releasing each boom (the
    # 3-stance with that gripper at its anchor, the gripper counted unloaded), NaN elsewhere
    release_r: np.ndarray | None = None


class PackedStances(NamedTuple):
    """Stances as the kernel reads them, one per row: S rows (a free boom's entries NaN)."""

    positions: np.ndarray      # (S, 4, 2)
    normals: np.ndarray        # (S, 4, 2)
    f_normal: np.ndarray       # (S, 4)
    f_lateral: np.ndarray      # (S, 4)
    sigma_normal: np.ndarray   # (S, 4)
    sigma_lateral: np.ndarray  # (S, 4)
    attached: np.ndarray       # (S, 4) bool


def score_poses(world: World, stance: Stance, poses: np.ndarray,
                free_tip: np.ndarray | None = None, ignore_grasps: bool = False) -> KernelCheck:
    """`check_poses(world, stance, poses, free_tip, full=True, ignore_grasps)` followed by
    `violation(...)` on the same poses, compiled.

    `stance` may be per-row (`Stance.mix`); a 3-stance needs `free_tip`, (2,) or (P, 2)."""
    poses = np.ascontiguousarray(poses, dtype=float).reshape(-1, 3)
    P = poses.shape[0]
    if _anchor_count(stance) == 3:
        if free_tip is None:
            raise ValueError(f"a 3-stance (boom {stance.free_boom} free) needs the free "
                             "gripper's position")
        tips = _floats(free_tip, (-1, 2))
        if tips.shape[0] not in (1, P):
            raise ValueError(f"free_tip holds {tips.shape[0]} points for {P} poses")
    else:
        tips = _NO_TIP
    S = P if stance.positions.ndim == 3 else 1
    attached = np.tile(np.asarray(stance.attached, dtype=bool), (S, 1))
    packed = PackedStances(_floats(stance.positions, (S, NUM_BOOMS, 2)),
                           _floats(stance.normals, (S, NUM_BOOMS, 2)),
                           _floats(stance.f_normal, (S, NUM_BOOMS)),
                           _floats(stance.f_lateral, (S, NUM_BOOMS)),
                           _floats(stance.sigma_normal, (S, NUM_BOOMS)),
                           _floats(stance.sigma_lateral, (S, NUM_BOOMS)), attached)
    rows = np.arange(P)
    return score_rows(world, packed, tips, poses, rows, rows if S > 1 else np.zeros(P, np.int64),
                      rows if tips.shape[0] > 1 else np.zeros(P, np.int64), ignore_grasps)


def score_rows(world: World, stances: PackedStances, tips: np.ndarray, poses: np.ndarray,
               pose_row: np.ndarray, stance_row: np.ndarray, tip_row: np.ndarray,
               ignore_grasps: bool = False, decide_only: bool = False,
               collide: int = ALL_SEGMENTS, release: bool = False) -> KernelCheck:
    """`score_poses` for R rows at once, each its own configuration: row r is pose
    poses[pose_row[r]] in stance stances[stance_row[r]], with the free gripper of a 3-stance
    at tips[tip_row[r]] (tips: (T, 2); ignored in a 4-stance). Lets one call score several
    stances, as a transition's four configurations. With `decide_only` (the lattice search,
    which asks only which rows are feasible) each row stops at a failing test: the violation
    is NaN and an infeasible row's reason is one failing test, not always the first.
    `collide` (decide_only only) tests only the segments of its bits for collision: those of
    the others must be known clear, e.g. decided in another configuration at the same pose.
    `release` (decide_only only): also each feasible 4-stance row's release r (KernelCheck),
    as the flood fill decides it."""
    if collide != ALL_SEGMENTS and not decide_only:
        raise ValueError("collide leaves out collision tests: only with decide_only")
    if release and not decide_only:
        raise ValueError("release sets are decided with decide_only only")
    R = len(pose_row)
    reason = np.empty(R, dtype=np.int64)
    robustness = np.empty(R)
    log_probs = np.empty((R, NUM_BOOMS))
    tensions = np.empty((R, NUM_BOOMS))
    violation = np.empty(R)
    release_r = np.full((R if release else 0, NUM_BOOMS), np.nan)
    if R:
        edges, owner, vertices = packed_rock(world.rock)
        tips = _floats(tips, (-1, 2))
        clearance = free_clearance(world.anchor_positions, tips)  # check_poses' rule
        score_kernel(_floats(poses, (-1, 3)), robot_params(world.robot, world.gravity_vector),
                     *stances, tips, _indices(pose_row), _indices(stance_row),
                     _indices(tip_row), clearance, edges, owner, vertices, bool(ignore_grasps),
                     bool(decide_only), int(collide), reason, robustness, log_probs, tensions,
                     violation, release_r, np.empty(0, dtype=np.int8), int(ALL_BOOMS), 0, 1)
    return KernelCheck(reason == 0, reason, robustness, log_probs, tensions, violation,
                       release_r if release else None)


_NO_TIP = np.full((1, 2), np.nan)


def _anchor_count(stance: Stance) -> int:
    n = int(np.count_nonzero(stance.attached))
    if n not in (3, 4):
        raise ValueError(f"a stance holds 3 or 4 anchors, this one holds {n}")
    return n


# The kernel is compiled for C-contiguous, writable float64 / int64 / bool arrays: anything
# else (a read-only view, say) would trigger a second compilation of it.
def _floats(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float).reshape(shape)
    return a if a.flags.writeable else a.copy()


def _indices(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.int64)
    return a if a.flags.writeable else a.copy()
