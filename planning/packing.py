"""Numpy arrays packed losslessly into bytes, for a memo entry kept compressed instead of dropped.

A bounded memo (`planning.bounded_cache`) past its cap first packs the least recently used
entries it can pack and drops entries only past a share of its cap: unpacking a stance's
components takes about a tenth of the time of growing them again. Each array is encoded by
what it holds, then all of them compressed together with zstd (level 1: on the search's
lattice work it packs about 6x and unpacks about 2.7x faster than zlib's fastest level, to
smaller bytes):
- "delta": integers mostly ascending (sorted lattice keys), as their differences;
- "bits": booleans, eight to a byte;
- "neginf": floats mostly -inf (a 3-stance's r where it cannot hold), as a mask and the rest;
- "plain": anything else.
Multi-byte values are byte-shuffled first (the k-th byte of every value together), which is
what lets zstd find the repetition in floats and small integers. Every encoding is exact:
`unpack_arrays(pack_arrays(a, modes))` gives arrays with the same dtype, shape and bytes.
"""

from __future__ import annotations

import pickle
from collections.abc import Sequence

import numpy as np
import zstandard

# one of each per process (the search's Python is single-threaded): made once, not per call
_COMPRESS = zstandard.ZstdCompressor(level=1)
_DECOMPRESS = zstandard.ZstdDecompressor()

MODES = ("delta", "bits", "neginf", "plain")


def _shuffled(a: np.ndarray) -> bytes:
    a = np.ascontiguousarray(a)
    if a.dtype.itemsize == 1:
        return a.tobytes()
    return np.frombuffer(a.tobytes(), np.uint8).reshape(-1, a.dtype.itemsize).T.tobytes()


def _unshuffled(raw: bytes, dtype: np.dtype, count: int) -> np.ndarray:
    if dtype.itemsize == 1:
        return np.frombuffer(raw, dtype=dtype, count=count).copy()
    grid = np.frombuffer(raw, np.uint8).reshape(dtype.itemsize, count).T
    return np.ascontiguousarray(grid).view(dtype).reshape(count)


def pack_arrays(arrays: Sequence[np.ndarray], modes: Sequence[str]) -> bytes:
    """The arrays, each encoded by its mode (module doc), compressed into one bytes object."""
    header, parts = [], []
    for a, mode in zip(arrays, modes, strict=True):
        a = np.asarray(a)
        flat = a.reshape(-1)
        if mode == "delta":
            if a.dtype.kind not in "iu":
                raise ValueError(f"delta packs integers, not {a.dtype}")
            chunks = [_shuffled(np.diff(flat, prepend=flat.dtype.type(0)))]
        elif mode == "bits":
            chunks = [np.packbits(flat.astype(bool)).tobytes()]
        elif mode == "neginf":
            held = flat != -np.inf
            chunks = [np.packbits(held).tobytes(), _shuffled(flat[held])]
        elif mode == "plain":
            chunks = [_shuffled(flat)]
        else:
            raise ValueError(f"unknown packing mode {mode!r} (one of {MODES})")
        header.append((a.dtype.str, a.shape, mode, [len(c) for c in chunks]))
        parts += chunks
    head = pickle.dumps(header, protocol=5)
    packed = _COMPRESS.compress(len(head).to_bytes(8, "little") + head + b"".join(parts))
    # zstandard allocates its output at the bound of the input's size and only shortens the
    # length: a right-sized copy, or each kept entry would hold about its unpacked size
    return memoryview(packed).tobytes()


def unpack_arrays(blob: bytes) -> list[np.ndarray]:
    """The arrays `pack_arrays` packed, exactly."""
    raw = _DECOMPRESS.decompress(blob)
    size = int.from_bytes(raw[:8], "little")
    header = pickle.loads(raw[8:8 + size])
    at = 8 + size
    out = []
    for dtype_str, shape, mode, lengths in header:
        dtype = np.dtype(dtype_str)
        count = int(np.prod(shape, dtype=np.int64))
        chunks = []
        for n in lengths:
            chunks.append(raw[at:at + n])
            at += n
        if mode == "delta":
            flat = np.cumsum(_unshuffled(chunks[0], dtype, count), dtype=dtype)
        elif mode == "bits":
            flat = np.unpackbits(np.frombuffer(chunks[0], np.uint8), count=count).astype(bool)
        elif mode == "neginf":
            held = np.unpackbits(np.frombuffer(chunks[0], np.uint8), count=count).astype(bool)
            flat = np.full(count, -np.inf, dtype=dtype)
            flat[held] = _unshuffled(chunks[1], dtype, int(held.sum()))
        else:
            flat = _unshuffled(chunks[0], dtype, count)
        out.append(flat.astype(dtype, copy=False).reshape(shape))
    return out
