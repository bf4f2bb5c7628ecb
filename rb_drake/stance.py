"""A stance: which anchor each boom holds, with that anchor's grasp parameters as arrays."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rb_drake import grasp


class Stance(NamedTuple):
    """Per boom (rows 0..3): anchor position, outward unit normal, limit-surface parameters.

    A free boom (a 3-stance) has `attached[i] == False`, id None and NaN parameters.
    """

    ids: tuple[str | None, ...]
    attached: np.ndarray       # (4,) bool
    positions: np.ndarray      # (4, 2)
    normals: np.ndarray        # (4, 2)
    f_normal: np.ndarray       # (4,)
    f_lateral: np.ndarray      # (4,)
    sigma_normal: np.ndarray   # (4,)
    sigma_lateral: np.ndarray  # (4,)

    @property
    def free_boom(self) -> int | None:
        free = np.flatnonzero(~self.attached)
        return int(free[0]) if len(free) else None

    def log_prob(self, tensions: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """log P per boom (shape of `tensions`, (..., 4)); 0 for a free boom."""
        lp = grasp.log_prob(tensions, psi, self.f_normal, self.f_lateral,
                            self.sigma_normal, self.sigma_lateral)
        return np.where(self.attached, lp, 0.0)

    def margin(self, tensions: np.ndarray, psi: np.ndarray) -> np.ndarray:
        return grasp.margin(tensions, psi, self.f_normal, self.f_lateral,
                            self.sigma_normal, self.sigma_lateral)

    def mean_limit(self, psi: np.ndarray) -> np.ndarray:
        return grasp.mean_limit(psi, self.f_normal, self.f_lateral)

    def sigma(self, psi: np.ndarray) -> np.ndarray:
        return grasp.sigma_limit(psi, self.sigma_normal, self.sigma_lateral)

    @staticmethod
    def mix(a: Stance, b: Stance, use_b: np.ndarray) -> Stance:
        """A per-row stance: row k is b where use_b[k], else a (same booms attached).

        Lets one vectorised check evaluate two stances that differ in one anchor, e.g. the old
        and the new 4-stance of a transition, at once."""
        if not np.array_equal(a.attached, b.attached):
            raise ValueError("mixed stances must attach the same booms")
        pick = use_b[:, None]
        return Stance(a.ids, a.attached, np.where(pick[..., None], b.positions, a.positions),
                      np.where(pick[..., None], b.normals, a.normals),
                      np.where(pick, b.f_normal, a.f_normal),
                      np.where(pick, b.f_lateral, a.f_lateral),
                      np.where(pick, b.sigma_normal, a.sigma_normal),
                      np.where(pick, b.sigma_lateral, a.sigma_lateral))

    def take(self, rows: np.ndarray) -> Stance:
        """The rows of a per-row stance (see `mix`); a plain stance is returned as it is."""
        if self.positions.ndim == 2:
            return self
        return Stance(self.ids, self.attached, self.positions[rows], self.normals[rows],
                      self.f_normal[rows], self.f_lateral[rows], self.sigma_normal[rows],
                      self.sigma_lateral[rows])

    def without(self, boom: int) -> Stance:
        """The 3-stance that frees `boom`."""
        attached = self.attached.copy()
        attached[boom] = False
        ids = tuple(None if i == boom else a for i, a in enumerate(self.ids))

        def blank(a: np.ndarray) -> np.ndarray:
            a = a.astype(float, copy=True)
            a[boom] = np.nan
            return a

        return Stance(ids, attached, blank(self.positions), blank(self.normals),
                      blank(self.f_normal), blank(self.f_lateral), blank(self.sigma_normal),
                      blank(self.sigma_lateral))
