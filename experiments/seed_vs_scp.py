"""What SCP makes of the seeds (the paper's Fig. 6), for one body and one reach phase and over
every phase of every trial.

Each trial runs the whole RBP pipeline on one cave (the baseline comparison's caves) and keeps,
per phase, the seed's and the optimised trajectory's minimum and mean probability of success
(`planning.pipeline.motion_summary`). results.json holds their distribution per phase kind (the
improvement SCP gives: optimised minus seed), the figure scp.png plots optimised against seed
per phase, and Fig. 6 (tensions and probability over time, seed against SCP) is drawn for the
body and the reach phase where SCP raised the mean probability most, in the first trial that
found a plan (planned again here, from the same parameters).

    python -m experiments.seed_vs_scp --trials 20 --out out/seed_vs_scp
"""

from __future__ import annotations

from typing import Any

from experiments.arguments import OneLineParser
from experiments.common import (
    add_cave_arguments,
    check_cave_arguments,
    climb_trials,
    plan_cave,
    plan_record,
    trial_cave,
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

KINDS = ("body", "reach")
TOLERANCE = 1e-9  # a change in P smaller than this is no change


def phase_rows(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every optimised phase of every successful plan, with its trial's name."""
    return [{"trial": r["name"], **row} for r in records
            if r["result"]["rbp"]["success"] for row in r["result"]["rbp"].get("motion", [])]


def improvement_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    summary = {}
    for kind in KINDS:
        mine = [r for r in rows if r["kind"] == kind]
        gain_min = [r["min"] - r["seed_min"] for r in mine]
        gain_mean = [r["mean"] - r["seed_mean"] for r in mine]
        statuses: dict[str, int] = {}
        for r in mine:
            statuses[r["status"]] = statuses.get(r["status"], 0) + 1
        summary[kind] = {
            "phases": len(mine),
            "min_raised": sum(g > TOLERANCE for g in gain_min),
            "min_lowered": sum(g < -TOLERANCE for g in gain_min),
            "mean_raised": sum(g > TOLERANCE for g in gain_mean),
            "mean_lowered": sum(g < -TOLERANCE for g in gain_mean),
            "gain_min": quantiles(gain_min), "gain_mean": quantiles(gain_mean),
            "seed_min": quantiles([r["seed_min"] for r in mine]),
            "min": quantiles([r["min"] for r in mine]),
            "scp_status": statuses,
            # SCP keeps the ends fixed: what it can raise, and how often it does
            "with_room": sum(r["room"] for r in mine),
            "mean_raised_with_room": sum(r["room"] and g > TOLERANCE
                                         for r, g in zip(mine, gain_mean, strict=True)),
            "min_inside": sum(not r["seed_min_at_end"] for r in mine),
            "min_raised_inside": sum(not r["seed_min_at_end"] and g > TOLERANCE
                                     for r, g in zip(mine, gain_min, strict=True)),
        }
    return summary


def scp_figure(rows: list[dict[str, Any]]):
    """Optimised against seed, per phase: minimum P (left) and mean P (right)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.2))
    colours = {"body": "#2171b5", "reach": "#d95f02"}
    for ax, what in zip(axes, ("min", "mean"), strict=True):
        lo = min([r[f"seed_{what}"] for r in rows] + [r[what] for r in rows] + [0.9])
        for kind in KINDS:
            mine = [r for r in rows if r["kind"] == kind]
            ax.plot([r[f"seed_{what}"] for r in mine], [r[what] for r in mine], "o", ms=4,
                    alpha=0.7, color=colours[kind], label=f"{kind} ({len(mine)} phases)")
        ax.plot([lo, 1.0], [lo, 1.0], "k--", lw=0.8, label="no change")
        ax.set_xlabel(f"{what} P of the seed")
        ax.set_ylabel(f"{what} P after SCP")
        ax.set_aspect("equal")
        ax.legend(fontsize=8)
    fig.suptitle("SCP against its seed, per phase", fontsize=11)
    fig.tight_layout()
    return fig


def best_phases(plan: dict[str, Any]) -> dict[str, int]:
    """Per kind, the phase where SCP raised the mean probability most."""
    from planning.pipeline import motion_summary
    from planning.plan_model import plan_of

    best: dict[str, int] = {}
    for kind in KINDS:
        rows = [r for r in motion_summary(plan_of(plan)) if r["kind"] == kind]
        if rows:
            best[kind] = max(rows, key=lambda r: r["mean"] - r["seed_mean"])["phase"]
    return best


def phase_figures(record: dict[str, Any], out: str) -> dict[str, Any]:
    """Plan the record's cave again and draw Fig. 6 for its best body and reach phase."""
    from planning.figures import phase_figure
    from planning.plan import write_plan
    from rb_drake.files import atomic_save_figure

    p = record["params"]
    scn = trial_cave(p)
    plan = plan_cave(scn, "rbp", p["max_expansions"], motion=True)
    path = write_plan(plan, f"{out}/plan.json")
    print(f"wrote {path}")
    figures = {}
    for kind, k in best_phases(plan).items():
        fig = atomic_save_figure(phase_figure(plan, k), f"{out}/fig6-{kind}.png", dpi=120)
        print(f"wrote {fig}")
        figures[kind] = {"phase": k, "figure": str(fig)}
    same = plan_record(plan) == record["result"]["rbp"]
    return {"trial": record["name"], "plan": str(path), "phases": figures,
            "reproduces_trial": same}


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_sweep_arguments(parser, trials=100, out="out/seed_vs_scp")
    add_cave_arguments(parser)
    args = parser.parse_args(argv)
    check_cave_arguments(parser, args)

    from rb_drake.files import atomic_save_figure

    records = sweep(climb_trials(args, ["rbp"], motion=True), args,
                    experiment="seed_vs_scp")
    done = ok_records(records)
    rows = phase_rows(done)
    summary = improvement_summary(rows)
    for kind, s in summary.items():
        g = s["gain_mean"]
        print(f"{kind}: {s['phases']} phases; SCP raised the minimum P in {s['min_raised']} "
              f"and the mean P in {s['mean_raised']}" +
              (f" (median gain {g['median']:.2e})" if g["n"] else "") +
              f"; the mean in {s['mean_raised_with_room']} of the {s['with_room']} with room, "
              f"the minimum in {s['min_raised_inside']} of the {s['min_inside']} whose seed's "
              "minimum is not at a fixed end")
    figure = atomic_save_figure(scp_figure(rows), f"{args.out}/scp.png", dpi=120)
    print(f"wrote {figure}")
    first = next((r for r in done if r["result"]["rbp"]["success"]), None)
    fig6 = phase_figures(first, args.out) if first is not None else None
    results = {
        "experiment": "seed_vs_scp", "machine": machine_info(),
        "params": {"trials": args.trials, "kind": args.kind, "first_seed": args.first_seed,
                   "length": list(args.length), "max_expansions": args.max_expansions},
        "summary": {"plans": sum(r["result"]["rbp"]["success"] for r in done),
                    "trials": len(done), **summary},
        "fig6": fig6, "phases": rows,
        "errors": [r["name"] for r in records if r["error"] is not None],
        "figure": str(figure),
    }
    write_results(args.out, results)
    return EXIT_FAILED if results["errors"] else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
