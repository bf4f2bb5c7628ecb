"""The allowed range of every field of the planner's configuration dataclasses.

`planning.config_io` reads a configuration (an `rbp plan --config` file, or a plan's
`provenance.config`) by its fields' types; this table adds what a type cannot say: the numbers
each field may take (finite unless infinity is documented to mean "none"; counts whole numbers
from 1 or 0 to a maximum that keeps the work and the memory bounded; steps and lengths positive
with a least value, so that nothing divides by zero or allocates by a tiny step) and the words
a string field may be. A value outside its range is refused when the file is read, naming the
file and the field, instead of crashing or hanging the planner later. docs/formats.md lists
these ranges (`range_lines`; tests/test_plan_config.py keeps the two equal, and checks that
every field of every configuration dataclass has its entry here).

The table is keyed by class name so that reading a configuration does not import the planner.
Checks that join two fields (segments' commit <= lookahead, the lattice's angle step dividing
180 deg) are `joint_problem`'s, which the dataclasses' `__post_init__` call too.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from typing import Any

from rb_drake.errors import MAX_SEED, key_text

INF = math.inf


@dataclasses.dataclass(frozen=True)
class Range:
    """Numbers from `lo` to `hi` (inclusive unless `open_lo`), `unit` for the message; whole
    numbers if `integer`. A tuple field's items each in range, and at most `items` of them
    (at least 1). Infinity passes only where `hi` is infinite."""

    lo: float
    hi: float
    unit: str = ""
    integer: bool = False
    open_lo: bool = False
    open_hi: bool = False
    items: int = 0  # a tuple field: its most items (0: not a tuple)

    def problem(self, value: Any) -> str:
        """Why `value` (already of the field's type) is out of range, or ""."""
        if self.items:
            if not 1 <= len(value) <= self.items:
                return f"must list 1 to {self.items} numbers, got {len(value)}"
            for v in value:
                if self.problem_of(v):
                    return f"{self.problem_of(v)} (in {list(value)})"
            return ""
        return self.problem_of(value)

    def problem_of(self, value: Any) -> str:
        above = value > self.lo if self.open_lo else value >= self.lo
        below = value < self.hi if self.open_hi else value <= self.hi
        if above and below and (math.isfinite(value) or self.hi == INF):
            return ""
        return f"must be {self.text()}, got {value!r}"

    def text(self) -> str:
        kind = "a whole number" if self.integer else "a number"
        lo, hi = _number(self.lo), _number(self.hi)
        unit = f" {self.unit}" if self.unit else ""
        if self.hi == INF:
            return f"{kind} {'above' if self.open_lo else 'of at least'} {lo}{unit} (or .inf)"
        if self.open_lo or self.open_hi:
            return (f"{kind} {'above' if self.open_lo else 'of at least'} {lo} and "
                    f"{'below' if self.open_hi else 'at most'} {hi}{unit}")
        return f"{kind} from {lo} to {hi}{unit}"


@dataclasses.dataclass(frozen=True)
class Choice:
    """One of `words`."""

    words: tuple[str, ...]

    def problem(self, value: Any) -> str:
        return "" if value in self.words else f"must be {self.text()}, got {value!r}"

    def text(self) -> str:
        return f"one of {', '.join(self.words)}"


def _number(x: float) -> str:
    if math.isfinite(x) and x == int(x) and abs(x) >= 1e4:
        return f"{int(x):,}"
    return f"{x:g}"


def count(lo: int, hi: int) -> Range:
    return Range(lo, hi, integer=True)


def positive(lo: float, hi: float, unit: str = "") -> Range:
    return Range(lo, hi, unit)


PI = round(math.pi, 4)
FIELDS: dict[str, dict[str, Range | Choice]] = {
    "PipelineConfig": {
        "dt": Range(0.25, 60.0, "s"),  # plan_model.MIN_TIME_STEP .. a minute
        "motion_retries": count(0, 100),
    },
    "FootstepConfig": {
        "search": Choice(("hybrid", "complete", "sampled")),
        "sampled_expansions": count(1, 10_000_000),
        "heuristic_weight": Range(0.0, 10_000.0),
        "fallback_weight": Range(0.0, 10_000.0),
        "fallback_after": Range(0.0, 1.0),
        "ordering": Choice(("distance", "travel", "distance+travel")),
        "min_success": Range(0.0, 1.0, open_lo=True, open_hi=True),
        "candidates_per_boom": count(1, 1000),
        "max_expansions": count(1, 1_000_000_000),
        "refine": count(0, 4),  # each level 8x the poses of the one before
        "search_memory_mb": Range(1.0, 10_000_000.0, "MiB"),
        "expansions_per_metre": Range(0.0, 1_000_000.0),
        "time_limit": Range(0.0, 1_000_000.0, "s", open_lo=True),
        "goal_samples": count(1, 100_000),
        "polish_rounds": count(0, 1000),
        "seed": count(0, MAX_SEED),
    },
    "LatticeConfig": {  # as planning.lattice's POSITION_STEP_RANGE and ANGLE_STEP_RANGE
        "position_step": positive(0.005, 0.5, "m"),
        "angle_step_deg": positive(0.5, 45.0, "deg"),
    },
    "AnytimeConfig": {
        "weights": Range(0.0, 10_000.0, open_lo=True, items=32),
        "target_bound": Range(1.0, 10_000.0),
        "improve_factor": Range(0.0, 10_000.0),
        "improve_min": count(0, 1_000_000_000),
        "corridor": Range(0.0, 10_000.0, "m"),
    },
    "RepairConfig": {
        "window": count(1, 1000),
        "stride": count(1, 1000),
        "window_expansions": count(1, 100_000_000),
        "passes": count(1, 1000),
    },
    "SegmentConfig": {  # a segment commits at least 10 cm: a climb's segments stay few
        "min_climb": positive(0.1, 10_000.0, "m"),
        "lookahead": positive(0.1, 1000.0, "m"),
        "commit": positive(0.1, 1000.0, "m"),
        "tolerance": positive(0.01, 100.0, "m"),
    },
    "TransitionConfig": {
        "release_candidates": count(1, 1_000_000),
        "release_samples": count(1, 100_000),
        "release_rounds": count(0, 1000),
        "samples": count(1, 100_000),
        "search_rounds": count(0, 1000),
        "refine_rounds": count(0, 1000),
        "refine_samples": count(1, 100_000),
        "elite": count(1, 100_000),
        "spread": positive(0.001, 100.0, "m"),
        "phi_range": Range(0.0, PI, "rad"),
        "max_reach_violation": Range(0.0, 1000.0, "m"),
        "hopeless_violation": Range(0.0, 1000.0, "m"),
        "patience": count(1, 1000),
    },
    # Steps of 5 mm / 5 mrad at least: a 100 m phase is then 20,000 poses at most. A reach's
    # local sampling builds an offset-to-offset table of (rounds x samples)^2: at these maxima
    # 1601^2 (about 100 MB); a body detour of more than 20,000 poses is not tried
    # (body_seeds.MAX_DETOUR_POSES). All maxima together plan demo-shaft in under 1 GB.
    "SeedConfig": {
        "step": positive(0.005, 1.0, "m"),
        "turn_step": positive(0.005, 1.0, "rad"),
        "local_rounds": count(0, 16),  # the spread doubles each round
        "local_samples": count(1, 100),
        "local_spread": positive(0.001, 10.0, "m"),
        "local_modes": count(1, 100),
        "ompl_checks": count(1, 1_000_000),  # seed_common.MAX_OMPL_CHECKS
        "ompl_time": Range(0.0, 86_400.0, "s", open_lo=True),
        "ompl_range": positive(0.001, 100.0),
        "ompl_margin": Range(0.0, 100.0, "m"),
        "arc_heights": Range(0.0, 10.0, items=32),
        "arc_min_height": Range(0.0, 10.0, "m"),
    },
    "ScpConfig": {
        "solver": Choice(("clarabel", "osqp")),
        "max_iterations": count(1, 10_000),
        "robustness_weight": Range(0.0, 1e6),
        "dynamics_weight": Range(0.0, 1e6),
        "smoothness_weight": Range(0.0, 1e6),
        "radius_pose": positive(1e-4, 100.0, "m"),
        "radius_angle": positive(1e-4, 10.0, "rad"),
        "radius_velocity": positive(1e-4, INF),  # .inf, the default: no trust region
        "radius_tension": positive(1e-3, 1e6, "N"),
        "radius_min": Range(0.0, 1.0, open_lo=True),
        "radius_max": Range(1.0, 1e6),
        "grow": Range(1.0, 100.0),
        "shrink": Range(0.0, 1.0, open_lo=True),
        "accept_ratio": Range(0.0, 1.0),
        "grow_ratio": Range(0.0, 1.0),
        "shrink_ratio": Range(0.0, 1.0),
        "curvature_floor": Range(0.0, 1e6),
        "curvature_scale_min": Range(0.0, 1.0, open_lo=True),
        "tolerance": positive(1e-12, 1e3),
    },
}


def field_problem(cls: type, name: str, value: Any) -> str:
    """Why `value` is out of range for field `name` of configuration class `cls`, or ""
    (also for None, and for fields and classes this table does not hold)."""
    spec = FIELDS.get(cls.__name__, {}).get(name)
    return "" if spec is None or value is None else spec.problem(value)


# Where each class's fields are in a configuration file
SECTIONS = {"PipelineConfig": "", "FootstepConfig": "footstep.",
            "LatticeConfig": "footstep.lattice.",
            "AnytimeConfig": "footstep.anytime.", "RepairConfig": "footstep.repair.",
            "SegmentConfig": "footstep.segments.", "TransitionConfig": "footstep.transition.",
            "SeedConfig": "seed.", "ScpConfig": "scp."}


def range_lines() -> list[str]:
    """docs/formats.md's table rows: | `key` | range |, in this table's order."""
    return [f"| `{SECTIONS[cls]}{name}` | {spec.text()} |"
            for cls, fields in FIELDS.items() for name, spec in fields.items()]


# The fields that take true or false, so need no range (section_keys lists them with FIELDS')
SWITCHES = {"PipelineConfig": ("optimise",), "AnytimeConfig": ("restart",),
            "TransitionConfig": ("ignore_grasps",), "ScpConfig": ("keep_seed_floor",)}


def section_keys(section: str) -> list[str]:
    """The keys a configuration file may give in `section` (a SECTIONS value: "" for the top
    level, "footstep." and so on): its class's fields (this table's and its switches) and its
    sub-sections (tests/test_plan_config.py holds them to the dataclasses)."""
    cls = next(name for name, prefix in SECTIONS.items() if prefix == section)
    subsections = {prefix[len(section):-1] for prefix in SECTIONS.values()
                   if prefix.startswith(section) and prefix.count(".") == section.count(".") + 1}
    return sorted(set(FIELDS.get(cls, {})) | set(SWITCHES.get(cls, ())) | subsections)


def unknown_key(data: Any, section: str = "") -> tuple[str, str] | None:
    """(field, reason) of the first key of configuration `data` that no class has, as
    `planning.config_io` words it, or None: `rbp plan` checks this before it imports the
    planner (0.6 s and 170 MB), so that a misspelt key costs a line, not the imports."""
    if not isinstance(data, dict):
        return None  # the reader names what it expected
    keys = section_keys(section)
    for key, value in data.items():
        field = f"{section}{key}"
        if key not in keys:
            return f"{section}{key_text(key)}", f"unknown key; expected one of {keys}"
        if f"{field}." in SECTIONS.values() and (found := unknown_key(value, f"{field}.")):
            return found
    return None





# The fields that may be null (`X | None` in their dataclass; tests/test_hostile_round10.py
# holds this to the classes), the sections among them too
NULLABLE = {"SeedConfig": ("ompl_time",), "AnytimeConfig": ("improve_factor", "corridor"),
            "FootstepConfig": ("fallback_weight", "anytime", "min_success", "repair",
                               "segments", "max_expansions", "search_memory_mb", "time_limit")}


def range_problem(data: Any, section: str = "") -> tuple[str, str] | None:
    """(field, reason) of the first value of configuration `data` of the wrong type or outside
    its range, in `planning.config_io`'s words, or None: checked before the planner's imports
    (`rbp plan --config`, and --from-plan's provenance.config, took 1.5-2.1 s and 170 MB a
    refusal with them), and by `rbp check` (which said ok to a null or a string that
    --from-plan refused). A section's check of two keys together is `joint_problem`'s."""
    if not isinstance(data, dict):
        return None
    cls = next(name for name, prefix in SECTIONS.items() if prefix == section)
    for key, value in data.items():
        field = f"{section}{key}"
        nullable = key in NULLABLE.get(cls, ())
        if f"{field}." in SECTIONS.values():
            if not isinstance(value, dict) and not (value is None and nullable):
                return field, f"expected a mapping, got {describe(value)}"
            if found := range_problem(value, f"{field}."):
                return found
            continue
        if value is None and nullable:
            continue
        spec = FIELDS.get(cls, {}).get(key)
        if key in SWITCHES.get(cls, ()):
            if not isinstance(value, bool):
                return field, f"expected true or false, got {describe(value)}"
            continue
        if isinstance(spec, Choice):
            if not isinstance(value, str):
                return field, f"expected a string, got {describe(value)}"
        elif isinstance(spec, Range) and spec.items:
            if not isinstance(value, list | tuple):
                return field, f"expected a list, got {describe(value)}"
            converted = []
            for i, item in enumerate(value):
                number, reason = _as_number(item)
                if reason:
                    return f"{field}[{i}]", reason
                converted.append(number)
            value = tuple(converted)
        elif isinstance(spec, Range) and spec.integer:
            if isinstance(value, bool) or not isinstance(value, int):
                return field, f"expected an integer, got {describe(value)}"
        elif isinstance(spec, Range):
            value, reason = _as_number(value)
            if reason:
                return field, reason
        if spec is not None and (problem := spec.problem(value)):
            return field, problem
    return None


def angle_count(step_deg: float) -> int | None:
    """Orientations of a lattice of angle step `step_deg` over the whole circle (an even
    number), or None when the step does not divide 180 deg (`LatticeConfig.angle_count`)."""
    n = round(360.0 / step_deg)
    return None if n % 2 or abs(n * step_deg - 360.0) > 1e-9 else n


def angle_step_problem(step_deg: float) -> str:
    """Why a lattice's angle step (in its range) is refused, or ""."""
    return "" if angle_count(step_deg) is not None else f"must divide 180 deg, got {step_deg}"


def commit_problem(commit: float, lookahead: float) -> str:
    """Why a segment's `commit` is refused beside its `lookahead`, or ""."""
    return "" if commit <= lookahead else (f"must be at most lookahead ({lookahead:g} m), got "
                                           f"{commit:g}")


def sub_goal_problem(tolerance: float, lookahead: float) -> str:
    """Why a segment's sub-goal `tolerance` is refused beside its `lookahead`, or "": a
    sub-goal disc holding the segment's own start is reached where it begins (the segments
    then moved on a commit at a time, searching from the start again each time: 37 s under a
    20 s time limit on a 20 m crevasse)."""
    return "" if tolerance < lookahead else (f"must be below lookahead ({lookahead:g} m), "
                                             f"got {tolerance:g}: a sub-goal disc holding the "
                                             "segment's start is reached where it begins")


# planning.segmented.SegmentConfig's defaults (tests/test_hostile_round14.py holds them equal)
SEGMENT_DEFAULTS = {"lookahead": 4.0, "commit": 2.0, "tolerance": 0.6}


def joint_problem(data: Any) -> tuple[str, str] | None:
    """(field, reason) of the first check joining two keys that configuration `data` (a whole
    configuration, once `range_problem` found nothing) fails, or None: the lattice's angle
    step dividing 180 deg and segments' commit at most their lookahead, as their dataclasses
    check them, without the planner's imports (`rbp check` said ok to a plan's
    provenance.config that --from-plan then refused)."""
    footstep = data.get("footstep") if isinstance(data, dict) else None
    if not isinstance(footstep, dict):
        return None
    lattice = footstep.get("lattice")
    if isinstance(lattice, dict) and "angle_step_deg" in lattice:
        step, _ = _as_number(lattice["angle_step_deg"])
        if problem := angle_step_problem(step):
            return "footstep.lattice.angle_step_deg", problem
    segments = footstep.get("segments")
    if isinstance(segments, dict) and segments.keys() & SEGMENT_DEFAULTS.keys():
        commit, lookahead, tolerance = (_as_number(segments.get(key, SEGMENT_DEFAULTS[key]))[0]
                                        for key in ("commit", "lookahead", "tolerance"))
        if problem := commit_problem(commit, lookahead):
            return "footstep.segments.commit", problem
        if problem := sub_goal_problem(tolerance, lookahead):
            return "footstep.segments.tolerance", problem
    return None


def search_problem(footstep: Any) -> tuple[str, str] | None:
    """(field, reason) when a FootstepConfig asks its search for what only the complete search
    does, or None: `min_success` with the sampled or hybrid search (whose sampled routes
    ignore it: a plan below the probability asked for said success: true), `repair` with the
    sampled one. Checked once the command line's flags are applied (`--search` overrides a
    file's `footstep.search`)."""
    if footstep.min_success is not None and footstep.search != "complete":
        return ("footstep.min_success", f"is the complete search's (footstep.search complete): "
                f"the {footstep.search} search's routes ignore it, and one below "
                f"{footstep.min_success:g} would be returned as a success")
    if footstep.repair is not None and footstep.search == "sampled":
        return ("footstep.repair", "is the complete search's (footstep.search complete or "
                "hybrid): the sampled search ignores it")
    return None


DEFAULT_DT = 0.5  # s: planning.pipeline.PipelineConfig.dt's default (with 5 cm steps, 0.1 m/s)


def recorded_speed_problem(config: Any) -> str | None:
    """`speed_problem` of a configuration mapping (a plan's provenance.config), the defaults
    for the keys it leaves out, without the planner's imports (rbp check does without them).
    Call it once `range_problem` found nothing."""
    from types import SimpleNamespace

    from planning.seed_common import SeedConfig

    if not isinstance(config, dict):
        return None
    seed = config.get("seed")
    seed = seed if isinstance(seed, dict) else {}
    default = SeedConfig()
    return speed_problem(SimpleNamespace(
        dt=config.get("dt", DEFAULT_DT),
        seed=SimpleNamespace(step=seed.get("step", default.step),
                             turn_step=seed.get("turn_step", default.turn_step))))


def speed_problem(config: Any) -> str | None:
    """Why a PipelineConfig's `dt` is too short for its `seed.step`/`seed.turn_step`, or None:
    the planner's steps, up to STEP_STRETCH times them every `dt`, must keep within rule
    `speed` (planning.verify_climb) for its plans to pass `rbp check`. One check for `rbp
    plan`, the API's `rbp.plan` and `rbp check` of a plan's provenance.config (the API
    skipped it and returned plans that failed `rbp check`)."""
    from planning.verify_climb import (
        BODY_SPEED_MAX,
        GRIPPER_SPEED_MAX,
        STEP_STRETCH,
        TURN_SPEED_MAX,
    )

    dt, step, turn = config.dt, config.seed.step, config.seed.turn_step
    # a free gripper's steps are held to seed.step too (`limits.step`)
    need = STEP_STRETCH * max(step / min(BODY_SPEED_MAX, GRIPPER_SPEED_MAX),
                              turn / TURN_SPEED_MAX)
    if dt >= need * (1 - 1e-9):
        return None
    return (f"steps of up to {STEP_STRETCH:g} x seed.step {step:g} m and seed.turn_step "
            f"{turn:g} rad every {dt:g} s exceed rule speed ({BODY_SPEED_MAX:g} m/s, "
            f"{TURN_SPEED_MAX:g} rad/s); give dt at least {need:.6g}")


def _as_number(value: Any) -> tuple[float, str]:
    """`value` as a float field reads it (planning.config_io), or the reader's reason not."""
    if isinstance(value, str) and value.strip().lower() in ("inf", "+inf", "-inf"):
        return float(value), ""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return 0.0, f"expected a number, got {describe(value)}"
    if isinstance(value, int) and abs(value) > sys.float_info.max:
        return 0.0, f"expected a number within the float range, got {describe(value)}"
    if math.isnan(value):
        return 0.0, f"expected a number (not nan), got {describe(value)}"
    return float(value), ""


def describe(value: Any) -> str:
    """A value as the configuration errors show it: its type and its repr, cut to 60
    characters; a null as the files write it (it was `NoneType None`)."""
    if value is None:
        return "null"
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"
