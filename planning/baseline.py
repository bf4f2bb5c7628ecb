"""The naive baseline (the paper's comparison): greedy steps that ignore limit surfaces.

From each stance it takes the move whose new anchor lies nearest the goal (the farthest step
toward it) among those in reach whose transition is kinematically and statically holdable with
tensions within bounds, grasp probabilities ignored. It never revisits a stance. Its plans are
scored afterwards with the same probability model as RBP's (planning.plan).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from planning.footsteps import (
    FootstepConfig,
    FootstepPlan,
    Step,
    candidate_moves,
    edge_rng,
    goal_pose_in,
)
from planning.lattice_search import Stance4, stance4
from planning.search_outcome import Stop
from planning.transition import find_transition
from rb_drake.scenario import Scenario


def plan_naive(scn: Scenario, config: FootstepConfig | None = None,
               max_steps: int = 80) -> FootstepPlan:
    cfg = config or FootstepConfig()
    tcfg = dataclasses.replace(cfg.transition, ignore_grasps=True)
    t0 = time.perf_counter()
    stance = stance4(scn.start_stance)
    pose = np.asarray(scn.start_pose, dtype=float)
    goal_rng = np.random.default_rng([cfg.seed, 2])
    goal = np.asarray(scn.goal_position)
    stances: list[Stance4] = [stance]
    steps: list[Step] = []
    seen = {stance}
    tested = 0
    for _ in range(max_steps):
        goal_pose = goal_pose_in(scn, stance, goal_rng, cfg.goal_samples, ignore_grasps=True)
        if goal_pose is not None:
            return FootstepPlan(True, "", stances, steps, np.asarray(scn.start_pose), goal_pose,
                                len(stances), tested, time.perf_counter() - t0)
        moves = candidate_moves(scn, stance, pose, per_boom=10**6, seed=cfg.seed)
        moves.sort(key=lambda m: float(np.linalg.norm(
            scn.anchor_positions[scn.anchor_index[m[1]]] - goal)))
        for j, anchor in moves:
            new = stance4(anchor if i == j else a for i, a in enumerate(stance))
            if new in seen:
                continue
            tested += 1
            tr = find_transition(scn, stance, j, anchor, edge_rng(cfg.seed, stance, j, anchor),
                                 guess=pose, config=tcfg)
            if tr.feasible:
                assert tr.pose is not None and tr.probabilities is not None  # feasible
                steps.append(Step(j, stance[j], anchor, tr.pose, tr.probabilities))
                stance, pose = new, tr.pose
                stances.append(stance)
                seen.add(stance)
                break
        else:
            return FootstepPlan(False, f"stuck after {len(steps)} steps: no feasible move from "
                                f"stance {list(stance)}", stances, steps,
                                np.asarray(scn.start_pose), None, len(stances), tested,
                                time.perf_counter() - t0, stop=Stop.EXHAUSTED)
    return FootstepPlan(False, f"no goal after {max_steps} steps", stances, steps,
                        np.asarray(scn.start_pose), None, len(stances), tested,
                        time.perf_counter() - t0, stop=Stop.BUDGET)
