"""Release and attach as planned steps: the ramps that hand a boom's load over before its
gripper opens and after it attaches.

A gripper that opens while its boom still pulls frees a loaded limb at once: the other three
booms take the boom's share in one instant and the limb rings. So before a release the plan
holds the transition pose for RAMP_DURATION while the freed boom's tension ramps to zero, the
other three take the load, and the boom's shoulder takes up the limb's weight; the gripper opens
when the boom's tension is at most RELEASE_TENSION. An attach is the reverse: the gripper
closes on its anchor with its boom slack and its shoulder holding the limb, then the boom's
tension ramps up to the body phase's first configuration.

A ramp step is a 4-stance configuration (the pose of the transition) with a `ramp` record
`{"boom": j, "share": s}`: boom j's shoulder carries the share s of its limb's cantilevered
weight (`geometry.limb_load` with the gripper on its anchor), so the statics read

    A f = (1 - s) b_4 + s b_3,

b_4 the 4-stance load (booms massless) and b_3 the 3-stance load with boom j free, and boom j's
tension may go down to 0. The ramp's steps are convex combinations of the body phase's end
configuration (s = 0) and the reach phase's (s = 1, f_j = 0): statics are affine in (f, s), so
they hold exactly on every step and on every point between two steps, and each grasp's P,
monotone in its own tension at a fixed pose, is smallest at an end of each interval: the
steps' P bound the whole ramp, and p_path (over the steps) covers it.

Why RAMP_DURATION = 1 s: the free limb (0.2 kg at 1.5 m: ten times the body's inertia about
its shoulder) and the body are tracked by PD loops at 2 Hz, critically damped, which settle in
about 4 / (2 pi 2 Hz) = 0.32 s; unloaded at once, the limb rang for about 0.3 s. A
minimum-jerk ramp over three settling times (two periods of the loops) changes the load at most
1.9 / RAMP_DURATION of its size per second, slow enough that the loops' lag costs the grasps
nothing measurable, and costs 2 s per regrasp (about 1 % of a 5 m climb). docs/model.md
gives the measurements.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from planning.plan_model import Phase, Plan, Ramp, Step
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import StaticsProblem, statics_problem

RAMP_DURATION = 1.0     # s: each release and attach ramp lasts at least this long
RELEASE_TENSION = 0.05  # N: a gripper opens (or closes) only with its boom's tension below this
# N: the least tension the execution commands to an anchored boom, below the planner's lower
# bound boom_tension[0] (0.5 N by default): the margin that lets the controller pull less than
# the plan where the plan's boom sits on its bound (docs/model.md, "The controller's tension
# floor"). Twice RELEASE_TENSION, so that a held boom never looks released.
CONTROL_TENSION_FLOOR = 0.1
RAMP_STEPS = 2          # steps of a ramp in a plan without a time step (end poses only)
# N/s: the rig's winch bound (`RigLcmConfig.max_tension_rate`), which `rbp rig-run` holds a
# phase to before flying it: a ramp lasts longer than RAMP_DURATION where its load needs it,
# so that a ramp never needs a faster winch (the bundled plans' fastest change: about 15 N/s).
TENSION_RATE_MAX = 25.0


def ramp_statics(scn: Scenario, pose: np.ndarray, stance: Stance, boom: int,
                 share: float) -> tuple[StaticsProblem, np.ndarray, float]:
    """A ramp step's statics at one pose: the 4-stance problem, its load with the share of boom
    `boom`'s limb on the body ((3,)), and the shoulder torque the share carries."""
    four = statics_problem(scn.robot, scn.gravity_vector, pose, stance)
    tip = stance.positions[boom]
    three = statics_problem(scn.robot, scn.gravity_vector, pose, stance.without(boom), tip)
    b = (1.0 - share) * four.b[0] + share * three.b[0]
    return four, b, float(share * three.shoulder_torque[0])


def ramp_ends_hold(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
                   pose: np.ndarray, probabilities: np.ndarray) -> bool:
    """Whether the release ramp's end (the 3-stance with the gripper still on its old anchor,
    unloaded) and the attach ramp's start (on the new anchor, unloaded) hold P >= p_min at a
    transition pose whose four configurations' P are `probabilities`: each 3-stance's P times
    the unloaded grasp's P at zero tension (the complete search's release sets count it, the
    local polish of planning.footsteps does not)."""
    pose = np.asarray(pose, dtype=float)[None]
    new = tuple(anchor if i == boom else a for i, a in enumerate(stance))
    for k, four in ((1, scn.stance(stance)), (2, scn.stance(new))):
        psi = np.nan_to_num(statics_problem(scn.robot, scn.gravity_vector, pose,
                                            four).pull_angles)
        unloaded = float(np.exp(four.log_prob(np.zeros((1, 4)), psi)[0, boom]))
        if not probabilities[k] * unloaded >= scn.robot.p_min:
            return False
    return True


def ramp_probabilities(scn: Scenario, stance_ids: Sequence[str | None], step: Step) -> Step:
    """A 4-stance step with its p_grasp and p_success set from its tensions (as `rbp check`)."""
    stance = scn.stance(tuple(stance_ids))
    prob = statics_problem(scn.robot, scn.gravity_vector, np.asarray(step.pose), stance)
    f = np.array(step.tension, dtype=float)
    lp = stance.log_prob(f, np.nan_to_num(prob.pull_angles[0]))
    return step.replace(p_grasp=tuple(float(np.exp(v)) for v in lp),
                        p_success=float(np.exp(lp.sum())))


def _blend(a: Step, b: Step, s: float, boom: int, t: float, scn: Scenario,
           stance_ids: Sequence[str | None]) -> Step:
    """The configuration (1 - s) a + s b (b the 3-stance end, its free boom's tension 0), as a
    4-stance ramp step carrying the share s of boom `boom`'s limb."""
    fa = np.array([0.0 if v is None else v for v in a.tension])
    fb = np.array([0.0 if v is None else v for v in b.tension])
    f = (1.0 - s) * fa + s * fb
    f[boom] = max(f[boom], 0.0)
    step = Step(t=round(float(t), 6), pose=tuple(a.pose), tension=tuple(float(v) for v in f),
                p_grasp=(), p_success=0.0, ramp=Ramp(boom=int(boom), share=float(s)))
    return ramp_probabilities(scn, stance_ids, step)


def _shift(phases: list[Phase], first: int, dt: float) -> None:
    """Shift the steps of phases[first:] by dt in time (the list's phases replaced)."""
    for k in range(first, len(phases)):
        phases[k] = dataclasses.replace(phases[k], steps=tuple(
            step.replace(t=round(float(step.t) + dt, 6)) for step in phases[k].steps))


def _extend_motion(phase: Phase, steps: list[Step], at_start: bool) -> Phase:
    """The phase with its trajectory's `motion` record kept one entry per step: a ramp step is
    its own seed."""
    motion = phase.motion
    if motion is None:
        return phase
    efforts = tuple(float(sum(v or 0.0 for v in s.tension)) for s in steps)
    rows: dict[str, tuple[Any, ...]] = {
        "seed_p_success": tuple(s.p_success for s in steps),
        "seed_tension": tuple(tuple(s.tension) for s in steps),
        "seed_effort": efforts, "effort": efforts}
    changes = {name: new + getattr(motion, name) if at_start else getattr(motion, name) + new
               for name, new in rows.items()}
    return dataclasses.replace(phase, motion=dataclasses.replace(motion, **changes))


def add_ramps(plan: Plan, scn: Scenario, duration: float = RAMP_DURATION) -> Plan:
    """The plan with a release ramp at the end of every body phase that a reach phase follows
    and an attach ramp at the start of every body phase that follows a reach phase, where they
    are missing; later steps are shifted in time. Ramp steps come every `time_step` in a plan
    with one (at least `duration` in all), else RAMP_STEPS of them over `duration`; either
    lasts longer where a boom's tension would change faster than TENSION_RATE_MAX. The plan's
    scores are left to the caller (`plan.score_plan`): a ramp's P never falls below its ends'."""
    dt = plan.time_step
    phases = list(plan.phases)
    for k in range(len(phases)):
        if phases[k].kind != "body":
            continue
        before = phases[k - 1] if k > 0 else None
        if (before is not None and before.kind == "reach"
                and phases[k].steps[0].ramp is None):
            j, end = _free_boom(before), before.steps[-1]
            first = phases[k].steps[0]
            t0 = float(first.t)
            n, step_dt = ramp_timing(first, end, dt, duration)
            ramp = [_blend(first, end, (n - m) / n, j, t0 + m * step_dt, scn, phases[k].stance)
                    for m in range(n)]
            _shift(phases, k, n * step_dt)
            phase = phases[k]
            phases[k] = _extend_motion(dataclasses.replace(phase, steps=(*ramp, *phase.steps)),
                                       ramp, at_start=True)
        after = phases[k + 1] if k + 1 < len(phases) else None
        if (after is not None and after.kind == "reach"
                and phases[k].steps[-1].ramp is None):
            j, start = _free_boom(after), after.steps[0]
            last = phases[k].steps[-1]
            t0 = float(last.t)
            n, step_dt = ramp_timing(last, start, dt, duration)
            ramp = [_blend(last, start, m / n, j, t0 + m * step_dt, scn, phases[k].stance)
                    for m in range(1, n + 1)]
            _shift(phases, k + 1, n * step_dt)
            phase = phases[k]
            phases[k] = _extend_motion(dataclasses.replace(phase, steps=(*phase.steps, *ramp)),
                                       ramp, at_start=False)
    return dataclasses.replace(plan, phases=tuple(phases))


def ramp_timing(a: Step, b: Step, dt: float | None, duration: float) -> tuple[int, float]:
    """(steps, seconds between them) of a ramp from configuration a to b: every `dt` over at
    least `duration` (RAMP_STEPS over `duration` without one), stretched so that no boom's
    tension changes faster than TENSION_RATE_MAX (the blend is linear in the tensions)."""
    fa = np.array([0.0 if v is None else v for v in a.tension], dtype=float)
    fb = np.array([0.0 if v is None else v for v in b.tension], dtype=float)
    least = max(duration, float(np.abs(fb - fa).max()) / TENSION_RATE_MAX)  # s
    if dt:
        return max(1, math.ceil(least / dt - 1e-9)), dt
    return RAMP_STEPS, least / RAMP_STEPS


def _free_boom(reach: Phase) -> int:
    if reach.free_boom is None:
        raise ValueError("a reach phase without a free boom")
    return reach.free_boom
