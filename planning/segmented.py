"""Long climbs in segments: a receding-horizon footstep search whose work grows with the climb.

On a long climb the whole-cave search is greedy until its first route (its ordering weight
makes it so) and its anytime passes, which would straighten the route, flood the graph before
they reach the goal: detours grow with the length, and so do regrasps per metre. A climber
plans a few metres ahead instead. `segmented_search` does the same with the complete search:
from the current vertex it searches (the anytime search, with its budget, as on a short cave)
to a sub-goal `lookahead` metres ahead along the straight line to the goal (a disc of radius
`tolerance`, moved sideways where no pose in it can hold a stance), keeps the part of that
route that climbs the first `commit` metres, and searches again from where it ends. Each
segment is a short climb's search, so the work per metre stays that of a short climb, and
each kept part is planned with `lookahead - commit` metres of what follows in view.

It is a heuristic for the route, not for the answer: if a segment finds no route (the kept
part led into a dead end, or the sub-goal lies beyond an obstacle), the whole climb is
searched from the start as without segments (with the lattice work done so far kept in the
memo), so a route is found whenever the whole search finds one, and "no route" is only ever
the whole search's proof. The segmented route's proven lower bound is the admissible bound
at the start (`RegraspHeuristic`): the segments' own bounds hold for their sub-goals only.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Collection
from typing import Any

import numpy as np

from planning.complete import complete_search
from planning.complete_config import CompleteConfig
from planning.config_ranges import commit_problem, sub_goal_problem
from planning.lattice_moves import goal_is_holdable
from planning.lattice_search import CompleteResult, LatticeMemo, SearchGraph, Vertex
from planning.search_clock import search_clock
from planning.search_cost import RegraspHeuristic, edge_cost
from planning.search_outcome import Quality, Stop
from rb_drake.errors import RbpInputError
from rb_drake.scenario import Scenario

SIDEWAYS = (0.0, 0.4, -0.4, 0.8, -0.8)  # m: where a sub-goal is tried, across the climb


@dataclasses.dataclass(frozen=True)
class SegmentConfig:
    """Climbs longer than `min_climb` m (start to goal) are searched in segments: each to a
    sub-goal `lookahead` m ahead (a disc of radius `tolerance`), the first `commit` m of its
    route kept. Each segment's budget is the whole search's rule applied to its own climb."""

    min_climb: float = 7.0
    lookahead: float = 4.0
    commit: float = 2.0
    tolerance: float = 0.6

    def __post_init__(self) -> None:
        for name in ("min_climb", "lookahead", "commit", "tolerance"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    0.0 < value < math.inf):
                raise RbpInputError(f"must be a positive number of metres, got {value!r}",
                                    field=f"footstep.segments.{name}")
        if problem := commit_problem(self.commit, self.lookahead):
            raise RbpInputError(problem, field="footstep.segments.commit")
        if problem := sub_goal_problem(self.tolerance, self.lookahead):
            raise RbpInputError(problem, field="footstep.segments.tolerance")


def climb_distance(scn: Scenario) -> float:
    """The straight distance from the start pose's position to the goal (m)."""
    return float(np.linalg.norm(np.asarray(scn.goal_position, dtype=float)
                                - np.asarray(scn.start_pose[:2], dtype=float)))


def _sub_goal(scn: Scenario, here: np.ndarray, lookahead: float, segment: SegmentConfig,
              config: CompleteConfig) -> Scenario | None:
    """`scn` with its goal moved `lookahead` m from `here` towards the goal (or sideways of
    that, by SIDEWAYS), where some lattice pose within `segment.tolerance` could hold a
    stance."""
    goal = np.asarray(scn.goal_position, dtype=float)
    ahead = (goal - here) / np.linalg.norm(goal - here)
    across = np.array([-ahead[1], ahead[0]])
    for side in SIDEWAYS:
        point = here + lookahead * ahead + side * across
        candidate = dataclasses.replace(scn, goal_position=(float(point[0]), float(point[1])),
                                        goal_tolerance=segment.tolerance)
        if goal_is_holdable(candidate, config.lattice):
            return candidate
    return None


def _kept(result: CompleteResult, here: np.ndarray, ahead: np.ndarray, commit: float) -> int:
    """How many edges of the segment's route to keep: up to the first vertex reached at a pose
    `commit` m or more along `ahead` from `here` (all of them if none is)."""
    for i, pose in enumerate(result.poses, 1):
        if float(np.dot(np.asarray(pose[:2]) - here, ahead)) >= commit:
            return i
    return len(result.poses)


def segmented_search(scn: Scenario, config: CompleteConfig, segment: SegmentConfig,
                     budget: Callable[[Scenario], int | None], *,
                     exclude: Collection[tuple[tuple[str, ...], int, str]] = (),
                     memo: LatticeMemo | None = None,
                     progress: Callable[..., None] | None = None,
                     partial: bool = False) -> CompleteResult:
    """`complete_search` of `scn` with `config`, in segments when the climb is longer than
    `segment.min_climb` (module doc). `budget(scenario)` gives a search's expansion budget on a
    scenario (the whole climb's, or a segment's); `partial`: as `complete_search`'s, for the
    whole search (a failed segment's answer is the whole search's)."""
    memo = memo if memo is not None else LatticeMemo()
    if climb_distance(scn) <= segment.min_climb:
        return complete_search(scn, dataclasses.replace(config, max_expansions=budget(scn)),
                               exclude=exclude, memo=memo, progress=progress, partial=partial)
    t0, clock0 = time.perf_counter(), search_clock()

    def limited(scenario: Scenario) -> CompleteConfig:
        """`config` for a search of `scenario`: its budget, and the time left of the limit."""
        limit = config.time_limit
        if limit is not None:
            limit = max(limit - (search_clock() - clock0), 1e-3)
        return dataclasses.replace(config, max_expansions=budget(scenario), time_limit=limit)

    goal = np.asarray(scn.goal_position, dtype=float)
    done = {"expansions": 0, "tested": 0}

    def offset(expansions: int, tested: int, *args: Any, **kwargs: Any) -> None:
        if progress is not None:
            progress(done["expansions"] + expansions, done["tested"] + tested, *args, **kwargs)

    path: list[Vertex] = []
    poses: list[np.ndarray] = []
    probabilities: list[np.ndarray] = []
    alternatives: list[np.ndarray] = []
    expanded: list[tuple[Vertex, np.ndarray]] = []
    graph = SearchGraph()
    current = scn
    lookahead = segment.lookahead
    while True:
        if config.time_limit is not None and search_clock() - clock0 >= config.time_limit:
            break  # the segments spent the limit: the whole search's answer (a budget stop)
        here = np.asarray(current.start_pose[:2], dtype=float)
        final = float(np.linalg.norm(goal - here)) <= lookahead + scn.goal_tolerance
        target = current if final else _sub_goal(current, here, lookahead, segment, config)
        if target is None:  # no sub-goal can be held: the rest of the climb in one search
            target, final = current, True
        part = complete_search(target, limited(target), exclude=exclude, memo=memo,
                               progress=offset)
        done["expansions"] += part.expansions
        done["tested"] += part.transitions_tested
        expanded += part.expanded
        graph.update(part.graph)
        if not part.success:  # a dead end or a sub-goal out of reach: the whole search decides
            break
        if not part.poses and not final:  # the start's own body motion reaches the sub-goal
            lookahead += segment.commit
            continue
        lookahead = segment.lookahead
        ahead = (goal - here) / max(float(np.linalg.norm(goal - here)), 1e-9)
        keep = len(part.poses) if final else _kept(part, here, ahead, segment.commit)
        others = part.alternatives or [np.asarray(p, dtype=float)[None, :] for p in part.poses]
        path += part.path[:keep] if not final else part.path
        poses += part.poses[:keep]
        probabilities += part.probabilities[:keep]
        alternatives += others[:keep]
        if final:
            return _joined(scn, part, path, poses, probabilities, alternatives, expanded, graph,
                           done, time.perf_counter() - t0)
        end_stance, _ = part.path[keep]
        pose = np.asarray(part.poses[keep - 1], dtype=float)
        current = dataclasses.replace(scn, start_stance=end_stance,
                                      start_pose=(float(pose[0]), float(pose[1]),
                                                  float(pose[2])))
    fallback = complete_search(scn, limited(scn), exclude=exclude, memo=memo, progress=offset,
                               partial=partial)
    expansions = done["expansions"] + fallback.expansions
    reason = fallback.reason
    if fallback.stop == Stop.BUDGET and config.time_limit is not None and \
            search_clock() - clock0 >= config.time_limit:  # the segments' time too: it said 0.001 s
        reason = (f"gave up after {config.time_limit:g} s ({expansions} expansions) without "
                  "reaching the goal")
    return fallback._replace(reason=reason, expansions=expansions,
                             transitions_tested=done["tested"] + fallback.transitions_tested)


def _joined(scn: Scenario, last: CompleteResult, path: list[Vertex], poses: list[np.ndarray],
            probabilities: list[np.ndarray], alternatives: list[np.ndarray],
            expanded: list[tuple[Vertex, np.ndarray]], graph: SearchGraph,
            done: dict[str, int], seconds: float) -> CompleteResult:
    """The segments' kept parts as one route, its cost, and the start's admissible bound."""
    cost = 0.0
    for (a, _), (b, _), pose in zip(path[:-1], path[1:], poses, strict=True):
        boom = next(i for i in range(len(a)) if a[i] != b[i])
        cost += edge_cost(scn, a, boom, b[boom], np.asarray(pose, dtype=float))
    lower = min(RegraspHeuristic(scn)(tuple(scn.start_stance)), cost)
    history = [(seconds, cost, lower, done["expansions"])]
    return CompleteResult(True, Stop.ROUTE, "", path, poses, probabilities, last.goal_pose,
                          done["expansions"], done["tested"], expanded, last.frontier, graph,
                          alternatives, cost, lower, cost, history,
                          Quality.OPTIMAL if cost <= lower else Quality.BOUNDED)
