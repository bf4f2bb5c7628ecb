"""The anytime footstep search and its admissible bound (planning.search_cost, planning.complete).

On the demo cave with a coarse lattice (5 cm x 5 deg: the code is the same at any resolution):
the regrasp bound is consistent on every edge the search evaluated (so it never overestimates
the cost to go), A* on it returns Dijkstra's optimal cost, and the anytime search's answers
bracket that optimum: lower bound <= optimum <= cost, improving monotonically.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.footsteps import FootstepConfig, plan_footsteps
from planning.lattice import LatticeConfig, poses_of
from planning.lattice_kernels import reach_violation
from planning.plan import build_plan, validate
from planning.plan_model import plan_dict
from planning.search_cost import (
    ORIENTATION_CELLS,
    RegraspHeuristic,
    TravelHeuristic,
    boom_hop_length,
    edge_cost,
    goal_targets,
)
from rb_drake.scenario import Scenario, bundled_caves, load_scenario

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)
EXHAUSTIVE = AnytimeConfig(improve_factor=None)  # on until the optimum is proved


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


@pytest.fixture(scope="module")
def optimal(demo: Scenario):
    """A* on the admissible bound (weight 1), to the proof of optimality."""
    return complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0, anytime=EXHAUSTIVE))


def test_hop_length_is_the_chord_of_the_shoulder_range(demo: Scenario) -> None:
    robot = demo.robot  # +-45 deg about the axis: two full-length booms 90 deg apart
    assert boom_hop_length(robot) == pytest.approx(math.sqrt(2) * robot.boom_length[1], 1e-12)


def test_hop_graph_joins_exactly_the_anchors_within_a_hop(demo: Scenario) -> None:
    """The sparse hop graph (a k-d tree's pairs) has an edge, of the anchors' distance, for
    every pair of distinct anchors at most `boom_hop_length` apart and for no other."""
    from experiments.common import make_cave
    from planning.search_cost import hop_graph

    for scn in (demo, make_cave("crevasse", 5001, (20.0, 20.0))):
        pts = scn.anchor_positions
        distance = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        within = distance <= boom_hop_length(scn.robot) * (1 + 1e-9) + 1e-9
        np.fill_diagonal(within, False)
        graph = hop_graph(scn).toarray()
        assert within.sum() >= 2 * len(pts), "too few edges for the check to mean anything"
        assert np.array_equal(graph > 0, within), "the graph's edges differ from the pairs"
        assert np.allclose(graph[within], np.maximum(distance[within], 1e-12), rtol=1e-12)


def test_bound_is_consistent_on_every_evaluated_edge(demo: Scenario, optimal) -> None:
    bound = RegraspHeuristic(demo)
    edges = [(u, v, c) for u, v, c in optimal.graph.edges() if c is not None]
    assert len(edges) >= 20, f"only {len(edges)} edges evaluated: the check would be vacuous"
    worst = max(bound(u[0]) - c - bound(v) for u, v, c in edges)
    assert worst <= 1e-12, f"h(u) exceeds cost(u, v) + h(v) by {worst:.3g} on some edge"
    goal_stance = optimal.path[-1][0]
    assert bound(goal_stance) == 0.0, "the bound of the goal stance must be 0"
    assert math.isfinite(bound(tuple(demo.start_stance)))


def test_travel_bound_is_consistent_and_below_the_hop_bound(demo: Scenario, optimal) -> None:
    """The travel bound (the search's order): consistent on every evaluated edge, 0 at the goal
    stance, and never above the regrasp bound (a path of n hops is at most n hops long)."""
    travel, hops = TravelHeuristic(demo), RegraspHeuristic(demo)
    edges = [(u, v, c) for u, v, c in optimal.graph.edges() if c is not None]
    assert len(edges) >= 20, f"only {len(edges)} edges evaluated: the check would be vacuous"
    worst = max(travel(u[0]) - c - travel(v) for u, v, c in edges)
    assert worst <= 1e-12, f"travel h(u) exceeds cost(u, v) + h(v) by {worst:.3g} on some edge"
    assert travel(optimal.path[-1][0]) == 0.0, "the travel bound of the goal stance must be 0"
    stances = {u[0] for u, _, _ in edges} | {v for _, v, _ in edges}
    above = max(travel(s) - hops(s) for s in stances)
    assert above <= 1e-12, f"the travel bound exceeds the hop bound by {above:.3g}"
    assert sum(travel(s) > 0 for s in stances) >= len(stances) // 2, "travel is 0 almost always"


@pytest.mark.parametrize("name", ["regrasp", "travel"])
def test_bound_never_exceeds_the_cost_to_go(demo: Scenario, optimal, name: str) -> None:
    """h(v) <= the cheapest cost from v to the goal stance through the edges the exhaustive A*
    evaluated (its components merged, so no more than the true cost to go), at every stance
    that reaches it there."""
    import networkx as nx

    bound = RegraspHeuristic(demo) if name == "regrasp" else TravelHeuristic(demo)
    def stance(node: tuple) -> tuple:  # the search graph's nodes: vertices or stances
        return node[0] if len(node) == 2 else node

    graph = nx.DiGraph()  # over stances (components merged: a cost to go no higher)
    for u, v, c in optimal.graph.edges():
        if c is not None:
            graph.add_edge(stance(u), stance(v), cost=c)
    goal = stance(optimal.path[-1])
    to_go = nx.single_source_dijkstra_path_length(graph.reverse(copy=False), goal, weight="cost")
    assert len(to_go) >= 10, f"only {len(to_go)} stances reach the goal: the check is vacuous"
    worst = max(bound(v) - c for v, c in to_go.items())
    assert worst <= 1e-12, f"h exceeds the cost to go by {worst:.3g} at some stance"
    informative = sum(bound(v) > 0 for v in to_go)
    assert informative >= len(to_go) // 2, "the bound is 0 almost everywhere: it tests nothing"


def _targets_cover(demo: Scenario, poses: np.ndarray) -> int:
    """Assert every anchor boom j reaches from `poses` is a target of their orientation cell;
    return how many (pose, boom, anchor) reaches there were."""
    theta = (poses[:, 2] + math.pi) % (2 * math.pi) - math.pi
    cell = np.minimum(((theta + math.pi) / (2 * math.pi) * ORIENTATION_CELLS).astype(int),
                      ORIENTATION_CELLS - 1)
    targets = goal_targets(demo)
    anchors = demo.anchor_positions
    reached = 0
    for j in range(4):
        hit = reach_violation(demo.robot, poses, anchors, np.full(len(anchors), j)) == 0.0
        reached += int(hit.sum())
        missed = hit & ~targets[cell, j, :]
        assert not missed.any(), (
            f"boom {j} reaches anchor {np.argwhere(missed)[0][1]} from a goal pose in cell "
            f"{cell[np.argwhere(missed)[0][0]]} that goal_targets leaves out")
    return reached


def test_goal_targets_hold_every_anchor_a_goal_pose_reaches(demo: Scenario) -> None:
    """Every anchor that boom j reaches from a goal pose (centre within the tolerance, any
    orientation) is among the targets of that orientation's cell: brute force on random poses
    and on every lattice goal pose (the poses the search tests)."""
    rng = np.random.default_rng(7)
    n = 20000
    radius = demo.goal_tolerance * np.sqrt(rng.uniform(0, 1, n))
    angle = rng.uniform(-math.pi, math.pi, n)
    poses = np.column_stack([demo.goal_position[0] + radius * np.cos(angle),
                             demo.goal_position[1] + radius * np.sin(angle),
                             rng.uniform(-math.pi, math.pi, n)])
    assert _targets_cover(demo, poses) > 0, "no goal pose reaches an anchor: vacuous"
    step = COARSE.position_step
    r = math.ceil(demo.goal_tolerance / step)
    gi, gk = (round(c / step) for c in demo.goal_position)
    half = COARSE.angle_count // 2
    idx = np.array([(i, k, m) for i in range(gi - r, gi + r + 1)
                    for k in range(gk - r, gk + r + 1) for m in range(-half, half)])
    lattice = poses_of(idx, COARSE)
    near = np.linalg.norm(lattice[:, :2] - np.asarray(demo.goal_position), axis=1)
    assert _targets_cover(demo, lattice[near <= demo.goal_tolerance]) > 0
    # and the targets are not everything: the orientation cells tell the booms apart
    assert goal_targets(demo).mean() < 0.5


def test_edge_costs_are_the_route_cost(demo: Scenario, optimal) -> None:
    stances = [v[0] for v in optimal.path]
    total = 0.0
    for a, b, pose in zip(stances[:-1], stances[1:], optimal.poses, strict=True):
        j = next(i for i in range(4) if a[i] != b[i])
        total += edge_cost(demo, a, j, b[j], np.asarray(pose))
    assert total == pytest.approx(optimal.cost, rel=1e-9), "route cost != sum of edge costs"


def test_astar_on_the_bound_equals_dijkstra(demo: Scenario, optimal, monkeypatch) -> None:
    assert optimal.success and optimal.quality == "optimal"
    monkeypatch.setattr(RegraspHeuristic, "__call__", lambda self, stance: 0.0)
    dijkstra = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0,
                                                    anytime=EXHAUSTIVE))
    assert dijkstra.quality == "optimal"
    assert optimal.cost == pytest.approx(dijkstra.cost, rel=1e-9), (
        f"A* on the bound found cost {optimal.cost:.6f}, Dijkstra {dijkstra.cost:.6f}: the "
        "bound overestimates somewhere")
    assert optimal.expansions <= dijkstra.expansions


@pytest.mark.parametrize("ordering,weight", [("distance", 300.0), ("travel", 7.0),
                                             ("distance+travel", 300.0)])
def test_anytime_answers_bracket_the_optimum(demo: Scenario, optimal, ordering: str,
                                             weight: float) -> None:
    found = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=weight,
                                                 ordering=ordering, anytime=EXHAUSTIVE))
    assert found.success and found.quality == "optimal"
    assert found.cost == pytest.approx(optimal.cost, rel=1e-9)
    history = found.history
    assert history and history[0][1] == found.first_cost
    costs = [h[1] for h in history]
    lows = [h[2] for h in history]
    assert all(b <= a for a, b in itertools.pairwise(costs)), costs
    assert all(b >= a for a, b in itertools.pairwise(lows)), lows
    assert max(lows) <= optimal.cost * (1 + 1e-9), "a lower bound above the optimum"


@pytest.mark.parametrize("restart", [True, False])
def test_lower_bound_counts_the_vertex_being_expanded(demo: Scenario, optimal, monkeypatch,
                                                      restart: bool) -> None:
    """With the bound refreshed at every expansion, it is also taken while a vertex is popped
    and its successors not yet pushed (after a restart, the start alone, with the open list
    empty): that vertex must count, or the search proves a wrong optimum."""
    import planning.complete as complete_module

    monkeypatch.setattr(complete_module, "BOUND_EVERY", 1)
    found = complete_search(demo, CompleteConfig(
        COARSE, heuristic_weight=300.0,
        anytime=AnytimeConfig(improve_factor=None, restart=restart)))
    assert found.success and found.quality == "optimal"
    assert found.cost == pytest.approx(optimal.cost, rel=1e-9), (
        f"claimed optimal at {found.cost:.6f}; the optimum is {optimal.cost:.6f}")
    assert all(lo <= optimal.cost * (1 + 1e-9) for _, _, lo, _ in found.history), (
        "a lower bound above the optimum")


@pytest.mark.parametrize("corridor", [0.0, 0.2, 0.6])
def test_corridor_keeps_the_lower_bound_proven(demo: Scenario, optimal, monkeypatch,
                                               corridor: float) -> None:
    """Passes confined to a corridor about the best route leave moves out; their least
    g + bound stays in the lower bound, so no bound exceeds the optimum (refreshed at every
    expansion, the strictest test), and a narrow corridor may leave the optimum unproven. A
    corridor of width 0 keeps the passes on the first route's own line: there, a bound that
    forgot the moves left out would call the first route (1.27x the optimum) optimal."""
    import planning.complete as complete_module

    monkeypatch.setattr(complete_module, "BOUND_EVERY", 1)
    found = complete_search(demo, CompleteConfig(
        COARSE, heuristic_weight=300.0,
        anytime=AnytimeConfig(improve_factor=None, corridor=corridor)))
    assert found.success
    assert found.cost >= optimal.cost * (1 - 1e-9), "a route cheaper than the optimum"
    assert all(lo <= optimal.cost * (1 + 1e-9) for _, _, lo, _ in found.history), (
        f"a lower bound above the optimum {optimal.cost:.6f}: {found.history}")
    assert found.lower_bound <= optimal.cost * (1 + 1e-9)
    if found.quality == "optimal":
        assert found.cost == pytest.approx(optimal.cost, rel=1e-9)


def test_target_bound_stops_within_it(demo: Scenario, optimal) -> None:
    found = complete_search(demo, CompleteConfig(
        COARSE, heuristic_weight=300.0,
        anytime=AnytimeConfig(improve_factor=None, target_bound=1.5)))
    assert found.success
    assert found.cost <= 1.5 * found.lower_bound * (1 + 1e-12)
    assert found.lower_bound <= optimal.cost * (1 + 1e-9) <= found.cost * (1 + 2e-9)


def test_plan_file_records_cost_and_bound(demo: Scenario, optimal) -> None:
    """The default's budget (twice the first route's expansions): a route no worse than the
    first, its bound and history in the plan file, and the same plan twice (work, not time)."""
    config = FootstepConfig(lattice=COARSE, polish_rounds=0)
    fp = plan_footsteps(demo, config)
    plan = plan_dict(build_plan(demo, fp, "rbp"))
    validate(plan)
    search = plan["search"]
    assert search["quality"] in ("optimal", "bounded")
    assert search["bound"] == pytest.approx(search["cost"] / search["lower_bound"], rel=1e-12)
    assert search["lower_bound"] <= optimal.cost * (1 + 1e-9) <= search["cost"] * (1 + 2e-9)
    assert search["cost"] <= search["first_cost"] + 1e-12
    assert search["history"] and search["history"][-1]["cost"] == search["cost"]
    again = plan_footsteps(demo, config)
    assert again.stances == fp.stances and again.cost == fp.cost, "not reproducible"


@pytest.mark.parametrize("setting, field", [("{target_bound: 0.5}", "target_bound"),
                                            ("{improve_factor: -1}", "improve_factor"),
                                            ("{weights: [10, 0]}", "weights"),
                                            ("{corridor: -0.5}", "corridor")])
def test_bad_anytime_settings_get_one_line(tmp_path, setting: str, field: str) -> None:
    from cli_helpers import run_rbp

    config = tmp_path / "planner.yaml"
    config.write_text(f"footstep:\n  anytime: {setting}\n")
    out = tmp_path / "plan.json"
    run = run_rbp("plan", "demo-shaft", "--config", str(config), "-o", str(out),
                  cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"footstep.anytime.{field}" in lines[0], run.stderr
    assert not out.exists(), "no plan may be written for a refused configuration"


@pytest.mark.parametrize("setting, field", [("ordering: sideways", "footstep.ordering"),
                                            ("segments: {commit: 9}", "footstep.segments.commit"),
                                            ("segments: {lookahead: -1}",
                                             "footstep.segments.lookahead")])
def test_bad_order_and_segment_settings_get_one_line(tmp_path, setting: str, field: str) -> None:
    from cli_helpers import run_rbp

    config = tmp_path / "planner.yaml"
    config.write_text(f"footstep:\n  {setting}\n")
    out = tmp_path / "plan.json"
    run = run_rbp("plan", "demo-shaft", "--config", str(config), "-o", str(out), cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], run.stderr
    assert not out.exists(), "no plan may be written for a refused configuration"
