"""Progress lines on stderr (tqdm), shown only on a terminal and never with --quiet.

`SearchProgress` is the live line of `rbp plan`: stances expanded (of the search's budget),
transitions tested and the elapsed time during the footstep search (plan_footsteps' `progress`
callback), then the phase being seeded and optimised. `CheckProgress` is `rbp check`'s (and the
verification before simulate and rig-run): phases verified of the plan's, shown only when the
check has run for CHECK_DELAY seconds. tqdm is imported only when a line is shown.
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


CHECK_DELAY = 1.0  # s: a check shorter than this shows no line


class CheckProgress:
    """A context manager called as `(phases_done, phases)` by `planning.check.verify_plan`:
    one line "LABEL: N/M phases verified [elapsed<remaining]" on a terminal, after
    CHECK_DELAY seconds (a 300-phase plan took 111 s with no sign of life)."""

    def __init__(self, label: str, quiet: bool = False, delay: float = CHECK_DELAY):
        self.label = label
        self.show = interactive(quiet)
        self.delay = delay
        self.bar: Any = None
        self.shown = 0.0
        self.start = time.monotonic()

    def __call__(self, done: int, total: int) -> None:
        if not self.show:
            return
        if self.bar is None:
            if time.monotonic() - self.start < self.delay:
                return
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self.label, unit=" phases", file=sys.stderr,
                            leave=False, dynamic_ncols=True, initial=done,
                            bar_format="{desc}: {n_fmt}/{total_fmt} phases verified "
                                       "[{elapsed}<{remaining}]")
            self.bar.start_t -= time.monotonic() - self.start  # elapsed since the check began
        self.bar.n = done
        now = time.monotonic()
        if now - self.shown >= 0.1 or done == total:  # at most ten redraws a second
            self.shown = now
            self.bar.refresh()

    def __enter__(self) -> CheckProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
