"""Route quality of the footstep search on the benchmark caves: cost, regrasps, p_path, time.

For each cave of the benchmark (`baseline_comparison`'s: kinds alternating shaft, crevasse,
shaft, rockfall; seed = trial + 1; 4.5 to 5 m, unless told otherwise) and each named search
variant, the footstep stage alone: whether it found a route, how it stopped, the route's
search cost (`planning.search_cost`), its regrasps, p_path and p_grasps at the footstep stage,
the bound it proved, expansions and seconds. `--compare OLD.json` then prints, cave by cave
and in summary, how the variants of this run differ from another run's (another tree's, say:
run the script in each tree, then compare).

    python -m experiments.route_quality --variants default --out out/rq-new.json
    python -m experiments.route_quality --variants first,default,oracle --trials 100 --workers 2

`--ompl-log PATH` also writes the runs as an OMPL benchmark log (`experiments.ompl_log`): a
planner per variant, a run per cave.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from experiments.arguments import (
    MAX_TRIALS,
    MAX_WORKERS,
    OneLineParser,
    json_argument,
    number,
    path_name,
    seed_list,
    seed_number,
    whole,
)
from experiments.common import ROUTE_VARIANTS as VARIANTS
from experiments.common import add_ompl_log_argument, cave_kind, check_ompl_log, variant_config
from experiments.common import finite_median as median
from experiments.common import route_variants as run_cave
from experiments.sweep import machine_info
from planning.config_io import ConfigError, checked_config
from rb_drake.errors import EXIT_OK, EXIT_USAGE, MAX_SEED, one_line
from rb_drake.files import atomic_write_text, output_problem
from rb_drake.generate import length_problem


def summary(caves: list[dict[str, Any]], variants: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    routed = [c for c in caves if any(c[v]["success"] for v in variants)]
    for v in variants:
        ok = [c[v] for c in caves if c[v]["success"]]
        out[v] = {"routes": len(ok), "caves": len(caves),
                  "stops": {s: sum(c[v]["stop"] == s for c in caves)
                            for s in sorted({c[v]["stop"] for c in caves})},
                  "median_regrasps": median([r["regrasps"] for r in ok]),
                  "median_p_path": median([r["p_path"] for r in ok]),
                  "p_grasps_over_0.90": sum((r["p_grasps"] or 0) > 0.90 for r in ok),
                  "p_grasps_over_0.95": sum((r["p_grasps"] or 0) > 0.95 for r in ok),
                  "median_seconds_route": median([r["seconds"] for r in ok]),
                  "median_seconds_all": median([c[v]["seconds"] for c in caves]),
                  "total_seconds": sum(c[v]["seconds"] for c in caves)}
    if len(variants) > 1:
        ref = variants[-1]
        for v in variants[:-1]:
            within = [c for c in routed if c[v]["success"] and c[ref]["success"]
                      and c[v]["cost"] <= 1.05 * c[ref]["cost"] + 1e-12]
            out[v][f"within_5pct_of_{ref}"] = len(within)
    out["caves_with_a_route"] = len(routed)
    return out


def compare(new: dict[str, Any], old: dict[str, Any]) -> None:
    """Cave by cave, each variant present in both runs: same answer? same route? time ratio."""
    old_caves = {(c["kind"], c["seed"]): c for c in old["caves"]}
    for v in new["variants"]:
        if v not in old["variants"]:
            continue
        same_route = diff = 0
        ratios = []
        for c in new["caves"]:
            o = old_caves.get((c["kind"], c["seed"]))
            if o is None:
                continue
            a, b = c[v], o[v]
            if a["success"] == b["success"] and a["stances"] == b["stances"] and \
                    a["stop"] == b["stop"]:
                same_route += 1
            else:
                diff += 1
                print(f"  {v} {c['kind']} {c['seed']}: new {a['stop'] or 'route'} "
                      f"{a['regrasps']} regrasps cost {a['cost']} / old {b['stop'] or 'route'} "
                      f"{b['regrasps']} regrasps cost {b['cost']}")
            if b["seconds"] > 0:
                ratios.append(a["seconds"] / b["seconds"])
        print(f"{v}: {same_route} caves the same, {diff} different; median time new/old "
              f"{median(ratios):.3f}")


def run_file(path: str) -> dict[str, Any]:
    """A run's results file (--compare, --against-oracle), read within the input bounds and
    checked for the shape the comparisons walk: else one line and exit status 2."""
    run = json_argument(path)
    variants, caves = run.get("variants"), run.get("caves")
    problem = None
    if not (isinstance(variants, list) and all(isinstance(v, str) for v in variants)):
        problem = "variants: must be a list of variant names"
    elif not isinstance(caves, list):
        problem = "caves: must be a list"
    else:
        for i, cave in enumerate(caves):
            if not (isinstance(cave, dict) and isinstance(cave.get("kind"), str)
                    and isinstance(cave.get("seed"), int)
                    and all(isinstance(cave.get(v), dict) for v in variants)):
                problem = (f"caves.{i}: must be an object with kind, seed and an object per "
                           "variant")
                break
    if problem is not None:
        print(one_line(f"error: {path}: {problem}"), file=sys.stderr)
        raise SystemExit(EXIT_USAGE)
    return run


def against_oracle(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each variant's routes against the oracle's, cave by cave, over several runs' files (the
    oracle may have run separately, on part of the caves): how many routes are within 5 % of
    the best cost the oracle found (its proven optimum where it says so), how many of those
    optima were proved, and the cost ratios."""
    caves: dict[tuple[str, int], dict[str, Any]] = {}
    for run in runs:  # a variant of a cave is taken from the first file that has it
        for cave in run["caves"]:
            entry = caves.setdefault((cave["kind"], cave["seed"]), {})
            for v in run["variants"]:
                entry.setdefault(v, cave[v])
    with_oracle = [c for c in caves.values() if c.get("oracle", {}).get("success")]
    out: dict[str, Any] = {"caves_with_an_oracle_route": len(with_oracle),
                           "oracle_proved_optimal": sum(c["oracle"]["bound"] == 1.0
                                                        for c in with_oracle),
                           "oracle_median_bound": median([c["oracle"]["bound"]
                                                          for c in with_oracle])}
    variants = sorted({v for c in with_oracle for v in c} - {"oracle"})
    for v in variants:
        pairs = [(c[v]["cost"], c["oracle"]["cost"], c["oracle"]["bound"] == 1.0)
                 for c in with_oracle if v in c and c[v]["success"]]
        ratios = [a / b for a, b, _ in pairs]
        out[v] = {"routes": len(pairs),
                  "within_5pct_of_oracle_best": sum(r <= 1.05 + 1e-9 for r in ratios),
                  "within_5pct_of_a_proven_optimum": sum(r <= 1.05 + 1e-9 and proved
                                                         for r, (_, _, proved)
                                                         in zip(ratios, pairs, strict=True)),
                  "better_than_oracle": sum(r < 1.0 - 1e-9 for r in ratios),
                  "median_cost_ratio_to_oracle": median(ratios),
                  "ratios": sorted(round(r, 4) for r in ratios)}
    return out


def write_ompl_log(args: argparse.Namespace, caves: list[dict[str, Any]], variants: list[str],
                   result: dict[str, Any], started: datetime) -> Path:
    """The run's OMPL benchmark log at args.ompl_log (a planner per variant)."""
    from experiments.common import variant_config
    from experiments.ompl_log import route_quality_log, write_log
    from planning.config_io import config_to_dict

    configs = {v: variant_config(v, args.time_limit) for v in variants
               if v != "default-quarter"}
    common = {v: {"variant": v, **({"footstep": config_to_dict(configs[v])} if v in configs
                                   else {"footstep": "default, memo capped at a quarter of "
                                                     "the default variant's most"})}
              for v in variants}
    limits = [c.time_limit for c in configs.values() if c.time_limit is not None]
    memory = [c.search_memory_mb for c in configs.values() if c.search_memory_mb is not None]
    log = route_quality_log(caves, variants, result["args"], common, result["machine"], started,
                            result["wall_seconds"], time_limit=max(limits, default=0.0),
                            memory_limit=max(memory, default=0.0))
    return write_log(args.ompl_log, log)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m experiments.route_quality",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=whole(1, MAX_TRIALS), default=100,
                        help="caves (default 100)")
    parser.add_argument("--first-seed", type=seed_number, default=1)
    parser.add_argument("--seeds", type=seed_list, default=None,
                        help="comma-separated seeds of the benchmark to run, instead of --trials")
    parser.add_argument("--kind", default="mixed", choices=("mixed", "shaft", "crevasse",
                                                             "rockfall"),
                        help="shaft, crevasse, rockfall or mixed")
    parser.add_argument("--length", type=number(0, 1e4), nargs=2, default=(4.5, 5.0))
    parser.add_argument("--variants", default="default",
                        help=f"comma-separated, of {', '.join(VARIANTS)}")
    parser.add_argument("--time-limit", type=number(0.001, 86_400), default=None,
                        help="s per search of the oracle variants (default 600)")
    parser.add_argument("--workers", type=whole(1, MAX_WORKERS), default=1)
    parser.add_argument("--out", type=path_name, default="out/route_quality.json")
    parser.add_argument("--compare", type=path_name, default=None, help="another run's json")
    parser.add_argument("--against-oracle", nargs="+", metavar="RUN.json", default=None,
                        help="no search: compare the variants of these runs' files with the "
                             "oracle variant found in them, cave by cave, and print it (a "
                             "variant of a cave is taken from the first file that has it)")
    add_ompl_log_argument(parser)
    args = parser.parse_args(argv)
    check_ompl_log(parser, args.ompl_log, args.out)
    # before the caves are searched: a bad --length, variant or --out was a worker's traceback
    # (or the results' rename's, after the whole run, leaving OUT.tmp)
    if (problem := length_problem(*args.length)) is not None:
        parser.error(f"--length: {problem}")
    if (problem := output_problem(args.out)) is not None:
        parser.error(f"--out: {args.out}: {problem}")
    old = run_file(args.compare) if args.compare else None  # before the run: it fails fast
    if args.against_oracle:
        runs = [run_file(f) for f in args.against_oracle]
        print(json.dumps(against_oracle(runs), indent=1))
        return EXIT_OK
    variants = args.variants.split(",")
    bad = [v for v in variants if v not in VARIANTS and not v.startswith(("corridor", "x-"))]
    if bad:
        parser.error(f"--variants: unknown {bad}; choose from {list(VARIANTS)}")
    if len(set(variants)) != len(variants):
        parser.error(f"--variants: a variant named twice in {args.variants!r}")
    if "default-quarter" in variants and "default" not in variants[:variants.index(
            "default-quarter")]:
        parser.error("--variants: default-quarter needs default before it")
    for v in variants:
        try:
            checked_config(variant_config(v, args.time_limit), v)
        except ConfigError as e:  # "VARIANT: FIELD: REASON"
            parser.error(f"--variants: {e}")
        except (ValueError, IndexError) as e:
            parser.error(f"--variants: {v}: cannot be read ({e})")
    if args.seeds is None and args.first_seed + args.trials - 1 > MAX_SEED:
        parser.error(f"--first-seed: the last cave's seed, {args.first_seed + args.trials - 1}"
                     f", is beyond {MAX_SEED}")
    indices = (range(args.trials) if args.seeds is None
               else [v - args.first_seed for v in args.seeds])
    jobs = [(cave_kind(i, args.kind), args.first_seed + i, tuple(args.length), variants,
             args.time_limit) for i in indices]
    if args.workers > 1:  # a search per core
        os.environ.setdefault("RBP_THREADS", "1")
    caves: list[dict[str, Any]] = []
    started = datetime.now(UTC)
    t0 = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        for k, cave in enumerate(pool.imap(run_cave, jobs), 1):
            caves.append(cave)
            line = " ".join(f"{v}:{cave[v]['stop'] or cave[v]['regrasps']}" for v in variants)
            print(f"[{k}/{len(jobs)}] {cave['kind']} {cave['seed']}: {line}", file=sys.stderr)
    result = {"variants": variants, "machine": machine_info(),
              "args": {k: v for k, v in vars(args).items() if k != "compare"},
              "wall_seconds": time.perf_counter() - t0,
              "summary": summary(caves, variants), "caves": caves}
    out = atomic_write_text(args.out, json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["summary"], indent=1))
    print(f"wrote {out}")
    if args.ompl_log:
        print(f"wrote {write_ompl_log(args, caves, variants, result, started)}")
    if old is not None:
        compare(result, old)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
