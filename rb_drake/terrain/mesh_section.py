"""The rock of a cave's cross-section, from a 3D scan: a mesh (STL, OBJ, PLY) or a point cloud
(a PLY of vertices without faces).

A scan of a cave is a scan of its hollow: the surface separates the free space (inside, where
the scanner stood) from the rock (outside). A plane cuts it into the outline of the free space;
the rock is everything else within a frame, the free space's bounding box grown by MARGIN. The
planner wants rock as simple polygons (no holes), as a scenario's `walls` are, so the frame
minus the free space is cut by vertical lines through each hole into hole-free pieces: a
vertical shaft gives a left and a right wall, each with half of the floor and the ceiling.

The section's 2D frame (docs/formats.md, "Meshes and point clouds"): the unit normal n points
toward the viewer; 2D +y is world +z (up) projected onto the plane, or world +y if the plane is
horizontal; 2D +x = y × n, so (x, y, n) is right-handed; the 2D origin is the plane's origin.
The default plane is vertical with n = world +x through the centre of the scan's bounding box,
so the 2D point (x, y) is the world point origin + (0, x, y).

Meshes: the section must be closed curves (a watertight cave, or a scan whose open ends and
holes were capped where the plane cuts); the free space is inside them, counted even-odd (a
pillar's outline inside the cave's is rock again).

Point clouds: the points are taken to sample the cave's walls (as a scanner inside sees them).
Those within `resolution` of the plane are projected onto it and their outline is a concave
hull: the Delaunay triangulation of the projected points, eroded from the outside by removing
border triangles whose border edge is longer than 2 × resolution while the outline stays a
simple polygon (the χ-shape of Duckham et al., 2008, with a length in metres instead of
shapely.concave_hull's ratio). The free space is the inside of that hull: one connected region
without pillars, bounded by walls sampled more densely than 2 × resolution (a wider gap lets
the erosion leak into the cave).
"""

from __future__ import annotations

import heapq
import io
import math
import re
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rb_drake.errors import RbpInputError
from rb_drake.input_files import InputFileError, check_input_file, max_scan_bytes, read_bytes
from rb_drake.terrain.scan_bytes import EMPTY, FAR, MAX_SCAN_COORDINATE, ScanBytesError, check_scan

if TYPE_CHECKING:
    from shapely.geometry import Polygon
    from shapely.geometry.base import BaseGeometry

MESH_SUFFIXES = (".stl", ".obj", ".ply")
DEFAULT_NORMAL = (1.0, 0.0, 0.0)  # a vertical plane; 2D (x, y) = world (y, z) from the origin
MARGIN = 0.5  # m, rock kept around the free space's bounding box
HULL_EDGE = 2.0  # a cloud's outline bridges gaps up to HULL_EDGE × resolution
# A dense cloud is thinned to one point per square of THIN × resolution before its hull is
# built (which moves the outline by at most a square's diagonal, 0.35 × resolution), so that
# the work grows with the section's size in units of resolution, not with the scan's density.
THIN_ABOVE = 20_000  # points near the plane
THIN = 0.25
MAX_HULL_POINTS = 500_000  # after thinning: a larger section needs a larger resolution
# A cloud's resolution when none is given: SPACINGS / sqrt(points per m² of wall). Points
# within r of the plane fall on a wall's trace at 2 r rho per metre, so a gap wider than the
# hull's 2 r (where the erosion leaks into the cave) has probability exp(-4 r² rho) =
# exp(-4 SPACINGS²) = 1e-7 each: none in the ~1,000 gaps of a 13 m outline. The import's old
# fixed 5 cm gave exp(-4.6) = 1 % on the example cloud (480 points/m²): the hull ate a third
# of the cave.
SPACINGS = 2.0
DENSITY_NEIGHBOURS = 6  # the rho estimate: the distance to a point's 6th nearest neighbour
DENSITY_SAMPLES = 20_000  # points whose neighbours are counted, at most
DENSITY_SUBSET = 200_000  # a larger cloud's density is its random subset's, scaled
# A mesh's section, bounded before trimesh assembles it (its curve assembly takes time
# quadratic in the number of separate pieces: 75,000 pieces of a mesh of random triangles took
# 81 s, a million would take hours): at most MAX_SECTION_SEGMENTS facets cut by the plane
# (as a drawing's vertices, polygon_files.MAX_VERTICES) in at most MAX_SECTION_PIECES separate
# curves (a cave's outline and its pillars: a few; 2,000 pieces take a fraction of a second).
MAX_SECTION_SEGMENTS = 50_000
MAX_METRES = 1e4  # once --unit and --scale are applied, as a drawing's (polygon_files)
MAX_SECTION_PIECES = 2_000
# Vertices of a PLY scan, from its header before it is loaded: trimesh took 5 s and 500 MB to
# load a 31 MB cloud of 2.6 million points that was then refused as too dense; a million
# points load and are thinned in about 2.5 s (the example cloud holds 12,000).
MAX_SCAN_VERTICES = 1_000_000
# Triangles likewise, counted in the file before trimesh builds its arrays (about 200 bytes a
# face: an OBJ of 3.9 million faces on one vertex took 2.7 s and 809 MB). An STL's vertices are
# 3 a triangle until trimesh merges them, so an STL holds at most a third of a million.
MAX_SCAN_FACES = 1_000_000
_PLY_ELEMENT = re.compile(rb"^[ \t]*element[ \t]+(\S+)[ \t]+(\S+)", re.MULTILINE)


def _error(path: Path, field: str, reason: str) -> RbpInputError:
    return RbpInputError(reason, file=str(path), field=field)


def _vec(values: Any, path: Path, what: str) -> np.ndarray:
    try:
        v = np.asarray(values, dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise _error(path, "plane", f"the {what} must be 3 numbers, got {values!r}") from None
    if not np.all(np.isfinite(v)):
        raise _error(path, "plane", f"the {what} must be finite, got {tuple(v.tolist())}")
    return v


def plane_frame(normal: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The section's axes (x2, y2, n) in world coordinates for a non-zero `normal`: n its unit
    vector, y2 world +z projected onto the plane (world +y for a horizontal plane), x2 = y2 × n."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    for up in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])):
        y = up - float(up @ n) * n
        if np.linalg.norm(y) > 1e-6:
            break
    y2 = y / np.linalg.norm(y)
    return np.cross(y2, n), y2, n


def load_scan(path: Path, metres_per_unit: float | None = None) -> tuple[str, Any]:
    """("mesh", trimesh.Trimesh) or ("cloud", (N, 3) array) read from `path`; a refusal is one
    RbpInputError naming the file ("mesh" field) and the reason. With `metres_per_unit` (the
    import's --unit times --scale), coordinates are also refused beyond MAX_METRES once scaled,
    before any geometry is made of them (as a drawing's)."""
    path = Path(path)
    try:
        # a missing file or a directory, before its name's suffix
        check_input_file(path, max_scan_bytes())
    except InputFileError as e:
        raise _error(path, e.field, e.reason) from None
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise _error(path, "mesh", f"unknown format {suffix or '(no suffix)'!r}: expected one of "
                     f"{', '.join(MESH_SUFFIXES)} (a mesh, or a PLY point cloud)")
    data = _read_bytes(path)
    _check_scan_counts(path, data, suffix)
    try:
        read = check_scan(data, suffix)  # an ASCII PLY is read there, in C
    except ScanBytesError as e:
        raise _error(path, "mesh", str(e)) from None
    try:
        import trimesh
    except ImportError:
        raise _error(path, "mesh", "reading meshes needs the optional package trimesh "
                     "(pip install trimesh)") from None
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            # overflows while trimesh merges vertices of 1e308 or NaN: refused below instead
            warnings.simplefilter("ignore")
            loaded = (_load_mesh(trimesh, data, suffix) if read is None
                      else trimesh.PointCloud(read[0]) if read[1] is None
                      else trimesh.Trimesh(vertices=read[0], faces=read[1]))
    except _UnreadableError as e:
        raise _error(path, "mesh", f"not a readable {suffix[1:].upper()} file: {e}") from None
    del data  # the file's bytes, before the geometry's arrays
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    if vertices.ndim != 2 or len(vertices) == 0:
        raise _error(path, "mesh", EMPTY)
    if vertices.shape[1] != 3:  # an OBJ's `v x y` (found in check_scan unless \r ends lines)
        raise _error(path, "mesh", f"has vertices of {vertices.shape[1]} coordinates, not 3")
    if not np.all(np.isfinite(vertices)):
        raise _error(path, "mesh", "has vertices with non-finite coordinates (nan or inf)")
    if np.abs(vertices).max() > MAX_SCAN_COORDINATE:
        raise _error(path, "mesh", FAR)
    if metres_per_unit is not None and np.abs(vertices).max() * metres_per_unit > MAX_METRES:
        raise _error(path, "mesh", f"a coordinate beyond {MAX_METRES:g} m once scaled; check "
                     "--unit and --scale")
    if isinstance(loaded, trimesh.Trimesh) and len(faces) > 0:
        return "mesh", loaded
    return "cloud", vertices


def _check_scan_counts(path: Path, data: bytes, suffix: str) -> None:
    """Refuse a scan of more than MAX_SCAN_VERTICES vertices or MAX_SCAN_FACES faces, counted
    in the file before trimesh loads it (what cannot be counted is left to trimesh to refuse)."""
    vertices, faces = _scan_counts(data, suffix)
    what = "its header states" if suffix == ".ply" else "it holds"
    if vertices > MAX_SCAN_VERTICES:
        merged = " (3 a triangle, before merging)" if suffix == ".stl" else ""
        raise _error(path, "mesh", f"{what} {vertices:,} vertices{merged}, over the limit of "
                     f"{MAX_SCAN_VERTICES:,}: thin or crop the scan to the cave's section first")
    if faces > MAX_SCAN_FACES:
        raise _error(path, "mesh", f"{what} {faces:,} faces, over the limit of "
                     f"{MAX_SCAN_FACES:,}: simplify or crop the scan to the cave's section first")


def _scan_counts(data: bytes, suffix: str) -> tuple[int, int]:
    """(vertices, faces) as trimesh's reader for `suffix` will find them in `data`."""
    if suffix == ".stl":
        stated = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
        # binary if the sizes agree (trimesh's test), else ASCII: every `vertex`, any case
        binary = len(data) - 84 == 50 * stated
        triangles = stated if binary else data.lower().count(b"vertex") // 3
        return 3 * triangles, triangles
    if suffix == ".obj":  # trimesh's vertices follow "\nv ", its faces start lines with "f"
        return (data.startswith(b"v ") + data.count(b"\nv ") + data.count(b"\rv "),
                data.startswith(b"f") + data.count(b"\nf") + data.count(b"\rf"))
    # PLY: every element line of the header (its count may carry a sign: int() takes "+2")
    end = data.find(b"end_header", 0, 65536)
    if not data.startswith(b"ply") or end < 0:
        return 0, 0  # not a PLY header: trimesh says what is wrong with it
    vertices = faces = 0
    for name, count in _PLY_ELEMENT.findall(data, 0, end):
        try:
            n = int(count)
        except ValueError:
            continue  # trimesh refuses the header
        if name == b"vertex":
            vertices = max(vertices, n)
        else:  # faces, or an element trimesh reads alongside them (edges, strips)
            faces = max(faces, n)
    return vertices, faces


class _UnreadableError(Exception):
    """A mesh file trimesh could not read; the message says why."""


def _load_mesh(trimesh: Any, data: bytes, suffix: str) -> Any:
    try:
        # from memory, without a resolver: the files an OBJ names (materials, textures) are
        # not opened, so a hostile `mtllib /dev/zero` cannot hang the reader
        loaded: Any = trimesh.load(io.BytesIO(data), file_type=suffix[1:], resolver=None)
        if isinstance(loaded, trimesh.Scene):
            loaded = loaded.to_geometry() if loaded.geometry else None
    except Exception as e:  # trimesh's readers raise whatever their parsers raise
        # an ImportError is trimesh trying an optional decoder on bytes that are not a mesh
        detail = ("" if isinstance(e, ImportError) else " ".join(str(e).split())[:200]
                  ) or "its content does not parse"
        raise _UnreadableError(detail) from None
    return loaded


def _read_bytes(path: Path) -> bytes:
    """The bytes of a regular file within the input size limit (rb_drake.input_files)."""
    try:
        return read_bytes(path, max_scan_bytes())
    except InputFileError as e:
        raise _error(path, e.field, e.reason) from None


def cloud_resolution(points: np.ndarray) -> float:
    """The resolution (in the cloud's unit) at which a point cloud's section does not leak:
    SPACINGS / sqrt(rho), rho the points per unit² of surface, estimated from the median
    distance d to the DENSITY_NEIGHBOURS-th nearest neighbour (a uniform sampling puts
    k - 1/3 points in the disc of radius d, the median of Gamma(k, 1)). A scan sampled
    unevenly is estimated by its typical point: give a resolution for its sparse parts."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    share = 1.0  # of the cloud's points kept: a random subset of a sampling is one, sparser
    if len(pts) > DENSITY_SUBSET:
        share = DENSITY_SUBSET / len(pts)
        pts = pts[np.random.default_rng(0).choice(len(pts), DENSITY_SUBSET, replace=False)]
    pts = np.unique(pts, axis=0)
    k = DENSITY_NEIGHBOURS
    if len(pts) <= k:
        return math.inf  # no density to speak of: refused later as too few points
    queries = pts[:: max(1, len(pts) // DENSITY_SAMPLES)]
    distance, _ = cKDTree(pts).query(queries, k=k + 1)  # the first is the point itself
    d = float(np.median(distance[:, k]))
    if not d > 0.0:
        return math.inf
    rho = (k - 1.0 / 3.0) / (math.pi * d * d) / share
    return SPACINGS / math.sqrt(rho)


def section_polygons(path: Path, origin: tuple[float, float, float] | None,
                     normal: tuple[float, float, float] | None, resolution: float | None,
                     tolerance: float, metres_per_unit: float | None = None) -> list[Polygon]:
    """The rock of the cave scanned in `path` (STL, OBJ or PLY mesh, or PLY point cloud) cut by
    the plane through `origin` (default: the scan's bounding-box centre) with `normal`
    (default: world +x, a vertical plane), as valid, non-empty, counter-clockwise shapely
    Polygons without holes in the section's 2D frame (metres; 2D +y is world +z projected onto
    the plane, 2D +x = 2D +y × normal, origin at `origin`; the module's docstring says more).

    `resolution` (m) matters for point clouds only: points within it of the plane are used, and
    their outline bridges gaps up to 2 × resolution; None takes it from the cloud's density
    (`cloud_resolution`: about 4 times its typical point spacing, 9 cm on the example cloud).
    `tolerance` (m) simplifies the outline (shapely's simplify, topology preserved);
    `metres_per_unit`: see load_scan. Bad input raises one RbpInputError naming the file, the
    field ("plane", "mesh", "resolution", "tolerance") and the reason.
    """
    path = Path(path)
    for name, value in (("resolution", resolution), ("tolerance", tolerance)):
        if name == "resolution" and value is None:
            continue  # a cloud's from its density
        if not (isinstance(value, int | float) and not isinstance(value, bool)
                and math.isfinite(value) and value > 0):
            raise _error(path, name, f"must be a positive number of metres, got {value!r}")
    n_raw = _vec(DEFAULT_NORMAL if normal is None else normal, path, "normal")
    if np.linalg.norm(n_raw) < 1e-12:
        raise _error(path, "plane", f"the normal {tuple(n_raw.tolist())} is zero: give the "
                     "direction across the plane")
    kind, scan = load_scan(path, metres_per_unit)
    vertices = np.asarray(scan.vertices if kind == "mesh" else scan, dtype=float)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    o = (lo + hi) / 2.0 if origin is None else _vec(origin, path, "origin")
    x2, y2, n = plane_frame(n_raw)
    where = (f"the plane at origin {_fmt(o)} with normal {_fmt(n_raw)} does not cut the "
             f"{'mesh' if kind == 'mesh' else 'point cloud'} (its bounds are {_fmt(lo)} to "
             f"{_fmt(hi)})")
    side = (vertices - o) @ n
    if kind == "mesh":
        if side.min() >= 0.0 or side.max() <= 0.0:
            raise _error(path, "plane", where)
        free = _mesh_free_space(path, scan, o, x2, y2, n, where)
    else:
        if resolution is None:
            resolution = cloud_resolution(vertices)
            if not math.isfinite(resolution):
                distinct = len(np.unique(vertices, axis=0))  # 4 million copies of one point
                raise _error(path, "resolution", f"{len(vertices):,} point(s), {distinct:,} "
                             "distinct, are too few to tell the cloud's density: give a "
                             "resolution")
        near = np.abs(side) <= resolution
        if not near.any():
            raise _error(path, "plane", f"{where}: no point within {resolution:g} m of it")
        pts = np.stack([(vertices[near] - o) @ x2, (vertices[near] - o) @ y2], axis=1)
        if len(pts) > THIN_ABOVE:
            pts = _thin(pts, THIN * resolution)
        if len(pts) > MAX_HULL_POINTS:
            raise _error(path, "resolution", f"{len(pts):,} points near the plane even thinned "
                         f"to one per {THIN * resolution:g} m square (at most "
                         f"{MAX_HULL_POINTS:,}): a larger resolution takes fewer")
        free = _cloud_free_space(path, pts, HULL_EDGE * resolution)
    return rock_polygons(free, tolerance)


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{float(x):.3g}" for x in v) + ")"


def _mesh_free_space(path: Path, mesh: Any, o: np.ndarray, x2: np.ndarray, y2: np.ndarray,
                     n: np.ndarray, misses: str) -> BaseGeometry:
    """The inside of the section's closed curves, even-odd; `misses` is the reason given
    when there is no section (the plane passes between parts of the mesh, or grazes it)."""
    from shapely import make_valid
    from shapely.geometry import Polygon

    _check_section_size(path, mesh, o, n)
    section = mesh.section(plane_origin=o, plane_normal=n)
    if section is None:
        raise _error(path, "plane", misses)
    open_curves = len(section.dangling)
    if open_curves:
        raise _error(path, "mesh", f"the section has {open_curves} open curve piece(s): the mesh "
                     "has holes or open ends where the plane cuts it, so the free space has no "
                     "closed outline (cap the scan's open ends, e.g. trimesh's fill_holes)")
    free = None
    for loop in section.discrete:
        q = np.stack([(loop - o) @ x2, (loop - o) @ y2], axis=1)
        if len(q) < 4:
            continue
        poly = make_valid(Polygon(q))
        free = poly if free is None else free.symmetric_difference(poly)
    if free is None or free.is_empty or free.area <= 0.0:
        raise _error(path, "mesh", "the section has no closed outline with an inside: the plane "
                     "only grazes the mesh")
    return free


def _check_section_size(path: Path, mesh: Any, o: np.ndarray, n: np.ndarray) -> None:
    """Refuse a section of more than MAX_SECTION_SEGMENTS segments or MAX_SECTION_PIECES
    separate curves, counted on trimesh's segments (vectorised) before it assembles them."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from trimesh.intersections import mesh_plane

    cut = np.sum(np.ptp(np.sign((mesh.vertices - o) @ n)[mesh.faces], axis=1) > 0)
    if cut > MAX_SECTION_SEGMENTS:
        raise _error(path, "mesh", f"the plane cuts {cut:,} facets, over the limit of "
                     f"{MAX_SECTION_SEGMENTS:,} outline segments: decimate the mesh (a cave's "
                     "outline needs a few thousand)")
    segments = np.asarray(mesh_plane(mesh, n, o)).reshape(-1, 3)
    if len(segments) == 0:
        return
    scale = max(float(np.ptp(segments, axis=0).max()), 1e-12)
    # endpoints shared by neighbouring facets agree to rounding: merged on a 1e-9 grid of the
    # section's size (an end split by the grid only adds a piece: the bound stays safe)
    _, ends = np.unique(np.round(segments / scale * 1e9), axis=0, return_inverse=True)
    ends = ends.reshape(-1, 2)
    graph = coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])),
                       shape=(ends.max() + 1,) * 2)
    pieces, _ = connected_components(graph, directed=False)
    if pieces > MAX_SECTION_PIECES:
        raise _error(path, "mesh", f"the section falls into {pieces:,} separate pieces, over "
                     f"the limit of {MAX_SECTION_PIECES:,}: is this a cave's surface? (a "
                     "mesh of loose facets, or a plane through debris)")


def _thin(pts: np.ndarray, cell: float) -> np.ndarray:
    """One point of `pts` per square of side `cell` (the first in the input's order)."""
    keys = np.floor((pts - pts.min(axis=0)) / cell).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return pts[np.sort(first)]


def _cloud_free_space(path: Path, pts: np.ndarray, max_edge: float) -> BaseGeometry:
    """The χ-shape of `pts`: their Delaunay triangles, border triangles with a border edge
    longer than `max_edge` eroded while the outline stays simple."""
    import shapely
    from scipy.spatial import Delaunay, QhullError

    pts = np.unique(pts, axis=0)
    too_few = _error(path, "mesh", f"the {len(pts)} point(s) near the plane do not outline a "
                     "closed region (too few, or all on one line): a larger resolution takes "
                     "more, or the plane misses the cave's walls")
    if len(pts) < 3:
        raise too_few
    try:
        tri = Delaunay(pts)
    except QhullError:
        raise too_few from None
    simplices, neighbors = tri.simplices, tri.neighbors
    alive = np.ones(len(simplices), dtype=bool)

    def edge_length(t: int, j: int) -> float:  # the edge of triangle t opposite its vertex j
        a, b = (simplices[t][k] for k in range(3) if k != j)
        return float(np.hypot(*(pts[a] - pts[b])))

    on_border = np.zeros(len(pts), dtype=bool)
    heap: list[tuple[float, int, int]] = []
    for t, j in zip(*np.nonzero(neighbors < 0), strict=True):
        on_border[[simplices[t][k] for k in range(3) if k != j]] = True
        if (length := edge_length(t, j)) > max_edge:
            heapq.heappush(heap, (-length, int(t), int(j)))
    while heap:
        _, t, j = heapq.heappop(heap)
        if not alive[t] or on_border[simplices[t][j]]:
            continue  # gone already, or removing it would pinch the outline into two
        alive[t] = False
        on_border[simplices[t][j]] = True
        for k in range(3):
            u = neighbors[t][k]
            if k == j or u < 0 or not alive[u]:
                continue
            ju = int(np.nonzero(neighbors[u] == t)[0][0])  # the edge u shares with t
            if (length := edge_length(u, ju)) > max_edge:
                heapq.heappush(heap, (-length, int(u), ju))
    if not alive.any():
        raise too_few
    triangles = shapely.polygons(pts[simplices[alive]])
    free = shapely.make_valid(shapely.union_all(triangles))
    if free.is_empty or free.area <= 0.0:
        raise too_few
    return free


def _polygons(geometry: BaseGeometry) -> list[Polygon]:
    """The polygons with an area in a shapely geometry of any kind."""
    from shapely.geometry import Polygon

    if isinstance(geometry, Polygon):
        return [geometry] if geometry.area > 0.0 else []
    return [p for g in getattr(geometry, "geoms", []) for p in _polygons(g)]


def rock_polygons(free: BaseGeometry, tolerance: float,
                  margin: float = MARGIN) -> list[Polygon]:
    """The rock around the free space `free` (simplified to `tolerance`), within its bounding
    box grown by `margin`, as valid counter-clockwise polygons without holes (each hole cut by
    a vertical line through it), ordered by their lowest x then y."""
    import shapely
    from shapely.geometry import LineString, MultiLineString, box
    from shapely.geometry.polygon import orient
    from shapely.ops import split

    free = shapely.make_valid(free.simplify(tolerance, preserve_topology=True))
    minx, miny, maxx, maxy = free.bounds
    frame = box(minx - margin, miny - margin, maxx + margin, maxy + margin)
    pieces = _polygons(shapely.make_valid(frame.difference(free)))
    done: list[Polygon] = []
    for _ in range(100):  # each round cuts every hole; a second round is for safety only
        holed = [p for p in pieces if p.interiors]
        done += [p for p in pieces if not p.interiors]
        if not holed:
            break
        pieces = []
        for p in holed:
            lines = [LineString([(x, frame.bounds[1] - 1.0), (x, frame.bounds[3] + 1.0)])
                     for x in (_cut_x(shapely.Polygon(h)) for h in p.interiors)]
            pieces += _polygons(split(p, MultiLineString(lines)))
    return sorted((orient(p, 1.0) for p in done if p.is_valid and p.area > 1e-12),
                  key=lambda p: (p.bounds[0], p.bounds[1]))


def _cut_x(hole: Polygon) -> float:
    """The x of a vertical line across `hole`: through its centroid when that line crosses it
    (a shaft is cut down its middle), else through a point inside it."""
    from shapely.geometry import LineString

    x = hole.centroid.x
    lo, hi = hole.bounds[1] - 1.0, hole.bounds[3] + 1.0
    if hole.intersection(LineString([(x, lo), (x, hi)])).length > 0.0:
        return float(x)
    return float(hole.representative_point().x)
