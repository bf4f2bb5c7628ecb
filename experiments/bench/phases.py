"""The phases the scp section of `rbp bench` optimises: the first moves of greedy climbs on the
bundled caves, each phase with the pipeline's seed."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from rb_drake.scenario import Scenario, bundled_caves, load_scenario
from rb_drake.stance import Stance


class Segment(NamedTuple):
    """One phase of a climb with its seed: the inputs both optimisers get."""

    cave: str
    kind: str                      # "body" | "reach"
    scn: Scenario
    stance_ids: tuple[str, ...]    # the 4-stance (a reach phase frees `boom`)
    boom: int | None
    poses: np.ndarray              # (N, 3) the seed
    tips: np.ndarray | None        # (N, 2) the free gripper's path (reach)

    @property
    def stance(self) -> Stance:
        st = self.scn.stance(self.stance_ids)
        return st if self.boom is None else st.without(self.boom)


@dataclasses.dataclass(eq=False)
class _Climb:
    """A greedy climb of `scp_segments` so far: where it stands and the stances it has held."""

    name: str
    scn: Scenario
    stance: tuple[str, ...]
    pose: np.ndarray
    seen: set[tuple[str, ...]]


def scp_segments(moves: int, seed: int = 0, min_steps: int = 3) -> list[Segment]:
    """The phases of the first `moves` regrasps of greedy climbs on the bundled caves (round
    robin): from the current stance the first feasible move toward the goal (as the footstep
    planner orders them), then the body phase to its transition pose and the reach phase, with
    the pipeline's seeds (`PipelineConfig().seed`). Phases of fewer than `min_steps` steps are
    left out."""
    from planning.footsteps import candidate_moves, edge_rng
    from planning.pipeline import PipelineConfig
    from planning.seeds import body_seed, reach_seed
    from planning.transition import find_transition

    cfg = PipelineConfig().seed
    climbs = []
    for name, path in sorted(bundled_caves().items()):
        scn = load_scenario(path)
        climbs.append(_Climb(name, scn, tuple(scn.start_stance),
                             np.asarray(scn.start_pose, float), {tuple(scn.start_stance)}))
    segments: list[Segment] = []
    done = 0
    while done < moves and climbs:
        for climb in list(climbs):
            if done >= moves:
                break
            name, scn, stance, pose = climb.name, climb.scn, climb.stance, climb.pose
            seen = climb.seen
            step = None
            for j, anchor in candidate_moves(scn, stance, pose, per_boom=3, seed=seed):
                new = tuple(anchor if i == j else a for i, a in enumerate(stance))
                if new in seen:
                    continue
                tr = find_transition(scn, stance, j, anchor, edge_rng(seed, stance, j, anchor),
                                     guess=pose)
                if tr.feasible:
                    assert tr.pose is not None  # a feasible transition's
                    step = (j, anchor, new, tr.pose)
                    break
            if step is None:
                climbs.remove(climb)
                continue
            j, anchor, new, goal = step
            body = body_seed(scn, stance, pose, goal, cfg, seed=seed)
            reach = reach_seed(scn, stance, j, anchor, goal, cfg, seed=seed)
            if body.success and len(body.poses) >= min_steps:
                segments.append(Segment(name, "body", scn, stance, None, body.poses, None))
            if reach.success and len(reach.poses) >= min_steps:
                segments.append(Segment(name, "reach", scn, stance, j, reach.poses, reach.tips))
            climb.stance, climb.pose = new, np.asarray(goal, dtype=float)
            seen.add(new)
            done += 1
    return segments
