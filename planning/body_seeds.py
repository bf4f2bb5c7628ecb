"""The body phase's seed (paper section IV-B): a 4-stance, the body moving from one transition
pose to the next as a discretised sequence of poses, each statically feasible by `check_poses`.

Three methods, cheapest first: the straight line (one vectorised check); local sampling of
smooth detours around it (a few vectorised rounds of growing spread, as the paper samples
locally around the straight line); OMPL's RRTConnect in SE(2) when the neighbourhood of the line
is blocked, followed by a vectorised shortcut and re-check. What both phase kinds share, and
the guarantees every seed keeps, are in `planning.seed_common` and `planning.seeds`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from planning.seed_common import (
    Seed,
    SeedConfig,
    check_configurations,
    describe_infeasible,
    failed_seed,
    found_seed,
    pieces,
    subdivide,
)
from rb_drake.feasibility import check_poses
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

MAX_DETOUR_POSES = 20_000  # a 100 m detour at the least step, 5 mm
CHECK_BATCH = 50_000  # poses checked in one vectorised call (tens of MB)


def _local(scn: Scenario, stance: Stance, line: np.ndarray, cfg: SeedConfig,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Local sampling around the straight line `line` (N, 3): detours
    line + sum_m c_m sin(m pi s) (s in [0, 1]; the ends stay put), c_m ~ N(0, spread / m) per
    pose coordinate (phi scaled by turn_step / step), the spread doubling each round; every
    candidate subdivided and checked in one vectorised call per round. Returns the feasible
    candidate with the fewest poses (the shortest) and its robustness, or None."""
    s = np.linspace(0.0, 1.0, len(line))
    modes = np.arange(1, cfg.local_modes + 1)
    shapes = np.sin(np.pi * modes[:, None] * s[None, :])          # (M, N)
    shapes[:, [0, -1]] = 0.0  # exactly: sin(m pi) is not
    scale = np.array([1.0, 1.0, cfg.turn_step / cfg.step])
    for r in range(cfg.local_rounds):
        spread = cfg.local_spread * 2.0**r
        c = rng.normal(0.0, 1.0, (cfg.local_samples, len(modes), 3)) * (
            spread / modes[None, :, None]) * scale
        detours = [line + shapes.T @ c[k] for k in range(cfg.local_samples)]
        # a detour of more poses than MAX_DETOUR_POSES is not tried: wide spreads over many
        # rounds and modes at a fine step would otherwise ask gigabytes
        sizes = [int(pieces(w, cfg.step, cfg.turn_step).sum()) + 1 for w in detours]
        found: list[tuple[int, np.ndarray, np.ndarray]] = []
        batch: list[np.ndarray] = []
        for k, w in enumerate(detours):
            if sizes[k] <= MAX_DETOUR_POSES:
                batch.append(subdivide(w, cfg.step, cfg.turn_step))
            if batch and (k == len(detours) - 1 or sum(map(len, batch)) >= CHECK_BATCH):
                found += _feasible_paths(scn, stance, batch)
                batch = []
        if found:
            _, path, robustness = min(found, key=lambda f: f[0])
            return path, robustness
    return None


def _feasible_paths(scn: Scenario, stance: Stance,
                    paths: list[np.ndarray]) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The paths all of whose poses are feasible, each with its length and robustness."""
    counts = [len(p) for p in paths]
    check = check_configurations(scn, stance, np.vstack(paths))
    cuts = np.cumsum(counts)[:-1]
    robust = np.split(check.allocation.robustness, cuts)
    return [(counts[k], paths[k], robust[k])
            for k, f in enumerate(np.split(check.feasible, cuts)) if f.all()]


def body_seed(scn: Scenario, stance_ids: tuple[str, ...], start_pose: np.ndarray,
              goal_pose: np.ndarray, config: SeedConfig | None = None, seed: int = 0,
              linked_ends: tuple[np.ndarray, np.ndarray] | None = None) -> Seed:
    """A feasible discretised body path from `start_pose` to `goal_pose` in a 4-stance.

    `linked_ends` are poses joined to the start and to the goal by feasible straight segments
    (the transition poses as the footstep search found them, before `polish_transition` moved
    them): when nothing joins start and goal directly, a path through them is tried."""
    cfg = config or SeedConfig()
    found = _body_seed(scn, stance_ids, start_pose, goal_pose, cfg, seed)
    if found.success or linked_ends is None:
        return found
    start, goal = (np.asarray(p, dtype=float).reshape(3) for p in (start_pose, goal_pose))
    a, b = (np.asarray(p, dtype=float).reshape(3) for p in linked_ends)
    if np.allclose(a, start) and np.allclose(b, goal):
        return found
    inner = _body_seed(scn, stance_ids, a, b, cfg, seed)
    if not inner.success:
        return found
    configs = np.vstack([subdivide(np.vstack([start, a]), cfg.step, cfg.turn_step)[:-1],
                         inner.poses,
                         subdivide(np.vstack([b, goal]), cfg.step, cfg.turn_step)[1:]])
    check = check_configurations(scn, scn.stance(stance_ids), configs)
    if not check.feasible.all():
        return found
    return found_seed(f"{inner.method} via search poses", configs, check.allocation.robustness)


def _body_seed(scn: Scenario, stance_ids: tuple[str, ...], start_pose: np.ndarray,
               goal_pose: np.ndarray, cfg: SeedConfig, seed: int) -> Seed:
    stance = scn.stance(stance_ids)
    start = np.asarray(start_pose, dtype=float).reshape(3)
    goal = np.asarray(goal_pose, dtype=float).reshape(3)
    straight = subdivide(np.vstack([start, goal]), cfg.step, cfg.turn_step)
    check = check_configurations(scn, stance, straight)
    for k, name in ((0, "start"), (len(straight) - 1, "goal")):
        if not check.feasible[k]:
            return failed_seed(describe_infeasible(check, straight, f"{name} pose", k))
    if check.feasible.all():
        return found_seed("straight", straight, check.allocation.robustness)
    reasons = [describe_infeasible(check, straight, "straight line")]
    rng = np.random.default_rng(seed)
    found = _local(scn, stance, straight, cfg, rng)
    if found is not None:
        return found_seed("local", *found)
    reasons.append(f"no feasible detour among {cfg.local_rounds * cfg.local_samples} local "
                   "samples")
    waypoints, why = _ompl_waypoints(scn, stance, start, goal, cfg,
                                     int(rng.integers(1, 2**31 - 1)))
    if waypoints is not None:
        waypoints = _shortcut(scn, stance, waypoints, cfg)
        configs = subdivide(waypoints, cfg.step, cfg.turn_step)
        check = check_configurations(scn, stance, configs)
        if check.feasible.all():
            return found_seed("ompl", configs, check.allocation.robustness)
        why = describe_infeasible(check, configs, "OMPL path")
    reasons.append(why)
    return failed_seed("; ".join(reasons))


class _ReachFilter:
    """Scalar boom-length and shoulder-angle test of one pose: rejects most of OMPL's samples in
    microseconds, before the full (vectorised, about 2 ms) check."""

    def __init__(self, scn: Scenario, stance: Stance):
        robot = scn.robot
        self.booms = [(float(robot.shoulder_array[i, 0]), float(robot.shoulder_array[i, 1]),
                       float(robot.shoulder_directions[i]), float(stance.positions[i, 0]),
                       float(stance.positions[i, 1]))
                      for i in np.flatnonzero(stance.attached)]
        self.lo, self.hi = (float(v) for v in robot.boom_length)
        self.range = float(robot.shoulder_range) + 1e-12

    def __call__(self, x: float, y: float, phi: float) -> bool:
        c, s = math.cos(phi), math.sin(phi)
        for sx, sy, alpha, ax, ay in self.booms:
            dx, dy = ax - (x + c * sx - s * sy), ay - (y + s * sx + c * sy)
            if not self.lo <= math.hypot(dx, dy) <= self.hi:
                return False
            theta = (math.atan2(dy, dx) - phi - alpha + math.pi) % (2 * math.pi) - math.pi
            if abs(theta) > self.range:
                return False
        return True


class _VectorisedMotion(ob.MotionValidator):
    """Checks a motion's poses, at the seed's resolution, in one vectorised call: the cost of a
    Python checker is per call, not per pose. Holds no reference to OMPL objects."""

    def __init__(self, si: ob.SpaceInformation, feasible: Callable[[np.ndarray], np.ndarray],
                 reach: _ReachFilter, step: float, turn_step: float):
        super().__init__(si)
        self.feasible, self.reach = feasible, reach
        self.step, self.turn_step = step, turn_step

    def checkMotion(self, s1, s2) -> bool:  # noqa: N802 (OMPL's name)
        if not self.reach(s2.getX(), s2.getY(), s2.getYaw()):
            return False
        a = np.array([s1.getX(), s1.getY(), s1.getYaw()])
        b = np.array([s2.getX(), s2.getY(), s2.getYaw()])
        b[2] = a[2] + (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi  # SO(2): the short way
        return bool(self.feasible(subdivide(np.vstack([a, b]), self.step, self.turn_step)[1:])
                    .all())


def _ompl_waypoints(scn: Scenario, stance: Stance, start: np.ndarray, goal: np.ndarray,
                    cfg: SeedConfig, seed: int) -> tuple[np.ndarray | None, str]:
    """RRTConnect in SE(2) with the full feasibility check, seeded, OMPL's Info and Debug
    messages silenced: its path's states (phi unwrapped from the start's), or None and why."""
    level = ou.getLogLevel()
    try:
        ou.setLogLevel(ou.LOG_NONE)  # reseeding after the first RNG logs an error; it still works
        ou.RNG.setSeed(seed)
        ou.setLogLevel(ou.LOG_WARN if level.value < ou.LOG_WARN.value else level)
        return _rrt_connect(scn, stance, start, goal, cfg)
    finally:
        ou.setLogLevel(level)


def _rrt_connect(scn: Scenario, stance: Stance, start: np.ndarray, goal: np.ndarray,
                 cfg: SeedConfig) -> tuple[np.ndarray | None, str]:
    checked = [0]  # poses given the full check: RRTConnect's budget, the same on any machine

    def feasible(poses: np.ndarray) -> np.ndarray:
        checked[0] += len(poses)
        return check_poses(scn, stance, poses).feasible

    reach = _ReachFilter(scn, stance)

    def valid(state) -> bool:
        x, y, phi = state.getX(), state.getY(), state.getYaw()
        return reach(x, y, phi) and bool(feasible(np.array([[x, y, phi]]))[0])

    space = ob.SE2StateSpace()
    bounds = ob.RealVectorBounds(2)
    lo = np.minimum(start[:2], goal[:2]) - cfg.ompl_margin
    hi = np.maximum(start[:2], goal[:2]) + cfg.ompl_margin
    for i in range(2):
        bounds.setLow(i, float(lo[i]))
        bounds.setHigh(i, float(hi[i]))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(valid)
    si = ss.getSpaceInformation()
    si.setMotionValidator(_VectorisedMotion(si, feasible, reach, cfg.step, cfg.turn_step))
    planner = og.RRTConnect(si)
    planner.setRange(cfg.ompl_range)
    ss.setPlanner(planner)
    states = []
    for pose in (start, goal):
        st = space.allocState()
        st.setX(float(pose[0]))
        st.setY(float(pose[1]))
        # within SE(2)'s bounds, [-pi, pi]: a heading past them (a body turned over, 3.18 rad
        # on rockfall-7029 at 8 m) was refused as an invalid start, on the terminal
        st.setYaw(math.remainder(float(pose[2]), 2.0 * math.pi))
        states.append(st)
    ss.setStartAndGoalStates(*states)
    # Stopped on the work done, not on the clock, so that a seed gives the same path on a busy
    # machine as on an idle one (same seed, same plan); `ompl_time` only as a safety net.
    done = ob.PlannerTerminationCondition(lambda: checked[0] >= cfg.ompl_checks)
    if cfg.ompl_time is not None:
        done = ob.plannerOrTerminationCondition(
            done, ob.timedPlannerTerminationCondition(cfg.ompl_time))
    status = ss.solve(done)
    if not (bool(status) and ss.haveExactSolutionPath()):
        return None, (f"OMPL RRTConnect found no path within {cfg.ompl_checks} checked poses"
                      + ("" if cfg.ompl_time is None else f" or {cfg.ompl_time} s"))
    path = np.array([[s.getX(), s.getY(), s.getYaw()] for s in ss.getSolutionPath().getStates()])
    path[:, 2] = start[2] + np.unwrap(path[:, 2] - start[2])
    # the first state holds the start's heading wrapped to [-pi, pi]: whole turns back
    path[:, 2] += 2.0 * math.pi * round((start[2] - path[0, 2]) / (2.0 * math.pi))
    path[0] = start
    if abs(path[-1, 2] - goal[2]) > 1e-6:
        return None, "OMPL path ends a full turn away from the goal's orientation"
    path[-1] = goal
    return path, ""


def _shortcut(scn: Scenario, stance: Stance, waypoints: np.ndarray,
              cfg: SeedConfig) -> np.ndarray:
    """Greedy, deterministic shortcutting: from each kept waypoint jump to the farthest one that
    a feasible straight piece reaches (all candidates checked in one vectorised call)."""
    kept = [0]
    last = len(waypoints) - 1
    while kept[-1] < last:
        i = kept[-1]
        pieces = [subdivide(waypoints[[i, j]], cfg.step, cfg.turn_step)[1:]
                  for j in range(i + 1, last + 1)]
        feasible = check_poses(scn, stance, np.vstack(pieces)).feasible
        ok = [f.all() for f in np.split(feasible, np.cumsum([len(p) for p in pieces])[:-1])]
        reach = [k for k, good in enumerate(ok) if good]
        kept.append(i + 1 + (reach[-1] if reach else 0))
    return waypoints[kept]
