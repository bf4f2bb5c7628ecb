"""Long climbs: regrasps, predicted success and footstep time against the climb's length.

Generated shafts and passages (crevasses) of 5, 10, 15 and 20 m (more with --lengths), seeds
5001-5003 of each (outside the benchmark's 1-100), footsteps only, each named search variant of
`experiments.route_quality` (default: today's default beside "before", the default of commit
203c53d with its fixed 1000-expansion budget). Writes the runs' JSON and a figure: per kind and
variant, the median over seeds of regrasps per metre climbed, exp(-search cost) and footstep
seconds per metre, against length.

    python -m experiments.long_climbs --workers 2 --out docs/figures/long-climbs.json
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from experiments.arguments import MAX_WORKERS, OneLineParser, number, path_name, whole
from experiments.common import ROUTE_VARIANTS as VARIANTS
from experiments.common import finite_median as median
from experiments.common import route_variants as run_cave
from experiments.sweep import machine_info
from rb_drake.errors import EXIT_OK

KINDS = ("shaft", "crevasse")


def climb_length(kind: str, seed: int, length: float) -> float:
    """The straight distance from the start pose to the goal of a generated cave (m)."""
    import numpy as np

    from experiments.common import make_cave

    scn = make_cave(kind, seed, (length, length))
    return float(np.linalg.norm(np.asarray(scn.start_pose[:2]) - np.asarray(scn.goal_position)))


def run_job(job: tuple[str, int, float, list[str]]) -> dict[str, Any]:
    kind, seed, length, variants = job
    out = run_cave((kind, seed, (length, length), variants, None))
    out["length"] = length
    out["climb"] = climb_length(kind, seed, length)
    return out


def table(caves: list[dict[str, Any]], variants: list[str]) -> list[dict[str, Any]]:
    """Per kind, variant and length: routes found and the medians over seeds."""
    rows = []
    for kind in sorted({c["kind"] for c in caves}):
        for v in variants:
            for length in sorted({c["length"] for c in caves}):
                runs = [c for c in caves if c["kind"] == kind and c["length"] == length]
                ok = [c for c in runs if c[v]["success"]]
                rows.append({
                    "kind": kind, "variant": v, "length": length, "caves": len(runs),
                    "routes": len(ok), "stops": sorted(c[v]["stop"] for c in runs
                                                       if not c[v]["success"]),
                    "regrasps_per_metre": median([c[v]["regrasps"] / c["climb"] for c in ok]),
                    "p_path": median([c[v]["p_path"] for c in ok]),
                    "seconds_per_metre": median([c[v]["seconds"] / c["climb"] for c in runs]),
                })
    return rows


def draw(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fields = [("regrasps_per_metre", "regrasps per metre"), ("p_path", "p_path (footsteps)"),
              ("seconds_per_metre", "footstep s per metre")]
    kinds = sorted({r["kind"] for r in rows})
    fig, axes = plt.subplots(len(kinds), 3, figsize=(12, 3.2 * len(kinds)), squeeze=False)
    for i, kind in enumerate(kinds):
        for k, (field, label) in enumerate(fields):
            ax = axes[i, k]
            for v in sorted({r["variant"] for r in rows}):
                mine = [r for r in rows if r["kind"] == kind and r["variant"] == v
                        and r[field] is not None]
                if mine:
                    line, = ax.plot([r["length"] for r in mine], [r[field] for r in mine],
                                    "o-", label=v)
                    if k == 0:  # how many of the caves each median is over
                        for r in mine:
                            ax.annotate(f"{r['routes']}/{r['caves']}", (r["length"], r[field]),
                                        textcoords="offset points", xytext=(4, 4), fontsize=7,
                                        color=line.get_color())
            ax.set_xlabel("cave length (m)")
            ax.set_ylabel(label)
            ax.set_title(f"{kind}: {label}", fontsize=9)
            if field == "p_path":
                ax.set_ylim(0, 1)
            ax.grid(alpha=0.3)
        axes[i, 0].legend(fontsize=8)
    fig.suptitle("Long climbs: median over seeds (over the routes found, n/N beside each point, "
                 "for regrasps and p_path)")
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m experiments.long_climbs",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--lengths", type=number(0, 1e4), nargs="+", default=[5.0, 10.0, 15.0,
                        20.0])
    parser.add_argument("--kinds", default=",".join(KINDS))
    parser.add_argument("--seeds", default="5001,5002,5003")
    parser.add_argument("--variants", default="default,before",
                        help=f"comma-separated, of {', '.join(VARIANTS)}")
    parser.add_argument("--workers", type=whole(1, MAX_WORKERS), default=1)
    parser.add_argument("--out", type=path_name, default="out/long-climbs.json")
    args = parser.parse_args(argv)
    variants = args.variants.split(",")
    bad = [v for v in variants if v not in VARIANTS and not v.startswith(("corridor", "x-"))]
    if bad:
        parser.error(f"--variants: unknown {bad}; choose from {list(VARIANTS)}")
    jobs = [(kind, int(seed), float(length), variants) for length in args.lengths
            for kind in args.kinds.split(",") for seed in args.seeds.split(",")]
    if args.workers > 1:
        os.environ.setdefault("RBP_THREADS", "1")
    caves: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        done: Iterator[dict[str, Any]]
        if args.workers > 1:
            pool = stack.enter_context(multiprocessing.get_context("spawn").Pool(args.workers))
            done = pool.imap_unordered(run_job, jobs)
        else:  # in this process
            done = map(run_job, jobs)
        for k, cave in enumerate(done, 1):
            caves.append(cave)
            line = " ".join(f"{v}:{cave[v]['stop'] or cave[v]['regrasps']}"
                            f"/{cave[v]['seconds']:.0f}s" for v in variants)
            print(f"[{k}/{len(jobs)}] {cave['kind']} {cave['seed']} {cave['length']:g} m: "
                  f"{line}", file=sys.stderr, flush=True)
    caves.sort(key=lambda c: (c["kind"], c["length"], c["seed"]))
    rows = table(caves, variants)
    result = {"variants": variants, "machine": machine_info(),
              "args": vars(args), "wall_seconds": time.perf_counter() - t0,
              "table": rows, "caves": caves}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1) + "\n")
    tmp.replace(out)
    draw(rows, out.with_suffix(".png"))
    for r in rows:
        print(json.dumps(r))
    print(f"wrote {out} and {out.with_suffix('.png')}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
