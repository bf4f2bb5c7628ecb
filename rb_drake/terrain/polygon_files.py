"""Rock outlines from polygon files: GeoJSON, DXF and SVG, read into shapely Polygons in metres.

GeoJSON says what is rock: each Polygon (with its holes) or closed LineString is rock, and
rocks that overlap are one rock. DXF and SVG draw outlines only, so their closed outlines nest by
the even-odd rule: an outline inside another is a hole (free space, a tunnel's section), an
island inside that is rock again. SVG's y axis points down; it is flipped so that up is +y.

Anything that is not closed rock is refused with one `RbpInputError` naming the file, the
element and what is wrong: an open polyline, a self-intersecting outline, an empty file, a file
of another format.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rb_drake.errors import RbpInputError
from rb_drake.input_files import InputFileError, load_json, max_scan_bytes, read_text
from rb_drake.terrain.drawing_bounds import svg_markup, use_copies
from rb_drake.terrain.drawing_outline import (
    CURVE_TOLERANCE,
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
    validity_reason,
)
from rb_drake.terrain.drawing_outline import (
    MAX_COORDINATE as MAX_COORDINATE,
)
from rb_drake.terrain.drawing_outline import (
    MAX_DXF_ENTITIES as MAX_DXF_ENTITIES,
)
from rb_drake.terrain.dxf_rock import read_dxf

if TYPE_CHECKING:
    from shapely.geometry import Polygon

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}  # metres per unit
POLYGON_SUFFIXES = (".geojson", ".json", ".dxf", ".svg")
MESH_SUFFIXES = (".stl", ".obj", ".ply")  # sectioned by rb_drake.terrain.mesh_section
MAX_SVG_ELEMENTS = 5_000  # svgelements and the outline take ~100 µs a <rect> (measured)
MAX_NUMBERS = 8 * MAX_VERTICES  # digit runs in a drawing: a vertex's two numbers need 2-4,
#                                 a DXF's header a few thousand


def read_rock(path: str | Path, unit: str | None = None, scale: float = 1.0,
              simplify: float = 0.0) -> list[Polygon]:
    """The rock of a GeoJSON (.geojson, .json), DXF (.dxf) or SVG (.svg) file as valid shapely
    Polygons in metres: file coordinates times UNITS[unit] times `scale`, then simplified to
    `simplify` m (shapely's `simplify`, topology kept; 0: as drawn). `unit` None: the unit a
    DXF declares (`declared_unit`), else metres. Raises RbpInputError naming the file for
    anything that is not closed, simple rock."""
    path = Path(path)
    name = str(path)
    if unit is not None and unit not in UNITS:
        raise RbpInputError(f"must be one of {sorted(UNITS)}, got {unit!r}", field="--unit")
    if not (math.isfinite(scale) and scale > 0):
        raise RbpInputError(f"must be a positive number, got {scale:g}", field="--scale")
    if not (math.isfinite(simplify) and simplify >= 0):
        raise RbpInputError(f"must be 0 or more metres, got {simplify:g}", field="--simplify")
    suffix = path.suffix.lower()
    readers: dict[str, Callable[[str, float], tuple[list[Polygon], bool]]] = {
        ".geojson": _geojson, ".json": _geojson, ".dxf": read_dxf, ".svg": _svg}
    if suffix not in readers:
        known = ", ".join(POLYGON_SUFFIXES + MESH_SUFFIXES)
        raise RbpInputError(f"unknown suffix {suffix or '(none)'!r}; rock is read from {known}",
                            file=name)
    try:
        import shapely  # noqa: F401  (the readers need it; say so once, here)
    except ImportError:
        raise missing_extra("shapely") from None
    try:
        text = read_text(path, max_scan_bytes())
    except InputFileError as e:
        raise RbpInputError(e.reason, file=name, field=e.field) from None
    if not text.strip():
        raise RbpInputError("empty file; no rock to read", file=name)
    if (numbers := _number_bound(text)) > MAX_NUMBERS:
        raise RbpInputError(f"holds up to {numbers:,} numbers, more than a drawing of "
                            f"{MAX_VERTICES:,} outline vertices needs (at most "
                            f"{MAX_NUMBERS:,}); simplify the drawing first", file=name)
    if unit is None and suffix == ".dxf" and (other := unread_unit(text)) is not None:
        raise RbpInputError(f"the drawing declares its unit as {other}, which rbp does not "
                            f"convert: give --unit ({', '.join(sorted(UNITS))}) for its "
                            "coordinates", file=name, field="$INSUNITS")
    if unit is None:
        unit = declared_unit_of(path, text) or "m"
    factor = UNITS[unit] * scale
    try:
        polygons, nested = readers[suffix](text, factor)
    except _ReadError as e:
        raise RbpInputError(e.reason, file=name, field=e.where) from None
    if not polygons:
        raise RbpInputError("no rock: the file holds no closed outline", file=name)
    rock = _combine(polygons, nested)
    return _finish(rock, name, simplify)


_DIGITS = bytes(48 if chr(b).isdigit() else 32 for b in range(256))  # digit -> "0", else " "


# A DXF's $INSUNITS codes for the units rbp reads (AutoCAD's table; 0 is "unitless")
INSUNITS = {1: "in", 2: "ft", 4: "mm", 5: "cm", 6: "m"}
_INSUNITS = re.compile(r"^\s*\$INSUNITS\s*\r?\n\s*70\s*\r?\n\s*(-?\d+)\s*$", re.MULTILINE)


# the other codes of that table: a drawing that declares one was read as metres, silently (a
# drawing in decimetres, a cave ten times too large)
OTHER_INSUNITS = {3: "miles", 7: "kilometres", 8: "microinches", 9: "mils", 10: "yards",
                  11: "angstroms", 12: "nanometres", 13: "microns", 14: "decimetres",
                  15: "decametres", 16: "hectometres", 17: "gigametres",
                  18: "astronomical units", 19: "light years", 20: "parsecs",
                  21: "US survey feet", 22: "US survey inches", 23: "US survey yards",
                  24: "US survey miles"}


def unread_unit(text: str) -> str | None:
    """The unit a DXF drawing declares in $INSUNITS when rbp does not read it (a code of
    another unit, or no unit's code), as words; None when it declares none, unitless or one
    rbp reads."""
    match = _INSUNITS.search(text[:200_000])
    if match is None:
        return None
    code = int(match.group(1))
    if code == 0 or code in INSUNITS:
        return None
    return f"{OTHER_INSUNITS[code]} (code {code})" if code in OTHER_INSUNITS else \
        f"code {code}, no unit's"


def declared_unit(text: str) -> str | None:
    """The unit a DXF drawing declares in its header ($INSUNITS), if rbp reads it (None:
    none, unitless, or one rbp has no name for)."""
    head = text[:200_000]  # the header comes first
    match = _INSUNITS.search(head)
    return INSUNITS.get(int(match.group(1))) if match else None


def declared_unit_of(path: str | Path, text: str | None = None) -> str | None:
    """The unit a DXF file declares (`declared_unit`), from `text` or else its first 200,000
    characters; None for other files, and for anything not a regular readable file (its reader
    says why). The one rule `read_rock` and the command line's note both follow."""
    path = Path(path)
    if path.suffix.lower() != ".dxf":
        return None
    if text is not None:
        return declared_unit(text)
    try:
        if not path.is_file():
            return None
        with open(path, encoding="utf-8", errors="replace") as f:
            return declared_unit(f.read(200_000))
    except OSError:
        return None


def _number_bound(text: str) -> int:
    """An upper bound on the numbers in a drawing: its runs of digits (a number has one or
    more), counted at C speed before any parser builds a value, so that a file of millions of
    coordinates is refused in a fraction of a second instead of parsed for minutes."""
    runs = text.encode("utf-8", "replace").translate(_DIGITS)
    return runs.count(b" 0") + runs.startswith(b"0")


def _combine(polygons: list[Polygon], nested: bool) -> list[Polygon]:
    """Overlapping rock merged (GeoJSON), or outlines nested by the even-odd rule (DXF, SVG)."""
    from shapely import union_all

    if not nested:
        return polygon_parts(union_all(polygons))
    return polygon_parts(even_odd(polygons))  # shapely's symmetric_difference_all is deprecated


def _finish(rock: list[Polygon], name: str, simplify: float) -> list[Polygon]:
    """The rock simplified to `simplify` m, refused if that leaves nothing or breaks it."""
    if simplify > 0:
        rock = [p for poly in rock for p in polygon_parts(poly.simplify(simplify,
                                                                 preserve_topology=True))]
        if not rock:
            raise RbpInputError(f"nothing is left after simplifying to {simplify:g} m; give a "
                                "smaller --simplify", file=name)
    for k, poly in enumerate(rock):
        if not poly.is_valid:  # as simplify can leave it
            raise RbpInputError(f"rock {k} is not simple after simplifying to {simplify:g} m: "
                                f"{validity_reason(poly)}; give a smaller --simplify",
                                file=name)
    return rock


# ---------------------------------------------------------------------------------------------
# GeoJSON (RFC 7946): coordinates as written, x then y (a third, z, is ignored)


def _geojson(text: str, factor: float) -> tuple[list[Polygon], bool]:
    try:
        data = load_json(text)
    except json.JSONDecodeError as e:
        raise _ReadError(f"line {e.lineno}, column {e.colno}", f"not JSON: {e.msg}") from None
    except RecursionError:
        raise _ReadError(None, "nested too deeply to be GeoJSON") from None
    except InputFileError as e:
        raise _ReadError(e.field, e.reason) from None
    _refuse_geographic(data)
    polygons: list[Polygon] = []
    total = [0]
    for where, geometry in _geometries(data, "(top level)"):
        polygons += _geojson_geometry(geometry, where, factor, total)
    return polygons, False


# CRS names of longitude and latitude in degrees (GIS exports name them in the old `crs` member)
_GEOGRAPHIC = re.compile(r"(EPSG:+4326|EPSG:+4269|EPSG:+4258|CRS:*84|CRS:*83|WGS ?84)$",
                         re.IGNORECASE)


def _refuse_geographic(data: Any) -> None:
    """A file that names a longitude-latitude CRS holds degrees, not the metres of a cave's
    section: read as metres, a cave became a few hundredths of a millimetre across, or a
    degree a metre. Other CRS names are the user's to scale (--unit, --scale)."""
    crs = data.get("crs") if isinstance(data, dict) else None
    props = crs.get("properties") if isinstance(crs, dict) else None
    name = props.get("name") if isinstance(props, dict) else None
    if isinstance(name, str) and _GEOGRAPHIC.search(name.strip()):
        raise _ReadError("crs", f"{name[:80]!r} is longitude and latitude in degrees; rbp reads "
                         "a cave's section in metres (or --unit): project it to a local "
                         "metric plane first")


def _geometries(data: Any, where: str, depth: int = 0) -> Iterator[tuple[str, Any]]:
    """(where, geometry object) for each geometry of a GeoJSON object."""
    if not isinstance(data, dict):
        raise _ReadError(where, f"expected a GeoJSON object, got {type(data).__name__}")
    kind = data.get("type")
    if kind == "FeatureCollection":
        features = data.get("features")
        if not isinstance(features, list):
            raise _ReadError(where, "a FeatureCollection needs a list 'features'")
        for k, feature in enumerate(features):
            yield from _geometries(feature, f"features[{k}]", depth + 1)
    elif kind == "Feature":
        if data.get("geometry") is not None:  # a feature without geometry holds no rock
            yield from _geometries(data["geometry"], f"{_prefix(where)}geometry", depth + 1)
    elif kind == "GeometryCollection" and depth < 8:
        members = data.get("geometries")
        if not isinstance(members, list):
            raise _ReadError(where, "a GeometryCollection needs a list 'geometries'")
        for k, member in enumerate(members):
            yield from _geometries(member, f"{_prefix(where)}geometries[{k}]", depth + 1)
    elif kind in ("Polygon", "MultiPolygon", "LineString", "MultiLineString"):
        yield where, data
    elif kind in ("Point", "MultiPoint"):
        raise _ReadError(where, f"a {kind} has no area; rock must be a Polygon or a closed "
                       "LineString")
    else:
        raise _ReadError(where, f"unknown GeoJSON type {kind!r}; expected a Feature, "
                       "FeatureCollection, Polygon, MultiPolygon or closed LineString")


def _prefix(where: str) -> str:
    return "" if where == "(top level)" else f"{where}."


def _geojson_geometry(geometry: dict, where: str, factor: float,
                      total: list[int]) -> list[Polygon]:
    kind = geometry["type"]
    coords = geometry.get("coordinates")
    field = f"{_prefix(where)}coordinates"
    if kind == "Polygon":
        rings = _rings(coords, field, factor, total)
        return [_polygon(rings[0], rings[1:], field)]
    if kind == "MultiPolygon":
        parts = _list(coords, field)
        out = []
        for k, part in enumerate(parts):
            rings = _rings(part, f"{field}[{k}]", factor, total)
            out.append(_polygon(rings[0], rings[1:], f"{field}[{k}]"))
        return out
    lines = [coords] if kind == "LineString" else _list(coords, field)
    out = []
    for k, line in enumerate(lines):
        at = field if kind == "LineString" else f"{field}[{k}]"
        ring = _ring(line, at, factor, total)
        if not _closed(ring, 1e-9):
            raise _ReadError(at, f"open {kind} (its last point is not its first); rock must be "
                           "closed")
        out.append(_polygon(ring, [], at))
    return out


def _list(value: Any, field: str) -> list:
    if not isinstance(value, list) or not value:
        raise _ReadError(field, f"expected a non-empty list, got {_describe(value)}")
    return value


def _rings(value: Any, field: str, factor: float, total: list[int]) -> list[Ring]:
    rings = [_ring(r, f"{field}[{k}]", factor, total) for k, r in enumerate(_list(value, field))]
    for k, ring in enumerate(rings):
        if not _closed(ring, 1e-9):
            raise _ReadError(f"{field}[{k}]", "open ring (its last point is not its first); rock "
                           "must be closed")
    return rings


def _ring(value: Any, field: str, factor: float, total: list[int]) -> Ring:
    points = _list(value, field)
    ring = []
    for k, p in enumerate(points):
        if (not isinstance(p, list) or len(p) < 2
                or not all(_finite(v) for v in p[:2])):
            raise _ReadError(f"{field}[{k}]", f"expected a position [x, y], got {_describe(p)}")
        ring.append(p)
    scaled = _scaled(iter(ring), factor)
    _count_vertices(total, scaled)
    return scaled


def _finite(value: Any) -> bool:
    """Whether `value` is a number (not a bool) that is a finite float (10**400 is not)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _describe(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text[:57] + '...' if len(text) > 60 else text}"


# ---------------------------------------------------------------------------------------------
# SVG: the closed (sub)paths of every shape, in the user units of the viewBox, y flipped


def _svg(text: str, factor: float) -> tuple[list[Polygon], bool]:
    try:
        import svgelements as se
    except ImportError:
        raise missing_extra("svgelements") from None
    for why in (svg_markup(text, MAX_SVG_ELEMENTS), use_copies(text, MAX_VERTICES)):
        if why is not None:
            raise _ReadError(None, why)
    with warnings.catch_warnings():  # svgelements warns on stderr of what it skips
        warnings.simplefilter("ignore")
        try:
            try:
                svg = se.SVG.parse(_Whole(text))
            except ZeroDivisionError:  # svgelements squares an arc's radii: 1e-300 gives 0
                raise _ReadError("path d", "an arc (A) whose radii are too small to compute "
                                 "(their squares are 0): give radii of 0 (a straight line, as "
                                 "SVG draws it) or of at least 1e-150") from None
            if not isinstance(svg, se.SVG):
                raise _ReadError(None, "not an SVG drawing: no <svg> element")
            # svgelements maps the viewBox to pixels; undo it, so that --unit names user units
            try:
                transform = svg.viewbox_transform
            except ZeroDivisionError:  # SVG: a zero width or height disables rendering
                raise _ReadError("viewBox", "a zero width or height: nothing is drawn (SVG "
                                 "disables the rendering): give a positive size") from None
            viewport = se.Matrix(transform) if transform else se.Matrix()
            to_user = ~viewport
            shapes = [e for e in svg.elements() if isinstance(e, se.Shape)]
        except _ReadError:
            raise
        except Exception as e:  # xml.etree's ParseError, a singular viewBox, svgelements' own
            raise _ReadError(None, f"not an SVG drawing: {_one_line(e)}") from None
        polygons: list[Polygon] = []
        total = [0]
        for k, element in enumerate(shapes):
            label = type(element).__name__.lower()
            ident = f" id {element.id!r}" if element.id else ""
            try:
                path = se.Path(element) * to_user
                path.reify()
                subpaths = [_svg_ring(se, se.Path(sub), factor, total)
                            for sub in path.as_subpaths()]
            except _ReadError:
                raise
            except Exception as e:  # a degenerate transform or arc svgelements cannot follow
                raise _ReadError(f"shape {k} ({label}{ident})",
                                 f"cannot be read: {_one_line(e)}") from None
            for j, (ring, closed) in enumerate(subpaths):
                where = f"shape {k} ({label}{ident}), subpath {j}"
                if len(ring) < 2:
                    continue  # a lone moveto draws nothing
                if not closed:
                    raise _ReadError(where, "open path; rock must be closed (end it with Z)")
                _count_vertices(total, ring)
                polygons.append(_polygon(ring, [], where))
    return polygons, True


class _Whole:
    """The text as a file read in one piece: xml.etree's iterparse reads 16 kB at a time, and
    expat scans a token that a read leaves unfinished (a 30 MB comment or attribute) again on
    each read. (io.StringIO would also hold a copy of 4 bytes a character.)"""

    def __init__(self, text: str):
        self.text: str | None = text

    def read(self, size: int = -1) -> str:
        text, self.text = self.text or "", None
        return text


def _svg_ring(se: Any, sub: Any, factor: float, total: list[int]) -> tuple[Ring, bool]:
    """The subpath's points in metres (up = +y) and whether it closes; the points a curve will
    add are counted against the file's MAX_VERTICES before it is sampled."""
    points: list[Any] = []
    closed = False
    for seg in sub.segments():
        if isinstance(seg, se.Move):
            points = [seg.end]
        elif isinstance(seg, se.Close):
            closed = True
        elif isinstance(seg, se.Line):
            points.append(seg.end)
        else:  # a curve: enough chords to stay within CURVE_TOLERANCE of it
            length = seg.length(error=1e-4) * factor
            n = max(2, min(1000, math.ceil(math.sqrt(length / CURVE_TOLERANCE)) * 2))
            _count_vertices(total, [], len(points) + n)
            points += list(seg.npoint([t / n for t in range(1, n + 1)]))  # all in one call
    ring = _scaled(((p[0], p[1]) for p in points), factor, flip_y=True)
    closed = closed or _closed(ring, 1e-9)
    return ring, closed
