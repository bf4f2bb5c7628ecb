"""Benchmark the footstep planners: RBP against the naive baseline on the same generated caves.

Prints, per planner, the median and spread of the planning time, the success count, p_path and
regrasps, and writes every trial and the summary to OUT/bench_footsteps.json.

    python -m experiments.bench_footsteps --kind shaft,crevasse,rockfall --trials 4 \
        --length 4.5 5 --out out/bench
"""

from __future__ import annotations

import json
import platform
import statistics
import time
from pathlib import Path

from experiments.arguments import (
    MAX_EXPANSIONS,
    MAX_TRIALS,
    OneLineParser,
    number,
    path_name,
    seed_number,
    whole,
)
from planning.baseline import plan_naive
from planning.footsteps import FootstepConfig, plan_footsteps
from planning.plan import build_plan
from planning.plan_model import plan_dict
from rb_drake.errors import EXIT_OK
from rb_drake.files import atomic_write_text
from rb_drake.generate import KINDS, CaveConfig, generate_cave


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kind", default="shaft",
                        help="cave kinds, comma-separated: shaft, crevasse, rockfall")
    parser.add_argument("--trials", type=whole(1, MAX_TRIALS), default=5)
    parser.add_argument("--first-seed", type=seed_number, default=1)
    parser.add_argument("--max-expansions", type=whole(1, MAX_EXPANSIONS), default=1000)
    parser.add_argument("--length", type=number(0, 1e4), nargs=2, default=None, metavar=("MIN",
                        "MAX"),
                        help="cave length range in m (default: the generator's, 7 to 9)")
    parser.add_argument("--out", type=path_name, default="out/bench")
    args = parser.parse_args(argv)
    kinds = args.kind.split(",")
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        parser.error(f"--kind: unknown {unknown}; kinds are {', '.join(KINDS)}")
    records = []
    for kind, seed in ((k, s) for k in kinds
                       for s in range(args.first_seed, args.first_seed + args.trials)):
        config = CaveConfig(length=tuple(args.length)) if args.length else CaveConfig()
        scn = generate_cave(kind, seed, config)
        cfg = FootstepConfig(max_expansions=args.max_expansions)
        for name, run in (("rbp", plan_footsteps), ("naive", plan_naive)):
            t0 = time.perf_counter()
            fp = run(scn, cfg)
            seconds = time.perf_counter() - t0
            plan = plan_dict(build_plan(scn, fp, name))
            records.append({"seed": seed, "kind": kind, "planner": name,
                            "success": plan["success"], "seconds": seconds,
                            "p_path": plan["p_path"], "p_min": plan["p_min"],
                            "regrasps": plan["regrasps"],
                            "transitions_tested": fp.transitions_tested,
                            "reason": plan["reason"]})
            print(f"{kind} seed {seed} {name:5s}: success {plan['success']!s:5s} "
                  f"{seconds:7.2f} s, p_path {plan['p_path']}, regrasps {plan['regrasps']}",
                  flush=True)
    summary = {}
    for name in ("rbp", "naive"):
        rows = [r for r in records if r["planner"] == name]
        times = [r["seconds"] for r in rows]
        ok = [r for r in rows if r["success"]]
        summary[name] = {
            "trials": len(rows), "successes": len(ok),
            "seconds_median": statistics.median(times),
            "seconds_min": min(times), "seconds_max": max(times),
            "p_path_median": statistics.median([r["p_path"] for r in ok]) if ok else None,
        }
        print(f"{name}: {len(ok)}/{len(rows)} succeeded; time median "
              f"{summary[name]['seconds_median']:.2f} s (min {min(times):.2f}, max "
              f"{max(times):.2f}); p_path median {summary[name]['p_path_median']}")
        for kind in kinds:
            solved = sum(r["success"] for r in ok if r["kind"] == kind)
            summary[name][f"successes_{kind}"] = solved
            print(f"  {kind}: {solved}/{args.trials}")
    result = {"machine": f"{platform.machine()}, {platform.python_implementation()} "
                         f"{platform.python_version()}", "summary": summary, "trials": records}
    out = Path(args.out) / "bench_footsteps.json"
    atomic_write_text(out, json.dumps(result, indent=1))
    print(f"wrote {out}")
    return EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
