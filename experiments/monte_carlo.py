"""Is p_path calibrated? The plans' predicted success probability against the success rate of
simulated executions with stochastic grasps, over many plans.

Each trial plans one cave with the whole RBP pipeline (the baseline comparison's caves), runs
the plan once in the Drake simulation (systems.diagram.ClimbSimulator), then draws `--runs`
stochastic executions of it (grasp strengths and attach failures, systems.montecarlo) and
records how many reach the goal. The calibration plot puts each plan at x = p_path, y = its
empirical rate with the 95 % Wilson interval, the plans pooled by p_path in bins, and the
diagonal. results.json holds the per-plan numbers and how many intervals contain p_path.

    python -m experiments.monte_carlo --trials 30 --runs 1000 --out out/monte_carlo
"""

from __future__ import annotations

import argparse
import itertools
from typing import Any

from experiments.arguments import MAX_RUNS, OneLineParser, seed_number, whole
from experiments.common import (
    add_cave_arguments,
    check_cave_arguments,
    climb_trials,
    plan_cave,
    plan_record,
    trial_cave,
)
from experiments.records import (
    BOOLEAN,
    COUNT,
    INTERVAL,
    MAGNITUDE,
    PROBABILITY,
    STRING,
    fields_problem,
    maybe,
    simulation_problem,
)
from experiments.sweep import (
    RESULT_CHECKS,
    Trial,
    add_sweep_arguments,
    machine_info,
    ok_records,
    quantiles,
    sweep,
    write_results,
)
from rb_drake.errors import EXIT_FAILED, EXIT_OK

BINS = (0.0, 0.5, 0.8, 0.9, 0.95, 0.98, 1.0)  # p_path bins of the pooled calibration


def simulate_trial(runs: int, mc_seed: int, **params: Any) -> dict[str, Any]:
    """Plan one cave (the climb trial's parameters), simulate the plan, then `runs`
    stochastic executions: {"plan": ..., "simulated": ... or None, "timing": ...}."""
    import time

    from systems.diagram import ClimbSimulator
    from systems.montecarlo import monte_carlo
    from systems.trajectory import PlanTrajectory

    start = time.perf_counter()
    try:
        scn = trial_cave(params)
    except RuntimeError as e:
        return {"plan": {"success": False, "reason": f"no cave: {e}", "p_path": None},
                "simulated": None, "timing": {"plan": time.perf_counter() - start}}
    plan = plan_cave(scn, "rbp", params["max_expansions"], motion=True)
    record = plan_record(plan)
    record.pop("motion", None)
    timing = {"plan": time.perf_counter() - start}
    if not plan["success"]:
        return {"plan": record, "simulated": None, "timing": timing}
    start = time.perf_counter()
    simulation = ClimbSimulator(scn).run(PlanTrajectory(plan, scn))
    mc = monte_carlo(simulation, runs, mc_seed)
    timing["simulate"] = time.perf_counter() - start
    err = simulation.position_error
    return {"plan": record, "timing": timing, "simulated": {
        "runs": mc.trials, "successes": mc.successes, "rate": mc.rate, "ci95": list(mc.ci95),
        "p_sim": mc.p_sim, "max_position_error": float(err.max()),
        "failures": mc.to_json()["failures"]}}


SIMULATE_TRIAL = "experiments.monte_carlo:simulate_trial"
# What the summaries read of a simulated plan (its runs, the rate's interval); `simulated_problem`
# (experiments.records.simulation_problem also checks that the counts agree)
_SIMULATED = {"runs": COUNT, "successes": COUNT, "rate": PROBABILITY, "ci95": INTERVAL,
              "p_sim": PROBABILITY, "max_position_error": MAGNITUDE,
              "failures": (lambda v: fields_problem(v, "", {}) is None, "an object")}


RESULT_CHECKS[SIMULATE_TRIAL] = lambda params, record: simulation_problem(
    record, {"success": BOOLEAN, "reason": STRING, "p_path": maybe(PROBABILITY)}, _SIMULATED)


def calibration_trials(args: argparse.Namespace) -> list[Trial]:
    """The climb trials' caves, each with the Monte Carlo settings."""
    trials = []
    for t in climb_trials(args, ["rbp"], motion=True):
        params = {k: v for k, v in t.params.items() if k not in ("planners", "motion")}
        trials.append(Trial(t.name, SIMULATE_TRIAL,
                            params | {"runs": args.runs, "mc_seed": args.mc_seed}))
    return trials


def simulated(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per simulated plan: trial name, p_path and the simulation's numbers."""
    # the simulation's own keys first: a "p_path" or "trial" in it (unchecked) cannot replace
    # the plan's
    return [{**r["result"]["simulated"], "trial": r["name"],
             "p_path": r["result"]["plan"]["p_path"]}
            for r in records if r["result"]["simulated"]]


def pooled(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Plans pooled by p_path bin: mean p_path against the pooled rate and its interval."""
    from systems.montecarlo import wilson_interval

    out = []
    for lo, hi in itertools.pairwise(BINS):
        mine = [r for r in rows if lo <= r["p_path"] < hi or (hi == 1.0 and r["p_path"] == 1.0)]
        if not mine:
            continue
        successes, runs = sum(r["successes"] for r in mine), sum(r["runs"] for r in mine)
        out.append({"bin": [lo, hi], "plans": len(mine),
                    "p_path_mean": sum(r["p_path"] for r in mine) / len(mine),
                    "runs": runs, "successes": successes, "rate": successes / runs,
                    "ci95": list(wilson_interval(successes, runs))})
    return out


def calibration_figure(rows: list[dict[str, Any]], bins: list[dict[str, Any]]):
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(5.6, 5.2))
    lo = min([0.8] + [r["p_path"] for r in rows] + [r["ci95"][0] for r in rows])
    if rows:
        x = np.array([r["p_path"] for r in rows])
        y = np.array([r["rate"] for r in rows])
        ci = np.array([r["ci95"] for r in rows])
        ax.errorbar(x, y, yerr=[y - ci[:, 0], ci[:, 1] - y], fmt="o", ms=4, color="#2171b5",
                    alpha=0.7, capsize=2, label=f"plans ({len(rows)})")
    if bins:
        x = np.array([b["p_path_mean"] for b in bins])
        y = np.array([b["rate"] for b in bins])
        ci = np.array([b["ci95"] for b in bins])
        ax.errorbar(x, y, yerr=[y - ci[:, 0], ci[:, 1] - y], fmt="s", ms=7, color="#cb181d",
                    capsize=3, label="pooled by p_path bin")
    ax.plot([lo, 1.0], [lo, 1.0], "k--", lw=0.8, label="calibrated")
    ax.set_xlabel("predicted p_path")
    ax.set_ylabel("simulated success rate (95% Wilson CI)")
    ax.set_xlim(lo - 0.01, 1.005)
    ax.set_ylim(lo - 0.01, 1.005)
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="upper left")
    runs = rows[0]["runs"] if rows else 0
    ax.set_title(f"calibration: {runs} simulated executions per plan", fontsize=10)
    fig.tight_layout()
    return fig


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_sweep_arguments(parser, trials=50, out="out/monte_carlo")
    add_cave_arguments(parser)
    parser.add_argument("--runs", type=whole(1, MAX_RUNS), default=1000,
                        help="stochastic executions per plan 1 to 100,000 (default 1000)")
    parser.add_argument("--mc-seed", type=seed_number, default=0,
                        help="seed of the executions' draws (default 0)")
    args = parser.parse_args(argv)
    check_cave_arguments(parser, args)
    if args.runs < 1:
        parser.error(f"--runs: must be 1 or more, got {args.runs}")

    from rb_drake.files import atomic_save_figure

    records = sweep(calibration_trials(args), args, experiment="monte_carlo")
    done = ok_records(records)
    rows = simulated(done)
    bins = pooled(rows)
    inside = sum(r["ci95"][0] <= r["p_path"] <= r["ci95"][1] for r in rows)
    gap = [r["rate"] - r["p_path"] for r in rows]
    print(f"{len(rows)} plans simulated ({args.runs} runs each): p_path inside the 95% "
          f"interval for {inside}; rate - p_path: "
          + (f"median {quantiles(gap)['median']:+.4f}" if gap else "n/a"))
    figure = atomic_save_figure(calibration_figure(rows, bins), f"{args.out}/calibration.png",
                                dpi=120)
    print(f"wrote {figure}")
    results = {
        "experiment": "monte_carlo", "machine": machine_info(),
        "params": {"trials": args.trials, "kind": args.kind, "first_seed": args.first_seed,
                   "length": list(args.length), "max_expansions": args.max_expansions,
                   "runs": args.runs, "mc_seed": args.mc_seed},
        "summary": {"trials": len(done), "plans": len(rows), "p_path_inside_ci95": inside,
                    "rate_minus_p_path": quantiles(gap), "pooled": bins},
        "plans": rows,
        "failed_plans": [{"trial": r["name"], "reason": r["result"]["plan"]["reason"]}
                         for r in done if not r["result"]["simulated"]],
        "errors": [r["name"] for r in records if r["error"] is not None],
        "figure": str(figure),
    }
    write_results(args.out, results)
    return EXIT_FAILED if results["errors"] else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
