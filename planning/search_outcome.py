"""How a footstep search ended: why it stopped (`Stop`) and what is known of its route's cost
(`Quality`).

Both are `StrEnum`s: each member is the very string the plan file, the experiments' records
and the tests have always used ("budget", "noroute", "optimal", ...), so a member compares
equal to its string, is written as it, and files read back as plain strings still match.
"""

from __future__ import annotations

from enum import StrEnum


class Stop(StrEnum):
    """Why a footstep search stopped."""

    ROUTE = ""              # a route was found
    BUDGET = "budget"       # max_expansions or time_limit reached: no claim either way
    # every stance (vertex) the search could reach was expanded: not a proof that no route
    # exists (an incomplete search, or moves excluded)
    EXHAUSTED = "exhausted"
    NOROUTE = "noroute"     # a complete search proved that no route exists at its resolution
    NOSTART = "nostart"     # the start pose is joined to no feasible lattice pose


class Quality(StrEnum):
    """What an anytime search proved of its best route's cost."""

    FIRST = ""              # the first route found: no claim
    OPTIMAL = "optimal"     # no route is cheaper (at the lattice's resolution)
    BOUNDED = "bounded"     # at most cost / lower_bound times the optimum (both proven)
