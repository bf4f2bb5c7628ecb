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
from rb_drake.feasibility import REASON_TEXT, Reason, check_poses
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

CONFIG_NAMES = ("old 4-stance", "3-stance, gripper at old anchor",
                "3-stance, gripper at new anchor", "new 4-stance")


@dataclasses.dataclass(frozen=True)
class TransitionConfig:
    candidates: int = 1500         # cheap random poses, filtered by reach alone
    samples: int = 96              # of those, poses evaluated in full
    refine_rounds: int = 2         # cross-entropy rounds after sampling
    refine_samples: int = 32       # poses per round
    elite: int = 8
    spread: float = 0.6            # m, std of the initial position samples
    phi_spread: float = 0.35       # rad, std of the initial orientation samples
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
    """min robustness over the four configurations (-inf if any is infeasible), the four
    robustnesses, and the first failure reason per pose."""
    s_old, s_three, s_new = transition_stances(scn, old, boom, new_anchor)
    tip_old = s_old.positions[boom]
    tip_new = s_new.positions[boom]
    world = scn if not ignore_grasps else _NaiveWorld(scn)
    P = poses.shape[0]
    r = np.full((P, 4), -np.inf)
    reason = np.zeros(P, dtype=int)
    alive = np.arange(P)
    for k, (stance, tip) in enumerate(((s_old, None), (s_three, tip_old), (s_three, tip_new),
                                      (s_new, None))):
        if not len(alive):
            break
        check = check_poses(world, stance, poses[alive], tip, ignore_grasps=ignore_grasps)
        r[alive, k] = np.where(check.feasible, check.allocation.robustness, -np.inf)
        reason[alive[~check.feasible]] = check.reason[~check.feasible] + 10 * k
        alive = alive[check.feasible]
    return r.min(axis=1), r, reason


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
    # Draw cheap candidates and keep those whose five booms are within length and shoulder
    # range (pure geometry, microseconds a pose) before the expensive statics.
    m = cfg.candidates
    cand = np.empty((m, 3))
    cand[:, :2] = centre + rng.normal(0.0, cfg.spread, (m, 2))
    cand[:, 2] = rng.normal(0.0, cfg.phi_spread, m)
    if guess is not None:
        k = m // 3
        cand[:k, :2] = guess[:2] + rng.normal(0.0, 0.5 * cfg.spread, (k, 2))
        cand[:k, 2] = guess[2] + rng.normal(0.0, cfg.phi_spread, k)
    reach_ok = _kinematics_ok(robot, cand, anchors, booms)
    if not reach_ok.any():
        return Transition(False, None, None, "no pose found: no sampled pose reaches all five "
                          "anchors within boom length and shoulder range", m)
    poses = cand[reach_ok][:cfg.samples]
    n = len(poses)
    score, r4, reason = _score(scn, old, boom, new_anchor, poses, cfg.ignore_grasps)
    evaluated = n
    if not np.isfinite(score).any():
        return Transition(False, None, None, _explain(reason), evaluated)
    best_pose, best_score = poses[np.argmax(score)], score.max()
    best_r4 = r4[np.argmax(score)]
    if not cfg.ignore_grasps:
        feasible = np.flatnonzero(np.isfinite(score))
        elite = poses[feasible[np.argsort(score[feasible])[::-1][:cfg.elite]]]
        for _ in range(cfg.refine_rounds):
            mean = elite.mean(axis=0)
            std = np.maximum(elite.std(axis=0), [0.01, 0.01, 0.01])
            cand = mean + rng.normal(0.0, 1.0, (cfg.refine_samples, 3)) * std
            s, r, _ = _score(scn, old, boom, new_anchor, cand, False)
            evaluated += len(cand)
            pool = np.vstack([elite, cand])
            pool_s = np.concatenate([np.full(len(elite), -np.inf), s])
            if s.max() > best_score:
                best_score, best_pose, best_r4 = s.max(), cand[np.argmax(s)], r[np.argmax(s)]
            ok = np.isfinite(pool_s)
            if ok.sum() >= 2:
                order = np.argsort(pool_s)[::-1][:cfg.elite]
                elite = np.vstack([best_pose[None], pool[order]])[:cfg.elite]
    return Transition(True, best_pose.copy(), np.exp(best_r4), "", evaluated)


def _kinematics_ok(robot, poses: np.ndarray, anchors: np.ndarray, booms: np.ndarray) -> np.ndarray:
    """Whether boom booms[k] at each pose can reach anchors[k] for every k (length and angle)."""
    sh = geometry.shoulder_positions(robot, poses)[:, booms, :]
    d = anchors - sh
    length = np.linalg.norm(d, axis=-1)
    theta = geometry.wrap_angle(np.arctan2(d[..., 1], d[..., 0]) - poses[:, 2, None]
                                - robot.shoulder_directions[booms])
    lo, hi = robot.boom_length
    return np.all((length >= lo) & (length <= hi) & (np.abs(theta) <= robot.shoulder_range),
                  axis=1)


def _explain(codes: np.ndarray) -> str:
    """The most common first failure among the samples, in words."""
    values, counts = np.unique(codes, return_counts=True)
    code = int(values[np.argmax(counts)])
    config, reason = divmod(code, 10)
    share = counts.max() / counts.sum()
    return (f"no pose found: {REASON_TEXT[Reason(reason)]} in the {CONFIG_NAMES[config]} "
            f"({share:.0%} of samples)")


def reachable_anchors(scn: Scenario, stance: tuple[str, ...], boom: int,
                      pose: np.ndarray, slack: float = 1.0) -> np.ndarray:
    """Indices of anchors boom `boom` might reach from near `pose`: within its length and
    shoulder range of a body moved by at most `slack` metres (a cheap filter before search)."""
    robot = scn.robot
    pts = scn.anchor_positions
    centre = np.asarray(pose[:2])
    sh = geometry.shoulder_positions(robot, pose)[0, boom]
    d = pts - sh
    dist = np.linalg.norm(d, axis=1)
    ok = (dist <= robot.boom_length[1] + slack) & (dist >= robot.boom_length[0])
    # Direction from the body centre within the shoulder's range, widened by the slack.
    ang = geometry.wrap_angle(np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0])
                              - pose[2] - robot.shoulder_directions[boom])
    ok &= np.abs(ang) <= robot.shoulder_range + 0.6
    ids = {scn.anchor_index[a] for a in stance if a is not None}
    ok[list(ids)] = False
    return np.flatnonzero(ok)
