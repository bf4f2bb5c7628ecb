"""The reach phase's seed (paper section IV-C): a 3-stance, the free gripper moving from its old
anchor to the new one.

The tip follows a collision-free parabolic arc (the lowest of a few heights that clears the
rock), or, where no arc clears it, the boom retracts, swings about its shoulder and extends. The
body holds the transition pose when that is feasible with the cantilevered limb at every tip
position; otherwise it sways: body offsets sampled around the transition pose are checked at
every tip position at once, and a shortest-path search picks the least motion that keeps every
configuration feasible and starts and ends at the transition pose.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

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
from rb_drake import geometry
from rb_drake.collision import ANCHOR_CLEARANCE
from rb_drake.feasibility import World, reach_world
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

ARC_OFFSET = 1e-3  # m; the arc's ends are tested for collision this far off the rock they grip
CHECK_BATCH = 50_000  # configurations checked in one vectorised call (tens of MB)
SWAY_REPAIRS = 5   # searches for a sway, each after striking out a failed piece




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
    ra, rb = min(radius, float(np.linalg.norm(a - s))), min(radius, float(np.linalg.norm(b - s)))
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
    world = reach_world(scn, np.vstack([a, b]))  # rock may be touched near a and b only
    check = check_configurations(world, three, ends)
    for k, where in enumerate(("old", "new")):
        if not check.feasible[k]:
            return failed_seed(describe_infeasible(
                check, ends, f"transition pose with the tip at the {where} anchor", k), reach=True)
    rng = np.random.default_rng(seed)
    reasons = []
    shoulder = geometry.shoulder_positions(scn.robot, pose)[0, boom]
    for tips in _clear_arcs(scn, a, b, na, nb, cfg, shoulder):
        hold = np.column_stack([np.broadcast_to(pose, (len(tips), 3)), tips])
        check = check_configurations(world, three, hold)
        if check.feasible.all():
            return found_seed("hold", hold, check.allocation.robustness)
        reasons.append(describe_infeasible(check, hold, "holding the pose"))

        found = _sway(world, three, pose, tips, cfg, rng)
        if found is not None:
            return found_seed("local", *found)
        reasons.append(f"no feasible sway among {cfg.local_rounds * cfg.local_samples} sampled "
                       "body offsets")
    if not reasons:
        reasons.append(f"no collision-free tip path from {stance_ids[boom]} to {to_anchor}: "
                       f"arcs at heights {cfg.arc_heights} x chord, or retracting the boom")
    return failed_seed("; ".join(reasons), reach=True)


def _sway(world: World, three: Stance, pose: np.ndarray, tips: np.ndarray, cfg: SeedConfig,
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
    feasible = np.zeros((N, C), dtype=bool)
    per = max(1, CHECK_BATCH // C)  # tips per vectorised check: its memory stays bounded
    for k in range(0, N, per):
        part = tips[k:k + per]
        grid = np.column_stack([np.tile(pose + offsets, (len(part), 1)),
                                np.repeat(part, C, axis=0)])
        feasible[k:k + per] = check_configurations(world, three, grid).feasible.reshape(-1, C)
    d = offsets[:, None, :] - offsets[None, :, :]
    cost = np.maximum(np.linalg.norm(d[..., :2], axis=-1) / cfg.step,
                      np.abs(d[..., 2]) / cfg.turn_step)  # steps from offset i to offset j
    for _ in range(SWAY_REPAIRS):
        path = _cheapest_sequence(feasible, cost, away=1e-3 * cost[0])
        if path is None:
            return None
        waypoints = np.column_stack([pose + offsets[path], tips])
        configs = subdivide(waypoints, cfg.step, cfg.turn_step)
        check = check_configurations(world, three, configs)
        if check.feasible.all():
            return configs, check.allocation.robustness
        bad = int(np.argmin(check.feasible))
        k = int(np.searchsorted(np.cumsum(pieces(waypoints, cfg.step, cfg.turn_step)), bad,
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
