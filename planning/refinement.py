"""Refinement: a complete search that finds no route on its lattice searches again on finer ones.

The complete search decides reachability over the points of one world-fixed pose lattice, so
"no route at 2 cm / 2.5 deg" says only that no route passes through those points: a move that
holds in a sliver of poses thinner than a cell (a shoulder limit on one side, P < p_min on the
other) can fall between them, and the same cave moved by a fraction of a cell can then plan.
So where the search exhausts its lattice without a route (or finds the start pose joined to none
of its points), it is searched again on the lattice
of half the steps (position and angle; every coarse point is a point of the finer lattice),
`FootstepConfig.refine` times at most, coarse to fine. The answer is a route from the finest
lattice searched, or "no route" at every lattice tried, or a budget stop on a finer one
(undecided). It is still an answer about lattice points, not a proof for every pose
(docs/model.md, "What "no route" means").

A lattice found without a route under some excluded moves stays without one under more of
them (the pipeline excludes moves whose motion fails, one at a time), so a memo remembers the
lattices refuted and the search again starts at the first one not refuted.
"""

from __future__ import annotations

import dataclasses

from planning.lattice import ANGLE_STEP_RANGE, POSITION_STEP_RANGE, LatticeConfig, span_problem
from planning.lattice_search import CompleteResult, LatticeMemo
from planning.search_outcome import Stop
from rb_drake.scenario import Scenario

# the answers a finer lattice may change: no route through the points, with or without moves
# excluded, and a start pose joined to none of them (the start's cell holds no pose it reaches)
REFINED_STOPS = (Stop.NOROUTE, Stop.EXHAUSTED, Stop.NOSTART)


def finer_lattices(scn: Scenario, base: LatticeConfig, levels: int) -> list[LatticeConfig]:
    """`base`, then up to `levels` lattices each of half the steps before it, as long as the
    steps stay within their ranges and the lattice indexes the whole cave."""
    out = [base]
    for _ in range(levels):
        position, angle = out[-1].position_step / 2.0, out[-1].angle_step_deg / 2.0
        if position < POSITION_STEP_RANGE[0] or angle < ANGLE_STEP_RANGE[0]:
            break
        finer = LatticeConfig(position_step=position, angle_step_deg=angle)
        if span_problem(scn, finer):
            break
        out.append(finer)
    return out


def resolution_text(cfg: LatticeConfig) -> str:
    """"2 cm / 2.5 deg": a lattice's steps as the search's reasons give them."""
    return f"{cfg.position_step * 100:g} cm / {cfg.angle_step_deg:g} deg"


@dataclasses.dataclass(frozen=True)
class Refuted:
    """A lattice searched without a route: under `excluded` moves, in `expansions`; `stop`
    says how (no route through its points, or a start joined to none of them)."""

    lattice: LatticeConfig
    excluded: frozenset
    expansions: int
    transitions_tested: int
    stop: Stop = Stop.NOROUTE

    def text(self) -> str:
        if self.stop == Stop.NOSTART:
            return f"{resolution_text(self.lattice)} (the start joined to none of its poses)"
        n = self.expansions
        return f"{resolution_text(self.lattice)} ({n} {'vertex' if n == 1 else 'vertices'})"


@dataclasses.dataclass
class RefinementState:
    """What a footstep memo knows of its lattices: those refuted so far (coarse to fine)."""

    refuted: list[Refuted] = dataclasses.field(default_factory=list)

    def first_open(self, lattices: list[LatticeConfig], excluded: frozenset) -> int:
        """The index in `lattices` of the first one not refuted under a subset of `excluded`
        (len - 1 at most: the finest is always searched, so that an answer comes back)."""
        level = 0
        while level < len(lattices) - 1 and any(
                r.lattice == lattices[level] and r.excluded <= excluded for r in self.refuted):
            level += 1
        return level

    def refutations(self, lattices: list[LatticeConfig], level: int,
                    excluded: frozenset) -> list[Refuted]:
        """For each of `lattices[:level]` (`first_open`'s level), the refutation it skips on:
        one per lattice, though a lattice searched again under other exclusions has two."""
        return [next(r for r in reversed(self.refuted)
                     if r.lattice == lattice and r.excluded <= excluded)
                for lattice in lattices[:level]]


def fresh_memo(like: LatticeMemo) -> LatticeMemo:
    """An empty memo with `like`'s memory cap, for the next lattice (a memo serves one)."""
    memo = LatticeMemo()
    memo.set_memory(like.memory_mb)
    return memo


def refined_result(result: CompleteResult, refuted: list[Refuted],
                    lattice: LatticeConfig) -> CompleteResult:
    """The result on `lattice`, its work counting the coarser lattices' and its reason
    saying where they found no route."""
    where = ", ".join(r.text() for r in refuted)
    reason = result.reason
    head = "no route at resolution "
    if result.stop in (Stop.NOROUTE, Stop.EXHAUSTED):
        reason = (f"{head}{where} nor, refined, at " + reason.removeprefix(head)
                  if reason.startswith(head)
                  else f"{head}{where} nor, refined, at {resolution_text(lattice)}: {reason}")
    elif result.stop == Stop.BUDGET:
        reason = f"{head}{where}; refined to {resolution_text(lattice)}, the search {reason}"
    elif not result.success:
        reason = f"{head}{where}; refined to {resolution_text(lattice)}: {reason}"
    return result._replace(
        reason=reason,
        expansions=result.expansions + sum(r.expansions for r in refuted),
        transitions_tested=result.transitions_tested + sum(r.transitions_tested
                                                           for r in refuted))


__all__ = ["REFINED_STOPS", "RefinementState", "Refuted", "finer_lattices", "fresh_memo",
           "refined_result", "resolution_text"]
