"""Long climbs in segments (planning.segmented).

On the demo cave with a coarse lattice (as tests/test_route_repair.py) and segments short
enough that its 2.8 m climb takes several: the joined route is a route (one boom per edge,
every configuration of every edge holds, the last vertex holds the goal, its cost the sum of
its edges'), its lower bound is admissible (at most the proven optimum), a short climb is
searched whole exactly as without segments, a failed segment hands the climb to the whole
search, and the memo serves searches of one cave from other starts and to other goals only.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

import planning.segmented as segmented_module
from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.lattice import LatticeConfig
from planning.lattice_search import LatticeMemo
from planning.search_outcome import Stop
from planning.segmented import SegmentConfig, climb_distance, segmented_search
from rb_drake.errors import RbpInputError
from rb_drake.scenario import Scenario, bundled_caves, load_scenario
from tests.test_route_repair import _check_route

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)
SHORT = SegmentConfig(min_climb=1.0, lookahead=1.2, commit=0.6, tolerance=0.5)
CONFIG = CompleteConfig(COARSE, anytime=AnytimeConfig())


def _budget(_: Scenario) -> int:
    return 2000


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


@pytest.fixture(scope="module")
def segments(demo: Scenario):
    calls: list[Scenario] = []
    original = segmented_module.complete_search

    def traced(scn, config, **kwargs):
        calls.append(scn)
        return original(scn, config, **kwargs)

    segmented_module.complete_search = traced
    try:
        result = segmented_search(demo, CONFIG, SHORT, _budget, memo=LatticeMemo())
    finally:
        segmented_module.complete_search = original
    return result, calls


def test_segments_join_into_a_route(demo: Scenario, segments) -> None:
    result, calls = segments
    assert climb_distance(demo) > SHORT.min_climb
    assert result.success, result.reason
    assert len(calls) >= 2, f"a {climb_distance(demo):.2f} m climb took {len(calls)} segment(s)"
    assert all(c.goal_position != demo.goal_position for c in calls[:-1]), \
        "every segment but the last must search to a sub-goal"
    _check_route(demo, result)
    assert len(result.alternatives) == len(result.poses)


def test_segmented_bound_is_admissible(demo: Scenario, segments) -> None:
    result, _ = segments
    proved = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0,
                                                  anytime=AnytimeConfig(improve_factor=None)))
    assert proved.quality == "optimal", proved.quality
    assert result.lower_bound <= proved.cost * (1 + 1e-9), \
        f"lower bound {result.lower_bound:.6g} above the optimum {proved.cost:.6g}"
    assert result.cost >= proved.cost * (1 - 1e-9), "a route cheaper than the proven optimum"


def test_short_climb_is_searched_whole(demo: Scenario) -> None:
    whole = complete_search(demo, dataclasses.replace(CONFIG, max_expansions=2000))
    asked = segmented_search(demo, CONFIG, SegmentConfig(min_climb=10.0), _budget)
    assert [v[0] for v in asked.path] == [v[0] for v in whole.path], \
        "a climb shorter than min_climb must be the whole search's"
    assert asked.cost == pytest.approx(whole.cost, rel=1e-12)


def test_failed_segment_hands_over_to_the_whole_search(demo: Scenario, monkeypatch) -> None:
    original = segmented_module.complete_search
    seen = []

    def first_fails(scn, config, **kwargs):
        seen.append(scn.goal_position)
        result = original(scn, config, **kwargs)
        if len(seen) == 1:
            return result._replace(success=False, stop=Stop.BUDGET, path=[], poses=[])
        return result

    monkeypatch.setattr(segmented_module, "complete_search", first_fails)
    result = segmented_search(demo, CONFIG, SHORT, _budget)
    assert len(seen) == 2 and seen[1] == demo.goal_position, \
        "after a failed segment the whole climb must be searched to the real goal"
    whole = original(demo, dataclasses.replace(CONFIG, max_expansions=2000))
    assert [v[0] for v in result.path] == [v[0] for v in whole.path]
    assert result.expansions >= whole.expansions, "the failed segment's work must be counted"


def test_memo_serves_one_cave_from_any_start_to_any_goal(demo: Scenario) -> None:
    memo = LatticeMemo()
    complete_search(demo, CompleteConfig(COARSE, max_expansions=3), memo=memo)
    moved = dataclasses.replace(demo, goal_position=(0.0, 2.5), goal_tolerance=0.6)
    complete_search(moved, CompleteConfig(COARSE, max_expansions=3), memo=memo)  # accepted
    other = dataclasses.replace(demo, anchors=demo.anchors[:-1])
    with pytest.raises(ValueError, match="one scenario"):
        complete_search(other, CompleteConfig(COARSE, max_expansions=3), memo=memo)


@pytest.mark.parametrize("field,value", [("lookahead", 0.0), ("commit", -1.0),
                                         ("tolerance", float("inf")), ("min_climb", True)])
def test_segment_config_refuses_bad_values(field: str, value: object) -> None:
    with pytest.raises(RbpInputError) as err:
        SegmentConfig(**{field: value})
    assert err.value.field == f"footstep.segments.{field}"


def test_commit_beyond_lookahead_refused() -> None:
    with pytest.raises(RbpInputError, match="at most lookahead"):
        SegmentConfig(lookahead=2.0, commit=3.0)


def test_segments_keep_progress_counting(demo: Scenario) -> None:
    """The progress callback counts expansions over all segments: it never goes back."""
    counts: list[int] = []
    segmented_search(demo, CONFIG, SHORT, _budget,
                     progress=lambda n, tested, *a, **k: counts.append(n))
    assert counts, "no progress reported"
    assert all(b >= a for a, b in itertools.pairwise(counts)), \
        "the expansion count went back between segments"
    assert np.isfinite(counts[-1])
