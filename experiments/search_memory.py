"""Peak memory of the footstep search against its expansions, old tree beside new (issue 31).

Each cave is searched by `rbp plan --thorough`'s footstep search (no expansion budget, on to the
proven optimum, stopped after `--time-limit` s) in a child process per tree, both trees at the
same time, one core each, so that both meet the same load. The child records its peak resident
memory (the kernel's `ru_maxrss`) every `--every` expansions; the figure plots it against the
expansions, one line per tree and cave.

    git worktree add /tmp/old 254c831           # the tree before the bounded memo
    python -m experiments.search_memory --old /tmp/old --time-limit 300 \\
        --caves rockfall:5001:5 shaft:5001:15 crevasse:5003:20 --out out/search-memory.png

`--memory-mb` caps the new tree's memo (`footstep.search_memory_mb`; default its default).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from experiments.arguments import OneLineParser, number, path_argument, whole
from experiments.sweep import machine_info
from rb_drake.errors import EXIT_OK

_CHILD = r"""
import json, resource, sys, time
from experiments.common import make_cave
from planning.complete_config import AnytimeConfig
from planning.footsteps import FootstepConfig, plan_footsteps
kind, seed, length, limit, every, cap = (sys.argv[1], int(sys.argv[2]), float(sys.argv[3]),
                                         float(sys.argv[4]), int(sys.argv[5]), sys.argv[6])
warm = make_cave("shaft", 5, (4.5, 5.0))
plan_footsteps(warm, FootstepConfig(max_expansions=3))  # load the compiled kernels first
scn = make_cave(kind, seed, (length, length))
extra = {} if cap == "default" else {"search_memory_mb": None if cap == "none" else float(cap)}
config = FootstepConfig(max_expansions=None, time_limit=limit,
                        anytime=AnytimeConfig(improve_factor=None), **extra)
curve = []
def progress(expansions, *args, **kwargs):
    if expansions % every == 0 and (not curve or curve[-1][0] != expansions):
        curve.append((expansions, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))
t0 = time.perf_counter()
fp = plan_footsteps(scn, config, progress=progress)
print(json.dumps({"stop": str(fp.stop), "success": bool(fp.success),
                  "expansions": int(fp.expansions), "seconds": time.perf_counter() - t0,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "curve": curve}))
"""


def run_cave(old: Path, new: Path, cave: tuple[str, int, float], limit: float, every: int,
             cap: str) -> dict[str, Any]:
    """One cave searched by both trees at once, one core each."""
    kind, seed, length = cave
    procs = {}
    for side, tree in (("old", old), ("new", new)):
        env = {**os.environ, "PYTHONPATH": str(tree), "RBP_THREADS": "1",
               "NUMBA_NUM_THREADS": "1"}
        procs[side] = subprocess.Popen(
            [sys.executable, "-c", _CHILD, kind, str(seed), str(length), str(limit),
             str(every), cap if side == "new" else "default"],
            cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict[str, Any] = {"kind": kind, "seed": seed, "length": length}
    for side, proc in procs.items():
        stdout, stderr = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f"{side} tree failed on {kind} {seed} {length} m:\n"
                               f"{stderr[-2000:]}")
        out[side] = json.loads(stdout.strip().splitlines()[-1])
        print(f"{kind} {seed} {length:g} m, {side}: {out[side]['expansions']} expansions, "
              f"{out[side]['seconds']:.0f} s, peak {out[side]['peak_mb']:.0f} MB "
              f"({out[side]['stop'] or 'route'})", flush=True)
    return out


def memory_figure(runs: list[dict[str, Any]], labels: tuple[str, str] = ("before", "bounded memo"),
                  title: str = "Footstep search memory (--thorough), before and after issue 31"):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, run in enumerate(runs):
        colour = f"C{k}"
        label = f"{run['kind']} {run['seed']}, {run['length']:g} m"
        for side, style in (("old", "--"), ("new", "-")):
            curve = run[side]["curve"]
            if curve:
                x, y = zip(*curve, strict=True)
                ax.plot(x, [v / 1024 for v in y], style, color=colour,
                        label=f"{label}, {labels[0] if side == 'old' else labels[1]}")
    ax.set_xlabel("expanded vertices")
    ax.set_ylabel("peak resident memory (GB)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _cave(text: str) -> tuple[str, int, float]:
    try:
        kind, seed, length = text.split(":")
        return kind, int(seed), float(length)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected KIND:SEED:LENGTH, got {text!r}") from None


def main(argv: list[str] | None = None) -> int:
    from rb_drake.files import atomic_save_figure, atomic_write_text

    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old", type=Path, required=True, help="the old source tree")
    parser.add_argument("--new", type=Path, default=Path(__file__).resolve().parents[1],
                        help="the new source tree (default: this one)")
    parser.add_argument("--caves", type=_cave, nargs="+",
                        default=[("rockfall", 5001, 5.0), ("shaft", 5001, 15.0),
                                 ("crevasse", 5003, 20.0)],
                        help="KIND:SEED:LENGTH of generated caves")
    parser.add_argument("--time-limit", type=number(0.001, 86_400), default=300.0,
                        help="s per search")
    parser.add_argument("--every", type=whole(1, 1_000_000_000), default=500,
                        help="expansions between memory samples")
    parser.add_argument("--memory-mb", default="default",
                        help="the new tree's cap in MiB, 'none' or 'default'")
    parser.add_argument("--labels", nargs=2, default=["before", "bounded memo"],
                        metavar=("OLD", "NEW"), help="the two trees' names in the figure")
    parser.add_argument("--title", default="Footstep search memory (--thorough), before and "
                        "after issue 31")
    parser.add_argument("--out", type=path_argument, default=Path("out/search-memory.png"))
    args = parser.parse_args(argv)
    runs = [run_cave(args.old, args.new, cave, args.time_limit, args.every, args.memory_mb)
            for cave in args.caves]
    atomic_save_figure(memory_figure(runs, tuple(args.labels), args.title), args.out, dpi=110)
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(
        {"machine": machine_info(), "args": {k: str(v) for k, v in vars(args).items()},
         "runs": runs}, indent=1) + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
