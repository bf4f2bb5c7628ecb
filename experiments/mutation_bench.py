"""Mutation benchmark of the plan verifier: random single faults in plans of bundled caves.

Plans each cave once (the `rbp plan` pipeline), then applies N random single faults
(`planning.plan_faults`), cycling through the caves, and verifies each damaged plan as
`rbp check` would. Reports how many were accepted (must be 0), how many were rejected but not
by one of their class's rules (or not in their phase and, where the class names one, step), and
per rule and per fault class how many each caught; with --out, writes the counts as JSON. Exit
status 1 if any fault was accepted or misattributed. --classes limits the faults to some
classes (the between-steps class alone: --classes between-cut).

    python -m experiments.mutation_bench --faults 1000
"""

from __future__ import annotations

import json
import sys
import time
from collections import Counter

import numpy as np

from experiments.arguments import OneLineParser, path_name, seed_number, whole
from planning.pipeline import plan_climb
from planning.plan_faults import FAULTS, judge, random_fault
from planning.plan_model import plan_dict
from rb_drake.errors import EXIT_FAILED, EXIT_OK, EXIT_USAGE
from rb_drake.files import atomic_write_text
from rb_drake.scenario import bundled_caves, load_scenario

CAVES = ("demo-shaft", "demo-crevasse", "rockfall-3")


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--faults", type=whole(1, 1_000_000), default=1000,
                        help="faults to try (default 1000)")
    parser.add_argument("--seed", type=seed_number, default=0, help="seed of the faults' draws")
    parser.add_argument("--caves", default=",".join(CAVES),
                        help=f"bundled caves, comma-separated (default {','.join(CAVES)})")
    parser.add_argument("--classes", help="only these fault classes, comma-separated (default: "
                        "all); e.g. --classes between-cut")
    parser.add_argument("--out", type=path_name, help="write the counts to this JSON file")
    args = parser.parse_args(argv)
    caves = bundled_caves()
    names = args.caves.split(",")
    unknown = sorted(set(names) - set(caves))
    if unknown:
        parser.error(f"--caves: unknown {unknown}; bundled caves are {', '.join(caves)}")
    kinds = args.classes.split(",") if args.classes else None
    wrong = sorted(set(kinds or ()) - set(FAULTS))
    if wrong:
        parser.error(f"--classes: unknown {wrong}; fault classes are {', '.join(FAULTS)}")
    if args.faults < 1:
        parser.error(f"--faults: must be at least 1, got {args.faults}")
    plans = {}
    for name in names:
        plan = plan_dict(plan_climb(load_scenario(caves[name])))
        if not plan["success"]:
            print(f"{name}: no plan ({plan['reason']})", file=sys.stderr)
            return EXIT_USAGE
        plans[name] = plan
    rng = np.random.default_rng(args.seed)
    by_rule: Counter[str] = Counter()
    by_class: Counter[str] = Counter()
    accepted, misattributed = [], []
    start = time.perf_counter()
    for i in range(args.faults):
        name = names[i % len(names)]
        kind = None if kinds is None else str(rng.choice(kinds))
        fault = random_fault(plans[name], rng, kind)
        verdict = judge(fault)
        by_class[fault.kind] += 1
        by_rule.update(verdict.rules)
        if not verdict.rejected:
            accepted.append(f"{name}: {fault.what}")
        elif not (verdict.right_rule and verdict.located):
            misattributed.append(f"{name}: {fault.what}: {sorted(verdict.rules)}")
    seconds = time.perf_counter() - start
    print(f"{args.faults} single faults in {len(names)} caves ({', '.join(names)}), "
          f"{seconds:.1f} s: {len(accepted)} accepted, {len(misattributed)} rejected without "
          "one of their class's rules (or not in their phase)")
    for line in (accepted + misattributed)[:20]:
        print(f"  {line}")
    print("faults per class: " + ", ".join(f"{k} {by_class[k]}" for k in FAULTS if by_class[k]))
    print("faults each rule reported: " + ", ".join(f"{r} {n}" for r, n in by_rule.most_common()))
    if args.out:
        atomic_write_text(args.out, json.dumps({
            "faults": args.faults, "seed": args.seed, "caves": names, "classes": kinds,
            "accepted": accepted, "misattributed": misattributed,
            "by_class": dict(by_class), "by_rule": dict(by_rule), "seconds": seconds},
            indent=1) + "\n")
        print(f"wrote {args.out}")
    return EXIT_FAILED if accepted or misattributed else EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
