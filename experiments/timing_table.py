"""Computation time of each stage of the plan (the paper's Table I), ours beside the paper's.

Each trial runs the whole pipeline (RBP footsteps, then a seed and SCP for every body and
end-effector phase) and the naive footstep planner on one cave (the baseline comparison's
caves). A plan's `timing` holds each stage's total; the time per segment is that total divided
by the plan's number of phases of that kind (body or reach), per successful plan. The table
gives medians with the interquartile range over the trials, and means (the paper's numbers
are averages over 100 trials), with the machine they ran on.

    python -m experiments.timing_table --trials 20 --out out/timing
"""

from __future__ import annotations

import json
from typing import Any

from experiments.arguments import OneLineParser
from experiments.common import (
    add_cave_arguments,
    check_cave_arguments,
    climb_trials,
    planner_summary,
    stage_times,
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

# (row key, label, the paper's RBP seconds, the paper's naive seconds)
PAPER = (
    ("footstep", "footstep plan", 66.19, 0.0123),
    ("seed_body", "seed for body movement (per segment)", 0.0839, None),
    ("scp_body", "SCP for body movement (per segment)", 10.80, None),
    ("seed_reach", "seed for end-effector movement (per segment)", 0.0417, None),
    ("scp_reach", "SCP for end-effector movement (per segment)", 50.09, None),
)
SEGMENT = {"seed_body": "body", "scp_body": "body", "seed_reach": "reach", "scp_reach": "reach"}


def per_segment(records: list[dict[str, Any]], stage: str) -> list[float]:
    """Per successful RBP plan with phases of the stage's kind: stage total / phase count."""
    values = []
    for r in records:
        plan = r["result"]["rbp"]
        count = plan["phases"][SEGMENT[stage]]
        if plan["success"] and count:
            values.append(r["timing"]["rbp"][stage] / count)
    return values


def timing_rows(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    rows = {}
    for key, label, paper_rbp, paper_naive in PAPER:
        if key == "footstep":
            ours = quantiles(stage_times(records, "rbp", "footstep"))
            ok = [r for r in records if r["result"]["rbp"]["success"]]
            rows[key] = {"label": label, "rbp": ours,
                         "rbp_successes": quantiles(stage_times(ok, "rbp", "footstep")),
                         "rbp_whole": quantiles(stage_times(ok, "rbp", "total")),
                         "naive": quantiles(stage_times(records, "naive", "footstep")),
                         "paper_rbp": paper_rbp, "paper_naive": paper_naive}
        else:
            rows[key] = {"label": label, "rbp": quantiles(per_segment(records, key)),
                         "paper_rbp": paper_rbp, "paper_naive": paper_naive}
    return rows


def _cell(q: dict[str, Any] | None) -> str:
    if not q or not q["n"]:
        return "n/a"
    return (f"{q['median']:.3g} [{q['q1']:.3g}, {q['q3']:.3g}] (mean {q['mean']:.3g}, "
            f"n={q['n']})")


def markdown_table(rows: dict[str, dict[str, Any]], machine: list[dict[str, Any]]) -> str:
    """Table I as Markdown: ours (median [IQR], mean, n) beside the paper's, then machines."""
    lines = ["| stage | RBP, ours (s) | RBP, paper (s) | naive, ours (s) | naive, paper (s) |",
             "|---|---|---|---|---|"]
    for key, row in rows.items():
        naive = _cell(row.get("naive")) if key == "footstep" else "N/A"
        paper_naive = "N/A" if row["paper_naive"] is None else f"{row['paper_naive']:g}"
        lines.append(f"| {row['label']} | {_cell(row['rbp'])} | {row['paper_rbp']:g} | "
                     f"{naive} | {paper_naive} |")
    if "footstep" in rows:
        lines.append(f"| footstep plan, successful RBP plans only | "
                     f"{_cell(rows['footstep']['rbp_successes'])} | | | |")
        lines.append(f"| whole plan (footsteps, seeds, SCP), successful RBP plans | "
                     f"{_cell(rows['footstep']['rbp_whole'])} | minutes | | |")
    lines.append("")
    lines.append("Median [first quartile, third quartile] over the trials. Per segment: a "
                 "plan's stage total / its number of phases of that kind, per successful plan. "
                 "Footstep times include plans that failed at the expansion cap.")
    for m in machine:
        lines.append(f"Machine: {m['cpu']}, {m['cores']} cores ({m['host']}), Python "
                     f"{m['python']}, Drake {m['drake']}.")
    return "\n".join(lines) + "\n"


def timing_figure(records: list[dict[str, Any]]):
    """Box plots of the per-segment times (log scale), the paper's values as crosses."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.0, 4.0))
    data = [stage_times(records, "rbp", "footstep"), stage_times(records, "naive", "footstep")]
    data += [per_segment(records, key) for key, *_ in PAPER[1:]]
    labels = ["RBP\nfootsteps", "naive\nfootsteps", "seed\nbody", "SCP\nbody", "seed\nreach",
              "SCP\nreach"]
    paper = [PAPER[0][2], PAPER[0][3]] + [p for _, _, p, _ in PAPER[1:]]
    positions = [k for k, d in enumerate(data) if d]
    ax.boxplot([data[k] for k in positions], positions=positions, widths=0.5)
    ax.plot(range(len(paper)), paper, "x", color="#cb181d", ms=9, label="paper (mean)")
    ax.set_xticks(range(len(labels)), labels)
    ax.set_yscale("log")
    ax.set_ylabel("seconds")
    ax.legend(fontsize=8)
    ax.set_title(f"computation time per stage over {len(records)} trials", fontsize=10)
    fig.tight_layout()
    return fig


def trial_machines(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The distinct machines the trials ran on (a Dask cluster may have several)."""
    machines = {json.dumps({k: v for k, v in r["worker"].items() if k != "pid"},
                           sort_keys=True) for r in records}
    return [json.loads(m) for m in sorted(machines)]


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_sweep_arguments(parser, trials=100, out="out/timing_table")
    add_cave_arguments(parser)
    args = parser.parse_args(argv)
    check_cave_arguments(parser, args)

    from rb_drake.files import atomic_save_figure, atomic_write_text

    records = sweep(climb_trials(args, ["rbp", "naive"], motion=True), args,
                    experiment="timing_table")
    done = ok_records(records)
    rows = timing_rows(done)
    machine = trial_machines(done)
    table = markdown_table(rows, machine)
    print(table, end="")
    rbp = planner_summary(done, "rbp")
    verified = rbp["verified"]
    print(f"{verified} of the {rbp['successes']} RBP plans pass rbp check's verifier")
    md = atomic_write_text(f"{args.out}/timing_table.md", table)
    figure = atomic_save_figure(timing_figure(done), f"{args.out}/timing.png", dpi=120)
    print(f"wrote {md}\nwrote {figure}")
    results = {
        "experiment": "timing_table", "machine": machine_info(), "trial_machines": machine,
        "params": {"trials": args.trials, "kind": args.kind, "first_seed": args.first_seed,
                   "length": list(args.length), "max_expansions": args.max_expansions},
        "per_segment": "stage total / number of phases of that kind, per successful plan",
        "summary": {"rbp_successes": sum(r["result"]["rbp"]["success"] for r in done),
                    "naive_successes": sum(r["result"]["naive"]["success"] for r in done),
                    "rbp_verified": verified,
                    "trials": len(done)},
        "timing": rows,
        "errors": [r["name"] for r in records if r["error"] is not None],
        "figure": str(figure), "table": str(md),
    }
    write_results(args.out, results)
    return EXIT_FAILED if results["errors"] else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
