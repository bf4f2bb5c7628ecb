"""Caves imported from polygon files (`rbp scenario import`): GeoJSON, DXF and SVG of the same
rock read alike, the cave is a valid scenario whose anchors sit on the rock facing out, a seed
gives one cave, and each bad file is refused in one line naming it (exit status 2).
"""

from __future__ import annotations

import functools
import importlib.util
import json
import math
import sys
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("shapely", reason="the extra rbp[import] is not installed")
pytest.importorskip("ezdxf", reason="the extra rbp[import] is not installed")
pytest.importorskip("svgelements", reason="the extra rbp[import] is not installed")

import ezdxf
from shapely.geometry import Point
from shapely.ops import unary_union

from rb_drake.errors import RbpInputError
from rb_drake.scenario import ANCHOR_GAP_TOL, Scenario, scenario_from_dict
from rb_drake.terrain.cave_from_rock import scenario_from_rock
from rb_drake.terrain.import_cave import ImportOptions, import_cave
from rb_drake.terrain.polygon_files import read_rock
from tests.cli_helpers import ROOT, run_rbp

EXAMPLE = ROOT / "rb_drake" / "data" / "terrain" / "lava-tube-shaft.geojson"
SAME_ROCK_TOL = 1e-6   # m: the three formats hold the same coordinates, converted exactly
OUTWARD_STEP = 0.05    # m: a step along an anchor's normal must leave the rock


def example_rings() -> list[list[list[float]]]:
    """The example's rock outlines in metres, closing point left out."""
    data = json.loads(EXAMPLE.read_text())
    return [f["geometry"]["coordinates"][0][:-1] for f in data["features"]]


@functools.cache
def example_cave(seed: int = 0) -> Scenario:
    """Imported once per seed for the module: choosing the start takes a few seconds."""
    return import_cave(EXAMPLE, ImportOptions(seed=seed))


def write_dxf(path: Path, rings: list[list[list[float]]], factor: float = 1.0,
              closed: bool = True) -> Path:
    doc = ezdxf.new()
    msp = doc.modelspace()
    msp.add_text("a label, not rock")
    for ring in rings:
        msp.add_lwpolyline([(x * factor, y * factor) for x, y in ring], close=closed)
    doc.saveas(path)
    return path


def write_svg(path: Path, rings: list[list[list[float]]], factor: float = 1.0) -> Path:
    """Rings as SVG paths, y flipped (SVG's y points down), in a viewBox scaled to mm."""
    paths = "\n".join(
        '<path d="M ' + " L ".join(f"{x * factor:.6f} {-y * factor:.6f}" for x, y in ring)
        + ' Z"/>' for ring in rings)
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="400mm" height="700mm" '
                    f'viewBox="-2000 -6000 4000 7000">\n{paths}\n</svg>\n')
    return path


def assert_same_rock(a, b, what: str) -> None:
    ua, ub = unary_union(a), unary_union(b)
    assert len(a) == len(b), f"{what}: {len(a)} rock polygons against {len(b)}"
    gap = ua.hausdorff_distance(ub)
    assert gap <= SAME_ROCK_TOL, f"{what}: outlines {gap:.2e} m apart (tolerance {SAME_ROCK_TOL})"
    assert ua.symmetric_difference(ub).area <= SAME_ROCK_TOL, f"{what}: the rock differs"


def test_formats_read_the_same_rock(tmp_path):
    rings = example_rings()
    geo = read_rock(EXAMPLE)
    dxf = read_rock(write_dxf(tmp_path / "cave.dxf", rings, factor=100.0), unit="cm")
    svg = read_rock(write_svg(tmp_path / "cave.svg", rings, factor=1000.0), unit="mm")
    assert len(geo) == 2, f"the example holds two walls, read {len(geo)}"
    assert_same_rock(geo, dxf, "DXF in cm")
    assert_same_rock(geo, svg, "SVG in mm")
    halved = read_rock(EXAMPLE, scale=0.5)
    area = sum(p.area for p in geo)
    assert abs(sum(p.area for p in halved) - area / 4) <= 1e-9, "--scale 0.5 quarters the area"


def test_nested_outlines_are_holes(tmp_path):
    """DXF outlines nest by the even-odd rule: a tunnel's section (rock round a free tube) in
    GeoJSON (a polygon with a hole) and in DXF (two closed polylines) is the same rock."""
    outer = [[-2.0, -1.0], [2.0, -1.0], [2.0, 6.0], [-2.0, 6.0]]
    hole = [[-0.85, 0.0], [0.85, 0.0], [0.85, 5.0], [-0.85, 5.0]]
    geojson = tmp_path / "tube.geojson"
    geojson.write_text(json.dumps({"type": "Polygon",
                                   "coordinates": [[*outer, outer[0]], [*hole, hole[0]]]}))
    geo = read_rock(geojson)
    dxf = read_rock(write_dxf(tmp_path / "tube.dxf", [outer, hole]))
    assert_same_rock(geo, dxf, "tube")
    assert len(geo[0].interiors) == 1, "the tube's rock has one hole"


def check_anchors_on_rock(scn: Scenario, rock) -> None:
    solid = unary_union(rock)
    for a in scn.anchors:
        p = np.array(a.position)
        gap = solid.boundary.distance(Point(p))
        assert gap <= ANCHOR_GAP_TOL, f"anchor {a.id} at {a.position} is {gap:.3f} m off the rock"
        out = p + OUTWARD_STEP * np.array(a.normal)
        assert not solid.contains(Point(out)), f"anchor {a.id}'s normal {a.normal} points in"


def test_example_cave_is_a_valid_scenario():
    scn = example_cave()
    again = scenario_from_dict(scn.to_dict(), "imported")  # with the start stance's check
    assert again.to_dict() == scn.to_dict(), "the cave does not read back unchanged"
    assert len(scn.walls) == 2, f"{len(scn.walls)} walls"
    check_anchors_on_rock(scn, read_rock(EXAMPLE))
    start_y, goal_y = scn.start_pose[1], scn.goal_position[1]
    assert goal_y - start_y >= 2.0, f"start at {start_y} m, goal at {goal_y} m: no climb"
    assert 1.0 <= start_y <= 2.0, f"the start ({start_y} m) is not 1.5 m above the bottom"


def test_same_seed_same_cave():
    first = example_cave(0)
    again = import_cave(EXAMPLE, ImportOptions(seed=0))
    assert again.to_dict() == first.to_dict(), "seed 0 gave two caves"
    other = import_cave(EXAMPLE, ImportOptions(seed=1, start=first.start_pose[:2],
                                               goal=first.goal_position))
    assert other.to_dict()["anchors"] != first.to_dict()["anchors"], "seeds 0 and 1 agree"
    check_anchors_on_rock(other, read_rock(EXAMPLE))


def test_tunnel_rock_with_a_hole_makes_simple_walls():
    from shapely.geometry import Polygon

    outer = [(-2.0, -1.0), (2.0, -1.0), (2.0, 6.0), (-2.0, 6.0)]
    hole = [(-0.85, 0.0), (0.85, 0.0), (0.8, 2.5), (0.85, 5.0), (-0.85, 5.0), (-0.9, 2.5)]
    rock = [Polygon(outer, [hole])]
    scn = scenario_from_rock(rock, seed=2, start=(0.0, 1.0), goal=(0.0, 4.0), source="tube")
    assert len(scn.walls) >= 2, "rock with a hole must be cut into simple walls"
    cover = unary_union([Polygon(w) for w in scn.walls])
    assert cover.symmetric_difference(rock[0]).area <= 1e-6, "the walls do not cover the rock"
    check_anchors_on_rock(scn, rock)
    inside = [a for a in scn.anchors if abs(a.position[0]) < 1.0 and 0.0 <= a.position[1] <= 5.0]
    assert len(inside) >= 10, f"only {len(inside)} anchors on the tube's inner wall"


def test_framed_rock_has_no_anchors_on_its_frame():
    """A scan's section is a frame minus the free space: the frame is no rock surface, so a
    framed import puts anchors on the cave's outline only, as many as its length gives."""
    from shapely.geometry import Polygon

    outer = [(-2.0, -1.0), (2.0, -1.0), (2.0, 6.0), (-2.0, 6.0)]
    hole = [(-0.85, 0.0), (0.85, 0.0), (0.8, 2.5), (0.85, 5.0), (-0.85, 5.0), (-0.9, 2.5)]
    rock = [Polygon(outer, [hole])]
    scn = scenario_from_rock(rock, seed=2, start=(0.0, 1.0), goal=(0.0, 4.0), source="tube",
                             framed=True)
    check_anchors_on_rock(scn, rock)
    cave = Polygon(hole).exterior
    gaps = [cave.distance(Point(a.position)) for a in scn.anchors]
    assert max(gaps) <= ANCHOR_GAP_TOL, f"an anchor {max(gaps):.3f} m off the cave's outline"
    # Poisson with mean 3 per metre of the 12.4 m outline: 37 +- 6.1
    expected = 3.0 * cave.length
    assert abs(len(scn.anchors) - expected) <= 4 * expected ** 0.5, \
        f"{len(scn.anchors)} anchors on {cave.length:.1f} m of outline"


def test_start_in_rock_refused():
    with pytest.raises(RbpInputError, match=r"--start: the body at .* meets rock"):
        import_cave(EXAMPLE, ImportOptions(start=(-1.5, 2.0), goal=(0.0, 4.0)))
    # free, but the booms reach no rock above the shaft's top
    with pytest.raises(RbpInputError, match="--start: no feasible stance"):
        import_cave(EXAMPLE, ImportOptions(start=(0.0, 9.0), goal=(0.0, 4.0)))


def test_missing_extra_named(monkeypatch):
    monkeypatch.setitem(sys.modules, "shapely", None)  # import shapely now raises ImportError
    with pytest.raises(RbpInputError, match=r"pip install 'rbp\[import\]'"):
        import_cave(EXAMPLE)


def test_mesh_without_its_module(tmp_path):
    if importlib.util.find_spec("rb_drake.terrain.mesh_section") is not None:
        pytest.skip("rb_drake.terrain.mesh_section exists: its own tests cover meshes")
    stl = tmp_path / "cave.stl"
    stl.write_text("solid empty\nendsolid empty\n")
    with pytest.raises(RbpInputError, match=r"mesh import needs rb_drake\.terrain\.mesh_section"):
        import_cave(stl)


def bowtie(path: Path) -> None:
    path.write_text(json.dumps({"type": "Polygon", "coordinates": [
        [[0, 0], [2, 2], [2, 0], [0, 2], [0, 0]]]}))


def open_dxf(path: Path) -> None:
    write_dxf(path, [[[0, 0], [1, 0], [1, 1], [0, 1]], [[3, 0], [4, 0], [4, 1]]], closed=True)
    doc = ezdxf.readfile(path)
    doc.modelspace().query("LWPOLYLINE")[1].closed = False
    doc.saveas(path)


BAD_FILES = {  # name -> (how to write it, what the message must say)
    "cave.txt": (lambda p: p.write_text("0 0\n1 0\n1 1\n"), "unknown suffix '.txt'"),
    "empty.geojson": (lambda p: p.write_text(""), "empty file"),
    "open.dxf": (open_dxf, "entity 3 (LWPOLYLINE"),
    "bowtie.geojson": (bowtie, "self-intersection"),
    "garbage.json": (lambda p: p.write_text('{"type": "Polygon", "coordinates": [[0, 0'),
                     "not JSON"),
    "huge.geojson": (lambda p: p.write_text('{"type": "Polygon", "coordinates": [[[0, 0], '
                                            f'[1{"0" * 400}, 0], [1, 1], [0, 0]]]}}'),
                     "beyond a float's range"),
    "notdxf.dxf": (lambda p: p.write_text("0\nSECTION\nnot a dxf\n"), "not a DXF drawing"),
    "open.svg": (lambda p: p.write_text('<svg xmlns="http://www.w3.org/2000/svg">'
                                        '<path d="M 0 0 L 10 0 L 10 10"/></svg>'), "open path"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_file_refused_in_one_line(tmp_path, name):
    write, expected = BAD_FILES[name]
    path = tmp_path / name
    write(path)
    out = tmp_path / "cave.yaml"
    result = run_rbp("scenario", "import", name, "-o", str(out), cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, f"{name}: exit {result.returncode}, stderr {result.stderr!r}"
    assert len(lines) == 1, f"{name}: {len(lines)} lines on stderr: {result.stderr!r}"
    assert lines[0].startswith(f"error: {name}: "), f"{name}: not named first: {lines[0]!r}"
    assert expected in lines[0], f"{name}: {expected!r} not in {lines[0]!r}"
    assert not out.exists(), f"{name}: a scenario was written"
    if name == "open.dxf":
        assert "open polyline; rock must be closed" in lines[0], lines[0]


def test_cli_writes_the_command_and_a_checked_scenario(tmp_path):
    first = example_cave()
    out = tmp_path / "lava.yaml"
    x, y = first.start_pose[:2]
    gx, gy = first.goal_position
    result = run_rbp("scenario", "import", str(EXAMPLE), "-o", str(out), "--start", str(x),
                     str(y), "--goal", str(gx), str(gy), "--name", "lava", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = out.read_text()
    assert text.startswith("# rbp scenario import "), text[:80]
    check = run_rbp("scenario", "check", str(out), cwd=tmp_path)
    assert check.returncode == 0, check.stderr
    assert "ok: lava" in check.stdout, check.stdout


def test_example_cave_has_a_climb():
    """The example is a cave to climb: the footstep search finds a route to the chosen goal
    (about 8 s; the start and the goal are the importer's own choice)."""
    import rbp

    plan = rbp.plan(example_cave(), footsteps_only=True)
    assert plan.success, f"no route up the imported example: {plan.reason}"


CURVE_AREA_TOL = 0.01  # relative: curves become chords within 5 mm


def test_curves_become_polylines(tmp_path):
    """A circle of radius 1 m drawn with DXF bulges and as an SVG <circle> reads as one."""
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline([(-1, 0, 0, 0, 1), (1, 0, 0, 0, 1)], format="xyseb",
                                    close=True)
    doc.saveas(tmp_path / "disc.dxf")
    (tmp_path / "disc.svg").write_text('<svg xmlns="http://www.w3.org/2000/svg">'
                                       '<circle cx="0" cy="0" r="100"/></svg>')
    for name, unit in (("disc.dxf", "m"), ("disc.svg", "cm")):
        (disc,) = read_rock(tmp_path / name, unit=unit)
        error = abs(disc.area - np.pi) / np.pi
        assert error <= CURVE_AREA_TOL, f"{name}: area {disc.area:.4f} against pi ({error:.2%})"


def test_meshes_go_to_mesh_section(monkeypatch, tmp_path):
    """A mesh's file, plane and resolution reach mesh_section.section_polygons, in the mesh's
    unit, and its section comes back in metres (a stand-in module: the real one is another
    branch's)."""
    import types

    from shapely.geometry import Polygon

    rings = example_rings()
    calls = []

    def section_polygons(path, origin, normal, resolution, tolerance, metres_per_unit):
        calls.append((path, origin, normal, resolution, tolerance, metres_per_unit))
        return [Polygon([(x * 100, y * 100) for x, y in ring]) for ring in rings]  # in cm

    fake = types.ModuleType("rb_drake.terrain.mesh_section")
    fake.section_polygons = section_polygons
    monkeypatch.setitem(sys.modules, "rb_drake.terrain.mesh_section", fake)
    first = example_cave()
    mesh = tmp_path / "cave.ply"
    scn = import_cave(mesh, ImportOptions(unit="cm", plane_origin=(0, 0, 1), resolution=0.05,
                                          plane_normal=(0, 1, 0), simplify=0.01,
                                          start=first.start_pose[:2], goal=first.goal_position))
    assert calls == [(mesh, (0, 0, 1), (0, 1, 0), pytest.approx(5.0), pytest.approx(1.0),
                      pytest.approx(0.01))], calls
    assert_same_rock([Polygon(w) for w in scn.walls], [Polygon(w) for w in first.walls],
                     "the section in cm, read in metres")


def _reading_problem(path: Path) -> str | None:
    """What is wrong with reading `path`, None when it gives valid rock or an RbpInputError
    naming the file on one line (any other exception propagates)."""
    try:
        rock = read_rock(path)
    except RbpInputError as e:
        if not str(e).startswith(f"{path}: "):
            return f"refusal not naming the file: {e}"
        if "\n" in str(e):
            return f"refusal on more than one line: {e!r}"
        return None
    if not rock or not all(p.is_valid for p in rock):
        return f"{path}: invalid rock accepted"
    return None


GEOJSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                                max_size=4),
    max_leaves=20)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(value=GEOJSON_VALUES, key=st.sampled_from(["type", "coordinates", "features",
                                                  "geometry", "geometries"]))
def test_any_geojson_value_refused_or_read(tmp_path, value, key):
    """Hypothesis's values (huge integers, NaN, nesting) in the example's fields."""
    data = json.loads(EXAMPLE.read_text())
    target = data if key in ("type", "features") else data["features"][0]
    if key == "coordinates":
        target = target["geometry"]
    target[key] = value
    path = tmp_path / "fuzz.geojson"
    path.write_text(json.dumps(data))
    problem = _reading_problem(path)
    assert problem is None, problem


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(cut=st.integers(min_value=0, max_value=10_000), junk=st.text(max_size=30),
       suffix=st.sampled_from([".dxf", ".svg"]))
def test_damaged_drawings_refused_or_read(tmp_path, cut, junk, suffix):
    """A DXF or SVG of the example cut short or with text spliced in."""
    rings = example_rings()
    whole = (write_dxf(tmp_path / "whole.dxf", rings) if suffix == ".dxf"
             else write_svg(tmp_path / "whole.svg", rings)).read_text()
    at = cut % (len(whole) + 1)
    path = tmp_path / f"fuzz{suffix}"
    path.write_text(whole[:at] + junk + whole[at + len(junk):])
    problem = _reading_problem(path)
    assert problem is None, problem


def test_drawings_that_would_expand_past_the_limit_refused_quickly(tmp_path):
    """Arcs and <use> copies are bounded before ezdxf or svgelements expand them: a bulge of
    1e10 made billions of chords (gigabytes, minutes), six levels of ten <use> a million
    elements, 2,000 tall Bézier curves 2 million points; a bulge of 1e300 made ezdxf warn.
    svgelements follows any href, dropping its first character: `href="xa"` copies `#a`, which
    the count once skipped (21 s and 1.3 GB for the bomb, a RecursionError for the loop)."""

    def bulge_dxf(name: str, bulge: float) -> Path:
        doc = ezdxf.new()
        doc.modelspace().add_lwpolyline([(0, 0, 0, 0, bulge), (1, 0, 0, 0, 0), (1, 1, 0, 0, 0)],
                                        format="xyseb", close=True)
        doc.saveas(tmp_path / name)
        return tmp_path / name

    use = "".join(f'<g id="g{k + 1}">' + f'<use href="#g{k}"/>' * 10 + "</g>" for k in range(6))
    svg = '<svg xmlns="http://www.w3.org/2000/svg">{}</svg>'
    cases = [
        (bulge_dxf("b1e10.dxf", 1e10), "more than 50000 outline vertices"),
        (bulge_dxf("b1e300.dxf", 1e300), "more than 50000 outline vertices"),
        (bulge_dxf("bnan.dxf", math.nan), "entity 1 .*: a bulge that is not a finite number"),
        (tmp_path / "bomb.svg", r"6,802,462 elements once <use> copies are expanded"),
        (tmp_path / "loop.svg", r"<use> nested more than 8 deep \(or in a loop\)"),
        (tmp_path / "bomb_nohash.svg", r"6,802,462 elements once <use> copies are expanded"),
        (tmp_path / "loop_nohash.svg", r"<use> nested more than 8 deep \(or in a loop\)"),
        (tmp_path / "curves.svg", "more than 50000 outline vertices"),
    ]
    (tmp_path / "bomb.svg").write_text(svg.format(
        '<defs><g id="g0"><rect width="1" height="1"/></g>' + use + '</defs><use href="#g6"/>'))
    (tmp_path / "loop.svg").write_text(svg.format('<g id="a"><use href="#a"/></g>'))
    (tmp_path / "bomb_nohash.svg").write_text(
        (tmp_path / "bomb.svg").read_text().replace('href="#', 'href="x'))
    (tmp_path / "loop_nohash.svg").write_text(svg.format(
        '<g id="a"><rect width="1" height="1"/><use href="_a"/></g>'))
    (tmp_path / "curves.svg").write_text(svg.format(
        '<path d="M0 0 ' + " ".join(f"Q {20 * k + 10} 5000 {20 * k + 20} 0" for k in range(2000))
        + ' Z"/>'))
    for path, words in cases:
        tracemalloc.start()  # the bombs took 0.6-5.7 GB before their refusal (not a time:
        try:                 # it depends on the machine)
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # nothing may reach stderr before the refusal
                with pytest.raises(RbpInputError, match=f"^{path}: {words}"):
                    read_rock(path)
            peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
        finally:
            tracemalloc.stop()
        assert peak_mb < 100, f"{path.name} took {peak_mb:.0f} MB before its refusal"
    semicircle = bulge_dxf("half.dxf", 1.0)  # an ordinary arc still reads
    assert len(read_rock(semicircle)) == 1


def test_imported_anchors_pass_the_scenario_reader(tmp_path):
    """Anchors are tested for facing into rock as written (rounded to 0.1 mm): this wavy
    5,000-vertex shaft's anchor a54 passed before rounding and the reader refused the import's
    own output ("normal points into the rock")."""
    from shapely import union_all

    from rb_drake.collision import Rock
    from rb_drake.generate import CaveConfig, place_anchors
    from rb_drake.terrain.cave_from_rock import _polygons, _surfaces, _walls

    k = range(1, 2500)
    left = [(-1.9, -0.5), (-0.9, -0.5),
            *((-0.9 + 0.02 * math.sin(i), -0.5 + 6 * i / 2499) for i in k), (-1.9, 5.5),
            (-1.9, -0.5)]
    right = [(1.9, -0.5), (1.9, 5.5), (0.9, 5.5),
             *((0.9 + 0.02 * math.sin(j), 5.5 - 6 * j / 2499) for j in k), (1.9, -0.5)]
    path = tmp_path / "shaft.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}}
        for ring in (left, right)]}))
    solid = [p for p in _polygons(union_all(read_rock(path))) if p.area > 0]
    rock = Rock(_walls(solid, str(path)))
    anchors = place_anchors(np.random.default_rng(0), CaveConfig(), _surfaces(solid), rock)
    inward = [a.id for a in anchors
              if rock.contains(np.array(a.position) + 0.05 * np.array(a.normal))]
    assert len(anchors) > 100 and not inward, inward


def test_cave_too_large_to_read_back_refused(tmp_path, monkeypatch):
    """An import whose scenario file would exceed the reader's limit on values (50,000 outline
    vertices make 150,000) is refused in one line naming the options and the variable."""
    out = tmp_path / "cave.yaml"
    monkeypatch.setenv("RBP_MAX_INPUT_VALUES", "500")  # the subprocess inherits it
    result = run_rbp("scenario", "import", str(EXAMPLE), "-o", str(out), cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "--simplify/--anchor-density" in lines[0] and "RBP_MAX_INPUT_VALUES" in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("crs", ["urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:4326",
                                 "urn:ogc:def:crs:EPSG::4326"])
def test_a_geojson_in_longitude_and_latitude_is_refused(tmp_path: Path, crs: str) -> None:
    """A GIS export naming a longitude-latitude CRS holds degrees: read as metres, it made a
    cave of a few hundredths of a millimetre (or a degree a metre). Refused, naming `crs`; a
    projected CRS is the user's to scale and is read as before."""
    from rb_drake.terrain.polygon_files import read_rock

    walls = [[[-3, -1], [-1, -1], [-1, 6], [-3, 6], [-3, -1]],
             [[1, -1], [3, -1], [3, 6], [1, 6], [1, -1]]]
    doc = {"type": "FeatureCollection", "crs": {"type": "name", "properties": {"name": crs}},
           "features": [{"type": "Feature", "properties": {},
                         "geometry": {"type": "Polygon", "coordinates": [w]}} for w in walls]}
    path = tmp_path / "gis.geojson"
    path.write_text(json.dumps(doc))
    with pytest.raises(RbpInputError, match=r"crs: .* longitude and latitude in degrees"):
        read_rock(path)
    doc["crs"]["properties"]["name"] = "EPSG:32633"  # UTM: metres
    path.write_text(json.dumps(doc))
    assert len(read_rock(path)) == 2, "a projected CRS is refused"
