"""Transition feasibility: one pose that holds a stance change of one boom.

Boom j moves from anchor a to anchor b. The transition is feasible when a single pose q is
feasible in the old 4-stance, in the new 4-stance, and in the common 3-stance with the free
gripper at a and at b (the two limiting cantilever cases, paper section III-C).

Two of the four configurations do not depend on b: the old 4-stance and the 3-stance with the
gripper still at a. Poses feasible in both, the *release poses* of boom j, are searched once per
(stance, boom) and shared by every move of that boom (`release_poses`); they are rare where a
boom carries much of the load (an upper boom in a passage), so this is where the sampling budget
goes. A move to b then checks only the release poses that reach b, in the other two
configurations, and falls back to a cross-entropy search on all four from the nearest of them.
A few refinement rounds raise the worst of the four robustnesses. Everything is vectorised over
poses, seeded, and has a fixed sample budget.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from planning.lattice_kernels import reach_violation
from planning.transition_score import (
    ALL,
    ARRIVE,
    CONFIG_NAMES,
    RELEASE,
    VIOLATION_OFFSET,
    score_configurations,
)
from rb_drake.feasibility import REASON_TEXT, Reason
from rb_drake.kernel.scoring import score_poses
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance


@dataclasses.dataclass(frozen=True)
class TransitionConfig:
    release_candidates: int = 3000  # cheap random poses per (stance, boom), ranked by reach
    release_samples: int = 160      # the best of those, checked in the two release configurations
    release_rounds: int = 3         # cross-entropy rounds toward release poses if none is found
    samples: int = 48               # release poses reaching the new anchor, checked for arrival
    search_rounds: int = 4          # cross-entropy rounds on all four configurations, at most
    refine_rounds: int = 1          # rounds spent raising robustness once feasible
    refine_samples: int = 32        # poses per round
    elite: int = 8
    spread: float = 0.6             # m, std of the initial position samples
    phi_range: float = 1.2          # rad, orientations drawn uniformly in +-phi_range
    max_reach_violation: float = 0.5  # give up at once when no sample comes this near
    hopeless_violation: float = 2.0   # ... or when the best full sample is this far off
    patience: int = 2                 # rounds without progress before giving up
    ignore_grasps: bool = False     # the naive baseline: limit surfaces play no part


class Transition(NamedTuple):
    feasible: bool
    pose: np.ndarray | None          # (3,)
    probabilities: np.ndarray | None  # (4,) P of the four configurations, CONFIG_NAMES order
    reason: str                      # why not, when infeasible
    evaluated: int                   # poses evaluated (configurations / 4)


class ReleaseSet(NamedTuple):
    """Poses at which boom j can let go: feasible in the old 4-stance and in the 3-stance with
    the gripper at its old anchor."""

    poses: np.ndarray       # (R, 3)
    robustness: np.ndarray  # (R, 4): the two release configurations' r, NaN for the others
    reason: str             # why there are none
    evaluated: int


def transition_stances(scn: Scenario, old: tuple[str, ...], boom: int,
                       new_anchor: str | None) -> tuple[Stance, Stance, Stance | None]:
    s_old = scn.stance(old)
    if new_anchor is None:
        return s_old, s_old.without(boom), None
    new = tuple(new_anchor if i == boom else a for i, a in enumerate(old))
    return s_old, s_old.without(boom), scn.stance(new)


def _sample_around(rng: np.random.Generator, centre: np.ndarray, guess: np.ndarray | None,
                   m: int, cfg: TransitionConfig) -> np.ndarray:
    """m random poses: around `centre`, half of them near the pose held now (`guess`)."""
    cand = np.empty((m, 3))
    cand[:, :2] = centre + rng.normal(0.0, cfg.spread, (m, 2))
    cand[:, 2] = rng.uniform(-cfg.phi_range, cfg.phi_range, m)
    if guess is not None:
        k = m // 2
        cand[:k, :2] = guess[:2] + rng.normal(0.0, 0.5 * cfg.spread, (k, 2))
        cand[:k, 2] = np.where(rng.uniform(size=k) < 0.5, guess[2] + rng.normal(0.0, 0.3, k),
                               rng.uniform(-cfg.phi_range, cfg.phi_range, k))
    return cand


def _meeting_point(scn: Scenario, anchors: np.ndarray, booms: np.ndarray) -> np.ndarray:
    """Where the booms can meet: each anchor less its boom's mid-range reach along the boom's
    equilibrium direction, averaged."""
    robot = scn.robot
    directions = robot.shoulder_directions[booms]
    reach = 0.5 * (robot.boom_length[0] + robot.boom_length[1])
    centres = anchors - robot.shoulder_array[booms] - reach * np.stack(
        [np.cos(directions), np.sin(directions)], axis=1)
    return centres.mean(axis=0)


def _best_by_reach(rng: np.random.Generator, kin: np.ndarray, n: int) -> np.ndarray:
    """Indices of the n candidates nearest to reaching (ties, often many at zero, at random:
    a stable order would favour the first drawn, those near the current pose)."""
    return np.lexsort((rng.uniform(size=len(kin)), kin))[:n]


def _cross_entropy(scn, old, boom, new_anchor, elite, elite_key, rng, cfg, configs, rounds,
                   keep_going) -> tuple[np.ndarray, np.ndarray, np.ndarray, int,
                                        tuple[int, int]]:
    """Rounds of cross-entropy search from an elite set; returns every sample drawn with its
    key and robustness, plus the evaluation count and the furthest miss."""
    poses, keys, rs = [], [], []
    evaluated = 0
    miss = (-1, 0)
    best = float(elite_key.max())
    stalled = 0
    for n in range(rounds):
        if stalled >= cfg.patience or not keep_going(best, n):
            break
        mean = elite.mean(axis=0)
        std = np.maximum(elite.std(axis=0), [0.02, 0.02, 0.02])
        cand = mean + rng.normal(0.0, 1.0, (cfg.refine_samples, 3)) * std
        k2, r2, reason2 = score_configurations(scn, old, boom, new_anchor, cand,
                                               cfg.ignore_grasps, configs)
        evaluated += len(cand) * len(configs)
        miss = max(miss, _furthest(reason2, r2))
        stalled = 0 if k2.max() > best else stalled + 1
        best = max(best, float(k2.max()))
        poses.append(cand)
        keys.append(k2)
        rs.append(r2)
        pool = np.vstack([elite, cand])
        pool_key = np.concatenate([elite_key, k2])
        top = np.argsort(pool_key)[::-1][:cfg.elite]
        elite, elite_key = pool[top], pool_key[top]
    if not poses:
        return np.zeros((0, 3)), np.zeros(0), np.zeros((0, 4)), evaluated, miss
    return np.vstack(poses), np.concatenate(keys), np.vstack(rs), evaluated, miss


def release_poses(scn: Scenario, old: tuple[str, ...], boom: int, rng: np.random.Generator,
                  guess: np.ndarray | None = None,
                  config: TransitionConfig | None = None) -> ReleaseSet:
    """The poses found at which boom `boom` can let go of its anchor in stance `old`."""
    cfg = config or TransitionConfig()
    robot = scn.robot
    held = scn.stance(old).positions
    centre = _meeting_point(scn, held, np.arange(NUM_BOOMS))
    cand = _sample_around(rng, centre, guess, cfg.release_candidates, cfg)
    kin = _kinematic_violation(robot, cand, held, np.arange(NUM_BOOMS))
    if kin.min() > cfg.max_reach_violation:
        return ReleaseSet(np.zeros((0, 3)), np.zeros((0, 4)), "no sampled pose reaches the four "
                          "anchors within boom length and shoulder range", len(cand))
    poses = cand[_best_by_reach(rng, kin, cfg.release_samples)]
    key, r, reason = score_configurations(scn, old, boom, None, poses, cfg.ignore_grasps, RELEASE)
    evaluated = 2 * len(poses)
    miss = _furthest(reason, r)
    ok = key > -VIOLATION_OFFSET
    found_poses, found_r = [poses[ok]], [r[ok]]
    if not ok.any() and key.max() >= -VIOLATION_OFFSET - cfg.hopeless_violation:
        top = np.argsort(key)[::-1][:cfg.elite]
        more, k2, r2, n, miss2 = _cross_entropy(
            scn, old, boom, None, poses[top], key[top], rng, cfg, RELEASE, cfg.release_rounds,
            lambda best, n: best < -VIOLATION_OFFSET)
        evaluated += n
        miss = max(miss, miss2)
        ok2 = k2 > -VIOLATION_OFFSET
        found_poses.append(more[ok2])
        found_r.append(r2[ok2])
    poses, r = np.vstack(found_poses), np.vstack(found_r)
    reason_text = "" if len(poses) else _explain(miss)
    return ReleaseSet(poses, r, reason_text, evaluated // 4)


def find_transition(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str,
                    rng: np.random.Generator, guess: np.ndarray | None = None,
                    config: TransitionConfig | None = None,
                    release: ReleaseSet | None = None) -> Transition:
    """Search a pose that holds boom `boom`'s move to `new_anchor` (see module doc).

    `release` is boom `boom`'s `release_poses` in `old`, shared between moves; without it
    they are searched here first, with the same generator."""
    cfg = config or TransitionConfig()
    robot = scn.robot
    target = scn.anchor_positions[scn.anchor_index[new_anchor]]
    if release is not None and not len(release.poses):  # shared and known empty: no search
        return _cannot_let_go(boom, release)
    # Reach first (geometry only, microseconds a pose): can any pose reach all five anchors?
    five = np.vstack([scn.stance(old).positions, target[None]])
    booms = np.array([0, 1, 2, 3, boom])
    cand = _sample_around(rng, _meeting_point(scn, five, booms), guess, cfg.release_candidates // 2,
                          cfg)
    if _kinematic_violation(robot, cand, five, booms).min() > cfg.max_reach_violation:
        return Transition(False, None, None, "no pose found: no sampled pose comes near reaching "
                          "all five anchors within boom length and shoulder range", 0)
    if release is None:
        release = release_poses(scn, old, boom, rng, guess, cfg)
    evaluated = 0
    if not len(release.poses):
        return _cannot_let_go(boom, release)
    kin = reach_violation(robot, release.poses, target[None], np.array([boom]))[:, 0]
    if kin.min() > cfg.max_reach_violation:
        return Transition(False, None, None, f"no pose found: no pose at which boom {boom} can "
                          "let go comes near to reach the new anchor within boom length and "
                          "shoulder range", 0)
    reaching = np.flatnonzero(kin == 0.0)
    if len(reaching) > cfg.samples:
        reaching = rng.choice(reaching, cfg.samples, replace=False)
    poses = release.poses[reaching]
    key, r4, reason = score_configurations(scn, old, boom, new_anchor, poses,
                                           cfg.ignore_grasps, ARRIVE,
                                           known=release.robustness[reaching])
    evaluated += 2 * len(poses)
    miss = _furthest(reason, r4) if len(poses) else (-1, 0)
    if len(poses) and key.max() < -VIOLATION_OFFSET - cfg.hopeless_violation:
        return Transition(False, None, None, _explain(miss), (evaluated + 3) // 4)
    if len(poses) and key.max() > -VIOLATION_OFFSET:
        elite_idx = np.argsort(key)[::-1][:cfg.elite]
        elite, elite_key = poses[elite_idx], key[elite_idx]
        rounds = 0 if cfg.ignore_grasps else cfg.refine_rounds
    else:
        # No release pose reaches b feasibly: search all four configurations from the release
        # poses that come nearest to reaching it.
        near = np.argsort(kin, kind="stable")[:cfg.elite]
        elite = release.poses[near]
        elite_key = -VIOLATION_OFFSET - 1.0 - kin[near]
        rounds = cfg.search_rounds
    best = int(np.argmax(key)) if len(poses) else -1
    best_key = key[best] if best >= 0 else -np.inf
    best_pose = poses[best].copy() if best >= 0 else None
    best_r4 = r4[best] if best >= 0 else None
    searching = best_key <= -VIOLATION_OFFSET
    more, k2, r2, n, miss2 = _cross_entropy(
        scn, old, boom, new_anchor, elite, elite_key, rng, cfg, ALL, rounds,
        lambda b, n: b < -VIOLATION_OFFSET or (not searching and n < cfg.refine_rounds))
    evaluated += n
    miss = max(miss, miss2)
    if len(k2) and k2.max() > best_key:
        b = int(np.argmax(k2))
        best_key, best_pose, best_r4 = k2[b], more[b].copy(), r2[b]
    if best_key <= -VIOLATION_OFFSET:
        return Transition(False, None, None, _explain(miss), (evaluated + 3) // 4)
    assert best_r4 is not None  # set with the best key, which is feasible
    return Transition(True, best_pose, np.exp(best_r4), "", (evaluated + 3) // 4)


def _cannot_let_go(boom: int, release: ReleaseSet) -> Transition:
    return Transition(False, None, None, f"no pose found: boom {boom} cannot let go in this "
                      f"stance ({release.reason.removeprefix('no pose found: ')})",
                      release.evaluated)


def _furthest(reason: np.ndarray, r4: np.ndarray) -> tuple[int, int]:
    """(progress, failure code) of the sample that got furthest: the most configurations
    feasible, then the latest failing test (codes as `score_configurations`')."""
    passed = (r4 > -np.inf).sum(axis=1)
    progress = passed * 100 + reason % 10
    k = int(np.argmax(progress))
    return int(progress[k]), int(reason[k])


def _explain(miss: tuple[int, int]) -> str:
    """Why the sample that got furthest failed, in words."""
    if miss[0] < 0:
        return "no pose found"
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
    ok = _kinematic_violation(robot, poses, held, np.arange(NUM_BOOMS)) == 0.0
    if not ok.any():
        return np.zeros(0, dtype=int)
    pts = scn.anchor_positions
    reachable = (reach_violation(robot, poses[ok], pts, np.full(len(pts), boom))
                 == 0.0).any(axis=0)
    reachable[[scn.anchor_index[a] for a in stance]] = False
    return np.flatnonzero(reachable)


def _kinematic_violation(robot, poses: np.ndarray, anchors: np.ndarray,
                         booms: np.ndarray) -> np.ndarray:
    """How far boom booms[k] at each pose is from reaching anchors[k], summed over k (m + rad)."""
    return reach_violation(robot, poses, anchors, booms).sum(axis=1)


def polish_transition(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str,
                      pose: np.ndarray, rng: np.random.Generator, rounds: int = 8,
                      samples: int = 24, step: tuple[float, float, float] = (0.06, 0.06, 0.08),
                      shrink: float = 0.7, link_step: float = 0.02) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """Raise the worst of the four robustnesses of a feasible transition pose by a local
    search: each round samples around the best pose so far, moving there on improvement and
    shrinking the spread otherwise. The search inside A* stops at the first feasible pose (a
    round of refinement at most); the few transitions of the chosen path are worth this.

    A move is taken only when the straight segment from `pose` to it (every `link_step` m or
    rad) is feasible in both 4-stances, so the polished pose stays joined to the found one in
    the stances the body moves in before and after: a body path between found poses extends to
    the polished ones (`seeds.body_seed`'s `linked_ends`).
    Returns the pose and its four probabilities; never worse than `pose`."""
    origin = np.asarray(pose, dtype=float).copy()
    best = origin.copy()
    key, r, _ = score_configurations(scn, old, boom, new_anchor, best[None], False)
    best_key, best_r = float(key[0]), r[0]
    if best_key <= -VIOLATION_OFFSET:
        raise ValueError("polish_transition needs a feasible transition pose")
    s_old, _, s_new = transition_stances(scn, old, boom, new_anchor)
    assert s_new is not None  # a new anchor is given
    spread = np.asarray(step, dtype=float)
    for _ in range(rounds):
        cand = best + rng.normal(0.0, 1.0, (samples, 3)) * spread
        k2, r2, _ = score_configurations(scn, old, boom, new_anchor, cand, False)
        moved = False
        for b in np.argsort(k2)[::-1][:3]:  # the best few, in case the best is cut off
            if k2[b] <= best_key:
                break
            n = max(2, int(np.ceil(np.abs(cand[b] - origin).max() / link_step)) + 1)
            link = origin + np.linspace(0.0, 1.0, n)[:, None] * (cand[b] - origin)
            link2 = np.vstack([link, link])
            mixed = Stance.mix(s_old, s_new, np.repeat([False, True], n))
            if score_poses(scn, mixed, link2).feasible.all():
                best, best_key, best_r = cand[b].copy(), float(k2[b]), r2[b]
                moved = True
                break
        if not moved:
            spread = spread * shrink
    return best, np.exp(best_r)
