"""Progress lines on stderr (tqdm), shown only on a terminal and never with --quiet.

`SearchProgress` is the live line of `rbp plan`: stances expanded (of the search's budget),
transitions tested and the elapsed time during the footstep search (plan_footsteps' `progress`
callback), then the phase being seeded and optimised. tqdm is imported only when a line is shown.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any


def interactive(quiet: bool = False) -> bool:
    """Whether progress lines are wanted: stderr is a terminal and --quiet was not given."""
    return not quiet and sys.stderr.isatty()


class SearchProgress:
    """A context manager whose `search(expansions, tested)` and `phase(text)` update one line."""

    def __init__(self, label: str, budget: int | None, quiet: bool = False):
        self.label = label
        self.budget = budget
        self.bar: Any = None
        if interactive(quiet):
            from tqdm import tqdm

            self.bar = tqdm(total=budget, desc=f"{label}: search", unit=" stances",
                            file=sys.stderr, leave=False, dynamic_ncols=True,
                            bar_format="{desc}: {n_fmt}/{total_fmt} stances expanded"
                                       "{postfix} [{elapsed}]")
        self.shown = 0.0
        self.route_bound: float | None = None

    def search(self, expansions: int, tested: int, nearest: float | None = None,
               bound: float | None = None) -> None:
        """plan_footsteps' progress callback; `nearest` (m from the goal) and, once an anytime
        search has a route, `bound` (its cost over the proven lower bound), when a search
        reports them, are shown too."""
        if self.bar is not None:
            self.bar.n = expansions  # a repeated search (the pipeline's retries) starts again
            if bound is not None:
                self.route_bound = bound
            text = f"{tested} transitions tested"
            if self.route_bound is not None and math.isfinite(self.route_bound):
                text += f", route within {self.route_bound:.2f}x of the best"
            elif nearest is not None:
                text += f", nearest {nearest:.2f} m from the goal"
            self.bar.set_postfix_str(text, refresh=False)
            now = time.monotonic()
            if now - self.shown >= 0.1:  # at most ten redraws a second
                self.shown = now
                self.bar.refresh()

    def phase(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_description_str(f"{self.label}: {text[:80]}", refresh=True)

    def __enter__(self) -> SearchProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
