"""What the sweep experiments share: the benchmark's randomised caves, the footstep planners
they compare, one climb trial (a cave and each planner on it), the caves' command-line flags,
and the summaries of the planners' records.

`baseline_comparison` (Fig. 4), `timing_table`, `seed_vs_scp`, `monte_carlo`, `param_sweep`,
`snapshots` and `footstep_ab` use these; an experiment script imports from here and from
`experiments.sweep`, never from another experiment script.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import math
import os
import time
from pathlib import Path
from typing import Any

from experiments.arguments import MAX_EXPANSIONS, number, path_name, seed_number, whole
from experiments.records import (
    BOOLEAN,
    COUNT,
    MEGABYTES,
    NUMBER,
    PROBABILITY,
    SECONDS,
    STRING,
    Rule,
    fields_problem,
    maybe,
    stage_seconds_problem,
)
from experiments.sweep import (
    RESULT_CHECKS,
    Trial,
    check_sweep_arguments,
    quantiles,
)
from rb_drake.errors import MAX_SEED

MIXED = ("shaft", "crevasse", "shaft", "rockfall")  # shafts and passages, alternating
THRESHOLDS = (0.90, 0.95)
MARS_G = 3.71  # m/s^2, the generator's default gravity magnitude


def make_cave(kind: str, seed: int, length: tuple[float, float], anchor_density: float = 3.0,
              gravity: float = MARS_G, p_min: float = 0.95, gripper_scale: float = 1.0):
    """A generated cave; `gripper_scale` multiplies every anchor's limit surface (its normal
    and lateral limits: the generator draws them from the scaled range with the same random
    numbers, so the cave's shape and anchor sites do not change)."""
    from rb_drake.generate import CaveConfig, generate_cave
    from rb_drake.params import RobotParams

    base = CaveConfig()
    config = CaveConfig(length=(float(length[0]), float(length[1])),
                        anchor_density=anchor_density, gravity=(0.0, -float(gravity)),
                        limit_normal=(gripper_scale * base.limit_normal[0],
                                      gripper_scale * base.limit_normal[1]))
    return generate_cave(kind, seed, config, RobotParams(p_min=p_min))


CAVE_PARAMS = ("kind", "seed", "length", "anchor_density", "gravity", "p_min", "gripper_scale")


def trial_cave(params: dict[str, Any]):
    """The cave of a climb trial's parameters."""
    return make_cave(**{k: v for k, v in params.items() if k in CAVE_PARAMS})


# The trial function of `climb_trials`, as a sweep records it in every trial file (OUT/trials/)
# and compares it to resume a sweep: it keeps the name it had before `climb_trial` moved here
# (`experiments.baseline_comparison` re-exports it), so that existing results folders resume.
CLIMB_TRIAL = "experiments.baseline_comparison:climb_trial"


# The footstep planners an experiment can compare: rbp (the default, complete search with its
# expansion budget), rbp-sampled (the sampling search of commit 36a65ef, for before/after
# ratios in one run), oracle (the complete search without an expansion budget, stopped only
# by --oracle-time: it labels each cave route / noroute / undecided) and the naive baseline;
# also rbp-hybrid (sampled for 150 expansions, then complete: the default before this one).
PLANNERS = ("rbp", "rbp-sampled", "oracle", "naive")
OTHER_PLANNERS = ("rbp-hybrid",)
ORACLE_SECONDS = 600.0


def footstep_config(planner: str, max_expansions: int, oracle_seconds: float = ORACLE_SECONDS):
    from planning.footsteps import FootstepConfig

    if planner == "rbp-sampled":
        return FootstepConfig(search="sampled", max_expansions=max_expansions)
    if planner == "rbp-hybrid":
        return FootstepConfig(search="hybrid", max_expansions=max_expansions)
    if planner == "oracle":  # labels caves route / noroute: its first route is enough (the
        # optimum is experiments.route_quality's oracle, rbp plan --thorough)
        return FootstepConfig(max_expansions=None, time_limit=oracle_seconds, anytime=None)
    return FootstepConfig(max_expansions=max_expansions)


def plan_cave(scn, planner: str, max_expansions: int, motion: bool,
              oracle_seconds: float = ORACLE_SECONDS) -> dict[str, Any]:
    """The plan-file object (`plan_dict`): the whole pipeline with `motion`, else the footstep
    stage only (the naive baseline always stops after its footsteps). Its timing also holds the
    footstep search's CPU seconds (`footstep_cpu`, every thread) and the threads its
    compiled kernels used."""
    from planning.footsteps import plan_footsteps
    from planning.pipeline import PipelineConfig, plan_climb
    from planning.plan import build_plan
    from planning.plan_model import plan_dict
    from rb_drake.kernel.threads import kernel_threads

    config = PipelineConfig(footstep=footstep_config(planner, max_expansions, oracle_seconds))
    name = "naive" if planner == "naive" else "rbp"
    if (motion and planner != "oracle") or planner == "naive":  # the oracle labels footsteps
        return plan_dict(plan_climb(scn, name, config))
    start, cpu = time.perf_counter(), time.process_time()
    fp = plan_footsteps(scn, config.footstep)
    return plan_dict(build_plan(scn, fp, name, {"footstep": fp.seconds,
                                                "footstep_cpu": time.process_time() - cpu,
                                                "threads": kernel_threads(),
                                                "total": time.perf_counter() - start}))



def plan_record(plan: dict[str, Any]) -> dict[str, Any]:
    """What the experiments keep of a plan (its timing goes to the trial's `timing`, with
    `search_measures`), and whether `rbp check`'s verifier finds it sound (`verified`; a
    failed plan is not)."""
    from planning.check import check_plan
    from planning.pipeline import motion_summary
    from planning.plan_model import plan_of

    kinds = [p["kind"] for p in plan["phases"]]
    search = plan.get("search", {})
    record = {"success": plan["success"], "reason": plan["reason"], "p_path": plan["p_path"],
              "stop": search.get("stop"), "expansions": search.get("expansions"),
              "cost": search.get("cost"), "bound": search.get("bound"),
              "p_grasps": plan.get("p_grasps"), "p_min": plan["p_min"],
              "regrasps": plan["regrasps"],
              "phases": {"body": kinds.count("body"), "reach": kinds.count("reach")},
              "verified": bool(plan["success"]) and not check_plan(plan)}
    rows = motion_summary(plan_of(plan))
    if plan["success"] and plan.get("time_step") is not None:
        from systems.plan_check import smooth_path_check

        # how far `rbp simulate`'s smooth path strays from the verified straight motion
        record["departure"] = smooth_path_check(plan)[1]
    if rows:
        record["motion"] = [{k: r[k] for k in ("phase", "kind", "steps", "seed_min", "min",
                                               "seed_mean", "mean", "seed_min_at_end", "room",
                                               "improved", "status")}
                            for r in rows]
    return record


def search_measures(plan: dict[str, Any]) -> dict[str, Any]:
    """What the footstep search measured that differs from run to run, kept with the trial's
    timing: its memory (peak resident and kept lattice work, MiB) and, an anytime search, its
    improvements over time (`history`: seconds, cost, lower_bound, expansions)."""
    search = plan.get("search", {})
    return {"peak_memory_mb": search.get("peak_memory_mb"),
            "kept_memory_mb": search.get("kept_memory_mb"), "history": search.get("history")}


def climb_trial(kind: str, seed: int, length: list[float], max_expansions: int,
                planners: list[str], motion: bool = False, anchor_density: float = 3.0,
                gravity: float = MARS_G, p_min: float = 0.95,
                gripper_scale: float = 1.0,
                oracle_seconds: float = ORACLE_SECONDS) -> dict[str, Any]:
    """One cave, each planner on it: {planner: plan_record, "cave": ..., "timing": ...}.

    A cave the generator cannot give a feasible start stance (a weak gripper scale, say)
    counts as a failure of every planner, with the generator's reason."""
    start = time.perf_counter()
    try:
        scn = make_cave(kind, seed, (length[0], length[1]), anchor_density, gravity, p_min,
                        gripper_scale)
    except RuntimeError as e:
        failed = {"success": False, "reason": f"no cave: {e}", "p_path": None,
                  "p_grasps": None, "p_min": None,
                  "regrasps": 0, "phases": {"body": 0, "reach": 0}}
        return {"cave": None, **{p: dict(failed) for p in planners},
                "timing": {"cave": time.perf_counter() - start}}
    out: dict[str, Any] = {"cave": {"name": scn.name, "anchors": len(scn.anchors)}}
    timing: dict[str, Any] = {"cave": time.perf_counter() - start}
    for planner in planners:  # each from scratch: its time is what `rbp plan` costs
        plan = plan_cave(scn, planner, max_expansions, motion, oracle_seconds)
        out[planner] = plan_record(plan)
        timing[planner] = {**plan["timing"], "search": search_measures(plan)}
    out["timing"] = timing
    return out


# The fields of a planner's plan_record the summaries and the OMPL log read: (check, what it
# must be); those after "phases" are missing from a cave the generator could not make.
_RECORD_FIELDS: dict[str, Rule] = {
    "success": BOOLEAN, "reason": STRING, "p_path": maybe(PROBABILITY),
    "p_grasps": maybe(PROBABILITY), "regrasps": (lambda v: COUNT[0](v) and v <= 10**6,
                                                 "a whole number from 0 to 1,000,000"),
    "phases": (lambda v: fields_problem(v, "", {"body": COUNT, "reach": COUNT}) is None,
               "an object of body and reach counts"),
    "stop": maybe(STRING), "expansions": maybe(COUNT), "cost": maybe(NUMBER),
    "bound": maybe(NUMBER), "verified": BOOLEAN,
}
_OPTIONAL = ("stop", "expansions", "cost", "bound", "verified")
_HISTORY_POINT = {"seconds": SECONDS, "cost": NUMBER, "lower_bound": NUMBER,
                  "expansions": COUNT}


def _search_problem(value: Any, where: str) -> str | None:
    """timing.PLANNER.search: the search's memory and an anytime search's history."""
    rules = {"peak_memory_mb": maybe(MEGABYTES), "kept_memory_mb": maybe(MEGABYTES),
             "history": (lambda v: v is None or isinstance(v, list), "null or a list")}
    if (problem := fields_problem(value, where, rules, optional=tuple(rules))) is not None:
        return problem
    for i, point in enumerate(value.get("history") or ()):
        if (problem := fields_problem(point, f"{where}.history.{i}", _HISTORY_POINT)):
            return problem
    return None


def climb_result_problem(params: dict[str, Any], record: dict[str, Any]) -> str | None:
    """What is wrong with a finished climb trial's record ("FIELD: REASON"), or None: each
    planner's record holds the fields the summaries read, within their ranges, and its timing
    (when it planned a cave) seconds per stage."""
    for planner in params.get("planners", ()):
        where = f"result.{planner}"
        if (problem := fields_problem(record["result"].get(planner), where, _RECORD_FIELDS,
                                      _OPTIONAL)) is not None:
            return problem if planner in record["result"] else f"{where}: missing"
        row = record["result"][planner]
        for key in ("p_path", "p_grasps"):  # the summaries count a success's probabilities
            if row["success"] and row[key] is None:
                return f"{where}.{key}: a successful plan's must be a number from 0 to 1"
        if row["success"] and planner not in record["timing"]:  # a plan has its times
            return f"timing.{planner}: missing (the planner succeeded)"
        if planner in record["timing"] and (problem := stage_seconds_problem(
                record["timing"][planner], f"timing.{planner}", ("footstep",),
                {"search": _search_problem})) is not None:
            return problem
    return None


RESULT_CHECKS[CLIMB_TRIAL] = climb_result_problem


def cave_kind(i: int, kind: str) -> str:
    return MIXED[i % len(MIXED)] if kind == "mixed" else kind


def add_cave_arguments(parser: argparse.ArgumentParser, max_expansions: int = 1000) -> None:
    """The flags of the caves and of the planners' cap."""
    parser.add_argument("--kind", default="mixed",
                        choices=("mixed", "shaft", "crevasse", "rockfall"),
                        help="cave kind (default mixed: shaft, crevasse, shaft, rockfall, ...)")
    parser.add_argument("--first-seed", type=seed_number, default=1,
                        help="seed of the first cave; trial i uses seed first + i (default 1)")
    parser.add_argument("--length", type=number(0, 1e4), nargs=2, default=(4.5, 5.0),
                        metavar=("MIN", "MAX"),
                        help="shaft height or passage length range in m (default 4.5 5.0)")
    parser.add_argument("--max-expansions", type=whole(1, MAX_EXPANSIONS),
                        default=max_expansions,
                        help="RBP gives up after expanding this many stances "
                             f"(default {max_expansions})")


def add_ompl_log_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ompl-log", metavar="PATH", type=path_name, default=None,
                        help="also write the runs as an OMPL benchmark log (a planner per "
                             "planner or variant, a run per cave), for ompl_benchmark_statistics "
                             "and Planner Arena")


def check_ompl_log(parser: argparse.ArgumentParser, path: str | None, out: str) -> None:
    """Refuse an --ompl-log path that cannot be written, or that lies in the experiment's
    --out folder (it replaced results.json or a trial record there), before any work."""
    from rb_drake.files import output_problem

    if path is None:
        return
    if (problem := output_problem(path)) is not None:
        parser.error(f"--ompl-log: {path}: {problem}")
    if Path(os.path.realpath(path)).is_relative_to(os.path.realpath(out)):
        parser.error(f"--ompl-log: {path}: is in the experiment's --out ({out}), where it "
                     "writes its own files; give a path outside it")


def check_cave_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    check_sweep_arguments(parser, args)
    from rb_drake.generate import length_problem

    if (problem := length_problem(*args.length)) is not None:
        parser.error(f"--length: {problem}")
    if args.max_expansions < 1:
        parser.error(f"--max-expansions: must be 1 or more, got {args.max_expansions}")
    if (last := args.first_seed + args.trials - 1) > MAX_SEED:  # trial i's seed is first + i
        parser.error(f"--first-seed: the last trial's seed, {last}, is beyond {MAX_SEED} "
                     f"(--first-seed at most {MAX_SEED - args.trials + 1} for {args.trials} "
                     "trials)")


def climb_trials(args: argparse.Namespace, planners: list[str], motion: bool,
                 prefix: str = "", **cave: Any) -> list[Trial]:
    """`args.trials` climb trials: cave i of the kind sequence with seed first + i."""
    trials = []
    for i in range(args.trials):
        kind, seed = cave_kind(i, args.kind), args.first_seed + i
        params = {"kind": kind, "seed": seed, "length": list(args.length),
                  "max_expansions": args.max_expansions, "planners": planners,
                  "motion": motion, **cave}
        trials.append(Trial(f"{prefix}{i:03d}-{kind}-s{seed}", CLIMB_TRIAL, params))
    return trials



def path_probabilities(records: list[dict[str, Any]], planner: str,
                       key: str = "p_path") -> list[float]:
    """p_path (or `key`, "p_grasps") per trial, 0 for a failed plan."""
    return [r["result"][planner][key] if r["result"][planner]["success"] else 0.0
            for r in records]


def stage_times(records: list[dict[str, Any]], planner: str, stage: str) -> list[float]:
    """Seconds the planner spent in `stage` (plan["timing"]), per trial that planned a cave."""
    return [r["timing"][planner][stage] for r in records if planner in r["timing"]]


def planner_summary(records: list[dict[str, Any]], planner: str) -> dict[str, Any]:
    p = path_probabilities(records, planner)
    p_grasps = path_probabilities(records, planner, "p_grasps")
    rows = [r["result"][planner] for r in records]
    ok = [row for row in rows if row["success"]]
    by_kind: dict[str, dict[str, int]] = {}
    for r, row in zip(records, rows, strict=True):
        counts = by_kind.setdefault(r["params"]["kind"], {"trials": 0, "successes": 0})
        counts["trials"] += 1
        counts["successes"] += bool(row["success"])
    return {"trials": len(rows), "successes": len(ok),
            "verified": sum(bool(row.get("verified")) for row in ok),
            **{f"p_path_over_{t:.2f}": sum(v > t for v in p) for t in THRESHOLDS},
            **{f"p_grasps_over_{t:.2f}": sum(v > t for v in p_grasps) for t in THRESHOLDS},
            "p_path": quantiles(p), "p_path_successes": quantiles([r["p_path"] for r in ok]),
            "regrasps_successes": quantiles([r["regrasps"] for r in ok]), "by_kind": by_kind}


# The named footstep-search variants of experiments.route_quality and experiments.long_climbs.
ROUTE_VARIANTS = ("default", "first", "before", "ara", "sampled", "w30", "w3", "anytime-f1",
            "anytime-f4", "oracle", "oracle-a*", "repair", "default-repair", "default-quarter",
            "segments", "travel7", "dt7", "lattice", "oracle-lattice", "corridorR-fF",
            "x-wW-fF-cR")


def variant_config(variant: str, time_limit: float | None):
    """The footstep configuration of a named variant: "default" (today's `rbp plan`), "first"
    (the first route of the complete search, weight 300: the default before the anytime
    search), "before" (the default of commit 203c53d: ARA*, weights 10, 3, 1, a fixed budget of
    1000 expansions), "ara" (today's weights, re-keying the open list at each weight as ARA*
    does instead of restarting), "sampled",
    "w30" / "w3" (lower weights, first route), "anytime-fK" (the first
    route, then better ones for K times its time), "oracle" (`rbp plan --thorough`: to the
    proven optimum, or `--time-limit`) and "oracle-a*" (A* on the admissible bound from the
    start), "repair" (the first route repaired window by window: planning.route_repair) and
    "default-repair" (today's default, then repaired); "default-quarter" is today's default with
    its memo capped at a quarter of the most the "default" variant kept on the same cave
    (`route_variants`: run "default" first); "segments" is today's default with climbs
    over 7 m searched in segments (planning.segmented); "travel7" orders the first route by the
    travel bound (weight 7, no anytime passes) and "dt7" the anytime passes after today's first
    route (weights 7, 4, 2, 1: `ordering: distance+travel`); "lattice" and "oracle-lattice" are
    "default" and "oracle" on the lattice alone, without refinement (planning.refinement: the
    default before session 25), as "first" and "before" are."""
    from planning.complete_config import AnytimeConfig
    from planning.footsteps import FootstepConfig
    from planning.route_repair import RepairConfig
    from planning.segmented import SegmentConfig

    limit = 600.0 if time_limit is None else time_limit
    exhaustive = AnytimeConfig(improve_factor=None)
    table: dict[str, dict[str, Any]] = {
        "default": {},
        "first": {"anytime": None, "heuristic_weight": 300.0, "refine": 0},
        "sampled": {"search": "sampled", "heuristic_weight": 300.0},
        "w30": {"heuristic_weight": 30.0, "anytime": None},
        "w3": {"heuristic_weight": 3.0, "anytime": None},
        "before": {"anytime": AnytimeConfig(weights=(10.0, 3.0, 1.0), restart=False),
                   "expansions_per_metre": 0.0, "heuristic_weight": 300.0, "refine": 0},
        "lattice": {"refine": 0},
        "oracle-lattice": {"max_expansions": None, "time_limit": limit, "anytime": exhaustive,
                           "refine": 0},
        "ara": {"anytime": AnytimeConfig(restart=False)},
        "anytime-f1": {"anytime": AnytimeConfig(improve_factor=1.0)},
        "anytime-f4": {"anytime": AnytimeConfig(improve_factor=4.0)},
        "oracle": {"max_expansions": None, "time_limit": limit, "anytime": exhaustive},
        "oracle-a*": {"max_expansions": None, "time_limit": limit, "anytime": exhaustive,
                      "heuristic_weight": 1.0},
        "repair": {"anytime": None, "repair": RepairConfig(), "heuristic_weight": 300.0},
        "default-repair": {"repair": RepairConfig()},
        "segments": {"segments": SegmentConfig()},
        "travel7": {"ordering": "travel", "heuristic_weight": 7.0, "anytime": None},
        "dt7": {"ordering": "distance+travel",
                "anytime": AnytimeConfig(weights=(7.0, 4.0, 2.0, 1.0))},
    }
    if variant.startswith("corridor"):  # corridorR-fF: a corridor of R m, F x the first's
        radius, _, factor = variant.removeprefix("corridor").partition("-f")
        return FootstepConfig(anytime=AnytimeConfig(corridor=float(radius),
                                                    improve_factor=float(factor or 2.0)))
    if variant.startswith("x-"):  # x-wW-fF-cR-bB-mM-eE-sA_B: today's default, any of its
        # first route's weight W (default 300, the default before session 24), improvement
        # budget F, corridor R, fallback point B, expansion budget M (at least; default 1000)
        # and per metre E (default 300) and passes' weights A, B, ... changed
        parts = variant.split("-")[1:]
        settings = {p[0]: float(p[1:]) for p in parts if p[0] != "s"}
        # sA_B_C: the passes' weights A, B, C (default today's)
        weights = [tuple(float(w) for w in p[1:].split("_")) for p in parts if p[0] == "s"]
        anytime = AnytimeConfig(weights=weights[0] if weights else AnytimeConfig().weights,
                                improve_factor=settings.get("f", 2.0),
                                corridor=settings.get("c"))
        return FootstepConfig(heuristic_weight=settings.get("w", 300.0), anytime=anytime,
                              fallback_after=settings.get("b", 0.75),
                              max_expansions=int(settings.get("m", 1000)),
                              expansions_per_metre=settings.get("e", 300.0))
    return FootstepConfig(**table[variant])


def route_variants(job: tuple[str, int, tuple[float, float], list[str], float | None]
             ) -> dict[str, Any]:
    from planning.footsteps import plan_footsteps
    from planning.plan import build_plan
    from planning.plan_model import plan_dict
    from planning.search_cost import edge_cost

    kind, seed, length, variants, limit = job
    scn = make_cave(kind, seed, length)
    out: dict[str, Any] = {"kind": kind, "seed": seed}
    for variant in variants:
        if variant == "default-quarter":
            if "default" not in out:
                raise ValueError("the variant default-quarter needs default before it")
            config = dataclasses.replace(variant_config("default", limit), search_memory_mb=max(
                1.0, out["default"]["kept_memory_mb"] / 4.0))
        else:
            config = variant_config(variant, limit)
        t0 = time.perf_counter()
        fp = plan_footsteps(scn, config)
        seconds = time.perf_counter() - t0
        plan = plan_dict(build_plan(scn, fp, "rbp"))
        cost = None
        if fp.success:
            cost = sum(edge_cost(scn, a, s.boom, s.to_anchor,
                                 s.found_pose if s.found_pose is not None else s.pose)
                       for a, s in zip(fp.stances[:-1], fp.steps, strict=True))
        search = plan.get("search", {})
        out[variant] = {"success": bool(fp.success), "stop": fp.stop,
                        "regrasps": len(fp.steps) if fp.success else None,
                        "cost": cost, "p_path": plan.get("p_path"),
                        "p_grasps": plan.get("p_grasps"),
                        "bound": search.get("bound"), "lower_bound": search.get("lower_bound"),
                        "expansions": int(fp.expansions), "seconds": seconds,
                        "peak_memory_mb": fp.peak_memory_mb,
                        "kept_memory_mb": fp.kept_memory_mb,
                        "history": search.get("history"),
                        "memo": fp.memo.lattice.stats() if fp.memo is not None else None,
                        "stances": [list(s) for s in fp.stances] if fp.success else None,
                        "refined": [[c.position_step, c.angle_step_deg] for c in fp.refined]}
        # The next variant must not run beside this one's memo (up to its cap, kept alive by
        # the result): a capped search watches the process's memory and would give way to it.
        del fp, plan
        gc.collect()
    return out


def finite_median(values: list[float]) -> float | None:
    """The median of the finite values (None when there are none)."""
    return quantiles([x for x in values if x is not None and math.isfinite(x)])["median"]
