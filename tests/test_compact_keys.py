"""The dropped keys of the search's memo: exact, compact, counted against the cap, and a search
that drops transitions to their keys decides as one that keeps everything."""

from __future__ import annotations

import numpy as np
import pytest

from planning.bounded_cache import PROTECTED, BoundedCache
from planning.compact_keys import (
    CODE_BYTES,
    MERGE_EVERY,
    CompactKeys,
    KeyCodec,
    mixed_radix,
    split_radix,
)
from planning.complete import complete_search
from planning.complete_config import CompleteConfig
from planning.lattice_search import LatticeMemo
from rb_drake.scenario import bundled_caves, load_scenario


def test_compact_keys_hold_exactly_the_codes_added() -> None:
    rng = np.random.default_rng(31)
    added = {int(x) << int(s) for x, s in zip(rng.integers(0, 2**62, 3 * MERGE_EVERY),
                                               rng.integers(0, 64, 3 * MERGE_EVERY),
                                               strict=True)}
    added |= {0, 2**128 - 1, 2**128, 2**200}  # the edges, and codes too large to pack
    keys = CompactKeys()
    for code in added:
        keys.add(code)
        keys.add(code)  # added twice: held once
    others = {int(x) for x in rng.integers(0, 2**62, 2000)} - added
    assert all(code in keys for code in added), "a code added is missing"
    assert not any(code in keys for code in others), "a code never added is found"
    assert set(keys) == added, "iteration gives other codes than those added"
    assert len(keys) == len(added), f"{len(keys)} codes held, {len(added)} added"
    with pytest.raises(ValueError, match="non-negative"):
        keys.add(-1)


def test_compact_keys_take_about_sixteen_bytes_a_key() -> None:
    keys = CompactKeys()
    n = 5 * MERGE_EVERY
    for code in range(0, 7 * n, 7):
        keys.add(code)
    assert keys.nbytes <= (CODE_BYTES + 1) * n, f"{keys.nbytes / n:.1f} bytes a key"


def test_mixed_radix_codes_round_trip() -> None:
    rng = np.random.default_rng(7)
    radices = [4, 867, 867, 13]
    for _ in range(500):
        fields = [int(rng.integers(0, 10**6))] + [int(rng.integers(0, r)) for r in radices]
        code = mixed_radix(fields, radices)
        assert split_radix(code, radices) == fields, f"{fields} came back other"
    with pytest.raises(ValueError, match="outside"):
        mixed_radix([0, 4], [4])


def test_a_cache_keeps_dropped_keys_compact_and_counted() -> None:
    built: list[int] = []
    cache: BoundedCache[tuple, list] = BoundedCache(
        lambda v: 800, lambda k, _tomb: built.append(k[0]) or [k[0]] * 100, cap_bytes=40_000,
        codec=KeyCodec(lambda k: k[0], lambda code: (code,)))
    for k in range(2000):
        cache[(k,)] = [k] * 100
    stats = cache.stats()
    assert stats["drops"] >= 1900, f"a cache far over its cap dropped too little: {stats}"
    assert cache.kept_bytes == cache.pool.kept_bytes > 0, \
        f"the dropped keys are not counted: {cache.kept_bytes}, pool {cache.pool.kept_bytes}"
    # what may exceed the cap: the protected most recent entries (PROTECTED)
    assert cache.pool.held_bytes <= max(40_000, cache.kept_bytes + 800 * PROTECTED), \
        f"keys and entries together outgrew the cap: {cache.pool.stats()}"
    assert (5,) in cache and (2500,) not in cache, "membership of a dropped key is wrong"
    assert cache[(5,)] == [5] * 100 and built == [5], "a dropped key was not rebuilt, once"
    assert len(cache) == 2000, f"{len(cache)} keys counted, 2000 stored"
    assert sorted(k for k, in cache) == list(range(2000)), "iteration lost or added a key"


def test_a_search_that_drops_transitions_to_their_keys_decides_as_before() -> None:
    scn = load_scenario(bundled_caves()["demo-shaft"])
    config = CompleteConfig(max_expansions=60)
    free = complete_search(scn, config, memo=LatticeMemo(memory_mb=None))
    memo = LatticeMemo(memory_mb=0.05)
    memo.pool.protected = 2
    capped = complete_search(scn, config, memo=memo)
    stats = memo.stats()
    assert stats["transitions"]["drops"] > 0 and stats["transitions"]["kept_bytes"] > 0, \
        f"no transition was dropped to its key, so this tests nothing: {stats['transitions']}"
    assert stats["transitions"]["rebuilds"] + stats["moves"]["rebuilds"] > 0, \
        f"no dropped key was asked for again: {stats}"
    assert (capped.path, capped.expansions, capped.transitions_tested, capped.cost) == \
        (free.path, free.expansions, free.transitions_tested, free.cost), \
        "a search dropping transitions to compact keys decided otherwise"
    for key in memo.transitions:  # every key decodes to a tuple of the search's own form
        stance, comp, boom, anchor = key
        assert len(stance) == 4 and anchor in scn.anchor_index and 0 <= boom < 4 \
            and isinstance(comp, int) and comp >= 0 and key in memo.transitions, key
