"""A set of the keys a bounded cache has dropped, in about 16 bytes a key.

A `planning.bounded_cache.BoundedCache` remembers which keys it dropped, so that asking for one
again rebuilds it (the same value) rather than counting a new decision: the footstep search
counts transitions it tests and skips a move whose transition it has not tested when the move
adds nothing, so forgetting a dropped key would change what it decides. Kept as tuples in a
dict, a dropped transition's key held about 120 bytes, uncounted, for every transition a long
search ever tested. `CompactKeys` keeps each key as an exact integer code (`KeyCodec`: the
tuple's fields in mixed radix), merged in batches into one sorted numpy array of 16-byte
values: about 16 bytes a key, counted by `nbytes`. Codes are exact (no hashing), so membership
is exact; a code of 128 bits or more (never for the search's keys) is kept in a Python set.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import numpy as np

CODE_BYTES = 16
_LIMIT = 1 << (8 * CODE_BYTES)
MERGE_EVERY = 1 << 14  # pending codes merged into the sorted array at this many
# what a pending code holds before it is merged: the int (about 36 bytes) and its set slot
PENDING_CODE_BYTES = 80


class KeyCodec(NamedTuple):
    """A key's exact integer code and back: `encode(key) -> int >= 0`, `decode(code) -> key`,
    with decode(encode(key)) == key."""

    encode: Callable[[Any], int]
    decode: Callable[[int], Any]


class CompactKeys:
    """An exact set of non-negative integer codes, about `CODE_BYTES` bytes each (module doc).
    Codes are only added, never removed: a key rebuilt from it stays in the set, and its owner
    looks in its live entries first."""

    def __init__(self) -> None:
        self._sorted = np.empty(0, dtype=f"V{CODE_BYTES}")
        self._pending: set[int] = set()
        self._large: set[int] = set()

    def add(self, code: int) -> None:
        if code < 0:
            raise ValueError(f"a key's code must be non-negative, got {code}")
        if code >= _LIMIT:
            self._large.add(code)
            return
        self._pending.add(code)
        if len(self._pending) >= MERGE_EVERY:
            self._merge()

    def __contains__(self, code: int) -> bool:
        if code in self._pending or code in self._large:
            return True
        if code >= _LIMIT or code < 0 or not len(self._sorted):
            return False
        value = np.frombuffer(code.to_bytes(CODE_BYTES, "big"), dtype=self._sorted.dtype)[0]
        i = int(np.searchsorted(self._sorted, value))
        return i < len(self._sorted) and self._sorted[i] == value

    def __bool__(self) -> bool:
        return bool(self._pending or self._large or len(self._sorted))

    def __len__(self) -> int:
        self._merge()
        return len(self._sorted) + len(self._large)

    def __iter__(self) -> Iterator[int]:
        self._merge()
        for value in self._sorted:
            yield int.from_bytes(bytes(value), "big")
        yield from self._large

    @property
    def nbytes(self) -> int:
        """What the set holds: its sorted array, and its pending and large codes."""
        return int(self._sorted.nbytes) + PENDING_CODE_BYTES * (
            len(self._pending) + len(self._large))

    def _merge(self) -> None:
        if not self._pending:
            return
        new = np.frombuffer(b"".join(c.to_bytes(CODE_BYTES, "big") for c in self._pending),
                            dtype=self._sorted.dtype)
        self._pending.clear()
        self._sorted = np.unique(np.concatenate([self._sorted, new]))


def mixed_radix(fields: list[int], radices: list[int]) -> int:
    """Fields as one integer: the first any non-negative int, field i + 1 in [0, radices[i])."""
    code = int(fields[0])  # Python ints: a numpy field would overflow
    if code < 0:
        raise ValueError(f"field {code} is negative")
    for value, radix in zip(map(int, fields[1:]), radices, strict=True):
        if not 0 <= value < radix:
            raise ValueError(f"field {value} outside [0, {radix})")
        code = code * radix + value
    return code


def split_radix(code: int, radices: list[int]) -> list[int]:
    """`mixed_radix`'s fields back."""
    fields = []
    for radix in reversed(radices):
        code, value = divmod(code, radix)
        fields.append(value)
    fields.append(code)
    return fields[::-1]
