"""Footstep search time, before and after, in one run: two source trees side by side.

These machines differ in speed by up to 4.5x from one day to the next and are shared, so a
change is measured as a ratio, the old code beside the new: for each benchmark cave, the old
tree's search and the new tree's search run at the same time, one process each (one per core
of a 2-core machine), so that both meet the same load; with `--all-cores`, one after the other,
each with every core, as the oracle runs (the order alternates from cave to cave, so that a
drift in the machine's speed falls on both). Each side reports its footstep seconds
(wall and CPU), stop reason, expansions and regrasps; the summary gives the median per-cave
ratio new / old and each side's medians.

    git worktree add /tmp/old 36a65ef      # or any commit
    python -m experiments.footstep_ab --old /tmp/old --caves noroute \\
        --labels out/baseline/results.json --thorough --out out/footstep_ab.json

Caves are the benchmark's (`baseline_comparison`: kind alternating shaft, crevasse, shaft,
rockfall; seed = trial + 1; 4.5 to 5 m), chosen by `--seeds` or by their oracle label in a
`baseline_comparison` results.json (`--caves route|noroute`). `--thorough` runs the oracle (no
expansion budget, `--time-limit` seconds), else the default search.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from experiments.arguments import OneLineParser, json_argument, number, path_argument, seed_number
from experiments.common import cave_kind
from experiments.sweep import quantiles
from rb_drake.errors import EXIT_OK

_CHILD = r"""
import json, resource, sys, time
try:
    from experiments.common import make_cave
except ImportError:  # an old tree, from before experiments/common.py
    from experiments.baseline_comparison import make_cave
from planning.footsteps import FootstepConfig, plan_footsteps
kind, seed, thorough, limit = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1", float(sys.argv[4])
warm = make_cave("shaft", 5, (4.5, 5.0))
plan_footsteps(warm, FootstepConfig(max_expansions=3))  # load the compiled kernels first
scn = make_cave(kind, seed, (4.5, 5.0))
config = (FootstepConfig(max_expansions=None, time_limit=limit) if thorough
          else FootstepConfig())
cpu, wall = time.process_time(), time.perf_counter()
fp = plan_footsteps(scn, config)
print(json.dumps({"success": bool(fp.success), "stop": fp.stop, "expansions": fp.expansions,
                  "regrasps": max(0, len(fp.stances) - 1) if fp.success else None,
                  "wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run_pair(old: Path, new: Path, kind: str, seed: int, thorough: bool,
             limit: float, all_cores: bool = False, new_first: bool = False) -> dict[str, Any]:
    """The cave searched by both trees at the same time, one core each; with `all_cores`, one
    tree after the other, each with every core (as the oracle runs), `new_first` or not."""
    sides = [("old", old), ("new", new)]
    if all_cores and new_first:
        sides.reverse()
    procs, out = {}, {"kind": kind, "seed": seed}
    for side, tree in sides:
        env = {**os.environ, "PYTHONPATH": str(tree)}
        if not all_cores:
            env["NUMBA_NUM_THREADS"] = "1"
        procs[side] = subprocess.Popen(
            [sys.executable, "-c", _CHILD, kind, str(seed), "1" if thorough else "0",
             str(limit)], cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True)
        if all_cores:  # wait for it before the other starts
            out[side] = _result(side, procs.pop(side), kind, seed)
    for side, proc in procs.items():
        out[side] = _result(side, proc, kind, seed)
    return out


def _result(side: str, proc: subprocess.Popen, kind: str, seed: int) -> dict[str, Any]:
    stdout, stderr = proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"{side} tree failed on {kind} seed {seed}:\n{stderr[-2000:]}")
    return json.loads(stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old", type=Path, required=True, help="the old source tree")
    parser.add_argument("--new", type=Path, default=Path(__file__).resolve().parents[1],
                        help="the new source tree (default: this one)")
    parser.add_argument("--seeds", type=seed_number, nargs="*", default=None,
                        help="benchmark seeds (1..100) to run")
    parser.add_argument("--caves", choices=("route", "noroute"), default=None,
                        help="the caves of this oracle label in --labels")
    parser.add_argument("--labels", type=Path, default=None,
                        help="a baseline_comparison results.json with oracle labels")
    parser.add_argument("--max-old-seconds", type=number(0.001, 86_400), default=None,
                        help="with --labels: leave out caves whose oracle took longer there")
    parser.add_argument("--thorough", action="store_true",
                        help="the oracle (no expansion budget), else the default search")
    parser.add_argument("--time-limit", type=number(0.001, 86_400), default=900.0)
    parser.add_argument("--all-cores", action="store_true",
                        help="one tree after the other, each with every core (the oracle's "
                             "setting; the order alternates from cave to cave), not both at "
                             "once on a core each")
    parser.add_argument("--out", type=path_argument, required=True, help="results JSON")
    args = parser.parse_args(argv)
    for tree in (args.old, args.new):
        if not (tree / "planning" / "complete.py").is_file():
            parser.error(f"{tree}: not an rbp source tree (no planning/complete.py)")
    seeds = list(args.seeds or [])
    if args.caves is not None:
        if args.labels is None:
            parser.error("--caves needs --labels")
        results = json_argument(args.labels)  # bounded: a FIFO or deep nesting is one line
        try:
            for trial in results["trials"]:  # baseline_comparison's per-cave table
                took = trial["oracle"]["footstep_seconds"]
                if trial["label"] == args.caves and (args.max_old_seconds is None
                                                     or took <= args.max_old_seconds):
                    seeds.append(int(trial["seed"]))
        except (OSError, ValueError, KeyError, TypeError) as e:
            parser.error(f"{args.labels}: cannot read oracle labels ({e})")
    if not seeds:
        parser.error("no caves: give --seeds or --caves with --labels")
    rows = []
    for n, seed in enumerate(sorted(set(seeds)), 1):
        start = time.perf_counter()
        row = run_pair(args.old, args.new, cave_kind(seed - 1, "mixed"), seed, args.thorough,
                       args.time_limit, args.all_cores, new_first=n % 2 == 0)
        row["ratio"] = row["new"]["wall"] / max(row["old"]["wall"], 1e-9)
        row["cpu_ratio"] = row["new"]["cpu"] / max(row["old"]["cpu"], 1e-9)
        rows.append(row)
        print(f"[{n}/{len(set(seeds))}] {row['kind']} {seed}: old {row['old']['wall']:.2f} s "
              f"({row['old']['stop'] or 'route'}), new {row['new']['wall']:.2f} s "
              f"({row['new']['stop'] or 'route'}), new/old {row['ratio']:.2f} "
              f"({time.perf_counter() - start:.0f} s)", flush=True)
    def median(values: list[float]) -> float | None:
        return quantiles(values)["median"]

    summary: dict[str, Any] = {side: {"median_wall": median([r[side]["wall"] for r in rows]),
                      "median_cpu": median([r[side]["cpu"] for r in rows]),
                      "most_peak_mb": max((r[side].get("peak_mb", 0.0) for r in rows),
                                          default=None)}
               for side in ("old", "new")}
    summary["ratio_median"] = median([r["ratio"] for r in rows])
    summary["cpu_ratio_median"] = median([r["cpu_ratio"] for r in rows])
    summary["same_outcome"] = sum(r["old"]["stop"] == r["new"]["stop"] for r in rows)
    print(f"{len(rows)} caves: median wall old {summary['old']['median_wall']:.2f} s, new "
          f"{summary['new']['median_wall']:.2f} s; per cave new/old median "
          f"{summary['ratio_median']:.2f} (CPU {summary['cpu_ratio_median']:.2f}); "
          f"same outcome in {summary['same_outcome']}")
    from rb_drake.files import atomic_write_text

    atomic_write_text(args.out, json.dumps({"old": str(args.old), "new": str(args.new),
                                            "thorough": args.thorough,
                                            "all_cores": args.all_cores, "caves": rows,
                                            "summary": summary}, indent=1))
    return EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
