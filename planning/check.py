"""`rbp check`: re-verify a plan file from scratch, trusting none of the planner's bookkeeping.

The scenario and robot are rebuilt from the plan file itself. `planning.verify_climb` checks the
climb as a whole (start, goal, phase order and joins, stance sequence, time, continuity, the
robot stored once); here every configuration is checked with the plan's own tensions (not
re-optimised): kinematic limits, collisions, statics to 1e-6 N, tension bounds, shoulder torque,
pull angles below the robot's max_pull_angle_deg, and P >= p_min recomputed from the limit
surfaces; every recorded per-step value (each grasp's P, P, shoulder torque, summed tension)
is recomputed and compared, and p_min, p_path and the regrasp count are recomputed (for a
successful plan and a partial one, `rbp plan --partial`, whose climb is checked as any other
but need not reach the goal). In a motion plan (one with `time_step`) the motion between
successive steps is verified densely (rule `between`, planning.verify_between); a footstep plan
states end configurations only.
Each problem names its rule (`verify_climb.RULES`), phase and step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from planning.plan_model import Plan, Step, plan_of, plan_scenario
from planning.probability import Configuration, path_probability
from planning.ramps import ramp_statics
from planning.smooth_motion import smooth_path_problems
from planning.verify_between import between_problems
from planning.verify_climb import Problem, climb_problems, locate
from rb_drake.collision import boom_clearances
from rb_drake.feasibility import (
    MIN_CONDITIONING,
    body_in_rock,
    pull_within,
    wrench_conditioning,
)
from rb_drake.statics import STATICS_TOL, statics_problem

TOL = 1e-9
REL = 1e-9  # recorded values equal their recomputation to this relative tolerance...
ABS = 1e-12  # ...or this absolute one


def _same(a: float, b: Any) -> bool:
    return isinstance(b, int | float) and math.isclose(a, b, rel_tol=REL, abs_tol=ABS)


Progress = Callable[[int, int], None]


def check_plan(plan: Plan | dict[str, Any], source: str = "<plan>",
               progress: Progress | None = None) -> list[str]:
    """Every problem found in `plan`, in words ("WHERE: RULE: WHAT"); [] for a valid plan."""
    return [str(p) for p in verify_plan(plan, source, progress)]


def verify_plan(plan: Plan | dict[str, Any], source: str = "<plan>",
                progress: Progress | None = None) -> list[Problem]:
    """Every broken rule in a schema-valid `plan` (a Plan, or its plan-file object); [] for a
    valid plan. A malformed scenario or robot raises rb_drake.scenario.ScenarioError (bad
    input, not a wrong plan). `progress(done, phases)` after each phase's configurations
    (`rbp.progress.CheckProgress`)."""
    plan = plan_of(plan)
    scn = plan_scenario(plan, source)
    robot = scn.robot
    problems = climb_problems(plan, scn)
    bad_form = {p.phase for p in problems if p.rule in ("phase-form", "stance")
                and p.step is None}
    recomputed: list[Configuration] = []
    for k, phase in enumerate(plan.phases):
        if k in bad_form:  # reported; its configurations cannot be set up
            continue
        stance = scn.stance(tuple(phase.stance))
        reach = phase.kind == "reach"
        # a free gripper may touch rock only near its own anchors (feasibility.reach_world)
        ids = (phase.from_anchor, phase.to_anchor) if reach else ()
        own = scn.anchor_positions[[scn.anchor_index[a] for a in ids if a in scn.anchor_index]]
        efforts = []
        for n, step in enumerate(phase.steps):
            out: list[Problem] = []

            def fail(rule: str, text: str, k=k, n=n, out=out) -> None:
                out.append(Problem(rule, text, k, n, locate(plan, k, n)))

            pose = np.asarray(step.pose, dtype=float)
            tip = np.asarray(step.free_tip, dtype=float) if reach else None
            with np.errstate(all="ignore"):  # absurd numbers fail the checks, not numpy
                p_grasp, p_success, effort = _check_configuration(scn, own, stance, pose, tip,
                                                                  step, fail)
            problems += out
            efforts.append(effort)
            recomputed.append(Configuration(tuple(phase.stance), p_grasp, p_success))
        _check_motion(plan, k, efforts, problems)
        if progress is not None:
            progress(k + 1, len(plan.phases))

    def between(k: int, n: int, text: str) -> None:
        problems.append(Problem("between", text, k, n, locate(plan, k, n)))

    if plan.time_step is not None:  # a footstep plan holds end configurations, no motion
        # steps out of time order have no motion between them to verify (`time-order`)
        unordered = {p.phase for p in problems if p.rule == "time-order"}
        between_problems(plan.phases, scn, bad_form | unordered, between)
        if not problems:  # the phases are well formed and join: the smooth path exists
            smooth_path_problems(plan, scn, lambda k: scn.stance(tuple(plan.phases[k].stance)),
                                 between)
    if (plan.success or plan.partial is not None) and recomputed:  # a partial climb's too
        mine = path_probability(recomputed, robot.attach_failure)
        theirs = path_probability(_configurations(plan), robot.attach_failure)
        # p_grasps is optional (plans before it): absent, it is not checked; null is wrong
        p_grasps = mine.p_grasps if plan.p_grasps_absent else plan.p_grasps
        for name, a, b in (("p_path", mine.p_path, plan.p_path),
                           ("p_min", mine.p_min, plan.p_min),
                           ("p_grasps", mine.p_grasps, p_grasps),
                           ("regrasps", mine.regrasps, plan.regrasps),
                           ("p_path from the file's own p_grasp", theirs.p_path, plan.p_path)):
            if not _same(a, b):
                problems.append(Problem("summary", f"{name}: the plan says {b}, recomputed {a}"))
    elif not plan.success and plan.partial is None:  # a failed plan is not climbed
        for name in ("p_path", "p_min", "p_grasps"):
            if (value := getattr(plan, name)) is not None:
                problems.append(Problem("summary", f"{name}: the plan says {value}, but a plan "
                                        "that found no route (not partial) has none (null)"))
    return problems


def _configurations(plan: Plan):
    """Every configuration of the plan as its file records it, in time order."""
    for phase in plan.phases:
        for step in phase.steps:
            yield Configuration(phase.stance, step.p_grasp, step.p_success)


def _check_motion(plan: Plan, k: int, efforts: list[float],
                  problems: list[Problem]) -> None:
    """A phase's `motion` record: one entry per step; `effort` is the summed tension."""
    motion = plan.phases[k].motion
    if motion is None:
        return
    n_steps = len(efforts)
    for name in ("seed_p_success", "seed_tension", "seed_effort", "effort"):
        entries = getattr(motion, name)
        if not isinstance(entries, tuple) or len(entries) != n_steps:
            problems.append(Problem("recorded-value", f"motion.{name} is not a list of one "
                                    f"entry per step ({n_steps})", k, None, locate(plan, k)))
            return
    for n, (a, b) in enumerate(zip(efforts, motion.effort, strict=True)):
        if not _same(a, b):
            problems.append(Problem("recorded-value", f"motion.effort {b} but the tensions sum "
                                    f"to {a}", k, n, locate(plan, k, n)))


def _check_configuration(scn, own, stance, pose, tip, step: Step, fail):
    """Checks one configuration; (p_grasp per boom, P, summed tension) recomputed. `own`
    (2, 2): the free gripper's anchors, where it may touch rock."""
    robot = scn.robot
    f = np.array([np.nan if v is None else v for v in step.tension], dtype=float)
    prob = statics_problem(robot, scn.gravity_vector, pose, stance, tip)
    geo = prob.geometry
    lo, hi = robot.boom_length
    used = stance.attached.copy()
    if tip is not None:
        used[stance.free_boom] = True
    for i in np.flatnonzero(used):
        L, th = geo.length[0, i], geo.shoulder_angle[0, i]
        if not lo - TOL <= L <= hi + TOL:
            fail("kinematics", f"boom {i} length {L:.4f} m outside [{lo}, {hi}]")
        if not abs(th) <= robot.shoulder_range + TOL:
            fail("kinematics", f"boom {i} shoulder angle {math.degrees(th):.2f} deg")
    rock = scn.rock
    # a rock wholly inside the body's outline too, as between steps (check_poses): its edges
    # and corners alone passed a footstep plan's body resting on a pebble
    if body_in_rock(robot, rock, pose[None])[0]:
        fail("collision", "body collides with rock")
    booms = np.flatnonzero(used)
    clearance = boom_clearances(own, 1, stance.free_boom, tip)[0, booms]
    ends = geo.shoulders[0, booms] + geo.d[0, booms] - clearance[:, None] * geo.u[0, booms]
    for i in booms[rock.segments_hit(geo.shoulders[0, booms], ends)]:  # one batch per pose
        fail("collision", f"boom {i} collides with rock")
    att = stance.attached
    if tip is not None:
        torque = float(prob.shoulder_torque[0])
        if not abs(torque) <= robot.shoulder_torque_max + TOL:
            fail("torque", f"shoulder torque {torque:.3f} N m over the limit "
                 f"{robot.shoulder_torque_max}")
        if not _same(torque, step.shoulder_torque):
            fail("recorded-value", f"shoulder_torque {step.shoulder_torque} but "
                 f"recomputed {torque}")
    if np.any(np.isnan(f[att])) or np.any(~np.isnan(f[~att])):
        fail("statics", "tensions must be given exactly for the attached booms")
        return [None] * 4, 0.0, math.nan
    fa = np.where(att, f, 0.0)
    load = prob.b[0]
    lo_f, hi_f = robot.boom_tension
    lower = np.where(att, lo_f, 0.0)
    ramp = step.ramp
    if ramp is not None:  # a release or attach ramp: boom j's limb partly on its shoulder
        j, share = int(ramp.boom), float(ramp.share)
        if tip is not None or not att[j]:
            fail("phase-form", f"a ramp step of boom {j} in a configuration where it is free")
        else:
            _, load, torque = ramp_statics(scn, pose, stance, j, share)
            lower[j] = 0.0  # the ramped boom goes slack
            if not abs(torque) <= robot.shoulder_torque_max + TOL:
                fail("torque", f"boom {j}'s shoulder torque {torque:.3f} N m (share {share:.3f} "
                     f"of its limb) over the limit {robot.shoulder_torque_max}")
    residual = np.abs(prob.A[0] @ fa - load).max()
    if not residual <= STATICS_TOL:
        fail("statics", f"statics residual {residual:.2e} N > {STATICS_TOL}")
    if np.any(fa[att] < lower[att] - TOL) or np.any(fa[att] > hi_f + TOL):
        fail("tension", f"tensions {np.round(fa[att], 3).tolist()} outside [{lo_f}, {hi_f}] N"
             + (" (a ramped boom down to 0)" if ramp is not None else ""))
    kappa = float(wrench_conditioning(robot, prob.A, att)[0])
    if not kappa >= MIN_CONDITIONING:
        fail("conditioning", f"the booms nearly meet in one point (wrench conditioning "
             f"{kappa:.4f} < {MIN_CONDITIONING})")
    psi = prob.pull_angles[0]
    if not pull_within(robot, psi[att]).all():
        worst = float(np.degrees(np.abs(psi[att]).max()))
        fail("pull-angle", f"a grasp is pulled at {worst:.3f} deg from its normal, not less than "
             f"max_pull_angle_deg {robot.max_pull_angle_deg}")
    lp = stance.log_prob(fa, np.nan_to_num(psi))
    p_success = float(np.exp(lp[att].sum()))
    if not p_success >= robot.p_min - TOL:
        fail("probability", f"P = {p_success:.5f} below p_min {robot.p_min}")
    if not _same(p_success, step.p_success):
        fail("recorded-value", f"p_success {step.p_success} but recomputed {p_success}")
    p_grasp = [float(np.exp(v)) if att[i] else None for i, v in enumerate(lp)]
    for b, (mine, theirs) in enumerate(zip(p_grasp, step.p_grasp, strict=True)):
        if (mine is None) != (theirs is None) or (mine is not None and not _same(mine, theirs)):
            fail("recorded-value", f"p_grasp[{b}] {theirs} but recomputed {mine}")
    return p_grasp, p_success, float(fa[att].sum())
