"""Rock outlines of a DXF drawing (`polygon_files.read_rock` of a .dxf), in the drawing's x, y.

Read as rock: closed LWPOLYLINE and 2D/3D POLYLINE (arcs drawn by bulges as chords), CIRCLE,
full ELLIPSE and closed SPLINE entities of model space, closed chains of LINE and ARC entities
(an outline drawn, or exploded, stroke by stroke: ends joined within JOIN_TOLERANCE), and the
filled area of HATCH and MPOLYGON entities (rock drawn as a fill: their boundary paths, lines,
arcs, ellipses and splines flattened, filled by the even-odd rule, so that a path inside another
is a hole, whatever the hatch's pattern or style); block references (INSERT, MINSERT) are
expanded, nested at most MAX_INSERT_DEPTH deep, their copies counted before any is made.
Annotations and open strokes (IGNORED, and LINE and ARC that close no chain) are skipped; any
other entity (SOLID, 3DFACE, MESH, REGION, ...) could be rock that rbp cannot read, so the file
is refused naming them: drawn geometry is never dropped without a word.
"""

from __future__ import annotations

import itertools
import logging
import math
import warnings
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from rb_drake.terrain.drawing_bounds import TextLines, arc_chords, dxf_entities
from rb_drake.terrain.drawing_outline import (
    CURVE_TOLERANCE,
    MAX_COORDINATE,
    MAX_DXF_ENTITIES,
    MAX_VERTICES,
    Ring,
    _closed,
    _count_vertices,
    _one_line,
    _polygon,
    _ReadError,
    _scaled,
    even_odd,
    missing_extra,
    polygon_parts,
)

if TYPE_CHECKING:
    from shapely.geometry import Polygon

POLYLINES = ("LWPOLYLINE", "POLYLINE")
CURVES = ("CIRCLE", "ELLIPSE", "SPLINE")  # closed curves, flattened within CURVE_TOLERANCE
FILLS = ("HATCH", "MPOLYGON")  # filled areas: the even-odd region of their boundary paths
IGNORED = frozenset((  # annotations and open strokes: they draw no closed rock
    "TEXT", "MTEXT", "DIMENSION", "ARC_DIMENSION", "LARGE_RADIAL_DIMENSION", "LEADER",
    "MULTILEADER", "MLEADER", "TOLERANCE", "POINT", "ATTRIB", "ATTDEF", "XLINE",
    "RAY", "VIEWPORT", "IMAGE", "ACAD_TABLE", "SHAPE"))
STROKES = ("LINE", "ARC")  # rock where they join end to end into closed chains
JOIN_TOLERANCE = 1e-6  # m: stroke ends this close are one point (a drawing's round-off)
MAX_INSERT_DEPTH = 8  # blocks inside blocks ...: a drawing's are one or two deep
MAX_SPLINE_DEGREE = 10  # ezdxf's evaluation grows with the degree's square; drawings use 2-3


def read_dxf(text: str, factor: float) -> tuple[list[Polygon], bool]:
    """The drawing's rock (module doc), as polygons to union (False: no even-odd rule left)."""
    try:
        import ezdxf
    except ImportError:
        raise missing_extra("ezdxf") from None
    if dxf_entities(text, MAX_DXF_ENTITIES) > MAX_DXF_ENTITIES:
        raise _ReadError(None, f"holds more than {MAX_DXF_ENTITIES:,} entities (each VERTEX of a "
                         "POLYLINE is one); simplify the drawing first")
    log = logging.getLogger("ezdxf")  # which would report what it skips on stderr
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        doc = ezdxf.read(TextLines(text))  # type: ignore[arg-type]  # readline() only
    except Exception as e:  # ezdxf raises DXFError subclasses and, on garbage, others
        raise _ReadError(None, f"not a DXF drawing: {_one_line(e)}") from None
    finally:
        log.setLevel(level)
    msp = doc.modelspace()
    try:
        copies = _entities(doc, msp, 0)
    except RecursionError:
        copies = -1
    if copies < 0:
        raise _ReadError("entities", f"blocks (INSERT) nested more than {MAX_INSERT_DEPTH} deep "
                         "(or a block that inserts itself)")
    if copies > MAX_DXF_ENTITIES:
        raise _ReadError("entities", f"more than {MAX_DXF_ENTITIES:,} once block references "
                         "(INSERT, MINSERT) are expanded; simplify the drawing first")
    polygons: list[Polygon] = []
    fills: list[Polygon] = []  # solid whatever the outlines around them: unioned at the end
    ignored: dict[str, int] = {}
    refused: dict[str, int] = {}
    strokes: list[tuple[str, str, Ring]] = []  # where, kind, points
    total = [0]
    for where, entity in _expanded(msp):
        kind = entity.dxftype()
        if kind in IGNORED:
            ignored[kind] = ignored.get(kind, 0) + 1
        elif kind in POLYLINES or kind in CURVES:
            polygons.append(_outline(entity, where, factor, total))
        elif kind in STROKES:
            strokes.append((where, kind, _stroke(entity, where, factor, total)))
        elif kind in FILLS:
            fills += _filled(entity, where, factor, total)
        else:
            refused[kind] = refused.get(kind, 0) + 1
    chains, loose = _closed_chains(strokes)
    polygons += [_polygon(ring, [], where) for where, ring in chains]
    for kind in loose:
        ignored[kind] = ignored.get(kind, 0) + 1
    if refused:
        found = ", ".join(f"{n} {kind}" for kind, n in sorted(refused.items()))
        raise _ReadError("entities", f"{found} entities not imported: rock is read from closed "
                         "LWPOLYLINE, POLYLINE, CIRCLE, ELLIPSE and SPLINE, closed chains of LINE "
                         "and ARC, HATCH and MPOLYGON (and blocks of them); redraw it as closed "
                         "polylines")
    if not polygons and not fills and ignored:
        found = ", ".join(f"{n} {kind}" for kind, n in sorted(ignored.items()))
        raise _ReadError(None, f"no closed outline (found {found}); rock must be closed "
                         "polylines, circles, ellipses or splines")
    # outlines nest by the even-odd rule; a fill is rock where it lies (a hatch drawn over its
    # own boundary polyline must not cancel it), so the two are unioned (read_rock's union)
    return (polygon_parts(even_odd(polygons)) if polygons else []) + fills, False


def _entities(doc: Any, entities: Any, depth: int) -> int:
    """The entities `entities` expand to, their blocks' copies included, counted past
    MAX_DXF_ENTITIES no further; -1 for blocks nested more than MAX_INSERT_DEPTH deep."""
    n = 0
    for e in entities:
        n += 1
        if e.dxftype() == "INSERT":
            block = doc.blocks.get(e.dxf.name)
            if block is not None and len(block):
                if depth >= MAX_INSERT_DEPTH:
                    return -1
                inner = _entities(doc, block, depth + 1)
                if inner < 0:
                    return -1
                n += max(1, e.dxf.row_count) * max(1, e.dxf.column_count) * inner  # MINSERT
        if n > MAX_DXF_ENTITIES:
            break
    return n


def _expanded(entities: Any, where: str = "") -> Iterator[tuple[str, Any]]:
    """Each entity (with where it is), the entities of the blocks it references in its place
    (their transforms applied by ezdxf). The nesting was bounded by _entities."""
    for k, entity in enumerate(entities, start=1):
        kind = entity.dxftype()
        here = (f"{where}, block entity {k} ({kind})" if where
                else f"entity {k} ({kind}, handle {entity.dxf.handle})")
        if kind != "INSERT":
            yield here, entity
            continue
        skipped: list[str] = []  # what ezdxf cannot transform (a non-uniform scale) it skips

        def skip(e: Any, why: str, skipped: list[str] = skipped) -> None:
            skipped.append(f"{e.dxftype()} ({_one_line(Exception(why))})")

        try:
            copies = list(entity.multi_insert()) if entity.mcount > 1 else [entity]
            parts = [list(c.virtual_entities(skipped_entity_callback=skip)) for c in copies]
        except Exception as e:  # a singular transform, a missing block ezdxf complains of
            raise _ReadError(here, f"block {entity.dxf.name!r} cannot be expanded: "
                             f"{_one_line(e)}") from None
        if skipped:
            raise _ReadError(here, f"block {entity.dxf.name!r}: {len(skipped)} entities cannot "
                             f"be placed, the first {skipped[0]}; explode the block first")
        for part in parts:
            yield from _expanded(part, f"{here} block {entity.dxf.name!r}")


def _outline(entity: Any, where: str, factor: float, total: list[int]) -> Polygon:
    """The closed outline of a polyline or curve entity as a polygon in metres; its chords are
    bounded (counted against MAX_VERTICES) before ezdxf makes them."""
    from ezdxf import path as dxf_path

    kind = entity.dxftype()
    tolerance = CURVE_TOLERANCE / factor
    if kind == "POLYLINE" and (entity.is_poly_face_mesh or entity.is_polygon_mesh):
        raise _ReadError(where, "a mesh, not an outline; rock must be closed 2D polylines")
    if kind in POLYLINES:
        if not entity.is_closed:
            raise _ReadError(where, "open polyline; rock must be closed")
        # arcs (bulges) become short chords: counted first, as a bulge of 1e10 makes billions
        chords = arc_chords(entity, tolerance, MAX_VERTICES)
        if chords is None:
            raise _ReadError(where, "a bulge that is not a finite number")
        _count_vertices(total, [], chords)
    else:
        _check_curve(entity, where, factor)
    try:
        with warnings.catch_warnings():  # ezdxf's overflow warnings: the error says it
            warnings.simplefilter("ignore")
            # a curve's extent is bounded, so its chords are few; stop past the file's limit
            points = list(itertools.islice(dxf_path.make_path(entity).flattening(tolerance),
                                           MAX_VERTICES - total[0] + 1))
    except Exception as e:  # a malformed entity
        raise _ReadError(where, f"cannot be read: {_one_line(e)}") from None
    ring = _scaled(((p.x, p.y) for p in points), factor)
    _count_vertices(total, ring)
    if kind in CURVES and len(ring) > 2 and not _closed(ring, CURVE_TOLERANCE):
        raise _ReadError(where, "open curve (an arc of it); rock must be closed")
    return _polygon(ring, [], where)


def _filled(entity: Any, where: str, factor: float, total: list[int]) -> list[Polygon]:
    """A HATCH's or MPOLYGON's filled area, in metres: its boundary paths flattened within
    CURVE_TOLERANCE (counted against MAX_VERTICES as they are made), filled by the even-odd
    rule (a path inside another is a hole)."""
    from ezdxf import path as dxf_path

    for k, boundary in enumerate(entity.paths, start=1):
        for edge in getattr(boundary, "edges", ()):  # an edge path's splines and arcs
            degree = getattr(edge, "degree", 1)
            if not 1 <= degree <= MAX_SPLINE_DEGREE:
                raise _ReadError(f"{where} boundary path {k}", f"a spline edge of degree "
                                 f"{degree}: rbp reads splines of degree 1 to "
                                 f"{MAX_SPLINE_DEGREE}")
            radius = getattr(edge, "radius", 0.0)
            centre = getattr(edge, "center", (0.0, 0.0))
            if not all(abs(float(v)) * factor + abs(float(radius)) * factor <= MAX_COORDINATE
                       for v in tuple(centre)[:2]):  # NaN fails too
                raise _ReadError(f"{where} boundary path {k}", f"a coordinate beyond "
                                 f"{MAX_COORDINATE:g} m; check --unit and --scale")
    loops = []
    try:
        with warnings.catch_warnings():  # ezdxf's overflow warnings: the error says it
            warnings.simplefilter("ignore")
            paths = list(dxf_path.from_hatch(entity))
            for k, path in enumerate(paths, start=1):
                points = list(itertools.islice(path.flattening(CURVE_TOLERANCE / factor),
                                               MAX_VERTICES - total[0] + 1))
                ring = _scaled(((p.x, p.y) for p in points), factor)
                _count_vertices(total, ring)
                if _closed(ring, 1e-12):
                    ring = ring[:-1]
                loops.append(_polygon(ring, [], f"{where} boundary path {k}"))
    except _ReadError:
        raise
    except Exception as e:  # a malformed boundary path
        raise _ReadError(where, f"cannot be read: {_one_line(e)}") from None
    if not loops:
        raise _ReadError(where, "a fill with no boundary path; rock must enclose an area")
    parts = polygon_parts(even_odd(loops))
    if not parts:
        raise _ReadError(where, "its boundary paths enclose no area")
    return parts


def _stroke(entity: Any, where: str, factor: float, total: list[int]) -> Ring:
    """A LINE's two ends, or an ARC's chords within CURVE_TOLERANCE, in metres."""
    if entity.dxftype() == "LINE":
        points = [entity.dxf.start, entity.dxf.end]
    else:
        reach = [abs(v) + abs(entity.dxf.radius) for v in entity.dxf.center]
        if not all(r * factor <= MAX_COORDINATE for r in reach):  # NaN fails too
            raise _ReadError(where, f"a coordinate beyond {MAX_COORDINATE:g} m; check --unit "
                             "and --scale")
        from ezdxf import path as dxf_path

        try:
            points = list(itertools.islice(
                dxf_path.make_path(entity).flattening(CURVE_TOLERANCE / factor),
                MAX_VERTICES - total[0] + 1))
        except Exception as e:  # a malformed entity
            raise _ReadError(where, f"cannot be read: {_one_line(e)}") from None
    line = _scaled(((p.x, p.y) for p in points), factor)
    if not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE for p in line for v in p):
        raise _ReadError(where, f"a coordinate beyond {MAX_COORDINATE:g} m (or not a number); "
                         "check --unit and --scale")
    _count_vertices(total, line)
    return line


def _closed_chains(strokes: list[tuple[str, str, Ring]]
                   ) -> tuple[list[tuple[str, Ring]], list[str]]:
    """The closed outlines that strokes (LINE, ARC) join into, end to end (ends within
    JOIN_TOLERANCE are one point; a chain closes where every point joins exactly two strokes),
    each named by its first stroke; and the kinds of the strokes left over (open or branching
    chains, which draw no closed rock)."""
    def point(p: tuple[float, float]) -> tuple[int, int]:
        return round(p[0] / JOIN_TOLERANCE), round(p[1] / JOIN_TOLERANCE)

    at: dict[tuple[int, int], list[int]] = {}
    ends = []
    for k, (_, _, line) in enumerate(strokes):
        a, b = point(line[0]), point(line[-1])
        ends.append((a, b))
        for p in (a, b):
            at.setdefault(p, []).append(k)
    used = [False] * len(strokes)  # in a closed chain: rock
    # walked once: a walk that does not close met a joint of other than two strokes, so none
    # of the strokes it passed closes either (each stroke is walked once: linear in strokes)
    walked = [False] * len(strokes)
    chains: list[tuple[str, Ring]] = []
    for first in range(len(strokes)):
        if walked[first] or ends[first][0] == ends[first][1]:
            continue
        ring, order, k, joint = list(strokes[first][2]), [first], first, ends[first][1]
        walked[first] = True
        while joint != ends[first][0]:
            nxt = [j for j in at[joint] if j != k]
            if len(at[joint]) != 2 or not nxt or walked[nxt[0]]:
                break  # an open end, a branch, or a stroke walked before
            k = nxt[0]
            walked[k] = True
            line = strokes[k][2] if ends[k][0] == joint else strokes[k][2][::-1]
            joint = ends[k][1] if ends[k][0] == joint else ends[k][0]
            ring += line[1:]
            order.append(k)
        if joint == ends[first][0] and len(at[joint]) == 2:
            for k in order:
                used[k] = True
            where = strokes[first][0]
            chains.append((f"{where} and {len(order) - 1} strokes joined to it", ring[:-1]))
    loose = [strokes[k][1] for k in range(len(strokes)) if not used[k]]
    return chains, loose


def _check_curve(entity: Any, where: str, factor: float) -> None:
    """Refuse a curve reaching beyond MAX_COORDINATE (its chords would be unbounded) or a
    spline ezdxf would take long to evaluate."""
    kind = entity.dxftype()
    if kind == "CIRCLE":
        reach = [abs(v) + abs(entity.dxf.radius) for v in entity.dxf.center]
    elif kind == "ELLIPSE":
        reach = [abs(v) + entity.dxf.major_axis.magnitude for v in entity.dxf.center]
    else:
        degree = entity.dxf.degree
        if not 1 <= degree <= MAX_SPLINE_DEGREE:
            raise _ReadError(where, f"degree {degree}: rbp reads splines of degree 1 to "
                             f"{MAX_SPLINE_DEGREE}")
        if entity.control_point_count() < 2:
            raise _ReadError(where, "a spline by fit points only; draw it by control points "
                             "or as a polyline")
        reach = [abs(v) for p in entity.control_points for v in p]
    if not all(r * factor <= MAX_COORDINATE for r in reach):  # NaN fails too
        raise _ReadError(where, f"a coordinate beyond {MAX_COORDINATE:g} m; check --unit and "
                         "--scale")
