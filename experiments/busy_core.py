"""Threads on a busy machine: the default thread count against one thread, cave by cave.

The benchmark's caves (`route_quality`'s: the same kinds, seeds and lengths), the footstep
stage of one search variant (default: today's `rbp plan`), run twice per cave in the same run:
once by a worker with the default kernel threads (RBP_THREADS unset: up to numba's count, the
cores, as many as other processes leave free) and once by a worker with RBP_THREADS=1 (and
other modes: `--modes`), one after the other (never at once), in alternating
order from cave to cave so that drift in the machine's load falls on both alike. With `--busy N`
(default 1) N processes spin on a core each for the whole run, as another user's job would.
Each worker plans a cave first to warm its compiled kernels; that cave is not counted.

Reports, per cave, each mode's footstep time and whether it made the default's decisions
(route, regrasps, expansions: the thread count must not change a plan), and the median and the
total-time ratio of the default over each other mode (issue 32 asks at most 1.2 over one thread
with a core busy, and idle at least as fast as before: `--modes default,one,before`, where
`before` is every thread always, waiting as libgomp does by default, as before issue 32).

    python -m experiments.busy_core --trials 100 --busy 1 --modes default,one,passive \
        --out docs/figures/busy-core.json
    python -m experiments.busy_core --trials 100 --busy 0 --modes default,one,before \
        --out docs/figures/idle-threads.json
"""

from __future__ import annotations

import json
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from experiments.arguments import (
    MAX_TRIALS,
    MAX_WORKERS,
    OneLineParser,
    number,
    path_name,
    seed_number,
    whole,
)
from experiments.common import ROUTE_VARIANTS, cave_kind
from experiments.common import route_variants as run_cave
from experiments.sweep import machine_info
from rb_drake.errors import EXIT_OK
from rb_drake.files import atomic_write_text

# The default (every thread the free cores allow, libgomp's spin: rb_drake.kernel.free_cores);
# RBP_THREADS=1; and every thread always (RBP_THREADS_ADAPT=0) with OpenMP's threads waiting
# as libgomp does by default ("before": a few ms of spinning, the default before issue 32),
# spinning without end (OMP_WAIT_POLICY=ACTIVE), sleeping at once (OMP_WAIT_POLICY=PASSIVE,
# the first fix of issue 32) or spinning N times ("spinN": GOMP_SPINCOUNT=N, about 100,000
# spins a millisecond)
MODES = ("default", "one", "before", "active", "passive", "spinN")
_ENVIRONMENT = ("RBP_THREADS", "RBP_THREADS_ADAPT", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT")


def valid_mode(mode: str) -> bool:
    """One of MODES, "spinN" with N a whole number of spins."""
    return mode in MODES[:-1] or (mode.startswith("spin") and mode[4:].isdigit())


def _spin() -> None:
    while True:
        pass


def _pool(mode: str) -> Any:
    """One spawned worker whose environment has the mode's RBP_THREADS (read at its start)."""
    saved = {k: os.environ.get(k) for k in _ENVIRONMENT}
    for k in saved:
        os.environ.pop(k, None)
    if mode == "one":
        os.environ["RBP_THREADS"] = "1"
    elif mode != "default":
        os.environ["RBP_THREADS_ADAPT"] = "0"
    if mode == "active":
        os.environ["OMP_WAIT_POLICY"] = "ACTIVE"
    if mode == "passive":
        os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
        os.environ["GOMP_SPINCOUNT"] = "0"
    if mode.startswith("spin"):
        os.environ["GOMP_SPINCOUNT"] = mode[4:]
    try:
        return multiprocessing.get_context("spawn").Pool(1)
    finally:
        for k, v in saved.items():
            os.environ.pop(k, None)
            if v is not None:
                os.environ[k] = v


def _threads() -> dict[str, Any]:
    from rb_drake.kernel.threads import run_conditions

    return run_conditions()


def decisions(run: dict[str, Any]) -> tuple:
    """What a thread count must not change: route or stop, regrasps, expansions, stances."""
    return (run["success"], run["stop"], run["regrasps"], run["expansions"], run["stances"])


def summarise(caves: list[dict[str, Any]], modes: tuple[str, ...]) -> dict[str, Any]:
    """Per mode but the default: the default's time over the mode's, cave by cave (median and
    quartiles) and in total, and on how many caves both made the same decisions."""
    total = {m: sum(c[m]["seconds"] for c in caves) for m in modes}
    out: dict[str, Any] = {"caves": len(caves), "total_seconds": total}
    for m in modes[1:]:
        ratios = [c["default"]["seconds"] / c[m]["seconds"] for c in caves]
        out[f"default_over_{m}"] = {
            "same_decisions": sum(decisions(c["default"]) == decisions(c[m]) for c in caves),
            "median_ratio": statistics.median(ratios) if ratios else None,
            "ratio_quartiles": statistics.quantiles(ratios, n=4) if len(ratios) > 1 else None,
            "total_ratio": total["default"] / total[m] if total[m] else None}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m experiments.busy_core",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=whole(1, MAX_TRIALS), default=100,
                        help="caves (default 100)")
    parser.add_argument("--first-seed", type=seed_number, default=1)
    parser.add_argument("--kind", default="mixed", help="shaft, crevasse, rockfall or mixed")
    parser.add_argument("--length", type=number(0, 1e4), nargs=2, default=(4.5, 5.0))
    parser.add_argument("--variant", default="default", choices=ROUTE_VARIANTS)
    parser.add_argument("--busy", type=whole(0, MAX_WORKERS), default=1,
                        help="cores kept spinning (default 1)")
    parser.add_argument("--modes", default="default,one",
                        help="comma-separated, the first 'default': default (today's threads), "
                             "one (RBP_THREADS=1); every thread always, waiting as: before "
                             "(libgomp's default), active (OMP_WAIT_POLICY=ACTIVE), passive "
                             "(OMP_WAIT_POLICY=PASSIVE), spinN (GOMP_SPINCOUNT=N)")
    parser.add_argument("--out", type=path_name, default="out/busy_core.json")
    args = parser.parse_args(argv)
    if args.trials < 1 or args.busy < 0:
        parser.error("--trials must be at least 1 and --busy at least 0")
    modes = tuple(args.modes.split(","))
    if modes[0] != "default" or len(modes) < 2 or not all(map(valid_mode, modes)) or \
            len(set(modes)) < len(modes):
        parser.error(f"--modes: 'default' first, then one or more of {MODES[1:]}")
    ctx = multiprocessing.get_context("spawn")
    pools = {m: _pool(m) for m in modes}
    spinners = []
    try:
        threads = {m: pools[m].apply(_threads) for m in modes}
        warm = ("shaft", args.first_seed, tuple(args.length), [args.variant], None)
        for m in modes:
            pools[m].apply(run_cave, (warm,))
        for _ in range(args.busy):
            spinners.append(ctx.Process(target=_spin, daemon=True))
            spinners[-1].start()
        caves: list[dict[str, Any]] = []
        t0 = time.perf_counter()
        for i in range(args.trials):
            job = (cave_kind(i, args.kind), args.first_seed + i, tuple(args.length),
                   [args.variant], None)
            cave: dict[str, Any] = {"kind": job[0], "seed": job[1]}
            for m in (modes if i % 2 == 0 else modes[::-1]):
                cave[m] = pools[m].apply(run_cave, (job,))[args.variant]
            caves.append(cave)
            times = ", ".join(f"{m} {cave[m]['seconds']:.2f} s" for m in modes)
            print(f"[{i + 1}/{args.trials}] {cave['kind']} {cave['seed']}: {times}",
                  file=sys.stderr)
    finally:
        for p in spinners:
            p.terminate()
        for pool in pools.values():
            pool.terminate()
    result = {"machine": machine_info(), "args": vars(args), "threads": threads,
              "wall_seconds": time.perf_counter() - t0, "summary": summarise(caves, modes),
              "caves": caves}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["summary"], indent=1))
    print(f"wrote {out}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
