"""The plan file as typed objects: `Plan` and its parts, and the conversion to and from JSON.

Every stage shares the plan: the planner builds it, `rbp check` verifies it, the simulator and
the rig run it, the replanners continue it. Its parts are frozen dataclasses here, one per
object of the file, each with `from_dict` (a schema-valid JSON object; numbers are kept as read,
so that a plan read and written again hashes the same) and `to_dict` (the JSON object, fields
in the file's order, optional fields omitted when absent). The JSON Schema of the file
(`plan_schema.json`) is generated from these classes (`planning.plan_schema_gen`): each field's
`metadata["schema"]` adds its bounds and description to what its type says, so the schema and
the code cannot drift apart.

The robot is stored once: `Plan.robot`. Format `reachbot-plan/1` also stored it under
`scenario.robot`; reading such a file keeps that copy in `Plan.scenario_robot` (the verifier's
`robot` rule compares the two) and writes it back, so an old file round-trips unchanged.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from planning.search_outcome import Quality, Stop
from rb_drake.errors import MAX_SEED

if TYPE_CHECKING:
    from rb_drake.scenario import Scenario

FORMAT = "reachbot-plan/2"
FORMATS = ("reachbot-plan/1", FORMAT)  # what the reader accepts
STAGES = ("footstep", "seed_body", "scp_body", "seed_reach", "scp_reach", "total")

Planner = Literal["rbp", "naive"]
PhaseKind = Literal["body", "reach"]


def spec(default: Any = dataclasses.MISSING, **schema: Any) -> Any:
    """A dataclass field whose JSON Schema adds `schema` (bounds, description, items, ...) to
    what its type says; `default` makes the field optional in the file."""
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata={"schema": schema})
    return dataclasses.field(default=default, metadata={"schema": schema})


MAYBE4 = {"$ref": "#/$defs/maybe4"}  # 4 numbers or nulls (plan_schema_gen.COMMON)
FORCE4 = {"$ref": "#/$defs/force4"}  # 4 tensions (N) or nulls, each within MAX_FORCE
# Physically meaningful magnitudes of a plan's numbers (docs/formats.md), refused beyond at
# reading so that nothing overflows later (a pose of 1e300 gave hundreds of warnings in the
# simulator). The same as rb_drake's scenario and robot bounds (tests/test_plan.py checks).
MAX_COORDINATE = 1e4  # m for positions and steps, rad for angles (rb_drake.scenario)
MAX_FORCE = 1e6       # N for tensions, N m for torques (rb_drake.params)
MAX_TIME = 1e7        # s: a plan's times (115 days; a climb takes minutes)
# rbp plan --dt's range, and a plan's time_step: the planner's steps (at most `limits.step`,
# 0.1 m, and `turn_step`, 0.1 rad) every 0.25 s keep within rule `speed` (planning.verify_climb,
# 0.4 m/s and rad/s; its plans at 0.1 s on demo-crevasse and rockfall-3, at 0.05 s on shaft-1 and
# at 0.02 s on demo-shaft failed every rbp simulate trial, docs/model.md "How fast a plan
# moves") and a 5 cm step takes at most a minute (rbp.commands.plan)
MIN_TIME_STEP, MAX_TIME_STEP = 0.25, 60.0
# The longest wait between successive steps (planning.plan_file.check_times): the simulator and
# the rig sample a plan over its time, so a plan stretched in time (a step a day apart) must be
# refused at reading, not run out of memory later.
MAX_STEP_GAP = MAX_TIME_STEP
# m/s and rad/s: the nominal speeds of a footstep plan's body phases (planning.plan.build_plan),
# which may take longer than MAX_STEP_GAP for a long move
BODY_SPEED = 0.1
TURN_SPEED = 0.2
# m/s: the free gripper's nominal speed in a footstep plan's reach (planning.plan.reach_duration),
# half of rule speed's limit so that a long reach still passes `rbp check`
GRIPPER_SPEED = 0.2
COORDINATE = {"type": "number", "minimum": -MAX_COORDINATE, "maximum": MAX_COORDINATE}


def _tuple(value: Any) -> Any:
    """JSON arrays as tuples (nested too): the parts stay immutable and compare by value."""
    return tuple(_tuple(v) for v in value) if isinstance(value, list) else value


def _list(value: Any) -> Any:
    return [_list(v) for v in value] if isinstance(value, tuple) else value


class Part:
    """The JSON conversion shared by the parts of a plan: fields map one to one to keys;
    `NESTED` names the fields that hold parts (or lists of parts), and `ALWAYS` the optional
    fields written even when None (they are `null` in the file, not absent)."""

    NESTED: ClassVar[dict[str, type[Part]]] = {}
    ALWAYS: ClassVar[frozenset[str]] = frozenset()
    OPEN: ClassVar[frozenset[str]] = frozenset()  # mapping fields kept as plain dicts

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Any:
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name not in data:
                continue
            value = data[f.name]
            part = cls.NESTED.get(f.name)
            if part is not None and value is not None:
                value = (tuple(part.from_dict(v) for v in value) if isinstance(value, list)
                         else part.from_dict(value))
            elif f.name in cls.OPEN and value is not None:
                value = dict(value)
            else:
                value = _tuple(value)
            kwargs[f.name] = value
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if value is None and f.default is None and f.name not in self.ALWAYS:
                continue
            if isinstance(value, Part):
                value = value.to_dict()
            elif isinstance(value, tuple) and value and isinstance(value[0], Part):
                value = [v.to_dict() for v in value]
            elif isinstance(value, dict):
                value = _plain(value)
            else:
                value = _list(value)
            out[f.name] = value
        return out


def _plain(value: Any) -> Any:
    """A copy of an open mapping (scenario, robot, config) as plain JSON values."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


@dataclasses.dataclass(frozen=True, kw_only=True)
class Ramp(Part):
    """A release or attach ramp step (`planning.ramps`): the share of `boom`'s limb its
    shoulder carries."""

    boom: int = spec(minimum=0, maximum=3)
    share: float = spec(minimum=0, maximum=1)
    DESCRIPTION: ClassVar[str] = ("a release or attach ramp step: the share of boom's limb its "
                                  "shoulder carries")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Step(Part):
    """One configuration: time, body pose, each boom's tension and grasp probability (None for
    a free boom), the configuration's probability; in a reach phase the free tip and its
    shoulder's torque."""

    t: float = spec(minimum=0, maximum=MAX_TIME)
    pose: tuple[float, ...] = spec(items=COORDINATE, minItems=3, maxItems=3)
    tension: tuple[float | None, ...] = spec(ref="force4")
    p_grasp: tuple[float | None, ...] = spec(ref="maybe4")
    p_success: float = spec(minimum=0, maximum=1)
    free_tip: tuple[float, ...] | None = spec(None, ref="point")
    shoulder_torque: float | None = spec(None, minimum=-MAX_FORCE, maximum=MAX_FORCE)
    ramp: Ramp | None = spec(None)
    NESTED: ClassVar[dict[str, type[Part]]] = {"ramp": Ramp}

    def replace(self, **changes: Any) -> Step:
        return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True, kw_only=True)
class Motion(Part):
    """A trajectory phase's record of its seed and what SCP and easing made of it, per step
    where a list (the final dwell repeats the last)."""

    seed_method: str = spec()
    seed_p_success: tuple[float, ...] = spec(items={"type": "number", "minimum": 0,
                                                    "maximum": 1})
    seed_tension: tuple[tuple[float | None, ...], ...] = spec(items=FORCE4)
    seed_effort: tuple[float, ...] = spec()
    effort: tuple[float, ...] = spec()
    optimised: bool = spec()
    improved: bool = spec()
    scp_status: str = spec()
    scp_iterations: int = spec(minimum=0)
    eased: int | None = spec(None, description="planning.easing: the easing's strength")
    slowed: float | None = spec(None, description="planning.easing: the slow-down factor")
    inertial_excess: float | None = spec(None, description=(
        "planning.easing: N by which the tensions that also accelerate the body and the free "
        "limb along the executed smooth path leave the tension bounds"))
    inertial_dip: float | None = spec(None, description=(
        "planning.easing: log P by which those tensions take a grasp below its holding's "
        "least planned P (what p_path counts of it)"))


@dataclasses.dataclass(frozen=True, kw_only=True)
class Phase(Part):
    """A body phase (4-stance, the body moving) or a reach phase (3-stance, the free gripper
    moving from `from_anchor` to `to_anchor` at a fixed pose)."""

    kind: PhaseKind = spec()
    stance: tuple[str | None, ...] = spec(minItems=4, maxItems=4)
    free_boom: int | None = spec(minimum=0, maximum=3)
    from_anchor: str | None = spec(None)
    to_anchor: str | None = spec(None)
    steps: tuple[Step, ...] = spec(minItems=1)
    motion: Motion | None = spec(None)
    NESTED: ClassVar[dict[str, type[Part]]] = {"steps": Step, "motion": Motion}
    EXTRA: ClassVar[dict[str, Any]] = {
        "if": {"properties": {"kind": {"const": "reach"}}},
        "then": {"required": ["from_anchor", "to_anchor"],
                 "properties": {"free_boom": {"type": "integer"},
                                "steps": {"items": {"required": ["free_tip",
                                                                 "shoulder_torque"]}}}},
        "else": {"properties": {"free_boom": {"type": "null"}}},
    }



@dataclasses.dataclass(frozen=True, kw_only=True)
class SearchPoint(Part):
    """An anytime search's improvement: when, the cost and bound then, expansions so far."""

    seconds: float = spec()
    cost: float = spec()
    lower_bound: float = spec()
    expansions: int = spec()


@dataclasses.dataclass(frozen=True, kw_only=True)
class SearchRecord(Part):
    """How the footstep search ended (`planning.plan.search_record`)."""

    stop: Stop = spec()
    expansions: int | None = spec(None, minimum=0)
    transitions_tested: int | None = spec(None, minimum=0)
    cost: float | None = spec(None, minimum=0,
                              description="the route's search cost (planning.search_cost)")
    min_success: float | None = spec(
        None, exclusiveMinimum=0, exclusiveMaximum=1,
        description="rbp plan --min-success: the route has the fewest regrasps of those whose "
                    "predicted success exp(-cost) is at least this; with stop noroute, none is")
    lower_bound: float | None = spec(None, minimum=0, description="anytime search: the "
                                     "optimal cost is at least this")
    first_cost: float | None = spec(None, minimum=0)
    bound: float | None = spec(None, nullable=True, minimum=1,
                               description="cost / lower_bound: the route's cost is at most "
                                           "this times the optimum's")
    quality: Quality | None = spec(None)
    history: tuple[SearchPoint, ...] | None = spec(None)
    peak_memory_mb: float | None = spec(None, minimum=0, description="the planning process's "
                                        "peak resident memory when the search ended, MiB")
    kept_memory_mb: float | None = spec(None, minimum=0, description="the most lattice work the "
                                        "search kept at once, MiB (capped by "
                                        "footstep.search_memory_mb)")
    refined: tuple[tuple[float, ...], ...] | None = spec(
        None, items={"type": "array", "items": {"type": "number", "exclusiveMinimum": 0,
                                                "maximum": 360}, "minItems": 2, "maxItems": 2},
        maxItems=8,
        description="the lattices [position step m, angle step deg] searched after "
                    "footstep.lattice found no route, coarse to fine; the last one answered "
                    "(planning.refinement)")
    NESTED: ClassVar[dict[str, type[Part]]] = {"history": SearchPoint}
    DESCRIPTION: ClassVar[str] = "how the footstep search ended (optional)"

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        if self.lower_bound is not None and "bound" not in out:
            out["bound"] = None  # written with the bound, null when it is 0
            order = [f.name for f in dataclasses.fields(self)]
            out = dict(sorted(out.items(), key=lambda kv: order.index(kv[0])))
        return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class Partial(Part):
    """A partial climb (`rbp plan --partial`): no route reached the goal, and the plan climbs to
    the expanded stance nearest it."""

    reached_stance: tuple[str, ...] = spec(minItems=4, maxItems=4, description="the stance "
                                           "the climb ends in (its last phase's)")
    goal_distance_m: float = spec(minimum=0, description="that stance's distance from the "
                                  "goal: its anchors' centroid to the goal's centre "
                                  "(planning.search_cost.centroid_distance), the measure of "
                                  "the failed search's reason")
    start_distance_m: float = spec(minimum=0, description="the start stance's, by the same "
                                   "measure")
    DESCRIPTION: ClassVar[str] = ("a partial climb (rbp plan --partial): no route reached the "
                                  "goal; the plan climbs to the expanded stance nearest it "
                                  "(success stays false)")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Limits(Part):
    """The largest change between successive trajectory steps (`planning.plan.step_limits`)."""

    step: float = spec(exclusiveMinimum=0, maximum=MAX_COORDINATE)
    turn_step: float = spec(exclusiveMinimum=0, maximum=MAX_COORDINATE)
    DESCRIPTION: ClassVar[str] = ("the largest change between successive trajectory steps "
                                  "(full plans; optional when reading)")

    def as_dict(self) -> dict[str, float]:
        return {"step": self.step, "turn_step": self.turn_step}


@dataclasses.dataclass(frozen=True, kw_only=True)
class Start(Part):
    """Where a continuation (a replan after a failed grasp) starts, instead of the scenario's
    start."""

    pose: tuple[float, ...] = spec(items=COORDINATE, minItems=3, maxItems=3)
    stance: tuple[str, ...] = spec(minItems=4, maxItems=4)
    DESCRIPTION: ClassVar[str] = ("where a continuation (a replan after a failed grasp) "
                                  "starts, instead of the scenario's start")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Provenance(Part):
    """How the plan was made, enough to make it again (`rbp plan --from-plan`)."""

    rbp_version: str = spec()
    command: str = spec()
    planner: Planner = spec()
    motion: bool = spec()
    # the range of --seed (rb_drake.errors.MAX_SEED): -1 was read, though --seed -1 is not
    seed: int = spec(minimum=0, maximum=MAX_SEED)
    scenario_source: str = spec()
    config: dict[str, Any] = spec(required=["footstep", "seed", "scp"],
                                  description="the PipelineConfig (planning.config_io)")
    threads: int | None = spec(None, minimum=1, description="the most threads the compiled "
                               "search kernels could use (RBP_THREADS, or the cores numba "
                               "sees; fewer while other processes held cores)")
    cores: int | None = spec(None, minimum=1, description="the cores of the machine it ran on")
    load: float | None = spec(None, minimum=0, description="the machine's load average over "
                              "the last minute when the plan was made (this run included): "
                              "its times are read against it")
    OPEN: ClassVar[frozenset[str]] = frozenset({"config"})
    DESCRIPTION: ClassVar[str] = ("how the plan was made, enough to make it again (rbp plan "
                                  "--from-plan); optional when reading")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Verified(Part):
    """The stamp of `rbp check --stamp` (`planning.plan_file`)."""

    sha256: str = spec()
    verifier: str = spec()
    DESCRIPTION: ClassVar[str] = "the stamp of rbp check --stamp: the hash of the rest of the file"


@dataclasses.dataclass(frozen=True, kw_only=True)
class Plan(Part):
    """A plan file: the summary (success, probabilities, regrasps), how it was made (timing,
    search, provenance), the cave and robot it is for, and its phases. `scenario` and `robot`
    are the file forms of rb_drake's scenario (without its robot) and robot (`plan_scenario`
    turns them into a Scenario); `scenario_robot` is the second copy of the robot that format
    `reachbot-plan/1` kept under `scenario.robot`, None in a plan of this format."""

    format: str = spec(enum=list(FORMATS))
    planner: Planner = spec()
    success: bool = spec()
    reason: str = spec(description="why the plan failed; empty on success")
    p_min: float | None = spec(minimum=0, maximum=1, description="the lowest configuration "
                               "probability of the climb; null when the plan failed (a "
                               "partial plan: its partial climb's)")
    p_path: float | None = spec(minimum=0, maximum=1, description="the climb's success "
                                "probability; null when the plan failed (a partial plan: its "
                                "partial climb's)")
    p_grasps: float | None = spec(None, nullable=True, minimum=0, maximum=1,
                                  description="p_path without the per-regrasp attach term "
                                              "(optional); null when the plan failed, as "
                                              "p_path is")
    regrasps: int = spec(minimum=0)
    timing: dict[str, float] = spec(required=list(STAGES),
                                    additionalProperties={"type": "number", "minimum": 0},
                                    description="seconds spent per stage")
    search: SearchRecord | None = spec(None)
    partial: Partial | None = spec(None)
    scenario: dict[str, Any] = spec(ref="scenario")
    robot: dict[str, Any] = spec(ref="robot")
    phases: tuple[Phase, ...] = spec()
    time_step: float | None = spec(None, minimum=MIN_TIME_STEP, maximum=MAX_TIME_STEP,
                                   description="s between trajectory steps (full plans)")
    limits: Limits | None = spec(None)
    start: Start | None = spec(None)
    provenance: Provenance | None = spec(None)
    verified: Verified | None = spec(None)
    scenario_robot: dict[str, Any] | None = dataclasses.field(default=None, compare=True,
                                                               metadata={"file": False})
    # `p_grasps` left out of an older file (not null): kept out when written again, so that the
    # file's stamp holds, and not checked by the verifier (rule `summary`), as before
    p_grasps_absent: bool = dataclasses.field(default=False, metadata={"file": False})
    ALWAYS: ClassVar[frozenset[str]] = frozenset({"p_grasps"})
    NESTED: ClassVar[dict[str, type[Part]]] = {
        "search": SearchRecord, "partial": Partial, "phases": Phase, "limits": Limits,
        "start": Start,
        "provenance": Provenance, "verified": Verified}
    OPEN: ClassVar[frozenset[str]] = frozenset({"timing", "scenario", "robot"})
    DESCRIPTION: ClassVar[str] = ("A climb planned by rbp (or the naive baseline). Units SI, "
                                  "angles in radians unless the name ends in _deg.")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Plan:
        """The plan of a schema-valid plan-file object, of either format."""
        scenario = dict(data["scenario"])
        inner = scenario.pop("robot", None)
        plan = super().from_dict(dict(data, scenario=scenario))
        if isinstance(inner, Mapping):
            inner = dict(inner)
        return dataclasses.replace(plan, scenario_robot=inner,
                                   p_grasps_absent="p_grasps" not in data)

    def to_dict(self) -> dict[str, Any]:
        """The plan-file object; a plan read from a `reachbot-plan/1` file gets its layout
        back (the robot under `scenario` too), so that its stamp still holds."""
        out = super().to_dict()
        out.pop("scenario_robot", None)
        out.pop("p_grasps_absent", None)
        if self.p_grasps_absent and self.p_grasps is None:
            del out["p_grasps"]
        if self.scenario_robot is not None:
            scenario = out["scenario"]
            keys = list(scenario)
            at = keys.index("gravity") + 1 if "gravity" in keys else len(keys)
            items = list(scenario.items())
            items.insert(at, ("robot", _plain(self.scenario_robot)))
            out["scenario"] = dict(items)
        return out

    def replace(self, **changes: Any) -> Plan:
        return dataclasses.replace(self, **changes)

    def failed(self, reason: str) -> Plan:
        """This plan as a failure for `reason`: its summary probabilities (p_path, p_min,
        p_grasps) null, since a failed plan is not climbed; `regrasps` stays the count of the
        route's regrasps, and the phases stay for a picture of where it went."""
        return dataclasses.replace(self, success=False, reason=reason, p_path=None, p_min=None,
                                   p_grasps=None)

    def upgraded(self) -> Plan:
        """This plan in the current format: the robot stored once (`robot`)."""
        return dataclasses.replace(self, format=FORMAT, scenario_robot=None)


def planner_of(name: str) -> Planner:
    """`name` as a plan's planner ("rbp" or "naive"); another name raises ValueError."""
    if name == "rbp":
        return "rbp"
    if name == "naive":
        return "naive"
    raise ValueError(f"planner must be one of ('rbp', 'naive'), got {name!r}")


def plan_of(plan: Plan | Mapping[str, Any]) -> Plan:
    """`plan` as a Plan: a plan-file object (schema-valid) is converted, a Plan returned as is.
    For the stages that still accept either while their callers move to the model."""
    return plan if isinstance(plan, Plan) else Plan.from_dict(plan)


def plan_dict(plan: Plan | Mapping[str, Any]) -> dict[str, Any]:
    """`plan` as a plan-file object (the file boundary)."""
    return plan.to_dict() if isinstance(plan, Plan) else dict(plan)


def plan_scenario(plan: Plan | Mapping[str, Any], source: str = "<plan>",
                  check_start: bool = False) -> Scenario:
    """The scenario a plan was made for, rebuilt from the plan: its cave with the plan's robot
    (`robot`, never the copy a `reachbot-plan/1` file keeps under `scenario.robot`). The one
    place a plan becomes a Scenario (rbp check, the simulator, the rig, rbp plan --from-plan).
    A malformed scenario or robot raises ScenarioError naming the field as it is in the file
    (`robot.body_mass`, `scenario.anchors[2].position`)."""
    from rb_drake.scenario import ScenarioError, scenario_from_dict

    if isinstance(plan, Plan):
        data, robot = dict(plan.scenario), plan.robot
    else:
        data, robot = dict(plan["scenario"]), plan["robot"]
    data["robot"] = robot
    try:
        return scenario_from_dict(data, source, check_start=check_start)
    except ScenarioError as e:
        field = e.field if e.field.startswith("robot") else f"scenario.{e.field}"
        raise ScenarioError(source, field, e.reason) from None


def scenario_robot_problem(plan: Plan) -> str | None:
    """What is wrong with a `reachbot-plan/1` file's second robot, under `scenario` (it must be
    the plan's robot), or None: rule `robot` of `rbp check`, and `rbp plan --from-plan`'s
    refusal (it planned with the top-level robot without a word)."""
    from rb_drake.params import ParamError, robot_from_dict

    block = plan.scenario_robot
    if block is None:
        return None
    try:
        inner = robot_from_dict(block)
    except ParamError as e:
        return f"scenario.robot.{e.field}: {e.reason}"
    a, b = inner.to_dict(), robot_from_dict(plan.robot).to_dict()
    if a == b:
        return None
    names = [name for name in a if a[name] != b[name]]
    return f"the robot under scenario differs from the top-level robot in {names}"
