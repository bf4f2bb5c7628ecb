"""`rbp plan`: the planner's configuration (defaults, --config FILE, flags, --from-plan), the
run with its progress line, the plan's provenance, and the pictures.

The configuration is `planning.pipeline.PipelineConfig`, built in layers: its defaults, then a
plan's recorded configuration (--from-plan), then a YAML file (--config), then the flags given
(--seed, --max-expansions, --dt, --no-scp). The plan file records the result under
`provenance` with the rbp version and the command line, so `--from-plan` repeats it exactly.
"""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planning.plan_model import MAX_TIME_STEP, MIN_TIME_STEP

if TYPE_CHECKING:
    from planning.footsteps import FootstepPlan
    from planning.pipeline import PipelineConfig
    from planning.plan_model import Plan, Provenance
    from rb_drake.scenario import Scenario
    from rbp.commands.common import UserError

# --dt's range, a plan's time_step's (planning.plan_model): the planner's steps keep within
# rule `speed` (`_check_speed`); a step of the plan is at least one of the simulator's plant
# steps (systems.diagram.PLANT_TIME_STEP; below, SCP's dynamics scale as
# 1/dt^2 and its solver fails, and the plan's time stamps, rounded to 1 us, cannot keep the steps
# apart), and a 5 cm step takes at most a minute
MIN_DT, MAX_DT = MIN_TIME_STEP, MAX_TIME_STEP
# Options that set a configuration field: held to the field's range (planning.config_ranges),
# so that a plan's provenance.config is always one --from-plan reads back (a budget of 1e20
# was accepted, written, then refused). --seed, --dt and --min-success have their own checks
# of the same ranges.
OPTION_FIELDS = {"--max-expansions": ("FootstepConfig", "max_expansions"),
                 "--time-limit": ("FootstepConfig", "time_limit")}

# --partial with a configuration's sampled search, which wrote no partial climb
PARTIAL_SAMPLED = ("--partial climbs with the complete search (complete or hybrid), and the "
                   "sampled one gives no partial climb")
# --partial with --min-success (or footstep.min_success), whose search wrote no partial climb
PARTIAL_MIN_SUCCESS = ("the partial climb is the complete search's, and --min-success's search "
                       "(the fewest regrasps within a success probability) gives none: give "
                       "one or the other")

PROVENANCE_KEYS = ("rbp_version", "command", "planner", "motion", "seed", "scenario_source",
                   "config")


def rbp_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("rbp")
    except metadata.PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown"


def check_plan_output(args: argparse.Namespace) -> None:
    """The plan's `-o` and the pictures written beside it, before planning: writable files
    that are none of the command's inputs, and a .json name (`-o cave.yaml` wrote the plan
    over the scenario)."""
    from rbp.commands.common import UserError, check_output

    inputs = {"the scenario's file": args.scenario, "--from-plan's file": args.from_plan,
              "--config's file": args.config}
    out = check_output(args.output, inputs=inputs)
    if out.suffix.lower() != ".json":
        raise UserError(f"{out}: -o: a plan file is JSON: give a name ending in .json, got "
                        f"{out.suffix or 'no suffix'}")
    if args.no_pictures:
        return
    pictures = [out.with_suffix(".png"), out.with_name(f"{out.stem}-search.png")]
    if args.phase_figure is not None:
        pictures.append(out.with_name(f"{out.stem}-phase{args.phase_figure}.png"))
    for picture in pictures:  # a folder there failed after the plan was made
        check_output(picture, "-o's picture", picture=True, inputs=inputs)


def read_plan_inputs(args: argparse.Namespace) -> None:
    """Read the scenario, --from-plan's plan and the --config file (into `args.loaded_scenario`,
    `args.loaded_from_plan`, `args.config_data`) before the planner's modules are imported
    (0.6 s and 170 MB): a near-limit file with an error was refused in 1.1 s and 239 MB, over
    issue 28's 1 s and 200 MB; `rbp scenario check` refused the same in 0.55 s and 100 MB.
    The configurations' keys are checked in `plan_setup`, against the planner's classes."""
    from planning.config_io import ConfigError
    from planning.config_ranges import joint_problem, range_problem, unknown_key
    from rb_drake.scenario import read_yaml_file
    from rbp.commands.common import load_scenario_spec

    check_options(args)
    if args.scenario is not None and not args.from_plan:
        args.loaded_scenario = load_scenario_spec(args.scenario)
    elif args.from_plan and args.scenario is None:
        args.loaded_from_plan = _read_from_plan(Path(args.from_plan))
    if args.config:
        data = read_yaml_file(args.config, ConfigError)
        args.config_data = {} if data is None else data
        if found := (unknown_key(args.config_data) or range_problem(args.config_data)
                     or joint_problem(args.config_data)):
            raise ConfigError(args.config, *found)  # as plan_setup's classes would refuse it
        footstep = args.config_data.get("footstep")
        if args.partial and args.search is None and isinstance(footstep, dict) and \
                footstep.get("search") == "sampled":  # as plan_setup would, before the imports
            raise ConfigError(args.config, "footstep.search", PARTIAL_SAMPLED)


def check_options(args: argparse.Namespace) -> None:
    """The options' own ranges (`plan_setup`'s checks of them, in its words), before the
    planner's imports: `--seed -1` was refused in 1.5 s and 170 MB, `--phase-figure -1` in
    0.3 s."""
    from planning.config_ranges import FIELDS
    from rbp.commands.common import UserError, check_seed

    for flag, (cls, name) in OPTION_FIELDS.items():
        value = getattr(args, name, None)
        if value is not None and (problem := FIELDS[cls][name].problem(value)):
            raise UserError(f"{flag}: {problem}")
    if args.seed is not None:
        check_seed(args.seed, "--seed")
    if args.dt is not None and not MIN_DT <= args.dt <= MAX_DT:
        raise UserError(f"--dt: seconds between trajectory steps must be at least {MIN_DT:g} "
                        f"(rule speed) and at most {MAX_DT:g}, got {args.dt!r}")
    wanted = getattr(args, "min_success", None)
    if wanted is not None and not args.thorough and not 0.0 < wanted < 1.0:
        raise UserError(f"--min-success: must lie strictly between 0 and 1, got {wanted}")
    option_conflict(args, args.planner)


def option_conflict(args: argparse.Namespace, planner: str | None) -> None:
    """Refuse options that contradict each other (UserError naming one), before the planner's
    imports where the command line alone says so (such refusals took 1.1-1.2 s and 172 MB),
    and again in `plan_setup` once --from-plan's planner is known. An option the run would
    silently ignore is refused too: --search sampled with --thorough searched completely,
    --partial with the sampled search (which gives no partial climb) wrote none, and the naive
    planner ignored --thorough, --min-success, --repair, --search, --max-expansions and
    --time-limit."""
    from rbp.commands.common import UserError

    if args.scenario is not None and args.from_plan:
        raise UserError(f"{args.scenario}: (argument): give a scenario or --from-plan, "
                        "not both (the plan holds its scenario)")
    if getattr(args, "min_success", None) is not None and args.thorough:
        raise UserError("--min-success: give it or --thorough, not both (--thorough asks "
                        "for the most robust route, --min-success for the fewest regrasps "
                        "within a success probability)")
    search_flag = ("--thorough" if args.thorough else "--min-success"
                   if getattr(args, "min_success", None) is not None else None)
    if search_flag and args.search not in (None, "complete"):
        raise UserError(f"--search: {search_flag} runs the complete search, not the "
                        f"{args.search} one: give --search complete or leave it out")
    if args.thorough and args.max_expansions is not None:
        raise UserError("--max-expansions: --thorough searches without an expansion budget "
                        "(--time-limit bounds its time): give one or the other")
    partial = getattr(args, "partial", False)
    naive = "--planner naive" if args.planner == "naive" else "--from-plan's naive planner"
    if partial and (planner == "naive" or args.footsteps_only):
        flag = naive if planner == "naive" else "--footsteps-only"
        raise UserError(f"--partial: flies the partial climb through the whole pipeline of the "
                        f"rbp planner, which {flag} leaves out")
    if partial and args.search == "sampled":
        raise UserError("--partial: the partial climb is the complete search's (the default, "
                        "or --search hybrid), which --search sampled leaves out")
    if partial and getattr(args, "min_success", None) is not None:  # it wrote none, silently
        raise UserError(f"--partial: {PARTIAL_MIN_SUCCESS}")
    if planner == "naive":
        given = [flag for flag, on in (
            ("--thorough", args.thorough),
            ("--min-success", getattr(args, "min_success", None) is not None),
            ("--repair", getattr(args, "repair", False)), ("--search", args.search is not None),
            ("--max-expansions", args.max_expansions is not None),
            ("--time-limit", args.time_limit is not None))
            if on]
        if given:
            raise UserError(f"{given[0]}: sets the rbp planner's footstep search, which "
                            f"{naive} does not use")


def plan_setup(args: argparse.Namespace):
    """(scenario, planner, PipelineConfig, motion) for `rbp plan`, from its arguments."""
    from planning.complete_config import AnytimeConfig
    from planning.config_io import config_from_dict, load_config
    from planning.config_ranges import FIELDS, search_problem
    from planning.pipeline import PipelineConfig
    from rbp.commands.common import MAX_SEED, UserError, check_seed, load_scenario_spec

    for flag, (cls, name) in OPTION_FIELDS.items():  # before any work, as a file's would be
        value = getattr(args, name, None)
        if value is not None and (problem := FIELDS[cls][name].problem(value)):
            raise UserError(f"{flag}: {problem}")
    cfg = PipelineConfig()
    planner, motion = args.planner or "rbp", not args.footsteps_only
    option_conflict(args, args.planner)
    if args.from_plan:
        scn, recorded, cfg, partial = _from_plan(Path(args.from_plan),
                                                 getattr(args, "loaded_from_plan", None))
        planner = args.planner or recorded.planner
        option_conflict(args, planner)
        if partial:  # a partial plan is made again partial (the flag is not in the config)
            if not getattr(args, "partial", False) and (args.footsteps_only or planner != "rbp"):
                flag = "--footsteps-only" if args.footsteps_only else "--planner naive"
                raise UserError(f"{flag}: {args.from_plan} is a partial climb, made again "
                                "through the whole pipeline of the rbp planner, which "
                                f"{flag} leaves out")  # it named --partial, never given
            args.partial = True
        motion = recorded.motion and not args.footsteps_only
    elif args.scenario is None:
        raise UserError("scenario: (argument): give a scenario file or bundled cave name, or "
                        "--from-plan PLAN")
    else:
        scn = getattr(args, "loaded_scenario", None) or load_scenario_spec(args.scenario)
    if args.config:
        data = getattr(args, "config_data", None)
        cfg = (load_config(args.config, PipelineConfig, base=cfg) if data is None
               else config_from_dict(PipelineConfig, data, args.config, base=cfg))
    flags: dict[str, Any] = {}
    if args.seed is not None:
        flags["seed"] = args.seed
    if args.max_expansions is not None:  # exactly this budget, whatever the climb's length
        flags["max_expansions"], flags["expansions_per_metre"] = args.max_expansions, 0.0
    if args.search is not None:
        flags["search"] = args.search
    if args.thorough:  # the oracle: complete, no expansion budget, on to the proven optimum
        flags["search"], flags["max_expansions"] = "complete", None
        flags["anytime"] = AnytimeConfig(improve_factor=None)
    if getattr(args, "min_success", None) is not None:
        if not 0.0 < args.min_success < 1.0:
            raise UserError(f"--min-success: must lie strictly between 0 and 1, got "
                            f"{args.min_success}")
        flags["search"], flags["min_success"] = "complete", args.min_success
        if args.max_expansions is None:
            flags["max_expansions"] = None
    if getattr(args, "repair", False):
        from planning.route_repair import RepairConfig

        flags["repair"] = cfg.footstep.repair or RepairConfig()
    if args.time_limit is not None:
        flags["time_limit"] = args.time_limit
    if flags:
        cfg = dataclasses.replace(cfg, footstep=dataclasses.replace(cfg.footstep, **flags))
    if args.dt is not None:
        cfg = dataclasses.replace(cfg, dt=args.dt)
    if args.no_scp:
        cfg = dataclasses.replace(cfg, optimise=False)
    if not MIN_DT <= cfg.dt <= MAX_DT:
        source = "--dt" if args.dt is not None else (
            f"{args.config or args.from_plan or '(configuration)'}: dt")
        raise UserError(f"{source}: seconds between trajectory steps must be at least "
                        f"{MIN_DT:g} (rule speed) and at most {MAX_DT:g}, got {cfg.dt:g}")
    _check_speed(cfg, args)
    if not 0 <= cfg.footstep.seed <= MAX_SEED:  # -1 ended in numpy's traceback
        source = "--seed" if args.seed is not None else (
            f"{args.config or args.from_plan or '(configuration)'}: footstep.seed")
        check_seed(cfg.footstep.seed, source)
    from planning.footsteps import SEARCHES

    if cfg.footstep.search not in SEARCHES:
        source = args.config or args.from_plan or "(configuration)"
        raise UserError(f"{source}: footstep.search: must be one of {', '.join(SEARCHES)}, "
                        f"got {cfg.footstep.search!r}")
    if planner == "rbp" and (found := search_problem(cfg.footstep)):
        source = ("--search" if args.search is not None
                  else args.config or args.from_plan or "(configuration)")
        raise UserError(f"{source}: {found[0]}: {found[1]}")
    if getattr(args, "partial", False) and planner == "rbp" and \
            cfg.footstep.search == "sampled":  # it wrote no partial climb, silently
        source = args.config or args.from_plan or "(configuration)"
        raise UserError(f"{source}: footstep.search: {PARTIAL_SAMPLED}")
    if getattr(args, "partial", False) and planner == "rbp" and \
            cfg.footstep.min_success is not None:  # a configuration's, or a partial --from-plan
        source = ("--min-success" if getattr(args, "min_success", None) is not None
                  else f"{args.config or args.from_plan or '(configuration)'}: "
                  "footstep.min_success")
        raise UserError(f"{source}: {PARTIAL_MIN_SUCCESS}")
    anytime = cfg.footstep.anytime
    if anytime is not None:
        source = args.config or args.from_plan or "(configuration)"
        problem = anytime_problem(anytime)
        if problem:
            raise UserError(f"{source}: footstep.anytime.{problem}")
    wanted = cfg.footstep.min_success
    if wanted is not None and not 0.0 < wanted < 1.0:
        source = args.config or args.from_plan or "(configuration)"
        raise UserError(f"{source}: footstep.min_success: must lie strictly between 0 and 1, "
                        f"or null, got {wanted}")
    from planning.lattice import span_problem

    if problem := span_problem(scn, cfg.footstep.lattice):
        source = args.config or args.from_plan or "(configuration)"
        raise UserError(f"{source}: footstep.lattice.position_step: {problem}")
    return scn, planner, cfg, motion


def anytime_problem(anytime) -> str:
    """What is wrong with an AnytimeConfig ("field: reason"), or "" if nothing."""
    if not anytime.target_bound >= 1.0:
        return f"target_bound: must be 1 (optimal) or more, got {anytime.target_bound}"
    if anytime.improve_factor is not None and not anytime.improve_factor >= 0:
        return f"improve_factor: must be 0 or more, or null, got {anytime.improve_factor}"
    if not anytime.improve_min >= 0:
        return f"improve_min: must be 0 or more, got {anytime.improve_min}"
    if not all(w > 0 for w in anytime.weights):
        return f"weights: must all be positive, got {list(anytime.weights)}"
    if anytime.corridor is not None and not anytime.corridor >= 0:
        return f"corridor: must be 0 or more metres, or null, got {anytime.corridor}"
    return ""


def _from_plan(path: Path, read: tuple[Scenario, Provenance, bool] | None = None
               ) -> tuple[Scenario, Provenance, PipelineConfig, bool]:
    """The scenario, provenance and configuration a plan file was planned with, and whether
    it is a partial plan (`rbp plan --partial`); `read` is `_read_from_plan(path)` if done."""
    scn, recorded, partial = read or _read_from_plan(path)
    return scn, recorded, recorded_config(recorded.config, path), partial


def check_recorded_config(config: Any, path: str | Path) -> None:
    """Refuse (ConfigError naming `provenance.config.FIELD`) a plan's recorded configuration
    with an unknown key or a value out of its range, without the planner's imports: `rbp plan
    --from-plan` before them, and `rbp check` (which said ok to a dt of 1e308 that
    --from-plan refused)."""
    from planning.config_io import ConfigError
    from planning.config_ranges import joint_problem, range_problem, unknown_key

    if found := unknown_key(config) or range_problem(config) or joint_problem(config):
        raise ConfigError(str(path), f"provenance.config.{found[0]}", found[1])
    from planning.config_ranges import recorded_speed_problem

    if problem := recorded_speed_problem(config):
        raise ConfigError(str(path), "provenance.config.dt", problem)


def recorded_config(config: Any, path: Path) -> PipelineConfig:
    """A plan's provenance.config as the PipelineConfig it records, held to a configuration
    file's types and ranges (ConfigError naming `provenance.config.FIELD`)."""
    from planning.config_io import config_from_dict
    from planning.pipeline import PipelineConfig

    return config_from_dict(PipelineConfig, config, str(path), prefix="provenance.config")


def _read_from_plan(path: Path) -> tuple[Scenario, Provenance, bool]:
    """The plan file's scenario and provenance, and whether it is partial: without the
    planner's modules (`read_plan_inputs`)."""
    from planning.plan_model import Plan, plan_scenario, scenario_robot_problem
    from rb_drake.scenario import ScenarioError
    from rbp.commands.common import UserError, read_plan

    plan = Plan.from_dict(read_plan(path))
    if (problem := scenario_robot_problem(plan)) is not None:  # as rbp check's rule robot
        raise UserError(f"{path}: robot: {problem}")
    recorded = plan.provenance
    if recorded is None:
        raise UserError(f"{path}: provenance: missing: the plan does not say how it was made "
                        "(written by an older rbp), so it cannot be repeated")
    check_recorded_config(recorded.config, path)
    try:
        scn = plan_scenario(plan, str(path), check_start=True)
    except ScenarioError as e:
        raise ScenarioError(f"{e.source}: scenario", e.field.removeprefix("scenario."),
                            e.reason) from None
    return scn, recorded, plan.partial is not None


def provenance(scn: Scenario, planner: str, cfg: PipelineConfig, motion: bool,
               argv: list[str] | None) -> Provenance:
    """How a plan was made: enough to make it again (`rbp plan --from-plan`), and the threads
    and load it ran under (its times depend on them)."""
    from planning.config_io import config_to_dict
    from planning.plan_model import Provenance, planner_of
    from rb_drake.errors import utf8_text
    from rb_drake.kernel.threads import run_conditions

    return Provenance(  # file names that are not UTF-8 escaped: the plan must read back
        rbp_version=rbp_version(),
        command=utf8_text(shlex.join(["rbp", *(argv if argv is not None else sys.argv[1:])])),
        planner=planner_of(planner), motion=motion, seed=cfg.footstep.seed,
        scenario_source=utf8_text(scn.source), config=config_to_dict(cfg), **run_conditions())


class SearchRecord:
    """Keeps the footstep plans a run produced (the last one explains a failed search)."""

    def __init__(self) -> None:
        self.last: FootstepPlan | None = None

    def __call__(self, fp: FootstepPlan) -> None:
        self.last = fp


def run_planner(scn: Scenario, planner: str, cfg: PipelineConfig, motion: bool = True,
                quiet: bool = False, record: SearchRecord | None = None,
                partial: bool = False) -> Plan:
    """The whole pipeline (footsteps, then seeds and SCP per phase) -> the plan
    (`rbp.api.plan`, with the progress line unless `quiet`; `partial`: rbp plan --partial)."""
    from rbp.api import plan

    return plan(scn, cfg, planner=planner, footsteps_only=not motion, progress=not quiet,
                footsteps_done=record, partial=partial)


def write_pictures(scn: Scenario, model: Plan, out: Path, phase: int | None,
                   animate: str | None, search: FootstepPlan | None = None,
                   say: Callable[[str], None] = print) -> UserError | None:
    """The snapshots (PLAN.png), the failed search's picture (PLAN-search.png) when the
    footstep search failed, Fig. 6 of phase `phase`, and the animation; `say` tells each
    written (inside an `output_batch`, once they all are). Returns the refusal of a `phase`
    without a trajectory (known only now: the plan and its pictures so far are kept), for
    the caller to raise once they are written."""
    from planning.figures import animate_plan, phase_figure, search_figure, snapshots_figure
    from planning.plan_model import plan_dict
    from rb_drake.errors import one_line
    from rb_drake.files import atomic_save_figure
    from rbp.commands.common import UserError

    plan = plan_dict(model)  # planning.figures draws the plan-file object
    with_motion = [k for k, p in enumerate(model.phases) if p.motion is not None]
    picture = atomic_save_figure(snapshots_figure(scn, plan), out.with_suffix(".png"), dpi=110)
    say(f"wrote {picture}")
    if search is not None and not search.success:
        path = out.with_name(f"{out.stem}-search.png")
        atomic_save_figure(search_figure(scn, search), path, dpi=110)
        say(f"wrote {path}")
    if phase is not None and phase not in with_motion:
        count = len(model.phases)
        return UserError(f"--phase-figure: the plan has {count} phase{'' if count == 1 else 's'}"
                         f" ({out} is written), and phase {phase} has no trajectory; phases "
                         f"with one: {with_motion[:10]}{'...' if len(with_motion) > 10 else ''}")
    if phase is not None:
        fig = out.with_name(f"{out.stem}-phase{phase}.png")
        atomic_save_figure(phase_figure(plan, phase), fig, dpi=110)
        say(f"wrote {fig}")
    if animate and not any(p.steps for p in model.phases):  # a search that found no route
        print(one_line(f"--animate: {animate} not written: the plan has no configurations to "
                       "animate"), file=sys.stderr)
    elif animate:
        animate_plan(scn, plan, animate)
        say(f"wrote {animate}")
    return None


ANIMATION_SUFFIXES = (".gif", ".mp4")


def check_animation(path: str, inputs: dict[str, str | None] | None = None) -> None:
    """`rbp plan --animate PATH` checked before planning: a writable .gif, or an .mp4 with
    ffmpeg installed (the writer is chosen by the suffix)."""
    from rbp.commands.common import UserError, check_output

    check_output(path, "--animate", picture=True, animation=True, inputs=inputs)
    suffix = Path(path).suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise UserError(f"{path}: --animate: must end in .gif or .mp4, got "
                        f"{suffix or 'no suffix'}")
    if suffix == ".mp4":
        from matplotlib.animation import writers

        if not writers.is_available("ffmpeg"):
            raise UserError(f"{path}: --animate: an .mp4 needs ffmpeg, which is not installed "
                            "(a .gif needs nothing more)")


def _check_speed(cfg: Any, args: argparse.Namespace) -> None:
    """`dt` long enough for the seeds' steps (planning.config_ranges.speed_problem)."""
    from planning.config_ranges import speed_problem
    from rbp.commands.common import UserError

    if problem := speed_problem(cfg):
        source = "--dt" if args.dt is not None else (
            f"{args.config or args.from_plan or '(configuration)'}: dt")
        raise UserError(f"{source}: {problem}")
