"""Arrays packed by planning.packing come back exactly: the same dtype, shape and bytes."""

from __future__ import annotations

import numpy as np
import pytest

from planning.packing import MODES, pack_arrays, unpack_arrays


def _cases(rng: np.random.Generator) -> list[tuple[np.ndarray, str]]:
    floats = rng.normal(size=(50, 4))
    floats[rng.random((50, 4)) < 0.7] = -np.inf
    floats[0, 0], floats[1, 1], floats[2, 2], floats[3, 3] = np.nan, np.inf, -0.0, 5e-324
    keys = np.sort(rng.integers(-2**62, 2**62, 300))
    return [
        (keys, "delta"),
        (rng.integers(-5, 5, 40).astype(np.int64), "delta"),  # not sorted: still exact
        (np.array([2**63 - 1, -2**63, 0], dtype=np.int64), "delta"),  # overflowing steps
        (rng.integers(0, 1000, 17).astype(np.int32), "delta"),
        (rng.random((13, 4)) < 0.3, "bits"),
        (floats, "neginf"),
        (floats, "plain"),
        (rng.integers(-3, 3, (7, 3)).astype(np.int32), "plain"),
        (np.zeros(0, dtype=np.int64), "delta"),
        (np.zeros((0, 4), dtype=bool), "bits"),
        (np.zeros((0, 4)), "neginf"),
        (np.full((3, 2), -np.inf), "neginf"),
        (np.arange(5, dtype=np.uint8), "plain"),
    ]


def test_every_mode_round_trips_exactly() -> None:
    cases = _cases(np.random.default_rng(5))
    assert {m for _, m in cases} == set(MODES)
    back = unpack_arrays(pack_arrays([a for a, _ in cases], [m for _, m in cases]))
    assert len(back) == len(cases)
    for (a, mode), b in zip(cases, back, strict=True):
        assert b.dtype == a.dtype and b.shape == a.shape, f"{mode}: {b.dtype}{b.shape}"
        assert b.tobytes() == a.tobytes(), f"{mode}: the bytes changed"
        assert b.flags.writeable, f"{mode}: an unpacked array must be writeable"


def test_sorted_keys_pack_small_and_wrong_modes_are_refused() -> None:
    keys = np.cumsum(np.random.default_rng(1).integers(1, 4, 100_000)).astype(np.int64)
    assert len(pack_arrays([keys], ["delta"])) < keys.nbytes / 20, "delta packing saves little"
    with pytest.raises(ValueError, match="delta packs integers"):
        pack_arrays([np.zeros(3)], ["delta"])
    with pytest.raises(ValueError, match="unknown packing mode"):
        pack_arrays([np.zeros(3)], ["zip"])


def test_packed_bytes_hold_no_more_memory_than_their_length() -> None:
    """A packed entry's memory is its length (the memo counts the length against its cap):
    zstandard's output buffer has the input's bound as its size, so it must be copied."""
    import tracemalloc

    keys = np.cumsum(np.ones(200_000, dtype=np.int64))
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        blob = pack_arrays([keys], ["delta"])
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(blob) < keys.nbytes / 100
    assert held < len(blob) + 4096, f"{held} B held for {len(blob)} B packed"
