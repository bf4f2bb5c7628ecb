"""DXF entities beyond polylines (probe 11 F3): circles, ellipses, splines and block references
are rock; entities rbp cannot read are refused by name, never dropped without a word."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from rb_drake.errors import RbpInputError
from rb_drake.terrain.dxf_rock import MAX_INSERT_DEPTH
from rb_drake.terrain.polygon_files import MAX_DXF_ENTITIES, read_rock
from tests.cli_helpers import run_rbp

ezdxf = pytest.importorskip("ezdxf", reason="the extra rbp[import] is not installed")

WALLS = ([(-3, -1), (-1, -1), (-1, 6), (-3, 6)], [(1, -1), (3, -1), (3, 6), (1, 6)])


def _doc() -> tuple[object, object]:
    doc = ezdxf.new()
    msp = doc.modelspace()
    msp.add_text("a label, not rock")
    for ring in WALLS:
        msp.add_lwpolyline(ring, close=True)
    return doc, msp


def _save(doc: object, path: Path) -> Path:
    doc.saveas(path)  # type: ignore[attr-defined]
    return path


def _contains(rock: list, x: float, y: float) -> bool:
    from shapely.geometry import Point

    return any(poly.contains(Point(x, y)) for poly in rock)


def test_circle_ellipse_spline_and_block_are_rock(tmp_path):
    doc, msp = _doc()
    msp.add_circle((0, 3), 0.4)  # a boulder
    msp.add_ellipse((0, 4.5), (0.3, 0), 0.5)
    msp.add_open_spline([(-0.5, 0), (0.5, 0), (0.5, 0.5), (-0.5, 0.5), (-0.5, 0)])  # ends meet
    block = doc.blocks.new("ROCK")
    block.add_lwpolyline([(-0.3, -0.2), (0.3, -0.2), (0.3, 0.2), (-0.3, 0.2)], close=True)
    inner = doc.blocks.new("TWO")
    inner.add_blockref("ROCK", (0, 0))
    msp.add_blockref("TWO", (0, 2))  # a block of a block: expanded with its transforms
    rock = read_rock(_save(doc, tmp_path / "boulder.dxf"))
    assert len(rock) == 6
    for x, y in ((0, 3), (0, 4.5), (0, 2), (0, 0.25)):
        assert _contains(rock, x, y), (x, y)
    circle = next(p for p in rock if _contains([p], 0, 3))
    assert circle.area == pytest.approx(3.14159 * 0.16, rel=0.02)  # chords within 5 mm


def test_unreadable_entities_refused_by_name(tmp_path):
    doc, msp = _doc()
    for y in (1, 3):
        msp.add_solid([(-0.2, y), (0.2, y), (-0.2, y + 0.3), (0.2, y + 0.3)])
    with pytest.raises(RbpInputError, match="entities: 2 SOLID entities not imported"):
        read_rock(_save(doc, tmp_path / "solid.dxf"))


def test_open_ellipse_arc_refused(tmp_path):
    doc, msp = _doc()
    msp.add_ellipse((0, 3), (0.3, 0), 0.5, start_param=0, end_param=3)
    with pytest.raises(RbpInputError, match=r"entity 4 \(ELLIPSE.*open curve"):
        read_rock(_save(doc, tmp_path / "arc.dxf"))


def test_block_inserting_itself_refused(tmp_path):
    doc, msp = _doc()
    block = doc.blocks.new("LOOP")
    block.add_lwpolyline([(0, 0), (1, 0), (1, 1)], close=True)
    block.add_blockref("LOOP", (2, 0))
    msp.add_blockref("LOOP", (0, 0))
    with pytest.raises(RbpInputError, match=f"nested more than {MAX_INSERT_DEPTH} deep"):
        read_rock(_save(doc, tmp_path / "loop.dxf"))


def test_minsert_copies_counted_before_expansion(tmp_path):
    doc, msp = _doc()
    block = doc.blocks.new("W")
    block.add_lwpolyline([(0, 0), (0.1, 0), (0.1, 0.1)], close=True)
    msp.add_blockref("W", (0, 0)).grid(size=(30000, 30000), spacing=(1, 1))
    with pytest.raises(RbpInputError, match=f"more than {MAX_DXF_ENTITIES:,} once block"):
        read_rock(_save(doc, tmp_path / "minsert.dxf"))


def test_huge_circle_refused_before_flattening(tmp_path):
    doc, msp = _doc()
    msp.add_circle((0, 3), 1e300)
    with pytest.raises(RbpInputError, match=r"CIRCLE.*a coordinate beyond"):
        read_rock(_save(doc, tmp_path / "huge.dxf"))


def test_cli_one_line_for_refused_entity(tmp_path):
    doc, msp = _doc()
    msp.add_solid([(-0.2, 1), (0.2, 1), (-0.2, 1.3), (0.2, 1.3)])
    _save(doc, tmp_path / "solid.dxf")
    res = run_rbp("scenario", "import", "solid.dxf", "-o", "c.yaml", cwd=tmp_path)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1
    assert res.stderr.startswith("error: solid.dxf: entities: 1 SOLID entities not imported")
    assert not (tmp_path / "c.yaml").exists()


def test_lines_and_arcs_joined_into_a_closed_outline_are_rock(tmp_path):
    """A boulder drawn stroke by stroke (an exploded polyline: LINEs and an ARC, in shuffled
    order and directions, ends off by round-off) is rock, as the polyline would be; strokes
    that close nothing (a scale bar, a dangling line) are skipped as before."""
    doc, msp = _doc()
    msp.add_line((0.5, 2.0), (-0.5, 2.0))  # bottom, right to left
    msp.add_arc((0.0, 3.0), 0.5, 0, 180)  # top: from (0.5, 3) to (-0.5, 3), counterclockwise
    msp.add_line((-0.5, 2.0 + 1e-9), (-0.5, 3.0))  # left side, its end off by round-off
    msp.add_line((0.5, 3.0), (0.5, 2.0))  # right side
    msp.add_line((-2.5, 6.5), (2.5, 6.5))  # an open stroke: a scale bar
    msp.add_line((0.0, -0.5), (0.2, -0.7))  # another
    rock = read_rock(_save(doc, tmp_path / "strokes.dxf"))
    assert len(rock) == 3, [p.bounds for p in rock]
    assert _contains(rock, 0.0, 2.5) and _contains(rock, 0.0, 3.3), "the boulder is rock"
    boulder = next(p for p in rock if _contains([p], 0.0, 2.5))
    expected = 1.0 * 1.0 + 3.14159 * 0.25 / 2  # the square and the half disc
    assert boulder.area == pytest.approx(expected, rel=0.01), boulder.area
    assert not _contains(rock, 0.0, 6.5), "an open stroke is not rock"


def test_a_branching_or_open_chain_is_not_rock(tmp_path):
    doc, msp = _doc()
    square = [(-0.3, 2.0), (0.3, 2.0), (0.3, 2.6), (-0.3, 2.6)]
    for a, b in itertools.pairwise(square):  # three sides: open
        msp.add_line(a, b)
    rock = read_rock(_save(doc, tmp_path / "open.dxf"))
    assert len(rock) == 2 and not _contains(rock, 0.0, 2.3)
    msp.add_line(square[3], square[0])  # closed now, and a spur from one corner
    msp.add_line(square[0], (-0.6, 1.5))
    rock = read_rock(_save(doc, tmp_path / "spur.dxf"))
    assert len(rock) == 2, "a chain with a branch is not one outline"
    doc2, msp2 = _doc()
    for a, b in zip(square, square[1:] + square[:1], strict=True):
        msp2.add_line(a, b)
    rock = read_rock(_save(doc2, tmp_path / "closed.dxf"))
    assert len(rock) == 3 and _contains(rock, 0.0, 2.3)


def test_lines_alone_that_close_are_rock(tmp_path):
    doc = ezdxf.new()
    msp = doc.modelspace()
    for ring in WALLS:
        for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
            msp.add_line(a, b)
    rock = read_rock(_save(doc, tmp_path / "walls.dxf"))
    assert len(rock) == 2 and _contains(rock, -2, 3) and _contains(rock, 2, 3)
    assert not _contains(rock, 0, 3)


def test_a_hatch_is_rock_its_inner_paths_holes(tmp_path):
    """Rock drawn as a fill (HATCH) was refused: now its area is rock, by the even-odd rule
    (an inner boundary path is a hole), arcs and splines of edge paths flattened."""
    doc, msp = _doc()
    boulder = msp.add_hatch(color=1)  # a square boulder with a square hole
    boulder.paths.add_polyline_path([(-0.5, 1), (0.5, 1), (0.5, 2), (-0.5, 2)], is_closed=True)
    boulder.paths.add_polyline_path([(-0.2, 1.3), (0.2, 1.3), (0.2, 1.7), (-0.2, 1.7)],
                                    is_closed=True)
    rounded = msp.add_hatch()  # a half-disc of radius 0.4: a line and an arc edge
    edges = rounded.paths.add_edge_path()
    edges.add_line((0.4, 3), (-0.4, 3))
    edges.add_arc((0, 3), 0.4, 180, 360)
    rock = read_rock(_save(doc, tmp_path / "hatched.dxf"))
    assert _contains(rock, 0, 1.15) and not _contains(rock, 0, 1.5), \
        "the hatch's outer path is not rock, or its inner path is not a hole"
    square = next(p for p in rock if _contains([p], 0, 1.15))
    assert square.area == pytest.approx(1.0 - 0.16, rel=1e-6), square.area
    assert _contains(rock, 0, 2.8) and not _contains(rock, 0, 3.2), "the half-disc is wrong"
    half = next(p for p in rock if _contains([p], 0, 2.8))
    assert half.area == pytest.approx(3.14159 * 0.16 / 2, rel=0.02), half.area


def test_a_hatch_is_imported_and_planned_around(tmp_path):
    doc, msp = _doc()
    boulder = msp.add_hatch()
    boulder.paths.add_polyline_path([(-0.3, 2), (0.3, 2), (0.3, 2.6), (-0.3, 2.6)],
                                    is_closed=True)
    path = _save(doc, tmp_path / "shaft.dxf")
    done = run_rbp("scenario", "import", str(path), "-o", "cave.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    from rb_drake.scenario import load_scenario

    scn = load_scenario(tmp_path / "cave.yaml")
    assert any(min(x for x, _ in wall) > -0.31 and max(x for x, _ in wall) < 0.31
               for wall in scn.walls), "the hatched boulder is not among the cave's walls"


def test_a_hatch_of_a_hopeless_spline_is_refused(tmp_path):
    doc, msp = _doc()
    fill = msp.add_hatch()
    edges = fill.paths.add_edge_path()
    edges.add_spline(control_points=[(0, 2), (1, 2), (1, 3), (0, 3)], degree=3)
    edges.edges[0].degree = 40  # ezdxf's evaluation grows with the degree's square
    edges.add_line((0, 3), (0, 2))
    with pytest.raises(RbpInputError, match=r"boundary path 1.*spline edge of degree 40"):
        read_rock(_save(doc, tmp_path / "spline.dxf"))


def test_a_hatch_over_its_own_outline_stays_rock(tmp_path):
    """A drawing's fill usually lies on the polyline it was made from: the even-odd rule of
    nested outlines must not make the two cancel."""
    doc, msp = _doc()
    square = [(-0.3, 2), (0.3, 2), (0.3, 2.6), (-0.3, 2.6)]
    msp.add_lwpolyline(square, close=True)
    msp.add_hatch().paths.add_polyline_path(square, is_closed=True)
    rock = read_rock(_save(doc, tmp_path / "outlined.dxf"))
    assert _contains(rock, 0, 2.3), "a hatch over its own outline cancelled it"


def test_many_outlines_nest_in_near_linear_time(tmp_path):
    """Outlines nest by the even-odd rule, one symmetric difference at a time: 3,000 small
    boulders took 27 s. A balanced tree of them: the same region."""
    doc, msp = _doc()
    for i in range(3000):
        y = 0.5 + i * 1.5e-3
        msp.add_lwpolyline([(-0.2, y), (0.2, y), (0.2, y + 5e-4)], close=True)
    msp.add_lwpolyline([(-0.5, 7), (0.5, 7), (0.5, 8), (-0.5, 8)], close=True)
    msp.add_lwpolyline([(-0.2, 7.3), (0.2, 7.3), (0.2, 7.7), (-0.2, 7.7)], close=True)
    rock = read_rock(_save(doc, tmp_path / "many.dxf"))
    assert len(rock) == 2 + 3000 + 1, f"{len(rock)} pieces of rock"
    assert _contains(rock, 0, 7.1) and not _contains(rock, 0, 7.5), "the hole is lost"


@pytest.mark.parametrize(("code", "metres"), [(4, 1e-3), (5, 1e-2), (1, 0.0254), (6, 1.0)])
def test_a_drawing_is_read_in_the_unit_it_declares(tmp_path, code, metres):
    """CAD drawings are mostly in millimetres and say so in $INSUNITS; read as metres, a 5 m
    cave was 5 km. Without --unit the declared unit is used; --unit still overrides it."""
    doc = ezdxf.new(units=code)
    msp = doc.modelspace()
    for ring in WALLS:
        msp.add_lwpolyline([(x / metres, y / metres) for x, y in ring], close=True)
    path = _save(doc, tmp_path / "cad.dxf")
    rock = read_rock(path)
    assert _contains(rock, -2, 3) and _contains(rock, 2, 3) and not _contains(rock, 0, 3), \
        f"$INSUNITS {code} not read as {metres} m a unit: {[p.bounds for p in rock]}"
    forced = read_rock(path, unit="m", scale=metres / 2)  # the user's unit wins
    assert sum(p.area for p in forced) == pytest.approx(sum(p.area for p in rock) / 4), \
        "--unit did not override the declared unit"


def test_scenario_import_reads_the_declared_unit(tmp_path):
    doc = ezdxf.new(units=4)  # millimetres
    msp = doc.modelspace()
    for ring in WALLS:
        msp.add_lwpolyline([(x * 1000, y * 1000) for x, y in ring], close=True)
    _save(doc, tmp_path / "mm.dxf")
    done = run_rbp("scenario", "import", "mm.dxf", "-o", "cave.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "cave.yaml").read_text()
    assert "--unit" not in text.splitlines()[0], "the command line names a unit not given"
    from rb_drake.scenario import load_scenario

    scn = load_scenario(tmp_path / "cave.yaml")
    assert 2.0 <= scn.goal_position[1] - scn.start_pose[1] <= 7.0, \
        "a millimetre drawing of a 7 m shaft did not make a shaft of metres"


def test_a_declared_unit_is_named_when_the_cave_fails(tmp_path):
    """A drawing in metres whose header declares millimetres (an exporter's default) makes a
    cave a thousand times too small: the refusal says which unit was read, and how to change
    it; --unit m reads it as drawn."""
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    for ring in WALLS:
        msp.add_lwpolyline(ring, close=True)
    _save(doc, tmp_path / "mislabelled.dxf")
    done = run_rbp("scenario", "import", "mislabelled.dxf", "-o", "cave.yaml", cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "(read in mm, the unit its $INSUNITS declares; --unit if it is not)" in done.stderr
    forced = run_rbp("scenario", "import", "mislabelled.dxf", "-o", "cave.yaml", "--unit", "m",
                     cwd=tmp_path)
    assert forced.returncode == 0 and "INSUNITS" not in forced.stdout, forced.stderr
