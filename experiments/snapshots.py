"""Snapshots of a climb through one cave (the paper's Fig. 5).

Plans a generated cave with the whole RBP pipeline (or its footsteps only) and draws the robot
at successive stances, grasped anchors' normals in red and the body's path dotted blue. A cave
where the planner finds no route is drawn as such; with `--tries K` the next seeds are tried
until one gives a plan.

    python -m experiments.snapshots --kind shaft --seed 1 --out out/snapshots
"""

from __future__ import annotations

from experiments.arguments import (
    MAX_EXPANSIONS,
    OneLineParser,
    number,
    path_name,
    seed_number,
    whole,
)
from experiments.common import make_cave, plan_cave, plan_record
from experiments.sweep import check_out_files, machine_info, write_results
from rb_drake.errors import EXIT_OK


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=path_name, default="out/snapshots", help="output folder")
    parser.add_argument("--kind", default="shaft", choices=("shaft", "crevasse", "rockfall"))
    parser.add_argument("--seed", type=seed_number, default=1, help="cave seed (default 1)")
    parser.add_argument("--tries", type=whole(1, 1000), default=3,
                        help="seeds to try, from --seed on, until one gives a plan (default 3)")
    parser.add_argument("--length", type=number(0, 1e4), nargs=2, default=(4.5, 5.0),
                        metavar=("MIN", "MAX"), help="cave length range in m (default 4.5 5.0)")
    parser.add_argument("--max-expansions", type=whole(1, MAX_EXPANSIONS), default=150,
                        help="RBP gives up after expanding this many stances (default 150)")
    parser.add_argument("--planner", choices=("rbp", "naive"), default="rbp")
    parser.add_argument("--footsteps-only", action="store_true",
                        help="draw the footstep plan (no seed and SCP trajectories)")
    parser.add_argument("--panels", type=whole(1, 1000), default=8,
                        help="at most this many snapshots")
    args = parser.parse_args(argv)
    if args.tries < 1 or args.panels < 1 or args.max_expansions < 1:
        parser.error("--tries, --panels and --max-expansions must be 1 or more")
    if not 2.0 <= args.length[0] <= args.length[1]:
        parser.error(f"--length: need 2 <= MIN <= MAX, got {args.length}")
    check_out_files(args.out, ("plan.json", "snapshots.png", "results.json"))

    from planning.figures import snapshots_figure
    from planning.plan import write_plan
    from rb_drake.files import atomic_save_figure

    attempts = []
    for seed in range(args.seed, args.seed + args.tries):
        scn = make_cave(args.kind, seed, tuple(args.length))
        plan = plan_cave(scn, args.planner, args.max_expansions, not args.footsteps_only)
        attempts.append({"seed": seed, "success": plan["success"], "reason": plan["reason"],
                         "seconds": plan["timing"]["total"]})
        print(f"{scn.name}: {args.planner} "
              + (f"p_path {plan['p_path']:.4f}, {plan['regrasps']} regrasps" if plan["success"]
                 else f"no plan ({plan['reason']})") + f" in {plan['timing']['total']:.1f} s")
        if plan["success"]:
            break
    path = write_plan(plan, f"{args.out}/plan.json")
    figure = atomic_save_figure(snapshots_figure(scn, plan, max_panels=args.panels),
                                f"{args.out}/snapshots.png", dpi=110)
    print(f"wrote {path}\nwrote {figure}")
    write_results(args.out, {
        "experiment": "snapshots", "machine": machine_info(), "params": vars(args) | {
            "length": list(args.length)},
        "cave": scn.name, "plan": plan_record(plan), "attempts": attempts,
        "figure": str(figure), "plan_file": str(path)})
    return EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
