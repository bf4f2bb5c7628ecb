"""How the complete footstep search (`planning.complete`) is configured: the search itself
(`CompleteConfig`) and its anytime part, which looks for better routes after the first
(`AnytimeConfig`).

Kept apart from the search's code so that the footstep configuration (`FootstepConfig` in
`planning.footsteps`, which holds the same fields with `rbp plan`'s defaults), the command line
and the experiments can name the configuration without the search.
"""

from __future__ import annotations

import dataclasses
import math

from planning.lattice import LatticeConfig


@dataclasses.dataclass(frozen=True)
class AnytimeConfig:
    """After the first route, the search goes on for better ones (docs/model.md): each route
    found lowers the ordering weight to the next of `weights` (a weight <= 1 orders by the
    admissible bound itself: A*), and everything that cannot beat the best route is pruned. It
    stops when the best cost is within `target_bound` of the proven lower bound (1: optimal),
    when nothing is left that could beat it (optimal), or when its improvement budget is spent.

    The budget is work, not time, so that the same cave gives the same plan on any machine
    and under any load: `improve_factor` times the first route's expansions (at least
    `improve_min`); None: no limit but the search's own (`rbp plan --thorough`)."""

    weights: tuple[float, ...] = (5.0, 3.0, 2.0, 1.0)
    target_bound: float = 1.0
    improve_factor: float | None = 2.0
    improve_min: int = 50
    # Each better route restarts the search at the next weight (from the start, the lattice
    # work kept in the memo) instead of re-keying the open list (ARA*): a greedy first search
    # leaves poor g-values behind that a lower weight has to undo one vertex at a time (Richter,
    # Thayer and Ruml, "The joy of forgetting", ICAPS 2010).
    restart: bool = True
    # m, or None: after a route, a pass expands only stances whose anchors' centroid lies
    # within `corridor` of the best route's centroids (joined by segments); what it leaves out
    # keeps its part of the lower bound (the least g + bound of the moves left out), so the
    # bound stays proven while the passes spend their budget near the route they improve.
    corridor: float | None = None

    def improve_expansions(self, first: int) -> float:
        """Expansions to look for better routes once the first took `first` expansions."""
        if self.improve_factor is None:
            return math.inf
        return max(float(self.improve_min), self.improve_factor * first)


@dataclasses.dataclass(frozen=True)
class CompleteConfig:
    """How `complete_search` searches (the scenario, the moves to leave out, the memo and the
    progress callback are not configuration: they are its other arguments).

    `FootstepConfig` (planning.footsteps) holds the same fields for `rbp plan`, with the plan's
    defaults (an anytime search with a budget); these defaults are the bare search's: the first
    route, no budget."""

    lattice: LatticeConfig = dataclasses.field(default_factory=LatticeConfig)
    # <= 1: A* ordered by the admissible bound, the first route is then optimal; above, the
    # weighted `ordering` estimate (planning.search_cost): "distance", the anchors' distance to
    # the goal (`DistanceHeuristic`), or "travel", each boom's travel (`TravelHeuristic`)
    heuristic_weight: float = 300.0
    ordering: str = "distance"
    # None: no fallback; else, when no route is found after `fallback_after` of
    # `max_expansions`, the search starts again at this weight (the lattice work kept in the
    # memo): a moderate weight finds better first routes in about the same time on most caves,
    # a greedy one finds a route on the few where the moderate one wanders (docs/model.md)
    fallback_weight: float | None = None
    fallback_after: float = 0.5
    max_expansions: int | None = None  # stop with Stop.BUDGET after this many; None: no limit
    time_limit: float | None = None    # s: stop with Stop.BUDGET after it; None: no limit
    ignore_grasps: bool = False        # decide poses without the grasps' probabilities
    # the start joins the lattice poses at the corners of its cell, and of the cells of 2, 4,
    # ... this many steps (a refined lattice: those of the coarser, planning.refinement)
    start_cell_steps: int = 1
    anytime: AnytimeConfig | None = None  # after the first route, better ones; None: first
