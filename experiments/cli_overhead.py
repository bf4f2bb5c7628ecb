"""How much of `rbp plan` and `rbp check` wall time is spent outside planning.

Runs `rbp plan CAVE` as a user would (a subprocess: interpreter start-up, imports, planning,
writing, pictures), with and without pictures, then `rbp check` of the plan it wrote, and
reports each run's wall time as a ratio to the plan's own planning time (`timing.total` in the
plan file) of the same run. `import floor` is a fresh interpreter that imports only the libraries
planning needs (FLOOR_IMPORTS) and exits: no start-up of `rbp plan` can be shorter. With
`--before DIR` the same runs of another source tree (an older checkout, e.g.
`git worktree add DIR COMMIT`) are interleaved with these, so that a shared machine's load falls
on both alike. A benchmark, not a test: the numbers depend on the machine.

    python -m experiments.cli_overhead --cave demo-shaft --repeats 3 --out out/cli_overhead
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from statistics import median

from experiments.arguments import OneLineParser, path_name, whole
from rb_drake.errors import EXIT_FAILED, EXIT_OK

FLOOR_IMPORTS = ("numpy", "scipy.special", "scipy.sparse", "scipy.ndimage", "numba", "networkx",
                 "pydrake.solvers", "ompl", "yaml")


def timed(cmd: list[str], cwd: Path, tree: str | None) -> tuple[float,
                                                               subprocess.CompletedProcess[str]]:
    env = {**os.environ, "MPLBACKEND": "Agg", "LCM_DEFAULT_URL": "memq://"}
    if tree:
        env["PYTHONPATH"] = os.pathsep.join([tree, env.get("PYTHONPATH", "")])
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    return time.perf_counter() - t0, proc


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--cave", default="demo-shaft", help="scenario (default demo-shaft)")
    parser.add_argument("--repeats", type=whole(1, 1000), default=3,
                        help="runs of each (default 3)")
    parser.add_argument("--out", type=path_name, default="out/cli_overhead", help="output folder")
    parser.add_argument("--before", metavar="DIR",
                        help="also run the source tree DIR (no --no-pictures there), "
                             "interleaved, labelled 'before'")
    args = parser.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rbp = [sys.executable, "-m", "rbp"]
    variants: list[tuple[str, str | None, list[str]]] = [
        ("plan", None, []), ("plan --no-pictures", None, ["--no-pictures"])]
    if args.before:
        variants.insert(0, ("before: plan", str(Path(args.before).resolve()), []))
    rows = []
    # The third-party libraries `rbp plan` cannot plan without, imported and nothing else: the
    # floor under any start-up of a fresh process (os._exit: no teardown either).
    floor = [sys.executable, "-c", f"import {', '.join(FLOOR_IMPORTS)}, os; os._exit(0)"]
    for k in range(args.repeats):
        for n, (name, tree, extra) in enumerate(variants):
            plan_file = out / f"plan-{k}-{n}.json"
            wall, proc = timed([*rbp, "plan", args.cave, "-o", str(plan_file), *extra], out, tree)
            if proc.returncode != 0:
                print(proc.stdout, proc.stderr, file=sys.stderr)
                return EXIT_FAILED
            planning = json.loads(plan_file.read_text())["timing"]["total"]
            rows.append({"run": name, "repeat": k, "wall": wall, "planning": planning,
                         "ratio": wall / planning})
            check_wall, proc = timed([*rbp, "check", str(plan_file)], out, tree)
            if proc.returncode != 0:
                print(proc.stdout, proc.stderr, file=sys.stderr)
                return EXIT_FAILED
            check = "before: check" if tree else "check"
            rows.append({"run": check, "repeat": k, "wall": check_wall, "planning": planning,
                         "ratio": check_wall / planning})
        wall, proc = timed(floor, out, None)
        if proc.returncode != 0:
            print(proc.stdout, proc.stderr, file=sys.stderr)
            return EXIT_FAILED
        rows.append({"run": "import floor", "repeat": k, "wall": wall, "planning": planning,
                     "ratio": wall / planning})
    for r in rows:
        print(f"{r['run']:22s} #{r['repeat']}: wall {r['wall']:6.2f} s, planning "
              f"{r['planning']:6.2f} s, outside planning {r['wall'] - r['planning']:5.2f} s, "
              f"ratio {r['ratio']:.2f}")
    # Medians per kind of run: the machine may be shared, and one slow run says little.
    print("median over repeats:")
    for name in dict.fromkeys(r["run"] for r in rows):
        mine = [r for r in rows if r["run"] == name]
        print(f"  {name:22s} wall {median([r['wall'] for r in mine]):6.2f} s, outside planning "
              f"{median([r['wall'] - r['planning'] for r in mine]):5.2f} s, ratio to planning "
              f"{median([r['ratio'] for r in mine]):.2f}")
    (out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
