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
from rb_drake.terrain.drawing_bounds import MAX_SVG_DEPTH, svg_markup
from rb_drake.terrain.polygon_files import MAX_SVG_ELEMENTS, _Whole, read_rock
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
