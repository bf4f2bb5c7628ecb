"""The plan file (`reachbot-plan/2`, typed in `planning.plan_model`): built, scored, written.

A plan alternates body phases (a 4-stance, the body moving) and reach phases (a 3-stance, the
free gripper moving from one anchor to the next at a fixed pose); a body phase ends with the
release ramp of the boom the next reach frees and starts with the attach ramp of the boom the
reach before moved (`planning.ramps`). At the footstep stage each
phase holds only the configurations the footstep planner found: a body phase from one
transition pose to the next, a reach phase at its transition pose with the free gripper at the
old and at the new anchor. Each configuration is evaluated with the robust force allocation,
for either planner, so that plans are scored by the same model.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from planning.easing import ease_motions
from planning.plan_model import (
    BODY_SPEED,
    FORMAT,
    GRIPPER_SPEED,
    STAGES,
    TURN_SPEED,
    Limits,
    Motion,
    Phase,
    Plan,
    SearchPoint,
    SearchRecord,
    Step,
    plan_dict,
    planner_of,
)
from planning.plan_schema import schema, validate  # noqa: F401 (re-exported)
from planning.plan_steps import allocation_step, steps_with_tensions
from planning.probability import Configuration, path_probability
from planning.ramps import add_ramps
from planning.verify_climb import DEFAULT_LIMITS, STEP_STRETCH
from rb_drake.feasibility import check_poses
from rb_drake.files import atomic_write_text
from rb_drake.scenario import Scenario

if TYPE_CHECKING:  # the footstep planner is not needed to read, check or write a plan
    from planning.footsteps import FootstepPlan
    from planning.pipeline import PhaseMotion

REACH_DURATION = 5.0  # s: the shortest time for the free gripper to travel between anchors


def reach_duration(tips: Sequence[np.ndarray] | np.ndarray) -> float:
    """The time of a reach whose free gripper passes `tips` in order: REACH_DURATION, or longer
    where the path is longer than GRIPPER_SPEED allows in it (rule speed: a 2 m reach in 5 s
    is over the free gripper's limit)."""
    path = np.asarray(tips, dtype=float)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0
    return max(REACH_DURATION, length / GRIPPER_SPEED)


def _configuration(scn: Scenario, stance_ids: tuple[str | None, ...], pose: np.ndarray,
                   free_tip: np.ndarray | None, t: float) -> Step:
    stance = scn.stance(stance_ids)
    check = check_poses(scn, stance, pose, free_tip, full=True)
    return allocation_step(stance, check.allocation, 0, round(float(t), 6), pose, free_tip)


def search_record(fp: FootstepPlan) -> SearchRecord:
    """How the footstep search ended: `stop` is "" (a route), "budget", "exhausted" (an
    incomplete search ran out of stances: no proof), "noroute" (the complete search proved that
    no route exists at its resolution) or "nostart" (the start pose joins no lattice pose)."""
    found = fp.success and math.isfinite(fp.cost)
    anytime = fp.success and math.isfinite(fp.lower_bound)  # an anytime search's proven bound
    return SearchRecord(
        stop=fp.stop, expansions=int(fp.expansions),
        transitions_tested=int(fp.transitions_tested),
        cost=float(fp.cost) if found else None,
        # the fewest-regrasp route within it (planning.constrained)
        min_success=None if fp.min_success is None else float(fp.min_success),
        lower_bound=float(fp.lower_bound) if anytime else None,
        first_cost=float(fp.first_cost) if anytime else None,
        bound=(float(fp.cost / fp.lower_bound) if anytime and fp.lower_bound > 0 else None),
        quality=fp.quality if anytime else None,
        history=(tuple(SearchPoint(seconds=float(t), cost=float(c), lower_bound=float(lo),
                                   expansions=int(n)) for t, c, lo, n in fp.history or [])
                 if anytime else None),
        peak_memory_mb=_finite(fp.peak_memory_mb), kept_memory_mb=_finite(fp.kept_memory_mb),
        refined=tuple((float(c.position_step), float(c.angle_step_deg)) for c in fp.refined)
        or None)


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def build_plan(scn: Scenario, fp: FootstepPlan, planner: str,
               timing: dict[str, float] | None = None) -> Plan:
    """The plan for a footstep plan (phases at the footstep stage)."""
    plan = plan_header(scn, planner, bool(fp.success), fp.reason, timing, search_record(fp))
    phases: list[Phase] = []
    t = 0.0
    # each heading the short way round from the one before, as the motion's seeds take it
    # (body_seeds): the search's headings lie in [-pi, pi], and a plan's step turns at most
    # half a turn (plan_file.check_times)
    chain = short_way([fp.start_pose] + [s.pose for s in fp.steps]
                      + ([fp.goal_pose] if fp.goal_pose is not None else []))
    poses, ends = chain[:len(fp.steps) + 1], chain[1:]
    for k, stance in enumerate(fp.stances):
        if k < len(ends):
            a, b = np.asarray(poses[k]), np.asarray(ends[k])
            duration = max(1.0, float(np.linalg.norm(b[:2] - a[:2])) / BODY_SPEED,
                           abs(float(b[2] - a[2])) / TURN_SPEED)
            phases.append(Phase(
                kind="body", stance=tuple(stance), free_boom=None,
                steps=(_configuration(scn, stance, a, None, t),
                       _configuration(scn, stance, b, None, t + duration))))
            t += duration
        if k < len(fp.steps):
            step = fp.steps[k]
            three = tuple(None if i == step.boom else x for i, x in enumerate(stance))
            old = np.array(scn.anchors[scn.anchor_index[step.from_anchor]].position)
            new = np.array(scn.anchors[scn.anchor_index[step.to_anchor]].position)
            duration = reach_duration((old, new))
            phases.append(Phase(
                kind="reach", stance=three, free_boom=step.boom,
                from_anchor=step.from_anchor, to_anchor=step.to_anchor,
                steps=(_configuration(scn, three, poses[k + 1], old, t),
                       _configuration(scn, three, poses[k + 1], new, t + duration))))
            t += duration
    plan = add_ramps(plan.replace(regrasps=len(fp.steps), phases=tuple(phases)), scn)
    if fp.success:
        plan = score_plan(plan, scn.robot.attach_failure)
    return plan


def short_way(poses: Sequence[np.ndarray]) -> list[np.ndarray]:
    """`poses` (x, y, heading) with each heading moved by whole turns to within half a turn of
    the one before (the first as given); a heading within it is kept to the bit."""
    out = [np.asarray(p, dtype=float) for p in poses[:1]]
    for p in poses[1:]:
        q = np.array(p, dtype=float)
        turn = q[2] - out[-1][2]
        if abs(turn) > math.pi:
            q[2] -= 2.0 * math.pi * round(turn / (2.0 * math.pi))
        out.append(q)
    return out


def plan_header(scn: Scenario, planner: str, success: bool, reason: str,
                timing: dict[str, float] | None = None,
                search: SearchRecord | None = None) -> Plan:
    """A plan without phases, in the current format: what every producer of a plan (the
    pipeline, the naive baseline, the rig's plan) starts from. The robot is stored once, at the
    top level (`scenario` is the cave without it); the summary is unset (`score_plan`)."""
    scenario = scn.to_dict(resolved=True)
    del scenario["robot"]
    return Plan(format=FORMAT, planner=planner_of(planner), success=success, reason=reason,
                p_min=None, p_path=None, p_grasps=None, regrasps=0,
                timing={k: 0.0 for k in STAGES} | (timing or {}), search=search,
                scenario=scenario, robot=scn.robot.to_dict(), phases=())


def step_limits(step: float, turn_step: float) -> dict[str, float]:
    """The plan's limits between successive trajectory steps for seeds `step` apart (m) and
    `turn_step` (rad): SCP may stretch a seed's steps, up to STEP_STRETCH times."""
    return {"step": STEP_STRETCH * step, "turn_step": STEP_STRETCH * turn_step}


def within_limits(poses: np.ndarray, tips: np.ndarray | None, limits: dict[str, float]) -> bool:
    """Whether successive poses (and free tips) keep within `limits` (`step_limits`)."""
    d = np.diff(poses, axis=0)
    ok = np.all(np.hypot(d[:, 0], d[:, 1]) <= limits["step"])
    ok &= np.all(np.abs(d[:, 2]) <= limits["turn_step"])
    if tips is not None:
        ok &= np.all(np.linalg.norm(np.diff(tips, axis=0), axis=1) <= limits["step"])
    return bool(ok)


def build_motion_plan(scn: Scenario, fp: FootstepPlan, motions: Sequence[PhaseMotion],
                      planner: str, timing: dict[str, float], dt: float,
                      limits: dict[str, float] | None = None) -> Plan:
    """The plan with full trajectories (`pipeline.PhaseMotion`s), one step
    every `dt` seconds, and a dwell of dt at the end of each phase. Each phase also records
    its seed (`motion`): method, per-step probability and effort, and what SCP made of it.

    `limits` (`step_limits`; default: those of `verify_climb.DEFAULT_LIMITS`) bound the step
    between successive configurations and are recorded in the plan; an SCP result that breaks
    them is not used (the seed, within them, stands)."""
    plan = build_plan(scn, fp, planner, timing)
    limits = dict(limits or DEFAULT_LIMITS)
    phases = []
    t = 0.0
    for m in motions:
        used = (m.result if m.result is not None
                and within_limits(m.result.poses, m.seed.tips, limits) else None)
        if used is not None:
            poses, tensions = used.poses, used.tensions
            seed_tensions = used.seed_tensions
        else:  # the seed with its robust allocation (per-row tips in a reach phase)
            poses = m.seed.poses
            check = check_poses(scn, scn.stance(m.stance), poses, m.seed.tips, full=True)
            tensions = seed_tensions = check.allocation.tensions
        steps = steps_with_tensions(scn, m.stance, poses, tensions, m.seed.tips, t, dt)
        t += len(poses) * dt
        # Each phase ends with a dwell of dt in its last configuration (the gripper engaging or
        # letting go): the next phase starts when it ends, and an execution that switches
        # stance at the boundary still spends time in every configuration the plan lists.
        steps.append(steps[-1].replace(t=round(t, 6)))
        # per step, like `steps` (the dwell repeats the last)
        seed_lp = np.append(m.seed.log_probs, m.seed.log_probs[-1])
        seed_tensions = np.vstack([seed_tensions, seed_tensions[-1:]])
        tensions = np.vstack([tensions, tensions[-1:]])
        motion = Motion(
            seed_method=m.seed.method,
            seed_p_success=tuple(float(np.exp(v)) for v in seed_lp),
            seed_tension=tuple(tuple(None if np.isnan(v) else float(v) for v in f)
                               for f in seed_tensions),
            seed_effort=tuple(float(np.nansum(f)) for f in seed_tensions),
            effort=tuple(float(np.nansum(f)) for f in tensions),
            optimised=m.result is not None,
            improved=bool(used is not None and used.improved),
            scp_status=(used.status if used is not None else "not run" if m.result is None
                        else "seed kept: SCP's steps exceed the plan's limits"),
            scp_iterations=int(m.result.iterations) if m.result is not None else 0,
        )
        reach = m.kind == "reach"
        phases.append(Phase(kind=m.kind, stance=tuple(m.stance), free_boom=m.free_boom,
                            from_anchor=m.from_anchor if reach else None,
                            to_anchor=m.to_anchor if reach else None,
                            steps=tuple(steps), motion=motion))
    plan = plan.replace(time_step=dt, phases=tuple(phases),
                        limits=Limits(step=limits["step"], turn_step=limits["turn_step"]))
    plan = add_ramps(ease_motions(plan, scn), scn)
    return score_plan(plan, scn.robot.attach_failure)


def score_plan(plan: Plan, attach_failure: float) -> Plan:
    """The plan with its p_path, p_grasps, p_min and regrasps set from its configurations."""
    prob = path_probability(plan_configurations(plan), attach_failure)
    return plan.replace(p_path=prob.p_path, p_grasps=prob.p_grasps, p_min=prob.p_min,
                        regrasps=prob.regrasps)


def plan_configurations(plan: Plan) -> Iterator[Configuration]:
    """Every configuration of a plan, in time order, for `path_probability`."""
    for phase in plan.phases:
        for step in phase.steps:
            yield Configuration(phase.stance, step.p_grasp, step.p_success)


def write_plan(plan: Plan | dict[str, Any], path: str | Path) -> Path:
    """Write a plan (a Plan or its plan-file object) after checking it against the schema."""
    plan = plan_dict(plan)
    validate(plan)
    return atomic_write_text(path, json.dumps(plan, indent=1, allow_nan=False) + "\n")
