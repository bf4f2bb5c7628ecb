"""What a drawing will expand to, bounded before it is expanded (`polygon_files` refuses it).

ezdxf flattens a DXF arc into chords and svgelements copies every `<use>` target before rbp
sees a vertex: a bulge of 1e10 makes billions of chords and six levels of ten `<use>` a million
elements, taking gigabytes and minutes before the outline vertex limit could refuse them.
Only the standard library is imported.
"""

from __future__ import annotations

import itertools
import math
import re
from typing import Any

MAX_USE_DEPTH = 8  # <use> of a <use> ...: a drawing's clones are one or two deep
XLINK = "http://www.w3.org/1999/xlink"


def arc_chords(entity: Any, tolerance: float, limit: int) -> int | None:
    """About how many chords flattening the DXF polyline's arcs (bulges) within `tolerance`
    (drawing units) makes, at most `limit` + 1 (past the limit, counting stops); None if a
    bulge is not a finite number."""
    if entity.dxftype() == "LWPOLYLINE":
        vertices = [(x, y, b) for x, y, b in entity.get_points("xyb")]
    else:
        vertices = [(*v.dxf.location.vec2, v.dxf.bulge) for v in entity.vertices]
    chords = 0
    for (x1, y1, bulge), (x2, y2, _) in zip(vertices, vertices[1:] + vertices[:1], strict=True):
        if not math.isfinite(bulge):
            return None
        chord = math.hypot(x2 - x1, y2 - y1)
        if chord * abs(bulge) / 2 <= tolerance:  # the arc's sagitta: straight enough
            continue
        angle = 4 * math.atan(abs(bulge))  # bulge = tan(angle / 4)
        radius = chord / (2 * math.sin(angle / 2))
        step = 4 * math.asin(min(1.0, math.sqrt(tolerance / (2 * radius))))  # sagitta = tol
        chords += math.ceil(angle / step) if step > 0 else limit + 1
        if chords > limit:
            return limit + 1
    return chords


def use_copies(text: str, limit: int) -> str | None:
    """Why the SVG `text` cannot be expanded (its <use> copies, of copies..., nested more than
    MAX_USE_DEPTH deep, in a loop, or making more than `limit` elements), or None."""
    if "use" not in text:
        return None
    from xml.etree import ElementTree

    try:
        root = ElementTree.fromstring(text)
    except (ElementTree.ParseError, ValueError):
        return None  # svgelements says what is wrong with it
    ids = {e.get("id"): e for e in root.iter() if e.get("id") is not None}
    sizes: dict[int, int] = {}  # elements under an element, its copies expanded

    def size(element: Any, depth: int) -> int:
        if id(element) not in sizes:
            if depth > MAX_USE_DEPTH:
                raise ValueError(f"<use> nested more than {MAX_USE_DEPTH} deep (or in a loop)")
            n = 1 + sum(size(child, depth) for child in element)
            if element.tag.rsplit("}", 1)[-1] == "use":
                # as svgelements resolves it: `href` over `xlink:href`, and any first
                # character dropped, so that `href="xa"` copies `#a` too
                href = element.get("href", element.get(f"{{{XLINK}}}href"))
                target = ids.get(href[1:]) if href is not None else None
                n += size(target, depth + 1) if target is not None else 0
            sizes[id(element)] = n
        return sizes[id(element)]

    try:
        elements = size(root, 0)
    except ValueError as e:
        return str(e)
    except RecursionError:
        return None  # svgelements refuses the nesting itself
    if elements > limit:
        return (f"{elements:,} elements once <use> copies are expanded: more than {limit:,}; "
                "simplify the drawing first")
    return None


MAX_SVG_DEPTH = 100  # elements inside elements: a drawing's groups are a few levels deep, and
#                      svgelements recurses per level (50,000 levels overflow Python's stack)
_TAG = re.compile(r"""<(?:[^<>"']|"[^"]*"|'[^']*')*>""")  # a quoted value may hold '>'
_PATH = re.compile(r"<(?:[\w.-]+:)?path[\s/>]")
_D = re.compile(r"""\sd\s*=\s*["']""")


def without_comments(text: str) -> str:
    """`text` without its `<!-- ... -->` comments (one pass of str.find, at C speed)."""
    parts: list[str] = []
    start = 0
    while (opening := text.find("<!--", start)) >= 0:
        parts.append(text[start:opening])
        closing = text.find("-->", opening + 4)
        start = len(text) if closing < 0 else closing + 3
    return "".join(parts) + text[start:] if parts else text


def svg_markup(text: str, limit: int) -> str | None:
    """Why the SVG `text` is too big to hand to svgelements, which builds a Python object per
    element and recurses per level of nesting (more than `limit` tags, nested more than
    MAX_SVG_DEPTH levels, or a <path> it cannot read), or None. Tags are counted at C speed
    before any is walked."""
    text = without_comments(text)  # a commented-out drawing draws nothing
    tags = text.count("<") - text.count("</")  # start tags, <?...?> and <!...>
    if tags > limit:
        return (f"holds up to {tags:,} elements, more than {limit:,}; simplify the drawing "
                "first")
    depth = 0
    for tag in _TAG.finditer(text):  # at most 2 * `limit` + 1 before the depth goes below 0
        if tag[0][1] == "/":
            depth -= 1
            if depth < 0:
                return None  # svgelements says what is wrong with it
        elif tag[0][1] not in "!?" and not tag[0].endswith("/>"):
            depth += 1
            if depth > MAX_SVG_DEPTH:
                return f"elements nested more than {MAX_SVG_DEPTH} levels deep"
        if _PATH.match(tag[0]) and not _D.search(tag[0]):  # svgelements: "NoneType has no len()"
            return "a <path> without a d attribute (its outline); give it one or delete it"
    return None


# a DXF group code 0 (its line "0") starts an entity, whose type follows: letters, where a
# value "0" is followed by the next group code, digits
_DXF_ENTITY = re.compile(r"^[ \t]*0[ \t]*\r?\n[ \t]*[A-Za-z_]", re.MULTILINE)


def dxf_entities(text: str, limit: int) -> int:
    """The DXF entities (and table records, section markers) of `text`, counted up to
    `limit` + 1: ezdxf builds an object of ~25 µs for each (60,000 TEXT took 2.4 s)."""
    if text.count("0\n") <= limit:  # an upper bound at C speed
        return 0
    return sum(1 for _ in itertools.islice(_DXF_ENTITY.finditer(text), limit + 1))


class TextLines:
    """`text` as a stream for ezdxf, which needs only readline(): io.StringIO would hold a copy
    of 4 bytes a character (120 MB for a 30 MB file)."""

    def __init__(self, text: str):
        self.text = text
        self.at = 0

    def readline(self) -> str:
        end = self.text.find("\n", self.at) + 1 or len(self.text)
        line, self.at = self.text[self.at:end], end
        return line
