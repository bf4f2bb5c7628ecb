"""A regrasp's four configurations scored at many poses at once: the step every transition
search repeats (`planning.transition`, and the lattice's `planning.lattice_moves` through the
same kernel rows).

Boom j moves from anchor a to anchor b. The four configurations (`CONFIG_NAMES`) are the old
4-stance, the 3-stance with the free gripper at a and at b, and the new 4-stance; the first two
do not depend on b (`RELEASE`), the last two do (`ARRIVE`). `score_configurations` packs them
as kernel stances and evaluates every configuration at every pose in one compiled call
(`rb_drake.kernel.scoring.score_rows`); a pose's key orders the search: its worst robustness where
all hold, below -`VIOLATION_OFFSET` by their summed violation where some do not.
"""

from __future__ import annotations

import numpy as np

from rb_drake.kernel.scoring import PackedStances, score_rows
from rb_drake.scenario import AnchorTable, Scenario

CONFIG_NAMES = ("old 4-stance", "3-stance, gripper at old anchor",
                "3-stance, gripper at new anchor", "new 4-stance")
RELEASE = (0, 1)   # the configurations that do not depend on the new anchor
ARRIVE = (2, 3)
ALL = (0, 1, 2, 3)  # configurations (CONFIG_NAMES), not booms

VIOLATION_OFFSET = 1e3  # keys of infeasible poses sit below every feasible robustness

# Each configuration's (CONFIG_NAMES order) stance row and tip row in `_configurations`
_STANCE_OF = np.array([0, 1, 1, 2])
_TIP_OF = np.array([0, 1, 2, 0])


class NaiveWorld:
    """The scenario as the naive baseline sees it (same rock, robot and gravity): the kernel
    reads only these, so grasps play no part."""

    def __init__(self, scn: Scenario):
        self.robot = scn.robot
        self.rock = scn.rock
        self.gravity_vector = scn.gravity_vector
        self.anchor_positions = scn.anchor_positions


def pack_rows(table: AnchorTable, rows: list[list[int]],
              tips: list[int]) -> tuple[PackedStances, np.ndarray]:
    """Kernel stances from rows of anchor-table indices, one per boom (the table's last row,
    `len(table.row)`, leaves that boom free), and the tips' positions from table indices."""
    idx = np.array(rows)
    stances = PackedStances(table.positions[idx], table.normals[idx], table.f_normal[idx],
                            table.f_lateral[idx], table.sigma_normal[idx],
                            table.sigma_lateral[idx], idx != len(table.row))
    return stances, table.positions[np.array(tips)]


def _configurations(scn: Scenario, old: tuple[str, ...], boom: int,
                    new_anchor: str | None) -> tuple[PackedStances, np.ndarray, np.ndarray,
                                                     np.ndarray]:
    """A move's stances (old 4-stance, 3-stance, new 4-stance if any) and free-gripper tips
    (none, at the old anchor, at the new one) as kernel rows, and each configuration's
    (CONFIG_NAMES order) stance row and tip row."""
    table = scn.anchor_table
    free = len(table.row)
    held = [table.row[a] for a in old]
    rows = [held, held.copy()]
    rows[1][boom] = free
    tips = [free, held[boom]]
    if new_anchor is not None:
        rows.append(held.copy())
        rows[2][boom] = table.row[new_anchor]
        tips.append(rows[2][boom])
    stances, tip_points = pack_rows(table, rows, tips)
    return stances, tip_points, _STANCE_OF, _TIP_OF


def score_configurations(scn: Scenario, old: tuple[str, ...], boom: int,
                         new_anchor: str | None, poses: np.ndarray, ignore_grasps: bool,
                         configs: tuple[int, ...] = ALL, known: np.ndarray | None = None,
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pose: a search key, the four robustnesses (-inf where infeasible, NaN where not
    evaluated) and the first failure code (10 * configuration + Reason; 0 if none).

    Only `configs` are evaluated; `known` (P, 4) supplies robustnesses already computed for the
    others (all feasible). The key is the worst robustness where every configuration is
    feasible, and minus the evaluated configurations' summed violation, below
    -VIOLATION_OFFSET, where not (0 for all feasible poses when grasps are ignored).

    Every configuration at every pose is one row of one compiled call
    (`rb_drake.kernel.scoring.score_rows`); the tests' `score_reference` is the same through
    check_poses and violation."""
    if new_anchor is None and any(k in configs for k in ARRIVE):
        raise ValueError("the arrival configurations need the new anchor")
    stances, tips, stance_of, tip_of = _configurations(scn, old, boom, new_anchor)
    world = scn if not ignore_grasps else NaiveWorld(scn)
    P = poses.shape[0]
    ks = np.array([k for k in (0, 3, 1, 2) if k in configs], dtype=np.int64)  # as score_reference
    C = len(ks)
    check = score_rows(world, stances, tips, poses, np.tile(np.arange(P), C),
                       np.repeat(stance_of[ks], P), np.repeat(tip_of[ks], P), ignore_grasps)
    ok = check.feasible.reshape(C, P)
    r = np.full((P, 4), np.nan) if known is None else known.astype(float, copy=True)
    r[:, ks] = np.where(ok, check.robustness.reshape(C, P), -np.inf).T
    total_violation = np.zeros(P)
    for v in check.violation.reshape(C, P):  # summed in score_reference's order
        total_violation += v
    # The first failure: the lowest failing configuration's code.
    codes = np.where(ok, np.iinfo(np.int64).max, check.reason.reshape(C, P) + 10 * ks[:, None])
    feasible = ok.all(axis=0)
    reason = np.where(feasible, 0, codes.min(axis=0, initial=np.iinfo(np.int64).max))
    if ignore_grasps:  # the naive planner only asks for feasibility, not robustness
        key = np.where(feasible, 0.0, -VIOLATION_OFFSET - total_violation)
    else:
        key = np.where(feasible, np.nanmin(np.where(np.isnan(r), np.inf, r), axis=1),
                       -VIOLATION_OFFSET - total_violation)
    return key, r, reason
