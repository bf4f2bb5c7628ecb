"""Hostile drawings for `rbp scenario import`: refused before a parser builds them, in one line.

svgelements builds a Python object per SVG element and recurses per level of nesting, so that
millions of `<g></g>` took a minute and gigabytes; the limits are stated in docs/formats.md.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("svgelements", reason="the extra rbp[import] is not installed")
pytest.importorskip("shapely", reason="the extra rbp[import] is not installed")

from rb_drake.errors import RbpInputError
from rb_drake.terrain.drawing_bounds import MAX_SVG_DEPTH, dxf_entities, svg_markup
from rb_drake.terrain.polygon_files import (
    MAX_DXF_ENTITIES,
    MAX_SVG_ELEMENTS,
    _Whole,
    read_rock,
)
from tests.cli_helpers import run_rbp

HEAD = '<svg xmlns="http://www.w3.org/2000/svg">'
SQUARE = '<path d="M 0 0 L 10 0 L 10 10 L 0 10 Z"/>'
OPEN = '<path d="M 0 0 L 1 0"/>'


def _svg(tmp_path: Path, body: str, name: str = "d.svg") -> Path:
    path = tmp_path / name
    path.write_text(f"{HEAD}{body}</svg>")
    return path


@pytest.mark.parametrize("element", ["<g></g>", "<rect/>", "<path/>", "<?x?>"])
def test_too_many_svg_elements_refused_before_parsing(tmp_path, element):
    path = _svg(tmp_path, element * MAX_SVG_ELEMENTS + OPEN)
    with pytest.raises(RbpInputError, match=f"elements, more than {MAX_SVG_ELEMENTS:,}"):
        read_rock(path)


def test_many_svg_elements_refused_on_one_line(tmp_path):
    path = _svg(tmp_path, "<g></g>" * 200_000 + OPEN)
    result = run_rbp("scenario", "import", str(path), "-o", str(tmp_path / "o.yaml"),
                     cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [
        f"error: {path}: holds up to 200,002 elements, more than {MAX_SVG_ELEMENTS:,}; "
        "simplify the drawing first"]


def test_commented_elements_are_not_counted(tmp_path):
    body = "<!--" + "<g></g>" * MAX_SVG_ELEMENTS + "-->" + SQUARE
    assert len(read_rock(_svg(tmp_path, body))) == 1


def test_deep_svg_nesting_refused_with_the_depth(tmp_path):
    deep = "<g>" * (MAX_SVG_DEPTH + 1) + SQUARE + "</g>" * (MAX_SVG_DEPTH + 1)
    with pytest.raises(RbpInputError, match=f"nested more than {MAX_SVG_DEPTH} levels deep"):
        read_rock(_svg(tmp_path, deep))
    ok = "<g>" * (MAX_SVG_DEPTH - 1) + SQUARE + "</g>" * (MAX_SVG_DEPTH - 1)
    assert len(read_rock(_svg(tmp_path, ok, "ok.svg"))) == 1


def test_self_closing_tags_and_quoted_brackets_do_not_nest():
    body = '<g title="a > b"/>' * (2 * MAX_SVG_DEPTH) + "<g a='/>'></g>" * MAX_SVG_DEPTH
    assert svg_markup(f"{HEAD}{body}{SQUARE}</svg>", MAX_SVG_ELEMENTS) is None


def test_svg_path_without_d_refused_in_rbp_words(tmp_path):
    with pytest.raises(RbpInputError, match=r"a <path> without a d attribute") as e:
        read_rock(_svg(tmp_path, "<path/>" + SQUARE))
    assert "NoneType" not in str(e.value)


def test_svg_is_parsed_in_one_read():
    """iterparse reads 16 kB at a time, and expat rescans a token left unfinished by a read:
    a 30 MB comment took 18 s. One read hands expat each token whole."""
    text = HEAD + "<!--" + "y" * 100_000 + "-->" + SQUARE + "</svg>"
    whole = _Whole(text)
    assert whole.read(16 * 1024) == text
    assert whole.read(16 * 1024) == ""


def test_long_comment_pi_and_attribute_keep_the_rock(tmp_path):
    plain = read_rock(_svg(tmp_path, SQUARE, "plain.svg"))
    long = "y" * 1_000_000
    body = f'<!--{long}--><?x {long}?><g class="{long}">{SQUARE}</g>'
    assert [p.wkt for p in read_rock(_svg(tmp_path, body))] == [p.wkt for p in plain]


def _dxf_text(entities: int, closed: bool = True) -> str:
    """A DXF (ezdxf's minimal R12 layout) of `entities` TEXT and one LWPOLYLINE square."""
    text = "".join("0\nTEXT\n8\n0\n10\n0\n20\n0\n40\n1\n1\nx\n" for _ in range(entities))
    square = "".join(f"10\n{x}\n20\n{y}\n" for x, y in ((0, 0), (9, 0), (9, 9), (0, 9)))
    poly = f"0\nLWPOLYLINE\n8\n0\n90\n4\n70\n{1 if closed else 0}\n{square}"
    return f"0\nSECTION\n2\nENTITIES\n{text}{poly}0\nENDSEC\n0\nEOF\n"


def test_too_many_dxf_entities_refused_before_ezdxf(tmp_path):
    pytest.importorskip("ezdxf", reason="the extra rbp[import] is not installed")
    path = tmp_path / "many.dxf"
    path.write_text(_dxf_text(MAX_DXF_ENTITIES + 1, closed=False))
    with pytest.raises(RbpInputError, match=f"more than {MAX_DXF_ENTITIES:,} entities"):
        read_rock(path)


def test_dxf_entity_count_skips_values_of_zero():
    """A value "0" (a layer, a coordinate) is followed by a group code, not an entity type."""
    assert dxf_entities(_dxf_text(10), 5) == 6  # counting stops past the limit
    values = "0\nLWPOLYLINE\n" + "10\n0\n20\n0\n" * 100
    assert dxf_entities(values, 5) == 1


def test_dxf_below_the_entity_limit_is_read(tmp_path):
    ezdxf = pytest.importorskip("ezdxf", reason="the extra rbp[import] is not installed")
    doc = ezdxf.new()
    for k in range(1000):
        doc.modelspace().add_text(f"note {k}")
    doc.modelspace().add_lwpolyline([(0, 0), (9, 0), (9, 9), (0, 9)], close=True)
    doc.saveas(tmp_path / "text.dxf")
    assert [p.area for p in read_rock(tmp_path / "text.dxf")] == [81.0]
