"""The connected components of one stance's feasible lattice poses, found as the search needs them.

A vertex of the complete search is (4-stance, component). `StanceComponents` holds the
components of one stance found so far, each grown by `planning.flood` from a pose the search
entered at, with the booms that may let go at each of its poses: the same sets, pose for pose,
as the tests' `stance_lattice` finds by scoring the stance's whole reachable lattice, but only for
the components the search enters.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from planning.flood import grow_component, reach_box
from planning.flood_kernel import component_arrays
from planning.lattice import SPAN, LatticeConfig, poses_of, unpack
from planning.packing import pack_arrays, unpack_arrays
from planning.transition_score import pack_rows
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario

INFEASIBLE = -1  # component_of / known_component: a pose no component holds
UNKNOWN = -2     # known_component: a pose not scored yet


class Component(NamedTuple):
    """One connected component of a stance's feasible lattice poses, sorted by key. A search
    keeps thousands: poses are decoded from the keys when asked for, not stored."""

    keys: np.ndarray        # (F,) int64 lattice keys, sorted
    robustness: np.ndarray  # (F,) r in the 4-stance
    release: np.ndarray     # (F, 4) bool: boom j may let go (3-stance, gripper at its anchor)
    release_r: np.ndarray   # (F, 4) r of that 3-stance (-inf where infeasible)
    lattice: LatticeConfig
    box: np.ndarray         # (2, 2) the smallest and largest (x, y) of its poses
    # the rows at which boom j may let go, ascending: release_rows[release_starts[j]:
    # release_starts[j + 1]] (about one pose-boom pair in ten: moves are sought there only)
    release_rows: np.ndarray
    release_starts: np.ndarray

    def boom_release_rows(self, boom: int) -> np.ndarray:
        """The rows at which boom `boom` may let go, ascending."""
        return self.release_rows[self.release_starts[boom]:self.release_starts[boom + 1]]

    @property
    def poses(self) -> np.ndarray:
        """(F, 3) body poses."""
        return self.poses_at(slice(None))

    def poses_at(self, rows: np.ndarray | slice) -> np.ndarray:
        """The body poses of `rows`."""
        return poses_of(unpack(self.keys[rows], self.lattice.angle_count), self.lattice)


class StanceComponents:
    """The components of one 4-stance's feasible lattice poses found so far (module doc)."""

    def __init__(self, scn: Scenario, stance: tuple[str, ...], cfg: LatticeConfig,
                 ignore_grasps: bool = False):
        table = scn.anchor_table
        free = len(table.row)
        held = [table.row[a] for a in stance]
        # Row 0 the 4-stance, row 1 + j the 3-stance with boom j's gripper at its anchor.
        rows = [held] + [[free if i == j else held[i] for i in range(NUM_BOOMS)]
                         for j in range(NUM_BOOMS)]
        self._stances, self._tips = pack_rows(table, rows, [free, *held])
        self._box = reach_box(table.positions[held], scn.robot.max_reach, cfg)
        self._scn, self._cfg, self._ignore = scn, cfg, ignore_grasps
        self.components: list[Component] = []
        self._keys = np.zeros(0, dtype=np.int64)    # every pose scored, sorted
        self._labels = np.zeros(0, dtype=np.int32)  # its component (INFEASIBLE if none)
        # the key each flood fill started from, in order: growing from them again gives the
        # same components with the same numbers (`replay`: a bounded memo drops and rebuilds)
        self.seeds: list[int] = []

    @classmethod
    def replay(cls, scn: Scenario, stance: tuple[str, ...], cfg: LatticeConfig,
               ignore_grasps: bool, seeds: list[int]) -> StanceComponents:
        """The components grown from `seeds` (another's `seeds`), in their order: the same
        components, numbered the same, and the same poses known infeasible."""
        out = cls(scn, stance, cfg, ignore_grasps)
        for key in seeds:
            out._grow(key)
        return out

    def packed(self) -> bytes:
        """What it knows, packed losslessly (`planning.packing`; `unpacked` reads it back)."""
        arrays: list[np.ndarray] = [self._keys, self._labels,
                                    np.asarray(self.seeds, dtype=np.int64)]
        modes = ["delta", "plain", "plain"]
        for c in self.components:
            arrays += [c.keys, c.robustness, c.release, c.release_r, c.box, c.release_rows,
                       c.release_starts]
            modes += ["delta", "plain", "bits", "neginf", "plain", "delta", "plain"]
        return pack_arrays(arrays, modes)

    @classmethod
    def unpacked(cls, scn: Scenario, stance: tuple[str, ...], cfg: LatticeConfig,
                 ignore_grasps: bool, blob: bytes) -> StanceComponents:
        """The components `packed` holds, exactly as they were (the same numbers)."""
        out = cls(scn, stance, cfg, ignore_grasps)
        arrays = unpack_arrays(blob)
        out._keys, out._labels = arrays[0], arrays[1]
        out.seeds = [int(k) for k in arrays[2]]
        for at in range(3, len(arrays), 7):
            keys, r, release, release_r, box, rows, starts = arrays[at:at + 7]
            out.components.append(Component(keys, r, release, release_r, cfg, box, rows,
                                            starts))
        return out

    @property
    def nbytes(self) -> int:
        """The bytes of its arrays."""
        return self._keys.nbytes + self._labels.nbytes + sum(
            sum(v.nbytes for v in c if isinstance(v, np.ndarray)) for c in self.components)

    def component_of(self, keys: np.ndarray) -> np.ndarray:
        """The component holding each lattice key (INFEASIBLE where the pose is infeasible),
        growing the components not found yet."""
        keys = np.asarray(keys, dtype=np.int64).reshape(-1)
        labels = self.known_component(keys)
        while (labels == UNKNOWN).any():
            self._grow(int(keys[np.argmax(labels == UNKNOWN)]))
            labels = self.known_component(keys)
        return labels

    def known_component(self, keys: np.ndarray) -> np.ndarray:
        """What is known of each key's pose: its component, INFEASIBLE (scored, or next to a
        component found) or UNKNOWN."""
        if not len(self._keys):
            return np.full(len(keys), UNKNOWN, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
        return np.where(self._keys[pos] == keys, self._labels[pos], UNKNOWN)

    def _grow(self, key: int) -> None:
        """Grow the component of lattice key `key` (or learn that its pose is infeasible)."""
        self.seeds.append(key)
        n = self._cfg.angle_count
        seed = unpack(np.array([key]), n)[0]
        idx, r, release_r, infeasible = grow_component(self._scn, self._stances, seed,
                                                       self._box, self._cfg, self._ignore)
        keys, r, release, release_r, rows, starts, box, bad = component_arrays(
            idx, r, release_r, infeasible, SPAN, n)
        if not len(keys):
            self._remember(bad, np.full(len(bad), INFEASIBLE, dtype=np.int32))
            return
        self.components.append(Component(keys, r, release, release_r, self._cfg,
                                         box * self._cfg.position_step, rows, starts))
        self._remember(np.concatenate([keys, bad]), np.concatenate([
            np.full(len(keys), len(self.components) - 1, dtype=np.int32),
            np.full(len(bad), INFEASIBLE, dtype=np.int32)]))

    def _remember(self, keys: np.ndarray, labels: np.ndarray) -> None:
        all_keys = np.concatenate([self._keys, keys])
        order = np.argsort(all_keys, kind="stable")
        self._keys, self._labels = all_keys[order], np.concatenate([self._labels, labels])[order]
