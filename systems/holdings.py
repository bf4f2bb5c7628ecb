"""One trial's drawn strengths laid out per phase (`StrengthDraws`; module `montecarlo` explains
the draws), over a plan's holdings (`planning.probability.Holding`, re-exported here)."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from planning.probability import Holding as Holding  # re-exported
from planning.probability import holdings_of as holdings_of  # re-exported
from rb_drake.params import NUM_BOOMS

if TYPE_CHECKING:
    from systems.trajectory import PlanTrajectory


class StrengthDraws(NamedTuple):
    """One trial's draws laid out per phase: quantile[k, i] is the strength quantile u of the
    holding of boom i in phase k (NaN when free); attach[k] the attach draw of the boom that
    regrasps at the start of phase k (NaN when none), which fails when below attach_failure."""

    quantile: np.ndarray     # (phases, 4)
    attach: np.ndarray       # (phases,)
    attach_boom: np.ndarray  # (phases,) int, -1 when none
    attach_failure: float

    @staticmethod
    def none(plan: PlanTrajectory) -> StrengthDraws:
        """Draws under which nothing ever fails (u = 0, no attach draws)."""
        n = len(plan.phases)
        return StrengthDraws(np.zeros((n, NUM_BOOMS)), np.full(n, np.nan),
                             np.full(n, -1), 0.0)

    @staticmethod
    def for_trial(plan: PlanTrajectory, quantiles: np.ndarray, attach_draws: np.ndarray,
                  attach_failure: float) -> StrengthDraws:
        """From one draw per holding (`plan.holdings` order) of u and of the attach variable."""
        n = len(plan.phases)
        q = np.full((n, NUM_BOOMS), np.nan)
        attach, boom = np.full(n, np.nan), np.full(n, -1)
        for h, hold in enumerate(plan.holdings):
            q[hold.first:hold.last + 1, hold.boom] = quantiles[h]
            if hold.attach:
                attach[hold.first], boom[hold.first] = attach_draws[h], hold.boom
        return StrengthDraws(q, attach, boom, float(attach_failure))
