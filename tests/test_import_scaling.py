"""Importing long drawn outlines: the work grows with the outline's vertices about linearly
(issue 32 T10: a valid 45,000-vertex GeoJSON outline ran past 60 s, its boom lines tested
against every edge near them). Work is counted, never timed."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rb_drake import collision
from rb_drake.collision import Rock
from rb_drake.errors import RbpInputError
from rb_drake.terrain.import_cave import import_cave

pytest.importorskip("shapely")


def wiggle_rings(n: int) -> list[list[list[float]]]:
    """A shaft: a left wall of `n` vertices wiggling 5 cm about x = -1, a plain right wall."""
    k = np.arange(n)
    wall = np.stack([-1.0 + 0.05 * np.sin(0.4 * k), -0.5 + 6.5 * k / n], axis=1)
    left = [[-2.0, -0.5], *wall.tolist(), [-2.0, 6.0], [-2.0, -0.5]]
    right = [[2.0, -0.5], [2.0, 6.0], [1.0, 6.0], [1.0, -0.5], [2.0, -0.5]]
    return [left, right]


def write_outline(path, n: int):
    path.write_text(json.dumps({"type": "MultiPolygon",
                                "coordinates": [[ring] for ring in wiggle_rings(n)]}))
    return path


class PairCount:
    """The segment x edge pairs the crossing tests compute, dense and indexed."""

    def __init__(self, monkeypatch):
        self.dense = self.indexed = 0
        dense, pairs = collision._segments_cross, collision._pairs_cross

        def count_dense(a, b, c, d):
            self.dense += len(a) * len(c)
            return dense(a, b, c, d)

        def count_pairs(a, b, c, d):
            self.indexed += len(a)
            return pairs(a, b, c, d)

        monkeypatch.setattr(collision, "_segments_cross", count_dense)
        monkeypatch.setattr(collision, "_pairs_cross", count_pairs)


def test_indexed_crossings_match_the_dense_test(monkeypatch):
    """On rock of more than INDEX_EDGES edges the quadtree finds every crossing the test of
    all pairs finds: random lines, lines along edges and lines ending on vertices."""
    rings = wiggle_rings(6000)
    rock = Rock([np.array(r[:-1]) for r in rings])
    assert len(rock.edge_start) > collision.INDEX_EDGES
    rng = np.random.default_rng(3)
    a = rng.uniform([-2.2, -0.7], [2.2, 6.2], (3000, 2))
    b = a + rng.normal(0.0, 0.8, (3000, 2))
    wall = np.array(rings[0][:-1])
    a = np.vstack([a, wall[:500], wall[:500], [[-1e308, 0.0]]])
    b = np.vstack([b, wall[1:501], wall[:500] + np.array([0.3, 0.0]), [[1e308, 1.0]]])
    with np.errstate(over="ignore", invalid="ignore"):  # the 1e308 line, in both tests
        fast = rock.segments_hit(a, b, inside=False)
        monkeypatch.setattr(collision, "INDEX_EDGES", math.inf)
        dense = np.concatenate([rock.segments_hit(a[k:k + 256], b[k:k + 256], inside=False)
                                for k in range(0, len(a), 256)])
    np.testing.assert_array_equal(fast, dense)
    assert fast.sum() > 100  # the lines do meet rock


def test_long_outline_imports_with_few_pair_tests(tmp_path, monkeypatch):
    """An 8,000-vertex outline: the boom and body lines are tested against the edges near
    them: 8 million line-edge pairs, most in small batches of few edges (before: each batch
    of lines against every edge in its box, 81 million pairs)."""
    count = PairCount(monkeypatch)
    scn = import_cave(write_outline(tmp_path / "wiggle.geojson", 8000))
    assert len(scn.walls[0]) > 8000 and len(scn.anchors) > 100
    assert count.indexed > 0  # the quadtree was used
    assert count.dense + count.indexed < 20_000_000

def test_outline_over_the_values_limit_refused_before_the_work(tmp_path, monkeypatch):
    """A 20,000-vertex outline makes a file of more than 50,000 values: refused as soon as
    its walls are known, before any line is tested (was: after the whole import)."""
    calls = []
    monkeypatch.setattr(Rock, "segments_hit", lambda *a, **k: calls.append(1))
    with pytest.raises(RbpInputError, match=r"at least 60,\d{3} values, over the limit of "
                                             r"50,000"):
        import_cave(write_outline(tmp_path / "big.geojson", 20000))
    assert not calls
