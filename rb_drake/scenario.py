"""Scenarios (caves): walls, anchors with their limit surfaces, the robot, start and goal.

File format `reachbot-scenario/1` (YAML; docs/formats.md). `load_scenario` refuses malformed
input with one `ScenarioError` naming the file, the field and the reason.
"""

from __future__ import annotations

import dataclasses
import math
import unicodedata
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml

from rb_drake.collision import MIN_EDGE, Rock, polygon_is_simple, signed_area
from rb_drake.errors import RbpInputError, apart, key_text
from rb_drake.input_files import InputFileError, load_yaml, read_text
from rb_drake.params import NUM_BOOMS, ParamError, RobotParams, robot_from_dict
from rb_drake.stance import Stance

FORMAT = "reachbot-scenario/1"
MARS_GRAVITY = (0.0, -3.71)
ANCHOR_DEPTH_TOL = 0.01  # m: an anchor may sit this far inside its rock (numerical slack)
ANCHOR_GAP_TOL = 0.05    # m: ... and this far off the rock surface (a gripper grasps rock)
TOL_SLACK = 1e-9         # m: an anchor written at a tolerance (1.21 beside 1.2) is within it,
#                          though its computed distance is a rounding over (0.010000000000000009)

# Physically meaningful magnitudes (docs/formats.md): a value beyond them is a typo or an attack,
# and refusing it at reading keeps overflow (1e308 squared) out of the planner.
MAX_COORDINATE = 1e4  # m: walls, anchors, start and goal positions
MAX_GOAL_TOLERANCE = 100.0  # m: a goal region the size of a large cave at most
MAX_ANGLE = 1e4       # rad for the start pose's angle, degrees for an anchor's normal angle
MAX_GRAVITY = 1e3     # m/s^2 per component (Earth 9.81)
MAX_FORCE = 1e6       # N: anchor limit surfaces and their spreads
MIN_FORCE = 1e-3      # N: ... at least (1e-200 or 5e-324 overflowed the grasp model to NaN)
MAX_NAME = 200        # characters of a scenario's name (a title, a file stem)


class ScenarioError(RbpInputError):
    """A scenario the planner refuses: `source` (file, also `file`), `field` (dotted path) and
    `reason`."""

    field: str  # always given here

    def __init__(self, source: str, field: str, reason: str):
        super().__init__(reason, file=source, field=field)
        self.source = source


@dataclasses.dataclass(frozen=True)
class Anchor:
    """A grasp site: position on the rock, outward unit normal, limit-surface parameters."""

    id: str
    position: tuple[float, float]
    normal: tuple[float, float]
    f_normal: float
    f_lateral: float
    sigma_normal: float
    sigma_lateral: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "position": [float(v) for v in self.position],
            "normal": [float(v) for v in self.normal],
            "limit": {"normal": float(self.f_normal), "lateral": float(self.f_lateral)},
            "sigma": {"normal": float(self.sigma_normal), "lateral": float(self.sigma_lateral)},
        }


class AnchorTable(NamedTuple):
    """A scenario's anchors as rows (as `Scenario.stance` reads them), plus a last row of NaN
    for a free boom: the feasibility kernel's stances are gathered from it by index
    (`planning.transition_score.pack_rows`)."""

    row: dict[str, int]        # anchor id -> row; len(row) is the free boom's row
    positions: np.ndarray      # (N + 1, 2)
    normals: np.ndarray        # (N + 1, 2)
    f_normal: np.ndarray       # (N + 1,)
    f_lateral: np.ndarray
    sigma_normal: np.ndarray
    sigma_lateral: np.ndarray


@dataclasses.dataclass(frozen=True)
class Scenario:
    name: str
    gravity: tuple[float, float]
    robot: RobotParams
    walls: tuple[np.ndarray, ...]
    anchors: tuple[Anchor, ...]
    start_pose: tuple[float, float, float]
    start_stance: tuple[str, ...]
    goal_position: tuple[float, float]
    goal_tolerance: float
    source: str = "<scenario>"
    robot_overrides: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        # the start's angle within [-pi, pi], as the lattice and the body's paths measure it:
        # a start at 2 pi (the same pose as 0) joined no lattice pose, its straight path to
        # one turning the body a full circle
        # (a Scenario built by hand may hold anything here: its reader says what is wrong)
        try:
            x, y, phi = self.start_pose
            wrapped = math.remainder(float(phi), 2.0 * math.pi)
        except (TypeError, ValueError, OverflowError):
            return
        if math.isfinite(wrapped) and wrapped != phi:
            object.__setattr__(self, "start_pose", (x, y, wrapped))

    @cached_property
    def rock(self) -> Rock:
        return Rock(self.walls)

    @cached_property
    def anchor_index(self) -> dict[str, int]:
        return {a.id: k for k, a in enumerate(self.anchors)}

    @cached_property
    def anchor_positions(self) -> np.ndarray:
        return np.array([a.position for a in self.anchors], dtype=float).reshape(-1, 2)

    @cached_property
    def anchor_normals(self) -> np.ndarray:
        return np.array([a.normal for a in self.anchors], dtype=float).reshape(-1, 2)

    @cached_property
    def anchor_table(self) -> AnchorTable:
        """The anchors as the kernel's table (`AnchorTable`), built once per scenario and held
        by it: a scenario is immutable, so the table can never go stale."""
        nan2 = (math.nan, math.nan)

        def col(get, default) -> np.ndarray:
            return np.array([get(a) for a in self.anchors] + [default], dtype=float)

        return AnchorTable(dict(self.anchor_index), col(lambda a: a.position, nan2),
                           col(lambda a: a.normal, nan2), col(lambda a: a.f_normal, math.nan),
                           col(lambda a: a.f_lateral, math.nan),
                           col(lambda a: a.sigma_normal, math.nan),
                           col(lambda a: a.sigma_lateral, math.nan))

    @property
    def gravity_vector(self) -> np.ndarray:
        return np.asarray(self.gravity, dtype=float)

    def stance(self, ids: Sequence[str | None]) -> Stance:
        """Stance arrays for anchor ids per boom (None: the boom is free)."""
        if len(ids) != NUM_BOOMS:
            raise RbpInputError(f"a stance names {NUM_BOOMS} anchors (None for free), got {ids!r}")
        rows = [self.anchors[self.anchor_index[i]] if i is not None else None for i in ids]
        nan2 = (math.nan, math.nan)

        def col(get, default):
            return np.array([get(a) if a is not None else default for a in rows], dtype=float)

        return Stance(
            ids=tuple(ids),
            attached=np.array([a is not None for a in rows]),
            positions=col(lambda a: a.position, nan2),
            normals=col(lambda a: a.normal, nan2),
            f_normal=col(lambda a: a.f_normal, math.nan),
            f_lateral=col(lambda a: a.f_lateral, math.nan),
            sigma_normal=col(lambda a: a.sigma_normal, math.nan),
            sigma_lateral=col(lambda a: a.sigma_lateral, math.nan),
        )

    def to_dict(self, resolved: bool = False) -> dict[str, Any]:
        """The file form; `resolved` writes every robot parameter, not just the overrides."""
        return {
            "format": FORMAT,
            "name": self.name,
            "gravity": [float(g) for g in self.gravity],
            "robot": self.robot.to_dict() if resolved else dict(self.robot_overrides),
            "walls": [[[float(x), float(y)] for x, y in w] for w in self.walls],
            "anchors": [a.to_dict() for a in self.anchors],
            "start": {"pose": [float(v) for v in self.start_pose],
                      "stance": list(self.start_stance)},
            "goal": {"position": [float(v) for v in self.goal_position],
                     "tolerance": float(self.goal_tolerance)},
        }


# ---------------------------------------------------------------------------------------------
# Parsing and validation


class _Reader:
    """Typed field access that raises ScenarioError with the field's path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, reason: str) -> ScenarioError:
        return ScenarioError(self.source, field, reason)

    def mapping(self, field: str, value: Any) -> Mapping[str, Any]:
        if not isinstance(value, Mapping):
            raise self.fail(field, f"expected a mapping, got {_describe(value)}")
        return value

    def closed(self, field: str, value: Any, known: set[str]) -> Mapping[str, Any]:
        """A mapping of only `known` keys (a misspelt key, silently ignored, would leave its
        default in force)."""
        m = self.mapping(field, value)
        extra = sorted(set(m) - known, key=str)
        if extra:
            raise self.fail(f"{field}.{key_text(extra[0])}", f"unknown field; expected one of "
                            f"{sorted(known)}")
        return m

    def require(self, field: str, m: Mapping[str, Any], key: str) -> Any:
        if key not in m:
            raise self.fail(f"{field}.{key}" if field else key, "missing required field")
        return m[key]

    def number(self, field: str, value: Any, positive: bool = False,
               nonnegative: bool = False, bound: float = MAX_COORDINATE,
               least: float = 0.0) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(field, f"expected a number, got {_describe(value)}")
        try:
            v = float(value)
        except OverflowError:  # an integer too large for a float
            v = math.inf
        if not math.isfinite(v):
            raise self.fail(field, f"must be a finite number, got {_describe(value)}")
        if abs(v) > bound:
            raise self.fail(field, f"must be at most {bound:g} in magnitude, got {v:g}")
        if positive and v <= 0:
            raise self.fail(field, f"must be positive, got {v}")
        if nonnegative and v < 0:
            raise self.fail(field, f"must not be negative, got {v}")
        if abs(v) < least:
            raise self.fail(field, f"must be at least {least:g}, got {v:g}")
        return v

    def vector(self, field: str, value: Any, n: int,
               bounds: Sequence[float] = ()) -> tuple[float, ...]:
        """`n` numbers, the k-th at most bounds[k] in magnitude (MAX_COORDINATE by default)."""
        if not isinstance(value, list | tuple) or len(value) != n:
            raise self.fail(field, f"expected a list of {n} numbers, got {_describe(value)}")
        limits = list(bounds) + [MAX_COORDINATE] * (n - len(bounds))
        return tuple(self.number(f"{field}[{k}]", v, bound=limits[k])
                     for k, v in enumerate(value))


def _describe(value: Any) -> str:
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


TOP_LEVEL = {"format", "name", "gravity", "robot", "walls", "anchors", "start", "goal"}


def scenario_from_dict(data: Any, source: str = "<scenario>",
                       check_start: bool = True) -> Scenario:
    """Parse and validate a scenario mapping; raises ScenarioError."""
    rd = _Reader(source)
    data = rd.mapping("(top level)", data)
    if str(data.get("format", "")).startswith("reachbot-plan/"):
        raise rd.fail("format", f"this is a plan ({data['format']}), not a scenario: to plan "
                      f"its cave again, rbp plan --from-plan {source} -o NEW.json")
    unknown = sorted(set(data) - TOP_LEVEL, key=str)
    if unknown:
        raise rd.fail(key_text(unknown[0]), f"unknown field; expected one of "
                      f"{sorted(TOP_LEVEL)}")
    fmt = rd.require("", data, "format")
    if fmt != FORMAT:
        raise rd.fail("format", f"expected {FORMAT!r}, got {fmt!r}")
    # a file's stem as a default name is cut to a name's length (a 220-character file name
    # refused a scenario that gives no name: "name: 220 characters")
    name = data.get("name", Path(source).stem[:MAX_NAME])
    if not isinstance(name, str):
        raise rd.fail("name", f"expected a string, got {_describe(name)}")
    if len(name) > MAX_NAME:  # 999,000 characters took minutes and 1 GB to draw in a title
        raise rd.fail("name", f"{len(name):,} characters; at most {MAX_NAME}")
    gravity = rd.vector("gravity", data.get("gravity", list(MARS_GRAVITY)), 2,
                        (MAX_GRAVITY, MAX_GRAVITY))

    overrides = data.get("robot")
    if overrides is None:  # `robot:` left empty; false, 0 or "" are refused as not a mapping
        overrides = {}
    try:
        robot = robot_from_dict(overrides)
    except ParamError as e:
        field = "robot" if e.field == "robot" else f"robot.{e.field}"
        raise rd.fail(field, e.reason) from None

    walls_raw = rd.require("", data, "walls")
    if not isinstance(walls_raw, list):
        raise rd.fail("walls", f"expected a list of polygons, got {_describe(walls_raw)}")
    walls = []
    for k, poly in enumerate(walls_raw):
        field = f"walls[{k}]"
        if not isinstance(poly, list) or len(poly) < 3:
            raise rd.fail(field, f"expected a polygon of >= 3 [x, y] points, got {_describe(poly)}")
        pts = np.array([rd.vector(f"{field}[{i}]", p, 2) for i, p in enumerate(poly)])
        edges = np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)
        k = int(np.argmin(edges))
        if edges[k] < MIN_EDGE:
            raise rd.fail(field, f"not a simple polygon: vertices {k} and {(k + 1) % len(pts)} "
                          f"are {edges[k]:.3g} m apart, closer than {MIN_EDGE:g} m (a repeated "
                          "vertex)")
        simple, why = polygon_is_simple(pts)
        if not simple:
            raise rd.fail(field, f"not a simple polygon: {why}")
        if signed_area(pts) < 0:
            raise rd.fail(field, "vertices are listed clockwise; list them counter-clockwise")
        walls.append(pts)
    rock = Rock(walls)

    anchors_raw = rd.require("", data, "anchors")
    if not isinstance(anchors_raw, list) or not anchors_raw:
        raise rd.fail("anchors", f"expected a non-empty list, got {_describe(anchors_raw)}")
    anchors: list[Anchor] = []
    seen: set[str] = set()
    normalised: dict[str, str] = {}  # NFC form -> the id: ids that look the same are one id
    for k, raw in enumerate(anchors_raw):
        anchors.append(_parse_anchor(rd, f"anchors[{k}]", raw, (seen, normalised), rock))

    start = rd.closed("start", rd.require("", data, "start"), {"pose", "stance"})
    pose = rd.vector("start.pose", rd.require("start", start, "pose"), 3,
                     (MAX_COORDINATE, MAX_COORDINATE, MAX_ANGLE))
    stance_raw = rd.require("start", start, "stance")
    if not isinstance(stance_raw, list) or len(stance_raw) != NUM_BOOMS:
        raise rd.fail("start.stance", f"expected {NUM_BOOMS} anchor ids (one per boom), "
                      f"got {_describe(stance_raw)}")
    for i, aid in enumerate(stance_raw):
        if not isinstance(aid, str) or aid not in seen:
            raise rd.fail(f"start.stance[{i}]", f"unknown anchor id {aid!r}")
    if len(set(stance_raw)) != NUM_BOOMS:
        raise rd.fail("start.stance", f"each boom needs its own anchor, got {stance_raw}")

    goal = rd.closed("goal", rd.require("", data, "goal"), {"position", "tolerance"})
    goal_pos = rd.vector("goal.position", rd.require("goal", goal, "position"), 2)
    tol = rd.number("goal.tolerance", goal.get("tolerance", 0.5), positive=True,
                    bound=MAX_GOAL_TOLERANCE)
    _check_goal(rd, rock, np.array(goal_pos), tol)

    scn = Scenario(name=name, gravity=(gravity[0], gravity[1]), robot=robot, walls=tuple(walls),
                   anchors=tuple(anchors), start_pose=(pose[0], pose[1], pose[2]),
                   start_stance=tuple(stance_raw), goal_position=(goal_pos[0], goal_pos[1]),
                   goal_tolerance=tol, source=source, robot_overrides=dict(overrides))
    if check_start:
        from rb_drake.feasibility import diagnose_pose

        problems = diagnose_pose(scn, scn.stance(scn.start_stance), np.array(scn.start_pose))
        if problems:
            raise rd.fail("start", "the start pose is not feasible in the start stance: "
                          + "; ".join(problems))
    return scn


def _parse_anchor(rd: _Reader, field: str, raw: Any,
                  ids: tuple[set[str], dict[str, str]], rock: Rock) -> Anchor:
    raw = rd.closed(field, raw, {"id", "position", "normal", "limit", "sigma"})
    aid = rd.require(field, raw, "id")
    if isinstance(aid, int) and not isinstance(aid, bool):
        # an id read as a number is no longer as written (1_000 is 1000, +5 is 5), and the
        # start stance and plans name anchors by text: a number is refused, not renamed
        raise rd.fail(f"{field}.id", f"expected a name, got the number {aid}: quote it "
                      f"(id: \"...\") so that it is read as written")
    if not isinstance(aid, str):
        raise rd.fail(f"{field}.id", f"expected a string, got {_describe(aid)}")
    _check_id(rd, f"{field}.id", aid, *ids)
    pos = rd.vector(f"{field}.position", rd.require(field, raw, "position"), 2)
    normal_raw = rd.require(field, raw, "normal")
    if isinstance(normal_raw, int | float) and not isinstance(normal_raw, bool):
        deg = rd.number(f"{field}.normal", normal_raw, bound=MAX_ANGLE)
        normal = (math.cos(math.radians(deg)), math.sin(math.radians(deg)))
    else:
        nx, ny = rd.vector(f"{field}.normal", normal_raw, 2)
        norm = math.hypot(nx, ny)
        if norm < 1e-9:
            raise rd.fail(f"{field}.normal", "the zero vector has no direction")
        # A unit vector (as Scenario.to_dict writes them) is kept bit for bit, so that a plan's
        # embedded scenario reads back exactly (rbp plan --from-plan repeats the plan).
        normal = (nx, ny) if abs(norm - 1.0) <= 1e-15 else (nx / norm, ny / norm)
    limit = rd.closed(f"{field}.limit", rd.require(field, raw, "limit"), {"normal", "lateral"})
    sigma = rd.closed(f"{field}.sigma", rd.require(field, raw, "sigma"), {"normal", "lateral"})
    fn = rd.number(f"{field}.limit.normal", rd.require(f"{field}.limit", limit, "normal"),
                   positive=True, bound=MAX_FORCE, least=MIN_FORCE)
    ft = rd.number(f"{field}.limit.lateral", rd.require(f"{field}.limit", limit, "lateral"),
                   positive=True, bound=MAX_FORCE, least=MIN_FORCE)
    sn = rd.number(f"{field}.sigma.normal", rd.require(f"{field}.sigma", sigma, "normal"),
                   positive=True, bound=MAX_FORCE, least=MIN_FORCE)
    st = rd.number(f"{field}.sigma.lateral", rd.require(f"{field}.sigma", sigma, "lateral"),
                   positive=True, bound=MAX_FORCE, least=MIN_FORCE)
    p = np.array(pos)
    if (rock.polygons and rock.contains(p)
            and (depth := float(rock.distance(p))) > ANCHOR_DEPTH_TOL + TOL_SLACK):
        raise rd.fail(f"{field}.position", f"anchor {aid!r} at {list(pos)} is inside rock: "
                      f"{apart(depth, ANCHOR_DEPTH_TOL)} m from the surface (at most "
                      f"{ANCHOR_DEPTH_TOL} m inside)")
    if rock.polygons and rock.contains(p + 0.05 * np.array(normal)):
        raise rd.fail(f"{field}.normal", f"anchor {aid!r}: the normal points into the rock; "
                      "it must point out of the wall, into free space")
    if (rock.polygons and (gap := float(rock.distance(p))) > ANCHOR_GAP_TOL + TOL_SLACK
            and not rock.contains(p)):
        raise rd.fail(f"{field}.position", f"anchor {aid!r} at {list(pos)} is off its wall: "
                      f"{apart(gap, ANCHOR_GAP_TOL)} m from the nearest rock surface (at most "
                      f"{ANCHOR_GAP_TOL} m)")
    return Anchor(aid, (pos[0], pos[1]), normal, fn, ft, sn, st)


def _check_id(rd: _Reader, field: str, aid: str, seen: set[str],
              normalised: dict[str, str]) -> None:
    """An anchor id is visible text, unique even once Unicode-normalised (NFC): an empty id,
    U+202E (which reverses the text after it) or 'e' + U+0301 beside 'é' would name anchors
    a reader cannot tell apart in a plan, a summary or an error."""
    if not aid.strip():
        raise rd.fail(field, f"an anchor id must not be empty or only spaces, got {aid!r}")
    if not aid.isprintable():  # control, format (bidi, zero-width) and separator characters
        bad = next(c for c in aid if not c.isprintable())
        raise rd.fail(field, f"anchor id {aid!r} holds the invisible or control character "
                      f"U+{ord(bad):04X} ({unicodedata.category(bad)}); use visible text")
    key = unicodedata.normalize("NFC", aid)
    if aid in seen or key in normalised:
        same = "" if normalised.get(key, aid) == aid else (  # escaped: they print alike
            f" ({aid!a}: the same as {normalised[key]!a} once Unicode-normalised)")
        raise rd.fail(field, f"duplicate anchor id {aid!r}{same}")
    seen.add(aid)
    normalised[key] = aid


def _check_goal(rd: _Reader, rock: Rock, goal: np.ndarray, tolerance: float) -> None:
    """The goal's position must be free space (the body's centre goes there); the message says
    when the whole tolerance disc is rock as well."""
    if not rock.polygons or not rock.contains(goal):
        return
    depth = float(rock.distance(goal))
    where = f"goal {[float(v) for v in goal]} is inside rock ({depth:.3f} m from the surface)"
    if depth >= tolerance:
        where += f", and so is its whole tolerance disc (radius {tolerance:g} m)"
    raise rd.fail("goal.position", f"{where}: the body's centre cannot go there; put the goal "
                  "in free space")


def load_scenario(path: str | Path, check_start: bool = True) -> Scenario:
    """Read and validate a scenario file; raises ScenarioError (never a bare parser error)."""
    data = read_yaml_file(path)
    return scenario_from_dict(data, str(path), check_start=check_start)


def checked_scenario(scn: Scenario, source: str, check_start: bool = False) -> Scenario:
    """A Scenario object (its fields the caller's to replace) read again as its file would be:
    a NaN start or an unknown stance id raises ScenarioError naming `source` and the field,
    before a planner or numpy meets it; `check_start` also checks that the start stance holds
    the robot, as `load_scenario` does. The object's own source is kept for the messages that
    name the cave."""
    try:
        data = scn.to_dict()
        checked = scenario_from_dict(data, source, check_start=False)
        if checked.robot != scn.robot:  # `robot` replaced, not its overrides: read it whole
            data["robot"] = scn.robot.to_dict()
            checked = scenario_from_dict(data, source, check_start=False)
        if check_start:  # the robot's own, once it is read
            checked = scenario_from_dict(data, source, check_start=True)
    except (TypeError, ValueError, AttributeError, RecursionError) as e:
        if isinstance(e, ScenarioError):
            raise
        raise ScenarioError(source, "(top level)", f"not a scenario's values: {e}") from None
    return dataclasses.replace(checked, source=scn.source if isinstance(scn.source, str)
                               else source)


def read_yaml_file(path: str | Path, error: type[ScenarioError] = ScenarioError) -> Any:
    """The YAML document of a file, read within rb_drake.input_files' bounds; a missing,
    unreadable, oversized or non-regular file, bad YAML, an alias or a duplicate key raises
    `error` (ScenarioError or a subclass) naming the file and the field, line or "(file)"."""
    try:
        return load_yaml(read_text(path))
    except InputFileError as e:
        raise error(str(path), e.field, e.reason) from None


def scenario_to_yaml(scn: Scenario) -> str:
    return yaml.safe_dump(scn.to_dict(), sort_keys=False, default_flow_style=None, width=100)


def bundled_caves() -> dict[str, Path]:
    """The caves shipped with the package, by name."""
    folder = Path(__file__).parent / "data" / "caves"
    return {p.stem: p for p in sorted(folder.glob("*.yaml"))}
