"""What a footstep search is asked (`FootstepConfig`) and what it answers (`FootstepPlan`, its
`Step`s, the stances it `Explored`), and the memo (`FootstepMemo`) a search again reuses: shared
by the complete search (`planning.footsteps`) and the sampled one (`planning.sampled_search`).
A found route's transition poses are polished for robustness here (`polished_step`).
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from typing import NamedTuple

import numpy as np

from planning.astar import SearchResult
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.lattice import LatticeConfig
from planning.lattice_search import (
    DEFAULT_MEMORY_MB,
    LatticeMemo,
    Stance4,
)
from planning.ramps import ramp_ends_hold
from planning.refinement import (
    RefinementState,
)
from planning.route_repair import RepairConfig
from planning.search_outcome import Quality, Stop
from planning.segmented import SegmentConfig
from planning.transition import (
    ReleaseSet,
    Transition,
    TransitionConfig,
    polish_transition,
    transition_stances,
)
from rb_drake.errors import RbpInputError
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


@dataclasses.dataclass
class FootstepMemo:
    """Transitions and release sets already searched on a scenario (same config and seed), so
    that a search repeated with some moves excluded costs only what is new."""

    transitions: dict[tuple, Transition] = dataclasses.field(default_factory=dict)
    releases: dict[tuple, ReleaseSet] = dataclasses.field(default_factory=dict)
    lattice: LatticeMemo = dataclasses.field(default_factory=LatticeMemo)
    # the lattices refuted so far (planning.refinement); `lattice` serves the first one not
    refinement: RefinementState = dataclasses.field(default_factory=RefinementState)


def holds_as_built(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
                   pose: np.ndarray) -> bool:
    """Whether the transition's four configurations hold at `pose` as the plan will be built
    and verified (`check_poses` and its robust allocation: finite tensions on every attached
    boom). The polish scores poses with the search's compiled tests; pushed to the edge of
    feasibility (300 rounds), it found poses where the allocation failed and the plan's ramps
    lost their tensions, so `rbp check` refused a plan that `rbp plan` called a success."""
    from rb_drake.feasibility import check_poses

    s_old, s_three, s_new = transition_stances(scn, stance, boom, anchor)
    assert s_new is not None  # a new anchor is given
    tips = (s_old.positions[boom], s_new.positions[boom])
    for st, tip in ((s_old, None), (s_three, tips[0]), (s_three, tips[1]), (s_new, None)):
        check = check_poses(scn, st, np.asarray(pose, dtype=float)[None], tip, full=True)
        tensions = check.allocation.tensions[0][st.attached]
        if not (bool(check.feasible[0]) and np.all(np.isfinite(tensions))):
            return False
    return True


def polished_step(scn: Scenario, cfg: FootstepConfig, stance: tuple[str, ...], boom: int,
                  anchor: str, pose: np.ndarray, probabilities: np.ndarray,
                  alternatives: np.ndarray | None = None) -> Step:
    """A step of the found path. The search accepts a transition at the first pose it finds
    (sampled) or its most robust lattice pose (complete); the few on the chosen path get a
    local search for robustness (p_path rises by 0.03-0.08), keeping the found pose."""
    found = pose
    # polishing raises the grasps' probabilities: a search that ignores them (the naive
    # baseline's transitions) may have found a pose where they fall below p_min, which
    # polishing cannot start from, and has nothing to raise
    if cfg.polish_rounds > 0 and not cfg.transition.ignore_grasps:
        polished, p4 = polish_transition(scn, stance, boom, anchor, found,
                                         edge_rng(cfg.seed, stance, boom, "polish"),
                                         cfg.polish_rounds)
        if ramp_ends_hold(scn, stance, boom, anchor, polished, p4) and \
                holds_as_built(scn, stance, boom, anchor, polished):
            pose, probabilities = polished, p4
    return Step(boom, stance[boom], anchor, pose, probabilities, found, alternatives)
