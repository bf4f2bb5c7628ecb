"""`rbp check`: re-verify a plan file from scratch, trusting none of the planner's bookkeeping.

The scenario and robot are rebuilt from the plan file itself; every configuration is checked
with the plan's own tensions (not re-optimised): kinematic limits, collisions, statics to
1e-6 N, tension bounds, shoulder torque, and P >= p_min recomputed from the limit surfaces; the
stance sequence must be consistent, and p_min, p_path and the regrasp count are recomputed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from planning.plan import plan_configurations
from planning.probability import Configuration, path_probability
from rb_drake import geometry
from rb_drake.collision import ANCHOR_CLEARANCE
from rb_drake.feasibility import MIN_CONDITIONING, wrench_conditioning
from rb_drake.grasp import HALF_PI
from rb_drake.scenario import scenario_from_dict
from rb_drake.statics import STATICS_TOL, statics_problem

TOL = 1e-9


def check_plan(plan: dict[str, Any], source: str = "<plan>") -> list[str]:
    """Every problem found in `plan`, in words; [] for a valid plan."""
    scenario = dict(plan["scenario"])
    scenario["robot"] = plan["robot"]
    scn = scenario_from_dict(scenario, source, check_start=False)
    robot = scn.robot
    problems: list[str] = []
    recomputed: list[Configuration] = []
    previous: list[str | None] | None = None
    arriving: tuple[int, str] | None = None  # (boom, anchor) a reach phase ended on
    for k, phase in enumerate(plan["phases"]):
        stance_ids = tuple(phase["stance"])
        where = f"phases[{k}] ({phase['kind']})"
        try:
            stance = scn.stance(stance_ids)
        except KeyError as e:
            problems.append(f"{where}: unknown anchor {e}")
            continue
        if phase["kind"] == "reach":
            j = phase["free_boom"]
            if phase["to_anchor"] not in scn.anchor_index:
                problems.append(f"{where}: unknown to_anchor {phase['to_anchor']!r}")
            arriving = (j, phase["to_anchor"])
            if stance_ids[j] is not None:
                problems.append(f"{where}: free boom {j} holds {stance_ids[j]}")
            if previous is not None and previous[j] != phase["from_anchor"]:
                problems.append(f"{where}: boom {j} leaves {phase['from_anchor']} but held "
                                f"{previous[j]}")
        elif previous is not None:
            expected = list(previous)
            if arriving is not None:
                expected[arriving[0]] = arriving[1]
            changed = [i for i in range(4) if expected[i] != stance_ids[i]]
            if changed:
                problems.append(f"{where}: booms {changed} hold {[stance_ids[i] for i in changed]}"
                                f" but the phases before lead to {[expected[i] for i in changed]}")
            arriving = None
        previous = list(stance_ids)
        for n, step in enumerate(phase["steps"]):
            at = f"{where} step {n} (t={step['t']})"
            pose = np.asarray(step["pose"], dtype=float)
            tip = np.asarray(step["free_tip"], dtype=float) if "free_tip" in step else None
            p_grasp, p_success = _check_configuration(scn, stance, pose, tip, step, at, problems)
            recomputed.append(Configuration(stance_ids, p_grasp, p_success))
    if plan["success"]:
        mine = path_probability(recomputed, robot.attach_failure)
        theirs = path_probability(plan_configurations(plan), robot.attach_failure)
        for name, a, b in (("p_path", mine.p_path, plan["p_path"]),
                           ("p_min", mine.p_min, plan["p_min"]),
                           ("p_grasps", mine.p_grasps, plan.get("p_grasps", mine.p_grasps)),
                           ("regrasps", mine.regrasps, plan["regrasps"]),
                           ("p_path from the file's own p_grasp", theirs.p_path, plan["p_path"])):
            if b is None or not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12):
                problems.append(f"{name}: the plan says {b}, recomputed {a}")
    return problems


def _check_configuration(scn, stance, pose, tip, step, at, problems):
    robot = scn.robot
    f = np.array([np.nan if v is None else v for v in step["tension"]], dtype=float)
    prob = statics_problem(robot, scn.gravity_vector, pose, stance, tip)
    geo = prob.geometry
    lo, hi = robot.boom_length
    used = stance.attached.copy()
    if tip is not None:
        used[stance.free_boom] = True
    for i in np.flatnonzero(used):
        L, th = geo.length[0, i], geo.shoulder_angle[0, i]
        if not lo - TOL <= L <= hi + TOL:
            problems.append(f"{at}: boom {i} length {L:.4f} m outside [{lo}, {hi}]")
        if abs(th) > robot.shoulder_range + TOL:
            problems.append(f"{at}: boom {i} shoulder angle {math.degrees(th):.2f} deg")
    rock = scn.rock
    corners = geometry.body_corners(robot, pose)
    if rock.segments_hit(corners, np.roll(corners, -1, axis=1)).any():
        problems.append(f"{at}: body collides with rock")
    targets = geo.shoulders[0] + geo.d[0]
    for i in np.flatnonzero(used):
        end = targets[i] - ANCHOR_CLEARANCE * geo.u[0, i]
        if rock.segments_hit(geo.shoulders[0, i], end)[()]:
            problems.append(f"{at}: boom {i} collides with rock")
    att = stance.attached
    if np.any(np.isnan(f[att])) or np.any(~np.isnan(f[~att])):
        problems.append(f"{at}: tensions must be given exactly for the attached booms")
        return [None] * 4, 0.0
    fa = np.where(att, f, 0.0)
    residual = np.abs(prob.A[0] @ fa - prob.b[0]).max()
    if residual > STATICS_TOL:
        problems.append(f"{at}: statics residual {residual:.2e} N > {STATICS_TOL}")
    lo_f, hi_f = robot.boom_tension
    if np.any(fa[att] < lo_f - TOL) or np.any(fa[att] > hi_f + TOL):
        problems.append(f"{at}: tensions {np.round(fa[att], 3).tolist()} outside "
                        f"[{lo_f}, {hi_f}] N")
    if tip is not None and abs(prob.shoulder_torque[0]) > robot.shoulder_torque_max + TOL:
        problems.append(f"{at}: shoulder torque {prob.shoulder_torque[0]:.3f} N m over the limit")
    kappa = float(wrench_conditioning(robot, prob.A, att)[0])
    if kappa < MIN_CONDITIONING:
        problems.append(f"{at}: the booms nearly meet in one point (wrench conditioning "
                        f"{kappa:.4f} < {MIN_CONDITIONING})")
    psi = prob.pull_angles[0]
    if np.any(np.abs(psi[att]) >= HALF_PI):
        problems.append(f"{at}: a grasp is pulled at 90 degrees or more from its normal")
    lp = stance.log_prob(fa, np.nan_to_num(psi))
    p_success = float(np.exp(lp[att].sum()))
    if p_success < robot.p_min - TOL:
        problems.append(f"{at}: P = {p_success:.5f} below p_min {robot.p_min}")
    if not math.isclose(p_success, step["p_success"], rel_tol=1e-9, abs_tol=1e-12):
        problems.append(f"{at}: p_success {step['p_success']} but recomputed {p_success}")
    return [float(np.exp(v)) if att[i] else None for i, v in enumerate(lp)], p_success
