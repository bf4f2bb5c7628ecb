"""The complete footstep search: A* over (4-stance, connected component) on the pose lattice.

Resolution-complete. Every transition and every body motion is decided on the pose lattice of
`planning.lattice` (default 2 cm x 2.5 deg, every orientation):
- a vertex is a 4-stance S together with one connected component C of its feasible lattice
  poses (the body can move between any two poses of C, one lattice step at a time, as the
  pipeline's body phase must);
- an edge moves boom j from its anchor to b through a lattice pose q of C at which all four
  configurations hold: S and the 3-stance with the gripper at its old anchor (q in the
  release set of j, computed once per stance), the 3-stance with the gripper at b and the new
  4-stance S'. It enters the component of S' that holds q. Every such pose is tested, so
  whenever a lattice pose holds a transition, the edge is found;
- the moves of a vertex are every anchor that boom j reaches (boom length and shoulder range,
  exactly) from some release pose of C with its segment there clear of rock: none that a
  pose could hold is dropped;
- the start is joined to the components of its stance whose lattice poses next to the start
  pose are linked to it by a feasible straight segment; a vertex is a goal when C holds a
  lattice pose within the goal tolerance.
So when the search expands every vertex it can reach without meeting a goal, no route exists
at that resolution (`stop == "noroute"`); when it stops on its budget it says so (`"budget"`).
What is not decided here: poses between lattice points, and the free gripper's path from one
anchor to the next (the pipeline plans it, and searches again without a move whose motion
fails), as in the paper's two limiting configurations.

Cost and heuristic are `planning.search_cost`'s (an upper bound on -log p_path; a lower bound
on the cost to go, weighted). An edge's pose is its most robust lattice pose (the worst of its four
configurations' r), polished afterwards on the found path as the sampled search does.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Collection

import numpy as np

from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.components import UNKNOWN
from planning.lattice_moves import (
    LatticeTransition,
    goal_disc_problem,
    goal_is_holdable,
    lattice_transition,
    start_components,
    vertex_moves,
)
from planning.lattice_search import (
    CompleteResult,
    LatticeMemo,
    PartialRoute,
    SearchGraph,
    Stance4,
    Vertex,
    best_poses,
    end_pose_of,
    goal_pose_of,
    stance_components,
    threads_held,
)
from planning.open_list import (
    DeferredMoves,
    Entry,
    MoveGroup,
    anchor_row,
    frontier,
    rekeyed,
)
from planning.search_clock import search_clock
from planning.search_cost import (
    DistanceHeuristic,
    RegraspHeuristic,
    TravelHeuristic,
    centroid_distance,
    edge_cost,
)
from planning.search_outcome import Quality, Stop
from rb_drake.scenario import Scenario

BOUND_EVERY = 100  # expansions between two updates of the anytime search's lower bound


def _adds_nothing(labels: np.ndarray, child: tuple, closed: dict[Vertex, float],
                  g: float = math.inf) -> bool:
    """Whether every pose a move could use (`labels`: what the child stance's components know
    of each, `known_component`) enters a vertex of the child stance expanded at a cost of at
    most `g` (the least the move's child can cost), or is known infeasible there: the move adds
    nothing to the search."""
    if (labels == UNKNOWN).any():
        return False
    for c in set(labels[labels >= 0].tolist()):
        done = closed.get((child, c))
        if done is None or done > g + 1e-12:
            return False
    return True


@threads_held
def complete_search(scn: Scenario, config: CompleteConfig | None = None, *,
                    exclude: Collection[tuple[tuple[str, ...], int, str]] = (),
                    memo: LatticeMemo | None = None,
                    progress: Callable[..., None] | None = None,
                    partial: bool = False) -> CompleteResult:
    """A* over (stance, component) vertices on the pose lattice (module doc), as `config`
    says (`CompleteConfig`).

    With `config.anytime`, after the first route it looks for better ones (`AnytimeConfig`);
    the result then carries the best cost, the proven lower bound and their history.
    `exclude`: moves (stance, boom, anchor) not to take; `memo`: what earlier searches on this
    scenario decided (same lattice).
    `progress(expansions, transitions tested, nearest goal distance)` after each expansion,
    and with `bound=` (cost over the proven lower bound) whenever an anytime search improves.
    `partial`: when no route reaches the goal, the result's `partial` holds the route to the
    expanded vertex nearest the goal (`PartialRoute`); the search itself is the same."""
    config = config or CompleteConfig()
    cfg = config.lattice
    heuristic_weight, anytime = config.heuristic_weight, config.anytime
    max_expansions, time_limit = config.max_expansions, config.time_limit
    ignore_grasps = config.ignore_grasps
    memo = memo if memo is not None else LatticeMemo()
    memo.bind(scn, cfg, ignore_grasps)
    t0 = time.perf_counter()
    clock0 = search_clock()  # the time limit's: numba's compiling left out
    distance_heuristic = DistanceHeuristic(scn)
    c_attach = distance_heuristic.c_attach
    excluded = {(tuple(st), int(j), a) for st, j, a in exclude}
    start: Stance4 = tuple(scn.start_stance)  # type: ignore[assignment]
    start_lat = stance_components(scn, memo, start, cfg, ignore_grasps)
    joined = start_components(scn, start_lat, cfg, cell_steps=config.start_cell_steps)
    graph = SearchGraph()
    tested = 0

    distance = distance_heuristic.distance

    if (problem := goal_disc_problem(scn, cfg)) is not None:
        return CompleteResult(False, Stop.NOROUTE, problem, [], [], [], None, 0, 0, [], [], graph)
    if not goal_is_holdable(scn, cfg):
        return CompleteResult(False, Stop.NOROUTE, "no route: no lattice pose within the goal "
                              "tolerance can hold a stance (the body meets rock, or some boom "
                              "reaches no anchor)", [], [], [], None, 0, 0, [], [], graph)
    if not joined:
        return CompleteResult(False, Stop.NOSTART, "the start pose is joined to no feasible "
                              f"lattice pose of its stance at {cfg.position_step * 100:g} cm / "
                              f"{cfg.angle_step_deg:g} deg", [], [], [], None, 0, 0, [], [],
                              graph)
    tie = itertools.count()
    # The admissible, consistent bound (planning.search_cost): it prunes stances from which no
    # route can reach the goal, and, once a route is known, everything that cannot beat it;
    # min over the open list of g + bound(stance) is a lower bound on the optimal cost (every
    # vertex found again at a lower g is expanded again, so some vertex of an optimal route is
    # always open with its optimal g).
    bound = RegraspHeuristic(scn)
    weight = heuristic_weight
    exact = heuristic_weight <= 1.0  # A*: ordered by the admissible bound itself
    fallback = config.fallback_weight if config.fallback_weight is not None and \
        config.fallback_weight > heuristic_weight and not exact else None
    # Until the first route, each vertex is expanded once, as the first-route search always
    # did; an entry that would lower an expanded vertex's cost then waits in `deferred` (ARA*'s
    # INCONS list) and rejoins the open list with the first route, from which on vertices are
    # expanded again when reached more cheaply: so the lower bound below stays valid.
    reopen = exact
    deferred: list = []
    deferred_moves = DeferredMoves()  # the moves among them, in columns

    def redundant(vertex: Vertex, g: float, entry: tuple) -> bool:
        """Whether `entry`, reaching `vertex` at `g`, adds nothing to the search now."""
        done = closed.get(vertex)
        if done is None:
            return False
        if done <= g + 1e-12:
            return True
        if reopen:
            return False
        if anytime is not None:
            deferred.append(entry)
        return True

    travel = TravelHeuristic(scn) if config.ordering in ("travel", "distance+travel") else None
    # "distance+travel": the first route by distance (greedy, as fast as ever), the better ones
    # after it by travel
    by_travel = config.ordering == "travel"

    def frozen_heuristic() -> Callable[[tuple], float]:
        """The heuristic as the search orders by it now, frozen (a `MoveGroup` finds its moves'
        f again from it): made again wherever its weight or ordering changes."""
        now_exact, now_travel, now_weight = exact, by_travel and travel is not None, weight

        def h(stance: tuple) -> float:
            if now_exact:
                return bound(stance)
            if now_travel:
                return now_weight * travel(stance)  # type: ignore[misc]
            # the weighted distance, in the order it always had
            return now_weight * c_attach * distance(stance) / distance_heuristic.max_step
        return h

    heuristic = frozen_heuristic()

    # Entries: (f, tie, g, kind, child stance, payload). Entry.REACHED: a stance reached by an
    # evaluated move, payload ((stance, component or None while unknown), move, pose, the
    # transition's rows it may use (None: all), parent's g, edge cost); Entry.MOVE: a move
    # to evaluate, payload (parent vertex, boom, anchor) (its rows are in `memo.move_table`), g
    # the parent's g plus the least an edge costs.
    start_pose = np.asarray(scn.start_pose, dtype=float)

    def start_entries() -> list:
        if not math.isfinite(bound(start)):
            return []
        return sorted((heuristic(start), next(tie), 0.0, Entry.REACHED, start,
                       ((start, comp), None, start_pose, None, 0.0, 0.0))
                      for comp in joined)

    open_list: list = start_entries()
    closed: dict[Vertex, float] = {}
    parent: dict[Vertex, tuple] = {}
    expanded: list[tuple[Vertex, np.ndarray]] = []
    expansions = 0
    nearest = math.inf
    stop, reason = Stop.NOROUTE, ""
    best: CompleteResult | None = None  # the cheapest route so far
    best_cost = math.inf
    history: list[tuple[float, float, float, int]] = []  # (s, cost, lower bound, expansions)
    first_expansions = -1
    schedule = list(anytime.weights) if anytime is not None else []

    proven = 0.0  # the highest lower bound found so far (each one is valid)
    # g + bound of the vertex being expanded: popped, its successors not yet pushed, it is in
    # no list, yet it may be the optimal route's only vertex left to expand
    current = math.inf

    # The corridor (AnytimeConfig.corridor): the best route's centroids, and the least
    # g + bound of the moves a pass left out for lying outside it (they count in the bound)
    guide: np.ndarray | None = None
    inside: dict[tuple, bool] = {}
    left_out = math.inf

    corridor = anytime.corridor if anytime is not None else None

    def in_corridor(stance: tuple) -> bool:
        if guide is None or corridor is None:
            return True
        hit = inside.get(stance)
        if hit is None:
            centroid = scn.anchor_positions[[scn.anchor_index[a] for a in stance]].mean(axis=0)
            hit = inside[stance] = _polyline_distance(centroid, guide) <= corridor
        return hit

    def lower() -> float:
        """min over the open list (and the vertex being expanded, and the moves left out of
        the corridor) of g + bound, and the best cost: the optimum is no lower."""
        nonlocal proven
        lo = min(best_cost, current, left_out, deferred_moves.least)
        for entry in itertools.chain(open_list, deferred):
            lo = min(lo, entry[5].least() if entry[3] == Entry.MOVES
                     else entry[2] + bound(entry[4]))
        proven = max(proven, lo)
        return proven

    def edge_entry(g_parent: float, move: tuple, tr: LatticeTransition,
                   pick: np.ndarray | None, child: Stance4, comp: int | None) -> tuple:
        """An open-list entry for the child reached through the most robust pose of `pick`
        (None: every pose of `tr`). It keeps the transition's memo key, not the transition:
        most entries are never popped, and transitions are most of their memory."""
        (stance, _), j, anchor = move
        pose = best_poses(tr, _rows(tr, pick), cfg)[0][0].copy()  # no view: of them all
        cost = edge_cost(scn, stance, j, anchor, pose)
        g_child = g_parent + cost
        graph.add(move[0], child, cost)
        return (g_child + heuristic(child), next(tie), g_child, Entry.REACHED, child,
                ((child, comp), move, pose, pick, g_parent, cost))

    def beaten(g: float, stance: tuple) -> bool:
        """Whether nothing through `stance` at `g` can beat the best route (or reach the goal)."""
        return g + bound(stance) >= best_cost * (1.0 - 1e-12)

    def route(vertex: Vertex) -> tuple[list, list, list, list, float]:
        """The route to an expanded `vertex` through the parent pointers (the cheapest the
        search knows): vertices, and per edge its pose, P4 and alternatives; its cost."""
        path, poses, probs, others, cost = [vertex], [], [], [], 0.0
        while parent[path[-1]][0] is not None:
            move, pick, c = parent[path[-1]]
            pv = move[0]
            tr = memo.transitions[_transition_key(move)]
            # as `edge_entry` found them (the memo gives back the same transition)
            alternatives, pp = best_poses(tr, _rows(tr, pick), cfg)
            poses.append(alternatives[0].copy())
            probs.append(pp)
            others.append(alternatives)
            path.append(pv)
            cost += c
        return path[::-1], poses[::-1], probs[::-1], others[::-1], cost

    def finished(vertex: Vertex, goal_pose: np.ndarray) -> CompleteResult:
        path, poses, probs, others, cost = route(vertex)
        return CompleteResult(True, Stop.ROUTE, "", path, poses, probs, goal_pose,
                              expansions, tested, expanded, [], graph, others, cost=cost)

    def nearest_route() -> PartialRoute | None:
        """The route to the expanded vertex nearest the goal (ties: the cheapest)."""
        if not closed:
            return None
        vertex = min(closed, key=lambda v: (centroid_distance(scn, v[0]), closed[v]))
        path, poses, probs, others, cost = route(vertex)
        stance, comp = vertex
        lat = stance_components(scn, memo, stance, cfg, ignore_grasps).components[comp]
        return PartialRoute(path, poses, probs, others, end_pose_of(scn, lat), cost,
                            centroid_distance(scn, stance))

    while open_list:
        popped = heapq.heappop(open_list)
        if popped[3] == Entry.MOVES:  # a vertex's first waiting move; its next one goes back
            group = popped[5]
            popped = group.pop(scn, Entry.MOVE)
            if len(group):
                heapq.heappush(open_list, group.entry(scn, Entry.MOVES))
        _, _, g, kind, child_stance, payload = popped
        if beaten(g, child_stance):
            continue
        if kind == Entry.MOVE:
            move = payload
            (stance, comp), j, anchor = move
            child: Stance4 = child_stance
            key = (stance, comp, j, anchor)
            tr = memo.transitions.get(key)
            if tr is None:
                lat = memo.components[stance].components[comp]
                rows = memo.move_table((stance, comp))[(j, scn.anchor_index[anchor])]
                known = memo.components.get(child)
                labels = None if known is None else known.known_component(lat.keys[rows])
                if labels is not None and _adds_nothing(labels, child, closed,
                                                         g if reopen else math.inf):
                    # every pose it could use enters an expanded vertex: nothing new (or, until
                    # the first route, nothing new now: it waits if it might lower their cost)
                    if not reopen and anytime is not None and \
                            not _adds_nothing(labels, child, closed, g):
                        deferred_moves.add(popped, anchor_row(scn, anchor), bound(child))
                    continue
                tr = memo.transitions[key] = lattice_transition(
                    scn, lat, stance, j, anchor, ignore_grasps, rows, known, labels)
                tested += 1
            if not len(tr.keys):
                continue
            graph.add((stance, comp), child)
            # The child's lattice (and so which of its components the move enters) waits until
            # the child is popped: most children are never expanded.
            heapq.heappush(open_list, edge_entry(g - c_attach, move, tr, None, child, None))
            continue
        (child, comp), move, pose, pick, g_parent, cost = payload
        if comp is None:  # entered through a move: split among the child's components
            tr = memo.transitions[_transition_key(move)]
            comps = stance_components(scn, memo, child, cfg, ignore_grasps).component_of(tr.keys)
            if (comps < 0).any():  # the kernel is deterministic: never expected
                raise RuntimeError("a transition pose is missing from the new stance's lattice")
            hit = np.unique(comps)
            if len(hit) > 1 or (child, int(hit[0])) in closed:
                for c2 in hit:
                    target = (child, int(c2))
                    if target in closed and ((not reopen and anytime is None)
                                             or closed[target] <= g_parent + c_attach + 1e-12):
                        continue  # expanded once and for all, or no entry can lower its cost
                    entry = edge_entry(g_parent, move, tr, np.flatnonzero(comps == c2), child,
                                       int(c2))
                    if not redundant(target, entry[2], entry):
                        heapq.heappush(open_list, entry)
                continue
            comp = int(hit[0])
        vertex = (child, comp)
        if redundant(vertex, g, popped):
            continue
        closed[vertex] = g
        # the edge's pose, P4 and alternatives are found again for the route's edges (`route`)
        parent[vertex] = (move, pick, cost)
        expanded.append((vertex, pose))
        expansions += 1
        stance, comp = vertex
        current = g + bound(stance)
        nearest = min(nearest, distance(stance))
        if progress is not None:
            progress(expansions, tested, nearest)
        lat = memo.components[stance].components[comp]
        goal_pose = goal_pose_of(scn, lat)
        if goal_pose is not None:
            found = finished(vertex, goal_pose)
            if anytime is None:
                return found._replace(frontier=frontier(open_list, closed))
            if found.cost < best_cost:
                best, best_cost = found, found.cost
                now = time.perf_counter() - t0
                if first_expansions < 0:
                    first_expansions = expansions
                    by_travel = travel is not None
                    heuristic = frozen_heuristic()
                history.append((now, best_cost, lower(), expansions))
                if progress is not None:
                    progress(expansions, tested, nearest, bound=_ratio(best_cost, history[-1][2]))
                if best_cost <= anytime.target_bound * history[-1][2]:
                    break
                # Better routes next: vertices reached more cheaply are expanded again, and the
                # weight is lowered (the last: A* on the admissible bound).
                if not reopen:
                    reopen = True
                    open_list.extend(deferred)
                    open_list.extend(deferred_moves.entries(scn, Entry.MOVE))
                    deferred.clear()
                    deferred_moves.clear()
                    heapq.heapify(open_list)
                if corridor is not None and anytime.restart:
                    guide = np.array([scn.anchor_positions[[scn.anchor_index[a] for a in v[0]]]
                                      .mean(axis=0) for v in found.path])
                    inside.clear()
                if schedule:
                    weight = schedule.pop(0)
                    exact = weight <= 1.0
                    heuristic = frozen_heuristic()
                    if anytime.restart:  # the open list's lower bound is recorded above
                        open_list = start_entries()
                        closed.clear()
                        parent.clear()
                        left_out = math.inf  # this pass's own moves left out, from here on
                    else:
                        open_list = [rekeyed(scn, e, heuristic, bound) for e in open_list]
                        heapq.heapify(open_list)
            current = math.inf
            continue  # a goal's successors cannot be cheaper routes
        # (a route is kept in `best` only by an anytime search: `anytime` is set below)
        if best is not None and anytime is not None and \
                (expansions - first_expansions) % BOUND_EVERY == 0:
            # The lower bound rises as the search goes on: record it (and stop at the target).
            lo = lower()
            if lo > history[-1][2] * (1.0 + 1e-9):
                history.append((time.perf_counter() - t0, best_cost, lo, expansions))
                if progress is not None:
                    progress(expansions, tested, nearest, bound=_ratio(best_cost, lo))
                if best_cost <= anytime.target_bound * lo:
                    break
        if (best is None and fallback is not None and max_expansions is not None
                and expansions >= config.fallback_after * max_expansions):
            # No route yet at the moderate weight: start again, greedy (CompleteConfig)
            weight, fallback = fallback, None
            heuristic = frozen_heuristic()
            open_list = start_entries()
            closed.clear()
            parent.clear()
            deferred.clear()
            deferred_moves.clear()
            current = math.inf
            continue
        if max_expansions is not None and expansions >= max_expansions and best is None:
            stop = Stop.BUDGET
            reason = (f"gave up after {expansions} expansions without reaching the goal "
                      f"(max_expansions {max_expansions})")
            break
        if time_limit is not None and search_clock() - clock0 > time_limit:
            stop = Stop.BUDGET
            reason = (f"gave up after {time_limit:g} s ({expansions} expansions) without "
                      "reaching the goal")
            break
        if best is not None and anytime is not None and \
                expansions - first_expansions >= anytime.improve_expansions(first_expansions):
            break
        # A move's rows stay in the memo's move table (bounded), not in the open list, and
        # the moves wait as one entry (`MoveGroup`): most are never evaluated, and one tuple
        # each was most of what a long search kept per vertex outside its memo.
        waiting = []
        for j, anchor, _, child in vertex_moves(scn, lat, stance, excluded,
                                                memo.move_table(vertex)):
            if not beaten(g + c_attach, child):
                if guide is not None and not in_corridor(child):
                    left_out = min(left_out, g + c_attach + bound(child))
                    continue
                waiting.append((g + c_attach + heuristic(child), next(tie), j,
                                anchor_row(scn, anchor), bound(child)))
        if waiting:
            group = MoveGroup(vertex, g + c_attach, waiting, heuristic)
            heapq.heappush(open_list, group.entry(scn, Entry.MOVES))
        current = math.inf  # its successors are in the open list
    if best is not None:
        lo = lower()
        now = time.perf_counter() - t0
        if not history or history[-1][1:3] != (best_cost, lo):
            history.append((now, best_cost, lo, expansions))
        quality = Quality.OPTIMAL if best_cost <= lo * (1.0 + 1e-12) else Quality.BOUNDED
        return best._replace(expansions=expansions, transitions_tested=tested,
                             expanded=expanded, frontier=frontier(open_list, closed),
                             lower_bound=lo, first_cost=history[0][1], history=history,
                             quality=quality)
    if stop == Stop.NOROUTE:
        reason = (f"no route at resolution {cfg.position_step * 100:g} cm / "
                  f"{cfg.angle_step_deg:g} deg: all {expansions} (stance, component) vertices "
                  "reachable from the start were expanded without reaching the goal")
        if excluded:
            stop = Stop.EXHAUSTED
            reason += f" ({len(excluded)} moves excluded)"
    return CompleteResult(False, stop, reason, [], [], [], None, expansions, tested, expanded,
                          frontier(open_list, closed), graph,
                          partial=nearest_route() if partial else None)


def _polyline_distance(point: np.ndarray, points: np.ndarray) -> float:
    """The distance from `point` to the polyline through `points` (n, 2)."""
    if len(points) == 1:
        return float(np.linalg.norm(point - points[0]))
    a, b = points[:-1], points[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.maximum(
        np.einsum("ij,ij->i", ab, ab), 1e-18), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - point, axis=1)))


def _rows(tr: LatticeTransition, pick: np.ndarray | None) -> np.ndarray:
    """The rows `pick` of transition `tr` (None: all of them)."""
    return np.arange(len(tr.keys)) if pick is None else pick


def _transition_key(move: tuple) -> tuple:
    """The memo key of a move ((stance, component), boom, anchor)'s transition."""
    (stance, comp), j, anchor = move
    return (stance, comp, j, anchor)


def _ratio(cost: float, lower_bound: float) -> float:
    """cost / lower bound, the route's proven distance from the optimum: 1 when both are 0 (a
    goal held in the start stance: the rig), inf while nothing positive is proven."""
    if lower_bound > 0:
        return cost / lower_bound
    return 1.0 if cost <= 0 else math.inf


__all__ = ["AnytimeConfig", "CompleteConfig", "LatticeMemo", "complete_search"]
