"""Motions that start and stop gently: in every trajectory phase the body (and, reaching, the
free gripper) speeds up and slows down over several time steps instead of one.

A reach phase moves a cantilevered limb whose inertia about its shoulder is ten times the
body's, on a body held by three booms whose moment direction is weak: to swing the limb
from rest to its cruising speed within one time step (0.5 s, the plan's knots 5 cm apart) the
booms must give it a moment they answer with newtons of tension, which the quasi-static plan
does not see (measured on a shaft plan: one grasp at P = 0.947 where the plan has 0.991, just
after its gripper let go). A body phase starting from rest jolts the body the same way (a
grasp at P = 0.984 fell to 0.964 on a shaft plan, just after an attach ramp). The
configurations are the plan's own: `ease_motions` re-times each phase's path so that its
speed grows linearly from rest over EASE_STEPS time steps and falls linearly to rest over as
many at its end, the configurations in between interpolated on the path (pose and free tip
linearly between the planned steps) with the most robust tensions there (unique in a
3-stance), checked like every other. Cruising, the path keeps its planned steps and speed;
each end adds EASE_STEPS / 2 time steps.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from rb_drake.feasibility import check_poses
from rb_drake.scenario import Scenario

EASE_STEPS = 4  # time steps over which a reach's speed grows from (falls to) rest


def _progress(intervals: int, ease: int) -> np.ndarray:
    """Positions along a path of `intervals` planned intervals (in intervals), one per time
    step: the speed grows linearly from 0 over `ease` steps, cruises at one interval per
    step, and falls linearly to 0 over `ease` steps. `ease` is even, so after the easing the
    positions land on the planned steps."""
    half = ease / 2.0
    cruise = intervals - ease  # intervals covered at full speed
    n = round(cruise + 2 * ease)
    s = []
    for i in range(1, n + 1):
        if i <= ease:
            s.append(i * i / (2.0 * ease))
        elif i <= ease + cruise:
            s.append(half + (i - ease))
        else:
            r = n - i
            s.append(intervals - r * r / (2.0 * ease))
    return np.array(s)


def _interpolate(values: np.ndarray, s: np.ndarray) -> np.ndarray:
    """values (K+1, n) at positions s in [0, K], linearly between rows."""
    k = np.minimum(np.floor(s).astype(int), len(values) - 2)
    w = (s - k)[:, None]
    return (1.0 - w) * values[k] + w * values[k + 1]


def ease_phase(scn: Scenario, phase: dict[str, Any], dt: float, t0: float,
               ease: int = EASE_STEPS) -> dict[str, Any] | None:
    """The phase re-timed to start and stop gently, its first step at t0 (None when its
    path is too short to ease or an interpolated configuration is infeasible). The phase's
    last step is its dwell (a repeat of the one before), kept."""
    from planning.plan import _steps_with_tensions

    steps = phase["steps"]
    path = steps[:-1]  # the dwell is added again below
    intervals = len(path) - 1
    ease = min(ease, 2 * (intervals // 2))
    if ease < 2 or intervals < ease:
        return None
    poses = np.array([s["pose"] for s in path], dtype=float)
    reach = phase["kind"] == "reach"
    tips = np.array([s["free_tip"] for s in path], dtype=float) if reach else None
    s = np.concatenate([[0.0], _progress(intervals, ease)])
    exact = np.abs(s - np.round(s)) < 1e-9
    new_poses = _interpolate(poses, s)
    new_poses[exact] = poses[np.round(s[exact]).astype(int)]
    new_tips = None
    if reach:
        new_tips = _interpolate(tips, s)
        new_tips[exact] = tips[np.round(s[exact]).astype(int)]
    stance = scn.stance(tuple(phase["stance"]))
    check = check_poses(scn, stance, new_poses, new_tips, full=True)
    if not check.feasible.all():
        return None
    tensions = check.allocation.tensions.copy()
    planned = np.array([[np.nan if v is None else v for v in st["tension"]] for st in path])
    tensions[exact] = planned[np.round(s[exact]).astype(int)]
    new = _steps_with_tensions(scn, tuple(phase["stance"]), new_poses, tensions, new_tips, t0,
                               dt)
    new.append(dict(new[-1], t=round(t0 + len(new) * dt, 6)))
    out = copy.deepcopy(phase)
    out["steps"] = new
    motion = out.get("motion")
    if motion is not None:  # the seed's record on the same path, for SCP's statistics
        m = len(path)
        seed_p = _interpolate(np.array(motion["seed_p_success"][:m], dtype=float)[:, None], s)
        seed_f = _interpolate(np.array([[np.nan if v is None else v for v in row]
                                        for row in motion["seed_tension"][:m]]), s)
        seed_p, seed_f = np.vstack([seed_p, seed_p[-1:]]), np.vstack([seed_f, seed_f[-1:]])
        motion["seed_p_success"] = [float(v) for v in seed_p[:, 0]]
        motion["seed_tension"] = [[None if np.isnan(v) else float(v) for v in row]
                                  for row in seed_f]
        motion["seed_effort"] = [float(np.nansum(row)) for row in seed_f]
        motion["effort"] = [float(sum(v for v in st["tension"] if v is not None)) for st in new]
        motion["eased"] = ease
    return out


def ease_motions(plan: dict[str, Any], scn: Scenario, ease: int = EASE_STEPS) -> dict[str, Any]:
    """The plan with every trajectory phase (body and reach) eased (`ease_phase`) where it can
    be, later steps shifted in time. Plans without a time step (end poses only) are left as
    they are: their two-step phases are executed rest to rest at minimum-jerk timing already."""
    dt = plan.get("time_step")
    if not dt:
        return plan
    plan = copy.deepcopy(plan)
    shift = 0.0
    for phase in plan["phases"]:
        if shift:
            for step in phase["steps"]:
                step["t"] = round(float(step["t"]) + shift, 6)
        if "motion" not in phase:
            continue
        t0 = float(phase["steps"][0]["t"])
        eased = None
        for e in range(ease, 0, -2):  # gentler where an interpolated configuration fails
            eased = ease_phase(scn, phase, dt, t0, e)
            if eased is not None:
                break
        if eased is None:
            continue
        shift += float(eased["steps"][-1]["t"]) - float(phase["steps"][-1]["t"])
        phase.clear()
        phase.update(eased)
    return plan
