"""The RBP pipeline: footstep plan, then for every body and reach phase a seed and its SCP.

`plan_climb` is what `rbp plan` runs. The footstep planner (or the naive baseline) fixes the
stance sequence and one transition pose per regrasp; each body phase then gets a feasible seed
trajectory from that pose to the next (`seeds.body_seed`: straight line, local detours, OMPL)
and each reach phase a seed with the free gripper on a collision-free arc (`seeds.reach_seed`);
SCP (`scp.optimise_body` / `optimise_reach`) raises their robustness, and where it cannot the
seed stands and the plan says so. The naive baseline stops after its footsteps: its
configurations need not be probable enough for the seeds' P >= p_min, and the paper compares
it on footsteps only.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Collection
from typing import Any, NamedTuple

import numpy as np

from planning.baseline import plan_naive
from planning.between import between_steps
from planning.config_ranges import DEFAULT_DT
from planning.footsteps import FootstepConfig, FootstepMemo, FootstepPlan, plan_footsteps
from planning.plan import build_motion_plan, build_plan, step_limits
from planning.plan_model import PhaseKind, Plan
from planning.scp import ScpConfig, ScpResult, optimise_body, optimise_reach
from planning.seeds import Seed, SeedConfig, body_seed, reach_seed
from planning.smooth_motion import smooth_path_problems
from planning.verify_between import between_problems
from rb_drake.feasibility import check_poses, reach_world
from rb_drake.scenario import Scenario
from rb_drake.statics import allocate, statics_problem

PLANNERS = ("rbp", "naive")
Move = tuple[tuple[str, ...], int, str]  # (stance, boom, anchor) of a footstep move


@dataclasses.dataclass(frozen=True)
class PipelineConfig:
    footstep: FootstepConfig = dataclasses.field(default_factory=FootstepConfig)
    seed: SeedConfig = dataclasses.field(
        default_factory=lambda: SeedConfig(step=0.05, turn_step=0.05))
    scp: ScpConfig = dataclasses.field(default_factory=ScpConfig)
    dt: float = DEFAULT_DT  # s between trajectory steps: with 5 cm steps, 0.1 m/s
    optimise: bool = True  # False: the seeds are the plan (no SCP)
    motion_retries: int = 10  # footstep searches again, each without a move whose motion failed


class PhaseMotion(NamedTuple):
    """One phase's trajectory, with its seed for comparison."""

    kind: PhaseKind
    stance: tuple[str | None, ...]   # the anchors held (None for the free boom)
    free_boom: int | None
    from_anchor: str | None
    to_anchor: str | None
    seed: Seed
    result: ScpResult | None         # None when SCP was not run

    @property
    def poses(self) -> np.ndarray:
        return self.result.poses if self.result is not None else self.seed.poses

    @property
    def tensions(self) -> np.ndarray | None:
        return self.result.tensions if self.result is not None else None


Progress = Callable[[str], None]


def phase_motions(scn: Scenario, fp: FootstepPlan, config: PipelineConfig | None = None,
                  timing: dict[str, float] | None = None,
                  progress: Progress | None = None) -> tuple[list[PhaseMotion], str]:
    """Seed and optimise every phase of a successful footstep plan, in order.

    Returns the motions and, if some phase has no feasible seed, why (the motions stop there).
    `timing` accumulates seconds under seed_body, scp_body, seed_reach and scp_reach."""
    cfg = config or PipelineConfig()
    timing = timing if timing is not None else {}
    seed_value = cfg.footstep.seed
    motions: list[PhaseMotion] = []
    if fp.goal_pose is None:
        raise ValueError("phase_motions: a footstep plan without its goal pose (no route)")
    ends = [s.pose for s in fp.steps] + [fp.goal_pose]
    found = [s.found_pose if s.found_pose is not None else s.pose for s in fp.steps]
    found_ends = [*found, fp.goal_pose]
    pose = np.asarray(fp.start_pose, dtype=float)
    found_pose = pose
    n_phases = len(fp.stances) + len(fp.steps)

    def clock(stage: str, t0: float) -> None:
        timing[stage] = timing.get(stage, 0.0) + time.perf_counter() - t0

    for k, stance in enumerate(fp.stances):
        reach = None
        if k < len(fp.steps):
            # The reach first: if it fails at the polished transition pose but holds at the
            # pose the search found, the body phase goes there instead.
            step = fp.steps[k]
            t0 = time.perf_counter()
            reach = reach_seed(scn, stance, step.boom, step.to_anchor, ends[k], cfg.seed,
                               seed=seed_value + k)
            if not reach.success and not np.allclose(found[k], ends[k]):
                unpolished = reach_seed(scn, stance, step.boom, step.to_anchor, found[k],
                                        cfg.seed, seed=seed_value + k)
                if unpolished.success:
                    reach, ends[k] = unpolished, found[k]
            # The complete search knows other poses that hold the move and join the same body
            # motions: the gripper's path may clear where it did not.
            for other in (step.alternatives if step.alternatives is not None else [])[1:]:
                if reach.success:
                    break
                again = reach_seed(scn, stance, step.boom, step.to_anchor, other, cfg.seed,
                                   seed=seed_value + k)
                if again.success:
                    reach, ends[k], found[k] = again, np.asarray(other, dtype=float), other
                    found_ends[k] = found[k]
            clock("seed_reach", t0)
        if progress is not None:
            progress(f"phase {len(motions) + 1}/{n_phases}: body movement")
        t0 = time.perf_counter()
        seed = body_seed(scn, stance, pose, ends[k], cfg.seed, seed=seed_value + k,
                         linked_ends=(found_pose, found_ends[k]))
        clock("seed_body", t0)
        if not seed.success:
            return motions, f"body phase {len(motions)} in stance {list(stance)}: {seed.reason}"
        result = None
        if cfg.optimise:
            t0 = time.perf_counter()
            result = optimise_body(scn, stance, seed.poses, cfg.dt, cfg.scp)
            clock("scp_body", t0)
        motion = PhaseMotion("body", tuple(stance), None, None, None, seed, result)
        crossing = _seed_between(scn, motion)
        if crossing:
            return motions, f"body phase {len(motions)} in stance {list(stance)}: {crossing}"
        motions.append(motion)
        if k == len(fp.steps):
            break
        step = fp.steps[k]
        if progress is not None:
            progress(f"phase {len(motions) + 1}/{n_phases}: boom {step.boom} "
                     f"{step.from_anchor} -> {step.to_anchor}")
        three = tuple(None if i == step.boom else a for i, a in enumerate(stance))
        if reach is None:  # seeded above: k < len(fp.steps) here
            raise ValueError(f"phase_motions: reach {k} was not seeded")
        seed = reach
        if not seed.success:
            return motions, (f"reach phase {len(motions)} (boom {step.boom} {step.from_anchor} "
                             f"-> {step.to_anchor}): {seed.reason}")
        result = None
        if cfg.optimise:
            if seed.tips is None:
                raise ValueError(f"phase_motions: reach {k}'s seed has no free tips")
            t0 = time.perf_counter()
            result = optimise_reach(scn, three, step.boom, seed.poses, seed.tips, cfg.dt, cfg.scp)
            clock("scp_reach", t0)
        motion = PhaseMotion("reach", three, step.boom, step.from_anchor, step.to_anchor, seed,
                             result)
        after = tuple(step.to_anchor if i == step.boom else a for i, a in enumerate(stance))
        short = _seed_between(scn, motion) or _handover_shortfall(scn, motion, tuple(stance),
                                                                    after)
        if short:
            return motions, (f"reach phase {len(motions)} (boom {step.boom} "
                             f"{step.from_anchor} -> {step.to_anchor}): {short}")
        motions.append(motion)
        pose = np.asarray(ends[k], dtype=float)
        found_pose = np.asarray(found[k], dtype=float)
    return motions, ""


def _seed_between(scn: Scenario, motion: PhaseMotion) -> str:
    """'' unless the phase keeps its seed (SCP did not improve it: SCP's own steps pass
    `between_steps`) and the seed's motion between its steps fails `between_steps`: a seed
    through a configuration where the booms' lines meet in one point (an OMPL path on
    crevasse-s6) swings the tensions in execution, and slowing it does not help."""
    if motion.result is not None and motion.result.improved:
        return ""
    stance = scn.stance(motion.stance)
    tips = motion.seed.tips
    world = reach_world(scn, tips)  # a free gripper touches rock only near its own anchors
    lp = check_poses(world, stance, motion.seed.poses, tips).allocation.log_probs
    # the straight motion only: a seed whose smooth path fails is eased (planning.easing),
    # and searching another route for it loses good routes (crevasse-8m-s2 went from 26 to
    # 27 regrasps, and its new route's feed-forward overloaded a grasp in simulation)
    failed = between_steps(world, stance, motion.seed.poses, lp, tips, smooth=False)
    return f"its seed fails between steps ({failed})" if failed else ""


def _handover_shortfall(scn: Scenario, reach: PhaseMotion, before: tuple[str | None, ...],
                        after: tuple[str | None, ...]) -> str:
    """'' when the ends of the release and attach ramps (planning.ramps) hold with p_min:
    there the reach's first (last) configuration's grasps hold the body, and the freed boom's
    grasp, unloaded but not yet open (already closed), still counts with its P at zero
    tension, below 1 where its pull angle is large (the lateral limit against its deviation:
    rockfall-3 had a ramp end at P 0.9499)."""
    robot, g = scn.robot, scn.gravity_vector
    j = reach.free_boom
    three = scn.stance(reach.stance)
    tips = reach.seed.tips  # SCP keeps the free tip's path
    if tips is None:
        raise ValueError("a reach phase's seed without its free tips")
    for name, ids, n in (("release", before, 0), ("attach", after, -1)):
        pose = reach.poses[n]
        f = allocate(robot, g, pose, three, tips[n]).tensions[0]
        four = scn.stance(ids)
        psi = statics_problem(robot, g, pose, four).pull_angles[0]
        lp = four.log_prob(np.where(four.attached, np.nan_to_num(f), 0.0), np.nan_to_num(psi))
        p = float(np.exp(lp[four.attached].sum()))
        if not p >= robot.p_min:
            return (f"the {name} ramp ends at P = {p:.4f} below p_min {robot.p_min} (boom {j}'s "
                    f"grasp unloaded at P = {math.exp(lp[j]):.4f})")
    return ""


def plan_climb(scn: Scenario, planner: str = "rbp", config: PipelineConfig | None = None,
               progress: Progress | None = None,
               footstep_progress: Callable[..., None] | None = None,
               footsteps_done: Callable[[FootstepPlan], None] | None = None,
               partial: bool = False) -> Plan:
    """The whole plan (`reachbot-plan/2`) for a scenario.

    `footsteps_done` is called with each footstep plan (the search's, then any retry's): a
    caller can picture where a failed search went. `partial`: when the search finds no route
    (none exists, or its budget ran out), the plan climbs to the expanded stance nearest the
    goal (`partial_climb`); it still says `success: false`."""
    if planner not in PLANNERS:
        raise ValueError(f"planner must be one of {PLANNERS}, got {planner!r}")
    cfg = config or PipelineConfig()
    t_start = time.perf_counter()
    timing: dict[str, float] = {}
    if planner == "naive":
        fp = plan_naive(scn, cfg.footstep)
    else:
        fp = plan_footsteps(scn, cfg.footstep, progress=footstep_progress, partial=partial)
    timing["footstep"] = time.perf_counter() - t_start
    if footsteps_done is not None:
        footsteps_done(fp)
    if planner == "rbp" and fp.partial is not None:
        plan = partial_climb(scn, fp, cfg, timing, progress, footstep_progress,
                             footsteps_done)
        timing["total"] = time.perf_counter() - t_start
        return plan.replace(timing=plan.timing | timing)
    if planner == "naive" or not fp.success:
        timing["total"] = time.perf_counter() - t_start
        plan = build_plan(scn, fp, planner, timing)
        if partial and planner == "rbp" and not fp.success:  # it wrote no climb, silently
            plan = plan.failed(f"{fp.reason}; no partial climb: the search expanded no stance "
                               "to climb to")
        return plan
    failure, done, built = _fly(scn, fp, cfg, timing, planner, progress)
    memo = fp.memo if fp.memo is not None else FootstepMemo(fp.transitions or {})
    excluded: list[Move] = []
    last_search = ""  # how the last search again ended, when it found no route
    for _ in range(cfg.motion_retries):
        if not failure:
            break
        # A transition holds at its pose, but the motion through it may not (a reach arc whose
        # intermediate cantilevers no tensions balance): search again without that move.
        move = failed_move(fp, done, excluded)
        excluded.append(move)
        if progress is not None:
            progress(f"{failure[:100]}...; searching footsteps again without boom {move[1]} "
                     f"-> {move[2]} from {list(move[0])}")
        t0 = time.perf_counter()
        retry = plan_footsteps(scn, cfg.footstep, progress=footstep_progress, exclude=excluded,
                               memo=memo)
        timing["footstep"] += time.perf_counter() - t0
        if footsteps_done is not None:
            footsteps_done(retry)
        if not retry.success:
            last_search = retry.reason
            break
        fp = retry
        for stage in ("seed_body", "scp_body", "seed_reach", "scp_reach"):
            timing.pop(stage, None)  # the plan's stages are those of the footsteps it keeps
        failure, done, built = _fly(scn, fp, cfg, timing, planner, progress)
    if failure or built is None:
        timing["total"] = time.perf_counter() - t_start
        reason = f"motion planning failed: {failure}" + retries_made(
            excluded, last_search, cfg.motion_retries)
        return build_plan(scn, fp, planner, timing).failed(reason)
    timing["total"] = time.perf_counter() - t_start
    return built.replace(timing=built.timing | timing)


def _fly(scn: Scenario, fp: FootstepPlan, cfg: PipelineConfig, timing: dict[str, float],
         planner: str, progress: Progress | None
         ) -> tuple[str, int, Plan | None]:
    """Why the motions of a route (`phase_motions`) failed ('' when they did not), how many
    phases came before the failure, and the plan they make (None when they failed).
    Motions that succeed are built into the plan's phases (eased, ramps added) and their
    smooth paths and straight motion tested as `rbp check` does: a phase whose path fails (a
    kept seed whose path rounds a corner across a limit, which no easing helps: crevasse-78)
    fails as a motion does, and the route is searched again."""
    motions, failure = phase_motions(scn, fp, cfg, timing, progress)
    if failure:
        return failure, len(motions), None
    built = build_motion_plan(scn, fp, motions, planner, dict(timing), cfg.dt,
                              step_limits(cfg.seed.step, cfg.seed.turn_step))
    found: list[tuple[int, str]] = []
    smooth_path_problems(built, scn, lambda k: scn.stance(tuple(built.phases[k].stance)),
                         lambda k, n, text: found.append((k, text)))
    # and the straight motion `rbp rig-run` commands, as rule `between` verifies it (SCP tested
    # its samples, not the rock its boom ends and body corners cut between them)
    between_problems(built.phases, scn, set(), lambda k, n, text: found.append((k, text)))
    if not found:
        return "", len(motions), built
    k, text = min(found)
    return f"{built.phases[k].kind} phase {k}: {text[:160]}", k, None


def partial_climb(scn: Scenario, fp: FootstepPlan, config: PipelineConfig | None = None,
                  timing: dict[str, float] | None = None,
                  progress: Progress | None = None,
                  footstep_progress: Callable[..., None] | None = None,
                  footsteps_done: Callable[[FootstepPlan], None] | None = None) -> Plan:
    """The plan of a failed search's partial route (`FootstepPlan.partial`: to the expanded
    stance nearest the goal), flown like a route: a seed and SCP per phase, ramps. Where a
    phase's motion fails, the footsteps are searched again without that move (as a route's are,
    `motion_retries` times), each search's partial route flown in turn; the climb kept is the
    one whose last stance is nearest the goal (the first of equals), cut to the last stance its
    motions reach (on a body phase) when they fail on the way, as the reason says. Where even
    the first body phase fails, the plan is the failed search's, without a climb. The plan says
    `success: false`, with `partial`; `footsteps_done` is called with each search again and at
    last with the search of the climb kept, its partial route the climb's."""
    from planning.plan_model import Partial
    from planning.search_cost import centroid_distance

    cfg = config or PipelineConfig()
    timing = timing if timing is not None else {}
    route = fp.partial
    if route is None:
        raise ValueError("partial_climb: the footstep plan has no partial route")
    memo = fp.memo if fp.memo is not None else FootstepMemo(fp.transitions or {})
    excluded: list[Move] = []
    search = fp
    kept: tuple | None = None  # (distance, motions, flown route, failure, search)
    first_failure = ""
    for attempt in range(cfg.motion_retries + 1):
        motions, failure = phase_motions(scn, route, cfg, timing, progress)
        first_failure = first_failure or failure
        if failure and motions and motions[-1].kind == "reach":
            motions = motions[:-1]  # the climb ends on four booms
        if motions:
            reached = len(motions) // 2  # body, reach, body, ...: the last body phase's stance
            flown = route._replace(stances=route.stances[:reached + 1],
                                   steps=route.steps[:reached], goal_pose=motions[-1].poses[-1],
                                   goal_distance=centroid_distance(scn, route.stances[reached]))
            if kept is None or flown.goal_distance < kept[0] - 1e-12:
                kept = (flown.goal_distance, motions, flown, failure, search)
        if not failure or not route.steps or attempt == cfg.motion_retries:
            break
        excluded.append(failed_move(route, len(motions), excluded))
        t0 = time.perf_counter()
        search = plan_footsteps(scn, cfg.footstep, progress=footstep_progress, exclude=excluded,
                                memo=memo, partial=True)
        timing["footstep"] = timing.get("footstep", 0.0) + time.perf_counter() - t0
        if footsteps_done is not None:
            footsteps_done(search)
        if search.success or search.partial is None:
            break  # (a route found without the moves excluded: rbp plan without --partial)
        route = search.partial
    if kept is None:
        return build_plan(scn, fp, "rbp", timing).failed(
            f"{fp.reason}; no partial climb: {first_failure}")
    distance, motions, flown, failure, search = kept
    if footsteps_done is not None:  # the search picture draws the climb kept
        footsteps_done(search._replace(partial=flown))
    plan = build_motion_plan(scn, flown, motions, "rbp", timing, cfg.dt,
                             step_limits(cfg.seed.step, cfg.seed.turn_step))
    stance = tuple(flown.stances[-1])
    start = centroid_distance(scn, tuple(scn.start_stance))
    n = len(flown.steps)
    reason = (f"{fp.reason}; partial climb: {n} regrasp{'' if n == 1 else 's'} to stance "
              f"{list(stance)}, {distance:.2f} m from the goal (the start is {start:.2f} m)")
    if excluded:
        reason += (f"; {len(excluded)} search{'' if len(excluded) == 1 else 'es'} again, each "
                   f"without a move whose motion failed (first: {first_failure})")
    if failure:
        reason += f"; the climb stops where a motion failed: {failure}"
    return plan.replace(success=False, reason=reason,
                        partial=Partial(reached_stance=stance, goal_distance_m=distance,
                                        start_distance_m=start))


def retries_made(excluded: list[Move], last_search: str,
                 allowed: int) -> str:
    """What a failed plan's reason adds about the footstep searches made again after a motion
    failed: the moves each was made without (`failed_move`), in order, and how they ended
    (the last found no route, or the retries ran out); '' when none was made."""
    if not excluded:
        return (f"; no footstep search again (motion_retries {allowed})" if allowed == 0
                else "")
    moves = [f"boom {boom} -> {anchor} from {list(stance)}" for stance, boom, anchor in excluded]
    n = len(excluded)
    text = (f"; searched footsteps again {n} time{'' if n == 1 else 's'}: without {moves[0]}"
            + "".join(f", then also without {move}" for move in moves[1:]))
    if last_search:
        return f"{text}; the last found no route ({last_search})"
    return f"{text}; motion_retries {allowed} used up (--config sets motion_retries)"


def failed_move(fp: FootstepPlan, done: int, excluded: Collection[Move] = ()) -> Move:
    """The move (stance, boom, anchor) to exclude when `phase_motions` stopped after `done`
    phases: a failed reach is its own move's; a failed body phase leads to the next move (or,
    the last one, from the previous), unless a move out of the same stance was excluded
    already: then the body's way out was not what failed but its way in (its start pose, where
    the booms nearly meet: generated rockfall 7029 failed its ten retries on one stance's
    exits), and the move into the stance is excluded."""
    k = min(done // 2, len(fp.steps) - 1)
    stance = tuple(fp.stances[k])
    body = done % 2 == 0 and done // 2 < len(fp.steps)
    if body and k > 0 and any(move[0] == stance for move in excluded):
        before = fp.steps[k - 1]
        return tuple(fp.stances[k - 1]), before.boom, before.to_anchor
    step = fp.steps[k]
    return stance, step.boom, step.to_anchor


ROOM = 1e-4  # a phase whose seed's mean P is within this of 1 leaves SCP nothing to gain


def motion_summary(plan: Plan) -> list[dict[str, Any]]:
    """Per phase: the seed's and the optimum's minimum and mean probability and effort.

    SCP keeps a phase's first and last pose fixed (the transition poses), so it cannot raise a
    minimum that sits there: `seed_min_at_end` says whether the seed's does, and `room` whether
    the seed's mean P leaves anything to gain (below 1 - ROOM)."""
    rows = []
    for k, phase in enumerate(plan.phases):
        motion = phase.motion
        if motion is None:
            continue
        p = np.array([s.p_success for s in phase.steps])
        p_seed = np.array(motion.seed_p_success)
        poses = np.array([s.pose for s in phase.steps])
        at = poses[int(np.argmin(p_seed))]
        at_end = bool(np.allclose(at, poses[0], atol=1e-9) or np.allclose(at, poses[-1],
                                                                          atol=1e-9))
        rows.append({"phase": k, "kind": phase.kind, "steps": len(p),
                     "seed_min": float(p_seed.min()), "min": float(p.min()),
                     "seed_mean": float(p_seed.mean()), "mean": float(p.mean()),
                     "seed_min_at_end": at_end, "room": bool(p_seed.mean() < 1.0 - ROOM),
                     "seed_effort": float(np.mean(motion.seed_effort)),
                     "effort": float(np.mean(motion.effort)),
                     "improved": bool(motion.improved), "status": motion.scp_status})
    return rows
