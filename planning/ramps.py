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

import copy
import math
from typing import Any

import numpy as np

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


def ramp_probabilities(scn: Scenario, stance_ids: list, step: dict[str, Any]) -> None:
    """Set a 4-stance step's p_grasp and p_success from its tensions (as `rbp check`)."""
    stance = scn.stance(tuple(stance_ids))
    prob = statics_problem(scn.robot, scn.gravity_vector, np.asarray(step["pose"]), stance)
    f = np.array(step["tension"], dtype=float)
    lp = stance.log_prob(f, np.nan_to_num(prob.pull_angles[0]))
    step["p_grasp"] = [float(np.exp(v)) for v in lp]
    step["p_success"] = float(np.exp(lp.sum()))


def _blend(a: dict[str, Any], b: dict[str, Any], s: float, boom: int, t: float,
           scn: Scenario, stance_ids: list) -> dict[str, Any]:
    """The configuration (1 - s) a + s b (b the 3-stance end, its free boom's tension 0), as a
    4-stance ramp step carrying the share s of boom `boom`'s limb."""
    fa = np.array([0.0 if v is None else v for v in a["tension"]])
    fb = np.array([0.0 if v is None else v for v in b["tension"]])
    f = (1.0 - s) * fa + s * fb
    f[boom] = max(f[boom], 0.0)
    step = {"t": round(float(t), 6), "pose": list(a["pose"]),
            "tension": [float(v) for v in f], "p_grasp": [], "p_success": 0.0,
            "ramp": {"boom": int(boom), "share": float(s)}}
    ramp_probabilities(scn, stance_ids, step)
    return step


def _shift(phases: list[dict[str, Any]], first: int, dt: float) -> None:
    for phase in phases[first:]:
        for step in phase["steps"]:
            step["t"] = round(float(step["t"]) + dt, 6)


def _extend_motion(phase: dict[str, Any], steps: list[dict[str, Any]], at_start: bool) -> None:
    """Keep a trajectory phase's `motion` record one entry per step: a ramp step is its own
    seed."""
    motion = phase.get("motion")
    if motion is None:
        return
    rows = {"seed_p_success": [s["p_success"] for s in steps],
            "seed_tension": [list(s["tension"]) for s in steps],
            "seed_effort": [float(sum(s["tension"])) for s in steps],
            "effort": [float(sum(s["tension"])) for s in steps]}
    for name, new in rows.items():
        motion[name] = new + motion[name] if at_start else motion[name] + new


def add_ramps(plan: dict[str, Any], scn: Scenario, duration: float = RAMP_DURATION
              ) -> dict[str, Any]:
    """The plan with a release ramp at the end of every body phase that a reach phase follows
    and an attach ramp at the start of every body phase that follows a reach phase, where they
    are missing; later steps are shifted in time. Ramp steps come every `time_step` in a plan
    with one (at least `duration` in all), else RAMP_STEPS of them over `duration`. The plan's
    scores are left to the caller (`plan.score_plan`): a ramp's P never falls below its ends'."""
    plan = copy.deepcopy(plan)
    dt = plan.get("time_step")
    n = max(1, math.ceil(duration / dt - 1e-9)) if dt else RAMP_STEPS
    step_dt = dt if dt else duration / RAMP_STEPS
    phases = plan["phases"]
    for k, phase in enumerate(phases):
        if phase["kind"] != "body":
            continue
        before = phases[k - 1] if k > 0 else None
        if before is not None and before["kind"] == "reach" and "ramp" not in phase["steps"][0]:
            j, end = before["free_boom"], before["steps"][-1]
            first = phase["steps"][0]
            t0 = float(first["t"])
            ramp = [_blend(first, end, (n - m) / n, j, t0 + m * step_dt, scn, phase["stance"])
                    for m in range(n)]
            _shift(phases, k, n * step_dt)
            phase["steps"] = ramp + phase["steps"]
            _extend_motion(phase, ramp, at_start=True)
        after = phases[k + 1] if k + 1 < len(phases) else None
        if after is not None and after["kind"] == "reach" and "ramp" not in phase["steps"][-1]:
            j, start = after["free_boom"], after["steps"][0]
            last = phase["steps"][-1]
            t0 = float(last["t"])
            ramp = [_blend(last, start, m / n, j, t0 + m * step_dt, scn, phase["stance"])
                    for m in range(1, n + 1)]
            _shift(phases, k + 1, n * step_dt)
            phase["steps"] = phase["steps"] + ramp
            _extend_motion(phase, ramp, at_start=False)
    return plan
