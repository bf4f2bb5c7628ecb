"""The search's bounded memo (planning.bounded_cache, issue 31): a dropped entry comes back the
same when asked for, and a search under a tiny cap, which drops and rebuilds its lattice work
all the time, decides exactly as one with no cap."""

from __future__ import annotations

import ctypes.util
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import numpy as np
import pytest

from planning.bounded_cache import (
    PROTECTED,
    BoundedCache,
    resident_memory_bytes,
)
from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.components import StanceComponents
from planning.constrained import constrained_search
from planning.lattice import LatticeConfig
from planning.lattice_moves import (
    pack_moves,
    pack_transition,
    unpack_moves,
    unpack_transition,
)
from planning.lattice_search import LatticeMemo
from rb_drake.scenario import bundled_caves, load_scenario

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)


def test_dropped_entries_are_rebuilt_from_their_tombstones() -> None:
    built: list[int] = []

    def rebuild(key: int, tomb: int) -> np.ndarray:
        built.append(key)
        return np.full(tomb, key, dtype=np.int64)

    cache: BoundedCache[int, np.ndarray] = BoundedCache(
        lambda v: v.nbytes, rebuild, tombstone=len, cap_bytes=8 * 10 * (PROTECTED + 2))
    for key in range(3 * PROTECTED):
        cache[key] = np.full(10, key, dtype=np.int64)
        assert cache.total_bytes <= max(cache.cap_bytes, 8 * 10 * PROTECTED), \
            f"{cache.total_bytes} bytes held after storing key {key}, cap {cache.cap_bytes}"
    assert cache.drops > 0, "a cache over its cap dropped nothing"
    assert len(cache) == 3 * PROTECTED and all(k in cache for k in range(3 * PROTECTED)), \
        "a dropped key is no longer counted as held"
    again = cache[0]
    assert built == [0], f"rebuilt {built}, expected only the dropped key 0"
    assert np.array_equal(again, np.full(10, 0)), "a rebuilt value differs from the dropped one"
    assert cache.get(10**6) is None and 10**6 not in cache
    with pytest.raises(KeyError):
        cache[10**6]


@pytest.mark.parametrize(("cave", "anytime"), [("demo-shaft", None),
                                               ("demo-shaft", AnytimeConfig()),
                                               ("shaft-1", AnytimeConfig())],
                         ids=["demo-first", "demo-anytime", "shaft-1-anytime"])
def test_a_capped_search_decides_as_an_uncapped_one(cave: str,
                                                    anytime: AnytimeConfig | None) -> None:
    scn = load_scenario(bundled_caves()[cave])
    config = CompleteConfig(COARSE, anytime=anytime)
    free = complete_search(scn, config, memo=LatticeMemo(memory_mb=None))
    capped_memo = LatticeMemo(memory_mb=0.05)  # 50 kB: a few stances' lattice work
    capped_memo.pool.protected = 2  # a search this small would stay within the protected
    capped = complete_search(scn, config, memo=capped_memo)
    stats = capped_memo.stats()
    assert stats["components"]["drops"] > 0 and stats["components"]["rebuilds"] > 0, \
        f"the cap never bit, so the test tests nothing: {stats}"
    assert free.success and capped.success, (free.reason, capped.reason)
    assert capped.path == free.path, "a capped search found another route"
    assert capped.expansions == free.expansions and \
        capped.transitions_tested == free.transitions_tested, \
        (f"expansions {capped.expansions} vs {free.expansions}, transitions "
         f"{capped.transitions_tested} vs {free.transitions_tested}")
    assert capped.cost == pytest.approx(free.cost, rel=0, abs=0), "the route's cost differs"
    for a, b in zip(capped.poses, free.poses, strict=True):
        np.testing.assert_array_equal(a, b, err_msg="a transition pose differs")


def test_a_replayed_stance_numbers_its_components_as_before() -> None:
    scn = load_scenario(bundled_caves()["shaft-1"])  # several stances of several components
    memo = LatticeMemo(memory_mb=None)
    complete_search(scn, CompleteConfig(COARSE), memo=memo)
    several = 0
    for stance, found in memo.components.items():
        again = StanceComponents.replay(scn, stance, COARSE, False, list(found.seeds))
        assert len(again.components) == len(found.components), stance
        several += len(found.components) > 1
        for a, b in zip(again.components, found.components, strict=True):
            np.testing.assert_array_equal(a.keys, b.keys, err_msg=f"{stance}: a component's "
                                          "poses or its number changed when replayed")
            np.testing.assert_array_equal(a.release_r, b.release_r)
        np.testing.assert_array_equal(again.known_component(found._keys), found._labels,
                                      err_msg=f"{stance}: what is known of its poses changed")
    assert several > 0, "no stance with several components: the numbering is not tested"


def test_a_packed_stance_unpacks_exactly() -> None:
    scn = load_scenario(bundled_caves()["shaft-1"])
    memo = LatticeMemo(memory_mb=None)
    complete_search(scn, CompleteConfig(COARSE), memo=memo)
    checked = raw = packed = 0
    for stance, found in memo.components.items():
        blob = found.packed()
        back = StanceComponents.unpacked(scn, stance, COARSE, False, blob)
        assert back.seeds == found.seeds, stance
        for a, b in ((back._keys, found._keys), (back._labels, found._labels)):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f"{stance}: poses known"
        assert len(back.components) == len(found.components), stance
        for ca, cb in zip(back.components, found.components, strict=True):
            for name in ("keys", "robustness", "release", "release_r", "box", "release_rows",
                         "release_starts"):
                a, b = getattr(ca, name), getattr(cb, name)
                assert a.dtype == b.dtype and a.shape == b.shape and \
                    a.tobytes() == b.tobytes(), f"{stance}: {name} changed when unpacked"
        raw += found.nbytes
        packed += len(blob)
        checked += 1
    assert checked >= 5, f"only {checked} stances packed"
    assert packed < 0.5 * raw, f"packed {packed} B of {raw} B: packing saves little"


def test_a_packing_cache_packs_before_it_drops() -> None:
    scn = load_scenario(bundled_caves()["demo-shaft"])
    config = CompleteConfig(COARSE, anytime=AnytimeConfig())
    free = complete_search(scn, config, memo=LatticeMemo(memory_mb=None))
    memo = LatticeMemo(memory_mb=0.2)
    memo.pool.protected = 2
    capped = complete_search(scn, config, memo=memo)
    stats = memo.stats()
    for name in ("components", "transitions", "moves"):
        assert stats[name]["packs"] > 0 and stats[name]["unpacks"] > 0, \
            f"{name}: nothing packed and unpacked: {stats[name]}"
    assert stats["moves"]["packs"] < stats["moves"]["unpacks"] + stats["moves"]["packed"], \
        "a move table unpacked and dropped again was packed again (it keeps its bytes)"
    pool = memo.pool.stats()
    assert pool["peak_bytes"] <= 0.2 * 2**20 + max(
        sc.nbytes for _, sc in memo.components.items()) * 2, f"the pool outgrew its cap: {pool}"
    assert (capped.path, capped.expansions, capped.transitions_tested, capped.cost) == \
        (free.path, free.expansions, free.transitions_tested, free.cost), \
        "a search whose memo packed entries decided otherwise"


def test_a_packed_move_table_unpacks_in_its_order() -> None:
    scn = load_scenario(bundled_caves()["shaft-1"])
    memo = LatticeMemo(memory_mb=None)
    complete_search(scn, CompleteConfig(COARSE), memo=memo)
    tables = [table for _, table in memo.moves.items() if table]
    assert len(tables) >= 5, "too few move tables to check"
    for table in tables:
        back = unpack_moves(pack_moves(table))
        assert list(back) == list(table), "the moves' order changed (it orders the search)"
        for key, rows in table.items():
            assert back[key].dtype == rows.dtype and np.array_equal(back[key], rows), key
    assert unpack_moves(pack_moves({})) == {}


def test_a_packed_transition_unpacks_exactly() -> None:
    scn = load_scenario(bundled_caves()["shaft-1"])
    memo = LatticeMemo(memory_mb=None)
    complete_search(scn, CompleteConfig(COARSE), memo=memo)
    transitions = [tr for _, tr in memo.transitions.items()]
    assert sum(len(tr.keys) > 0 for tr in transitions) >= 5, "too few transitions to check"
    for tr in transitions:
        back = unpack_transition(pack_transition(tr))
        assert back.tested == tr.tested
        for a, b in zip(back[:3], tr[:3], strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_an_unpacked_entry_is_packed_again_only_once_it_changed() -> None:
    built: list[int] = []
    # 1600 B live (1800 with its kept bytes), 200 + PACKED_ENTRY_BYTES packed: one entry live
    # and three packed fit
    cache: BoundedCache[int, list[int]] = BoundedCache(
        lambda v: 8 * len(v), lambda k, _: built.append(k) or [k], cap_bytes=4000,
        pack=lambda v: bytes(v), unpack=lambda k, b: list(b), version=len)
    cache.pool.protected = 1
    for k in range(4):
        cache[k] = [k] * 200
    assert cache.packs == 3 and built == [], (cache.stats(), built)
    for k in range(4):  # each unpacked once, keeping its bytes
        assert cache[k] == [k] * 200
    packs = cache.packs
    for _ in range(3):
        for k in range(4):
            cache.get(k)
    assert cache.unpacks >= 12 and cache.packs == packs, (
        f"entries unpacked and pushed out again unchanged were packed again: "
        f"{cache.packs - packs} packs")
    grown = cache[0]
    grown.append(7)  # a new version: packed anew when it goes
    cache._account(0, grown)
    for k in range(1, 4):
        cache.get(k)
    assert cache.packs == packs + 1, "the grown entry was not packed anew"
    assert cache[0] == [0] * 200 + [7], "a grown entry came back as it was before it grew"
    assert built == [], "nothing should have been dropped and rebuilt"


def test_a_capped_min_success_search_decides_as_an_uncapped_one() -> None:
    """`--min-success`'s labels keep no transitions: under a tiny cap its route, cost, poses and
    each edge's alternatives (decided again at the end) are the uncapped search's."""
    scn = load_scenario(bundled_caves()["demo-shaft"])
    config = CompleteConfig(COARSE)
    free = constrained_search(scn, 0.5, config, memo=LatticeMemo(memory_mb=None))
    capped_memo = LatticeMemo(memory_mb=0.05)
    capped_memo.pool.protected = 2
    capped = constrained_search(scn, 0.5, config, memo=capped_memo)
    stats = capped_memo.stats()
    assert stats["transitions"]["drops"] > 0, f"the cap never bit on transitions: {stats}"
    assert free.success and capped.success, (free.reason, capped.reason)
    assert capped.path == free.path and capped.expansions == free.expansions, \
        f"another route or search: {capped.expansions} vs {free.expansions} expansions"
    assert capped.cost == pytest.approx(free.cost, rel=0, abs=0), "the route's cost differs"
    assert len(capped.alternatives) == len(free.alternatives) == len(free.path) - 1
    for a, b in zip(capped.alternatives, free.alternatives, strict=True):
        np.testing.assert_array_equal(a, b, err_msg="an edge's alternatives differ")
    for a, b in zip(capped.poses, free.poses, strict=True):
        np.testing.assert_array_equal(a, b, err_msg="a transition pose differs")


def test_a_pool_watching_the_process_gives_way_and_recovers(monkeypatch) -> None:
    """Past its process budget a pool lowers its cap by the excess (not under the floor) and
    drops to it; with room again it returns to its own cap."""
    from planning import bounded_cache
    from planning.bounded_cache import GOVERNOR_EVERY, GOVERNOR_FLOOR_MB, MemoryPool

    mib = 2.0 ** 20
    pool = MemoryPool(cap_bytes=400 * mib)
    pool.process_budget = 1000 * mib
    pool.protected = 0
    cache: BoundedCache[int, np.ndarray] = BoundedCache(
        lambda a: a.nbytes, lambda k, _t: np.zeros(1), pool=pool, name="c")
    resident = {"bytes": 500 * mib}
    monkeypatch.setattr(bounded_cache, "resident_memory_bytes", lambda: resident["bytes"])
    for key in range(GOVERNOR_EVERY):  # 256 entries of 1 MiB each: 256 MiB, under both
        cache[key] = np.zeros(2**17)
    assert pool.lowered_cap is None and pool.total_bytes == 256 * mib, pool.stats()
    resident["bytes"] = 1100 * mib  # 100 MiB over the budget: the cap is held - 100 MiB
    for key in range(GOVERNOR_EVERY):
        cache.get(key)
    assert pool.lowered_cap == pytest.approx(156 * mib, abs=1 * mib), pool.stats()
    assert pool.total_bytes <= pool.lowered_cap, f"not dropped to the lowered cap: {pool.stats()}"
    resident["bytes"] = 5000 * mib  # far over: never under the floor
    for key in range(GOVERNOR_EVERY):
        cache.get(key)
    assert pool.lowered_cap == GOVERNOR_FLOOR_MB * mib, pool.stats()
    assert pool.stats()["lowest_cap"] == GOVERNOR_FLOOR_MB * mib
    small = MemoryPool(cap_bytes=1 * mib)  # a cap under the floor is never raised to it
    small.process_budget = 1000 * mib
    small._watch_process(small.process_budget)
    assert small.lowered_cap == 1 * mib, small.stats()
    resident["bytes"] = 300 * mib  # room again: its own cap
    for key in range(GOVERNOR_EVERY):
        cache.get(key)
    assert pool.lowered_cap is None, pool.stats()


def test_a_search_squeezed_by_the_process_decides_as_an_uncapped_one() -> None:
    """A memo whose process budget is below what the process already holds keeps only its
    floor, and the search decides exactly as with no cap."""
    from planning.bounded_cache import GOVERNOR_FLOOR_MB

    scn = load_scenario(bundled_caves()["demo-shaft"])
    config = CompleteConfig(COARSE, anytime=AnytimeConfig())
    free = complete_search(scn, config, memo=LatticeMemo(memory_mb=None))
    memo = LatticeMemo(memory_mb=768.0)
    memo.pool.process_budget = 1.0  # every reading is over it
    squeezed = complete_search(scn, config, memo=memo)
    assert memo.pool.lowest_cap == GOVERNOR_FLOOR_MB * 2**20, memo.pool.stats()
    assert (squeezed.path, squeezed.expansions, squeezed.transitions_tested, squeezed.cost) == \
        (free.path, free.expansions, free.transitions_tested, free.cost), \
        "a search whose memo gave way to the process decided otherwise"


@pytest.mark.skipif(resident_memory_bytes() is None or ctypes.util.find_library("c") is None,
                    reason="needs /proc and the C library")
def test_freed_heap_is_given_back_before_a_search_counts_the_process() -> None:
    """A pool watching the process (issue 31) must not count memory an earlier search freed:
    blocks freed behind small live ones stay resident until the heap is trimmed. Measured in
    a fresh interpreter: in this one, earlier tests decide what the heap holds."""
    script = textwrap.dedent("""
        from planning.bounded_cache import release_free_heap, resident_memory_bytes
        blocks, pins = [], []
        for _ in range(2000):
            blocks.append(bytearray(100_000))
            pins.append(bytearray(1000))  # live, small: the heap's top cannot shrink past them
        del blocks
        before = resident_memory_bytes()
        release_free_heap()
        print(before, resident_memory_bytes(), len(pins))
        """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1], timeout=120)
    assert done.returncode == 0, done.stderr[-500:]
    before, after, _ = map(int, done.stdout.split())
    assert after < before - 100 * 2 ** 20, (
        f"resident {before / 2**20:.0f} MiB before releasing ~190 MiB of freed blocks, "
        f"{after / 2**20:.0f} MiB after")


def test_packed_entries_stay_when_the_most_recent_alone_pass_the_cap() -> None:
    """A cap smaller than the protected entries' bytes (a quarter cap of a small search, whose
    stances hold a MiB each) packs the older entries and keeps them within their share: dropping
    them could not bring the memo under the cap, and rebuilt them at every other use."""
    built: list[int] = []

    def rebuild(key: int, _tomb: object) -> np.ndarray:
        built.append(key)
        return np.full(1000, key, dtype=np.int64)

    cache: BoundedCache[int, np.ndarray] = BoundedCache(
        lambda v: v.nbytes, rebuild, cap_bytes=8000 * PROTECTED // 2,
        pack=lambda v: zlib.compress(v.tobytes()),
        unpack=lambda _key, blob: np.frombuffer(zlib.decompress(blob), dtype=np.int64).copy())
    for key in range(3 * PROTECTED):
        cache[key] = np.full(1000, key, dtype=np.int64)
    stats = cache.stats()
    assert stats["packed"] == 2 * PROTECTED and stats["drops"] == 0, (
        f"{stats['packed']} packed and {stats['drops']} dropped of {2 * PROTECTED} entries "
        f"older than the {PROTECTED} most recent, whose packed bytes fit their share")
    assert np.array_equal(cache[0], np.full(1000, 0)) and built == [], \
        f"an old entry came back by a rebuild ({built}), not unpacked"
