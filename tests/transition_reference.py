"""A regrasp's four configurations scored through the numpy path (`feasibility.check_poses`
and `feasibility.violation`, one vectorised check per stance kind): the reference the compiled
`planning.transition_score.score_configurations` is tested against
(tests/test_feasibility_kernel.py). Test code only: the planner never calls it.
"""

from __future__ import annotations

import numpy as np

from planning.transition import transition_stances
from planning.transition_score import ALL, VIOLATION_OFFSET, NaiveWorld
from rb_drake.feasibility import check_poses, violation
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance


def score_reference(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str | None,
                    poses: np.ndarray, ignore_grasps: bool, configs: tuple[int, ...] = ALL,
                    known: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray,
                                                              np.ndarray]:
    """`score_configurations` through the numpy path (check_poses + violation)."""
    s_old, s_three, s_new = transition_stances(scn, old, boom, new_anchor)
    world = scn if not ignore_grasps else NaiveWorld(scn)
    P = poses.shape[0]
    r = np.full((P, 4), np.nan) if known is None else known.astype(float, copy=True)
    total_violation = np.zeros(P)
    reason = np.zeros(P, dtype=int)
    feasible = np.ones(P, dtype=bool)
    tip_old = s_old.positions[boom]
    tip_new = s_new.positions[boom] if s_new is not None else None
    # One vectorised check per stance kind: the two 4-stances differ in one anchor (a per-row
    # stance), the two 3-stances in where the free gripper is (a per-row tip).
    groups = []
    fours = [k for k in (0, 3) if k in configs]
    threes = [k for k in (1, 2) if k in configs]
    if fours:
        second = np.repeat([k == 3 for k in fours], P)
        stance = Stance.mix(s_old, s_new, second) if 3 in fours and 0 in fours else (
            s_old if fours == [0] else s_new)
        groups.append((fours, stance, None))
    if threes:
        tips = np.vstack([np.broadcast_to(tip_old if k == 1 else tip_new, (P, 2))
                          for k in threes])
        groups.append((threes, s_three, tips))
    for ks, stance, tip in groups:
        rows_all = np.vstack([poses] * len(ks))
        check = check_poses(world, stance, rows_all, tip, full=True, ignore_grasps=ignore_grasps)
        v = violation(world, stance, rows_all, check, tip, ignore_grasps)
        for n, k in enumerate(ks):
            rows = slice(n * P, (n + 1) * P)
            ok = check.feasible[rows]
            r[:, k] = np.where(ok, check.allocation.robustness[rows], -np.inf)
            total_violation += v[rows]
            codes = check.reason[rows] + 10 * k
            first = (reason == 0) & ~ok | (~ok & (reason > codes))
            reason[first] = codes[first]
            feasible &= ok
    if ignore_grasps:  # the naive planner only asks for feasibility, not robustness
        key = np.where(feasible, 0.0, -VIOLATION_OFFSET - total_violation)
    else:
        key = np.where(feasible, np.nanmin(np.where(np.isnan(r), np.inf, r), axis=1),
                       -VIOLATION_OFFSET - total_violation)
    return key, r, reason
