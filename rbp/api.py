"""rbp's Python front door: load or generate a cave, plan a climb, check, simulate and draw it,
and read and write plan files; `import rbp` exports these functions (`rbp.plan`, ...).

    import rbp

    cave = rbp.load_scenario("demo-shaft")
    plan = rbp.plan(cave)                  # a planning.plan_model.Plan
    assert rbp.check(plan) == []           # the verifier of `rbp check` finds nothing
    rbp.write_plan(plan, "climb.json")
    result = rbp.simulate(plan)            # one simulated climb (trials=N: Monte Carlo)
    rbp.draw(plan, "climb.png")
    view = rbp.meshcat(result)             # the climb replayed in Meshcat: open view.url

The command line (`rbp plan`, `rbp check`, ...) is built on the same functions. Only the
standard library is imported here at the top: each function imports what it needs when
called, so `import rbp` stays instant (no Drake, no numba) and the command line starts fast.
Mistakes in the input raise `rb_drake.errors.RbpInputError` (a `ScenarioError` for a cave,
a `PlanFileError` for a plan file), whose message names the file, the field and the reason.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from planning.footsteps import FootstepPlan
    from planning.pipeline import PipelineConfig
    from planning.plan_model import Plan
    from rb_drake.generate import CaveConfig
    from rb_drake.scenario import Scenario
    from systems.diagram import SimulationRecord
    from systems.montecarlo import MonteCarloResult

__all__ = ["MeshcatView", "SimulationResult", "bundled_caves", "check", "draw",
           "generate_scenario", "import_scenario", "load_scenario", "meshcat", "plan",
           "read_plan", "simulate", "write_plan"]

PLAN_DPI = 110  # `rbp plan`'s pictures
SCENARIO_DPI = 120  # `rbp scenario show`'s default
MAX_TRIALS = 1_000_000  # Monte Carlo climbs of one plan; more is a sweep's job


def _whole(value: Any, field: str, lo: int, hi: int) -> int:
    """`value` if it is a whole number (not a bool) from `lo` to `hi`, the command line's range;
    else RbpInputError naming `field` (1.5 or 10**30 ended in numpy's TypeError or ValueError)."""
    import operator

    from rb_drake.errors import RbpInputError

    try:
        number = None if isinstance(value, bool) else operator.index(value)  # numpy's ints too
    except TypeError:
        number = None
    if number is None or not lo <= number <= hi:
        raise RbpInputError(f"must be a whole number from {lo:,} to {hi:,}, got {value!r:.60}",
                            field=field)
    return number


def _flag(value: Any, field: str) -> bool:
    """`value` if it is a bool (numpy's too), else RbpInputError naming `field`: "no" was taken
    as true."""
    from rb_drake.errors import RbpInputError

    # numpy's bool is `numpy.bool` since numpy 2 (`bool_` before): np.False_ was refused
    if not isinstance(value, bool) and not (type(value).__module__ == "numpy"
                                            and type(value).__name__ in ("bool", "bool_")):
        raise RbpInputError(f"expected True or False, got {value!r:.60}", field=field)
    return bool(value)


def _number(value: Any, field: str) -> float:
    """`value` as a float if it is a real number (not a bool); else RbpInputError on `field`."""
    import numbers

    from rb_drake.errors import RbpInputError

    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise RbpInputError(f"must be a number, got {value!r:.60}", field=field)
    return float(value)


def _point(value: Any, field: str, size: int) -> Any:
    """`value` as a tuple of `size` numbers (None stays None); else RbpInputError on `field`
    (a third coordinate of a 2-D start was dropped silently, strings ended in TypeError)."""
    from rb_drake.errors import RbpInputError

    if value is None:
        return None
    try:
        items = list(value)
    except TypeError:
        items = []
    if isinstance(value, str | bytes) or len(items) != size:
        raise RbpInputError(f"expected {size} numbers, got {value!r:.60}", field=field)
    return tuple(_number(v, f"{field}[{i}]") for i, v in enumerate(items))


def _path(value: Any, field: str, what: str = "a file path") -> str | Path:
    """`value` if it is a str or Path, else RbpInputError naming the argument `field` (pathlib's
    TypeError on 5, bytes or None told nothing of which argument)."""
    from rb_drake.errors import RbpInputError

    if not isinstance(value, str | Path):
        raise RbpInputError(f"expected {what} (str or Path), got {type(value).__name__}",
                            field=field)
    return value


def _output(path: Any, picture: bool = False) -> Path:
    """`path` as an output file, refused as the command line refuses one (RbpInputError naming
    it: a folder, an unwritable place, a picture's suffix matplotlib cannot write)."""
    from rb_drake.errors import RbpInputError
    from rb_drake.files import output_problem, picture_format_problem

    _path(path, "path")
    problem = output_problem(path) or (picture_format_problem(path) if picture else None)
    if problem is not None:
        raise RbpInputError(problem, file=str(path))
    return Path(path)


def bundled_caves() -> dict[str, Path]:
    """The caves shipped with rbp, by name (what `rbp scenario list` prints): name -> file."""
    from rb_drake.scenario import bundled_caves as caves

    return caves()


def load_scenario(path_or_name: str | Path, check_start: bool = True) -> Scenario:
    """A cave from a scenario file (YAML, `reachbot-scenario/1`), or a bundled cave by name
    (`bundled_caves()`; "rig" is the lab rig's frame). A file of that name wins over a bundled
    cave. `check_start` also checks that the start stance holds the robot. Raises
    `rb_drake.scenario.ScenarioError` (file, field, reason) for a bad or missing file."""
    from rb_drake.scenario import load_scenario as load

    _path(path_or_name, "path_or_name", "a file path or a bundled cave's name")
    check_start = _flag(check_start, "check_start")
    spec = Path(path_or_name)
    try:
        exists = spec.exists()
    except (OSError, ValueError):  # a name too long, a NUL byte: the reader names the file;
        # a current folder that cannot be searched (`sudo -u` from a private home) refused
        # `demo-shaft` itself, "cannot read: Permission denied": a bundled cave's name stands
        exists = str(path_or_name) not in (*bundled_caves(), "rig")
    if not exists:
        caves = bundled_caves()
        if str(path_or_name) in caves:
            return load(caves[str(path_or_name)], check_start=check_start)
        if str(path_or_name) == "rig":  # the lab rig's frame (systems.rig)
            from systems.rig import RIG_SCENARIO

            return load(RIG_SCENARIO, check_start=check_start)
    return load(path_or_name, check_start=check_start)  # as given: Path drops a last "/."


def generate_scenario(kind: str = "shaft", seed: int = 0,
                      length: tuple[float, float] = (4.5, 5.0), anchor_density: float = 3.0,
                      config: CaveConfig | None = None) -> Scenario:
    """A seeded random cave, as `rbp scenario generate` makes it: `kind` is "shaft" (a
    vertical shaft to climb), "crevasse" or "rockfall" (a passage to cross); `length` the range
    its height or length is drawn from in m (default the experiments' 4.5 to 5 m), with
    `anchor_density` anchors per metre of rock. The same arguments give the same cave. Give
    `config` (an `rb_drake.generate.CaveConfig`) for the other knobs; `length` and
    `anchor_density` then override it. Raises `RbpInputError` for a bad kind or length and
    `CaveGenerationError` when no draw has a feasible start stance."""
    from rb_drake.errors import MAX_SEED, RbpInputError
    from rb_drake.generate import (
        CaveConfig,
        config_problem,
        density_problem,
        generate_cave,
        length_problem,
        values_problem,
    )

    if not isinstance(length, tuple | list) or len(length) != 2:
        raise RbpInputError(f"expected (MIN, MAX) in m, got {length!r:.60}", field="length")
    lo, hi = (_number(x, "length") for x in length)
    if (problem := length_problem(lo, hi)) is not None:
        raise RbpInputError(problem, field="length")
    anchor_density = _number(anchor_density, "anchor_density")
    if (problem := density_problem(anchor_density)) is not None:
        raise RbpInputError(problem, field="anchor_density")
    if (problem := values_problem(hi, anchor_density)) is not None:
        raise RbpInputError(problem)  # up front: a 1000 m cave takes minutes to draw
    seed = _whole(seed, "seed", 0, MAX_SEED)
    if config is not None and not isinstance(config, CaveConfig):
        raise RbpInputError("expected an rb_drake.generate.CaveConfig or None, got "
                            f"{type(config).__name__}", field="config")
    cfg = dataclasses.replace(config or CaveConfig(), anchor_density=anchor_density,
                              length=(lo, hi))
    if (bad := config_problem(cfg)) is not None:  # before any draw (a NaN gravity took 15 s)
        raise RbpInputError(bad[1], field=f"config.{bad[0]}")
    return generate_cave(kind, seed, cfg)


def import_scenario(path: str | Path, *, unit: str | None = None, scale: float = 1.0,
                    simplify: float = 0.0, anchor_density: float = 3.0, seed: int = 0,
                    start: tuple[float, float] | None = None,
                    goal: tuple[float, float] | None = None, name: str | None = None,
                    plane_origin: tuple[float, float, float] | None = None,
                    plane_normal: tuple[float, float, float] | None = None,
                    resolution: float | None = None) -> Scenario:
    """A cave from a file of rock, as `rbp scenario import` makes it: a polygon drawing
    (GeoJSON .geojson/.json, DXF .dxf, SVG .svg) or a mesh or point cloud (.stl, .obj, .ply)
    cut by the plane through `plane_origin` with normal `plane_normal` (a point cloud's points
    within `resolution` m of it outlined, bridging gaps up to twice that; None: from the
    cloud's density). Coordinates are in `unit` (m, cm, mm, in, ft; None: the unit a DXF
    declares in $INSUNITS, else m) times `scale`; outlines are simplified to `simplify` m.
    Anchors are placed as `generate_scenario` places them (`anchor_density` per metre, from
    `seed`: the same file and seed, the same cave); `start`
    and `goal` (x, y in m) are chosen when None: the lowest place with a feasible stance and
    the highest free place above it. Needs the extra `rbp[import]`. Raises `RbpInputError`
    (file and reason) for a file that is not closed, simple rock or makes no cave."""
    from rb_drake.errors import MAX_SEED, RbpInputError
    from rb_drake.terrain.import_cave import ImportOptions, import_cave, name_text_problem

    for text, field in ((unit, "unit"), (name, "name")):
        if text is not None and not isinstance(text, str):
            raise RbpInputError(f"must be a string or None, got {text!r:.60}", field=field)
    if name is not None and (problem := name_text_problem(name)) is not None:
        raise RbpInputError(problem, field="name")
    return import_cave(_path(path, "path"), ImportOptions(
        unit=unit, scale=_number(scale, "scale"), simplify=_number(simplify, "simplify"),
        anchor_density=_number(anchor_density, "anchor_density"),
        seed=_whole(seed, "seed", 0, MAX_SEED), start=_point(start, "start", 2),
        goal=_point(goal, "goal", 2), name=name,
        plane_origin=_point(plane_origin, "plane_origin", 3),
        plane_normal=_point(plane_normal, "plane_normal", 3),
        resolution=None if resolution is None else _number(resolution, "resolution")))


def plan(scenario: Scenario | str | Path, config: PipelineConfig | None = None, *,
         planner: str = "rbp", footsteps_only: bool = False, progress: bool = False,
         footsteps_done: Callable[[FootstepPlan], None] | None = None,
         partial: bool = False) -> Plan:
    """Plan a climb of `scenario` (a Scenario, or what `load_scenario` takes), as `rbp plan`
    does: the footstep search, then a seed and SCP per phase (`planning.pipeline.plan_climb`).

    `config` is a `planning.pipeline.PipelineConfig` (its footstep search: `.footstep`, a
    `planning.footsteps.FootstepConfig`); None for the defaults. `planner` is "rbp" or
    "naive" (the baseline, footsteps only). `footsteps_only` stops after the footstep plan
    (phases hold only the transition poses: seconds, not minutes). `progress` shows the
    progress line on stderr (on a terminal only). `footsteps_done` is called with each footstep
    plan (a failed one explains where the search went: `planning.figures.search_figure`).
    `partial` (rbp plan --partial; the rbp planner's complete search, the whole pipeline): when
    no route reaches the goal, the plan climbs to the expanded stance nearest it
    (`planning.pipeline.partial_climb`), with `success` False and `partial` saying where it
    ends and how far from the goal.

    Returns the plan (`planning.plan_model.Plan`); when no climb is found it has
    `success` False and the `reason`, and is still a plan to write and draw."""
    from planning.config_io import ConfigError, checked_config
    from planning.config_ranges import search_problem
    from planning.footsteps import expansion_budget
    from planning.pipeline import PLANNERS, PipelineConfig, plan_climb
    from rb_drake.errors import RbpInputError
    from rbp.progress import SearchProgress

    if planner not in PLANNERS:
        raise RbpInputError(f"must be one of {PLANNERS}, got {planner!r}", field="planner")
    footsteps_only = _flag(footsteps_only, "footsteps_only")
    partial = _flag(partial, "partial")
    progress = _flag(progress, "progress")
    if footsteps_done is not None and not callable(footsteps_done):  # failed after the search
        raise RbpInputError(f"expected a callable or None, got {type(footsteps_done).__name__}",
                            field="footsteps_done")
    if partial and (planner != "rbp" or footsteps_only):
        raise RbpInputError("a partial climb is flown through the whole pipeline of the rbp "
                            "planner: not with the naive planner or footsteps only",
                            field="partial")
    if config is not None and not isinstance(config, PipelineConfig):
        raise RbpInputError(f"expected a planning.pipeline.PipelineConfig or None, got "
                            f"{type(config).__name__}", field="config")
    # held to a configuration file's ranges before any work (dt=0 failed after the search)
    cfg = PipelineConfig() if config is None else checked_config(config)
    if planner == "rbp" and (found := search_problem(cfg.footstep)):  # returned it ignored
        raise ConfigError("config", *found)
    if partial and cfg.footstep.search == "sampled":  # it returned no partial climb, silently
        raise RbpInputError("a partial climb is the complete search's (footstep.search "
                            "'complete' or 'hybrid'): the sampled search gives none",
                            field="partial")
    if partial and cfg.footstep.min_success is not None:  # it returned none, silently
        raise RbpInputError("a partial climb is the complete search's: the search for the "
                            "fewest regrasps within footstep.min_success gives none",
                            field="partial")
    # its start checked as rbp plan's is: a cave loaded with check_start=False, or a start
    # replaced, was searched and answered "no route" where the command line names the start
    scn = _scenario(scenario, "scenario", check_start=True)
    budget = (expansion_budget(scn, cfg.footstep) if cfg.footstep.search == "complete"
              else cfg.footstep.max_expansions)
    with SearchProgress(f"{planner} on {scn.name}", budget, quiet=not progress) as bar:
        if footsteps_only:
            from planning.baseline import plan_naive
            from planning.footsteps import plan_footsteps
            from planning.plan import build_plan

            fp = (plan_footsteps(scn, cfg.footstep, progress=bar.search) if planner == "rbp"
                  else plan_naive(scn, cfg.footstep))
            if footsteps_done is not None:
                footsteps_done(fp)
            return build_plan(scn, fp, planner, {"footstep": fp.seconds, "total": fp.seconds})
        return plan_climb(scn, planner, cfg, progress=bar.phase, footstep_progress=bar.search,
                          footsteps_done=footsteps_done, partial=partial)


def _scenario(scenario: Any, field: str, check_start: bool = False) -> Scenario:
    """`scenario` as a Scenario: a Scenario (checked again by the scenario reader, its file
    named "(FIELD argument)"; `check_start`: its start stance too), or what `load_scenario`
    takes (which checks the start stance)."""
    from rb_drake.errors import RbpInputError
    from rb_drake.scenario import Scenario, checked_scenario

    if isinstance(scenario, Scenario):
        return checked_scenario(scenario, f"({field} argument)", check_start)
    if not isinstance(scenario, str | Path):
        raise RbpInputError("expected a Scenario, a scenario file or a bundled cave's name, got "
                            f"{type(scenario).__name__}", field=field)
    return load_scenario(scenario)


def _same_cave(plan: Plan, scn: Scenario) -> bool:
    """Whether `plan` was made for the cave and robot of `scn` (the plan keeps both)."""
    cave = scn.to_dict(resolved=True)
    del cave["robot"]
    return plan.scenario == cave and plan.robot == scn.robot.to_dict()


def check(plan: Plan | dict[str, Any], scenario: Scenario | str | Path | None = None,
          progress: bool = False) -> list[str]:
    """What `rbp check` finds wrong with `plan`, one line each ("WHERE: RULE: WHAT"); an empty
    list when the plan holds. Every configuration is recomputed from scratch against the cave
    and robot the plan carries (`planning.check.check_plan`); given a `scenario` (a Scenario,
    or what `load_scenario` takes), the plan must also have been made for that cave and robot.
    `progress` shows a progress line on stderr (on a terminal only, after a second). A plan
    dict is read as a plan file is: a malformed one raises PlanFileError naming the field."""
    from planning.plan_file import plan_from
    from rbp.progress import CheckProgress
    from systems.plan_check import plan_problems

    model = plan_from(plan)
    scenario = None if scenario is None else _scenario(scenario, "scenario")
    problems = []
    if scenario is not None and not _same_cave(model, scenario):
        problems.append(f"scenario: the plan was made for another cave or robot than "
                        f"{scenario.name} ({scenario.source})")
    with CheckProgress("checking the plan", quiet=not _flag(progress, "progress")) as bar:
        problems += plan_problems(model, "<plan>", progress=bar)[0]  # named as simulate's
    return problems


def read_plan(path: str | Path) -> Plan:
    """A plan file (`rbp plan`'s JSON), validated against its schema (NaN and Infinity
    refused); raises `planning.plan_file.PlanFileError` naming the file, the field and the
    reason."""
    from planning.plan_file import PlanFileError
    from planning.plan_file import read_plan as read

    try:
        return read(_path(path, "path"))
    except PlanFileError as e:  # named as load_scenario names its file
        raise PlanFileError(str(e.field), e.reason, file=str(path)) from None


def write_plan(plan: Plan | dict[str, Any], path: str | Path) -> Path:
    """Write `plan` to `path` (a .json name) as a plan file (JSON, checked against the schema
    first; written to a temporary file and renamed, so never half-written); returns the path. A
    plan dict is checked as a plan file is read (PlanFileError naming the field), and a path
    that cannot be written (a folder, an unwritable place, another suffix than .json) raises
    RbpInputError naming it, before writing."""
    from planning.plan import write_plan as write
    from planning.plan_file import plan_from
    from rb_drake.errors import RbpInputError

    out = _output(path)
    if out.suffix.lower() != ".json":  # as `rbp plan -o`: a plan under cave.yaml or a .png
        raise RbpInputError("a plan file is JSON: give a name ending in .json, got "
                            f"{out.suffix or 'no suffix'}", file=str(path))
    model = plan_from(plan)
    return write(model, out)


@dataclasses.dataclass(frozen=True)
class SimulationResult:
    """A simulated climb: the deterministic run (`record`, sampled every 20 ms), its tracking
    errors, the success probability the simulated forces imply (`p_sim`) beside the plan's
    (`p_path`), and the Monte Carlo estimate when trials were asked for (`monte_carlo`)."""

    record: SimulationRecord
    p_path: float | None
    p_sim: float
    tracking: dict[str, float]  # max_position_error, rms_position_error (m), max_heading_error
    monte_carlo: MonteCarloResult | None = None

    @property
    def success(self) -> bool:
        """Whether the deterministic run climbed to the end of the plan (no grasp failed)."""
        return self.record.failure is None

    def to_json(self) -> dict[str, Any]:
        """The numbers `rbp simulate --json` writes (without the plan's file name)."""
        out: dict[str, Any] = {"trials": 0, "successes": None, "rate": None, "ci95": None,
                               "p_path": self.p_path, "p_sim": self.p_sim, "seed": None,
                               "tracking": self.tracking}
        if self.monte_carlo is not None:
            out |= self.monte_carlo.to_json()
            out["tracking"] = self.tracking
        return out


def simulate(plan: Plan | dict[str, Any], *, trials: int = 0, seed: int = 0,
             replan: str | None = None, plant: str = "full") -> SimulationResult:
    """Execute `plan` in the Drake simulation `rbp simulate` uses (the full plant, grasps
    monitored): one deterministic climb, then, with `trials` > 0, that many stochastic
    executions (grasp strengths and attach failures drawn from `seed`) for a Monte Carlo
    estimate of the success rate with its 95 % Wilson interval (`result.monte_carlo`).
    `replan` continues failed trials on a new plan, as `rbp simulate --replan` does: "retry"
    re-grasps the same anchor, "footsteps" plans again from where the robot is (slow); the
    climbs it saves are in `result.monte_carlo.replanning`. `plant="body"` simulates the body
    alone (faster, less faithful).

    The plan is not verified here: `check(plan)` first (the command line refuses a plan that
    fails it). A partial climb (`plan(..., partial=True)`) is flown to its end, as `rbp
    rig-run` flies it (a trial succeeds when it gets there). Raises `RbpInputError` for a plan
    without a route or one that cannot be flown, and `systems.diagram.SimulationError` when
    the solver fails."""
    import numpy as np

    from planning.plan_file import plan_from
    from rb_drake.errors import MAX_SEED, RbpInputError
    from systems.diagram import ClimbSimulator
    from systems.montecarlo import FootstepReplanner, monte_carlo, retry_replanner
    from systems.trajectory import PlanTrajectory, plan_scenario

    trials = _whole(trials, "trials", 0, MAX_TRIALS)  # `rbp simulate --trials`'s range
    seed = _whole(seed, "seed", 0, MAX_SEED)
    if replan not in (None, "retry", "footsteps"):
        raise RbpInputError(f"must be None, 'retry' or 'footsteps', got {replan!r}",
                            field="replan")
    if replan is not None and trials == 0:
        raise RbpInputError("replanning continues failed trials; give trials > 0",
                            field="replan")
    model = plan_from(plan)  # a dict as a plan file: a NaN pose aborted Drake
    if not model.success and model.partial is None:  # a partial climb is flown to its end
        raise RbpInputError(f"the plan found no route ({model.reason}); nothing to simulate",
                            field="success")
    scn = plan_scenario(model)
    traj = PlanTrajectory(model, scn)
    simulator = ClimbSimulator(scn, plant=plant)
    record = simulator.run(traj)
    err, heading = record.position_error, record.heading_error
    tracking = {"max_position_error": float(err.max()),
                "rms_position_error": float(np.sqrt(np.mean(err**2))),
                "max_heading_error": float(heading.max())}
    replanner: Callable[..., Any] | None = None
    if replan == "retry":
        replanner = retry_replanner
    elif replan == "footsteps":
        replanner = FootstepReplanner(seed=seed)
    mc = (monte_carlo(record, trials, seed, replanner, replan or "", simulator)
          if trials > 0 else None)
    return SimulationResult(record, model.p_path, record.implied_p_path(), tracking, mc)


def draw(scenario_or_plan: Scenario | Plan | dict[str, Any], path: str | Path,
         dpi: int | None = None) -> Path:
    """Draw a cave or a plan into `path` (.png, .pdf, .svg), the picture the command line
    writes: for a Scenario, `rbp scenario show`'s (the robot in its start stance); for a plan,
    `rbp plan`'s snapshots of the climb. `dpi` defaults to theirs (120 and 110); it must be
    20 to 600, as the command line's --dpi. Returns the path written. Raises RbpInputError for
    a bad path or dpi, and PlanFileError for a malformed plan dict."""
    from planning.plan_file import plan_from
    from planning.plan_model import Plan, plan_scenario
    from rb_drake.errors import RbpInputError
    from rb_drake.files import MAX_DPI, MIN_DPI, atomic_save_figure
    from rb_drake.scenario import Scenario

    if not isinstance(scenario_or_plan, Scenario | Plan | dict):
        raise RbpInputError("expected a Scenario, a Plan or a plan-file object (a dict), got "
                            f"{type(scenario_or_plan).__name__}", field="scenario_or_plan")
    out = _output(path, picture=True)
    if dpi is not None:
        dpi = _whole(dpi, "dpi", MIN_DPI, MAX_DPI)  # 100000 ran out of memory in matplotlib
    if isinstance(scenario_or_plan, Scenario):
        from rb_drake.draw import scenario_figure

        fig = scenario_figure(_scenario(scenario_or_plan, "scenario_or_plan"))
        return atomic_save_figure(fig, out, dpi=dpi or SCENARIO_DPI)
    from planning.figures import snapshots_figure

    data = plan_from(scenario_or_plan, "scenario_or_plan").to_dict()
    fig = snapshots_figure(plan_scenario(data), data)
    return atomic_save_figure(fig, out, dpi=dpi or PLAN_DPI)


@dataclasses.dataclass
class MeshcatView:
    """A Meshcat server showing a cave or a climb: open `url` in a browser (127.0.0.1 only).
    The server runs while this object (or its `server`) is referenced: `close()`, leaving a
    `with` block or dropping the last reference stops it. `frames` is the replay's length
    (0 for a cave alone)."""

    url: str
    server: Any  # pydrake.geometry.Meshcat; None once closed
    frames: int = 0

    def save_html(self, path: str | Path) -> Path:
        """The scene and its replay as one self-contained HTML page (as `rbp simulate --html`),
        written atomically; returns the path."""
        from systems.meshcat_view import save_html

        if self.server is None:
            raise RuntimeError("this Meshcat view is closed")
        return save_html(self.server, path)

    def close(self) -> None:
        """Stop the server (Drake stops it when its last reference goes; keep none elsewhere)."""
        import gc

        self.server = None
        gc.collect()

    def __enter__(self) -> MeshcatView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def meshcat(what: Scenario | Plan | dict[str, Any] | SimulationResult, *,
            speedup: float = 4.0) -> MeshcatView:
    """Show a cave or a climb in Meshcat, as `rbp simulate --meshcat` does: a Scenario is drawn
    alone; a plan is simulated once (`simulate(plan)`, the deterministic climb) and replayed;
    a `SimulationResult` replays its run without simulating again. The replay runs `speedup`
    times faster than the climb (0.1 at least: Drake numbers a replay's frames as int). The
    server listens on 127.0.0.1 and a free port only (never every interface). Returns a
    `MeshcatView` with the `url` to open; it serves until closed (`view.close()` or `with
    rbp.meshcat(plan) as view:`). Raises `RbpInputError` for a plan that cannot be simulated
    (as `simulate`)."""
    from planning.plan_model import Plan
    from rb_drake.errors import RbpInputError
    from rb_drake.scenario import Scenario
    from systems.meshcat_view import MIN_SPEEDUP, show_climb, show_scenario, start_meshcat

    if not isinstance(what, Scenario | Plan | dict | SimulationResult):  # named as this
        # argument: simulate's refusal named its own, `plan`
        raise RbpInputError("expected a Scenario, a Plan, a plan-file object (a dict) or a "
                            f"SimulationResult, got {type(what).__name__}", field="what")
    speedup = _number(speedup, "speedup")
    if not MIN_SPEEDUP <= speedup < math.inf:  # slower: Drake's frame numbers wrap round
        raise RbpInputError(f"must be {MIN_SPEEDUP:g} or more and finite, got {speedup:g}",
                            field="speedup")
    if isinstance(what, Scenario):
        scn = _scenario(what, "what")
        server = start_meshcat()
        show_scenario(server, scn)
        return MeshcatView(server.web_url(), server)
    # simulated before the server starts: a plan that cannot be flown leaves none behind
    result = what if isinstance(what, SimulationResult) else simulate(what)
    server = start_meshcat()
    frames = show_climb(server, result.record, speedup=speedup)
    return MeshcatView(server.web_url(), server, frames)
