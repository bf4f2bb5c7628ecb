"""References for the pose lattice that the planner itself never computes, for the tests to
hold its incremental results equal to (tests/test_complete_search.py). Test code only.

- `stance_lattice` scores a stance's whole reachable lattice at once and labels its connected
  components; the search grows only the components it enters (`planning.components`, by flood
  fill), which must be these, pose for pose.
- `candidate_moves` / `candidate_anchors`: every anchor a boom reaches from some release pose
  of a component, without the rock test of the segment that `lattice_moves.move_table` adds.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from planning.components import Component
from planning.lattice import LatticeConfig, pack, poses_of, reachable_lattice
from planning.lattice_kernels import lattice_reached_anchors
from planning.lattice_moves import _lattice_args, _near_anchors
from planning.transition_score import pack_rows
from rb_drake.kernel.scoring import score_rows
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


class StanceLattice(NamedTuple):
    """The feasible lattice poses of one 4-stance, sorted by key."""

    keys: np.ndarray        # (F,) int64, sorted
    idx: np.ndarray         # (F, 3) lattice indices
    poses: np.ndarray       # (F, 3)
    robustness: np.ndarray  # (F,) r in the 4-stance
    release: np.ndarray     # (F, 4) bool: boom j may let go (3-stance, gripper at its anchor)
    release_r: np.ndarray   # (F, 4) r of that 3-stance (-inf where infeasible)
    component: np.ndarray   # (F,) connected component label, 0 .. n_components - 1
    n_components: int
    reachable: int          # lattice poses at which the booms reach (the region scored)

    def find(self, keys: np.ndarray) -> np.ndarray:
        """Rows of `keys` in this set (-1 where absent)."""
        pos = np.searchsorted(self.keys, keys)
        pos = np.minimum(pos, max(len(self.keys) - 1, 0))
        hit = len(self.keys) > 0
        return np.where(hit & (self.keys[pos] == keys) if hit else False, pos, -1)


def stance_lattice(scn: Scenario, stance: tuple[str, ...], cfg: LatticeConfig,
                   ignore_grasps: bool = False) -> StanceLattice:
    """The feasible lattice poses of `stance`, their release booms and components."""
    table = scn.anchor_table
    free = len(table.row)
    held = [table.row[a] for a in stance]
    anchors = table.positions[held]
    idx = reachable_lattice(scn.robot, anchors, np.arange(NUM_BOOMS), cfg)
    reachable = len(idx)
    poses = poses_of(idx, cfg)
    rows = [held] + [[free if i == j else held[i] for i in range(NUM_BOOMS)]
                     for j in range(NUM_BOOMS)]
    stances, tips = pack_rows(table, rows, [free, *held])
    P = len(idx)
    # The four release 3-stances are decided where the 4-stance holds (KernelCheck.release_r).
    check = score_rows(scn, stances, tips, poses, np.arange(P), np.zeros(P, np.int64),
                       np.zeros(P, np.int64), ignore_grasps, decide_only=True, release=True)
    ok = check.feasible
    idx, poses, r = idx[ok], poses[ok], check.robustness[ok]
    release = ~np.isnan(check.release_r[ok])
    release_r = np.where(release, check.release_r[ok], -np.inf)
    component, n = _components(idx)
    keys = pack(idx, cfg.angle_count)
    order = np.argsort(keys)
    return StanceLattice(keys[order], idx[order], poses[order], r[order], release[order],
                         release_r[order], component[order], n, reachable)


def _components(idx: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected components of lattice points under 26-connectivity."""
    if not len(idx):
        return np.zeros(0, dtype=np.int64), 0
    lo = idx.min(axis=0)
    shape = tuple(idx.max(axis=0) - lo + 1)
    grid = np.zeros(shape, dtype=bool)
    local = idx - lo
    grid[local[:, 0], local[:, 1], local[:, 2]] = True
    labels, n = ndimage.label(grid, structure=np.ones((3, 3, 3), dtype=bool))
    return labels[local[:, 0], local[:, 1], local[:, 2]].astype(np.int64) - 1, int(n)


def candidate_moves(scn: Scenario, lat: Component, stance: tuple) -> list[np.ndarray]:
    """Per boom, the indices of every anchor it reaches from some release pose of component
    `lat` (exact on the lattice), the stance's own anchors excluded: one compiled pass over
    the component, anchors beyond reach of its bounding box left out first."""
    pts = scn.anchor_positions
    near = _near_anchors(scn, lat, stance)
    if not len(near):
        return [near] * NUM_BOOMS
    found = lattice_reached_anchors(lat.keys, lat.release_rows, lat.release_starts,
                                    np.ascontiguousarray(pts[near]),
                                    *_lattice_args(scn, lat.lattice))
    return [near[found[j]] for j in range(NUM_BOOMS)]


def candidate_anchors(scn: Scenario, lat: Component, stance: tuple, boom: int) -> np.ndarray:
    """Indices of every anchor boom `boom` reaches from some release pose of component `lat`
    (exact on the lattice), the stance's own anchors excluded."""
    return candidate_moves(scn, lat, stance)[boom]
