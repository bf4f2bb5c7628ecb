"""The anytime footstep search's curve: best route cost and proven lower bound against time.

For each benchmark cave given (`--caves shaft:7,crevasse:6,...`, the generator's kind and
seed, 4.5 to 5 m as in the benchmark), `rbp plan --thorough`'s search (the first route, then
better ones, on to the proven optimum or `--time-limit`), one after the other. The figure has
a panel per cave: the best cost (solid) and the lower bound (dashed) as steps over time, the
default's stopping point (twice the first route's expansions) marked. The JSON holds each
search's history.

    python -m experiments.anytime_curve --caves shaft:7,rockfall:8,crevasse:18 \\
        --time-limit 120 --out docs/figures/anytime-curve.png
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from experiments.arguments import OneLineParser, number, path_name
from experiments.common import make_cave
from rb_drake.errors import EXIT_OK


def search_history(kind: str, seed: int, time_limit: float) -> dict:
    from planning.complete_config import AnytimeConfig
    from planning.footsteps import FootstepConfig, plan_footsteps

    scn = make_cave(kind, seed, (4.5, 5.0))
    fp = plan_footsteps(scn, FootstepConfig(max_expansions=None, time_limit=time_limit,
                                            anytime=AnytimeConfig(improve_factor=None),
                                            polish_rounds=0))
    default_stop = None
    if fp.history:
        first = fp.history[0][3]
        default_stop = first + AnytimeConfig().improve_expansions(first)
    return {"kind": kind, "seed": seed, "success": bool(fp.success), "stop": fp.stop,
            "quality": fp.quality, "regrasps": len(fp.steps) if fp.success else None,
            "default_stop_expansions": default_stop,
            "history": [{"seconds": t, "cost": c, "lower_bound": lo, "expansions": n}
                        for t, c, lo, n in fp.history or []],
            "expansions": int(fp.expansions), "seconds": fp.seconds}


def curve_figure(runs: list[dict]):
    from rb_drake.draw import new_figure

    fig = new_figure(figsize=(4.0 * len(runs), 3.4), layout="constrained")
    axes = fig.subplots(1, len(runs), squeeze=False)[0]
    for ax, run in zip(axes, runs, strict=True):
        h = run["history"]
        if not h:
            ax.set_title(f"{run['kind']} {run['seed']}: no route ({run['stop']})")
            continue
        t = [p["seconds"] for p in h] + [run["seconds"]]
        cost = [p["cost"] for p in h] + [h[-1]["cost"]]
        low = [p["lower_bound"] for p in h] + [h[-1]["lower_bound"]]
        ax.step(t, cost, where="post", color="C0", label="best route's cost")
        ax.step(t, low, where="post", color="C3", linestyle="--", label="proven lower bound")
        stop = run["default_stop_expansions"]
        at = next((p["seconds"] for p in h if p["expansions"] >= stop), None) if stop else None
        if at is not None:
            ax.axvline(at, color="0.5", linewidth=0.8, linestyle=":",
                       label="default stops (about here)")
        final = h[-1]["cost"] / h[-1]["lower_bound"]
        ax.set_title(f"{run['kind']} {run['seed']}: {run['quality']}, "
                     f"bound {final:.2f}x, {run['regrasps']} regrasps", fontsize=9)
        ax.set_xlabel("footstep search time (s)")
        ax.set_ylabel("search cost (-log)")
        ax.set_ylim(bottom=0.0)
    axes[0].legend(fontsize=7, loc="upper right")
    return fig


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m experiments.anytime_curve",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--caves", default="shaft:7,rockfall:8,crevasse:18",
                        help="kind:seed, comma-separated")
    parser.add_argument("--time-limit", type=number(0.001, 86_400), default=120.0,
                        help="s per cave")
    parser.add_argument("--out", type=path_name, default="out/anytime-curve.png")
    args = parser.parse_args(argv)
    from rb_drake.files import atomic_save_figure, atomic_write_text

    try:
        caves = [(k, int(s)) for k, s in (c.split(":") for c in args.caves.split(","))]
    except ValueError:
        parser.error(f"--caves: expected kind:seed,..., got {args.caves!r}")
    runs = []
    for kind, seed in caves:
        runs.append(search_history(kind, seed, args.time_limit))
        print(f"{kind} {seed}: {runs[-1]['quality'] or runs[-1]['stop']}", file=sys.stderr)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_save_figure(curve_figure(runs), out, dpi=110)
    atomic_write_text(out.with_suffix(".json"), json.dumps(runs, indent=1) + "\n")
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
