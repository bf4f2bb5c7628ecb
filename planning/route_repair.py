"""Route repair: a found route improved window by window, each window searched optimally.

The anytime search (planning.complete) improves a route by searching again from the start with
a lower weight; on a long climb each such search floods the graph before it gets anywhere,
because its admissible bound (the regrasps each boom needs to reach the goal) is far below the
cost. Between two vertices of a route a few regrasps apart the picture is different: every boom
knows its target anchor, so the regrasps each boom needs are counted exactly on the relaxed hop
graph, and A* with that bound settles a window in a few dozen expansions. Sliding a window
along the route and splicing in every cheaper segment costs time linear in the route's length,
and the route it returns is optimal within every window it searched (a local optimum; the
anytime search's lower bound, where one was proven, still bounds the distance to the global
one). This is large-neighbourhood search on a path, with windows as neighbourhoods.

A window's search is A* over (stance, component) vertices, as the complete search's: a move
(boom j to anchor b from component C) is evaluated only when popped, with key g + c_att +
h(child), where c_att = -log(1 - p_att) is the least an edge costs; h counts, per boom, the hops
from its anchor to its target anchor in the relaxed graph of `planning.search_cost`
(`boom_hop_length`), times c_att: admissible and consistent. The window's end must be the same
vertex (stance and component) as the route's, so that the rest of the route, which leaves from
that component, still holds; the last window ends at any goal vertex, with the goal's
`RegraspHeuristic`.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import math
from collections.abc import Collection

import numpy as np

from planning.lattice import LatticeConfig
from planning.lattice_moves import lattice_transition, vertex_moves
from planning.lattice_search import (
    CompleteResult,
    LatticeMemo,
    Vertex,
    best_poses,
    goal_pose_of,
    stance_components,
)
from planning.search_cost import (
    RegraspHeuristic,
    attach_cost,
    edge_cost,
    hop_graph,
    hops_from,
)
from planning.search_outcome import Quality
from rb_drake.errors import RbpInputError
from rb_drake.kernel.threads import held_kernel_threads
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class RepairConfig:
    """Windows of `window` regrasps, `stride` apart, each searched for at most
    `window_expansions` expansions (a window that runs out keeps its segment); passes along the
    route until one improves nothing or `passes` are done."""

    window: int = 6
    stride: int = 3
    window_expansions: int = 150
    passes: int = 3

    def __post_init__(self) -> None:
        for name in ("window", "stride", "window_expansions", "passes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise RbpInputError(f"must be a whole number of at least 1, got {value!r}",
                                    field=f"footstep.repair.{name}")


class _Edge:
    """One edge of a route: its transition pose, the four configurations' P there, its
    alternative poses and its cost."""

    __slots__ = ("alternatives", "cost", "p4", "pose")

    def __init__(self, pose: np.ndarray, p4: np.ndarray, alternatives: np.ndarray | None,
                 cost: float):
        self.pose, self.p4, self.alternatives, self.cost = pose, p4, alternatives, cost


class _HopTable:
    """Regrasps each boom needs to reach an anchor in the relaxed hop graph
    (`planning.search_cost.hop_graph`), counted from each target anchor on demand."""

    def __init__(self, scn: Scenario):
        self.adjacent = hop_graph(scn)
        self.row = scn.anchor_index
        self._from: dict[int, np.ndarray] = {}

    def hops_to(self, anchor: str) -> np.ndarray:
        target = self.row[anchor]
        table = self._from.get(target)
        if table is None:
            sources = np.zeros(self.adjacent.shape[0], dtype=bool)
            sources[target] = True
            table = self._from[target] = hops_from(self.adjacent, sources)
        return table


def _window_search(scn: Scenario, memo: LatticeMemo, cfg: LatticeConfig, start: Vertex,
                   target: Vertex | None, budget: float, max_expansions: int,
                   hops: _HopTable, goal_bound: RegraspHeuristic, ignore_grasps: bool,
                   excluded: Collection[tuple[tuple, int, str]]
                   ) -> tuple[list[Vertex], list[_Edge], np.ndarray | None] | None:
    """The cheapest path from `start` to `target` (None: to any goal vertex) costing less
    than `budget`, as (vertices, edges, goal pose if it ends at the goal); None if there is
    none within `max_expansions` expansions."""
    c_attach = attach_cost(scn.robot)
    if target is not None:
        tables = [hops.hops_to(a) for a in target[0]]
        row = scn.anchor_index

        def bound(stance: tuple) -> float:
            return c_attach * sum(float(tables[j][row[stance[j]]]) for j in range(NUM_BOOMS))
    else:
        bound = goal_bound

    tie = itertools.count()
    # (f, tie, g, vertex or None, move or None, rows, parent info)
    open_list: list = [(bound(start[0]), next(tie), 0.0, start, None, None, None)]
    closed: dict[Vertex, float] = {}
    parent: dict[Vertex, tuple] = {start: (None, None)}
    expansions = 0
    while open_list:
        f, _, g, vertex, move, rows, info = heapq.heappop(open_list)
        if f >= budget * (1.0 - 1e-12):
            return None
        if move is not None:  # evaluate a move, push the vertices it enters
            source, j, anchor, child = move
            stance, comp = source
            key = (stance, comp, j, anchor)
            lat = memo.components[stance].components[comp]
            tr = memo.transitions.get(key)
            if tr is None:
                tr = memo.transitions[key] = lattice_transition(
                    scn, lat, stance, j, anchor, ignore_grasps, rows,
                    memo.components.get(child))
            if not len(tr.keys):
                continue
            # Which component of the child the move enters waits until the child is popped:
            # most children never are, and splitting them takes a flood fill each.
            poses, p4 = best_poses(tr, np.arange(len(tr.keys)), cfg)
            cost = edge_cost(scn, stance, j, anchor, poses[0])
            g_child = g - c_attach + cost
            f_child = g_child + bound(child)
            if f_child < budget * (1.0 - 1e-12):
                heapq.heappush(open_list, (f_child, next(tie), g_child, (child, None), None, tr,
                                           (source, _Edge(poses[0], p4, poses, cost), j,
                                            anchor)))
            continue
        if vertex[1] is None:  # entered through a move: split among the child's components
            child = vertex[0]
            source, edge, j, anchor = info
            tr = rows
            comps = stance_components(scn, memo, child, cfg, ignore_grasps).component_of(tr.keys)
            hit = np.unique(comps[comps >= 0]).tolist()
            if len(hit) == 1:
                vertex, info = (child, hit[0]), (source, edge)
            else:
                g_parent = g - edge.cost
                for c2 in hit:
                    poses, p4 = best_poses(tr, np.flatnonzero(comps == c2), cfg)
                    cost = edge_cost(scn, source[0], j, anchor, poses[0])
                    h = bound(child)
                    if g_parent + cost + h < budget * (1.0 - 1e-12) and \
                            closed.get((child, c2), math.inf) > g_parent + cost + 1e-12:
                        heapq.heappush(open_list, (g_parent + cost + h, next(tie),
                                                   g_parent + cost, (child, c2), None, None,
                                                   (source, _Edge(poses[0], p4, poses, cost))))
                continue
        if vertex in closed and closed[vertex] <= g + 1e-12:
            continue
        closed[vertex] = g
        if info is not None:
            parent[vertex] = info
        stance, comp = vertex
        lat = stance_components(scn, memo, stance, cfg, ignore_grasps).components[comp]
        goal_pose = None
        if target is None:
            goal_pose = goal_pose_of(scn, lat)
        if (target is not None and vertex == target) or goal_pose is not None:
            vertices, edges = [vertex], []
            while parent[vertices[-1]][0] is not None:
                before, edge = parent[vertices[-1]]
                edges.append(edge)
                vertices.append(before)
            return vertices[::-1], edges[::-1], goal_pose
        expansions += 1
        if expansions > max_expansions:
            return None
        for j, anchor, rows, child in vertex_moves(scn, lat, stance, excluded):
            key = g + c_attach + bound(child)
            if key < budget * (1.0 - 1e-12):
                heapq.heappush(open_list, (key, next(tie), g + c_attach, None,
                                           (vertex, j, anchor, child), rows, None))
    return None


def repair_route(scn: Scenario, result: CompleteResult, memo: LatticeMemo,
                 repair: RepairConfig | None = None, ignore_grasps: bool = False,
                 exclude: Collection[tuple[tuple[str, ...], int, str]] = ()
                 ) -> CompleteResult:
    """`result`'s route with every window of `repair.window` regrasps replaced by the cheapest
    segment between the same vertices (the last window: to any goal vertex), as long as that
    is cheaper (module doc). The result's cost is the new route's; its lower bound is kept.
    `memo` must be the one the search filled: a vertex's component is numbered in it."""
    if not result.success or len(result.path) < 2:
        return result
    repair = repair or RepairConfig()
    cfg = memo.config or LatticeConfig()
    excluded = {(tuple(st), int(j), a) for st, j, a in exclude}
    hops = _HopTable(scn)
    goal_bound = RegraspHeuristic(scn)
    path = list(result.path)
    others: list[np.ndarray | None] = (list(result.alternatives) if result.alternatives
                                       else [None] * len(result.poses))
    edges = []
    for (a, _), (b, _), pose, p4, alt in zip(path[:-1], path[1:], result.poses,
                                            result.probabilities, others, strict=True):
        j = _boom(a, b)
        edges.append(_Edge(np.asarray(pose, dtype=float), np.asarray(p4), alt,
                           edge_cost(scn, a, j, b[j], pose)))
    goal_pose = result.goal_pose
    settled: set[tuple] = set()  # segments searched without a cheaper one found: skip them
    with held_kernel_threads():
        for _ in range(repair.passes):
            improved = False
            i = 0
            while i < len(edges):
                end = min(i + repair.window, len(edges))
                last = end == len(edges)
                old = sum(e.cost for e in edges[i:end])
                segment = (last, *path[i:end + 1])
                if segment in settled:
                    if last:
                        break
                    i += repair.stride
                    continue
                found = _window_search(scn, memo, cfg, path[i], None if last else path[end],
                                       old, repair.window_expansions, hops, goal_bound,
                                       ignore_grasps, excluded)
                if found is not None and sum(e.cost for e in found[1]) < old * (1.0 - 1e-9):
                    vertices, new_edges, new_goal = found
                    path[i:end + 1] = vertices
                    edges[i:end] = new_edges
                    if last:
                        goal_pose = new_goal
                    improved = True
                    segment = (last, *vertices)  # the cheapest between its ends
                settled.add(segment)
                if last:
                    break
                i += repair.stride
            if not improved:
                break
    cost = float(sum(e.cost for e in edges))
    if cost >= result.cost * (1.0 - 1e-12):
        return result
    quality = Quality.OPTIMAL if cost <= result.lower_bound * (1.0 + 1e-12) else (
        Quality.BOUNDED if math.isfinite(result.lower_bound) else result.quality)
    alternatives = [e.alternatives for e in edges if e.alternatives is not None]
    return result._replace(path=path, poses=[e.pose for e in edges],
                           probabilities=[e.p4 for e in edges],
                           alternatives=alternatives if len(alternatives) == len(edges) else None,
                           goal_pose=goal_pose, cost=cost, quality=quality)


def _boom(a: tuple, b: tuple) -> int:
    return next(j for j in range(NUM_BOOMS) if a[j] != b[j])
