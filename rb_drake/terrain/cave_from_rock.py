"""A scenario from rock polygons (an imported drawing or a mesh's section): anchors placed on the
rock's surface by the generator's rules (`rb_drake.generate.place_anchors`), a start stance at
the lowest place the robot can hang from and a goal at the top of the free space it can get to,
with rock above it for the upper booms.

The scenario's walls must be simple polygons, so rock with holes (a tunnel's section: rock all
round a free tube) is cut into simple pieces through each hole; anchors come from the rock's
true outline, never from those cuts.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from rb_drake.collision import Rock, polygon_is_simple
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import body_in_rock
from rb_drake.generate import (
    CaveConfig,
    Surface,
    best_stance,
    ccw,
    place_anchors,
    with_start_stance,
)
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.scenario import Scenario, scenario_from_dict

if TYPE_CHECKING:
    from shapely.geometry import Polygon

MAX_ANCHORS = 5000     # anchors in one cave: the planner's tables grow with their square
GRID_CELLS = 40_000    # candidate body positions for the start and the goal, at most
GRID_STEP = 0.1        # m between candidate body positions (coarser if the cave is large)
START_TRIES = 60       # the lowest candidates tried for a start stance ...
PER_ROW = 2            # ... at most this many at each height
GOAL_TOLERANCE = 0.5   # m, as the generator's caves
GOAL_HEADROOM = 0.5    # m: the upper booms reach anchors this far above the goal, so that the
#                        body, within GOAL_TOLERANCE of it, has 1 m of rock above (as in the
#                        generator's shafts: goal 1.5 m below the walls' top)
START_RISE = 1.5       # m above the lowest anchor where the start is looked for first (the
#                        generator's shafts: 1.5 m; lower, the lower booms have only the rock's
#                        bottom edge to hold, and the start is often a dead end)
DECIMALS = 4           # wall coordinates are rounded as the generator rounds them


def scenario_from_rock(rock: list[Polygon], *, seed: int = 0, config: CaveConfig | None = None,
                       robot: RobotParams | None = None,
                       start: tuple[float, float] | None = None,
                       goal: tuple[float, float] | None = None,
                       name: str = "imported", source: str = "<imported>",
                       framed: bool = False, max_values: int | None = None) -> Scenario:
    """A cave of the rock `rock` (shapely Polygons in metres, up = +y). Anchors are placed as
    the generator places them (config's density, normal noise and limit-surface ranges) from
    `seed`: the same rock and seed, the same cave. `start` (x, y) is the body's position to
    hang from (a feasible stance at or near it), chosen when None: the lowest free position
    with a feasible stance, START_RISE above the lowest anchor if one there has. `goal` (x, y)
    is chosen when None: the highest free position the body can get to from the start
    (through free space) with anchors in reach of each boom, those of the upper booms
    GOAL_HEADROOM above it. `framed`: the rock's bounding box is a frame drawn round the cave
    (a scan's section: rock is the frame minus the free space), not rock surface, and has no
    anchors. Raises RbpInputError (file `source`) when the rock makes no cave."""
    from shapely import union_all

    from rb_drake.terrain.polygon_files import validity_reason

    cfg = config or CaveConfig()
    robot = robot or RobotParams()
    for k, poly in enumerate(rock):  # as a mesh's section or an API caller gives them
        if not poly.is_valid:
            raise RbpInputError(f"rock polygon {k} is not simple: "
                                f"{validity_reason(poly)}", file=source)
    solid = [p for p in _polygons(union_all(rock)) if p.area > 0]
    if not solid:
        raise RbpInputError("no rock to climb", file=source)
    surfaces = _surfaces(solid, union_all(solid).bounds if framed else None)
    perimeter = sum(float(np.linalg.norm(np.diff(surf.points, axis=0), axis=1).sum())
                    for surf in surfaces)
    if perimeter * cfg.anchor_density > MAX_ANCHORS:
        raise RbpInputError(f"{perimeter:.0f} m of rock surface at {cfg.anchor_density:g} "
                            f"anchors per metre is more than {MAX_ANCHORS} anchors; lower "
                            "--anchor-density or import a smaller section", file=source)
    walls = _walls(solid, source)
    wall_values = sum(1 + 3 * len(w) for w in walls)  # each vertex a list of two numbers
    if max_values is not None and wall_values > max_values:
        raise too_many_values(source, f"at least {wall_values:,}", max_values)
    rng = np.random.default_rng(seed)
    anchors = place_anchors(rng, cfg, surfaces, Rock(walls))
    if len(anchors) < NUM_BOOMS:
        raise RbpInputError(f"only {len(anchors)} anchors on {perimeter:.2f} m of rock surface "
                            f"(the robot needs {NUM_BOOMS}); raise it", file=source,
                            field="--anchor-density")
    scn = Scenario(name=name, gravity=cfg.gravity, robot=robot, walls=tuple(walls),
                   anchors=tuple(anchors), start_pose=(0.0, 0.0, 0.0), start_stance=("",) * 4,
                   goal_position=(0.0, 0.0), goal_tolerance=GOAL_TOLERANCE, source=source,
                   robot_overrides={} if robot == RobotParams() else robot.to_dict())
    if max_values is not None:  # the file as it will be written (a start and goal of the same
        #                         shape fill in later), refused before the start and goal search
        from rb_drake.input_files import count_values

        if (values := count_values(scn.to_dict())) > max_values:
            raise too_many_values(source, f"{values:,}", max_values)
    grid = _Grid(scn) if start is None or goal is None else None
    if start is not None:
        pose = np.array([start[0], start[1], 0.0])
        if body_in_rock(robot, scn.rock, pose[None])[0] or scn.rock.contains(pose[:2]):
            raise RbpInputError(f"the body at ({start[0]:g}, {start[1]:g}) meets rock: give a "
                                "position in free space", file=source, field="--start")
        started = with_start_stance(scn, pose)
        if started is None:
            raise RbpInputError(f"no feasible stance for the body at or near ({start[0]:g}, "
                                f"{start[1]:g}): give a free position with anchors in reach of "
                                "all four booms", file=source, field="--start")
    else:
        assert grid is not None
        started = _lowest_start(scn, grid)
    if goal is None:
        assert grid is not None
        goal = _highest_goal(started, grid, source)
    scn = dataclasses.replace(started, goal_position=(float(goal[0]), float(goal[1])))
    # the file's own checks (simple counter-clockwise walls, anchors on them, goal in free
    # space, the start stance holding the robot) on what will be written
    return scenario_from_dict(scn.to_dict(), source)


def too_many_values(source: str, values: str, limit: int) -> RbpInputError:
    """The refusal of a cave whose file would hold `values` values, over `limit`."""
    return RbpInputError(f"the cave's file would hold {values} values, over the limit of "
                         f"{limit:,} for reading it back: a larger --simplify (fewer outline "
                         "vertices) or a lower --anchor-density; RBP_MAX_INPUT_VALUES raises "
                         "the limit", file=source, field="--simplify/--anchor-density")



def _polygons(geometry: object) -> list[Polygon]:
    from shapely.geometry import Polygon

    if isinstance(geometry, Polygon):
        return [geometry]
    return [g for g in getattr(geometry, "geoms", ()) if isinstance(g, Polygon)]


def _surfaces(solid: list[Polygon],
              frame: tuple[float, float, float, float] | None = None) -> list[Surface]:
    """Every ring of the rock, oriented so that rock is on its left: outward is to the right;
    without the stretches along the box `frame` (minx, miny, maxx, maxy) when given."""
    from shapely.geometry.polygon import orient

    surfaces = []
    for poly in solid:
        poly = orient(poly, 1.0)  # exterior counter-clockwise, holes clockwise
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords, dtype=float)
            surfaces += [Surface(piece, -1) for piece in _off_frame(pts, frame)]
    return surfaces


def _off_frame(ring: np.ndarray,
               frame: tuple[float, float, float, float] | None) -> list[np.ndarray]:
    """The closed `ring` (last point = first) as polylines without its segments along the
    box `frame`'s edges (both ends on one edge): the whole ring when `frame` is None."""
    if frame is None:
        return [ring]
    tol = 1e-9 * max(1.0, *(abs(v) for v in frame))
    minx, miny, maxx, maxy = frame
    ends = [np.abs(ring[:, 0] - minx) <= tol, np.abs(ring[:, 0] - maxx) <= tol,
            np.abs(ring[:, 1] - miny) <= tol, np.abs(ring[:, 1] - maxy) <= tol]
    on_frame = np.zeros(len(ring) - 1, dtype=bool)  # segment k: ring[k] to ring[k + 1]
    for edge in ends:
        on_frame |= edge[:-1] & edge[1:]
    if not on_frame.any():
        return [ring]
    first = int(np.flatnonzero(on_frame)[0])  # start the walk on the frame: no run wraps
    order = np.roll(np.arange(len(ring) - 1), -first)
    pieces: list[np.ndarray] = []
    run: list[np.ndarray] = []
    for k in order:
        if on_frame[k]:
            if run:
                pieces.append(np.array([*run, ring[k]]))
            run = []
        else:
            run.append(ring[k])
    if run:
        pieces.append(np.array([*run, ring[order[0]]]))
    return pieces


def _walls(solid: list[Polygon], source: str) -> list[np.ndarray]:
    """Simple counter-clockwise polygons (numpy, rounded) covering the rock."""
    walls = []
    for piece in (p for poly in solid for p in _without_holes(poly)):
        pts = np.round(np.asarray(piece.exterior.coords, dtype=float)[:-1], DECIMALS)
        keep = np.any(pts != np.roll(pts, 1, axis=0), axis=1)  # repeats rounding made
        pts = pts[keep]
        simple, why = polygon_is_simple(pts) if len(pts) >= 3 else (False, "too small")
        if not simple:
            x, y = piece.representative_point().coords[0]
            raise RbpInputError(f"the rock near ({x:.2f}, {y:.2f}) is not simple at "
                                f"{10 ** -DECIMALS:g} m resolution ({why}); give --simplify "
                                "to smooth it", file=source)
        walls.append(ccw(pts))
    return walls


def _without_holes(poly: Polygon) -> list[Polygon]:
    """`poly` cut into pieces without holes by vertical lines through its holes."""
    from shapely.geometry import LineString
    from shapely.ops import split

    if not poly.interiors:
        return [poly]
    hole = poly.interiors[0].bounds
    x = 0.5 * (hole[0] + hole[2])  # a vertical line here crosses the hole
    lo, hi = poly.bounds[1] - 1.0, poly.bounds[3] + 1.0
    pieces = split(poly, LineString([(x, lo), (x, hi)]))
    return [q for piece in _polygons(pieces) for q in _without_holes(piece)]


class _Grid:
    """Candidate body positions (angle 0) on a grid over the anchors: which are free of rock,
    which have an anchor in reach of each boom (`holdable`), and which also have, for each
    upper boom, an anchor in reach GOAL_HEADROOM above the body (`headroom`)."""

    def __init__(self, scn: Scenario):
        pos = scn.anchor_positions
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        area = float(np.prod(np.maximum(hi - lo, GRID_STEP)))
        self.step = max(GRID_STEP, math.sqrt(area / GRID_CELLS))
        nx, ny = (np.floor((hi - lo) / self.step).astype(int) + 1)
        xs = np.round(lo[0] + self.step * np.arange(nx), DECIMALS)
        ys = np.round(lo[1] + self.step * np.arange(ny), DECIMALS)
        self.shape = (ny, nx)
        gx, gy = np.meshgrid(xs, ys)
        self.points = np.stack([gx.ravel(), gy.ravel()], axis=1)
        poses = np.column_stack([self.points, np.zeros(len(self.points))])
        # row by row: a row's bounding box meets few edges, so the rock tests stay small (the
        # whole grid against a 10,000-edge cave at once took 2.2 GB)
        self.free = np.concatenate([
            ~body_in_rock(scn.robot, scn.rock, poses[k:k + nx])
            & ~scn.rock.contains(self.points[k:k + nx])  # a body wholly inside rock
            for k in range(0, len(poses), nx)])
        self.holdable = np.zeros(len(self.points), dtype=bool)
        self.headroom = np.zeros(len(self.points), dtype=bool)
        where = np.flatnonzero(self.free)
        self.holdable[where], self.headroom[where] = _anchors_in_reach(scn, poses[where])


def _anchors_in_reach(scn: Scenario, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, whether every boom reaches some anchor (its length and angle in range, its
    line clear of rock), and whether every upper boom (pointing up at rest) reaches one
    GOAL_HEADROOM or more above the pose."""
    from scipy.spatial import cKDTree

    from rb_drake import geometry
    from rb_drake.collision import ANCHOR_CLEARANCE, INDEX_EDGES

    robot = scn.robot
    upper = np.sin(robot.shoulder_directions) > 0
    tree = cKDTree(scn.anchor_positions)
    starts, ends, which, high = [], [], [], []  # each boom line to test: pose * 4 + boom
    for k, near in enumerate(tree.query_ball_point(poses[:, :2], robot.max_reach)):
        if len(near) < NUM_BOOMS:
            continue
        idx = np.array(near)
        targets = scn.anchor_positions[idx]
        above = targets[:, 1] >= poses[k, 1] + GOAL_HEADROOM
        shoulders = geometry.shoulder_positions(robot, poses[k])[0]  # (4, 2)
        for i in range(NUM_BOOMS):
            ok = geometry.reach(robot, poses[k], targets, np.full(len(idx), i)).violation[0] == 0
            d = targets[ok] - shoulders[i]  # of those in range, those whose booms pass no rock
            ends.append(targets[ok] - ANCHOR_CLEARANCE * d / np.linalg.norm(d, axis=1)[:, None])
            starts.append(np.broadcast_to(shoulders[i], d.shape))
            which.append(np.full(len(d), 4 * k + i))
            high.append(above[ok])
    clear = np.zeros((len(poses), NUM_BOOMS), dtype=bool)  # some anchor held clear of rock
    clear_high = np.zeros((len(poses), NUM_BOOMS), dtype=bool)  # ... and one GOAL_HEADROOM up
    if ends:
        a, b = np.concatenate(starts), np.concatenate(ends)
        line, up = np.concatenate(which), np.concatenate(high)
        # all poses' lines in few batches, not four a pose (each a pass over the rock's edges
        # or its quadtree); batches bounded, as the test of a batch is lines x nearby edges
        edges = len(scn.rock.edge_start)
        batch = 1 << 12 if edges > INDEX_EDGES else max(64, (1 << 18) // max(1, edges))
        free = np.concatenate([~scn.rock.segments_hit(a[j:j + batch], b[j:j + batch],
                                                      inside=False)
                               for j in range(0, len(a), batch)])
        clear.reshape(-1)[line[free]] = True
        clear_high.reshape(-1)[line[free & up]] = True
    hold = np.asarray(clear.all(axis=1))
    room = hold & np.asarray((clear_high | ~upper).all(axis=1))
    return hold, room


def _by_rows(points: np.ndarray, idx: np.ndarray, centre: float, upward: bool) -> np.ndarray:
    """Candidates `idx` row by row (from the bottom, or the top), at most PER_ROW a row, the
    nearest `centre` first; START_TRIES at most."""
    height = points[idx, 1] if upward else -points[idx, 1]
    order = idx[np.lexsort((np.abs(points[idx, 0] - centre), height))]
    rows = points[order, 1]
    rank = np.zeros(len(order), dtype=int)  # place of each candidate within its row
    for k in range(1, len(order)):
        rank[k] = rank[k - 1] + 1 if rows[k] == rows[k - 1] else 0
    return order[rank < PER_ROW][:START_TRIES]


def _holds(scn: Scenario, point: np.ndarray) -> bool:
    """Whether the body at `point` (angle 0) has a feasible stance, screened with two anchors
    per boom (a tenth of a second)."""
    return best_stance(scn, np.array([point[0], point[1], 0.0]), per_boom=2) is not None


def _lowest_start(scn: Scenario, grid: _Grid) -> Scenario:
    """`scn` with the most robust stance near the lowest candidate START_RISE or more above the
    lowest anchor that has a feasible one (lower candidates after, from the highest down):
    candidates are screened with `_holds`; the first that holds is searched fully, as the
    generator searches its start (`with_start_stance`)."""
    idx = np.flatnonzero(grid.holdable)
    if not len(idx):
        raise RbpInputError(f"no free position has anchors in reach of all four booms "
                            f"({len(scn.anchors)} anchors): the cave is too small, too wide or "
                            "too sparse for the robot; give --start X Y or raise "
                            "--anchor-density", file=scn.source, field="start")
    centre = float(np.mean(grid.points[idx, 0]))
    rise = grid.points[idx, 1] >= scn.anchor_positions[:, 1].min() + START_RISE
    tried = np.concatenate([_by_rows(grid.points, idx[rise], centre, upward=True),
                            _by_rows(grid.points, idx[~rise], centre, upward=False)])
    for k in tried[:START_TRIES]:
        if _holds(scn, grid.points[k]):
            started = with_start_stance(scn, np.array([*grid.points[k], 0.0]))
            if started is not None:
                return started
    raise RbpInputError(f"no feasible start stance at the {min(len(tried), START_TRIES)} lowest "
                        "free positions with anchors in reach; give --start X Y, or raise "
                        "--anchor-density", file=scn.source, field="start")


def _highest_goal(scn: Scenario, grid: _Grid, source: str) -> tuple[float, float]:
    """The highest candidate with rock GOAL_HEADROOM above in reach of the upper booms (as the
    generator's shafts end their climb below the top) that the body can get to from the start
    through free candidates; of those at that height, the nearest above the start."""
    from scipy import ndimage

    labels, _ = ndimage.label(grid.free.reshape(grid.shape))
    flat = labels.ravel()
    start = np.array(scn.start_pose[:2])
    free = np.flatnonzero(grid.free)
    home = free[np.argmin(np.linalg.norm(grid.points[free] - start, axis=1))]
    reachable = np.flatnonzero(grid.headroom & (flat == flat[home]))
    top = grid.points[reachable, 1].max() if len(reachable) else -math.inf
    if top - start[1] <= GOAL_TOLERANCE:
        raise RbpInputError(f"nothing to climb: no free position more than {GOAL_TOLERANCE:g} m "
                            f"above the start, reached from it, has rock {GOAL_HEADROOM:g} m "
                            "above in reach; give --goal X Y", file=source)
    level = reachable[grid.points[reachable, 1] >= top - 1e-9]
    k = level[np.argmin(np.abs(grid.points[level, 0] - start[0]))]
    return float(grid.points[k, 0]), float(grid.points[k, 1])
