"""Checks of a scan's bytes that trimesh's readers skip (`mesh_section.load_scan`).

trimesh drops an STL triangle with a NaN vertex without a word, reads a binary PLY's faces as
if every list held 3 indices (a count of 0 or 255 passes) and wraps a negative index, and
parses an ASCII PLY through Python lists (926 MB for a 22 MB cloud with a short last line).
These are found here first, vectorised, and refused with the line or element that is wrong.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator

import numpy as np

# PLY scalar types (both spellings) as numpy's
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
MAX_SCAN_COORDINATE = 1e7  # in the file's unit, whatever --unit says: 10 km in millimetres
FAR = (f"has a coordinate beyond {MAX_SCAN_COORDINATE:g} (in the file's unit): 10 km in "
       "millimetres; is this the right file?")
EMPTY = "holds no triangles or points: is this the right file?"
_STL = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


class ScanBytesError(ValueError):
    """Why a scan's bytes are not a valid scan (one line)."""


def check_scan(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Raise ScanBytesError if the bytes of a scan (suffix .stl, .obj or .ply) are not a valid
    one (what is not checked here is left to trimesh to refuse); return the (N, 3) vertices and
    (M, 3) faces (None: a point cloud) of an ASCII PLY, read here as trimesh reads them, else
    None (trimesh reads the file)."""
    problem: str | None = None
    if suffix == ".stl":
        stated = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
        if len(data) - 84 == 50 * stated:  # binary, as trimesh decides
            corners = np.frombuffer(data, dtype=_STL, count=stated, offset=84)["v"]
            finite = np.isfinite(corners).all(axis=(1, 2))
            if not finite.all():
                i = int(np.argmin(finite))
                value = corners[i][~np.isfinite(corners[i])][0]
                problem = f"triangle {i + 1:,} has a non-finite vertex coordinate ({value})"
            elif stated and np.abs(corners).max() > MAX_SCAN_COORDINATE:
                problem = FAR  # before trimesh's arrays (300 MB for 16 MB)
        else:
            low = data.lower()
            problem = _text_non_finite(low, rb"vertex") if b"vertex" in low else EMPTY
    elif suffix == ".obj":
        problem = _text_non_finite(data.lower(), rb"v") or _obj_short_line(data)
    else:
        return _ply(data)
    if problem is not None:
        raise ScanBytesError(problem)
    return None


def _line_words(data: bytes, start: int, chunk: int = 1 << 22
                ) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """From `start` (a line's start) on, a few MB at a time: (the chunk's offset, its bytes,
    its lines' starts within it, the number of words on each), counted in numpy (a regex
    took 0.7 s on 27 MB, trimesh's per-line lists 800 MB)."""
    while start < len(data):
        end = data.find(b"\n", min(start + chunk, len(data)))
        end = len(data) if end < 0 else end + 1
        a = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start)
        space = a <= 32  # blanks, tabs, line ends
        word = np.flatnonzero(~space & np.concatenate(([True], space[:-1])))  # words' starts
        lines = np.concatenate(([0], np.flatnonzero(a == 10) + 1))
        lines = lines[lines < len(a)]
        ends = np.append(lines[1:], len(a))
        yield start, a, lines, np.searchsorted(word, ends) - np.searchsorted(word, lines)
        start = end


def _quote(data: bytes, offset: int) -> str:
    """Line `n`: 'its text', of the line starting at `offset`."""
    end = data.find(b"\n", offset)
    text = data[offset:len(data) if end < 0 else end].strip()[:80].decode("latin-1")
    return f"line {_line(data, offset):,}: {text!r}"


def _text_non_finite(low: bytes, keyword: bytes) -> str | None:
    """The line of an ASCII STL or OBJ (lower case: `low`) whose vertex (a line starting with
    `keyword`) has a nan or inf coordinate; the slower line search runs only if such a word
    occurs at all."""
    first = min((at for at in (low.find(b"nan"), low.find(b"inf")) if at >= 0), default=-1)
    if first < 0:
        return None
    pattern = re.compile(rb"(?m)^[ \t]*" + keyword + rb"[ \t][^\r\n]*(?:nan|inf)[^\r\n]*")
    for match in pattern.finditer(low, low.rfind(b"\n", 0, first) + 1):
        try:
            values = [float(t) for t in match.group().split()[1:]]
        except ValueError:
            continue  # not numbers: trimesh says so
        if not all(np.isfinite(values)):
            return f"{_quote(low, match.start())} has a non-finite coordinate"
    return None


def _line(data: bytes, offset: int) -> int:
    """The number (from 1) of the line holding `offset`."""
    return data.count(b"\n", 0, offset) + 1


def _obj_short_line(data: bytes) -> str | None:
    """The first `v ` line (trimesh's vertex lines) with fewer than 3 coordinates (trimesh
    kept 2 columns and rbp failed on them; its fallback for such a line took 7 s and 800 MB)."""
    for start, a, lines, words in _line_words(data, 0):
        lines, words = lines[lines < len(a) - 1], words[lines < len(a) - 1]
        vertex = (a[lines] == ord("v")) & (a[lines + 1] == ord(" "))
        short = np.flatnonzero(vertex & (words < 4))  # `v` and 3 numbers
        if len(short):
            return f"{_quote(data, start + int(lines[short[0]]))} has fewer than 3 coordinates"
    return None


def _ply_header(data: bytes) -> tuple[str, list[tuple[str, int, list[list[str]]]], int] | None:
    """(format, [(element, count, [property words])], the body's offset), or None."""
    end = data.find(b"end_header", 0, 65536)
    if not data.startswith(b"ply") or end < 0:
        return None
    newline = data.find(b"\n", end)
    body = len(data) if newline < 0 else newline + 1
    fmt = ""
    elements: list[tuple[str, int, list[list[str]]]] = []
    for line in data[:end].decode("latin-1").splitlines():
        words = line.split()
        if words[:1] == ["format"] and len(words) > 1:
            fmt = words[1]
        elif words[:1] == ["element"] and len(words) == 3:
            try:
                elements.append((words[1], int(words[2]), []))
            except ValueError:
                return None  # trimesh refuses the header
        elif words[:1] == ["property"] and elements:
            elements[-1][2].append(words[1:])
    return fmt, elements, body


def _ply(data: bytes) -> tuple[np.ndarray, np.ndarray | None] | None:
    header = _ply_header(data)
    if header is None:
        return None
    fmt, elements, body = header
    names = [e[0] for e in elements]
    if fmt == "ascii" and names in (["vertex"], ["vertex", "face"]):
        return _ascii_ply(data, elements, body)
    if fmt.startswith("binary") and names == ["vertex", "face"]:
        _check_binary_faces(data, fmt, elements, body)
    return None


def _ascii_ply(data: bytes, elements: list[tuple[str, int, list[list[str]]]], body: int
               ) -> tuple[np.ndarray, np.ndarray | None] | None:
    """An ASCII PLY cloud's or triangle mesh's (x, y, z) and faces (None for a cloud) as
    trimesh reads them (each line's numbers as float64, cast to the property's type), by
    numpy's C parser instead of trimesh's per-line lists (550 MB for a valid 22 MB cloud, 18
    MB a MB for a mesh); a line without one number a property (`3` and 3 indices a face) is
    named. Other layouts: None, trimesh reads them."""
    _, count, props = elements[0]
    n_faces, face_type = 0, "i4"
    if len(elements) == 2:
        _, n_faces, fprops = elements[1]
        if (len(fprops) != 1 or len(fprops[0]) != 4 or fprops[0][0] != "list"
                or not {fprops[0][1], fprops[0][2]} <= set(_PLY_TYPES)):
            return None
        face_type = _PLY_TYPES[fprops[0][2]]
    names = [p[1] for p in props if len(p) == 2]
    if (count < 0 or n_faces < 0 or not props or not {"x", "y", "z"} <= set(names)
            or any(len(p) != 2 or p[0] not in _PLY_TYPES for p in props)):
        return None  # lists, or a header trimesh reads or refuses
    k, row, total = len(props), 0, count + n_faces
    for start, _, lines, words in _line_words(data, body):
        take = min(len(lines), total - row)
        expected = np.where(np.arange(row, row + take) < count, k, 4)
        wrong = np.flatnonzero(words[:take] != expected)
        if len(wrong):
            i, at = int(wrong[0]), row + int(wrong[0])
            what = f"vertex {at + 1:,}" if at < count else f"face {at - count + 1:,}"
            raise ScanBytesError(f"{_quote(data, start + int(lines[i]))} ({what}) holds "
                                 f"{int(words[i])} value(s), not {int(expected[i])}")
        row += take
        if row == total:
            break
    if row < total:
        raise ScanBytesError(f"holds {row:,} element lines, not the header's {total:,}")
    try:
        # all lines, as trimesh parses them (numbers after the elements are ignored, text not)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # fromstring's text mode is deprecated, not gone
            values = np.fromstring(data[body:], sep=" ")[: count * k + 4 * n_faces]
    except ValueError:
        bad = re.compile(rb"[^\s0-9eE+\-.nNaAiIfFtTyY]").search(data, body)
        where = _quote(data, data.rfind(b"\n", 0, bad.start()) + 1) if bad else "a line"
        raise ScanBytesError(f"{where} holds a value that is not a number") from None
    rows = values[: count * k].reshape(count, k)
    points = np.stack([rows[:, names.index(c)].astype(_PLY_TYPES[props[names.index(c)][0]])
                       for c in "xyz"], axis=1).astype(float)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise ScanBytesError(f"{_quote(data, _line_start(data, body, row))} (vertex {row + 1:,}) "
                             "has a non-finite coordinate")
    if len(elements) == 1:
        return points, None
    lists = values[count * k:].reshape(n_faces, 4)
    faces = lists[:, 1:].astype(face_type)
    wrong = (lists[:, 0] != 3) | ((faces < 0) | (faces >= count)).any(axis=1)
    if wrong.any():
        row = int(np.argmax(wrong))
        raise ScanBytesError(f"{_quote(data, _line_start(data, body, count + row))} (face "
                             f"{row + 1:,}) is not 3 indices of the {count:,} vertices")
    return points, faces


def _line_start(data: bytes, start: int, row: int) -> int:
    """The offset of the line `row` lines (from 0) after the line starting at `start`."""
    for _ in range(row):
        start = data.index(b"\n", start) + 1
    return start


def _check_binary_faces(data: bytes, fmt: str, elements: list[tuple[str, int, list[list[str]]]],
                        body: int) -> None:
    """A binary mesh of vertices then triangles (one list property): every list holds 3
    indices of existing vertices. Files of another layout are left to trimesh."""
    (_, n_vertices, vprops), (_, n_faces, fprops) = elements
    order = "<" if fmt == "binary_little_endian" else ">"
    if (any(len(p) != 2 or p[0] not in _PLY_TYPES for p in vprops) or len(fprops) != 1
            or len(fprops[0]) != 4 or fprops[0][0] != "list"
            or not {fprops[0][1], fprops[0][2]} <= set(_PLY_TYPES)):
        return
    vsize = sum(np.dtype(_PLY_TYPES[p[0]]).itemsize for p in vprops)
    face = np.dtype([("n", order + _PLY_TYPES[fprops[0][1]]),
                     ("i", order + _PLY_TYPES[fprops[0][2]], 3)])
    start = body + vsize * n_vertices
    if n_vertices < 0 or n_faces < 0 or len(data) - start != face.itemsize * n_faces:
        return  # not all triangles, or counts that lie: trimesh decides
    faces = np.frombuffer(data, dtype=face, count=n_faces, offset=start)
    wrong = faces["n"] != 3
    if wrong.any():
        i = int(np.argmax(wrong))
        raise ScanBytesError(f"face {i + 1:,} has a list count of {int(faces['n'][i])}, not 3")
    index = faces["i"]
    outside = ((index < 0) | (index >= n_vertices)).any(axis=1)
    if outside.any():
        i = int(np.argmax(outside))
        raise ScanBytesError(f"face {i + 1:,} has vertex indices {index[i].tolist()}, outside "
                             f"0 to {n_vertices - 1:,}")
