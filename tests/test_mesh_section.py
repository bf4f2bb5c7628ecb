"""The rock of a cave's cross-section from a mesh or a point cloud (rb_drake/terrain/), checked
against the design of the bundled lava tube (rb_drake/terrain/examples.py): its width and axis
at a few heights, mesh and cloud agreeing, a rotated plane's chord, and the refusals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="the optional extra 'import' (trimesh) is missing")
shapely = pytest.importorskip("shapely", reason="the optional extra 'import' (shapely) is missing")

from shapely.geometry import LineString, Polygon  # noqa: E402

from rb_drake.errors import RbpInputError  # noqa: E402
from rb_drake.terrain.examples import (  # noqa: E402
    CLOUD_FILE,
    MESH_FILE,
    SEED,
    TubeDesign,
    example_bytes,
    lava_tube_cloud,
    lava_tube_mesh,
)
from rb_drake.terrain.mesh_section import MARGIN, section_polygons  # noqa: E402

DESIGN = TubeDesign()
RESOLUTION = 0.1  # m: the cloud's slab half-width; its outline bridges gaps up to 0.2 m
TOLERANCE = 0.02  # m: simplification
HEIGHTS = (1.0, 2.5, 4.0)  # m, world z: away from the floor (0) and the ceiling (5)
# The walls are within noise + jitter of the design on each side; simplification moves each
# by at most TOLERANCE; the mesh's facets and the cloud's sampling add a centimetre or two.
WALL_SLACK = DESIGN.noise + DESIGN.jitter + TOLERANCE + 0.02
FILES = {"mesh": MESH_FILE, "cloud": CLOUD_FILE}


def free_interval(rock: list[Polygon], y: float) -> tuple[float, float]:
    """(width, centre) of the free space along the horizontal line at height y of the
    section, which must be one interval between the rock."""
    solid = shapely.union_all(rock)
    minx, _, maxx, _ = solid.bounds
    free = LineString([(minx, y), (maxx, y)]).difference(solid)
    assert isinstance(free, LineString) and free.length > 0, \
        f"the free space at y = {y} is not one interval: {free.wkt[:200]}"
    xs = np.asarray(free.coords)[:, 0]
    return float(xs.max() - xs.min()), float(xs.mean())


def free_region(rock: list[Polygon]) -> Polygon:
    """The free space: the one hole of the rock's union (the rock surrounds the tube)."""
    holes = list(shapely.union_all(rock).interiors)
    assert len(holes) == 1, f"expected the rock to surround one free region, got {len(holes)}"
    return Polygon(holes[0])


def check_polygons(rock: list[Polygon]) -> None:
    assert rock, "no rock polygons"
    for k, p in enumerate(rock):
        assert p.is_valid and p.area > 0, f"rock[{k}] is invalid or empty: {p.wkt[:200]}"
        assert not p.interiors, f"rock[{k}] has holes: walls are simple polygons"
        assert p.exterior.is_ccw, f"rock[{k}] is clockwise: walls are counter-clockwise"


@pytest.mark.parametrize("kind", FILES)
def test_section_has_the_designed_width_and_axis(kind: str) -> None:
    # Plane x = 0 (the tube's axis), normal +x: the section's (x, y) is world (y, z).
    rock = section_polygons(FILES[kind], (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), RESOLUTION, TOLERANCE)
    check_polygons(rock)
    assert len(rock) == 2, f"a shaft cut down its middle gives a left and a right wall: {rock}"
    for z in HEIGHTS:
        width, centre = free_interval(rock, z)
        assert abs(width - DESIGN.width_at(z)) <= 2 * WALL_SLACK, \
            f"{kind}: width {width:.3f} m at z = {z}, designed {DESIGN.width_at(z):.3f} m"
        # 2D +x is world +y here: the free space follows the axis's sway along world y
        assert abs(centre - DESIGN.axis_y(z)) <= WALL_SLACK, \
            f"{kind}: free space centred at {centre:.3f} at z = {z}, axis at {DESIGN.axis_y(z):.3f}"
    # the floor and the ceiling: free from z = 0 to the height, rock MARGIN beyond
    free = free_region(rock)
    assert abs(free.bounds[1] - 0.0) <= WALL_SLACK and \
        abs(free.bounds[3] - DESIGN.height) <= WALL_SLACK, f"{kind}: free space {free.bounds}"
    frame = shapely.union_all(rock).bounds
    assert math.isclose(frame[1], free.bounds[1] - MARGIN, abs_tol=1e-9), (frame, free.bounds)


def test_default_plane_is_normal_plus_x_through_the_bounds_centre() -> None:
    mesh = trimesh.load(MESH_FILE)
    centre = tuple(float(c) for c in mesh.bounds.mean(axis=0))
    default = section_polygons(MESH_FILE, None, None, RESOLUTION, TOLERANCE)
    explicit = section_polygons(MESH_FILE, centre, (1.0, 0.0, 0.0), RESOLUTION, TOLERANCE)
    assert [p.wkt for p in default] == [p.wkt for p in explicit]
    # the 2D origin is the plane's origin: the floor is at 2D y = -centre z
    assert abs(free_region(default).bounds[1] + centre[2]) <= 0.02, free_region(default).bounds


def test_mesh_and_cloud_agree() -> None:
    regions = {kind: free_region(section_polygons(path, None, None, RESOLUTION, TOLERANCE))
               for kind, path in FILES.items()}
    a, b = regions["mesh"], regions["cloud"]
    # the cloud's outline runs along the outer edge of the points near the plane: within a
    # few centimetres of the mesh's along ~13 m of outline, i.e. a few per cent of ~8 m²
    ratio = a.symmetric_difference(b).area / a.area
    assert ratio <= 0.04, f"mesh and cloud sections differ by {ratio:.1%} of the free area"


def ellipse_chord(z: float, angle: float, design: TubeDesign = DESIGN) -> float:
    """The designed tube's chord at height z along the world line through (0, 0, z) in the
    horizontal direction (-sin angle, cos angle): the section by the plane of normal
    (cos angle, sin angle, 0) through the origin."""
    s, c = math.sin(angle), math.cos(angle)
    A, B, yc = design.depth_at(z) / 2, design.width_at(z) / 2, design.axis_y(z)
    qa, qb, qc = s * s / A**2 + c * c / B**2, -2 * c * yc / B**2, yc * yc / B**2 - 1
    return math.sqrt(qb * qb - 4 * qa * qc) / qa


def slab_extent(z: float, angle: float, r: float, design: TubeDesign = DESIGN) -> float:
    """How far apart, along the plane's horizontal direction, the designed tube's wall points
    at height z within r of that plane project: the widest a cloud's outline can be."""
    s, c = math.sin(angle), math.cos(angle)
    theta = np.linspace(0.0, 2 * math.pi, 200_001)
    x = design.depth_at(z) / 2 * np.cos(theta)
    y = design.axis_y(z) + design.width_at(z) / 2 * np.sin(theta)
    near = np.abs(c * x + s * y) <= r
    along = -s * x[near] + c * y[near]
    return float(along.max() - along.min())


@pytest.fixture(scope="module")
def smooth_tube(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bundled tube's design without noise, as a mesh and a cloud: its section must follow
    the design to within the simplification and the facets, not the noise."""
    design = TubeDesign(noise=0.0, jitter=0.0)
    folder = tmp_path_factory.mktemp("smooth")
    mesh = lava_tube_mesh(SEED, design)
    files = {"mesh": folder / "tube.ply", "cloud": folder / "tube_cloud.ply"}
    files["mesh"].write_bytes(mesh.export(file_type="ply"))
    cloud = trimesh.PointCloud(lava_tube_cloud(mesh, SEED, design.cloud_points))
    files["cloud"].write_bytes(cloud.export(file_type="ply"))
    return files


# Without noise: simplification moves a wall by at most TOLERANCE, the 48-sided rings by at
# most 2 mm (their sagitta), so each wall is within SMOOTH_SLACK of the design.
SMOOTH_SLACK = TOLERANCE + 0.005


@pytest.mark.parametrize("kind", FILES)
@pytest.mark.parametrize("degrees", [0.0, 50.0])
def test_section_of_the_smooth_tube_follows_the_design(smooth_tube: dict[str, Path], kind: str,
                                                       degrees: float) -> None:
    design = TubeDesign(noise=0.0, jitter=0.0)
    angle = math.radians(degrees)
    normal = (math.cos(angle), math.sin(angle), 0.0)
    rock = section_polygons(smooth_tube[kind], (0.0, 0.0, 0.0), normal, RESOLUTION, TOLERANCE)
    check_polygons(rock)
    for z in HEIGHTS:
        width, _ = free_interval(rock, z)
        chord = ellipse_chord(z, angle, design)
        # a mesh's section is the chord; a cloud's outline runs along the outer edge of the
        # points within RESOLUTION of the plane, so it may be wider where the wall is oblique
        widest = chord if kind == "mesh" else slab_extent(z, angle, RESOLUTION, design)
        assert chord - 2 * SMOOTH_SLACK <= width <= widest + 2 * SMOOTH_SLACK, \
            (f"{kind} at {degrees}°: width {width:.3f} m at z = {z}, designed chord "
             f"{chord:.3f} m (a cloud's at most {widest:.3f} m)")
    # the rotated plane's chord is far from the width: the test can tell them apart
    assert ellipse_chord(2.5, math.radians(50.0), design) < design.width_at(2.5) - 0.3


def test_examples_are_deterministic_and_shipped() -> None:
    first, again = example_bytes(SEED), example_bytes(SEED)
    assert first == again, "the same seed must give the same files"
    assert example_bytes(SEED + 1)[0] != first[0], "another seed must give another tube"
    # the shipped files hold the generator's arrays (compared as arrays, not bytes: another
    # trimesh may write another PLY header; to a micrometre: another CPU's sine may differ in
    # its last bit)
    mesh = lava_tube_mesh(SEED)
    shipped = trimesh.load(MESH_FILE, process=False)
    stale = "is stale: python -m rb_drake.terrain.examples"
    assert np.array_equal(shipped.faces, mesh.faces), f"{MESH_FILE} {stale}"
    assert np.allclose(shipped.vertices, mesh.vertices, atol=1e-6), f"{MESH_FILE} {stale}"
    cloud = trimesh.load(CLOUD_FILE).vertices
    assert np.allclose(cloud, lava_tube_cloud(mesh, SEED, DESIGN.cloud_points), atol=1e-6), \
        f"{CLOUD_FILE} {stale}"
    for path in FILES.values():
        assert path.stat().st_size < 300_000, f"{path} is {path.stat().st_size} bytes"
    assert mesh.is_watertight and mesh.volume > 0, "the example must be a closed tube"


def refusal(path: Path, **overrides) -> str:
    args = {"origin": None, "normal": None, "resolution": RESOLUTION, "tolerance": TOLERANCE}
    args.update(overrides)
    with pytest.raises(RbpInputError) as info:
        section_polygons(path, **args)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path)), message
    return message


@pytest.mark.parametrize("kind", FILES)
def test_plane_that_misses(kind: str) -> None:
    message = refusal(FILES[kind], origin=(5.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0))
    assert ": plane: " in message and "does not cut" in message and "bounds" in message, message


def test_bad_plane_and_numbers() -> None:
    assert "is zero" in refusal(MESH_FILE, normal=(0.0, 0.0, 0.0))
    assert ": resolution: " in refusal(CLOUD_FILE, resolution=0.0)
    assert ": tolerance: " in refusal(MESH_FILE, tolerance=-1.0)
    assert ": tolerance: " in refusal(MESH_FILE, tolerance=float("nan"))
    assert ": resolution: " in refusal(MESH_FILE, resolution=True)  # a flag, not metres


def test_garbage_empty_and_unknown_files(tmp_path: Path) -> None:
    garbage = tmp_path / "cave.ply"
    garbage.write_bytes(b"\x00\x13garbage, not a PLY\xff" * 10)
    assert ": mesh: not a readable PLY file" in refusal(garbage)
    empty = tmp_path / "cave.stl"
    empty.write_bytes(b"")
    assert ": mesh: holds no triangles or points" in refusal(empty)
    other = tmp_path / "cave.xyz"
    other.write_text("1 2 3\n")
    assert ": mesh: unknown format '.xyz'" in refusal(other)
    assert ": (file): no such file" in refusal(tmp_path / "missing.obj")
    # headers that promise billions of elements in a few bytes: refused, not allocated
    lying_stl = tmp_path / "lying.stl"
    lying_stl.write_bytes(b"\0" * 80 + (4_000_000_000).to_bytes(4, "little") + b"\0" * 100)
    assert ": mesh: holds no triangles or points" in refusal(lying_stl)
    lying_ply = tmp_path / "lying.ply"
    lying_ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
                          b"property float x\nproperty float y\nproperty float z\nend_header\n"
                          + bytes(36))
    assert ": mesh: its header states 1,000,000,000,000 vertices" in refusal(lying_ply)
    assert "is a directory" in refusal(tmp_path)


def test_open_mesh_has_no_closed_outline(tmp_path: Path) -> None:
    tube = trimesh.creation.cylinder(radius=0.8, height=5.0, sections=24)
    sides = np.abs(tube.face_normals[:, 2]) < 0.5  # drop the caps: an open scan of a shaft
    tube.update_faces(sides)
    path = tmp_path / "open.stl"
    path.write_bytes(tube.export(file_type="stl"))
    message = refusal(path)
    assert ": mesh: " in message and "open curve" in message, message


def test_obj_and_stl_read_as_the_ply(tmp_path: Path) -> None:
    mesh = trimesh.load(MESH_FILE)
    expected = free_region(section_polygons(MESH_FILE, None, None, RESOLUTION, TOLERANCE))
    for suffix in ("stl", "obj"):
        path = tmp_path / f"tube.{suffix}"
        path.write_bytes(mesh.export(file_type=suffix).encode() if suffix == "obj"
                         else mesh.export(file_type=suffix))
        got = free_region(section_polygons(path, None, None, RESOLUTION, TOLERANCE))
        ratio = got.symmetric_difference(expected).area / expected.area
        assert ratio < 1e-3, f"{suffix}: differs from the PLY's section by {ratio:.2%}"


def test_figure_is_written(tmp_path: Path) -> None:
    from rb_drake.terrain.mesh_figure import section_figure

    for kind, path in FILES.items():
        out = section_figure(path, tmp_path / f"{kind}.png", compare=CLOUD_FILE, max_items=200)
        data = out.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, f"{kind}: not a picture"
    assert not list(tmp_path.glob(".*.tmp")), "a temporary file was left behind"


def test_dense_cloud_is_thinned_and_still_agrees(tmp_path: Path) -> None:
    import time

    from rb_drake.terrain import mesh_section

    mesh = lava_tube_mesh(SEED)
    path = tmp_path / "dense.ply"
    path.write_bytes(trimesh.PointCloud(lava_tube_cloud(mesh, SEED, 300_000)).export(
        file_type="ply"))
    points = trimesh.load(path).vertices
    near = np.abs(points[:, 0] - mesh.bounds.mean(axis=0)[0]) <= RESOLUTION
    assert near.sum() > mesh_section.THIN_ABOVE, "the cloud must be dense enough to be thinned"
    start = time.perf_counter()
    dense = free_region(section_polygons(path, None, None, RESOLUTION, TOLERANCE))
    elapsed = time.perf_counter() - start
    exact = free_region(section_polygons(MESH_FILE, None, None, RESOLUTION, TOLERANCE))
    ratio = dense.symmetric_difference(exact).area / exact.area
    assert ratio <= 0.04, f"the thinned cloud's section differs by {ratio:.1%} from the mesh's"
    assert elapsed < 5.0, f"{near.sum()} points near the plane took {elapsed:.1f} s"


def test_obj_naming_other_files_does_not_open_them(tmp_path: Path) -> None:
    # an OBJ's `mtllib` is not followed: /dev/zero would never end
    mesh = trimesh.load(MESH_FILE)
    path = tmp_path / "tube.obj"
    path.write_text("mtllib /dev/zero\n" + mesh.export(file_type="obj"))
    rock = section_polygons(path, None, None, RESOLUTION, TOLERANCE)
    check_polygons(rock)


def test_default_cloud_resolution_follows_the_density_and_does_not_leak() -> None:
    """Without a resolution the cloud's comes from its density: 16 times the points, a
    quarter of the resolution; and the shipped cloud's default section is the mesh's (the
    import's old fixed 5 cm let the outline leak through its walls: 35 % of the cave lost)."""
    from rb_drake.terrain.mesh_section import SPACINGS, cloud_resolution

    mesh = lava_tube_mesh(SEED)
    sparse = cloud_resolution(lava_tube_cloud(mesh, SEED, 5_000))
    dense = cloud_resolution(lava_tube_cloud(mesh, SEED, 80_000))
    assert abs(sparse / dense - 4.0) <= 0.4, f"resolutions {sparse:.4f} and {dense:.4f} m"
    # the example's walls and caps: the sampled surface
    area = mesh.area
    expected = SPACINGS / math.sqrt(DESIGN.cloud_points / area)
    shipped = cloud_resolution(trimesh.load(CLOUD_FILE).vertices)
    assert abs(shipped - expected) <= 0.15 * expected, \
        f"{shipped:.4f} m for {DESIGN.cloud_points} points on {area:.1f} m²: {expected:.4f} m"
    exact = free_region(section_polygons(MESH_FILE, None, None, None, TOLERANCE))
    cloud = free_region(section_polygons(CLOUD_FILE, None, None, None, TOLERANCE))
    ratio = cloud.symmetric_difference(exact).area / exact.area
    assert ratio <= 0.04, f"the cloud's default section differs by {ratio:.1%} from the mesh's"


def test_too_few_points_for_a_density_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "five.ply"
    points = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 1], [0, 2, 3]], dtype=float)
    path.write_bytes(trimesh.PointCloud(points).export(file_type="ply"))
    with pytest.raises(RbpInputError,
                       match=r"five\.ply: resolution: 5 point\(s\), 5 distinct, are too few"):
        section_polygons(path, None, None, None, TOLERANCE)
    copies = tmp_path / "copies.obj"  # "4000000 point(s) are too few" said a cloud of one point
    copies.write_text("v 0 0 0\n" * 1000 + "v 1 1 1\n")
    with pytest.raises(RbpInputError,
                       match=r"copies\.obj: resolution: 1,001 point\(s\), 2 distinct, are too"):
        section_polygons(copies, None, None, None, TOLERANCE)
