"""The rules that tie a plan's configurations into one climb, and the plan to its cave.

`planning.check` verifies each configuration on its own (limits, statics, probabilities);
this module verifies what lies between them: the robot stored once, the climb starting at the
scenario's start and (when the plan claims success) ending in its goal, phases alternating and
joining exactly, the stance sequence following from the reach phases, time increasing, and
successive configurations within the plan's own step and turn limits. Each rule has a short id
(`RULES`, documented in docs/formats.md); every `Problem` names its rule, phase and step.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from planning.plan_model import Phase, Plan, Step, scenario_robot_problem
from planning.ramps import RAMP_DURATION, RELEASE_TENSION
from planning.search_outcome import Quality, Stop
from rb_drake.scenario import Scenario

RULES = {
    "robot": "the robot under `scenario` is the robot at the top level",
    "start": "the climb starts at t = 0 at the start pose, in the start stance",
    "goal": "a plan that claims success ends inside the goal disc (and its search record, if "
            "any, says a route was found); a partial plan (`partial`, never a continuation) "
            "does not claim success (nor does its search record say a route was found) and "
            "ends in the stance it names, as far from the goal as it says",
    "phase-order": "phases alternate body, reach, ..., and a successful or partial plan ends "
                   "on a body phase",
    "phase-form": "a phase's stance, free boom, anchors and steps fit its kind",
    "stance": "each phase's anchors follow from the phase before (a reach frees one boom, the "
              "next body phase holds it on to_anchor)",
    "reach-ends": "the free gripper starts on from_anchor and ends on to_anchor",
    "phase-join": "each phase starts where and when the phase before ended",
    "time-order": "time increases within a phase by at least MIN_STEP_GAP; in a trajectory, "
                  "by time_step",
    "speed": "between every two successive steps of the plan (within and across phases, "
             "continuations' spliced phases and footstep plans too) the body moves at most "
             "BODY_SPEED_MAX, turns at most TURN_SPEED_MAX and the free gripper moves at most "
             "GRIPPER_SPEED_MAX",
    "release": "a climb from the scenario's start begins with a body phase, and a body "
               "phase that a reach phase follows ends with a release ramp at the "
               "transition pose: the freed boom's tension falls (its shoulder taking up its "
               "limb) over at least RAMP_DURATION to at most RELEASE_TENSION when its "
               "gripper opens",
    "attach": "a body phase that follows a reach phase starts with an attach ramp at the "
              "transition pose: the gripper closes with its boom's tension at most "
              "RELEASE_TENSION, which rises (its shoulder letting go of its limb) over at "
              "least RAMP_DURATION before the body moves",
    "continuity": "successive configurations of a trajectory within the plan's step and turn "
                  "limits (body and free tip)",
    "recorded-value": "every recorded per-step value equals its recomputation",
    "kinematics": "boom lengths and shoulder angles within the robot's limits",
    "collision": "neither body nor booms cross rock",
    "statics": "the tensions balance gravity (to 1e-6 N) on exactly the attached booms",
    "tension": "tensions within the robot's tension limits",
    "torque": "the free boom's shoulder torque within its limit",
    "conditioning": "the booms' wrench not degenerate (not all through one point)",
    "pull-angle": "every grasp pulled at less than the robot's max_pull_angle_deg from its normal",
    "probability": "every configuration's P at least p_min",
    "between": "in a motion plan (with time_step), the motion from each step to the next "
               "(linear, as rbp rig-run executes it) passes the checks of a step at every "
               "sample of a resolution of 5 mm, 0.5 deg and 5 mm of boom or gripper travel "
               "(planning.verify_between)",
    "summary": "p_path, p_min, p_grasps and regrasps equal their recomputation (null but "
               "regrasps in a failed plan)",
    "scenario": "with rbp check --scenario CAVE: the plan's embedded cave and robot are "
                "CAVE's (the plan is verified against what it embeds)",
}

POSE_TOL = 1e-9   # m, rad: phases join and the climb starts exactly (plans copy these values)
TIME_TOL = 1e-6   # s: plans round time stamps to 6 decimals
LIMIT_TOL = 1e-9  # m, rad: above a step limit by more than this is a jump
# Successive steps of a phase at least this far apart in time: time stamps have 6 decimals and
# the splines of `rbp simulate` and `between` need increasing knots (Drake: 2.2e-16 s apart).
MIN_STEP_GAP = 1e-3  # s
# How fast a plan may move (rule `speed`, docs/model.md "How fast a plan moves"): the planner's
# steps (`limits.step` 0.1 m, `turn_step` 0.1 rad) every MIN_TIME_STEP (0.25 s) at most; its
# default plans (time_step 0.5 s) move at most 0.17 m/s, 0.10 rad/s and a gripper 0.10 m/s on
# the bundled caves. Its plans at 0.02 s on demo-shaft (0.45 m/s, 0.41 rad/s) failed every
# rbp simulate trial, and a continuation's spliced reach moved a gripper 0.57 m in 1 us.
BODY_SPEED_MAX = 0.4  # m/s
TURN_SPEED_MAX = 0.4  # rad/s
GRIPPER_SPEED_MAX = 0.4  # m/s
# The planner's step limits when a plan file does not record them (plans before `limits`):
# PipelineConfig's seed step and turn step (0.05 m, 0.05 rad) stretched by STEP_STRETCH.
STEP_STRETCH = 2.0  # SCP may lengthen a seed's step up to this factor (planning.plan)
DEFAULT_LIMITS = {"step": 0.1, "turn_step": 0.1}
# relative: a search record's cost / lower_bound is its bound, and an optimal route's cost
# its lower bound (planning.complete decides "optimal" at 1e-12)
SEARCH_REL = 1e-9


class Problem(NamedTuple):
    """One broken rule: where (`phase`, `step`: indices, None for the whole plan) and why."""

    rule: str
    text: str
    phase: int | None = None
    step: int | None = None
    where: str = ""  # "phases[3] (reach) step 5 (t=2.5)"; "" for the whole plan

    def __str__(self) -> str:
        return f"{self.where or 'plan'}: {self.rule}: {self.text}"


def locate(plan: Plan, k: int | None, n: int | None = None) -> str:
    """"phases[k] (kind) step n (t=...)" for the messages."""
    if k is None:
        return ""
    phase = plan.phases[k]
    where = f"phases[{k}] ({phase.kind})"
    if n is not None:
        where += f" step {n} (t={phase.steps[n].t})"
    return where


def step_limits(plan: Plan | Mapping[str, Any]) -> dict[str, float]:
    """The plan's own limits between successive configurations of a trajectory."""
    if isinstance(plan, Plan):
        return dict(DEFAULT_LIMITS) | (plan.limits.as_dict() if plan.limits else {})
    return dict(DEFAULT_LIMITS) | dict(plan.get("limits") or {})


def climb_problems(plan: Plan, scn: Scenario) -> list[Problem]:
    """Every broken rule between configurations and between the plan and its cave."""
    out: list[Problem] = []

    def fail(rule: str, text: str, k: int | None = None, n: int | None = None) -> None:
        out.append(Problem(rule, text, k, n, locate(plan, k, n)))

    _robot(plan, fail)
    if not plan.phases:  # a plan that found no route may hold none
        if plan.success:
            fail("phase-order", "the plan claims success but has no phases")
        if plan.partial is not None:
            fail("phase-order", "a partial plan without phases (no climb)")
        if plan.regrasps != 0:
            fail("summary", f"regrasps: the plan says {plan.regrasps}, its phases hold no reach "
                 "phase")
        return out
    _start(plan, scn, fail)
    _phase_order(plan, fail)
    _stances(plan, scn, fail)
    _joins(plan, fail)
    _times(plan, fail)
    speed_problems(plan, fail)
    _continuity(plan, fail)
    _ramps(plan, fail)
    _goal(plan, scn, fail)
    _search(plan, fail)
    return out


def _robot(plan: Plan, fail) -> None:
    """A `reachbot-plan/1` file's second robot, under `scenario`, is the plan's robot."""
    if (problem := scenario_robot_problem(plan)) is not None:
        fail("robot", problem)


def _start(plan: Plan, scn: Scenario, fail) -> None:
    """The first configuration is the scenario's start, or the plan's `start` (a continuation
    after a failed grasp starts where the robot was)."""
    if plan.start is not None:
        start_pose, start_stance = list(plan.start.pose), list(plan.start.stance)
    else:
        start_pose, start_stance = list(scn.start_pose), list(scn.start_stance)
    first = plan.phases[0]
    step = first.steps[0]
    held = list(first.stance)
    if first.kind == "reach" and first.free_boom is not None and first.free_boom in range(4):
        held[first.free_boom] = first.from_anchor
    if held != start_stance:
        fail("start", f"the climb starts in stance {held}, not the start stance "
             f"{start_stance}", 0, 0)
    elif len(set(held)) != len(held):  # a continuation's first reach left an anchor held twice
        fail("start", f"the start stance {start_stance} holds an anchor with two booms (a "
             "stance holds four distinct anchors)", 0, 0)
    gap = np.abs(np.subtract(step.pose, start_pose)).max()
    if not gap <= POSE_TOL:
        fail("start", f"the first pose {list(step.pose)} is not the start pose {start_pose} "
             f"(off by {gap:.3g})", 0, 0)
    if step.t != 0:
        fail("start", f"the climb starts at t = {step.t}, not 0", 0, 0)


def _phase_order(plan: Plan, fail) -> None:
    phases = plan.phases
    for k in range(1, len(phases)):
        if phases[k].kind == phases[k - 1].kind:
            fail("phase-order", f"two {phases[k].kind} phases in a row", k)
    if (plan.success or plan.partial is not None) and phases[-1].kind != "body":
        fail("phase-order", f"a {'successful' if plan.success else 'partial'} climb ends on a "
             "body phase", len(phases) - 1)
    reaches = sum(p.kind == "reach" for p in phases)
    if reaches != plan.regrasps:
        fail("summary", f"regrasps: the plan says {plan.regrasps}, its phases hold {reaches} "
             "reach phases")
    for k, phase in enumerate(phases):
        stance = list(phase.stance)
        free = [i for i, a in enumerate(stance) if a is None]
        if phase.kind == "body" and free:
            fail("phase-form", f"a body phase holds all four anchors, not {stance}", k)
        if phase.kind == "reach" and free != [phase.free_boom]:
            fail("phase-form", f"a reach phase frees exactly boom {phase.free_boom}, not "
                 f"{stance}", k)
        held = [a for a in stance if a is not None]
        if len(set(held)) != len(held):
            fail("phase-form", f"two booms on one anchor: {stance}", k)
        tips = [s.free_tip is not None for s in phase.steps]
        if any(tips) != (phase.kind == "reach") or (any(tips) and not all(tips)):
            fail("phase-form", "free_tip is given on every step of a reach phase and only there",
                 k)
        if phase.kind == "body":  # what only a reach has: its anchors, its free boom's torque
            ends = [a for a in (phase.from_anchor, phase.to_anchor) if a is not None]
            if ends:
                fail("phase-form", f"from_anchor and to_anchor belong to a reach phase, not a "
                     f"body phase (it gives {ends})", k)
            if any(s.shoulder_torque is not None for s in phase.steps):
                fail("phase-form", "shoulder_torque (the free boom's) is given on reach steps "
                     "only", k)


def _stances(plan: Plan, scn: Scenario, fail) -> None:
    phases = plan.phases
    for k, phase in enumerate(phases):
        unknown = [a for a in phase.stance if a is not None and a not in scn.anchor_index]
        if unknown:
            fail("stance", f"unknown anchors {unknown}", k)
        if phase.kind != "reach":
            continue
        for end, name, n in (("from_anchor", "starts", 0), ("to_anchor", "ends", -1)):
            anchor = getattr(phase, end)
            if anchor not in scn.anchor_index:
                fail("stance", f"unknown {end} {anchor!r}", k)
                continue
            tip = phase.steps[n].free_tip
            if tip is None:
                continue
            p = scn.anchors[scn.anchor_index[anchor]].position
            gap = math.dist(tip, p)
            if not gap <= POSE_TOL:
                fail("reach-ends", f"the free gripper {name} {gap:.3g} m from {end} {anchor}",
                     k, n % len(phase.steps))
    for k in range(1, len(phases)):
        before, phase = phases[k - 1], phases[k]
        if phase.kind == "reach" and before.kind == "body" and phase.free_boom is not None:
            j = phase.free_boom
            if before.stance[j] != phase.from_anchor:
                fail("stance", f"boom {j} leaves {phase.from_anchor} but held "
                     f"{before.stance[j]}", k)
            expected = [None if i == j else a for i, a in enumerate(before.stance)]
        elif phase.kind == "body" and before.kind == "reach":
            freed = before.free_boom
            expected = [before.to_anchor if i == freed else a
                        for i, a in enumerate(before.stance)]
        else:
            continue  # phase-order says what is wrong
        changed = [i for i in range(4) if expected[i] != phase.stance[i]]
        if changed:
            fail("stance", f"booms {changed} hold {[phase.stance[i] for i in changed]} but "
                 f"the phases before lead to {[expected[i] for i in changed]}", k)


def _joins(plan: Plan, fail) -> None:
    phases = plan.phases
    for k in range(1, len(phases)):
        a, b = phases[k - 1].steps[-1], phases[k].steps[0]
        gap = np.abs(np.subtract(a.pose, b.pose)).max()
        if not gap <= POSE_TOL:
            fail("phase-join", f"starts {gap:.3g} away from where phases[{k - 1}] ended "
                 f"({list(b.pose)} after {list(a.pose)})", k, 0)
        if abs(b.t - a.t) > TIME_TOL:
            fail("phase-join", f"starts at t = {b.t}, phases[{k - 1}] ended at t = {a.t}",
                 k, 0)


def is_trajectory(plan: Plan, phase: Phase) -> bool:
    """Whether a phase holds a trajectory (one step every time_step) rather than end poses."""
    return plan.time_step is not None and phase.motion is not None


def _times(plan: Plan, fail) -> None:
    dt = plan.time_step
    moved = False  # a phase with its trajectory came before
    for k, phase in enumerate(plan.phases):
        steps = phase.steps
        regular = is_trajectory(plan, phase)
        if dt is not None and not regular and plan.start is None:
            # Only a continuation (`start`) splices in phases that hold end poses only.
            fail("phase-form", "a phase of a full plan without its trajectory (motion)", k)
        elif dt is not None and not regular and moved:
            # ... and only as its first phases, before the replanned ones
            fail("phase-form", "a phase without its trajectory (motion) after one with it (a "
                 "continuation's spliced phases without motion come first)", k)
        moved = moved or regular
        if phase.motion is not None and dt is None:
            fail("phase-form", "a trajectory (motion) in a plan without time_step", k)
        for n in range(1, len(steps)):
            gap = steps[n].t - steps[n - 1].t
            if not gap >= MIN_STEP_GAP - TIME_TOL:
                fail("time-order", f"t = {steps[n].t} does not follow t = {steps[n - 1].t} "
                     f"by at least {MIN_STEP_GAP} s", k, n)
            elif regular and dt is not None and abs(gap - dt) > TIME_TOL:
                fail("time-order", f"{gap:.6g} s after the step before, not time_step {dt} s",
                     k, n)


def speed_problems(plan: Plan, fail) -> None:
    """Rule `speed`: per phase and quantity, the fastest of its step intervals over the limit
    (the interval into a phase's first step from the phase before's last included)."""
    for k, phase in enumerate(plan.phases):
        steps = phase.steps
        joined = (plan.phases[k - 1].steps[-1],) if k > 0 else ()  # the join: no motion
        t = np.array([s.t for s in joined + steps], dtype=float)
        q = np.array([s.pose for s in joined + steps], dtype=float)
        with np.errstate(all="ignore"):  # absurd numbers fail the rule, not numpy
            gap = np.maximum(np.diff(t), 0.0)  # phase-join allows TIME_TOL back at the join
            d = np.diff(q, axis=0)
            moves = [("the body moves", np.hypot(d[:, 0], d[:, 1]), BODY_SPEED_MAX, "m"),
                     ("the body turns", np.abs(d[:, 2]), TURN_SPEED_MAX, "rad")]
            if phase.kind == "reach" and all(s.free_tip is not None for s in steps):
                tips = np.array([s.free_tip for s in steps], dtype=float)
                travel = np.linalg.norm(np.diff(tips, axis=0), axis=1)
                moves.append(("the free gripper moves", np.r_[np.zeros(len(joined)), travel],
                              GRIPPER_SPEED_MAX, "m"))
            for what, size, limit, unit in moves:
                over = np.flatnonzero(~(size <= limit * gap + LIMIT_TOL))
                if not len(over):
                    continue
                n = int(over[np.argmax(size[over] / np.maximum(gap[over], 1e-300))])
                more = f" (and {len(over) - 1} more steps)" if len(over) > 1 else ""
                fail("speed", f"{what} {size[n]:.4g} {unit} in {gap[n]:.3g} s, over "
                     f"{limit:g} {unit}/s{more}", k, n + 1 - len(joined))


def _continuity(plan: Plan, fail) -> None:
    lim = step_limits(plan)
    for k, phase in enumerate(plan.phases):
        if not is_trajectory(plan, phase) or len(phase.steps) < 2:
            continue
        poses = np.array([s.pose for s in phase.steps], dtype=float)
        d = np.diff(poses, axis=0)
        moves = [("the body moves", np.hypot(d[:, 0], d[:, 1]), lim["step"], "m"),
                 ("the body turns", np.abs(d[:, 2]), lim["turn_step"], "rad")]
        if phase.kind == "reach" and all(s.free_tip is not None for s in phase.steps):
            tips = np.array([s.free_tip for s in phase.steps], dtype=float)
            moves.append(("the free tip moves", np.linalg.norm(np.diff(tips, axis=0), axis=1),
                          lim["step"], "m"))
        for what, size, limit, unit in moves:
            for n in np.flatnonzero(~(size <= limit + LIMIT_TOL)):
                fail("continuity", f"{what} {size[n]:.4g} {unit} in one step (limit {limit:g})",
                     k, int(n) + 1)


def _goal(plan: Plan, scn: Scenario, fail) -> None:
    if plan.partial is not None:
        _partial(plan, scn, fail)
    if not plan.success:
        return
    stop = plan.search.stop if plan.search is not None else Stop.ROUTE
    if stop != Stop.ROUTE:
        fail("goal", f"the plan claims success but its search record says it stopped with "
             f"{str(stop)!r} (no route found)")
    k = len(plan.phases) - 1
    n = len(plan.phases[k].steps) - 1
    end = plan.phases[k].steps[n].pose
    gap = math.dist(end[:2], scn.goal_position)
    if not gap <= scn.goal_tolerance + POSE_TOL:
        fail("goal", f"the plan claims success but ends {gap:.3f} m from the goal "
             f"{list(scn.goal_position)} (tolerance {scn.goal_tolerance} m)", k, n)


def _search(plan: Plan, fail) -> None:
    """The search record's cost, lower bound, bound and quality agree with one another (what
    `rbp check` prints of them: "route optimal", "within 2.03x of the optimum"). The lower
    bound is the search's proof, which the plan does not hold: not verified."""
    rec = plan.search
    if rec is None or rec.cost is None or rec.lower_bound is None:
        return
    cost, lower = rec.cost, rec.lower_bound
    if not lower <= cost * (1.0 + SEARCH_REL):
        fail("summary", f"search.lower_bound {lower} is above the route's cost {cost}")
    if rec.bound is not None and not (lower > 0 and math.isclose(rec.bound, cost / lower,
                                                                  rel_tol=SEARCH_REL)):
        fail("summary", f"search.bound {rec.bound} is not cost / lower_bound "
             f"({cost} / {lower})")
    if rec.quality == Quality.OPTIMAL and not cost <= lower * (1.0 + SEARCH_REL):
        fail("summary", f"search.quality 'optimal' but the route's cost {cost} is above the "
             f"lower bound {lower}")


def _partial(plan: Plan, scn: Scenario, fail) -> None:
    """A partial plan's record: not a success, and its stance and distances are the climb's."""
    part = plan.partial
    assert part is not None
    k = len(plan.phases) - 1
    if plan.success:
        fail("goal", "a plan that claims success is not partial (it reaches the goal or it is "
             "not a success)")
    if plan.start is not None:
        # rbp plan --partial climbs from the cave's start, which start_distance_m measures; a
        # replan (systems.replanning) is a route to the goal or none
        fail("goal", "a continuation (a plan with `start`) is not a partial plan: a partial "
             "climb starts at the cave's start")
    if plan.search is not None and plan.search.stop == Stop.ROUTE:
        # a partial climb is flown only when the search found no route (its stop says how it
        # ended); a record saying a route was found contradicts the plan's failure
        fail("goal", "a partial plan's search record says a route was found (stop ''): a "
             "partial climb follows a search that found none")
    last = plan.phases[k]
    if last.kind == "body" and tuple(last.stance) != tuple(part.reached_stance):
        fail("goal", f"partial.reached_stance {list(part.reached_stance)} but the climb ends in "
             f"{list(last.stance)}", k)
    for name, stance, said in (("goal_distance_m", tuple(last.stance), part.goal_distance_m),
                               ("start_distance_m", tuple(scn.start_stance),
                                part.start_distance_m)):
        ids = [a for a in stance if a is not None and a in scn.anchor_index]
        if len(ids) != len(stance):
            continue  # `stance` or `phase-form` says what is wrong
        # the measure of planning.search_cost.centroid_distance, recomputed here
        centre = scn.anchor_positions[[scn.anchor_index[a] for a in ids]].mean(axis=0)
        mine = float(np.linalg.norm(centre - np.asarray(scn.goal_position, dtype=float)))
        if not math.isclose(mine, said, rel_tol=1e-9, abs_tol=1e-9):
            fail("goal", f"partial.{name}: the plan says {said}, recomputed {mine}")
    # the reason, which `rbp check` prints on its ok line, says what the partial climb is in
    # the words planning.pipeline.partial_climb writes: they are the climb's
    n = sum(p.kind == "reach" for p in plan.phases)
    told = (f"partial climb: {n} regrasp{'' if n == 1 else 's'} to stance "
            f"{list(part.reached_stance)}, {part.goal_distance_m:.2f} m from the goal (the "
            f"start is {part.start_distance_m:.2f} m)")
    if told not in plan.reason:
        at = plan.reason.find("partial climb:")
        theirs = (f"it says {plan.reason[at:at + len(told) + 40]!r}" if at >= 0
                  else "it does not say")
        fail("goal", f"the reason does not say what the partial climb is ({told!r}): {theirs}")


def scenario_problems(plan: Plan, scn: Scenario) -> list[Problem]:
    """Rule `scenario` (`rbp check --scenario CAVE`): the cave and robot the plan embeds, which
    every other rule verifies it against, are those of `scn` (its name aside). A plan verifies
    against what it embeds, so an edit of it passes: a robot with a smaller body, longer booms
    or a lower p_min, an anchor's limit raised with the steps' P rescored, the goal moved to
    where the climb ends. Names what differs: top-level fields, anchors by id, robot
    parameters."""
    from rb_drake.params import ParamError, robot_from_dict

    out: list[Problem] = []
    where = f"{scn.name} ({scn.source})" if scn.source else scn.name
    cave = scn.to_dict(resolved=True)
    del cave["robot"]
    mine = json.loads(json.dumps(plan.scenario))  # its arrays as lists, as the cave's
    fields = [k for k in sorted(set(cave) | set(mine))
              if k not in ("name", "anchors") and mine.get(k) != cave.get(k)]
    ours = {a.get("id"): a for a in mine.get("anchors") or [] if isinstance(a, Mapping)}
    theirs = {a["id"]: a for a in cave["anchors"]}
    anchors = [f"anchors[{i}]" for i in sorted(set(ours) | set(theirs), key=str)
               if ours.get(i) != theirs.get(i)]
    if fields or anchors:
        out.append(Problem("scenario", f"the plan's cave differs from {where} in "
                           f"{', '.join(fields + anchors[:8])}"
                           + (f" and {len(anchors) - 8} more anchors" if len(anchors) > 8
                              else "")))
    try:
        robot = robot_from_dict(plan.robot).to_dict()
    except ParamError as e:  # the verifier refuses it too (bad input)
        return [*out, Problem("scenario", f"the plan's robot is malformed: {e.field}: "
                              f"{e.reason}")]
    expected = scn.robot.to_dict()
    names = [k for k in expected if robot.get(k) != expected[k]]
    if names:
        out.append(Problem("scenario", f"the plan's robot differs from {where}'s in {names}"))
    return out


def check_note(plan: Plan) -> str:
    """What `rbp check` says of a partial plan or a continuation that verifies ('' for
    another plan)."""
    notes = []
    if plan.start is not None:
        # the verifier trusts a continuation's `start`: say where it starts, so that a climb
        # cut from the middle of another does not read as a climb from the cave's start
        start = plan.scenario.get("start", {})
        first = plan.phases[0] if plan.phases else None
        free = ""
        if first is not None and first.kind == "reach":  # it starts after a failed grasp
            free = (f" with boom {first.free_boom} free, its gripper at {first.from_anchor} (a "
                    "grasp that failed: the robot starts on three booms, and that stance "
                    "holding on four is not verified)")
        notes.append(f"a continuation: starts at pose {_rounded(plan.start.pose)} in stance "
                     f"{list(plan.start.stance)}{free} (the cave's start: pose "
                     f"{_rounded(start.get('pose', []))} in stance {start.get('stance')}); how "
                     "the robot got there is not verified")
    part = plan.partial
    if part is not None:
        notes.append(f"partial: ends {part.goal_distance_m:.2f} m from the goal in stance "
                     f"{list(part.reached_stance)} (the start is {part.start_distance_m:.2f} m)")
    return "; ".join(notes)


def _rounded(values: Any) -> list[float]:
    return [round(float(v), 4) for v in values]


SHARE_TOL = 1e-9  # a ramp's share reaches 1 exactly (plans write the value 1.0)
TENSION_TOL = 1e-9  # N, for the ramps' monotonic tensions


def _ramp_run(steps: tuple[Step, ...], boom: int | None, from_end: bool) -> int:
    """How many steps at the start (or end) of a phase are ramp steps of `boom`."""
    order = reversed(steps) if from_end else iter(steps)
    n = 0
    for step in order:
        if step.ramp is None or step.ramp.boom != boom:
            break
        n += 1
    return n


def _ramps(plan: Plan, fail) -> None:
    """Every release and attach is ramped (RULES "release", "attach"); ramp steps appear only
    there."""
    phases = plan.phases
    first = phases[0]
    if plan.start is None and first.kind == "reach":
        # the climb starts on the four anchors of the start stance (rule start): a reach first
        # opens a gripper under load at t = 0, with no release ramp and its 4-stance unverified;
        # only a continuation (`start`, after a failed grasp) starts with the boom free
        fail("release", f"the climb starts with a reach phase: boom {first.free_boom}'s gripper "
             f"opens on {first.from_anchor} at the start without a release ramp (a climb "
             "from the scenario's start begins with a body phase)", 0, 0)
    for k, phase in enumerate(phases):
        steps = phase.steps
        marked = [n for n, s in enumerate(steps) if s.ramp is not None]
        if phase.kind != "body":
            for n in marked:
                fail("phase-form", "a ramp step in a reach phase", k, n)
            continue
        lead = trail = 0
        before = phases[k - 1] if k > 0 else None
        after = phases[k + 1] if k + 1 < len(phases) else None
        if before is not None and before.kind == "reach":
            j = before.free_boom
            # a phase of ramp steps only: its ramp ends on its last step (`attach` says so)
            lead = _ramp_run(steps, j, from_end=False)
            _check_ramp(plan, k, j, list(range(min(lead, len(steps) - 1) + 1)), "attach", fail)
        if after is not None and after.kind == "reach" and len(steps) > lead:
            j = after.free_boom
            trail = min(_ramp_run(steps, j, from_end=True), len(steps) - lead - 1)
            _check_ramp(plan, k, j, list(range(len(steps) - 1, len(steps) - trail - 2, -1)),
                        "release", fail)
        for n in marked:
            if lead <= n < len(steps) - trail:
                fail("phase-form", "a ramp step away from a release or an attach", k, n)


def _check_ramp(plan: Plan, k: int, boom, order: list[int], rule: str, fail) -> None:
    """One ramp of body phase k: `order` lists its step indices from the gripper's contact (the
    attach's first step, the release's last) to the first (last) configuration without a ramp,
    where the body is at rest on four booms."""
    steps = plan.phases[k].steps
    contact = steps[order[0]]
    where = order[0]
    f = contact.tension[boom] if isinstance(boom, int) and 0 <= boom < 4 else None
    if contact.ramp is None or f is None:
        fail(rule, f"boom {boom}'s gripper {'closes' if rule == 'attach' else 'opens'} at "
             f"tension {f} N: no {rule} ramp (the tension must be at most {RELEASE_TENSION} N "
             "there)", k, where)
        return
    if not f <= RELEASE_TENSION:
        fail(rule, f"boom {boom}'s gripper {'closes' if rule == 'attach' else 'opens'} at "
             f"tension {f:.4g} N, over {RELEASE_TENSION} N", k, where)
    if not abs(contact.ramp.share - 1.0) <= SHARE_TOL:
        fail(rule, f"boom {boom}'s shoulder carries {contact.ramp.share} of its limb when "
             "its gripper lets go or takes hold, not all of it", k, where)
    pose = contact.pose
    for a, b in itertools.pairwise(order):  # from the contact outwards
        sa, sb = steps[a], steps[b]
        if not np.abs(np.subtract(sb.pose, pose)).max() <= POSE_TOL:
            fail(rule, "the body moves during the ramp", k, b)
        share_a = sa.ramp.share if sa.ramp is not None else 0.0
        share_b = sb.ramp.share if sb.ramp is not None else 0.0
        fa, fb = sa.tension[boom], sb.tension[boom]
        if fb is None or not (share_b <= share_a + SHARE_TOL and fb >= fa - TENSION_TOL):
            fail(rule, f"boom {boom}'s load must move monotonically between its shoulder and "
                 f"its gripper (share {share_a:.3f} -> {share_b:.3f}, tension {fa} -> {fb})",
                 k, b)
    end = steps[order[-1]]
    if end.ramp is not None and end.ramp.boom == boom:
        fail(rule, f"the {rule} ramp of boom {boom} has no configuration on four booms at its "
             "end", k, order[-1])
    span = abs(float(end.t) - float(contact.t))
    if not span >= RAMP_DURATION - TIME_TOL:
        fail(rule, f"the {rule} ramp of boom {boom} lasts {span:.3g} s, under "
             f"{RAMP_DURATION} s", k, where)
