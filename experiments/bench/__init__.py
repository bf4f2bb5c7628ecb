"""Benchmark rbp against what a user would write instead, side by side on the same inputs.

Three sections, each run in this one process, cases interleaved so that a noisy shared machine
slows every method alike; times are medians over cases.

* allocation: the most robust tensions at a pose. Ours: `statics.allocate` (per pose, and
  vectorised over a batch), `statics.ForceAllocator` (Drake + OSQP / Clarabel). Theirs: the
  public ReachBot code's formulation, cvxpy maximising sum cp.log_normcdf(z_i) subject to
  A f = b and the tension bounds (a DPP problem built once, re-solved with Clarabel and ECOS),
  and scipy SLSQP on the exact objective (log_ndtr). All maximise the same J = sum log Phi(z_i)
  - REGULARISATION/2 |f|^2; every answer is scored with the exact J, against the best answer
  of the case. cp.log_normcdf is a piecewise quadratic approximation (exactly 0 for z >= 3),
  so cvxpy's own objective value is compared with the exact one too. Cases: random poses and
  stances on the bundled caves, feasible by `check_poses` (4- and 3-stances), plus 4-stances
  whose statics hold but whose probability is below p_min (the planner allocates those too).
* scp: one phase's trajectory. Ours: `scp.optimise_body` / `optimise_reach` on seeds from
  `seeds.body_seed` / `reach_seed` along the first moves of a climb on the bundled caves.
  Theirs: one nonlinear program of the same phase solved by IPOPT (bundled with Drake; allowed
  here, never in the product): the exact geometry, written here independently of rb_drake as
  a function of the poses that Drake differentiates (AutoDiffXd), the statics A(q) f = b(q),
  boom length, shoulder angle, pull angle and shoulder torque limits as constraints, r_k >=
  log p_min, fixed start and goal states and the merit of `planning.scp` (robustness, dynamics
  penalty, smoothness), from the same seed. Differences, each forced by the method: collisions
  are not modelled (not smooth); the floor is log p_min, not SCP's max(log p_min, the seed's
  least r_k), which starves the interior-point method where the seed is near certain; poses
  and velocities are boxed far from the seed (interior-point methods diverge on unbounded
  variables here). Both answers are re-checked with `check_poses` and scored with the merit
  of `PhaseProgram.evaluate`; the program's own merit is checked equal to it at the seed.
* footstep: `footsteps.plan_footsteps` against `baseline.plan_naive` on short generated caves.

Writes every case and a summary to a JSON file; `--compare OLD.json` prints new/old ratios of
every summary metric.

    python -m experiments.bench --only allocation,scp --samples 300 --out out/bench
    rbp bench --compare out/bench/bench-old.json

The sections are `allocation.py`, `scp.py` (its phases `phases.py`, the IPOPT program
`ipopt.py`) and `footstep.py`; `report.py` holds the results file and --compare; `stats.py`
what they share.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from experiments.arguments import (
    OneLineParser,
    json_type,
    path_name,
    read_json_file,
    seed_number,
    whole,
)
from experiments.bench.allocation import run_allocation
from experiments.bench.footstep import run_footstep
from experiments.bench.report import jsonable, machine, print_comparison
from experiments.bench.scp import run_scp
from rb_drake.errors import EXIT_OK, EXIT_USAGE, one_line
from rb_drake.files import atomic_write_text, output_problem
from rb_drake.input_files import InputFileError

SECTIONS = ("allocation", "scp", "footstep")
FORMAT = "rbp-bench/1"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections (default: {','.join(SECTIONS)})")
    parser.add_argument("--samples", type=whole(1, 10_000), default=300,
                        help="allocation cases, 1 to 10,000 (default 300)")
    parser.add_argument("--moves", type=whole(1, 100), default=4,
                        help="scp: regrasps along climbs of the bundled caves; each gives a "
                             "body and a reach phase, 1 to 100 (default 4)")
    parser.add_argument("--ipopt-iterations", type=whole(1, 100_000), default=1000,
                        help="scp: IPOPT's iteration cap per phase, 1 to 100,000 "
                             "(default 1000)")
    parser.add_argument("--caves", type=whole(1, 1000), default=3,
                        help="footstep: generated caves, 1 to 1000 (default 3)")
    parser.add_argument("--max-expansions", type=whole(1, 1_000_000), default=60,
                        help="footstep: the planners' cap, 1 to 1,000,000 (default 60)")
    parser.add_argument("--seed", type=seed_number, default=0)
    parser.add_argument("--out", type=path_name, default="out/bench",
                        help="output folder (default out/bench)")
    parser.add_argument("--json", metavar="FILE", type=path_name,
                        help="results file (default OUT/bench.json)")
    parser.add_argument("--compare", metavar="OLD", type=path_name,
                        help="an earlier results file: print the "
                        "ratio new/old of every summary metric")


def run(args: argparse.Namespace) -> int:
    sections = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = sorted(set(sections) - set(SECTIONS))
    if not sections:  # --only '' or ',,': no work, and an empty results file said it ran
        print(one_line(f"error: --only: no section given ({args.only!r}); choose from "
                       f"{list(SECTIONS)}"), file=sys.stderr)
        return EXIT_USAGE
    if unknown:
        print(one_line(f"error: --only: unknown section(s) {unknown}; choose from "
                       f"{list(SECTIONS)}"), file=sys.stderr)
        return EXIT_USAGE
    out = Path(args.json) if args.json else Path(args.out) / "bench.json"
    # before any work, and never over the --compare file it reads (it was overwritten)
    if (problem := output_problem(out, {"--compare's file": args.compare})) is not None:
        print(one_line(f"error: {out}: {'--json' if args.json else '--out'}: {problem}"),
              file=sys.stderr)
        return EXIT_USAGE
    old = None
    if args.compare:  # read first: a bad file should fail before minutes of benchmarking
        try:  # the bounded reader: /dev/zero or a huge file is refused, not read
            old = read_json_file(args.compare, object)
            comparable(old)
        except InputFileError as e:
            print(f"error: {one_line(args.compare)}: {e}", file=sys.stderr)
            return EXIT_USAGE
    result: dict[str, Any] = {
        "format": FORMAT, "created": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(),
        "options": {k: v for k, v in vars(args).items() if k != "func"}, "sections": {}}
    started = time.perf_counter()
    for name in SECTIONS:
        if name not in sections:
            continue
        if name == "allocation":
            result["sections"][name] = run_allocation(args.samples, args.seed)
        elif name == "scp":
            result["sections"][name] = run_scp(args.moves, args.seed, args.ipopt_iterations)
        else:
            result["sections"][name] = run_footstep(args.caves, args.max_expansions, args.seed)
    result["seconds"] = time.perf_counter() - started
    atomic_write_text(out, json.dumps(result, indent=1, default=jsonable))
    print(f"\nwrote {out} ({result['seconds']:.0f} s)")
    if old is not None:
        print_comparison(old, result, args.compare)
    return EXIT_OK


def comparable(old: Any) -> None:
    """Refuse (InputFileError naming the field) a --compare file that is not an rbp bench
    results file's shape: an object whose "sections" hold objects whose "summary" is one."""
    if not isinstance(old, dict):
        raise InputFileError("(file)", "must be a JSON object (an rbp bench results file), got "
                             f"{type(old).__name__}")
    if old.get("format", FORMAT) != FORMAT:  # a GeoJSON was compared with "no metric in common"
        raise InputFileError("format", f"must be {FORMAT!r} (an rbp bench results file), got "
                             f"{one_line(repr(old['format']))[:80]}")
    if "sections" not in old:
        raise InputFileError("sections", "missing: not an rbp bench results file")
    sections = old["sections"]
    if not isinstance(sections, dict):
        raise InputFileError("sections", "must be an object")
    for name, section in sections.items():
        if not isinstance(section, dict) or not isinstance(section.get("summary", {}), dict):
            raise InputFileError(f"sections.{name}", "must be an object with a summary object")
    if not isinstance(old.get("created", ""), str):  # printed as the comparison's heading
        raise InputFileError("created", "must be a string (when it was measured), got "
                             f"{json_type(old['created'])}")


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))
