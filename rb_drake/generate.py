"""Seeded random caves: a vertical shaft to climb, or a horizontal passage with a crevasse or a
rockfall to cross. Anchors are scattered along the rock surfaces with normals that follow the
wall with noise and randomised limit-surface magnitudes (as in the paper's trials). Every cave
comes with a feasible start stance: a generated cave where none exists is redrawn from the same
random stream, so a seed always gives the same cave.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from rb_drake import geometry
from rb_drake.collision import Rock
from rb_drake.errors import RbpError, RbpInputError
from rb_drake.feasibility import check_poses
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.scenario import MARS_GRAVITY, MAX_FORCE, MAX_GRAVITY, MIN_FORCE, Anchor, Scenario

KINDS = ("shaft", "crevasse", "rockfall")
MIN_LENGTH = 2.0  # m: start and goal sit 1 m from either end of a cave, so shorter has no climb
MAX_LENGTH = 1000.0  # m: a longer cave is a typo (and 1e308 overflows)
MAX_ANCHOR_DENSITY = 20.0  # anchors per metre: one every 5 cm; denser caves take minutes to draw


def length_problem(lo: float, hi: float) -> str | None:
    """Why (lo, hi) is no range of cave lengths to draw from, or None if it is one."""
    if not MIN_LENGTH <= lo <= hi <= MAX_LENGTH:
        return f"need {MIN_LENGTH:g} <= MIN <= MAX <= {MAX_LENGTH:g} (m), got {lo:g} {hi:g}"
    return None


def density_problem(anchor_density: float) -> str | None:
    """Why `anchor_density` is no density of anchors to draw or place, or None if it is one
    (`rbp scenario generate`, `rbp scenario import` and the Python API share it)."""
    if not 0 < anchor_density <= MAX_ANCHOR_DENSITY:  # NaN fails the comparison
        return (f"must be above 0 and at most {MAX_ANCHOR_DENSITY:g} anchors per metre, got "
                f"{anchor_density:g}")
    return None


def estimated_values(hi: float, anchor_density: float) -> int:
    """About how many values (YAML nodes) the file of a cave up to `hi` m long holds: measured
    2.0-2.1 anchors per metre of length and anchor a metre of rock (two walls and the ends),
    23-24 values an anchor and about 150 for the rest; rounded up so as not to undercount."""
    return math.ceil(24 * anchor_density * (2.2 * hi + 8) + 200)


def values_problem(hi: float, anchor_density: float) -> str | None:
    """Why a cave up to `hi` m long at `anchor_density` would make a file rbp cannot read back
    (over rb_drake.input_files' limit on a YAML document's values), or None."""
    from rb_drake.input_files import max_input_values

    values, limit = estimated_values(hi, anchor_density), max_input_values()
    if values <= limit:
        return None
    return (f"--length/--anchor-density: the file of a cave up to {hi:g} m long at "
            f"{anchor_density:g} anchors a metre would hold about {values:,} values, over the "
            f"limit of {limit:,} for reading it back (a shorter --length or a lower "
            "--anchor-density; RBP_MAX_INPUT_VALUES raises the limit)")


@dataclasses.dataclass(frozen=True)
class CaveConfig:
    """Knobs of the generator; the defaults reproduce the benchmark caves."""

    anchor_density: float = 3.0            # anchors per metre of rock surface
    normal_noise_deg: float = 20.0         # std of the normal about the wall's
    limit_normal: tuple[float, float] = (15.0, 50.0)   # N, uniform range of F_n
    lateral_ratio: tuple[float, float] = (0.25, 0.7)   # F_t / F_n
    sigma_normal: tuple[float, float] = (1.5, 4.0)     # N
    sigma_lateral: tuple[float, float] = (2.0, 6.0)    # N
    length: tuple[float, float] = (7.0, 9.0)           # m, shaft height or passage length
    # Booms leave the body along its diagonals, so hanging from one upper boom while the other
    # moves needs steep booms: shafts wider than about 2 m leave few feasible transitions.
    width: tuple[float, float] = (1.5, 1.9)            # m, shaft width
    # In a passage an upper boom lets go only with the body turned ~45 deg so that the other
    # upper shoulder is above its centre; the lower boom on that side must then pull at the
    # edge of its shoulder range (45 deg below horizontal), which needs floor anchors as far
    # out as the floor is below. Low passages keep those anchors within reach.
    passage_height: tuple[float, float] = (1.1, 1.4)   # m
    roughness: float = 0.08                # m, std of wall vertex jitter
    gravity: tuple[float, float] = MARS_GRAVITY
    max_redraws: int = 20


# CaveConfig's ranges (rbp.generate_scenario checks them before any draw): each (lo, hi) pair
# within these bounds with lo <= hi; forces within the scenario reader's (rb_drake.scenario)
_PAIRS = {"limit_normal": (0.1, 1e5), "lateral_ratio": (0.01, 10.0),
          "sigma_normal": (MIN_FORCE, MAX_FORCE), "sigma_lateral": (MIN_FORCE, MAX_FORCE),
          "length": (MIN_LENGTH, MAX_LENGTH), "width": (0.1, 20.0),
          "passage_height": (0.1, 20.0)}
_SINGLES = {"anchor_density": (1e-3, MAX_ANCHOR_DENSITY), "normal_noise_deg": (0.0, 180.0),
            "roughness": (0.0, 1.0)}
MAX_REDRAWS = 1000  # each draw that fails takes up to about 0.75 s


def config_problem(cfg: CaveConfig) -> tuple[str, str] | None:
    """(field, reason) for the first CaveConfig value out of its range, or None: a NaN
    gravity drew 20 caves in 15 s before failing, a negative width drew one."""
    def number(x: object) -> bool:  # finite and not huge (NaN fails the comparison)
        return isinstance(x, int | float) and not isinstance(x, bool) and abs(x) <= MAX_FORCE

    for name, (lo, hi) in _SINGLES.items():
        v = getattr(cfg, name)
        if not (number(v) and lo <= v <= hi):
            return name, f"must be a number from {lo:g} to {hi:g}, got {v!r:.60}"
    for name, (lo, hi) in _PAIRS.items():
        v = getattr(cfg, name)
        if not (isinstance(v, tuple | list) and len(v) == 2 and all(map(number, v))
                and lo <= v[0] <= v[1] <= hi):
            return name, f"must be (MIN, MAX) with {lo:g} <= MIN <= MAX <= {hi:g}, got {v!r:.60}"
    g = cfg.gravity
    if not (isinstance(g, tuple | list) and len(g) == 2 and all(map(number, g))
            and all(abs(x) <= MAX_GRAVITY for x in g)):
        return "gravity", (f"must be 2 finite numbers at most {MAX_GRAVITY:g} m/s^2 in "
                           f"magnitude, got {g!r:.60}")
    r = cfg.max_redraws
    if isinstance(r, bool) or not isinstance(r, int) or not 1 <= r <= MAX_REDRAWS:
        return "max_redraws", f"must be a whole number from 1 to {MAX_REDRAWS}, got {r!r:.60}"
    return None


class Surface:
    """A rock surface to put anchors on: a polyline whose outward side is `side` (+1: left)."""

    def __init__(self, points: np.ndarray, side: int):
        self.points = np.asarray(points, dtype=float)
        self.side = side

    def sample(self, rng: np.random.Generator, density: float) -> list[tuple[np.ndarray, float]]:
        """Points along the polyline (uniform in arclength) with their outward normal angle."""
        seg = np.diff(self.points, axis=0)
        seg_len = np.linalg.norm(seg, axis=1)
        total = float(seg_len.sum())
        n = rng.poisson(density * total)
        out = []
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])
        for s in np.sort(rng.uniform(0.0, total, n)):
            k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
            t = seg[k] / seg_len[k]
            p = self.points[k] + (s - cum[k]) * t
            normal = self.side * np.array([-t[1], t[0]])
            out.append((p, math.atan2(normal[1], normal[0])))
        return out


def _jagged(rng: np.random.Generator, start: np.ndarray, end: np.ndarray, step: float,
            roughness: float) -> np.ndarray:
    """A rough polyline from start to end, jittered perpendicular to it."""
    n = max(2, int(np.linalg.norm(end - start) / step) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    pts = start + t * (end - start)
    d = (end - start) / np.linalg.norm(end - start)
    off = rng.normal(0.0, roughness, n)
    off[[0, -1]] = 0.0
    return pts + off[:, None] * np.array([-d[1], d[0]])


def _shaft(rng: np.random.Generator, cfg: CaveConfig):
    H = rng.uniform(*cfg.length)
    W = rng.uniform(*cfg.width)
    left = _jagged(rng, np.array([-W / 2, -0.5]), np.array([-W / 2, H + 0.5]), 0.5,
                   cfg.roughness)
    right = _jagged(rng, np.array([W / 2, -0.5]), np.array([W / 2, H + 0.5]), 0.5,
                    cfg.roughness)
    xo_l, xo_r = -W / 2 - 1.0, W / 2 + 1.0
    walls = [
        np.vstack([[xo_l, -0.5], left, [xo_l, H + 0.5]]),
        np.vstack([[xo_r, -0.5], [xo_r, H + 0.5], right[::-1]]),
    ]
    # Walking up the left wall, free space is on the right (side -1); the right wall, the left.
    surfaces = [Surface(left, -1), Surface(right, +1)]
    start = np.array([0.0, 1.0, 0.0])
    goal = np.array([0.0, H - 1.0])
    return walls, surfaces, start, goal


def _passage(rng: np.random.Generator, cfg: CaveConfig, obstacle: str):
    L = rng.uniform(*cfg.length)
    H = rng.uniform(*cfg.passage_height)
    ceiling = _jagged(rng, np.array([-0.5, H]), np.array([L + 0.5, H]), 0.5, cfg.roughness)
    walls = [np.vstack([ceiling, [L + 0.5, H + 1.0], [-0.5, H + 1.0]])]
    surfaces = [Surface(ceiling, -1)]
    mid = rng.uniform(0.4, 0.6) * L
    if obstacle == "crevasse":
        gap = rng.uniform(1.0, 1.6)
        a, b = mid - gap / 2, mid + gap / 2
        floor_a = _jagged(rng, np.array([-0.5, 0.0]), np.array([a, 0.0]), 0.5, cfg.roughness)
        floor_b = _jagged(rng, np.array([b, 0.0]), np.array([L + 0.5, 0.0]), 0.5, cfg.roughness)
        walls.append(np.vstack([[-0.5, -3.0], [a, -3.0], floor_a[::-1]]))
        walls.append(np.vstack([[b, -3.0], [L + 0.5, -3.0], floor_b[::-1]]))
        surfaces += [Surface(floor_a, +1), Surface(floor_b, +1),
                     Surface(np.array([[a, 0.0], [a, -3.0]]), +1),
                     Surface(np.array([[b, -3.0], [b, 0.0]]), +1)]
    else:
        floor = _jagged(rng, np.array([-0.5, 0.0]), np.array([L + 0.5, 0.0]), 0.5, cfg.roughness)
        walls.append(np.vstack([[-0.5, -1.0], [L + 0.5, -1.0], floor[::-1]]))
        surfaces.append(Surface(floor, +1))
        h = rng.uniform(0.5, 0.8) * H * 0.45
        w = rng.uniform(0.8, 1.3)
        ang = np.linspace(0.0, math.pi, 9)
        rad = 1.0 + rng.normal(0.0, 0.08, ang.size)
        top = np.stack([mid + 0.5 * w * np.cos(ang) * rad, h * np.sin(ang) * rad], axis=1)
        top[[0, -1], 1] = -0.3  # sink the boulder's feet into the floor
        walls.append(np.vstack([top, [[mid - 0.5 * w, -0.5], [mid + 0.5 * w, -0.5]]]))
        surfaces.append(Surface(top, -1))  # the arc runs right to left: free space on its right
    start = np.array([1.0, H / 2, 0.0])
    goal = np.array([L - 1.0, H / 2])
    return walls, surfaces, start, goal


def ccw(poly: np.ndarray) -> np.ndarray:
    """The polygon with its vertices counter-clockwise, as scenario files want them."""
    q = np.roll(poly, -1, axis=0)
    area = 0.5 * np.sum(poly[:, 0] * q[:, 1] - q[:, 0] * poly[:, 1])
    return poly if area > 0 else poly[::-1]


def place_anchors(rng: np.random.Generator, cfg: CaveConfig, surfaces: list[Surface],
                  rock: Rock) -> list[Anchor]:
    """Anchors scattered along `surfaces` (cfg.anchor_density per metre), their normals the
    surface's outward normal with noise and their limit surfaces drawn from cfg's ranges."""
    anchors: list[Anchor] = []
    for surf in surfaces:
        for p, normal_angle in surf.sample(rng, cfg.anchor_density):
            ang = normal_angle + math.radians(rng.normal(0.0, cfg.normal_noise_deg))
            n = np.array([math.cos(ang), math.sin(ang)])
            fn = rng.uniform(*cfg.limit_normal)
            ft = fn * rng.uniform(*cfg.lateral_ratio)
            sn = rng.uniform(*cfg.sigma_normal)
            st = rng.uniform(*cfg.sigma_lateral)
            # Skip sites buried under other rock or facing into it (boulder feet, pit rims),
            # tested as written (rounded), as the scenario reader tests them.
            p = np.array([round(float(p[0]), 4), round(float(p[1]), 4)])
            n = np.array([round(float(n[0]), 6), round(float(n[1]), 6)])
            if rock.contains(p + 0.05 * n) or (rock.contains(p) and rock.distance(p) > 0.005):
                continue
            anchors.append(Anchor(f"a{len(anchors)}", (float(p[0]), float(p[1])),
                                  (float(n[0]), float(n[1])),
                                  round(fn, 3), round(ft, 3), round(sn, 3), round(st, 3)))
    return anchors


def best_stance(scn: Scenario, poses: np.ndarray, per_boom: int = 4,
                exclude: tuple[str, ...] = ()) -> tuple[np.ndarray, tuple[str, ...], float] | None:
    """The most robust feasible 4-stance at any of `poses` (the pose, anchor ids, probability).

    Candidates per boom are the `per_boom` reachable anchors nearest its equilibrium direction.
    Poses are tried in order; the search stops at the first pose that has a feasible stance.
    """
    robot = scn.robot
    best = None
    pos = scn.anchor_positions
    for pose in np.atleast_2d(poses):
        cands = []
        for i in range(NUM_BOOMS):
            r = geometry.reach(robot, pose, pos, np.full(len(pos), i))
            th = r.shoulder_angle[0]
            ok = r.violation[0] == 0.0
            ok &= ~np.isin([a.id for a in scn.anchors], exclude)
            idx = np.flatnonzero(ok)
            cands.append(idx[np.argsort(np.abs(th[idx]))][:per_boom])
        for combo in itertools.product(*cands):
            if len(set(combo)) < 4:
                continue
            ids = tuple(scn.anchors[k].id for k in combo)
            check = check_poses(scn, scn.stance(ids), pose)
            if check.feasible[0] and (best is None or check.probability[0] > best[2]):
                best = (pose.copy(), ids, float(check.probability[0]))
        if best is not None:
            break
    return best


START_OFFSETS = np.array([[0, 0, 0], [0.15, 0, 0], [-0.15, 0, 0], [0, 0.15, 0], [0, -0.15, 0],
                          [0, 0, 0.2], [0, 0, -0.2]])  # tried about a start pose, in order


def with_start_stance(scn: Scenario, start: np.ndarray) -> Scenario | None:
    """`scn` with the most robust feasible start stance at `start` (x, y, phi) or a pose
    near it (START_OFFSETS), or None when there is none."""
    found = best_stance(scn, start + START_OFFSETS)
    if found is None:
        return None
    pose, ids, _ = found
    return dataclasses.replace(scn, start_pose=(float(pose[0]), float(pose[1]), float(pose[2])),
                               start_stance=ids)


class CaveGenerationError(RbpError, RuntimeError):
    """No cave of the kind asked for had a feasible start stance in `CaveConfig.max_redraws`
    draws (the user's seed and configuration: `rbp scenario generate` reports it as their
    input's). A RuntimeError, as callers catch it."""


def generate_cave(kind: str, seed: int, config: CaveConfig | None = None,
                  robot: RobotParams | None = None) -> Scenario:
    """A random cave of `kind` ('shaft', 'crevasse' or 'rockfall'); the same seed, the same cave."""
    if kind not in KINDS:
        raise RbpInputError(f"must be one of {KINDS}, got {kind!r}", field="kind")
    cfg = config or CaveConfig()
    robot = robot or RobotParams()
    rng = np.random.default_rng(seed)
    for _ in range(cfg.max_redraws):
        if kind == "shaft":
            walls, surfaces, start, goal = _shaft(rng, cfg)
        else:
            walls, surfaces, start, goal = _passage(rng, cfg, kind)
        walls = [ccw(np.round(w, 4)) for w in walls]
        rock = Rock(walls)
        anchors = place_anchors(rng, cfg, surfaces, rock)
        if len(anchors) < 4:
            continue
        scn = Scenario(name=f"{kind}-{seed}", gravity=cfg.gravity, robot=robot,
                       walls=tuple(walls), anchors=tuple(anchors),
                       start_pose=tuple(start), start_stance=("",) * 4,
                       goal_position=tuple(goal), goal_tolerance=0.5,
                       source=f"generated:{kind}:{seed}",
                       robot_overrides={} if robot == RobotParams() else robot.to_dict())
        started = with_start_stance(scn, start)
        if started is not None:
            return started
    raise CaveGenerationError(f"no cave of kind {kind!r} with a feasible start stance after "
                              f"{cfg.max_redraws} draws from seed {seed}; loosen the CaveConfig")
