"""The success probability of a whole climb.

A holding is boom i attached to one anchor from attach to detach. Each holding draws its grasp
strength once, so it survives iff it survives its worst instant: its survival probability is
the minimum of P_i over the configurations it goes through. Holdings are independent, and every
regrasp must also take hold on contact (probability 1 - attach_failure):

    p_path = prod_holdings min_t P_i(t) * (1 - attach_failure)^regrasps.

`p_grasps`, the first factor alone, is how likely the grasps are to hold once taken: the
paper's robustness metric has no attach term, so its path probabilities compare with this one
(with attach_failure = 0.01, a plan of more than 10 regrasps has p_path < 0.90 however robust
its grasps).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

from rb_drake.params import NUM_BOOMS


class Holding(NamedTuple):
    """Boom `boom` on `anchor` during phases first..last; `attach` when it starts by a regrasp."""

    boom: int
    anchor: str
    first: int
    last: int
    attach: bool


def holdings_of(stances: Sequence[Sequence[str | None]]) -> list[Holding]:
    """Maximal runs of phases (their stances, in order) in which a boom stays on one anchor:
    the holdings `path_probability` counts."""
    out: list[Holding] = []
    for i in range(NUM_BOOMS):
        k = 0
        while k < len(stances):
            anchor = stances[k][i]
            end = k
            while end + 1 < len(stances) and stances[end + 1][i] == anchor:
                end += 1
            if anchor is not None:
                out.append(Holding(i, anchor, k, end, attach=k > 0))
            k = end + 1
    return sorted(out, key=lambda h: (h.first, h.boom))


class PathProbability(NamedTuple):
    p_path: float
    p_grasps: float    # p_path without the attach term: prod_holdings min_t P_i(t)
    p_min: float       # the smallest configuration probability along the plan
    regrasps: int
    holdings: list[tuple[int, str, float]]  # (boom, anchor, min P) in the order they end


class Configuration(NamedTuple):
    """One instant of a plan: anchor id per boom (None: free) and P per boom (None: free)."""

    stance: Sequence[str | None]
    p_grasp: Sequence[float | None]
    p_success: float


def path_probability(configurations: Iterable[Configuration],
                     attach_failure: float) -> PathProbability:
    current: list[str | None] = [None] * NUM_BOOMS
    worst = [1.0] * NUM_BOOMS
    holdings: list[tuple[int, str, float]] = []
    regrasps = 0
    p_min = 1.0
    first = True
    for config in configurations:
        p_min = min(p_min, float(config.p_success))
        for i, (anchor, p) in enumerate(zip(config.stance, config.p_grasp, strict=True)):
            if anchor != current[i]:
                if (held := current[i]) is not None:
                    holdings.append((i, held, worst[i]))
                if anchor is not None and not first:
                    regrasps += 1
                current[i], worst[i] = anchor, 1.0
            if anchor is not None and p is not None:
                worst[i] = min(worst[i], float(p))
        first = False
    for i in range(NUM_BOOMS):
        if (held := current[i]) is not None:
            holdings.append((i, held, worst[i]))
    p_grasps = 1.0
    for _, _, p in holdings:
        p_grasps *= p
    p_path = p_grasps * (1.0 - attach_failure) ** regrasps
    return PathProbability(p_path, p_grasps, p_min, regrasps, holdings)
