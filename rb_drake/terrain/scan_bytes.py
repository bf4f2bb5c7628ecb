"""Checks of a scan's bytes that trimesh's readers skip (`mesh_section.load_scan`).

trimesh drops an STL triangle with a NaN vertex without a word, reads a binary PLY's faces as
if every list held 3 indices (a count of 0 or 255 passes) and wraps a negative index, and
parses an ASCII PLY through Python lists (926 MB for a 22 MB cloud with a short last line).
These are found here first, vectorised, and refused with the line or element that is wrong.
"""

from __future__ import annotations

import io
import re
import warnings

import numpy as np

# PLY scalar types (both spellings) as numpy's
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
_STL = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def scan_problem(data: bytes, suffix: str) -> str | None:
    """Why the bytes of a scan (suffix .stl, .obj or .ply) are not a valid one, or None (what
    is not checked here is left to trimesh to refuse)."""
    if suffix == ".stl":
        stated = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
        if len(data) - 84 == 50 * stated:  # binary, as trimesh decides
            corners = np.frombuffer(data, dtype=_STL, count=stated, offset=84)["v"]
            finite = np.isfinite(corners).all(axis=(1, 2))
            if not finite.all():
                i = int(np.argmin(finite))
                value = corners[i][~np.isfinite(corners[i])][0]
                return f"triangle {i + 1:,} has a non-finite vertex coordinate ({value})"
            return None
        return _text_non_finite(data, rb"vertex")
    if suffix == ".obj":
        return _text_non_finite(data, rb"v") or _obj_short_line(data)
    return _ply_problem(data)


def _text_non_finite(data: bytes, keyword: bytes) -> str | None:
    """The line of an ASCII STL or OBJ whose vertex (a line starting with `keyword`) has a
    nan or inf coordinate; the slower line search runs only if such a word occurs at all."""
    low = data.lower()
    if low.find(b"nan") < 0 and low.find(b"inf") < 0:
        return None
    pattern = rb"(?m)^[ \t]*" + keyword + rb"[ \t][^\r\n]*(?:nan|inf)[^\r\n]*"
    for match in re.finditer(pattern, low):
        try:
            values = [float(t) for t in match.group().split()[1:]]
        except ValueError:
            continue  # not numbers: trimesh says so
        if not all(np.isfinite(values)):
            return (f"line {_line(low, match.start()):,} has a non-finite "
                    f"coordinate: {match.group().strip()[:80].decode('latin-1')!r}")
    return None


def _line(data: bytes, offset: int) -> int:
    """The number (from 1) of the line holding `offset`."""
    return data.count(b"\n", 0, offset) + 1


def _obj_short_line(data: bytes, chunk: int = 1 << 22) -> str | None:
    """The first `v ` line (trimesh's vertex lines) with fewer than 3 coordinates, found by
    counting each line's words in numpy, a few MB at a time (a regex took 0.7 s on 27 MB;
    trimesh's own fallback for such a line, 7 s and 800 MB)."""
    start = 0
    while start < len(data):
        end = data.find(b"\n", min(start + chunk, len(data)))
        end = len(data) if end < 0 else end + 1
        a = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start)
        space = a <= 32  # blanks, tabs, line ends
        word = np.flatnonzero(~space & np.concatenate(([True], space[:-1])))  # words' starts
        lines = np.concatenate(([0], np.flatnonzero(a == 10) + 1))
        lines = lines[lines < len(a) - 1]
        vertex = lines[(a[lines] == ord("v")) & (a[lines + 1] == ord(" "))]
        ends = np.append(lines, len(a))[np.searchsorted(lines, vertex) + 1]
        words = np.searchsorted(word, ends) - np.searchsorted(word, vertex)
        short = np.flatnonzero(words < 4)  # `v` and 3 numbers
        if len(short):
            offset = start + int(vertex[short[0]])
            text = data[offset:data.find(b"\n", offset) % (len(data) + 1)]
            return (f"line {_line(data, offset):,} has fewer than 3 coordinates: "
                    f"{text.strip()[:80].decode('latin-1')!r}")
        start = end
    return None


def short_vertex_line(data: bytes) -> str | None:
    """The first OBJ `v` line with fewer than 3 coordinates (on the refusal's path only)."""
    match = re.search(rb"(?m)^[ \t]*v(?:[ \t]+[^\s]+){0,2}[ \t]*\r?$", data)
    if match is None:
        return None
    return (f"line {_line(data, match.start()):,} has fewer than 3 coordinates: "
            f"{match.group().strip()[:80].decode('latin-1')!r}")


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


def _ply_problem(data: bytes) -> str | None:
    header = _ply_header(data)
    if header is None:
        return None
    fmt, elements, body = header
    if fmt == "ascii" and len(elements) == 1 and elements[0][0] == "vertex":
        return _ascii_cloud_problem(data, elements[0][1], elements[0][2], body)
    if fmt.startswith("binary") and [e[0] for e in elements] == ["vertex", "face"]:
        return _binary_faces_problem(data, fmt, elements, body)
    return None


def _ascii_cloud_problem(data: bytes, count: int, props: list[list[str]],
                         body: int) -> str | None:
    """An ASCII point cloud: every vertex line holds one number a property (C's parser, not
    trimesh's lists); the first short or long line is named."""
    if count < 0 or any(len(p) != 2 or p[0] not in _PLY_TYPES for p in props) or not props:
        return None  # lists, or a header trimesh refuses
    k = len(props)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # fromstring's text mode is deprecated, not removed
        values = np.fromstring(data[body:], sep=" ")  # stops at the first non-number
    first = data.count(b"\n", 0, body) + 1  # the first vertex's line
    if len(values) >= count * k:
        bad = ~np.isfinite(values[: count * k])
        if bad.any():
            row = int(np.argmax(bad)) // k
            return f"line {first + row:,} (vertex {row + 1:,}) has a non-finite coordinate"
        return None
    for row, line in enumerate(io.BytesIO(data[body:])):
        if row >= count:
            break
        if len(line.split()) != k:
            return (f"line {first + row:,} (vertex {row + 1:,}) holds "
                    f"{len(line.split())} value(s), not the header's {k} properties: "
                    f"{line.strip()[:80].decode('latin-1')!r}")
    return f"holds fewer numbers than its header's {count:,} vertices of {k} properties"


def _binary_faces_problem(data: bytes, fmt: str, elements: list[tuple[str, int, list[list[str]]]],
                          body: int) -> str | None:
    """A binary mesh of vertices then triangles (one list property): every list holds 3
    indices of existing vertices. Files of another layout are left to trimesh."""
    (_, n_vertices, vprops), (_, n_faces, fprops) = elements
    order = "<" if fmt == "binary_little_endian" else ">"
    if (any(len(p) != 2 or p[0] not in _PLY_TYPES for p in vprops) or len(fprops) != 1
            or len(fprops[0]) != 4 or fprops[0][0] != "list"
            or not {fprops[0][1], fprops[0][2]} <= set(_PLY_TYPES)):
        return None
    vsize = sum(np.dtype(_PLY_TYPES[p[0]]).itemsize for p in vprops)
    face = np.dtype([("n", order + _PLY_TYPES[fprops[0][1]]),
                     ("i", order + _PLY_TYPES[fprops[0][2]], 3)])
    start = body + vsize * n_vertices
    if n_vertices < 0 or n_faces < 0 or len(data) - start != face.itemsize * n_faces:
        return None  # not all triangles, or counts that lie: trimesh decides
    faces = np.frombuffer(data, dtype=face, count=n_faces, offset=start)
    wrong = faces["n"] != 3
    if wrong.any():
        i = int(np.argmax(wrong))
        return f"face {i + 1:,} has a list count of {int(faces['n'][i])}, not 3"
    index = faces["i"]
    outside = ((index < 0) | (index >= n_vertices)).any(axis=1)
    if outside.any():
        i = int(np.argmax(outside))
        return (f"face {i + 1:,} has vertex indices {index[i].tolist()}, outside 0 to "
                f"{n_vertices - 1:,}")
    return None
