"""A dictionary of recomputable values that holds at most a given number of bytes.

The footstep search keeps, per stance it meets, the connected components of its feasible
lattice poses, and per move it evaluates, the lattice poses that hold it (`LatticeMemo`). Kept
forever, they grow by about 60 kB per expanded vertex: a long proof or a 20 m climb would fill
the machine. Both are pure functions of their key (and of the scenario and lattice), so they
can be dropped and decided again when asked for: `BoundedCache` drops the least recently used
entries once its values exceed `cap_bytes`, and rebuilds a dropped entry when it is asked for
again. What it keeps of a dropped entry (its *tombstone*, from `tombstone(value)`) is what the
rebuild needs to give back the same value: for a stance's components, the lattice poses its
components were grown from, in order, so that they are numbered as before (a search's vertex
names its component by number). The keys and tombstones of dropped entries count against the
cap too (`kept_bytes`): a cache given a `KeyCodec` keeps its dropped keys (whose tombstones are
None) as exact integer codes in about 16 bytes each (`planning.compact_keys`), the others as
they are, counted at `DROPPED_KEY_BYTES` a key plus their tombstone's `tombstone_size`.

A cache that can pack its values (`pack`, `unpack`: the search's components, move tables and
transitions, by `planning.packing`; a stance's components to about a fifth) keeps the entries
it would drop packed instead, until packed entries fill a share of the cap (`MemoryPool`):
unpacking takes about a tenth of the time of deciding an entry again.

A pool may also watch the whole process (`MemoryPool.process_budget`): the search's own
structures (its open list, parents, labels) grow beside the caches, and what else lives in the
process (the libraries, a caller's data) is not the cache's to count; when resident memory
passes the budget, the pool lowers its cap by the excess (to at least `GOVERNOR_FLOOR_MB`), and
raises it again, up to its own cap, when memory allows. Only what is kept changes, never what
is decided.

To the code that uses it the cache is a dict that never forgets: `get` and `[]` rebuild a
dropped key, `in` counts it, and the search's decisions do not change
(tests/test_bounded_cache.py, and the benchmark of docs/benchmarks.md: the same routes capped
and uncapped). The `PROTECTED` most recently used entries are never dropped, so that an entry a
caller is still working on is not rebuilt beside it.
"""

from __future__ import annotations

import ctypes
import math
import os
import resource
import sys
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Any, Generic, TypeVar

import numpy as np

from planning.compact_keys import CompactKeys, KeyCodec

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")

PROTECTED = 16  # the most recently used entries, never dropped
_MISSING = object()


def peak_memory_mb() -> float:
    """The process's peak resident memory so far, MiB."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2.0 ** 20 if sys.platform == "darwin" else peak / 1024.0  # bytes there, kB here


def resident_memory_bytes() -> int | None:
    """The process's resident memory now (bytes), or None where /proc does not say."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def release_free_heap() -> None:
    """Give the memory that earlier work freed back to the system (glibc's `malloc_trim`;
    elsewhere nothing), so that resident memory counts what is live. Without it, a search
    that follows a larger one in the same process (a sweep's worker, a notebook) finds the
    earlier search's freed heap still resident, and a pool watching the process lowers its cap
    for memory that nothing holds (a quarter cap after an uncapped run of the same cave:
    resident 735 MiB, 256 MiB once released)."""
    global _malloc_trim
    if _malloc_trim is None:
        try:
            _malloc_trim = ctypes.CDLL("libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _malloc_trim = False
    if _malloc_trim:
        _malloc_trim(0)


_malloc_trim: Any = None  # glibc's malloc_trim once looked for; False: not there

GOVERNOR_FLOOR_MB = 64.0  # the least a watching pool's cap is lowered to
GOVERNOR_EVERY = 256      # uses of its entries between two readings of resident memory


def array_bytes(value: Any) -> int:
    """The bytes of the numpy arrays a value holds (a NamedTuple or a sequence of fields)."""
    return sum(v.nbytes for v in value if isinstance(v, np.ndarray))


# what a dropped entry's key holds in the dict of dropped keys (a tuple of a few fields and its
# dict slot), counted with its tombstone's `tombstone_size`
DROPPED_KEY_BYTES = 160

PACKED_SHARE = 2.0 / 3.0  # of the cap, the most that packed entries may hold
# what a packed entry holds besides its bytes (its slots in the cache's and the pool's dicts,
# its tuples, the bytes object's header; measured by tracemalloc: about 350), counted with them
PACKED_ENTRY_BYTES = 400


def packed_size(blob: bytes) -> int:
    """The bytes a packed entry counts against the cap."""
    return len(blob) + PACKED_ENTRY_BYTES


class MemoryPool:
    """One cap shared by several caches (`BoundedCache(pool=...)`): past it, the least
    recently used entry of any of them goes first, so that a cache whose entries are used more
    keeps more of the memory (None: no cap). An entry of a cache that can pack its values is
    packed (kept compressed, `planning.packing`) rather than dropped, while packed entries hold
    at most `PACKED_SHARE` of the cap; past that the least recently packed are dropped. Live
    and packed bytes both count against the cap."""

    def __init__(self, cap_bytes: float | None = None) -> None:
        self.cap_bytes = cap_bytes
        self.protected = PROTECTED  # the most recently used entries, never dropped
        self._order: OrderedDict[tuple[str, Hashable], BoundedCache[Any, Any]] = OrderedDict()
        self._packed: OrderedDict[tuple[str, Hashable], BoundedCache[Any, Any]] = OrderedDict()
        self.total_bytes = 0   # live entries
        self.packed_bytes = 0  # packed entries
        self.kept_bytes = 0    # dropped entries' keys and tombstones (never dropped themselves)
        self.peak_bytes = 0
        # resident bytes the whole process should keep within (None: not watched), and the
        # cap lowered to keep it there (module doc)
        self.process_budget: float | None = None
        self.lowered_cap: float | None = None
        self.lowest_cap: float | None = None
        self._uses = 0

    def touched(self, cache: BoundedCache[Any, Any], key: Hashable, grew: int) -> None:
        """`cache` used (or stored) `key`, whose bytes grew by `grew`."""
        slot = (cache.name, key)
        self._order[slot] = cache
        self._order.move_to_end(slot)
        self.total_bytes += grew
        self._uses += 1
        if self.process_budget is not None and self._uses % GOVERNOR_EVERY == 0:
            self._watch_process(self.process_budget)
        cap = self.cap_bytes if self.lowered_cap is None else self.lowered_cap
        if cap is not None and self.held_bytes > cap:
            self._shrink(cap)
        self.peak_bytes = max(self.peak_bytes, self.held_bytes)

    @property
    def held_bytes(self) -> int:
        """Everything counted against the cap: live and packed entries, dropped keys."""
        return self.total_bytes + self.packed_bytes + self.kept_bytes

    def _watch_process(self, budget: float) -> None:
        """Lower the cap by the process's excess over `budget`, or raise it by its room."""
        resident = resident_memory_bytes()
        if resident is None:
            return
        cap = self.held_bytes + budget - resident
        if self.cap_bytes is not None and cap >= self.cap_bytes:
            self.lowered_cap = None
            return
        # never under the floor, nor (a cap below the floor, as the tests set) over its own cap
        self.lowered_cap = max(GOVERNOR_FLOOR_MB * 2.0 ** 20, cap)
        if self.cap_bytes is not None:
            self.lowered_cap = min(self.lowered_cap, self.cap_bytes)
        self.lowest_cap = min(self.lowered_cap, self.lowest_cap or math.inf)

    def unpacked(self, cache: BoundedCache[Any, Any], key: Hashable, nbytes: int) -> None:
        """`cache`'s packed entry `key` (`nbytes`) is packed no more."""
        del self._packed[(cache.name, key)]
        self.packed_bytes -= nbytes

    def _shrink(self, cap: float) -> None:
        while self.held_bytes > cap:
            # Packed entries are dropped only past their share: when the most recent entries
            # alone hold more than the cap (a small cap, large stances), dropping the packed
            # ones could not bring it under, and they are the cheapest to keep.
            if self._packed and self.packed_bytes > PACKED_SHARE * cap:
                (_, key), owner = self._packed.popitem(last=False)
                self.packed_bytes -= owner.drop_packed(key)
            elif len(self._order) > self.protected:
                (name, oldest), owner = self._order.popitem(last=False)
                freed, packed = owner.drop(oldest)
                self.total_bytes -= freed
                if packed is not None:
                    self._packed[(name, oldest)] = owner
                    self.packed_bytes += packed
            else:
                return

    def stats(self) -> dict[str, float]:
        return {"bytes": self.held_bytes, "peak_bytes": self.peak_bytes,
                "live": len(self._order), "packed": len(self._packed),
                "packed_bytes": self.packed_bytes, "kept_bytes": self.kept_bytes} | (
                    {} if self.lowest_cap is None else {"lowest_cap": self.lowest_cap})


class BoundedCache(Generic[K, V]):
    """A dict of at most `cap_bytes` of values (`size(value)`: its bytes; None: no cap), or
    sharing `pool`'s cap with other caches, that rebuilds a dropped entry with
    `rebuild(key, tombstone)` (module doc). `grows`: a stored value may grow (a stance's
    components do), so its size is measured again each time it is used. `pack(value)` and
    `unpack(key, bytes)`, if given, keep an entry packed before it is dropped (`MemoryPool`);
    `unpack` must give back a value equal to the one packed. An unpacked entry keeps its
    packed bytes (counted as its own), so that packing it again costs nothing while
    `version(value)` is unchanged (a value that grows must change its version). `codec`: the
    keys' exact integer codes, to keep dropped keys compact (its tombstones must be None);
    `tombstone_size(tombstone)`: the bytes a kept tombstone holds (module doc)."""

    def __init__(self, size: Callable[[V], int], rebuild: Callable[[K, Any], V],
                 tombstone: Callable[[V], Any] = lambda value: None,
                 cap_bytes: float | None = None, pool: MemoryPool | None = None,
                 name: str = "", grows: bool = False,
                 pack: Callable[[V], bytes] | None = None,
                 unpack: Callable[[K, bytes], V] | None = None,
                 version: Callable[[V], Hashable] = lambda value: None,
                 codec: KeyCodec | None = None,
                 tombstone_size: Callable[[Any], int] = lambda tombstone: 0) -> None:
        self._size, self._rebuild, self._tombstone = size, rebuild, tombstone
        if (pack is None) != (unpack is None):
            raise ValueError("a cache that packs its entries must unpack them too")
        self._pack, self._unpack, self._version = pack, unpack, version
        self.pool = pool if pool is not None else MemoryPool(cap_bytes)
        self.name, self.grows = name, grows
        self._live: OrderedDict[K, V] = OrderedDict()
        self._bytes: dict[K, int] = {}
        self._packed: dict[K, tuple[bytes, Any]] = {}  # key -> (packed value, tombstone)
        self._kept: dict[K, tuple[bytes, Hashable]] = {}  # unpacked: (its bytes, version)
        self._dropped: dict[K, Any] = {}
        self._codec, self._tombstone_size = codec, tombstone_size
        self._codes = CompactKeys()  # dropped keys, with a codec
        self._codes_bytes = 0  # what they held when last counted
        self._known = 0  # keys ever stored
        self.kept_bytes = 0  # what the dropped keys and tombstones hold
        self.total_bytes = 0
        self.peak_bytes = 0
        self.drops = 0
        self.rebuilds = 0
        self.packs = 0
        self.unpacks = 0

    @property
    def cap_bytes(self) -> float | None:
        return self.pool.cap_bytes

    def __len__(self) -> int:
        return self._known

    def __contains__(self, key: object) -> bool:
        return key in self._live or key in self._packed or key in self._dropped or \
            self._coded(key)

    def _coded(self, key: object) -> bool:
        """Whether `key` is among the compact dropped keys (a key rebuilt since stays there:
        callers look among the live and packed entries first)."""
        if not self._codes or self._codec is None:
            return False
        try:
            code = self._codec.encode(key)
        except (KeyError, ValueError, TypeError):  # not a key of this cache's form
            return False
        return code in self._codes

    def __iter__(self) -> Iterator[K]:
        yield from list(self._live)
        yield from list(self._packed)
        yield from list(self._dropped)
        if self._codec is not None:
            codes = list(self._codes)
            self._sync_codes()
            for code in codes:
                key = self._codec.decode(code)
                if key not in self._live and key not in self._packed:
                    yield key

    def items(self) -> Iterator[tuple[K, V]]:
        for key in list(self):
            yield key, self[key]

    def get(self, key: K, default: Any = None) -> Any:
        if key in self._live:
            value = self._live[key]
            self._live.move_to_end(key)
            self._account(key, value if self.grows else None)
            return value
        if key in self._packed:
            assert self._unpack is not None  # set with `pack` (__init__)
            blob, _ = self._packed.pop(key)
            self.pool.unpacked(self, key, packed_size(blob))
            value = self._unpack(key, blob)
            self.unpacks += 1
            self._kept[key] = (blob, self._version(value))
            self._store(key, value)
            return value
        if key in self._dropped:
            tomb = self._dropped.pop(key)
            self._kept_change(-(DROPPED_KEY_BYTES + self._tombstone_size(tomb)))
        elif self._coded(key):
            tomb = None  # the code stays: this cache looks in its live entries first
        else:
            return default
        value = self._rebuild(key, tomb)
        self.rebuilds += 1
        self._store(key, value)
        return value

    def __getitem__(self, key: K) -> V:
        value = self.get(key, _MISSING)
        if value is _MISSING:
            raise KeyError(key)
        return value

    def __setitem__(self, key: K, value: V) -> None:
        if key not in self:
            self._known += 1
        if key in self._dropped:
            tomb = self._dropped.pop(key)
            self._kept_change(-(DROPPED_KEY_BYTES + self._tombstone_size(tomb)))
        if key in self._packed:
            blob, _ = self._packed.pop(key)
            self.pool.unpacked(self, key, packed_size(blob))
        self._kept.pop(key, None)
        self._store(key, value)

    def _store(self, key: K, value: V) -> None:
        self._live[key] = value
        self._live.move_to_end(key)
        self._account(key, value)

    def _account(self, key: K, value: V | None) -> None:
        """`key` used; its size measured again if `value` is given (stored, or may grow)."""
        grew = 0
        if value is not None:
            kept = self._kept.get(key)
            size = self._size(value) + (len(kept[0]) if kept is not None else 0)
            grew = size - self._bytes.get(key, 0)
            self.total_bytes += grew
            self._bytes[key] = size
        self.pool.touched(self, key, grew)
        self.peak_bytes = max(self.peak_bytes, self.total_bytes)

    def drop(self, key: K) -> tuple[int, int | None]:
        """Pack live `key` if this cache packs (else drop it, keeping its tombstone): the
        bytes it held live, and those it holds packed (None: dropped)."""
        value = self._live.pop(key)
        size = self._bytes.pop(key)
        self.total_bytes -= size
        if self._pack is not None:
            kept = self._kept.pop(key, None)
            if kept is not None and kept[1] == self._version(value):
                blob = kept[0]  # unchanged since it was unpacked
            else:
                blob = self._pack(value)
                self.packs += 1
            self._packed[key] = (blob, self._tombstone(value))
            return size, packed_size(blob)
        self._forget(key, self._tombstone(value))
        return size, None

    def drop_packed(self, key: K) -> int:
        """Drop packed `key`, keeping its tombstone: the bytes it held."""
        blob, tomb = self._packed.pop(key)
        self._forget(key, tomb)
        return packed_size(blob)

    def _forget(self, key: K, tomb: Any) -> None:
        """Keep only `key` (compact, with a codec) and its tombstone."""
        self.drops += 1
        if self._codec is not None:
            if tomb is not None:
                raise ValueError(f"cache {self.name!r} keeps compact keys: its tombstones "
                                 "must be None")
            self._codes.add(self._codec.encode(key))
            self._sync_codes()
            return
        self._dropped[key] = tomb
        self._kept_change(DROPPED_KEY_BYTES + self._tombstone_size(tomb))

    def _sync_codes(self) -> None:
        """Count what the compact keys hold now (merging pending codes shrinks them)."""
        now = self._codes.nbytes
        self._kept_change(now - self._codes_bytes)
        self._codes_bytes = now

    def _kept_change(self, grew: int) -> None:
        self.kept_bytes += grew
        self.pool.kept_bytes += grew

    def stats(self) -> dict[str, float]:
        """Bytes held now and at most, entries held and dropped, drops and rebuilds."""
        dropped = len(self._dropped) + len(self._codes)
        self._sync_codes()
        return {"bytes": self.total_bytes, "peak_bytes": self.peak_bytes,
                "live": len(self._live), "packed": len(self._packed),
                "dropped": dropped, "kept_bytes": self.kept_bytes,
                "drops": self.drops, "rebuilds": self.rebuilds,
                "packs": self.packs, "unpacks": self.unpacks}
