"""Footstep planning: A* over the graph of 4-stances linked by feasible transitions.

A vertex is a 4-stance (an anchor id per boom); an edge moves one boom to another anchor and
exists when `find_transition` finds a pose holding all four configurations of the move. The
graph is explored lazily (`planning.astar`): candidate anchors come from reach alone, and a
transition is searched only when A* pops it.

Cost and heuristic are `planning.search_cost`'s: an edge costs the regrasp's attach cost plus
each boom's worst -log P over the move's configurations, and the goal-distance heuristic is
multiplied by `heuristic_weight` (default 10, falling back to 300, the paper's distance-driven
search, where 10 finds no route in half the budget) to find a first route fast. The complete
search then goes on for better
routes (`FootstepConfig.anytime`), with an admissible bound that proves how far the best one
is from the optimum (docs/model.md, "Route cost, its lower bound and the anytime search").

Polish. Inside the search a transition is accepted at its first feasible pose. Once a path is
found, each of its transition poses gets a local search for robustness
(`transition.polish_transition`), which raises p_path by 0.03 to 0.08 on the bundled and
generated caves for about a second; `Step.found_pose` keeps the pose the search found.
"""

from __future__ import annotations

import dataclasses
import math
import time
import zlib
from collections.abc import Callable, Collection
from typing import Any, NamedTuple

import numpy as np

from planning.astar import Edge, SearchResult, lazy_astar
from planning.bounded_cache import peak_memory_mb
from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.constrained import constrained_search
from planning.lattice import LatticeConfig
from planning.lattice_search import (
    DEFAULT_MEMORY_MB,
    CompleteResult,
    LatticeMemo,
    Stance4,
    search_result,
    stance4,
)
from planning.ramps import ramp_ends_hold
from planning.refinement import (
    RefinementState,
    Refuted,
    finer_lattices,
    fresh_memo,
    refined_result,
)
from planning.route_repair import RepairConfig, repair_route
from planning.search_cost import (
    DistanceHeuristic,
    attach_cost,
    centroid_distance,
    edge_cost,
    goal_distance,
)
from planning.search_outcome import Quality, Stop
from planning.segmented import SegmentConfig, segmented_search
from planning.transition import (
    ReleaseSet,
    Transition,
    TransitionConfig,
    find_transition,
    polish_transition,
    reachable_anchors,
    release_poses,
)
from rb_drake.errors import RbpInputError
from rb_drake.kernel.scoring import score_poses
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario

SEARCHES = ("hybrid", "complete", "sampled")
ORDERINGS = ("distance", "travel", "distance+travel")  # the complete search's weighted estimates


@dataclasses.dataclass(frozen=True)
class FootstepConfig:
    # "complete" (the default): resolution-complete on the pose lattice (planning.complete):
    # finds a route whenever one exists at its resolution and proves it when none does;
    # "sampled": the sampling search of commit 36a65ef (no proof either way); "hybrid": the
    # sampled search for at most `sampled_expansions`, then the complete one. Since the
    # complete search grows components by flood fill it is as fast as the sampled one where
    # both succeed, with fewer regrasps (docs/benchmarks.md), so it is the default.
    search: str = "complete"
    sampled_expansions: int = 150
    lattice: LatticeConfig = dataclasses.field(default_factory=LatticeConfig)
    # The first route's weight (<= 1: A* on the admissible bound, optimal routes); without a
    # route after `fallback_after` of the expansion budget, the search starts again at
    # `fallback_weight` (None: never), greedy: it finds a route in few expansions where it
    # finds one. On the 69 benchmark routes a weight of 10 found routes with 27 % fewer
    # regrasps than 300 in about the same time, and 300 found the one route that 10 missed
    # within the budget (docs/benchmarks.md, "Session 24")
    heuristic_weight: float = 10.0
    fallback_weight: float | None = 300.0
    fallback_after: float = 0.75
    # complete search: what the weight multiplies (planning.complete_config.CompleteConfig)
    ordering: str = "distance"
    # complete search only: after the first route, better ones for twice its expansions, with
    # a proven bound on how far the best is from the optimum
    # (planning.complete_config.AnytimeConfig; None: the first route, as before)
    anytime: AnytimeConfig | None = dataclasses.field(default_factory=AnytimeConfig)
    # complete search only: the route with the fewest regrasps whose predicted success
    # exp(-cost) is at least this (planning.constrained), or the proof that none reaches it;
    # None: the anytime search
    min_success: float | None = None
    # complete search only: the route improved window by window, each window searched to its
    # optimum (planning.route_repair); None: the route as the search found it
    repair: RepairConfig | None = None
    # complete search with a budget (not --thorough, not min_success): a long climb searched in
    # segments a few metres ahead (planning.segmented; `segments: {}` in a --config file for
    # the defaults of SegmentConfig); None, the default: every climb searched whole (on the
    # long-climb benchmark, segments changed regrasps by -10 % to +7 % and took up to 2x the
    # time: docs/benchmarks.md)
    segments: SegmentConfig | None = None
    candidates_per_boom: int = 8   # sampled search only: anchors tried per boom
    max_expansions: int | None = 1000  # None: no budget (the oracle)
    # complete search: where it finds no route on `lattice`, it searches again on lattices of
    # half the steps, at most this many times (planning.refinement; 0: the lattice's answer)
    refine: int = 1
    # complete search: at most this many MiB of lattice work kept for reuse (components and
    # transitions; past it the least recently used are decided again when needed, with the same
    # answers: planning.bounded_cache); None: no cap
    search_memory_mb: float | None = DEFAULT_MEMORY_MB
    # complete search: the budget grows with the climb, to at least this many expansions per
    # metre from the start pose to the goal (a 20 m climb needs about ten times a 2 m one's
    # search, not the same); 0: max_expansions as given
    expansions_per_metre: float = 300.0
    time_limit: float | None = None    # s; None: no limit
    goal_samples: int = 96
    polish_rounds: int = 8   # local search rounds per transition pose of the found path
    seed: int = 0
    transition: TransitionConfig = dataclasses.field(default_factory=TransitionConfig)

    def __post_init__(self) -> None:
        if self.ordering not in ORDERINGS:
            raise RbpInputError(f"must be one of {', '.join(ORDERINGS)}, got {self.ordering!r}",
                                field="footstep.ordering")
        mb = self.search_memory_mb
        if mb is not None and not (isinstance(mb, int | float) and 1.0 <= mb < math.inf):
            raise RbpInputError(f"must be a number of MiB of at least 1 (or null: no cap), "
                                f"got {mb!r}", field="footstep.search_memory_mb")

    def complete_config(self) -> CompleteConfig:
        """The complete (or constrained) search's part of this configuration."""
        return CompleteConfig(lattice=self.lattice, heuristic_weight=self.heuristic_weight,
                              ordering=self.ordering, fallback_weight=self.fallback_weight,
                              fallback_after=self.fallback_after,
                              max_expansions=self.max_expansions, time_limit=self.time_limit,
                              ignore_grasps=self.transition.ignore_grasps, anytime=self.anytime)


class Step(NamedTuple):
    """One regrasp: boom `boom` moves `from_anchor` -> `to_anchor`, holding `pose` throughout."""

    boom: int
    from_anchor: str
    to_anchor: str
    pose: np.ndarray
    probabilities: np.ndarray  # the four configurations' P (transition.CONFIG_NAMES order)
    found_pose: np.ndarray | None = None  # the search's pose, when polishing moved it
    # (K, 3) other poses that hold the move (and join the same body motions), best first: the
    # complete search's, for the pipeline to try where the gripper's path fails at `pose`
    alternatives: np.ndarray | None = None


class FootstepPlan(NamedTuple):
    success: bool
    reason: str
    stances: list[Stance4]       # S_0 .. S_n
    steps: list[Step]            # n regrasps
    start_pose: np.ndarray
    goal_pose: np.ndarray | None  # a feasible pose in S_n within the goal tolerance
    expansions: int
    transitions_tested: int
    seconds: float
    search: SearchResult[Stance4] | None = None
    transitions: dict | None = None   # every transition tested: (stance, boom, anchor) -> result
    # Why the search stopped (planning.search_outcome.Stop): a route was found, the budget was
    # reached, every stance it could reach was expanded (no proof unless the search is
    # complete), or a complete search proved that no route exists at its resolution.
    stop: Stop = Stop.ROUTE
    explored: list[Explored] | None = None  # expanded stances, in expansion order
    frontier: list[Explored] | None = None  # stances reached but never expanded
    memo: FootstepMemo | None = None  # what the search decided, for a search again
    # The route's search cost (planning.search_cost), and with an anytime search: the proven
    # lower bound on the optimal cost, the first route's cost, (s, cost, lower bound,
    # expansions) at each improvement, and "optimal" or "bounded".
    cost: float = math.nan
    lower_bound: float = math.nan
    first_cost: float = math.nan
    history: list[tuple[float, float, float, int]] | None = None
    quality: Quality = Quality.FIRST
    # --min-success P: the route has the fewest regrasps of those with exp(-cost) >= P (or,
    # with stop "noroute", none reaches P)
    min_success: float | None = None
    # MiB: the process's peak resident memory when the search ended, and the most lattice work
    # its memo kept at once (planning.bounded_cache; at most FootstepConfig.search_memory_mb)
    peak_memory_mb: float = math.nan
    kept_memory_mb: float = math.nan
    # a failed complete search asked for it (`plan_footsteps(partial=True)`): the route to the
    # expanded stance nearest the goal, as a footstep plan (success False, `goal_pose` where the
    # body ends in its last stance, `goal_distance` that stance's centroid distance from the
    # goal), for `rbp plan --partial`
    partial: FootstepPlan | None = None
    goal_distance: float = math.nan
    # the lattices searched after `FootstepConfig.lattice` found no route, coarse to fine (the
    # last one answered: planning.refinement); () when the first lattice answered
    refined: tuple[LatticeConfig, ...] = ()


class Explored(NamedTuple):
    """A stance the search reached, for pictures of where it went."""

    stance: tuple[str, ...]
    pose: np.ndarray       # the body pose it was reached at (the start pose for the start)
    order: int             # expansion order (0 = the start); -1 for the frontier
    goal_distance: float   # footsteps.goal_distance of the stance (m)


def edge_rng(seed: int, stance: tuple[str, ...], boom: int, anchor: str) -> np.random.Generator:
    """A generator that depends only on the edge, so results do not depend on search order."""
    key = zlib.crc32(f"{stance}|{boom}|{anchor}".encode())
    return np.random.default_rng([seed, key])


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


@dataclasses.dataclass
class FootstepMemo:
    """Transitions and release sets already searched on a scenario (same config and seed), so
    that a search repeated with some moves excluded costs only what is new."""

    transitions: dict[tuple, Transition] = dataclasses.field(default_factory=dict)
    releases: dict[tuple, ReleaseSet] = dataclasses.field(default_factory=dict)
    lattice: LatticeMemo = dataclasses.field(default_factory=LatticeMemo)
    # the lattices refuted so far (planning.refinement); `lattice` serves the first one not
    refinement: RefinementState = dataclasses.field(default_factory=RefinementState)


def plan_footsteps(scn: Scenario, config: FootstepConfig | None = None,
                   progress: Callable[..., None] | None = None,
                   exclude: Collection[tuple[tuple[str, ...], int, str]] = (),
                   memo: FootstepMemo | None = None, partial: bool = False) -> FootstepPlan:
    """RBP's footstep plan from the scenario's start stance to a stance that reaches the goal.

    `exclude` holds moves (stance, boom, new anchor) not to take (the pipeline excludes one
    whose motion could not be planned); `memo` carries searched transitions between calls;
    `progress(expansions, transitions tested, nearest goal distance in m)` follows the search;
    `partial`: a failed complete search also returns the route to the expanded stance nearest
    the goal (`FootstepPlan.partial`; the sampled search has none)."""
    cfg = config or FootstepConfig()
    if cfg.search not in SEARCHES:
        raise RbpInputError(f"must be one of {SEARCHES}, got {cfg.search!r}", field="search")
    memo = memo if memo is not None else FootstepMemo()
    if cfg.search == "complete":
        return _plan_complete(scn, cfg, progress, exclude, memo, partial)
    if cfg.search == "hybrid":
        budget = cfg.sampled_expansions
        if cfg.max_expansions is not None:
            budget = min(budget, cfg.max_expansions)
        t0 = time.perf_counter()
        first = plan_footsteps(scn, dataclasses.replace(cfg, search="sampled",
                                                        max_expansions=budget),
                               progress, exclude, memo)
        if first.success:
            return first
        rest = None if cfg.max_expansions is None else max(1, cfg.max_expansions - budget)
        second = _plan_complete(scn, dataclasses.replace(cfg, max_expansions=rest), progress,
                                exclude, memo, partial)
        return second._replace(seconds=time.perf_counter() - t0,
                               expansions=first.expansions + second.expansions,
                               transitions_tested=first.transitions_tested
                               + second.transitions_tested)
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
                        start_data=start_pose, on_expand=on_expand)
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
        stop = Stop.BUDGET if budget else Stop.EXHAUSTED
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


def polished_step(scn: Scenario, cfg: FootstepConfig, stance: tuple[str, ...], boom: int,
                  anchor: str, pose: np.ndarray, probabilities: np.ndarray,
                  alternatives: np.ndarray | None = None) -> Step:
    """A step of the found path. The search accepts a transition at the first pose it finds
    (sampled) or its most robust lattice pose (complete); the few on the chosen path get a
    local search for robustness (p_path rises by 0.03-0.08), keeping the found pose."""
    found = pose
    if cfg.polish_rounds > 0:
        polished, p4 = polish_transition(scn, stance, boom, anchor, found,
                                         edge_rng(cfg.seed, stance, boom, "polish"),
                                         cfg.polish_rounds)
        if cfg.transition.ignore_grasps or ramp_ends_hold(scn, stance, boom, anchor, polished,
                                                          p4):
            pose, probabilities = polished, p4
    return Step(boom, stance[boom], anchor, pose, probabilities, found, alternatives)


def segmented(cfg: FootstepConfig) -> bool:
    """Whether `cfg` searches a long climb in segments: a budgeted anytime search (the oracle,
    `--thorough`, and `min_success` search the whole climb for their proofs)."""
    return (cfg.segments is not None and cfg.max_expansions is not None
            and cfg.min_success is None and cfg.anytime is not None
            and cfg.anytime.improve_factor is not None)


def expansion_budget(scn: Scenario, cfg: FootstepConfig) -> int | None:
    """The complete search's expansion budget on `scn`: max_expansions, or more for a long
    climb (`expansions_per_metre` times the start's distance to the goal)."""
    if cfg.max_expansions is None:
        return None
    climb = float(np.linalg.norm(np.asarray(scn.start_pose[:2]) - np.asarray(scn.goal_position)))
    return max(int(cfg.max_expansions), math.ceil(cfg.expansions_per_metre * climb))


def _plan_complete(scn: Scenario, cfg: FootstepConfig,
                   progress: Callable[..., None] | None,
                   exclude: Collection[tuple[tuple[str, ...], int, str]],
                   memo: FootstepMemo, partial: bool = False) -> FootstepPlan:
    """plan_footsteps through the complete search (planning.complete)."""
    t0 = time.perf_counter()
    start_pose = np.asarray(scn.start_pose, dtype=float)
    asked = cfg
    cfg = dataclasses.replace(cfg, max_expansions=expansion_budget(scn, cfg))
    memo.lattice.set_memory(cfg.search_memory_mb)
    # --min-success answers for its P on the lattice asked (no refinement)
    lattices = finer_lattices(scn, cfg.lattice, cfg.refine if cfg.min_success is None else 0)
    excluded = frozenset((tuple(st), int(j), a) for st, j, a in exclude)
    level = memo.refinement.first_open(lattices, excluded)
    refuted = [r for r in memo.refinement.refuted if r.lattice in lattices[:level]]
    while True:
        # a time limit holds for all the lattices together
        left = None if cfg.time_limit is None else max(
            1e-3, cfg.time_limit - (time.perf_counter() - t0))
        result = _search_lattice(
            scn, dataclasses.replace(asked, lattice=lattices[level], time_limit=left),
            dataclasses.replace(cfg, lattice=lattices[level], time_limit=left), progress,
            exclude, memo, partial)
        if result.stop not in (Stop.NOROUTE, Stop.EXHAUSTED) or level == len(lattices) - 1:
            break
        refuted.append(Refuted(lattices[level], excluded, result.expansions,
                               result.transitions_tested))
        memo.refinement.refuted.append(refuted[-1])
        memo.lattice = fresh_memo(memo.lattice)  # the next lattice's; this one is refuted
        level += 1
    if refuted:
        result = refined_result(result, refuted, lattices[level])
    cfg = dataclasses.replace(cfg, lattice=lattices[level])
    refined = tuple(lattices[1:level + 1])
    if cfg.min_success is None and cfg.repair is not None and result.success:
        result = repair_route(scn, result, memo.lattice, cfg.repair,
                              cfg.transition.ignore_grasps, exclude)
    search = search_result(result)
    peak, kept = _memory(memo)
    explored = [Explored(v[0], np.asarray(p, dtype=float), k, goal_distance(scn, v[0]))
                for k, (v, p) in enumerate(result.expanded)]
    frontier = [Explored(v[0], np.asarray(p, dtype=float), -1, goal_distance(scn, v[0]))
                for v, p in result.frontier]
    start = stance4(scn.start_stance)
    if not result.success:
        reason = result.reason
        if explored:
            nearest = min(centroid_distance(scn, e.stance) for e in explored)
            reason += (f"; the nearest stance reached is {nearest:.2f} m from the goal (the "
                       f"start is {centroid_distance(scn, start):.2f} m)")
        failed = FootstepPlan(False, reason, [start], [], start_pose, None, result.expansions,
                              result.transitions_tested, time.perf_counter() - t0, search, None,
                              result.stop, explored, frontier, memo,
                              min_success=cfg.min_success, peak_memory_mb=peak,
                              kept_memory_mb=kept, refined=refined)
        near = result.partial
        if near is None:
            return failed
        stances = [v[0] for v in near.path]
        route = failed._replace(
            stances=stances, goal_pose=np.asarray(near.end_pose, dtype=float),
            steps=_route_steps(scn, cfg, stances, near.poses, near.probabilities,
                               near.alternatives),
            goal_distance=near.goal_distance)
        return failed._replace(partial=route)
    stances = [v[0] for v in result.path]
    steps = _route_steps(scn, cfg, stances, result.poses, result.probabilities,
                         result.alternatives)
    return FootstepPlan(True, "", stances, steps, start_pose, result.goal_pose,
                        result.expansions, result.transitions_tested,
                        time.perf_counter() - t0, search, None, Stop.ROUTE, explored, frontier,
                        memo,
                        result.cost, result.lower_bound, result.first_cost, result.history,
                        result.quality, cfg.min_success, peak, kept, refined=refined)


def _search_lattice(scn: Scenario, asked: FootstepConfig, cfg: FootstepConfig,
                    progress: Callable[..., None] | None,
                    exclude: Collection[tuple[tuple[str, ...], int, str]],
                    memo: FootstepMemo, partial: bool) -> CompleteResult:
    """One complete (or constrained, or segmented) search on `cfg.lattice` (`asked`: the
    configuration as given, `cfg` with its budget for this climb)."""
    if cfg.min_success is not None:
        return constrained_search(scn, cfg.min_success, cfg.complete_config(),
                                  exclude=exclude, memo=memo.lattice, progress=progress)
    if segmented(asked):
        assert asked.segments is not None
        return segmented_search(scn, asked.complete_config(), asked.segments,
                                lambda part: expansion_budget(part, asked), exclude=exclude,
                                memo=memo.lattice, progress=progress, partial=partial)
    return complete_search(scn, cfg.complete_config(), exclude=exclude, memo=memo.lattice,
                           progress=progress, partial=partial)


def _route_steps(scn: Scenario, cfg: FootstepConfig, stances: list[Stance4],
                 poses: list[np.ndarray], probabilities: list[np.ndarray],
                 alternatives: list[np.ndarray] | None) -> list[Step]:
    """The polished steps of a route found by the complete search."""
    steps = []
    no_alternatives: list[np.ndarray | None] = [None] * len(poses)
    others = alternatives or no_alternatives
    for a, b, pose, p4, other in zip(stances[:-1], stances[1:], poses, probabilities, others,
                                     strict=True):
        j = next(i for i in range(NUM_BOOMS) if a[i] != b[i])
        steps.append(polished_step(scn, cfg, a, j, b[j], np.asarray(pose, dtype=float), p4,
                                   other))
    return steps


def _memory(memo: FootstepMemo) -> tuple[float, float]:
    """FootstepPlan's peak_memory_mb and kept_memory_mb, as the search ends."""
    kept = memo.lattice.pool.peak_bytes
    return peak_memory_mb(), kept / 2.0 ** 20


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
