"""Lazy weighted A*: edges are evaluated only when the search pops them.

Successors are pushed with a cheap lower bound on their edge cost; when one is popped, its edge
is evaluated (in our use, a transition-feasibility search costing milliseconds); an infeasible
edge is dropped, a feasible one is pushed again with its true cost. A node is expanded only when
popped with an evaluated edge; one found again through a cheaper path after its expansion is
reopened. So with an admissible heuristic and `weight = 1` the first goal expanded is optimal,
and with `weight = w > 1` its cost is at most w times the optimum.
networkx's A* needs the graph's edges up front, which is exactly what we cannot afford, so the
loop is ours; the explored graph is kept in a networkx DiGraph for analysis.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Hashable, Iterable, Sequence
from typing import Any, Generic, NamedTuple, TypeVar

import networkx as nx

from planning.search_clock import search_clock

N = TypeVar("N", bound=Hashable)  # a node of the searched graph


class Edge(NamedTuple):
    cost: float
    data: Any


class SearchResult(NamedTuple, Generic[N]):
    success: bool
    path: list[N]                  # nodes from start to goal
    edges: list[Any]               # edge data along the path
    goal_data: Any                 # what the goal test returned for the goal node
    cost: float
    expansions: int
    evaluations: int
    graph: nx.DiGraph              # every evaluated feasible edge
    reason: str
    expanded: Sequence[N] = ()     # nodes in expansion order (the start first)
    node_data: Any = None          # dict: the data each reached node was last reached with
    timed_out: bool = False        # stopped by its time limit


def lazy_astar(
    start: N,
    successors: Callable[[N, Any], Iterable[tuple[N, Any, float]]],
    evaluate: Callable[[N, N, Any, Any], Edge | None],
    heuristic: Callable[[N], float],
    is_goal: Callable[[N, Any], Any],
    weight: float = 1.0,
    max_expansions: int = 1000,
    start_data: Any = None,
    on_expand: Callable[[int, N], None] | None = None,
    time_limit: float | None = None,
) -> SearchResult[N]:
    """Search from `start` to the first node for which `is_goal(node, node_data)` is truthy.

    successors(node, node_data) yields (child, edge_key, lower_bound_cost);
    evaluate(node, child, edge_key, node_data) returns Edge(cost, data) or None (infeasible);
    the edge's data becomes the child's node_data when it is reached through that edge.
    `time_limit` (s, None: none): once the start is expanded, the search gives up when it has
    run longer, checked before each expansion and each edge's evaluation.
    """
    t0 = search_clock()  # numba's compiling left out of the time limit
    tie = itertools.count()
    graph = nx.DiGraph()
    graph.add_node(start)
    g_best: dict[N, float] = {start: 0.0}
    parent: dict[N, tuple[N, Any]] = {}
    node_data: dict[N, Any] = {start: start_data}
    closed: dict[N, float] = {}  # expanded nodes and the g they were expanded with
    # entries: (f, tie, g, node, parent, edge_key, evaluated, edge_data); for an unevaluated
    # entry g is the parent's g plus the edge's lower bound.
    open_list: list = [(weight * heuristic(start), next(tie), 0.0, start, None, None, True, None)]
    expansions = evaluations = 0
    order: list[N] = []
    while open_list:
        if time_limit is not None and expansions and search_clock() - t0 > time_limit:
            return SearchResult(False, [], [], None, float("inf"), expansions, evaluations, graph,
                                f"gave up after {time_limit:g} s ({expansions} expansions) "
                                "without reaching the goal", order, node_data, timed_out=True)
        _, _, g, node, par, key, evaluated, data = heapq.heappop(open_list)
        if node in closed and g >= closed[node] - 1e-15:
            continue
        if not evaluated:
            evaluations += 1
            edge = evaluate(par, node, key, node_data[par])
            if edge is None:
                continue
            g_true = g_best[par] + edge.cost
            graph.add_edge(par, node, cost=edge.cost, data=edge.data)
            if g_true < g_best.get(node, float("inf")) - 1e-15 or node not in parent:
                g_best[node] = min(g_true, g_best.get(node, float("inf")))
                heapq.heappush(open_list, (g_true + weight * heuristic(node), next(tie), g_true,
                                           node, par, key, True, edge.data))
            continue
        if par is not None:
            if g > g_best.get(node, float("inf")) + 1e-15:
                continue
            parent[node] = (par, data)
            node_data[node] = data
        closed[node] = g
        expansions += 1
        order.append(node)
        if on_expand is not None:
            on_expand(expansions, node)
        goal = is_goal(node, node_data[node])
        if goal:
            path, edges = [node], []
            while path[-1] in parent:
                p, d = parent[path[-1]]
                edges.append(d)
                path.append(p)
            return SearchResult(True, path[::-1], edges[::-1], goal, g, expansions, evaluations,
                                graph, "", order, node_data)
        if expansions >= max_expansions:
            return SearchResult(False, [], [], None, float("inf"), expansions, evaluations, graph,
                                f"gave up after {expansions} expansions without reaching the goal",
                                order, node_data)
        for child, edge_key, lower in successors(node, node_data[node]):
            g_child = g + lower
            if child in closed and g_child >= closed[child] - 1e-15:
                continue
            heapq.heappush(open_list, (g_child + weight * heuristic(child), next(tie), g_child,
                                       child, node, edge_key, False, None))
    return SearchResult(False, [], [], None, float("inf"), expansions, evaluations, graph,
                        "every reachable stance was explored without reaching the goal", order,
                        node_data)
