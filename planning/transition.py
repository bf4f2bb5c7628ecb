"""Transition feasibility: one pose that holds a stance change of one boom.

Boom j moves from anchor a to anchor b. The transition is feasible when a single pose q is
feasible in the old 4-stance, in the new 4-stance, and in the common 3-stance with the free
gripper at a and at b (the two limiting cantilever cases, paper section III-C). The search is
random sampling of poses plus a local refinement (a cross-entropy search) that maximises the
worst of the four configurations' robustness, all vectorised over poses, seeded and with a
fixed sample budget.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from rb_drake import geometry
from rb_drake.feasibility import REASON_TEXT, Reason, check_poses, violation
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

CONFIG_NAMES = ("old 4-stance", "3-stance, gripper at old anchor",
                "3-stance, gripper at new anchor", "new 4-stance")


@dataclasses.dataclass(frozen=True)
class TransitionConfig:
    candidates: int = 2000         # cheap random poses, ranked by reach alone
    samples: int = 64              # of those, the best poses evaluated in full
    search_rounds: int = 5         # cross-entropy rounds at most
    refine_rounds: int = 2         # rounds spent raising robustness once feasible
    refine_samples: int = 32       # poses per round
    elite: int = 8
    spread: float = 0.6            # m, std of the initial position samples
    phi_range: float = 1.2         # rad, orientations drawn uniformly in +-phi_range
    max_reach_violation: float = 0.5  # give up at once when no sample comes this near
    hopeless_violation: float = 2.0   # ... or when the best full sample is this far off
    patience: int = 2                 # rounds without progress before giving up
    ignore_grasps: bool = False    # the naive baseline: limit surfaces play no part


class Transition(NamedTuple):
    feasible: bool
    pose: np.ndarray | None          # (3,)
    probabilities: np.ndarray | None  # (4,) P of the four configurations, CONFIG_NAMES order
    reason: str                      # why not, when infeasible
    evaluated: int                   # poses evaluated


def transition_stances(scn: Scenario, old: tuple[str, ...], boom: int,
                       new_anchor: str) -> tuple[Stance, Stance, Stance]:
    new = tuple(new_anchor if i == boom else a for i, a in enumerate(old))
    s_old = scn.stance(old)
    return s_old, s_old.without(boom), scn.stance(new)


def _score(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str, poses: np.ndarray,
           ignore_grasps: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pose: a search key (the worst robustness of the four configurations where all are
    feasible; minus their summed violation, below -VIOLATION_OFFSET, where not), the four
    robustnesses, and the first failure code (10 * configuration + Reason)."""
    s_old, s_three, s_new = transition_stances(scn, old, boom, new_anchor)
    world = scn if not ignore_grasps else _NaiveWorld(scn)
    P = poses.shape[0]
    # Two vectorised checks instead of four: the two 4-stances differ in one anchor (a per-row
    # stance), the two 3-stances in where the free gripper is (a per-row tip). Rows [0, P)
    # are the first configuration of each pair, rows [P, 2P) the second.
    second = np.repeat([False, True], P)
    both = np.vstack([poses, poses])
    four = Stance.mix(s_old, s_new, second)
    tips = np.where(second[:, None], s_new.positions[boom], s_old.positions[boom])
    r = np.full((P, 4), -np.inf)
    total_violation = np.zeros(P)
    reason = np.zeros(P, dtype=int)
    feasible = np.ones(P, dtype=bool)
    results = {}
    for name, stance, tip in (("four", four, None), ("three", s_three, tips)):
        check = check_poses(world, stance, both, tip, full=True, ignore_grasps=ignore_grasps)
        results[name] = (check, violation(world, stance, both, check, tip, ignore_grasps))
    # configurations in CONFIG_NAMES order: old 4, 3 at old, 3 at new, new 4
    for k, (name, half) in enumerate((("four", 0), ("three", 0), ("three", 1), ("four", 1))):
        check, v = results[name]
        rows = slice(half * P, (half + 1) * P)
        ok = check.feasible[rows]
        r[:, k] = np.where(ok, check.allocation.robustness[rows], -np.inf)
        feasible &= ok
        total_violation += v[rows]
        first = (reason == 0) & ~ok
        reason[first] = check.reason[rows][first] + 10 * k
    if ignore_grasps:  # the naive planner only asks for feasibility, not robustness
        key = np.where(feasible, 0.0, -VIOLATION_OFFSET - total_violation)
    else:
        key = np.where(feasible, r.min(axis=1), -VIOLATION_OFFSET - total_violation)
    return key, r, reason


VIOLATION_OFFSET = 1e3  # keys of infeasible poses sit below every feasible robustness


class _NaiveWorld:
    """The scenario as the naive baseline sees it (same rock, robot and gravity)."""

    def __init__(self, scn: Scenario):
        self.robot = scn.robot
        self.rock = scn.rock
        self.gravity_vector = scn.gravity_vector


def find_transition(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str,
                    rng: np.random.Generator, guess: np.ndarray | None = None,
                    config: TransitionConfig | None = None) -> Transition:
    """Search a pose that holds boom `boom`'s move to `new_anchor` (see module doc)."""
    cfg = config or TransitionConfig()
    robot = scn.robot
    s_old, _, s_new = transition_stances(scn, old, boom, new_anchor)
    # Centre the samples where the five anchors' booms can meet: each anchor less its boom's
    # mid-range reach along the boom's equilibrium direction.
    anchors = np.vstack([s_old.positions, s_new.positions[boom:boom + 1]])
    booms = np.array([0, 1, 2, 3, boom])
    directions = robot.shoulder_directions[booms]
    reach = 0.5 * (robot.boom_length[0] + robot.boom_length[1])
    centres = anchors - robot.shoulder_array[booms] - reach * np.stack(
        [np.cos(directions), np.sin(directions)], axis=1)
    centre = centres.mean(axis=0)
    # Draw cheap candidates and keep the `samples` whose five booms come closest to their length
    # and shoulder ranges (pure geometry, microseconds a pose) before the expensive statics.
    m = cfg.candidates
    cand = np.empty((m, 3))
    cand[:, :2] = centre + rng.normal(0.0, cfg.spread, (m, 2))
    cand[:, 2] = rng.uniform(-cfg.phi_range, cfg.phi_range, m)
    if guess is not None:  # half of them near the pose the robot holds now
        k = m // 2
        cand[:k, :2] = guess[:2] + rng.normal(0.0, 0.5 * cfg.spread, (k, 2))
        cand[:k, 2] = np.where(rng.uniform(size=k) < 0.5, guess[2] + rng.normal(0.0, 0.3, k),
                               rng.uniform(-cfg.phi_range, cfg.phi_range, k))
    kin = _kinematic_violation(robot, cand, anchors, booms)
    if kin.min() > cfg.max_reach_violation:
        return Transition(False, None, None, "no pose found: no sampled pose comes near "
                          "reaching all five anchors within boom length and shoulder range", m)
    # Rank by reach; many candidates reach all five anchors, so ties are broken at random (a
    # stable sort would keep only the first-drawn, those near `guess`, and miss the rotated
    # poses that releasing an upper boom needs).
    order = np.lexsort((rng.uniform(size=m), kin))
    poses = cand[order[:cfg.samples]]
    key, r4, reason = _score(scn, old, boom, new_anchor, poses, cfg.ignore_grasps)
    evaluated = len(poses)
    best = int(np.argmax(key))
    best_pose, best_key, best_r4 = poses[best].copy(), key[best], r4[best]
    # The explanation of a rejection comes from the sample that got furthest: most
    # configurations passed, then the latest test failed (probability is the last).
    miss = _furthest(reason, r4)
    top = np.argsort(key)[::-1][:cfg.elite]
    elite, elite_key = poses[top], key[top]
    if best_key < -VIOLATION_OFFSET - cfg.hopeless_violation:
        return Transition(False, None, None, _explain(miss), evaluated)
    # Cross-entropy search: descend the violation until feasible, then raise the robustness.
    rounds = stalled = 0
    while stalled < cfg.patience and rounds < cfg.search_rounds and (
            best_key < -VIOLATION_OFFSET
            or (rounds < cfg.refine_rounds and not cfg.ignore_grasps)):
        rounds += 1
        mean = elite.mean(axis=0)
        std = np.maximum(elite.std(axis=0), [0.02, 0.02, 0.02])
        cand = mean + rng.normal(0.0, 1.0, (cfg.refine_samples, 3)) * std
        k2, r2, reason2 = _score(scn, old, boom, new_anchor, cand, cfg.ignore_grasps)
        evaluated += len(cand)
        stalled += 1
        if k2.max() > best_key:
            stalled = 0
            b = int(np.argmax(k2))
            best_key, best_pose, best_r4 = k2[b], cand[b].copy(), r2[b]
        miss = max(miss, _furthest(reason2, r2))
        pool = np.vstack([elite, cand])
        pool_key = np.concatenate([elite_key, k2])
        top = np.argsort(pool_key)[::-1][:cfg.elite]
        elite, elite_key = pool[top], pool_key[top]
    if best_key < -VIOLATION_OFFSET:
        return Transition(False, None, None, _explain(miss), evaluated)
    return Transition(True, best_pose, np.exp(best_r4), "", evaluated)


def _furthest(reason: np.ndarray, r4: np.ndarray) -> tuple[int, int]:
    """(progress, failure code) of the sample that got furthest: the most configurations
    feasible, then the latest failing test (codes as `_score`'s)."""
    passed = np.isfinite(r4).sum(axis=1)
    progress = passed * 100 + reason % 10
    k = int(np.argmax(progress))
    return int(progress[k]), int(reason[k])


def _explain(miss: tuple[int, int]) -> str:
    """Why the sample that got furthest failed, in words."""
    config, reason = divmod(miss[1], 10)
    return (f"no pose found: nearest miss fails with {REASON_TEXT[Reason(reason)]} in the "
            f"{CONFIG_NAMES[config]}")


def reachable_anchors(scn: Scenario, stance: tuple[str, ...], boom: int, pose: np.ndarray,
                      rng: np.random.Generator, samples: int = 400) -> np.ndarray:
    """Indices of anchors boom `boom` can reach from some pose that also reaches the stance's
    four anchors (boom length and shoulder range only): the cheap filter before any search.
    The poses are sampled around `pose`."""
    robot = scn.robot
    held = scn.anchor_positions[[scn.anchor_index[a] for a in stance]]
    poses = np.column_stack([pose[0] + rng.normal(0.0, 0.5, samples),
                             pose[1] + rng.normal(0.0, 0.5, samples),
                             rng.uniform(-0.8, 0.8, samples)])
    ok = _kinematic_violation(robot, poses, held, np.arange(4)) == 0.0
    if not ok.any():
        return np.zeros(0, dtype=int)
    pts = scn.anchor_positions
    reachable = (geometry.reach(robot, poses[ok], pts, np.full(len(pts), boom)).violation
                 == 0.0).any(axis=0)
    reachable[[scn.anchor_index[a] for a in stance]] = False
    return np.flatnonzero(reachable)


def _kinematic_violation(robot, poses: np.ndarray, anchors: np.ndarray,
                         booms: np.ndarray) -> np.ndarray:
    """How far boom booms[k] at each pose is from reaching anchors[k], summed over k (m + rad)."""
    return geometry.reach(robot, poses, anchors, booms).violation.sum(axis=1)
