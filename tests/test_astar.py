"""Lazy weighted A* (planning.astar.lazy_astar) on small hand-built graphs.

Graphs are dicts node -> [(child, cost)]; `infeasible` edges are offered by `successors` (with
a lower bound) but `evaluate` returns None for them, as for a transition with no holding pose.
networkx's Dijkstra on the feasible edges is the reference optimum.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable, Hashable, Mapping

import networkx as nx
import numpy as np
import pytest

from planning.astar import Edge, SearchResult, lazy_astar

Graph = Mapping[Hashable, list[tuple[Hashable, float]]]
REL = 1e-9  # relative tolerance on path costs (sums of a few floats)


class Recorder:
    """successors / evaluate / is_goal callbacks over a dict graph, recording every call."""

    def __init__(self, graph: Graph, goal: Hashable, infeasible: set = frozenset(),
                 lower_factor: float = 0.5):
        self.graph = graph
        self.goal = goal
        self.infeasible = set(infeasible)
        self.lower_factor = lower_factor
        self.evaluated: Counter = Counter()       # (parent, child) -> evaluate calls
        self.feasible_evaluated: dict = {}        # (parent, child) -> cost returned
        self.node_data_seen: dict = {}            # node -> node_data passed to successors

    def cost(self, u: Hashable, v: Hashable) -> float:
        return next(c for w, c in self.graph.get(u, []) if w == v)

    def successors(self, node: Hashable, node_data):
        self.node_data_seen[node] = node_data
        for child, cost in self.graph.get(node, []):
            yield child, ("key", node, child), self.lower_factor * cost

    def evaluate(self, parent: Hashable, child: Hashable, key, parent_data) -> Edge | None:
        assert key == ("key", parent, child), f"edge key {key!r} not the one yielded"
        assert parent_data == self.node_data_seen[parent], (
            f"evaluate({parent!r}, {child!r}) got parent_data {parent_data!r}, but successors "
            f"saw {self.node_data_seen[parent]!r}")
        self.evaluated[(parent, child)] += 1
        if (parent, child) in self.infeasible:
            return None
        cost = self.cost(parent, child)
        self.feasible_evaluated[(parent, child)] = cost
        return Edge(cost, ("edge", parent, child))

    def is_goal(self, node: Hashable, data):
        return {"reached": node} if node == self.goal else None


def to_nx(graph: Graph, skip: set = frozenset()) -> nx.DiGraph:
    g = nx.DiGraph()
    g.add_nodes_from(graph)
    for u, edges in graph.items():
        for v, c in edges:
            if (u, v) not in skip:
                g.add_edge(u, v, weight=c)
    return g


def exact_distance(graph: Graph, goal: Hashable) -> dict:
    """Cost-to-go on the full graph (feasible or not): a consistent lower bound."""
    return nx.single_source_dijkstra_path_length(to_nx(graph).reverse(copy=True), goal)


def scaled_heuristic(graph: Graph, goal: Hashable, scale: float) -> Callable[[Hashable], float]:
    dist = exact_distance(graph, goal)
    return lambda n: scale * dist.get(n, math.inf)


def search(rec: Recorder, start: Hashable, heuristic: Callable[[Hashable], float],
           weight: float = 1.0, max_expansions: int = 1000) -> SearchResult:
    return lazy_astar(start, rec.successors, rec.evaluate, heuristic, rec.is_goal,
                      weight=weight, max_expansions=max_expansions, start_data=("start-data",))


def path_cost(rec: Recorder, path: list) -> float:
    return sum(rec.cost(u, v) for u, v in itertools.pairwise(path))


def assert_valid_result(rec: Recorder, res: SearchResult, start: Hashable) -> None:
    """The path is a chain of feasible graph edges; cost, edge data and goal data agree."""
    assert res.success, f"search failed: {res.reason}"
    assert res.path[0] == start and res.path[-1] == rec.goal, f"path {res.path} not start->goal"
    pairs = list(itertools.pairwise(res.path))
    for u, v in pairs:
        assert any(w == v for w, _ in rec.graph.get(u, [])), f"{u}->{v} is not a graph edge"
        assert (u, v) not in rec.infeasible, f"path {res.path} uses infeasible edge {u}->{v}"
    assert math.isclose(res.cost, path_cost(rec, res.path), rel_tol=REL, abs_tol=1e-12), (
        f"reported cost {res.cost} != summed edge costs {path_cost(rec, res.path)}")
    assert res.edges == [("edge", u, v) for u, v in pairs], "edge data not in path order"
    assert res.goal_data == {"reached": rec.goal}, f"goal data {res.goal_data!r}"
    assert res.reason == "", f"successful search with reason {res.reason!r}"


def assert_lazy_bookkeeping(rec: Recorder, res: SearchResult) -> None:
    """Each (parent, child) evaluated at most once; the DiGraph holds exactly the evaluated
    feasible edges with their costs, and never an infeasible one."""
    repeats = {e: n for e, n in rec.evaluated.items() if n > 1}
    assert not repeats, f"edges evaluated more than once: {repeats}"
    assert res.evaluations == sum(rec.evaluated.values()), (
        f"evaluations {res.evaluations} != evaluate calls {sum(rec.evaluated.values())}")
    assert set(res.graph.edges) == set(rec.feasible_evaluated), (
        f"graph edges {sorted(res.graph.edges)} != evaluated feasible edges "
        f"{sorted(rec.feasible_evaluated)}")
    for (u, v), cost in rec.feasible_evaluated.items():
        assert res.graph.edges[u, v]["cost"] == pytest.approx(cost, rel=REL), (
            f"graph cost of {u}->{v}: {res.graph.edges[u, v]['cost']} != {cost}")
        assert res.graph.edges[u, v]["data"] == ("edge", u, v), f"graph data of {u}->{v}"
    bad = set(res.graph.edges) & rec.infeasible
    assert not bad, f"infeasible edges in the explored graph: {bad}"


# ---------------------------------------------------------------------------------------------
# (a) a hand-drawn trap: the cheapest first edge leads to an expensive detour

TRAP: dict[str, list[tuple[str, float]]] = {
    "S": [("A", 1.0), ("C", 3.0)],
    "A": [("B", 10.0)],           # cheap start, expensive continuation
    "B": [("G", 1.0)],
    "C": [("D", 1.5)],
    "D": [("G", 1.5)],            # S-C-D-G = 6 < S-A-B-G = 12
    "G": [],
}


@pytest.mark.parametrize("heuristic_scale", [0.0, 0.5, 1.0], ids=["h0", "h-half", "h-exact"])
@pytest.mark.parametrize("lower_factor", [0.0, 0.5, 1.0], ids=["lb0", "lb-half", "lb-tight"])
def test_trap_graph_returns_optimal_path(heuristic_scale: float, lower_factor: float) -> None:
    rec = Recorder(TRAP, "G", lower_factor=lower_factor)
    res = search(rec, "S", scaled_heuristic(TRAP, "G", heuristic_scale))
    assert_valid_result(rec, res, "S")
    ref = nx.dijkstra_path(to_nx(TRAP), "S", "G")
    assert res.path == ref == ["S", "C", "D", "G"], f"path {res.path}, networkx {ref}"
    assert res.cost == pytest.approx(6.0, rel=REL), f"cost {res.cost}, optimum 6"
    assert_lazy_bookkeeping(rec, res)
    # B is reached with g = 11 > 6 at best, so it is never expanded and B->G never evaluated.
    assert rec.evaluated[("B", "G")] == 0, "B->G evaluated although B (g=11) is past the goal"


def test_trap_graph_node_data_flows_along_edges() -> None:
    """successors sees start_data at the start and the incoming edge's data elsewhere."""
    rec = Recorder(TRAP, "G")
    res = search(rec, "S", lambda n: 0.0)
    assert res.success, res.reason
    assert rec.node_data_seen["S"] == ("start-data",), rec.node_data_seen["S"]
    assert rec.node_data_seen["C"] == ("edge", "S", "C"), rec.node_data_seen["C"]
    assert rec.node_data_seen["D"] == ("edge", "C", "D"), rec.node_data_seen["D"]


def test_trap_with_infeasible_shortcut_takes_the_detour() -> None:
    """Marking C->D infeasible makes the 'trap' the only way; it must never use C->D."""
    rec = Recorder(TRAP, "G", infeasible={("C", "D")})
    res = search(rec, "S", scaled_heuristic(TRAP, "G", 0.5))
    assert_valid_result(rec, res, "S")
    assert res.path == ["S", "A", "B", "G"], f"path {res.path}"
    assert res.cost == pytest.approx(12.0, rel=REL), f"cost {res.cost}, optimum 12"
    assert rec.evaluated[("C", "D")] == 1, "the infeasible edge should be tried exactly once"
    assert_lazy_bookkeeping(rec, res)


# ---------------------------------------------------------------------------------------------
# (b) random DAG-ish graphs against networkx


def random_graph(seed: int, n: int = 25) -> tuple[dict[int, list[tuple[int, float]]], set]:
    """Forward edges (always i -> i+1, others at random), a few backward edges, positive costs;
    ~15% of the edges infeasible. Start 0, goal n - 1."""
    rng = np.random.default_rng(seed)
    graph: dict[int, list[tuple[int, float]]] = {i: [] for i in range(n)}
    for i in range(n - 1):
        children = {i + 1} | {int(j) for j in rng.integers(i + 1, n, size=rng.integers(0, 4))}
        if i > 2 and rng.uniform() < 0.3:
            children.add(int(rng.integers(0, i)))  # a back edge: not quite a DAG
        for j in sorted(children):
            graph[i].append((j, float(rng.uniform(0.1, 5.0))))
    edges = [(u, v) for u in graph for v, _ in graph[u]]
    infeasible = {edges[k] for k in np.flatnonzero(rng.uniform(size=len(edges)) < 0.15)}
    return graph, infeasible


SEEDS = list(range(20))


@pytest.mark.parametrize("heuristic_scale", [0.0, 0.5], ids=["h0", "h-half-exact"])
@pytest.mark.parametrize("seed", SEEDS)
def test_random_graphs_match_dijkstra(seed: int, heuristic_scale: float) -> None:
    graph, infeasible = random_graph(seed)
    goal = max(graph)
    rec = Recorder(graph, goal, infeasible)
    res = search(rec, 0, scaled_heuristic(graph, goal, heuristic_scale))
    feasible = to_nx(graph, skip=infeasible)
    assert_lazy_bookkeeping(rec, res)
    if not nx.has_path(feasible, 0, goal):
        assert not res.success, f"seed {seed}: goal unreachable but search returned {res.path}"
        assert res.path == [] and res.cost == math.inf, (res.path, res.cost)
        return
    assert_valid_result(rec, res, 0)
    opt = nx.dijkstra_path_length(feasible, 0, goal)
    assert res.cost == pytest.approx(opt, rel=REL), (
        f"seed {seed}: cost {res.cost} != optimum {opt} (path {res.path}, networkx "
        f"{nx.dijkstra_path(feasible, 0, goal)})")


def test_random_graphs_are_not_trivial() -> None:
    """Most seeds reach the goal, and several only round infeasible edges that lie on the
    unconstrained optimum, so the comparisons above are not vacuous."""
    reachable = detours = 0
    for seed in SEEDS:
        graph, infeasible = random_graph(seed)
        goal = max(graph)
        feasible = to_nx(graph, skip=infeasible)
        if nx.has_path(feasible, 0, goal):
            reachable += 1
            full = nx.dijkstra_path_length(to_nx(graph), 0, goal)
            detours += nx.dijkstra_path_length(feasible, 0, goal) > full * (1 + 1e-9)
    assert reachable >= 12, f"only {reachable} of {len(SEEDS)} seeds reach the goal"
    assert detours >= 3, f"only {detours} seeds force a detour round infeasible edges"


@pytest.mark.parametrize("weight", [1.5, 2.0, 4.0])
@pytest.mark.parametrize("seed", SEEDS)
def test_weighted_search_is_bounded_suboptimal(seed: int, weight: float) -> None:
    graph, infeasible = random_graph(seed)
    goal = max(graph)
    feasible = to_nx(graph, skip=infeasible)
    rec = Recorder(graph, goal, infeasible)
    res = search(rec, 0, scaled_heuristic(graph, goal, 1.0), weight=weight)
    assert_lazy_bookkeeping(rec, res)
    if not nx.has_path(feasible, 0, goal):
        assert not res.success, f"seed {seed}: goal unreachable but search returned {res.path}"
        return
    assert_valid_result(rec, res, 0)
    opt = nx.dijkstra_path_length(feasible, 0, goal)
    assert res.cost <= weight * opt * (1 + REL), (
        f"seed {seed}, w={weight}: cost {res.cost} > w * optimum {weight * opt}")


# ---------------------------------------------------------------------------------------------
# laziness, limits, failure


def test_laziness_goal_near_start() -> None:
    """A cheap edge straight to the goal among many others: evaluate only what is popped."""
    graph: dict[str, list[tuple[str, float]]] = {"S": [("G", 1.0)], "G": []}
    for i in range(20):
        graph["S"].append((f"x{i}", 5.0 + i))
        graph[f"x{i}"] = [(f"y{i}", 1.0), ("G", 1.0)]
        graph[f"y{i}"] = [("G", 1.0)]
    n_edges = sum(len(v) for v in graph.values())
    rec = Recorder(graph, "G", lower_factor=0.9)
    res = search(rec, "S", lambda n: 0.0)
    assert_valid_result(rec, res, "S")
    assert res.path == ["S", "G"] and res.cost == pytest.approx(1.0, rel=REL), res.path
    assert res.evaluations < n_edges, f"{res.evaluations} evaluations for {n_edges} edges"
    assert res.evaluations == 1, (
        f"only S->G (lower bound 0.9 < every other 4.5) should be evaluated, got "
        f"{dict(rec.evaluated)}")
    assert_lazy_bookkeeping(rec, res)


def test_start_is_goal() -> None:
    rec = Recorder(TRAP, "S")
    res = search(rec, "S", lambda n: 0.0)
    assert res.success and res.path == ["S"], (res.success, res.path)
    assert res.cost == 0.0 and res.edges == [] and res.evaluations == 0, res
    assert res.goal_data == {"reached": "S"}, res.goal_data


def test_max_expansions_gives_up_with_reason() -> None:
    graph = {i: [(i + 1, 1.0)] for i in range(10)} | {10: []}
    rec = Recorder(graph, 10)
    res = search(rec, 0, lambda n: 0.0, max_expansions=3)
    assert not res.success, f"reached the goal in 3 expansions on a 10-edge chain: {res.path}"
    assert res.expansions == 3, f"expansions {res.expansions}, limit 3"
    assert "expansion" in res.reason, f"reason {res.reason!r} does not name the limit"
    assert res.path == [] and res.edges == [] and res.cost == math.inf, (res.path, res.cost)
    assert res.goal_data is None, res.goal_data
    # With enough expansions the same search succeeds.
    ok = search(Recorder(graph, 10), 0, lambda n: 0.0, max_expansions=11)
    assert ok.success and ok.cost == pytest.approx(10.0, rel=REL), (ok.success, ok.cost)


@pytest.mark.parametrize("why", ["no-edge", "infeasible"])
def test_unreachable_goal(why: str) -> None:
    graph = {"S": [("A", 1.0), ("B", 2.0)], "A": [("B", 1.0)], "B": [("A", 1.0)],
             "G": [("S", 1.0)]}
    infeasible: set = set()
    if why == "infeasible":
        graph["B"].append(("G", 1.0))
        infeasible = {("B", "G")}
    rec = Recorder(graph, "G", infeasible)
    res = search(rec, "S", lambda n: 0.0)
    assert not res.success, f"found a path to an unreachable goal: {res.path}"
    assert res.path == [] and res.cost == math.inf, (res.path, res.cost)
    assert res.reason, "a failed search must say why"
    assert res.expansions == 3, f"S, A, B should each be expanded once, got {res.expansions}"
    assert_lazy_bookkeeping(rec, res)


# ---------------------------------------------------------------------------------------------
# A known limitation


def test_admissible_inconsistent_heuristic_is_optimal() -> None:
    graph = {"S": [("A", 3.0), ("B", 1.0)], "B": [("A", 1.0)], "A": [("G", 3.0)], "G": []}
    h = {"S": 0.0, "A": 0.0, "B": 4.0, "G": 0.0}
    dist = exact_distance(graph, "G")
    assert all(h[n] <= dist[n] for n in graph), "the heuristic must be admissible"
    rec = Recorder(graph, "G", lower_factor=1.0)
    res = search(rec, "S", h.__getitem__)
    assert res.success, res.reason
    assert res.cost == pytest.approx(5.0, rel=REL), (
        f"cost {res.cost} on path {res.path}; optimum 5 via S-B-A-G")
