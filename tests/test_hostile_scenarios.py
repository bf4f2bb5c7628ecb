"""Hostile scenarios and imports (issue 32, probe round 5): a drawing of thousands of small
polygons refused before the start and goal search, and messages that state their limits as
the checks apply them. Work is counted, never timed."""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import pytest
import yaml

from rb_drake.collision import Rock
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import rock_inside_body
from rb_drake.scenario import ScenarioError, scenario_from_dict


def many_triangles(path, n: int):
    """A 4 m-wide shaft of two walls and `n` 1 cm triangles in a row beside it."""
    walls = [[[-2, 0], [-1.2, 0], [-1.1, 8], [-2, 8], [-2, 0]],
             [[1.2, 0], [2, 0], [2, 8], [1.2, 8], [1.2, 0]]]
    tris = [[[10 + 0.02 * k, 10], [10.01 + 0.02 * k, 10], [10 + 0.02 * k, 10.01],
             [10 + 0.02 * k, 10]] for k in range(n)]
    geom = {"type": "MultiPolygon", "coordinates": [[ring] for ring in walls + tris]}
    path.write_text(json.dumps({"type": "Feature", "geometry": geom, "properties": {}}))
    return path


def test_many_small_polygons_refused_before_the_start_and_goal(tmp_path, monkeypatch):
    """Walls within the values limit, walls and anchors over it: the exact count of the file
    to write is refused once the anchors are placed, before the grid of start and goal
    candidates (4,000 triangles: 29.5 s, 990 MB to the same refusal, was)."""
    pytest.importorskip("shapely")
    from rb_drake.terrain import cave_from_rock
    from rb_drake.terrain.import_cave import import_cave

    monkeypatch.setenv("RBP_MAX_INPUT_VALUES", "5000")
    calls = []
    monkeypatch.setattr(cave_from_rock, "_Grid", lambda *a: calls.append(1))
    monkeypatch.setattr(Rock, "segments_hit", lambda *a, **k: calls.append(1))
    with pytest.raises(RbpInputError, match=r"would hold 5,\d{3} values, over the limit of 5,0"):
        import_cave(many_triangles(tmp_path / "tri.geojson", 250))
    assert not calls


def test_rock_inside_body_screens_by_box():
    """Only vertices in the squares' box are tested; a NaN pose does not hide the others."""
    tri = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]])
    rock = Rock([tri + np.array([x, 0.0]) for x in range(50)])
    square = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    corners = np.stack([square + np.array([3.0, 0.0]), square + np.array([3.0, 5.0]),
                        np.full((4, 2), np.nan)])
    assert rock_inside_body(rock, corners).tolist() == [True, False, False]
    assert rock_inside_body(rock, corners[:0]).shape == (0,)


def two_walls() -> dict[str, Any]:
    """A 2.4 m shaft whose start stance holds: anchors a0 and a3 on the right wall (x = 1.2)."""
    def anchor(aid: str, x: float, y: float, normal: Any) -> dict[str, Any]:
        return {"id": aid, "position": [x, y], "normal": normal,
                "limit": {"normal": 40, "lateral": 20}, "sigma": {"normal": 3, "lateral": 5}}

    return {"format": "reachbot-scenario/1", "name": "two-walls", "gravity": [0.0, -3.71],
            "walls": [[[-2.0, 0.0], [-1.2, 0.0], [-1.1, 8.0], [-2.0, 8.0]],
                      [[1.2, 0.0], [2.0, 0.0], [2.0, 8.0], [1.2, 8.0]]],
            "anchors": [anchor("a0", 1.2, 2.0, 180), anchor("a1", -1.175, 2.0, [1.0, 0.0]),
                        anchor("a2", -1.2, 0.3, [1.0, 0.0]), anchor("a3", 1.2, 0.3, 180)],
            "start": {"pose": [0.0, 1.0, 0.0], "stance": ["a0", "a1", "a2", "a3"]},
            "goal": {"position": [0.0, 7.0], "tolerance": 0.5}}


def reason(data: dict[str, Any], check_start: bool = False) -> str:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, "s.yaml", check_start=check_start)
    return str(info.value)


@pytest.mark.parametrize("x", [1.15, 1.21])
def test_anchor_exactly_at_a_tolerance_is_accepted(x):
    """0.05 m off the wall and 0.01 m inside it are allowed: written so, they are (their
    computed distances are a rounding over the limit, and were refused)."""
    data = two_walls()
    data["anchors"][0]["position"] = [x, 2.0]
    assert scenario_from_dict(data, "s.yaml").anchors[0].position == (x, 2.0)


@pytest.mark.parametrize("x, words", [  # the right wall's face is x = 1.2, rock beyond
    (1.1499999, "is off its wall: 0.0500001 m from the nearest rock surface (at most 0.05 m)"),
    (1.1, "is off its wall: 0.100 m from the nearest rock surface (at most 0.05 m)"),
    (1.2100001, "is inside rock: 0.0100001 m from the surface (at most 0.01 m inside)"),
    (1.4, "is inside rock: 0.200 m from the surface (at most 0.01 m inside)")])
def test_anchor_past_a_tolerance_states_it(x, words):
    data = two_walls()
    data["anchors"][0]["position"] = [x, 2.0]
    assert reason(data).endswith(words)


def test_p_min_1_refusal_reads_below_it():
    """p_min 1 is met only where every boom's probability rounds to 1.0: the refusal prints
    the probability with the digits that show it below (was 'probability 1.000 below p_min 1.0')."""
    data = two_walls()
    data["robot"] = {"p_min": 1}
    text = reason(data, check_start=True)
    got = re.search(r"probability (\S+) below p_min 1", text)
    assert got and float(got.group(1)) < 1.0 and got.group(1) != "1.000", text


def test_tiny_edge_names_its_tolerance():
    data = two_walls()
    data["walls"].append([[5.0, 5.0], [5.0 + 1e-15, 5.0], [5.0, 5.0 + 1e-15]])
    assert reason(data).endswith("walls[2]: not a simple polygon: vertices 0 and 1 are 8.88e-16 "
                                 "m apart, closer than 1e-12 m (a repeated vertex)")


@pytest.mark.parametrize("aid, words", [
    ("", "an anchor id must not be empty or only spaces, got ''"),
    (" \t", "an anchor id must not be empty or only spaces"),
    ("\u202eabc", r"anchor id '\u202eabc' holds the invisible or control character U+202E (Cf)"),
    ("a\u200b", "U+200B (Cf)"),
    ("a\nb", "U+000A (Cc)"),
    ("e\u0301", "duplicate anchor id 'e\u0301' ('e\\u0301': the same as '\\xe9' once "),
    ("\u00e9", "duplicate anchor id 'é'")])
def test_anchor_ids_are_visible_and_distinct(aid, words):
    data = two_walls()
    data["anchors"][1]["id"] = "\u00e9"
    data["anchors"][3]["id"] = aid
    data["start"]["stance"] = ["a0", "\u00e9", "a2", aid]
    text = reason(data)
    assert "anchors[3].id: " in text and words in text, text
    assert text.isprintable()


def test_scenario_check_summary_escapes_user_text(tmp_path, capsys):
    """A name holding U+202E (reversing what follows on a terminal) is escaped on stdout."""
    from rbp import cli

    data = two_walls()
    data["name"] = "\u202eevil"
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True))
    assert cli.main(["scenario", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.isprintable() or out.replace("\n", "").isprintable()
    assert r"ok: \u202eevil" in out


def test_long_scenario_name_reads_as_other_files(tmp_path, capsys):
    """A path whose name is too long for the system: '(file): cannot read:' as the plan and
    configuration readers say (was the bare OSError text)."""
    from rbp import cli

    assert cli.main(["scenario", "check", str(tmp_path / ("x" * 300 + ".yaml"))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(".yaml: (file): cannot read: File name too long")
