"""Replanning after a grasp failure (beyond the paper), for the Monte Carlo trials of
`systems.montecarlo`.

When a grasp fails in a 4-stance (under load, or a new grasp on contact) and the 3-stance left
still holds the body (`still_holds`: `check_poses` with the failed boom free and its gripper at
the failed anchor), a pluggable `Replanner` is asked for a new plan from that state
(`ReplanRequest`). `retry_replanner` re-grasps the same anchor and resumes the plan (cheap);
`FootstepReplanner` moves the free boom to another anchor and runs the footstep planner from
there (10-60 s per call on a whole cave).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from planning.plan import score_plan
from planning.plan_model import Phase, Plan, Start, Step
from planning.plan_steps import allocation_step
from planning.ramps import add_ramps
from rb_drake.feasibility import check_poses
from rb_drake.scenario import Scenario

RETRY_DURATION = 2.0     # s, to re-grasp the same anchor


class ReplanRequest(NamedTuple):
    """The state after a grasp failed in a 4-stance: the body at `pose` in the 3-stance
    `stance` (the failed boom free, its gripper at `anchor`)."""

    scenario: Scenario
    plan: Plan             # the plan being executed
    phase: int             # index of the phase that failed, in that plan
    time: float            # s, in that plan's time
    pose: np.ndarray       # (3,)
    stance: tuple[str | None, ...]
    boom: int
    anchor: str
    cause: str


Replanner = Callable[[ReplanRequest], Plan | None]
"""A new plan (times from 0) starting at the request's pose and
3-stance, or None when it finds none."""


def still_holds(scn: Scenario, stance: tuple[str | None, ...], pose: np.ndarray,
                boom: int, anchor: str) -> bool:
    """Whether the 3-stance left after `boom` failed holds the body at `pose`, the free limb
    approximated as cantilevered with its gripper at the failed anchor."""
    if sum(a is not None for a in stance) != 3:
        return False
    tip = np.array(scn.anchors[scn.anchor_index[anchor]].position)
    return bool(check_poses(scn, scn.stance(stance), np.asarray(pose), tip).feasible[0])


def configuration(scn: Scenario, stance: tuple[str | None, ...], pose: np.ndarray,
                  free_tip: np.ndarray | None, t: float) -> tuple[Step, bool]:
    """A plan step at `pose` with the robust allocation (as planning.plan writes them), and
    whether the configuration is feasible."""
    s = scn.stance(stance)
    check = check_poses(scn, s, np.asarray(pose, dtype=float), free_tip, full=True)
    step = allocation_step(s, check.allocation, 0, float(t), pose, free_tip)
    return step, bool(check.feasible[0])


def shifted_phases(phases: Sequence[Phase], dt: float) -> list[Phase]:
    """The phases with their steps dt later."""
    return [dataclasses.replace(phase, steps=tuple(step.replace(t=float(step.t + dt))
                                                   for step in phase.steps))
            for phase in phases]


def _finish_plan(request: ReplanRequest, phases: Sequence[Phase],
                 planned: Plan | None = None) -> Plan:
    """The continuation: the executed plan's fields with these phases; `planned`, the new
    plan they come from, if any, gives its time step and step limits (its trajectories')."""
    source = request.plan if planned is None else planned
    # The continuation starts where the grasp failed, not at the scenario's start.
    held = _held(tuple(request.anchor if i == request.boom else a
                       for i, a in enumerate(request.stance)))
    plan = request.plan.replace(
        phases=tuple(phases), verified=None, time_step=source.time_step, limits=source.limits,
        start=Start(pose=tuple(float(v) for v in request.pose), stance=held))
    plan = add_ramps(plan, request.scenario)  # the new phases' attach and release
    return score_plan(plan, request.scenario.robot.attach_failure)


def _held(stance: tuple[str | None, ...]) -> tuple[str, ...]:
    """A 4-stance's anchors (every boom holds one)."""
    anchors = tuple(a for a in stance if a is not None)
    if len(anchors) != len(stance):
        raise ValueError(f"a 4-stance with a free boom: {list(stance)}")
    return anchors


def retry_replanner(request: ReplanRequest) -> Plan | None:
    """Re-grasp the failed anchor from where the body is (a fresh grasp: new strength and
    attach draws), finish the failed body phase from here and go on with the plan."""
    scn, plan, k = request.scenario, request.plan, request.phase
    phase = plan.phases[k]
    if phase.kind != "body":
        return None
    tip = np.array(scn.anchors[scn.anchor_index[request.anchor]].position)
    pose = np.asarray(request.pose, dtype=float)
    a, ok_a = configuration(scn, request.stance, pose, tip, 0.0)
    b, ok_b = configuration(scn, request.stance, pose, tip, RETRY_DURATION)
    start, ok_c = configuration(scn, tuple(phase.stance), pose, None, RETRY_DURATION)
    end_step = phase.steps[-1]
    remaining = max(1.0, float(end_step.t) - request.time)
    end, ok_d = configuration(scn, tuple(phase.stance), np.array(end_step.pose), None,
                              RETRY_DURATION + remaining)
    if not (ok_a and ok_b and ok_c and ok_d):
        return None
    reach = Phase(kind="reach", stance=tuple(request.stance), free_boom=request.boom,
                  from_anchor=request.anchor, to_anchor=request.anchor, steps=(a, b))
    body = Phase(kind="body", stance=tuple(phase.stance), free_boom=None, steps=(start, end))
    rest = shifted_phases(plan.phases[k + 1:], end.t - float(end_step.t))
    return _finish_plan(request, [reach, body, *rest])


@dataclasses.dataclass
class FootstepReplanner:
    """Move the free boom to another reachable anchor from where the body is, then plan the
    rest of the climb from that 4-stance with the whole pipeline (`planning.pipeline.
    plan_climb`: footsteps, then a seed and SCP per phase), so the continuation is a plan like
    any other, trajectories and tensions included.

    Candidates are the reachable anchors nearest the goal whose 3-stance (gripper there) and
    4-stance both hold at the current pose; the first `candidates` are tried in turn. The
    gripper moves on the straight line where it is clear of rock, else along the planner's
    tip arc (`planning.reach_seeds`): a free gripper may touch rock only near an anchor."""

    candidates: int = 3
    max_expansions: int = 400
    seed: int = 0
    optimise: bool = True  # False: the continuation keeps its seed trajectories (no SCP)

    def __call__(self, request: ReplanRequest) -> Plan | None:
        from planning.footsteps import FootstepConfig
        from planning.pipeline import PipelineConfig, plan_climb
        from planning.plan import reach_duration
        from planning.transition import reachable_anchors

        scn, j = request.scenario, request.boom
        pose = np.asarray(request.pose, dtype=float)
        held = tuple(request.anchor if a is None else a for a in request.stance)
        rng = np.random.default_rng([self.seed, j])
        idx = reachable_anchors(scn, held, j, pose, rng)
        goal = np.asarray(scn.goal_position)
        idx = idx[np.argsort(np.linalg.norm(scn.anchor_positions[idx] - goal, axis=1))]
        old_tip = np.array(scn.anchors[scn.anchor_index[request.anchor]].position)
        tried = 0
        for k in idx:
            if tried >= self.candidates:
                break
            new = scn.anchors[k]
            four = tuple(new.id if i == j else a for i, a in enumerate(request.stance))
            duration = reach_duration((old_tip, np.array(new.position)))
            a, ok_a = configuration(scn, request.stance, pose, old_tip, 0.0)
            b, ok_b = configuration(scn, request.stance, pose, np.array(new.position),
                                    duration)
            _, ok_c = configuration(scn, four, pose, None, duration)
            if not (ok_a and ok_b and ok_c):
                continue
            reach = Phase(kind="reach", stance=tuple(request.stance), free_boom=j,
                          from_anchor=request.anchor, to_anchor=new.id, steps=(a, b))
            if _crosses(scn, reach):  # the executors run the straight line: it must hold too
                arc = _arc_reach(scn, held, j, new.id, pose, reach)
                if arc is None:
                    continue
                reach = arc
            tried += 1
            start = dataclasses.replace(
                scn, start_pose=(float(pose[0]), float(pose[1]), float(pose[2])),
                start_stance=_held(four))
            config = PipelineConfig(footstep=FootstepConfig(seed=self.seed,
                                                            max_expansions=self.max_expansions),
                                    optimise=self.optimise)
            plan = plan_climb(start, "rbp", config)
            if not plan.success:
                continue
            rest = shifted_phases(plan.phases, reach.steps[-1].t)
            return _finish_plan(request, [reach, *rest], plan)
        return None


def _crosses(scn: Scenario, reach: Phase) -> bool:
    """Whether the straight motion between a reach's steps fails `rbp check`'s rule `between`
    (the free gripper's straight line from anchor to anchor often runs along the rock, which
    a free gripper may touch only within 2 cm of an anchor)."""
    from planning.verify_between import failing_intervals, phase_samples, verification_world

    return bool(failing_intervals(verification_world(scn), scn.stance(reach.stance), reach,
                                  phase_samples(scn.robot, reach)))


def _arc_reach(scn: Scenario, held: tuple[str, ...], j: int, to_anchor: str, pose: np.ndarray,
               straight: Phase) -> Phase | None:
    """The reach along the planner's collision-free tip arc (`planning.reach_seeds`), one step
    per arc point over the arc's `reach_duration`, where the straight line from anchor to anchor
    crosses rock; None where no arc holds."""
    from planning.plan import reach_duration
    from planning.reach_seeds import reach_seed

    seed = reach_seed(scn, held, j, to_anchor, pose)
    if not seed.success or seed.tips is None:
        return None
    tips = np.asarray(seed.tips, dtype=float)
    along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(tips, axis=0), axis=1))]
    # half evenly, half by the tip's travel: no arc segment over twice the nominal speed
    share = 0.5 * np.linspace(0.0, 1.0, len(tips)) + 0.5 * along / max(along[-1], 1e-12)
    times = reach_duration(tips) * share
    steps: list[Step] = []
    for q, tip, t in zip(seed.poses, seed.tips, times, strict=True):
        step, ok = configuration(scn, straight.stance, q, tip, float(t))
        if not ok:
            return None
        steps.append(step)
    reach = dataclasses.replace(straight, steps=tuple(steps))
    return None if _crosses(scn, reach) else reach
