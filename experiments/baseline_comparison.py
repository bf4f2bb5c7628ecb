"""RBP against the naive baseline on the same randomised caves (the paper's Fig. 4).

Trial i plans cave i (seeded; shafts and passages alternating: shaft, crevasse, shaft,
rockfall, ...) with both footstep planners and records each plan's success, reason, path
success probability p_path and regrasps. The figure shows each planner's distribution of p_path
over the trials, a failed plan counting p_path = 0, and results.json holds the counts
"p_path > 0.90" and "> 0.95" (the paper: RBP over 0.90 in 86 of 100 and over 0.95 in more
than half, the naive planner mostly failing). Both are also counted for p_grasps, p_path without
the per-regrasp attach term: the paper's robustness metric has none, and with it a plan of more
than 10 regrasps cannot pass 0.90.

    python -m experiments.baseline_comparison --trials 100 --out out/baseline

`--ompl-log PATH` also writes the runs as an OMPL benchmark log (`experiments.ompl_log`), for
`ompl_benchmark_statistics` and Planner Arena.

The trial function `climb_trial` (a cave from its parameters, the planners on it) and the other
helpers the timing table, the SCP statistics and the parameter sweep share with this
experiment are in `experiments.common`.
"""

from __future__ import annotations

import argparse
from datetime import UTC, datetime
from typing import Any

from experiments.arguments import OneLineParser, number
from experiments.common import (
    ORACLE_SECONDS,
    OTHER_PLANNERS,
    PLANNERS,
    THRESHOLDS,
    add_cave_arguments,
    add_ompl_log_argument,
    check_cave_arguments,
    check_ompl_log,
    climb_trial,  # noqa: F401 (CLIMB_TRIAL names it here: the trials' records keep that name)
    climb_trials,
    path_probabilities,
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


def oracle_label(record: dict[str, Any]) -> str:
    """route / noroute / undecided, from the oracle's plan record."""
    if record["success"]:
        return "route"
    return "noroute" if record.get("stop") in ("noroute", "nostart") else "undecided"


def oracle_summary(records: list[dict[str, Any]], planners: list[str]) -> dict[str, Any]:
    """The oracle's label counts, and per planner how many caves with a route it planned."""
    from planning.lattice import LatticeConfig

    lattice = LatticeConfig()
    labels = [oracle_label(r["result"]["oracle"]) for r in records]
    counts = {k: labels.count(k) for k in ("route", "noroute", "undecided")}
    route = [r for r, lab in zip(records, labels, strict=True) if lab == "route"]
    planned = {p: {"route": len(route),
                   "planned": sum(bool(r["result"][p]["success"]) for r in route),
                   "planned_where_no_route": sum(
                       bool(r["result"][p]["success"]) for r, lab in
                       zip(records, labels, strict=True) if lab == "noroute")}
               for p in planners if p != "oracle"}
    oracle_ok = [r["result"]["oracle"] for r in route]
    return {"labels": counts,
            "resolution": f"{lattice.position_step * 100:g} cm / {lattice.angle_step_deg:g} deg",
            # labelling the benchmark: the oracle's footstep time summed over the caves
            # a cave the generator could not make has no planner's timing
            "seconds_total": sum(r["timing"]["oracle"]["footstep"] for r in records
                                 if "oracle" in r["timing"]),
            "planned_of_route": planned,
            "oracle_regrasps": quantiles([o["regrasps"] for o in oracle_ok]),
            "by_kind": {k: {lab: sum(1 for r, x in zip(records, labels, strict=True)
                                     if r["params"]["kind"] == k and x == lab)
                            for lab in counts}
                        for k in sorted({r["params"]["kind"] for r in records})}}


def footstep_times(records: list[dict[str, Any]], planners: list[str]) -> dict[str, Any]:
    """Per planner, footstep seconds (quantiles) where it found a route, where it proved that
    there is none, and where it failed otherwise (budget, exhausted, undecided)."""
    out = {}
    for p in planners:
        rows = [(r["result"][p], r["timing"][p]["footstep"]) for r in records
                if p in r["timing"]]
        out[p] = {"found": quantiles([t for rec, t in rows if rec["success"]]),
                  "noroute": quantiles([t for rec, t in rows if not rec["success"]
                                        and rec.get("stop") in ("noroute", "nostart")]),
                  "failed": quantiles([t for rec, t in rows if not rec["success"]
                                       and rec.get("stop") not in ("noroute", "nostart")])}
    return out


def paired_time_ratio(records: list[dict[str, Any]], new: str, old: str) -> dict[str, Any]:
    """Quantiles over the caves both planners solve of new's footstep time over old's, the
    same cave in the same run (machines differ in speed from day to day; ratios do not)."""
    ratios = [r["timing"][new]["footstep"] / r["timing"][old]["footstep"] for r in records
              if r["result"][new]["success"] and r["result"][old]["success"]
              and r["timing"][old]["footstep"] > 0]
    return quantiles(ratios)


def _seconds(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f} s"


def baseline_figure(records: list[dict[str, Any]], planners: list[str]):
    """Fig. 4: histograms of p_path over the plans found, failed plans in a hatched column of
    their own (left of 0), and the share of trials above each p, for p_path (solid) and
    p_grasps (dashed), a failed plan counting 0. The legends, below the plots, give the
    counts the bars add up to."""
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    from rb_drake import draw

    colours = {"rbp": "#2171b5", "rbp-sampled": "#6baed6", "naive": "#cb181d"}
    fig = draw.new_figure(figsize=(11.0, 5.2), layout="constrained")
    hist, tail = fig.subplots(1, 2)
    bins = np.linspace(0.0, 1.0, 21)
    step = bins[1] - bins[0]
    width = step / max(1, len(planners))
    failed_at = -3.0 * step  # the failed plans' column, left of p = 0
    for k, planner in enumerate(planners):
        ok = [r["result"][planner] for r in records if r["result"][planner]["success"]]
        p = np.array([o["p_path"] for o in ok], dtype=float)
        counts, _ = np.histogram(p, bins)
        failed = len(records) - len(ok)
        colour = colours.get(planner)
        hist.bar(bins[:-1] + k * width, counts, width, align="edge", color=colour,
                 label=f"{planner}: {len(ok)} plans, by p_path")
        hist.bar([failed_at + k * width], [failed], width, align="edge", color="white",
                 edgecolor=colour, hatch="///", label=f"{planner}: {failed} failed (no plan)")
        grid = np.linspace(0.0, 1.0, 1001)
        for key, style in (("p_path", "-"), ("p_grasps", "--")):
            q = np.array(path_probabilities(records, planner, key))
            over = [f"{int(np.sum(q > t))} > {t:.2f}" for t in THRESHOLDS]
            tail.plot(grid, (q[None, :] > grid[:, None]).mean(axis=1), style,
                      color=colour, label=f"{planner} {key}: {', '.join(over)}")
    for t in THRESHOLDS:
        tail.axvline(t, color="grey", lw=0.8, ls="--")
    ticks = [failed_at + step / 2, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
    hist.set_xticks(ticks, ["failed"] + [f"{t:.1f}" for t in ticks[1:]])
    hist.set_xlim(failed_at - step / 2, 1.0 + step / 2)
    hist.set_xlabel("path success probability p_path of the plans found")
    hist.set_ylabel("trials")
    hist.yaxis.set_major_locator(MaxNLocator(integer=True))
    hist.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
                frameon=False)
    tail.set_xlabel("p")
    tail.set_ylabel("share of trials above p (a failed plan: 0)")
    tail.set_xlim(0.0, 1.0)
    tail.set_ylim(0.0, 1.02)
    tail.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
    fig.suptitle(f"footstep planners over {len(records)} randomised caves", fontsize=11)
    return fig


def labelled_sweep(args: argparse.Namespace, planners: list[str]) -> list[dict[str, Any]]:
    """The trials' records, every planner in one record per cave. The oracle runs after the
    others, one cave at a time in this process, so that its compiled kernels have every core
    (`kernel_threads`): the others run one per worker, a core each, as they cannot use more.
    Its records (trials named oracle-...) join the others'."""
    others = [p for p in planners if p != "oracle"]
    records = sweep(climb_trials(args, others, motion=args.motion), args,
                    experiment="baseline_comparison") if others else []
    if "oracle" not in planners:
        return records
    alone = argparse.Namespace(**{**vars(args), "workers": 1})
    labels = sweep(climb_trials(args, ["oracle"], motion=False, prefix="oracle-",
                                oracle_seconds=args.oracle_time), alone,
                   experiment="baseline_comparison")
    if not records:
        return [{**o, "name": o["name"].removeprefix("oracle-")} for o in labels]
    merged = []
    for r, o in zip(records, labels, strict=True):
        r = dict(r)
        if r["error"] is None and o["error"] is not None:
            r["error"] = o["error"]
        elif r["error"] is None:
            r["result"] = {**r["result"], "oracle": o["result"]["oracle"]}
            r["timing"] = {**r["timing"], "oracle": o["timing"]["oracle"]}
        merged.append(r)
    return merged


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_sweep_arguments(parser, trials=100, out="out/baseline_comparison")
    add_cave_arguments(parser)
    parser.add_argument("--planners", default=",".join(PLANNERS),
                        help="comma-separated planners among "
                        + ",".join(PLANNERS + OTHER_PLANNERS) +
                        " (default all; rbp-sampled is the search before the complete one, "
                        "oracle labels each cave)")
    parser.add_argument("--motion", action="store_true",
                        help="plan the whole climb (seeds and SCP too) for rbp and rbp-sampled, "
                             "so that 'verified' means the whole plan passes rbp check")
    parser.add_argument("--oracle-time", type=number(0.001, 86_400), default=ORACLE_SECONDS,
                        help="seconds the oracle may search a cave before it says undecided "
                             f"(default {ORACLE_SECONDS:g})")
    add_ompl_log_argument(parser)
    args = parser.parse_args(argv)
    check_cave_arguments(parser, args)
    planners = [p.strip() for p in args.planners.split(",")]
    if not all(planners) or not set(planners) <= set(PLANNERS + OTHER_PLANNERS):
        parser.error(f"--planners: choose from {','.join(PLANNERS + OTHER_PLANNERS)}, got "
                     f"{args.planners!r}")
    if len(set(planners)) != len(planners):
        parser.error(f"--planners: each planner once, got {args.planners!r}")
    if not args.oracle_time > 0:
        parser.error(f"--oracle-time: must be positive, got {args.oracle_time}")
    check_ompl_log(parser, args.ompl_log, args.out)

    from rb_drake.files import atomic_save_figure

    started = datetime.now(UTC)
    records = labelled_sweep(args, planners)
    done = ok_records(records)
    summary = {p: planner_summary(done, p) for p in planners}
    for p, s in summary.items():
        print(f"{p}: {s['successes']}/{s['trials']} plans; p_path > 0.90 in "
              f"{s['p_path_over_0.90']}, > 0.95 in {s['p_path_over_0.95']}; p_grasps > 0.90 "
              f"in {s['p_grasps_over_0.90']}, > 0.95 in {s['p_grasps_over_0.95']}; "
              f"{s['verified']} pass rbp check's verifier")
    oracle = oracle_summary(done, planners) if "oracle" in planners else None
    if oracle is not None:
        print(f"oracle: {oracle['labels']['route']} caves have a route, "
              f"{oracle['labels']['noroute']} have none at {oracle['resolution']}, "
              f"{oracle['labels']['undecided']} undecided after {args.oracle_time:g} s")
        for p, line in oracle["planned_of_route"].items():
            print(f"{p} plans {line['planned']} of the {line['route']} caves that have a route")
        print(f"oracle: {oracle['seconds_total']:.0f} s of search to label the caves")
    times = footstep_times(done, planners)
    for p, t in times.items():
        print(f"{p} footstep time, median: {_seconds(t['found']['median'])} where it found a "
              f"route, {_seconds(t['noroute']['median'])} where it proved there is none, "
              f"{_seconds(t['failed']['median'])} where it failed otherwise")
    ratio = (paired_time_ratio(done, "rbp", "rbp-sampled")
             if {"rbp", "rbp-sampled"} <= set(planners) else None)
    if ratio is not None and ratio["n"]:
        print(f"rbp / rbp-sampled footstep time on the {ratio['n']} caves both solve, per cave: "
              f"median {ratio['median']:.2f} [{ratio['q1']:.2f}, {ratio['q3']:.2f}]")
    figure = atomic_save_figure(baseline_figure(done, [p for p in planners if p != "oracle"]),
                                f"{args.out}/baseline.png", dpi=120)
    print(f"wrote {figure}")
    results: dict[str, Any] = {
        "experiment": "baseline_comparison", "machine": machine_info(),
        "params": {"trials": args.trials, "kind": args.kind, "first_seed": args.first_seed,
                   "length": list(args.length), "max_expansions": args.max_expansions,
                   "oracle_seconds": args.oracle_time, "motion": args.motion,
                   "planners": planners},
        "summary": summary,
        "errors": [r["name"] for r in records if r["error"] is not None],
        "oracle": oracle,
        "timing": {p: {"footstep": quantiles(stage_times(done, p, "footstep")), **times[p]}
                   for p in planners},
        "rbp_over_sampled": ratio,
        "trials": [{"name": r["name"], "kind": r["params"]["kind"], "seed": r["params"]["seed"],
                    **({"label": oracle_label(r["result"]["oracle"])}
                       if "oracle" in planners else {}),
                    **{p: {**{k: r["result"][p].get(k) for k in (
                        "success", "stop", "p_path", "p_grasps", "regrasps", "reason")},
                        "footstep_seconds": r["timing"].get(p, {}).get("footstep")}
                       for p in planners}}
                   for r in done],
        "figure": str(figure),
    }
    write_results(args.out, results)
    if args.ompl_log:
        from experiments.common import footstep_config
        from experiments.ompl_log import baseline_log, write_log
        from planning.config_io import config_to_dict

        common = {p: {"planner": p, "motion": args.motion and p not in ("oracle", "naive"),
                      "footstep": config_to_dict(footstep_config(p, args.max_expansions,
                                                                 args.oracle_time))}
                  for p in planners}
        memory = footstep_config("rbp", args.max_expansions).search_memory_mb
        log = baseline_log(done, planners, results["params"], common, results["machine"],
                           started, time_limit=args.oracle_time if "oracle" in planners else 0.0,
                           memory_limit=memory or 0.0)
        print(f"wrote {write_log(args.ompl_log, log)}")
    return EXIT_FAILED if results["errors"] else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
