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

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from planning.between import BETWEEN_DIP, between_steps, dense_problem
from planning.plan_model import Phase, Plan
from planning.plan_steps import steps_with_tensions
from planning.probability import holdings_of
from planning.ramps import CONTROL_TENSION_FLOOR
from planning.smooth_motion import phase_path, smooth_problem
from planning.verify_between import phase_arrays, phase_world
from rb_drake import geometry
from rb_drake.feasibility import check_poses, reach_world
from rb_drake.kernel.scoring import score_poses
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import null_vector, statics_problem

EASE_STEPS = 4  # time steps over which a reach's speed grows from (falls to) rest
SLOW_FACTORS = (1, 2, 3, 4, 6, 8)  # cruise speeds tried, 1 / factor of the planned


def _progress(intervals: int, ease: int, slow: int = 1) -> np.ndarray:
    """Positions along a path of `intervals` planned intervals (in intervals), one per time
    step: the speed grows linearly from 0 over `ease` steps, cruises at 1 / `slow` interval
    per step, and falls linearly to 0 over `ease` steps. `ease` is even, so with `slow` 1 the
    positions after the easing land on the planned steps."""
    v = 1.0 / slow
    cruise = slow * intervals - ease  # time steps at full speed
    n = cruise + 2 * ease
    s = []
    for i in range(1, n + 1):
        if i <= ease:
            s.append(v * i * i / (2.0 * ease))
        elif i <= ease + cruise:
            s.append(v * (ease / 2.0 + (i - ease)))
        else:
            r = n - i
            s.append(intervals - v * r * r / (2.0 * ease))
    return np.array(s)


def _interpolate(values: np.ndarray, s: np.ndarray) -> np.ndarray:
    """values (K+1, n) at positions s in [0, K], linearly between rows."""
    k = np.minimum(np.floor(s).astype(int), len(values) - 2)
    w = (s - k)[:, None]
    return (1.0 - w) * values[k] + w * values[k + 1]


def ease_phase(scn: Scenario, phase: Phase, dt: float, t0: float,
               ease: int = EASE_STEPS, slow: int = 1,
               floor: np.ndarray | None = None) -> Phase | None:
    """The phase re-timed to start and stop gently, its first step at t0, cruising at 1 /
    `slow` of its planned speed (None when its path is too short to ease or an interpolated
    configuration is infeasible). The phase's last step is its dwell (a repeat of the one
    before), kept. `motion.inertial_excess` and `motion.inertial_dip` record `inertial_load`
    of the result, the dip below `floor` (per boom, log P: its holding's smallest planned P,
    `holding_floors`; NaN or None: no floor) or the phase's own steps', the lesser."""
    path = phase.steps[:-1]  # the dwell is added again below
    intervals = len(path) - 1
    ease = min(ease, 2 * (intervals // 2))
    if ease < 2 or intervals < ease:
        return None
    poses = np.array([s.pose for s in path], dtype=float)
    reach = phase.kind == "reach"
    s = np.concatenate([[0.0], _progress(intervals, ease, slow)])
    exact = np.abs(s - np.round(s)) < 1e-9
    new_poses = _interpolate(poses, s)
    new_poses[exact] = poses[np.round(s[exact]).astype(int)]
    new_tips = None
    if reach:
        tips = np.array([s.free_tip for s in path], dtype=float)
        new_tips = _interpolate(tips, s)
        new_tips[exact] = tips[np.round(s[exact]).astype(int)]
    stance = scn.stance(tuple(phase.stance))
    # a free gripper touches rock only near its own anchors, where its path starts and ends
    check = check_poses(reach_world(scn, new_tips), stance, new_poses, new_tips, full=True)
    if not check.feasible.all():
        return None
    tensions = check.allocation.tensions.copy()
    planned = np.array([[np.nan if v is None else v for v in st.tension] for st in path])
    tensions[exact] = planned[np.round(s[exact]).astype(int)]
    new = steps_with_tensions(scn, tuple(phase.stance), new_poses, tensions, new_tips, t0, dt)
    new.append(new[-1].replace(t=round(t0 + len(new) * dt, 6)))
    times = np.array([st.t for st in new])
    with np.errstate(divide="ignore"):
        own = np.log(np.array([[1.0 if p is None else p for p in st.p_grasp] for st in new]))
    lowest = own.min(axis=0)
    if floor is not None:
        lowest = np.fmin(lowest, floor)
    load = inertial_load(scn, stance, times, np.vstack([new_poses, new_poses[-1:]]),
                         None if new_tips is None else np.vstack([new_tips, new_tips[-1:]]),
                         lowest)
    motion = phase.motion
    if motion is not None:  # the seed's record on the same path, for SCP's statistics
        m = len(path)
        seed_p = _interpolate(np.array(motion.seed_p_success[:m], dtype=float)[:, None], s)
        seed_f = _interpolate(np.array([[np.nan if v is None else v for v in row]
                                        for row in motion.seed_tension[:m]]), s)
        seed_p, seed_f = np.vstack([seed_p, seed_p[-1:]]), np.vstack([seed_f, seed_f[-1:]])
        motion = dataclasses.replace(
            motion,
            seed_p_success=tuple(float(v) for v in seed_p[:, 0]),
            seed_tension=tuple(tuple(None if np.isnan(v) else float(v) for v in row)
                               for row in seed_f),
            seed_effort=tuple(float(np.nansum(row)) for row in seed_f),
            effort=tuple(float(sum(v for v in st.tension if v is not None)) for st in new),
            eased=ease, slowed=slow,
            inertial_excess=float(load.excess.max()), inertial_dip=float(load.dip.max()))
    return dataclasses.replace(phase, steps=tuple(new), motion=motion)


class Inertial(NamedTuple):
    """What accelerating a phase's configurations costs, per sample of its smooth path."""

    excess: np.ndarray  # N (summed over booms) by which the tensions leave the bounds
    dip: np.ndarray     # the largest log P by which a grasp falls below its floor (or, with
    # no floor, below its static log P there) with the least tension change


# Where in each interval of the smooth path the inertial load is evaluated: both sides of each
# knot (a cubic Hermite piece's acceleration jumps there: a body coming to rest while its
# gripper still swings) and between them.
INERTIAL_FRACTIONS = (1e-6, 0.25, 0.5, 0.75, 1.0 - 1e-6)


def inertial_excess(scn: Scenario, stance: Stance, times: np.ndarray, poses: np.ndarray,
                    tips: np.ndarray | None) -> np.ndarray:
    """`inertial_load(...).excess`."""
    return inertial_load(scn, stance, times, poses, tips).excess


def inertial_load(scn: Scenario, stance: Stance, times: np.ndarray, poses: np.ndarray,
                  tips: np.ndarray | None, floor: np.ndarray | None = None) -> Inertial:
    """Along the smooth path `rbp simulate` follows through a phase's steps (`times`, `poses`,
    `tips`, its dwell last: `planning.smooth_motion.phase_path`), at INERTIAL_FRACTIONS of
    each interval: by how much (N, summed over booms; 0 where none) the tensions that also
    accelerate the body, and the free limb, as the path's second derivatives say, leave the
    execution's bounds [CONTROL_TENSION_FLOOR, boom_tension[1]], and `dip`, each sample's
    largest log P by which a grasp falls below `floor` (per boom; the least planned log P of
    its holding: what p_path counts of it) with that least tension change (what the tension
    controller adds to the feed-forward, the most robust tensions there); with no floor, its
    loss against the static log P there. Accelerating the body needs the
    wrench diag(m, m, I) a more, and a free limb (its gripper and the tip half of its boom,
    m_t, at the tip) m_t a_t more at the tip. In a 3-stance the change is unique; in a
    4-stance the best member of the family counts. Second differences of the steps, used
    before, saw a tenth of the dip where a body came to rest while its gripper swung on
    (shaft-8m-s1's reach phase 57: log P 0.0008 estimated, 0.009 simulated). Samples that
    do not hold statically count 0 here: the test between steps refuses them."""
    path = phase_path(times, poses, tips)
    knots = path.knots
    t = (knots[:-1, None] + np.asarray(INERTIAL_FRACTIONS)[None, :]
         * np.diff(knots)[:, None]).ravel()
    q = path.pose.vector_values(t).T
    acc = path.pose.derivative(2).vector_values(t).T
    tip = a_t = None
    if path.tip is not None and stance.free_boom is not None:
        tip = path.tip.vector_values(t).T
        a_t = path.tip.derivative(2).vector_values(t).T
    # compiled: check_poses' decisions (a free gripper near its own anchors, `tips`' ends)
    check = score_poses(reach_world(scn, tips), stance, q, tip)
    held = check.feasible
    robot = scn.robot
    m = robot.body_mass
    w, h = robot.body_size
    wrench = np.column_stack([m * acc[:, 0], m * acc[:, 1], m * (w * w + h * h) / 12.0 * acc[:, 2]])
    if tip is not None and a_t is not None:
        shoulder = geometry.shoulder_positions(robot, q)[:, stance.free_boom]
        m_t = robot.gripper_mass + 0.5 * robot.boom_linear_density * np.linalg.norm(
            tip - shoulder, axis=1)
        push = m_t[:, None] * a_t
        wrench[:, :2] += push
        wrench[:, 2] += geometry.cross2(tip - q[:, :2], push)
    statics = statics_problem(robot, scn.gravity_vector, q, stance, tip)
    A = statics.A
    att = stance.attached
    f = np.where(att & held[:, None], np.nan_to_num(check.tensions), 0.0)
    lo, hi = CONTROL_TENSION_FLOOR, robot.boom_tension[1]

    def excess(g: np.ndarray) -> np.ndarray:
        return np.sum(np.where(att, np.maximum(0.0, lo - g) + np.maximum(0.0, g - hi), 0.0),
                      axis=-1)

    At = np.swapaxes(A, 1, 2)
    AAt = A @ At
    ok = np.abs(np.linalg.det(AAt)) > 1e-14
    d = (At @ np.linalg.solve(np.where(ok[:, None, None], AAt, np.eye(3)),
                              wrench[..., None]))[..., 0]  # the least change (unique: 3 booms)
    g = f + np.where(att, d, 0.0)
    out = excess(g)
    if att.all():  # 4 booms: the best member f + d + t n of the family
        n = null_vector(A)
        with np.errstate(divide="ignore", invalid="ignore"):
            ts = np.concatenate([(lo - g) / n, (hi - g) / n], axis=1)
        ts = np.nan_to_num(ts, nan=0.0, posinf=0.0, neginf=0.0)
        out = np.minimum(out, excess(g[:, None, :] + ts[:, :, None] * n[:, None, :]).min(axis=1))
    psi = np.nan_to_num(statics.pull_angles)
    with np.errstate(divide="ignore", invalid="ignore"):
        moving = stance.log_prob(np.where(att, g, 0.0), psi)
        reference = stance.log_prob(f, psi) if floor is None else np.broadcast_to(
            np.asarray(floor, dtype=float), moving.shape)
        loss = np.maximum(0.0, reference - moving)[:, att]
    dip = np.nan_to_num(loss.max(axis=1), nan=np.inf) if len(t) else np.zeros(0)
    return Inertial(np.where(held, np.where(ok, out, np.inf), 0.0),
                    np.where(held, np.where(ok, dip, np.inf), 0.0))


def _verifier_fails(scn: Scenario, phase: Phase) -> bool:
    """Whether the motion between a phase's steps fails rule `between` of `rbp check`: the
    straight motion or the smooth path at the rule's resolution, with its tolerance."""
    times, poses, tips = phase_arrays(phase)
    stance = scn.stance(tuple(phase.stance))
    world = phase_world(scn, phase)
    return bool(dense_problem(world, stance, poses, tips)
                or smooth_problem(world, stance, poses, tips, times, dwell=False))


def _between_fails(scn: Scenario, phase: Phase) -> bool:
    """Whether the motion between a phase's steps (at their times, its dwell included) fails
    `between_steps`."""
    times, poses, tips = phase_arrays(phase)
    with np.errstate(divide="ignore"):
        lp = np.log(np.array([[1.0 if p is None else p for p in st.p_grasp]
                              for st in phase.steps]))
    return bool(between_steps(phase_world(scn, phase), scn.stance(tuple(phase.stance)), poses,
                              lp, tips, times, dwell=False))


def _motion_score(scn: Scenario, phase: Phase) -> tuple[bool, float, float]:
    """(whether the motion between the steps fails `between_steps`, the inertial excess, the
    inertial dip beyond BETWEEN_DIP): the smaller the better; (False, 0.0, 0.0) passes."""
    failed = _between_fails(scn, phase)
    motion = phase.motion
    if motion is None or motion.inertial_excess is None or motion.inertial_dip is None:
        raise ValueError("an eased phase without its inertial record")
    return (bool(failed), max(0.0, float(motion.inertial_excess)),
            max(0.0, float(motion.inertial_dip) - BETWEEN_DIP))


def holding_floors(plan: Plan) -> np.ndarray:
    """(phases, 4): at each phase, the log of the least planned P of the holding each boom is
    in (`planning.probability.holdings_of`), NaN where free: what p_path counts of that grasp,
    so what its execution must not fall below."""
    out = np.full((len(plan.phases), NUM_BOOMS), np.nan)
    for h in holdings_of([phase.stance for phase in plan.phases]):
        worst = min((float(p) for phase in plan.phases[h.first:h.last + 1]
                     for step in phase.steps if (p := step.p_grasp[h.boom]) is not None),
                    default=1.0)
        out[h.first:h.last + 1, h.boom] = math.log(worst) if worst > 0 else -math.inf
    return out


def ease_motions(plan: Plan, scn: Scenario, ease: int = EASE_STEPS) -> Plan:
    """The plan with every trajectory phase (body and reach) eased (`ease_phase`) where it can
    be, later steps shifted in time. Plans without a time step (end poses only) are left as
    they are: their two-step phases are executed rest to rest at minimum-jerk timing already."""
    dt = plan.time_step
    if not dt:
        return plan
    phases = []
    shift = 0.0
    floors = holding_floors(plan)
    for k, phase in enumerate(plan.phases):
        if shift:
            phase = dataclasses.replace(phase, steps=tuple(
                step.replace(t=round(float(step.t) + shift, 6)) for step in phase.steps))
        if phase.motion is None:
            phases.append(phase)
            continue
        t0 = float(phase.steps[0].t)
        eased: Phase | None = None
        best: tuple[bool, float, float] = (True, np.inf, np.inf)
        for slow in SLOW_FACTORS:  # slower where the motion between steps or its inertia fails
            candidate = None
            for e in range(ease, 0, -2):  # gentler where an interpolated configuration fails
                candidate = ease_phase(scn, phase, dt, t0, e, slow, floors[k])
                if candidate is not None:
                    break
            if candidate is None:
                break
            score = _motion_score(scn, candidate)
            if eased is None or score < best:
                eased, best = candidate, score
            if best == (False, 0.0, 0.0):
                break
        if eased is None or (best[0] and _verifier_fails(scn, eased)
                             and not _verifier_fails(scn, phase)):
            # no easing, or the eased timing's motion between steps fails `rbp check`'s rule
            # where the planned one passes (its smooth path, re-timed, crossed a limit SCP's
            # steps ride)
            phases.append(phase)
            continue
        shift += float(eased.steps[-1].t) - float(phase.steps[-1].t)
        phases.append(eased)
    return dataclasses.replace(plan, phases=tuple(phases))
