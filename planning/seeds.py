"""Seed trajectories for the two continuous phases of a plan (paper sections IV-B and IV-C).

Body phase (a 4-stance; the body moves from one transition pose to the next): a discretised
sequence of poses, each statically feasible by `check_poses` (kinematic limits, collisions,
statics, P >= p_min). Three methods, cheapest first: the straight line (one vectorised check);
local sampling of smooth detours around it (a few vectorised rounds of growing spread, as the
paper samples locally around the straight line); OMPL's RRTConnect in SE(2) when the
neighbourhood of the line is blocked, followed by a vectorised shortcut and re-check.

Reach phase (a 3-stance; the free gripper moves from its old anchor to the new one): the tip
follows a collision-free parabolic arc (the lowest of a few heights that clears the rock). The
body holds the transition pose when that is feasible with the cantilevered limb at every tip
position; otherwise it sways: body offsets sampled around the transition pose are checked at
every tip position at once, and a shortest-path search picks the least motion that keeps every
configuration feasible and starts and ends at the transition pose.

Every returned seed has been checked configuration by configuration, starts and ends exactly at
the requested configurations and moves at most `step` (m; the tip too) and `turn_step` (rad)
between successive configurations. Poses are not wrapped: phi runs continuously from the start's
value to the goal's. Randomness comes from `seed` alone (numpy's generator and OMPL's RNG).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from typing import NamedTuple

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from rb_drake import geometry
from rb_drake.collision import ANCHOR_CLEARANCE
from rb_drake.feasibility import REASON_TEXT, PoseCheck, Reason, check_poses
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

ARC_OFFSET = 1e-3  # m; the arc's ends are tested for collision this far off the rock they grip
SWAY_REPAIRS = 5   # reach phase: searches for a sway, each after striking out a failed piece


@dataclasses.dataclass(frozen=True)
class SeedConfig:
    step: float = 0.02          # m between successive poses (and free tip positions)
    turn_step: float = 0.03     # rad between successive poses
    # local sampling: body detours (body phase) or body offsets (reach phase)
    local_rounds: int = 4       # rounds (spreads), the spread doubling each round
    local_samples: int = 24     # candidates per round
    local_spread: float = 0.05  # m, first round's std (a detour's first mode); phi's: x turn/step
    local_modes: int = 3        # half-sine modes of a body detour
    ompl_time: float = 0.5      # s, RRTConnect's budget
    ompl_range: float = 0.3     # RRTConnect's extension length (SE(2) distance)
    ompl_margin: float = 0.5    # m, the SE(2) bounds: start and goal's box grown by this
    arc_heights: tuple[float, ...] = (0.1, 0.2, 0.35, 0.5)  # tip arc heights / chord, tried
    arc_min_height: float = 0.05  # m


class Seed(NamedTuple):
    success: bool
    method: str               # body: "straight" | "local" | "ompl"; reach: "hold" | "local"
    poses: np.ndarray         # (N, 3); in a reach phase the pose at each tip position
    tips: np.ndarray | None   # (N, 2) free tip positions (reach phases), else None
    log_probs: np.ndarray     # (N,) robustness r = log P of each configuration
    reason: str               # why not, when failed


def _failed(reason: str, reach: bool = False) -> Seed:
    return Seed(False, "", np.zeros((0, 3)), np.zeros((0, 2)) if reach else None, np.zeros(0),
                reason)


def _pieces(waypoints: np.ndarray, step: float, turn_step: float) -> np.ndarray:
    """How many equal parts each straight piece between waypoints needs (see `subdivide`)."""
    d = np.diff(waypoints, axis=0)
    ratio = np.maximum(np.linalg.norm(d[:, :2], axis=1) / step, np.abs(d[:, 2]) / turn_step)
    if waypoints.shape[1] > 3:
        ratio = np.maximum(ratio, np.linalg.norm(d[:, 3:5], axis=1) / step)
    return np.maximum(1, np.ceil(ratio)).astype(int)


def subdivide(waypoints: np.ndarray, step: float, turn_step: float) -> np.ndarray:
    """Waypoints (W, 3) or (W, 5) (pose, then free tip) joined by straight pieces, each cut into
    equal parts that move the position and the tip at most `step` and phi at most `turn_step`.
    The waypoints themselves are kept exactly."""
    w = np.asarray(waypoints, dtype=float)
    parts = _pieces(w, step, turn_step)
    seg = np.repeat(np.arange(len(parts)), parts)
    first = np.concatenate([[0], np.cumsum(parts)[:-1]])
    t = (np.arange(len(seg)) - first[seg]) / parts[seg]
    return np.vstack([w[seg] + t[:, None] * np.diff(w, axis=0)[seg], w[-1:]])


def _check(scn: Scenario, stance: Stance, configs: np.ndarray) -> PoseCheck:
    """check_poses on configurations (N, 3) or (N, 5) (pose, free tip)."""
    tips = configs[:, 3:5] if configs.shape[1] > 3 else None
    return check_poses(scn, stance, configs[:, :3], tips)


def _describe(check: PoseCheck, configs: np.ndarray, what: str, k: int | None = None) -> str:
    """Configuration k (default: the first infeasible one) and check_poses' reason for it."""
    where = ""
    if k is None:
        k = int(np.argmin(check.feasible))
        where = f" at configuration {k} of {len(configs)}"
    x, y, phi = configs[k, :3]
    code = Reason(int(check.reason[k]))
    boom = int(check.boom[k])
    tip = f", tip ({configs[k, 3]:.3f}, {configs[k, 4]:.3f})" if configs.shape[1] > 3 else ""
    on = f" (boom {boom})" if boom >= 0 else ""
    return (f"{what} infeasible{where}: pose ({x:.3f}, {y:.3f}, {phi:.3f}){tip}: "
            f"{REASON_TEXT[code]}{on}")


def _success(method: str, configs: np.ndarray, log_probs: np.ndarray) -> Seed:
    tips = configs[:, 3:5].copy() if configs.shape[1] > 3 else None
    return Seed(True, method, configs[:, :3].copy(), tips, np.array(log_probs, dtype=float), "")


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
        paths = [subdivide(line + shapes.T @ c[k], cfg.step, cfg.turn_step)
                 for k in range(cfg.local_samples)]
        counts = [len(p) for p in paths]
        check = _check(scn, stance, np.vstack(paths))
        cuts = np.cumsum(counts)[:-1]
        ok = [bool(f.all()) for f in np.split(check.feasible, cuts)]
        if any(ok):
            best = min((counts[k], k) for k in range(len(ok)) if ok[k])[1]
            return paths[best], np.split(check.allocation.robustness, cuts)[best]
    return None


# ---------------------------------------------------------------------------------------------
# Body phase


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
    check = _check(scn, scn.stance(stance_ids), configs)
    if not check.feasible.all():
        return found
    return _success(f"{inner.method} via search poses", configs, check.allocation.robustness)


def _body_seed(scn: Scenario, stance_ids: tuple[str, ...], start_pose: np.ndarray,
               goal_pose: np.ndarray, cfg: SeedConfig, seed: int) -> Seed:
    stance = scn.stance(stance_ids)
    start = np.asarray(start_pose, dtype=float).reshape(3)
    goal = np.asarray(goal_pose, dtype=float).reshape(3)
    straight = subdivide(np.vstack([start, goal]), cfg.step, cfg.turn_step)
    check = _check(scn, stance, straight)
    for k, name in ((0, "start"), (len(straight) - 1, "goal")):
        if not check.feasible[k]:
            return _failed(_describe(check, straight, f"{name} pose", k))
    if check.feasible.all():
        return _success("straight", straight, check.allocation.robustness)
    reasons = [_describe(check, straight, "straight line")]
    rng = np.random.default_rng(seed)
    found = _local(scn, stance, straight, cfg, rng)
    if found is not None:
        return _success("local", *found)
    reasons.append(f"no feasible detour among {cfg.local_rounds * cfg.local_samples} local "
                   "samples")
    waypoints, why = _ompl_waypoints(scn, stance, start, goal, cfg,
                                     int(rng.integers(1, 2**31 - 1)))
    if waypoints is not None:
        waypoints = _shortcut(scn, stance, waypoints, cfg)
        configs = subdivide(waypoints, cfg.step, cfg.turn_step)
        check = _check(scn, stance, configs)
        if check.feasible.all():
            return _success("ompl", configs, check.allocation.robustness)
        why = _describe(check, configs, "OMPL path")
    reasons.append(why)
    return _failed("; ".join(reasons))


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
    def feasible(poses: np.ndarray) -> np.ndarray:
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
        st.setYaw(float(pose[2]))
        states.append(st)
    ss.setStartAndGoalStates(*states)
    status = ss.solve(cfg.ompl_time)
    if not (bool(status) and ss.haveExactSolutionPath()):
        return None, f"OMPL RRTConnect found no path in {cfg.ompl_time} s"
    path = np.array([[s.getX(), s.getY(), s.getYaw()] for s in ss.getSolutionPath().getStates()])
    path[:, 2] = start[2] + np.unwrap(path[:, 2] - start[2])
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


# ---------------------------------------------------------------------------------------------
# Reach phase


def tip_arc(start: np.ndarray, end: np.ndarray, normal_start: np.ndarray,
            normal_end: np.ndarray, height: float, n: int) -> np.ndarray:
    """n points (n >= 2), evenly spaced by arc length, on the parabola
    p(s) = (1 - s) start + s end + 4 height s (1 - s) m, which bulges by `height` (m) at its middle
    along m, the mean of the two anchors' outward normals (the chord's left normal when they
    cancel), so that it leaves the rock at `start` and comes back to it at `end`."""
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    m = np.asarray(normal_start, dtype=float) + np.asarray(normal_end, dtype=float)
    if np.linalg.norm(m) < 0.1:
        chord = b - a
        m = np.array([-chord[1], chord[0]])
    m = m / max(np.linalg.norm(m), 1e-12)
    s = np.linspace(0.0, 1.0, 513)[:, None]
    dense = (1 - s) * a + s * b + 4.0 * height * s * (1 - s) * m
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    at = np.linspace(0.0, length[-1], max(int(n), 2))
    out = np.column_stack([np.interp(at, length, dense[:, 0]), np.interp(at, length, dense[:, 1])])
    out[0], out[-1] = a, b
    return out


def _arc_length(start, end, normal_start, normal_end, height) -> float:
    return float(np.sum(np.linalg.norm(np.diff(
        tip_arc(start, end, normal_start, normal_end, height, 257), axis=0), axis=1)))


def _arc_is_clear(scn: Scenario, tips: np.ndarray, normal_start: np.ndarray,
                  normal_end: np.ndarray) -> bool:
    """Whether the polyline through `tips` stays off the rock between its ends, which grip it:
    as for a boom (`rb_drake.collision`), the gripper's last ANCHOR_CLEARANCE of path at either
    end may touch the rock it grasps, and the cut ends are tested ARC_OFFSET off it along the
    anchors' normals."""
    pts = _trim_path(_trim_path(np.asarray(tips, dtype=float), ANCHOR_CLEARANCE)[::-1],
                     ANCHOR_CLEARANCE)[::-1]
    if len(pts) < 2:
        return True
    pts[0] += ARC_OFFSET * np.asarray(normal_start, dtype=float)
    pts[-1] += ARC_OFFSET * np.asarray(normal_end, dtype=float)
    return not bool(scn.rock.segments_hit(pts[:-1], pts[1:]).any())


def _trim_path(pts: np.ndarray, length: float) -> np.ndarray:
    """The polyline `pts` without its first `length` of arc length (a copy)."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    k = int(np.searchsorted(cum, length, side="right"))  # first point beyond `length`
    if k >= len(pts):
        return pts[-1:].copy()
    t = (length - cum[k - 1]) / max(seg[k - 1], 1e-12)
    start = pts[k - 1] + t * (pts[k] - pts[k - 1])
    return np.vstack([start, pts[k:]])


def _clear_arcs(scn: Scenario, start: np.ndarray, end: np.ndarray, normal_start: np.ndarray,
                normal_end: np.ndarray, cfg: SeedConfig,
                shoulder: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """Collision-free tip paths (tip spacing <= step): parabolic arcs, lowest first, at the
    configured heights, then (given the shoulder) the boom retracting along its line, swinging
    about the shoulder and extending to the new anchor, which clears corners no arc can."""
    chord = float(np.linalg.norm(np.asarray(end, dtype=float) - np.asarray(start, dtype=float)))
    for frac in cfg.arc_heights:
        h = max(cfg.arc_min_height, frac * chord)
        n = math.ceil(_arc_length(start, end, normal_start, normal_end, h) / cfg.step) + 1
        tips = tip_arc(start, end, normal_start, normal_end, h, n)
        if _arc_is_clear(scn, tips, normal_start, normal_end):
            yield tips
    if shoulder is not None:
        for radius in RETRACT_RADII:
            tips = retract_path(start, end, shoulder, radius, cfg.step)
            if _arc_is_clear(scn, tips, normal_start, normal_end):
                yield tips
                break


RETRACT_RADII = (0.2, 0.1, 0.05)  # m from the shoulder, where a retracted gripper swings


def retract_path(start: np.ndarray, end: np.ndarray, shoulder: np.ndarray, radius: float,
                 step: float) -> np.ndarray:
    """Tip positions (spacing <= step) from `start` in along the boom's line to `radius` from the
    shoulder, round the shoulder (the shorter way) to the line towards `end`, and out to it."""
    a, b, s = (np.asarray(v, dtype=float) for v in (start, end, shoulder))
    ua, ub = (a - s) / np.linalg.norm(a - s), (b - s) / np.linalg.norm(b - s)
    ra, rb = min(radius, np.linalg.norm(a - s)), min(radius, np.linalg.norm(b - s))
    th_a, th_b = math.atan2(ua[1], ua[0]), math.atan2(ub[1], ub[0])
    sweep = (th_b - th_a + math.pi) % (2 * math.pi) - math.pi

    def line(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        n = max(1, math.ceil(np.linalg.norm(q - p) / step))
        return p + np.linspace(0.0, 1.0, n + 1)[:, None] * (q - p)

    n_arc = max(1, math.ceil(abs(sweep) * max(ra, rb) / step))
    th = th_a + np.linspace(0.0, 1.0, n_arc + 1) * sweep
    rr = ra + np.linspace(0.0, 1.0, n_arc + 1) * (rb - ra)
    swing = s + rr[:, None] * np.column_stack([np.cos(th), np.sin(th)])
    return np.vstack([line(a, s + ra * ua)[:-1], swing, line(s + rb * ub, b)[1:]])


def reach_seed(scn: Scenario, stance_ids: tuple[str, ...], boom: int, to_anchor: str,
               pose: np.ndarray, config: SeedConfig | None = None, seed: int = 0) -> Seed:
    """The free gripper of `boom` moves from its anchor in the 4-stance `stance_ids` to
    `to_anchor` along a collision-free arc; the body starts and ends at `pose` (the transition
    pose) and holds poses feasible in the 3-stance with the tip at each arc point."""
    cfg = config or SeedConfig()
    three = scn.stance(stance_ids).without(boom)
    k_from, k_to = scn.anchor_index[stance_ids[boom]], scn.anchor_index[to_anchor]
    a, b = scn.anchor_positions[k_from], scn.anchor_positions[k_to]
    na, nb = scn.anchor_normals[k_from], scn.anchor_normals[k_to]
    pose = np.asarray(pose, dtype=float).reshape(3)
    ends = np.column_stack([np.vstack([pose, pose]), np.vstack([a, b])])
    check = _check(scn, three, ends)
    for k, where in enumerate(("old", "new")):
        if not check.feasible[k]:
            return _failed(_describe(check, ends, f"transition pose with the tip at the {where} "
                                     "anchor", k), reach=True)
    rng = np.random.default_rng(seed)
    reasons = []
    shoulder = geometry.shoulder_positions(scn.robot, pose)[0, boom]
    for tips in _clear_arcs(scn, a, b, na, nb, cfg, shoulder):
        hold = np.column_stack([np.broadcast_to(pose, (len(tips), 3)), tips])
        check = _check(scn, three, hold)
        if check.feasible.all():
            return _success("hold", hold, check.allocation.robustness)
        reasons.append(_describe(check, hold, "holding the pose"))

        found = _sway(scn, three, pose, tips, cfg, rng)
        if found is not None:
            return _success("local", *found)
        reasons.append(f"no feasible sway among {cfg.local_rounds * cfg.local_samples} sampled "
                       "body offsets")
    if not reasons:
        reasons.append(f"no collision-free tip path from {stance_ids[boom]} to {to_anchor}: "
                       f"arcs at heights {cfg.arc_heights} x chord, or retracting the boom")
    return _failed("; ".join(reasons), reach=True)


def _sway(scn: Scenario, three: Stance, pose: np.ndarray, tips: np.ndarray, cfg: SeedConfig,
          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Local sampling for a reach phase. Body offsets from the transition pose, shared by all tip
    positions (zero first, then `local_samples` per spread, the spread doubling over
    `local_rounds`; phi scaled by turn_step / step), are checked at every tip in one vectorised
    call. A shortest-path search over (tip, offset) then picks, among the feasible ones, a
    sequence from zero back to zero that moves the body least and leaves the pose latest. It is
    subdivided (body and tip together) and re-checked; when a piece between two tips fails, the
    offset it moved to is struck out there and the search repeated (`SWAY_REPAIRS` times)."""
    scale = np.array([1.0, 1.0, cfg.turn_step / cfg.step])
    spreads = cfg.local_spread * 2.0 ** np.arange(cfg.local_rounds)
    draws = rng.normal(0.0, 1.0, (cfg.local_rounds, cfg.local_samples, 3))
    offsets = np.vstack([np.zeros((1, 3)), (draws * spreads[:, None, None] * scale).reshape(-1, 3)])
    N, C = len(tips), len(offsets)
    grid = np.column_stack([np.tile(pose + offsets, (N, 1)), np.repeat(tips, C, axis=0)])
    feasible = _check(scn, three, grid).feasible.reshape(N, C)
    d = offsets[:, None, :] - offsets[None, :, :]
    cost = np.maximum(np.linalg.norm(d[..., :2], axis=-1) / cfg.step,
                      np.abs(d[..., 2]) / cfg.turn_step)  # steps from offset i to offset j
    for _ in range(SWAY_REPAIRS):
        path = _cheapest_sequence(feasible, cost, away=1e-3 * cost[0])
        if path is None:
            return None
        waypoints = np.column_stack([pose + offsets[path], tips])
        configs = subdivide(waypoints, cfg.step, cfg.turn_step)
        check = _check(scn, three, configs)
        if check.feasible.all():
            return configs, check.allocation.robustness
        bad = int(np.argmin(check.feasible))
        k = int(np.searchsorted(np.cumsum(_pieces(waypoints, cfg.step, cfg.turn_step)), bad,
                                side="right"))
        k = k + 1 if path[k + 1] != 0 else k  # the offset the failing piece moved to (or from)
        feasible[k, path[k]] = False
    return None


def _cheapest_sequence(feasible: np.ndarray, cost: np.ndarray,
                       away: np.ndarray) -> np.ndarray | None:
    """Offsets j_0 .. j_{N-1} with feasible[k, j_k], j_0 = j_{N-1} = 0, minimising
    sum cost[j_k, j_k+1] + sum away[j_k] (dynamic programming), or None when there is none."""
    N, C = feasible.shape
    value = np.where(np.arange(C) == 0, 0.0, np.inf)
    value[~feasible[0]] = np.inf
    back = np.zeros((N, C), dtype=int)
    for k in range(1, N):
        total = value[:, None] + cost
        back[k] = np.argmin(total, axis=0)
        value = np.where(feasible[k], total[back[k], np.arange(C)] + away, np.inf)
    if not np.isfinite(value[0]):
        return None
    path = [0]
    for k in range(N - 1, 0, -1):
        path.append(int(back[k][path[-1]]))
    return np.array(path[::-1])
