"""Hostile scenarios and imports (issue 32, probe round 5): a drawing of thousands of small
polygons refused before the start and goal search, and messages that state their limits as
the checks apply them. Work is counted, never timed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rb_drake.collision import Rock
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import rock_inside_body


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
