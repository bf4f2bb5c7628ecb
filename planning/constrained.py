"""The route with the fewest regrasps whose predicted success is at least P (`rbp plan
--min-success P`): a resource-constrained search over the complete search's graph.

The graph is `planning.complete`'s: vertices are (4-stance, component of its feasible lattice
poses), an edge is a regrasp decided on every lattice pose, and its cost is
`planning.search_cost.edge_cost` (-log of the regrasp's attach and grasp probabilities at its
most robust transition pose). A route's predicted success is exp(-its cost). The search
minimises the number of regrasps subject to cost <= B = -log P:

- labels (vertex, regrasps k, cost c) are popped in order of f = k + hops(vertex), then c,
  where hops is `RegraspHeuristic.regrasps`, the admissible and consistent lower bound on the
  regrasps left (f never decreases along a route), so a vertex's labels are popped with k
  non-decreasing;
- a label is dominated, and dropped, when a label of its vertex with no more regrasps and no
  higher cost was popped before it; one whose cost plus the lower bound on the cost to go
  exceeds B cannot lead to a route within P, and is dropped too;
- a vertex's moves are evaluated when they are popped, keyed by the least they can cost (the
  attach term), so every key is a lower bound on the labels it leads to: the first goal label
  popped has the fewest regrasps of any route within P and, of those, the lowest cost (the
  most robust).

When no label is left, no route at the lattice's resolution has predicted success >= P: a
proof, as the complete search's "noroute" is.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Collection

import numpy as np

from planning.complete_config import CompleteConfig
from planning.components import UNKNOWN
from planning.lattice import LatticeConfig
from planning.lattice_moves import (
    goal_disc_problem,
    goal_is_holdable,
    lattice_transition,
    start_components,
    vertex_moves,
)
from planning.lattice_search import (
    CompleteResult,
    LatticeMemo,
    SearchGraph,
    best_poses,
    goal_pose_and_r,
    stance_components,
    threads_held,
)
from planning.search_clock import search_clock
from planning.search_cost import RegraspHeuristic, edge_cost, goal_distance
from planning.search_outcome import Stop
from rb_drake.errors import RbpInputError, as_given
from rb_drake.scenario import Scenario


@threads_held
def constrained_search(scn: Scenario, min_success: float, config: CompleteConfig | None = None,
                       *, exclude: Collection[tuple[tuple[str, ...], int, str]] = (),
                       memo: LatticeMemo | None = None,
                       progress: Callable[..., None] | None = None) -> CompleteResult:
    """The fewest-regrasp route with exp(-cost) >= `min_success` (module doc), or the proof that
    none exists (`stop == "noroute"`), or a budget stop (`"budget"`). `config` as the complete
    search's: its lattice, budget (`max_expansions`, `time_limit`) and `ignore_grasps` (the
    order is by regrasps, so `heuristic_weight` and `anytime` play no part). `exclude`: moves
    (stance, boom, anchor) not to take (the pipeline's search again without a move whose
    motion failed)."""
    if not 0.0 < min_success < 1.0:
        raise RbpInputError(f"must lie in (0, 1), got {min_success}", field="min_success")
    config = config or CompleteConfig()
    cfg = config.lattice
    max_expansions, time_limit = config.max_expansions, config.time_limit
    ignore_grasps = config.ignore_grasps
    memo = memo if memo is not None else LatticeMemo(config=cfg)
    memo.bind(scn, cfg, ignore_grasps)
    clock0 = search_clock()  # the time limit's: numba's compiling left out
    budget = -math.log(min_success)
    slack = budget * (1.0 + 1e-12)
    bound = RegraspHeuristic(scn)
    graph = SearchGraph()
    start = tuple(scn.start_stance)
    joined = start_components(scn, stance_components(scn, memo, start, cfg, ignore_grasps), cfg)
    if (problem := goal_disc_problem(scn, cfg)) is not None:
        return CompleteResult(False, Stop.NOROUTE, problem, [], [], [], None, 0, 0, [], [], graph)
    if not goal_is_holdable(scn, cfg):
        return CompleteResult(False, Stop.NOROUTE, "no route: no lattice pose within the goal "
                              "tolerance can hold a stance", [], [], [], None, 0, 0, [], [],
                              graph)
    if not joined:
        return CompleteResult(False, Stop.NOSTART, "the start pose is joined to no feasible "
                              "lattice pose of its stance", [], [], [], None, 0, 0, [], [], graph)
    excluded = {(tuple(st), int(j), a) for st, j, a in exclude}
    tie = itertools.count()
    # a label: (vertex, regrasps, cost, parent label, pose, P4, (boom, anchor) of the edge that
    # reached it); the open list holds (regrasps + bound, cost, tie, label, None) for a label and
    # (the child's, its parent's cost plus the least the edge can cost, tie, parent label, move)
    # for a move: first not yet evaluated (attach term only), then evaluated (its transition's
    # least known). Neither keeps a transition or its alternatives: the memo's cap bounds them,
    # and the route's alternatives are decided again at the end (issue 31)
    labels: list[tuple] = []
    open_list: list[tuple] = []

    def push(vertex: tuple, k: int, cost: float, parent: int, pose, p4, edge) -> None:
        hops = bound.regrasps(vertex[0])
        if not math.isfinite(hops) or cost + bound.c_attach * hops > slack:
            return  # no route through it reaches the goal within the budget
        if cost >= popped_cost.get(vertex, math.inf):
            return  # dominated: popped before with no more regrasps and no higher cost
        labels.append((vertex, k, cost, parent, pose, p4, edge))
        heapq.heappush(open_list, (k + hops, cost, next(tie), len(labels) - 1, None))

    popped_cost: dict[tuple, float] = {}
    start_pose = np.asarray(scn.start_pose, dtype=float)
    # The footstep plan's p_path also takes the start configuration and the goal pose's, which
    # no edge scores: each route's cost starts with the start's -r and ends with its goal
    # pose's, so that exp(-cost) never exceeds the plan's p_path (docs/model.md).
    start_term = 0.0 if ignore_grasps else _holding_term(scn, start, start_pose)
    for comp in joined:
        push((start, comp), 0, start_term, -1, start_pose, None, None)
    expansions = tested = 0
    nearest = math.inf
    found: tuple[int, np.ndarray] | None = None  # (goal label, goal pose)
    goal_term = 0.0  # the goal pose's -r, added to the found route's cost
    expanded: list[tuple[tuple, np.ndarray]] = []
    stop, reason = Stop.NOROUTE, ""
    while open_list:
        f, cost, _, index, move = heapq.heappop(open_list)
        if move is not None:  # a move: evaluate it, then (when popped again) enter the child
            j, anchor, child, evaluated = move
            vertex = labels[index][0]
            stance, comp = vertex
            k, base = labels[index][1], labels[index][2]
            key = (stance, comp, j, anchor)
            if not evaluated:
                lat = memo.components[stance].components[comp]
                tr = memo.transitions.get(key)
                if tr is None:
                    rows = memo.move_table(vertex)[(j, scn.anchor_index[anchor])]
                    known = memo.components.get(child)
                    seen = None if known is None else known.known_component(lat.keys[rows])
                    tr = memo.transitions[key] = lattice_transition(
                        scn, lat, stance, j, anchor, ignore_grasps, rows, known, seen)
                    tested += 1
                if len(tr.keys):
                    # At any of its poses the edge costs at least the attach term plus the
                    # worst configuration's -r (a sum over booms of the per-boom worst is at
                    # least the worst sum): the child's components wait for that key.
                    least = base + bound.c_attach + max(0.0, -float(tr.worst.max()))
                    heapq.heappush(open_list, (f, least * (1.0 - 1e-12), next(tie), index,
                                               (j, anchor, child, True)))
                continue
            tr = memo.transitions[key]  # decided again, the same, if the memo dropped it
            known = memo.components.get(child)
            if known is not None:  # every component it enters popped as cheaply: dominated
                seen = known.known_component(tr.keys)
                if (seen != UNKNOWN).all() and all(
                        popped_cost.get((child, c2), math.inf) <= cost
                        for c2 in set(seen[seen >= 0].tolist())):
                    continue
            comps = stance_components(scn, memo, child, cfg, ignore_grasps).component_of(
                tr.keys)
            for c2 in np.unique(comps):
                poses, p4 = best_poses(tr, np.flatnonzero(comps == c2), cfg)
                pose = poses[0].copy()  # not a view: it would keep the alternatives alive
                step = edge_cost(scn, stance, j, anchor, pose)
                graph.add(vertex, (child, int(c2)), step)
                push((child, int(c2)), k + 1, base + step, index, pose, p4, (j, anchor))
            continue
        vertex, k, _, _, pose, _, _ = labels[index]
        if cost >= popped_cost.get(vertex, math.inf):
            continue
        popped_cost[vertex] = cost
        stance, comp = vertex
        lat = memo.components[stance].components[comp]
        at_goal = goal_pose_and_r(scn, lat)
        if at_goal is not None and (ignore_grasps or cost + max(0.0, -at_goal[1]) <= slack):
            # Popped in order of (regrasps + bound, cost) with every key a lower bound on what
            # it leads to: no route left has fewer regrasps. (A goal vertex whose goal pose
            # takes the route past -log P is expanded: a later goal vertex may hold a better.)
            found = (index, at_goal[0])
            goal_term = 0.0 if ignore_grasps else max(0.0, -at_goal[1])
            break
        expansions += 1
        expanded.append((vertex, pose))
        nearest = min(nearest, goal_distance(scn, stance))
        if progress is not None:
            progress(expansions, tested, nearest)
        if max_expansions is not None and expansions > max_expansions:
            stop, reason = Stop.BUDGET, (f"gave up after {max_expansions} expansions without a "
                                      f"route of predicted success >= {as_given(min_success)}")
            break
        if time_limit is not None and search_clock() - clock0 > time_limit:
            stop, reason = Stop.BUDGET, (f"gave up after {time_limit:g} s ({expansions} "
                                      f"expansions) without a route of predicted success >= "
                                      f"{as_given(min_success)}")
            break
        # a pending move keeps no lattice rows (they are in `memo.move_table`, within its cap):
        # kept in the open list they took most of the search's own memory
        for j, anchor, _, child in vertex_moves(scn, lat, stance, excluded,
                                                memo.move_table(vertex)):
            hops = bound.regrasps(child)
            least = cost + bound.c_attach  # every edge costs at least the attach term
            if not math.isfinite(hops) or least + bound.c_attach * hops > slack:
                continue
            heapq.heappush(open_list, (k + 1 + hops, least, next(tie), index,
                                       (j, anchor, child, False)))
    if found is None:
        if stop == Stop.NOROUTE and excluded:
            stop = Stop.EXHAUSTED
            reason = f"no route without the {len(excluded)} excluded moves"
        elif stop == Stop.NOROUTE:
            reason = (f"no route with predicted success >= {as_given(min_success)} at resolution "
                      f"{cfg.position_step * 100:g} cm / {cfg.angle_step_deg:g} deg: every "
                      f"route's search cost exceeds -log P = {budget:.4g} ({expansions} "
                      "vertices expanded)")
        return CompleteResult(False, stop, reason, [], [], [], None, expansions, tested,
                              expanded, [], graph)
    path, poses, probs, others = [], [], [], []
    index = found[0]
    total = labels[index][2] + goal_term
    while index >= 0:
        vertex, _, _, parent, pose, p4, edge = labels[index]
        path.append(vertex)
        if parent >= 0:
            poses.append(pose)
            probs.append(p4)
            others.append(_alternatives(scn, memo, cfg, ignore_grasps, labels[parent][0],
                                        edge, vertex))
        index = parent
    return CompleteResult(True, Stop.ROUTE, "", path[::-1], poses[::-1], probs[::-1], found[1],
                          expansions, tested, expanded, [], graph, others[::-1], cost=total)


def _holding_term(scn: Scenario, stance: tuple, pose: np.ndarray) -> float:
    """-r (-log P, at least 0) of `stance` at `pose`: the start configuration's share of the
    plan's -log p_path."""
    from rb_drake.feasibility import check_poses

    r = float(check_poses(scn, scn.stance(stance), pose[None, :]).allocation.robustness[0])
    return max(0.0, -r) if math.isfinite(r) else 0.0


def _alternatives(scn: Scenario, memo: LatticeMemo, cfg: LatticeConfig, ignore_grasps: bool,
                  parent: tuple, edge: tuple[int, str], child: tuple) -> np.ndarray:
    """The most robust transition poses of the edge parent -> child (boom, anchor) into the
    child's component, best first: as the search found them (its decisions are replayed the
    same when the memo dropped them)."""
    (stance, comp), (j, anchor) = parent, edge
    tr = memo.transitions[(stance, comp, j, anchor)]
    comps = stance_components(scn, memo, child[0], cfg, ignore_grasps).component_of(tr.keys)
    return best_poses(tr, np.flatnonzero(comps == child[1]), cfg)[0]
