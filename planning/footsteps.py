"""Footstep planning: a route of 4-stances from the start to the goal (`plan_footsteps`).

A vertex is a 4-stance (an anchor id per boom); an edge moves one boom to another anchor and
exists when a pose holds all four configurations of the move. The default search is the
complete one on the pose lattice (`planning.complete`), searched again on finer lattices where
its lattice has no route (`planning.refinement`); `search: sampled` is the sampled search of
commit 36a65ef (`planning.sampled_search`) and "hybrid" that, then the complete one. What a
search is asked and answers (`FootstepConfig`, `FootstepPlan`) is `planning.footstep_plan`'s.

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
import re
import time
from collections.abc import Callable, Collection
from typing import Any

import numpy as np

from planning.bounded_cache import peak_memory_mb
from planning.complete import complete_search
from planning.constrained import constrained_search
from planning.footstep_plan import (
    ORDERINGS,
    SEARCHES,
    Explored,
    FootstepConfig,
    FootstepMemo,
    FootstepPlan,
    Step,
    edge_rng,
    polished_step,
)
from planning.lattice_search import (
    CompleteResult,
    Stance4,
    search_result,
    stance4,
)
from planning.refinement import (
    REFINED_STOPS,
    Refuted,
    finer_lattices,
    fresh_memo,
    refined_result,
)
from planning.route_repair import repair_route
from planning.sampled_search import candidate_moves, explored_stances, goal_pose_in, plan_sampled
from planning.search_clock import search_clock
from planning.search_cost import (
    centroid_distance,
    goal_distance,
)
from planning.search_outcome import Stop
from planning.segmented import segmented_search
from rb_drake.errors import RbpInputError
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


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
        t0, clock0 = time.perf_counter(), search_clock()
        first = plan_footsteps(scn, dataclasses.replace(cfg, search="sampled",
                                                        max_expansions=budget),
                               progress, exclude, memo)
        if first.success or (cfg.max_expansions is not None and cfg.max_expansions <= budget):
            return first  # a route, or the whole budget spent by the sampled stage
        rest = None if cfg.max_expansions is None else cfg.max_expansions - budget
        # the time limit holds for both stages together (each had all of it)
        left = None if cfg.time_limit is None else max(
            1e-3, cfg.time_limit - (search_clock() - clock0))
        second = _plan_complete(scn, dataclasses.replace(cfg, max_expansions=rest,
                                                         time_limit=left),
                                progress, exclude, memo, partial)
        expansions = first.expansions + second.expansions
        reason = second.reason  # the two stages' time and expansions (it said the second's)
        if left is not None and second.stop == Stop.BUDGET:
            reason = re.sub(r"^gave up after \S+ s \(\d+ expansions\)",
                            f"gave up after {cfg.time_limit:g} s ({expansions} expansions)",
                            reason)
        return second._replace(seconds=time.perf_counter() - t0, reason=reason,
                               expansions=expansions,
                               transitions_tested=first.transitions_tested
                               + second.transitions_tested)
    return plan_sampled(scn, cfg, progress, exclude, memo)


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
    t0, clock0 = time.perf_counter(), search_clock()
    start_pose = np.asarray(scn.start_pose, dtype=float)
    asked = cfg
    cfg = dataclasses.replace(cfg, max_expansions=expansion_budget(scn, cfg))
    memo.lattice.set_memory(cfg.search_memory_mb)
    # --min-success answers for its P on the lattice asked (no refinement)
    lattices = finer_lattices(scn, cfg.lattice, cfg.refine if cfg.min_success is None else 0)
    excluded = frozenset((tuple(st), int(j), a) for st, j, a in exclude)
    level = memo.refinement.first_open(lattices, excluded)
    refuted = memo.refinement.refutations(lattices, level, excluded)
    while True:
        # a time limit holds for all the lattices together
        left = None if cfg.time_limit is None else max(
            1e-3, cfg.time_limit - (search_clock() - clock0))
        result = _search_lattice(
            scn, dataclasses.replace(asked, lattice=lattices[level], time_limit=left),
            dataclasses.replace(cfg, lattice=lattices[level], time_limit=left),
            _counted_on(progress, refuted), exclude, memo, partial, 2 ** level)
        if result.stop not in REFINED_STOPS or level == len(lattices) - 1:
            break
        refuted.append(Refuted(lattices[level], excluded, result.expansions,
                               result.transitions_tested, result.stop))
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


def _counted_on(progress: Callable[..., None] | None,
                refuted: list[Refuted]) -> Callable[..., None] | None:
    """`progress`, its expansions and transitions counted on from the lattices refuted before
    (as the plan's search record counts them)."""
    if progress is None or not refuted:
        return progress
    done = sum(r.expansions for r in refuted), sum(r.transitions_tested for r in refuted)

    def counted(expansions: int, tested: int, *args: Any, **kwargs: Any) -> None:
        progress(expansions + done[0], tested + done[1], *args, **kwargs)

    return counted


def _search_lattice(scn: Scenario, asked: FootstepConfig, cfg: FootstepConfig,
                    progress: Callable[..., None] | None,
                    exclude: Collection[tuple[tuple[str, ...], int, str]],
                    memo: FootstepMemo, partial: bool, start_cell_steps: int = 1
                    ) -> CompleteResult:
    """One complete (or constrained, or segmented) search on `cfg.lattice` (`asked`: the
    configuration as given, `cfg` with its budget for this climb); the start joins the poses
    of its cell of `start_cell_steps` steps too (the base lattice's, once refined)."""
    if cfg.min_success is not None:
        return constrained_search(scn, cfg.min_success, cfg.complete_config(),
                                  exclude=exclude, memo=memo.lattice, progress=progress)
    if segmented(asked):
        assert asked.segments is not None
        return segmented_search(
            scn, dataclasses.replace(asked.complete_config(), start_cell_steps=start_cell_steps),
            asked.segments, lambda part: expansion_budget(part, asked), exclude=exclude,
            memo=memo.lattice, progress=progress, partial=partial)
    return complete_search(
        scn, dataclasses.replace(cfg.complete_config(), start_cell_steps=start_cell_steps),
        exclude=exclude, memo=memo.lattice, progress=progress, partial=partial)


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


# What the footstep stage exports: the configuration and the plan types (planning.footstep_plan),
# the searches, and the sampled search's helpers the pipeline and the tests use.
__all__ = ["ORDERINGS", "SEARCHES", "Explored", "FootstepConfig", "FootstepMemo", "FootstepPlan",
           "Step", "candidate_moves", "edge_rng", "expansion_budget", "explored_stances",
           "goal_pose_in", "plan_footsteps", "plan_sampled", "polished_step", "segmented"]
