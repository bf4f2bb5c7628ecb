"""Test helpers for the compiled kernel (rb_drake.kernel): plain stances packed as its rows."""

from __future__ import annotations

import numpy as np

from rb_drake.kernel.scoring import PackedStances
from rb_drake.stance import Stance


def pack_stances(*stances: Stance) -> PackedStances:
    """Plain (not per-row) stances, one row each, for `score_rows`."""
    for stance in stances:
        n = int(np.count_nonzero(stance.attached))
        if n not in (3, 4):
            raise ValueError(f"a stance holds 3 or 4 anchors, this one holds {n}")
    return PackedStances(*(np.stack([getattr(s, name) for s in stances]).astype(
        bool if name == "attached" else float) for name in PackedStances._fields))
