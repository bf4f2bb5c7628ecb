"""The sampled footstep search of commit 36a65ef (`FootstepConfig.search` "sampled", and the
first stage of "hybrid"): lazy A* over 4-stances (`planning.astar`), candidate anchors by reach,
nearest the goal first; a transition is searched by sampling poses when A* pops it, and the
goal by sampling poses within its tolerance. It proves nothing either way: "exhausted" means
only that the stances it could reach were expanded.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Collection
from typing import Any, NamedTuple

import numpy as np

from planning.astar import Edge, SearchResult, lazy_astar
from planning.footstep_plan import (
    Explored,
    FootstepConfig,
    FootstepMemo,
    FootstepPlan,
    edge_rng,
    polished_step,
)
from planning.lattice_search import (
    Stance4,
    stance4,
)
from planning.search_cost import (
    DistanceHeuristic,
    attach_cost,
    centroid_distance,
    edge_cost,
    goal_distance,
)
from planning.search_outcome import Stop
from planning.transition import (
    find_transition,
    reachable_anchors,
    release_poses,
)
from rb_drake.kernel.scoring import score_poses
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


def goal_pose_in(scn: Scenario, stance: tuple[str, ...], rng: np.random.Generator,
                 samples: int, ignore_grasps: bool = False) -> np.ndarray | None:
    """The most robust sampled pose within the goal tolerance that is feasible in `stance`."""
    robot = scn.robot
    goal = np.asarray(scn.goal_position)
    reach = robot.max_reach
    pts = scn.anchor_positions[[scn.anchor_index[a] for a in stance]]
    if np.any(np.linalg.norm(pts - goal, axis=1) > reach + scn.goal_tolerance):
        return None
    radius = scn.goal_tolerance * np.sqrt(rng.uniform(0.0, 1.0, samples))
    ang = rng.uniform(0.0, 2 * math.pi, samples)
    poses = np.column_stack([goal[0] + radius * np.cos(ang), goal[1] + radius * np.sin(ang),
                             rng.normal(0.0, 0.3, samples)])
    check = score_poses(scn, scn.stance(stance), poses, ignore_grasps=ignore_grasps)
    if not check.feasible.any():
        return None
    # Among feasible poses the most robust; the naive planner's may all have r = -inf.
    score = np.where(check.feasible, np.maximum(check.robustness, -1e300), -np.inf)
    return poses[int(np.argmax(score))]


def candidate_moves(scn: Scenario, stance: tuple[str, ...], pose: np.ndarray,
                    per_boom: int, seed: int = 0) -> list[tuple[int, str]]:
    """(boom, anchor) moves worth testing: reachable, nearest the goal first, per boom."""
    goal = np.asarray(scn.goal_position)
    moves = []
    rng = np.random.default_rng([seed, zlib.crc32(str(stance).encode())])
    for j in range(NUM_BOOMS):
        idx = reachable_anchors(scn, stance, j, pose, rng)
        order = np.argsort(np.linalg.norm(scn.anchor_positions[idx] - goal, axis=1))
        moves += [(j, scn.anchors[k].id) for k in idx[order][:per_boom]]
    return moves


def plan_sampled(scn: Scenario, cfg: FootstepConfig,
                 progress: Callable[..., None] | None,
                 exclude: Collection[tuple[tuple[str, ...], int, str]],
                 memo: FootstepMemo) -> FootstepPlan:
    """The sampled search of commit 36a65ef (`FootstepConfig.search` "sampled"): lazy A*
    over 4-stances, candidate anchors by reach, a transition searched by sampling poses
    when A* pops it; no proof either way (`plan_footsteps`' arguments)."""
    t0 = time.perf_counter()
    c_attach = attach_cost(scn.robot)
    distance_heuristic = DistanceHeuristic(scn)
    start = stance4(scn.start_stance)
    start_pose = np.asarray(scn.start_pose, dtype=float)
    cache, releases = memo.transitions, memo.releases
    excluded = {(tuple(st), int(j), a) for st, j, a in exclude}
    goal_rng = np.random.default_rng([cfg.seed, 1])
    tested = 0

    def successors(node: Stance4, pose: np.ndarray):
        for j, anchor in candidate_moves(scn, node, pose, cfg.candidates_per_boom, cfg.seed):
            child = stance4(anchor if i == j else a for i, a in enumerate(node))
            yield child, (j, anchor), c_attach

    def evaluate(node: Stance4, child: Stance4, key: tuple[int, str], pose: np.ndarray):
        nonlocal tested
        j, anchor = key
        ck = (node, j, anchor)
        if ck in excluded:
            return None
        if ck not in cache:
            tested += 1
            if (node, j) not in releases:  # shared by every move of boom j from this stance
                releases[node, j] = release_poses(scn, node, j,
                                                  edge_rng(cfg.seed, node, j, "release"),
                                                  guess=pose, config=cfg.transition)
            cache[ck] = find_transition(scn, node, j, anchor, edge_rng(cfg.seed, node, j, anchor),
                                        guess=pose, config=cfg.transition,
                                        release=releases[node, j])
        tr = cache[ck]
        if not tr.feasible:
            return None
        assert tr.pose is not None  # a feasible transition's
        return Edge(edge_cost(scn, node, j, anchor, tr.pose), tr.pose)

    def heuristic(node: Stance4) -> float:
        return distance_heuristic(node)

    def is_goal(node: Stance4, pose: np.ndarray):
        return goal_pose_in(scn, node, goal_rng, cfg.goal_samples)

    nearest = [math.inf]

    def on_expand(n: int, node: Stance4) -> None:
        if progress is not None:
            nearest[0] = min(nearest[0], goal_distance(scn, node))
            progress(n, tested, nearest[0])

    result = lazy_astar(start, successors, evaluate, heuristic,
                        is_goal=lambda n, d: _as_goal(is_goal(n, d)),
                        weight=cfg.heuristic_weight,
                        max_expansions=cfg.max_expansions or 10**9,
                        start_data=start_pose, on_expand=on_expand,
                        time_limit=cfg.time_limit)
    seconds = time.perf_counter() - t0
    if not result.success:
        explored, frontier = explored_stances(scn, result, start_pose)
        # the expanded stances, as the complete search measures them (and the search picture)
        closest = min((centroid_distance(scn, e.stance) for e in explored),
                      default=centroid_distance(scn, start))
        reason = (f"{result.reason}; the nearest stance reached is {closest:.2f} m from the "
                  f"goal (the start is {centroid_distance(scn, start):.2f} m)")
        budget = cfg.max_expansions is not None and result.expansions >= cfg.max_expansions
        if budget:
            reason += f"; a longer search may find one (max_expansions, now {cfg.max_expansions})"
        elif result.timed_out:  # the time limit was not passed on (a 10 s limit ran 44 s)
            reason += f"; a longer search may find one (time_limit, now {cfg.time_limit:g} s)"
        stop = Stop.BUDGET if budget or result.timed_out else Stop.EXHAUSTED
        return FootstepPlan(False, reason, [start], [], start_pose, None,
                            result.expansions, tested, seconds, result, cache, stop, explored,
                            frontier, memo)
    steps = []
    for a, b, pose in zip(result.path[:-1], result.path[1:], result.edges, strict=True):
        j = next(i for i in range(NUM_BOOMS) if a[i] != b[i])
        probabilities = cache[(a, j, b[j])].probabilities
        assert probabilities is not None  # the path's transitions are feasible
        steps.append(polished_step(scn, cfg, a, j, b[j], pose, probabilities))
    seconds = time.perf_counter() - t0
    explored, frontier = explored_stances(scn, result, start_pose)
    return FootstepPlan(True, "", list(result.path), steps, start_pose, result.goal_data.pose,
                        result.expansions, tested, seconds, result, cache, Stop.ROUTE, explored,
                        frontier, memo)


def explored_stances(scn: Scenario, result: SearchResult[Stance4],
                     start_pose: np.ndarray) -> tuple[list[Explored], list[Explored]]:
    """The expanded stances in order, and the frontier (reached by a feasible transition but
    never expanded), each with the pose it was reached at."""
    expanded = {node: k for k, node in enumerate(result.expanded)}
    explored, frontier = [], []
    for node, k in expanded.items():
        pose = start_pose if k == 0 else (result.node_data or {}).get(node, start_pose)
        explored.append(Explored(node, np.asarray(pose, dtype=float), k,
                                 goal_distance(scn, node)))
    for _parent, node, data in result.graph.edges(data="data"):
        if node not in expanded and data is not None:
            frontier.append(Explored(node, np.asarray(data, dtype=float), -1,
                                     goal_distance(scn, node)))
            expanded[node] = -1
    return explored, frontier


class _Goal(NamedTuple):
    pose: np.ndarray


def _as_goal(pose: np.ndarray | None) -> Any:
    return _Goal(pose) if pose is not None else None
