"""Route repair (planning.route_repair): windows of a route searched again to their optimum.

On the demo cave with a coarse lattice (5 cm x 5 deg, as tests/test_anytime.py): a repaired
route is a route (one boom moves per edge, each edge's pose holds all four configurations on
the lattice, the last vertex holds the goal), its reported cost is the sum of its edge costs
and never exceeds the route it started from, and with one window as long as the route and no
expansion limit, the repair is A* from the start and returns the proven optimum.
"""

from __future__ import annotations

import numpy as np
import pytest

from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.lattice import LatticeConfig
from planning.lattice_search import LatticeMemo
from planning.route_repair import RepairConfig, repair_route
from planning.search_cost import edge_cost
from rb_drake.feasibility import check_poses
from rb_drake.scenario import Scenario, bundled_caves, load_scenario

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


@pytest.fixture(scope="module")
def first(demo: Scenario):
    """The first route (weight 300, no anytime search) and the memo its search filled."""
    memo = LatticeMemo()
    result = complete_search(demo, CompleteConfig(COARSE), memo=memo)
    assert result.success, result.reason
    return result, memo


@pytest.fixture(scope="module")
def optimum(demo: Scenario) -> float:
    proved = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0,
                                                  anytime=AnytimeConfig(improve_factor=None)))
    assert proved.quality == "optimal", proved.quality
    return proved.cost


def _check_route(scn: Scenario, result) -> None:
    stances = [v[0] for v in result.path]
    assert stances[0] == tuple(scn.start_stance), "the route must leave from the start stance"
    total = 0.0
    for k, (a, b, pose) in enumerate(zip(stances[:-1], stances[1:], result.poses, strict=True)):
        moved = [j for j in range(4) if a[j] != b[j]]
        assert len(moved) == 1, f"edge {k}: {a} -> {b} moves {len(moved)} booms"
        j = moved[0]
        three = scn.stance(tuple(None if i == j else x for i, x in enumerate(a)))
        at = np.asarray(pose, dtype=float)[None, :]
        checks = [("old 4-stance", check_poses(scn, scn.stance(a), at)),
                  ("new 4-stance", check_poses(scn, scn.stance(b), at))]
        for name, anchor in (("release", a[j]), ("attach", b[j])):
            tip = scn.anchor_positions[scn.anchor_index[anchor]]
            checks.append((name, check_poses(scn, three, at, free_tip=tip)))
        for name, check in checks:
            assert bool(check.feasible[0]), f"edge {k} ({a} -> {b}): {name} fails at {pose}"
        total += edge_cost(scn, a, j, b[j], pose)
    assert total == pytest.approx(result.cost, rel=1e-9), "cost is not the sum of edge costs"
    goal = np.asarray(scn.goal_position)
    assert np.linalg.norm(result.goal_pose[:2] - goal) <= scn.goal_tolerance + 1e-9, \
        "the route's goal pose is outside the goal tolerance"


def test_repaired_route_is_a_route_and_no_dearer(demo: Scenario, first) -> None:
    result, memo = first
    repaired = repair_route(demo, result, memo, RepairConfig(window=3, stride=2))
    # here the first route is not the cheapest within windows of 3: the repair has work to do
    assert repaired.cost < result.cost * (1 - 1e-3), (repaired.cost, result.cost)
    _check_route(demo, repaired)


def test_one_window_over_the_whole_route_is_optimal(demo: Scenario, first, optimum) -> None:
    result, memo = first
    whole = RepairConfig(window=len(result.path), window_expansions=10**9, passes=1)
    repaired = repair_route(demo, result, memo, whole)
    assert repaired.cost == pytest.approx(optimum, rel=1e-9), \
        f"A* over the whole route gave {repaired.cost:.6g}, the proven optimum is {optimum:.6g}"
    _check_route(demo, repaired)


def test_repair_is_deterministic(demo: Scenario, first) -> None:
    """The same search and repair, from a fresh memo, give the same route."""
    result, memo = first
    a = repair_route(demo, result, memo, RepairConfig(window=3, stride=2))
    fresh = LatticeMemo()
    again = complete_search(demo, CompleteConfig(COARSE), memo=fresh)
    b = repair_route(demo, again, fresh, RepairConfig(window=3, stride=2))
    assert [v[0] for v in a.path] == [v[0] for v in b.path], "a fresh memo changed the route"
    assert a.cost == pytest.approx(b.cost, rel=1e-12)


def test_cli_repair_flag_and_config(tmp_path) -> None:
    """`rbp plan --repair` records the repair in the plan's configuration and returns a route
    no dearer than the default's; a bad repair setting gets one line naming its field."""
    import json

    from tests.cli_helpers import run_rbp

    runs = {}
    for name, extra in (("default", ()), ("repair", ("--repair",))):
        result = run_rbp("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "-o",
                         f"{name}.json", *extra, cwd=tmp_path)
        assert result.returncode == 0, result.stderr[-2000:]
        runs[name] = json.loads((tmp_path / f"{name}.json").read_text())
    repair = runs["repair"]["provenance"]["config"]["footstep"]["repair"]
    assert repair is not None and repair["window"] >= 1, repair
    assert runs["default"]["provenance"]["config"]["footstep"]["repair"] is None
    assert runs["repair"]["search"]["cost"] <= runs["default"]["search"]["cost"] * (1 + 1e-9)
    (tmp_path / "bad.yaml").write_text("footstep:\n  repair: {window: 0}\n")
    bad = run_rbp("plan", "demo-shaft", "--footsteps-only", "--config", "bad.yaml", "-o",
                  "bad.json", cwd=tmp_path)
    assert bad.returncode == 2 and "footstep.repair.window" in bad.stderr, bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1, bad.stderr
