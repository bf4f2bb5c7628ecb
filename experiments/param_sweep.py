"""How RBP fares as one parameter changes: success rate and median p_path against its value.

For each value of `--param` and each of `--trials` caves (the same caves, by seed, for every
value), plans the cave with the chosen planner and records the outcome. Parameters:
p_min (the robot's required configuration probability), gripper_scale (every anchor's limit
surface scaled), anchor_density (anchors per metre of rock), gravity (its magnitude, m/s^2).

    python -m experiments.param_sweep --param anchor_density --values 2,3,4 --trials 10
"""

from __future__ import annotations

import argparse
from typing import Any

from experiments.arguments import OneLineParser, decimal
from experiments.common import (
    add_cave_arguments,
    check_cave_arguments,
    climb_trials,
    path_probabilities,
)
from experiments.sweep import (
    add_sweep_arguments,
    machine_info,
    ok_records,
    quantiles,
    sweep,
    write_results,
)
from rb_drake.errors import EXIT_FAILED, EXIT_OK
from rb_drake.generate import MAX_ANCHOR_DENSITY
from rb_drake.scenario import MAX_FORCE, MAX_GRAVITY

# The ranges of the scenario fields each parameter sets (rb_drake.scenario, docs/formats.md),
# so that no swept value makes a cave the scenario reader would refuse (gravity 1e4 hung the
# planner; 1e308 overflowed): an anchor's largest limit (50 N) scaled stays within MAX_FORCE.
MAX_GRIPPER_SCALE = MAX_FORCE / 100  # x the generator's largest limit, 50 N
MIN_GRIPPER_SCALE = 1e-6  # x its smallest, 15 N: far below any grip, and never 0 N

# name -> (label, the check of one value, its range in words)
PARAMETERS = {
    "p_min": ("required configuration probability p_min", lambda v: 0.0 < v < 1.0,
              "above 0 and below 1"),
    "gripper_scale": ("gripper strength scale (every anchor's limit)",
                      lambda v: MIN_GRIPPER_SCALE <= v <= MAX_GRIPPER_SCALE,
                      f"{MIN_GRIPPER_SCALE:g} to {MAX_GRIPPER_SCALE:g}"),
    "anchor_density": ("anchor density (per metre of rock)",
                       lambda v: 0.0 < v <= MAX_ANCHOR_DENSITY,
                       f"above 0 and at most {MAX_ANCHOR_DENSITY:g}"),
    "gravity": ("gravity magnitude (m/s^2)", lambda v: 0.0 < v <= MAX_GRAVITY,
                f"above 0 and at most {MAX_GRAVITY:g}"),
}


def value_summary(records: list[dict[str, Any]], planner: str) -> dict[str, Any]:
    from systems.montecarlo import wilson_interval

    rows = [r["result"][planner] for r in records]
    successes = sum(bool(row["success"]) for row in rows)
    return {"trials": len(rows), "successes": successes,
            "success_rate": successes / len(rows) if rows else None,
            "success_ci95": list(wilson_interval(successes, len(rows))) if rows else None,
            "p_path_successes": quantiles([row["p_path"] for row in rows if row["success"]]),
            "p_path": quantiles(path_probabilities(records, planner)),
            "reasons": sorted({row["reason"].split(";")[0] for row in rows
                               if not row["success"]})}


def sweep_figure(param: str, values: list[float], summary: list[dict[str, Any]], planner: str):
    """Success rate (95 % Wilson interval) and median p_path of the plans found (IQR)."""
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.0, 6.0), sharex=True)
    x = np.array(values)
    rate = np.array([s["success_rate"] for s in summary])
    ci = np.array([s["success_ci95"] for s in summary])
    top.errorbar(x, rate, yerr=[rate - ci[:, 0], ci[:, 1] - rate], fmt="o-", capsize=3,
                 color="#2171b5")
    top.set_ylabel("success rate (95% CI)")
    top.set_ylim(-0.02, 1.02)
    found = [k for k, s in enumerate(summary) if s["p_path_successes"]["n"]]
    if found:
        q = [summary[k]["p_path_successes"] for k in found]
        med = np.array([v["median"] for v in q])
        bottom.errorbar(x[found], med, yerr=[med - [v["q1"] for v in q],
                                             [v["q3"] for v in q] - med],
                        fmt="s-", capsize=3, color="#d95f02")
    bottom.set_ylabel("median p_path of the plans (IQR)")
    bottom.set_xlabel(PARAMETERS[param][0])
    n = summary[0]["trials"] if summary else 0
    top.set_title(f"{planner} over {n} caves per value", fontsize=10)
    fig.tight_layout()
    return fig


def parse_values(parser: argparse.ArgumentParser, param: str, text: str) -> list[float]:
    given = [v.strip() for v in text.split(",")]
    if not all(given):  # "0.5,,0.6" dropped its empty item: a typo, not two values
        parser.error(f"--values: an empty item in {text!r}")
    try:  # as --length reads a number: float() took "1_0" as 10 and full-width digits
        values = [decimal(v) for v in given]
    except argparse.ArgumentTypeError:
        parser.error(f"--values: comma-separated numbers, got {text!r}")
    if not values or len(set(values)) != len(values):
        parser.error(f"--values: give distinct values, got {text!r}")
    # a value's trials, line and figure are named by its %g (6 digits): two values alike there
    # made one trial name twice ("error: trial name ...: used twice in one sweep")
    shown = [f"{v:g}" for v in values]
    if len(set(shown)) != len(shown):
        twice = next(s for k, s in enumerate(shown) if s in shown[:k])
        parser.error(f"--values: two values read {twice} to 6 significant digits, which name "
                     f"the trials; give values that differ there, got {text!r}")
    # as given: 20.0000001 printed with %g read "20 is not ... at most 20"
    bad = [g for g, v in zip(given, values, strict=True) if not PARAMETERS[param][1](v)]
    if bad:
        parser.error(f"--values: {bad[0]} is not a valid {param}: must be "
                     f"{PARAMETERS[param][2]}")
    return values


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_sweep_arguments(parser, trials=10, out="out/param_sweep")
    add_cave_arguments(parser)
    parser.add_argument("--param", required=True, choices=tuple(PARAMETERS))
    parser.add_argument("--values", required=True, help="comma-separated values, e.g. 2,3,4")
    parser.add_argument("--planner", choices=("rbp", "naive"), default="rbp")
    parser.add_argument("--motion", action="store_true",
                        help="plan the whole climb (seeds and SCP), not only the footsteps")
    args = parser.parse_args(argv)
    check_cave_arguments(parser, args)
    values = parse_values(parser, args.param, args.values)

    from rb_drake.files import atomic_save_figure

    trials = [t for v in values for t in climb_trials(
        args, [args.planner], args.motion, prefix=f"{args.param}={v:g}-", **{args.param: v})]
    records = sweep(trials, args, experiment="param_sweep")
    done = ok_records(records)
    summary = []
    for v in values:
        mine = [r for r in done if r["params"][args.param] == v]
        summary.append({"value": v, **value_summary(mine, args.planner)})
        s = summary[-1]
        med = s["p_path_successes"]["median"]
        print(f"{args.param} = {v:g}: {s['successes']}/{s['trials']} plans, median p_path "
              + ("n/a" if med is None else f"{med:.4f}"))
    figure = atomic_save_figure(sweep_figure(args.param, values, summary, args.planner),
                                f"{args.out}/param_sweep-{args.param}.png", dpi=120)
    print(f"wrote {figure}")
    results = {
        "experiment": "param_sweep", "machine": machine_info(),
        "params": {"param": args.param, "values": values, "trials": args.trials,
                   "planner": args.planner, "motion": args.motion, "kind": args.kind,
                   "first_seed": args.first_seed, "length": list(args.length),
                   "max_expansions": args.max_expansions},
        "summary": summary,
        "trials": [{"name": r["name"], "value": r["params"][args.param],
                    "kind": r["params"]["kind"], "seed": r["params"]["seed"],
                    **{k: r["result"][args.planner][k]
                       for k in ("success", "p_path", "regrasps", "reason")}} for r in done],
        "errors": [r["name"] for r in records if r["error"] is not None],
        "figure": str(figure),
    }
    write_results(args.out, results)
    return EXIT_FAILED if results["errors"] else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
