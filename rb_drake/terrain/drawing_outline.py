"""What the drawing readers (`polygon_files`, `dxf_rock`) share: limits, the reader's error, and
rings made into polygons in metres."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

from rb_drake.errors import RbpInputError

if TYPE_CHECKING:
    from shapely.geometry import Polygon

MAX_COORDINATE = 1e4  # m, as rb_drake.scenario.MAX_COORDINATE: farther is a wrong unit or scale
CURVE_TOLERANCE = 0.005  # m: arcs and Bézier curves become polylines this close to them
MAX_VERTICES = 50_000  # outline vertices in one file: a cave section needs a few thousand
#                       (the scenario written, 3 YAML values a vertex, is checked against
#                       the reader's limit on values: import_cave._check_readable)

MAX_DXF_ENTITIES = 25_000  # ezdxf takes ~25 µs an entity; more than 16,600 outline vertices
#                            make a scenario too big to read back, unless simplified

INSTALL_HINT = "pip install 'rbp[import]'"

Ring = list[tuple[float, float]]


def missing_extra(module: str) -> RbpInputError:
    """The error for an optional dependency of `rbp scenario import` that is not installed."""
    return RbpInputError(f"importing caves needs {module}, of the optional extra 'import': "
                         f"{INSTALL_HINT}")



class _ReadError(Exception):
    """A reader's complaint: where in the file (`where`, or None for the file) and why."""

    def __init__(self, where: str | None, reason: str):
        super().__init__(reason)
        self.where = where
        self.reason = reason


def _polygon(shell: Ring, holes: Sequence[Ring], where: str) -> Polygon:
    """A valid polygon from rings already in metres, or a _ReadError saying why not."""
    from shapely.geometry import Polygon

    for ring in (shell, *holes):
        if len({(round(x, 9), round(y, 9)) for x, y in ring}) < 3:
            raise _ReadError(where, "fewer than 3 distinct points; rock must enclose an area")
        if not all(abs(v) <= MAX_COORDINATE for p in ring for v in p):  # NaN fails too
            raise _ReadError(where, f"a coordinate beyond {MAX_COORDINATE:g} m; check --unit "
                           "and --scale")
    poly = Polygon(shell, holes)
    if not poly.is_valid:
        raise _ReadError(where, f"not a simple outline: {validity_reason(poly)}")
    if poly.area <= 0:
        raise _ReadError(where, "encloses no area")
    return poly


def validity_reason(poly: Polygon) -> str:
    """Why shapely finds `poly` invalid: "Self-intersection[1 1]" as "self-intersection at
    (1, 1) m"."""
    from shapely.validation import explain_validity

    validity = explain_validity(poly)
    match = re.fullmatch(r"(.*?)\[(\S+) (\S+)\]", validity.strip())
    if match is None:
        return validity.lower()
    what, x, y = match.groups()
    return f"{what.lower()} at ({float(x):g}, {float(y):g}) m"



def _scaled(points: Iterator[Sequence[float]], factor: float, flip_y: bool = False) -> Ring:
    sign = -1.0 if flip_y else 1.0
    return [(float(p[0]) * factor, sign * float(p[1]) * factor) for p in points]


def _closed(ring: Ring, tolerance: float) -> bool:
    return len(ring) >= 2 and math.dist(ring[0], ring[-1]) <= tolerance


def _count_vertices(total: list[int], ring: Ring, coming: int = 0) -> None:
    """Adds the ring's vertices to the file's total; refuses a total (with `coming` vertices
    still to be made) past MAX_VERTICES."""
    total[0] += len(ring)
    if total[0] + coming > MAX_VERTICES:
        raise _ReadError(None, f"more than {MAX_VERTICES} outline vertices; simplify the "
                       "drawing first")



def _one_line(error: Exception) -> str:
    """A parser's message on one line (ezdxf quotes the offending line, newline and all)."""
    return " ".join(str(error).split())[:200]


def polygon_parts(geometry: Any) -> list[Polygon]:
    """The non-empty polygons of a shapely geometry, largest first (a stable order)."""
    from shapely.geometry import Polygon

    if isinstance(geometry, Polygon):
        found = [geometry]
    else:
        found = [g for g in getattr(geometry, "geoms", ()) if isinstance(g, Polygon)]
    found = [g for g in found if not g.is_empty and g.area > 0]
    return sorted(found, key=lambda g: (-g.area, g.bounds))


def even_odd(polygons: Sequence[Polygon]) -> Any:
    """The region the polygons fill by the even-odd rule (an outline inside another is a hole),
    as one shapely geometry: their symmetric difference, taken pairwise in a balanced tree
    (associative, so the same region; one outline at a time was quadratic: 3,000 small outlines
    took 27 s, now 0.02 s)."""
    import shapely

    layer = list(polygons)
    while len(layer) > 1:
        layer = [shapely.symmetric_difference(layer[i], layer[i + 1]) if i + 1 < len(layer)
                 else layer[i] for i in range(0, len(layer), 2)]
    return layer[0]

