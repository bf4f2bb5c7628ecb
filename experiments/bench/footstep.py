"""The footstep section of `rbp bench`: `footsteps.plan_footsteps` against
`baseline.plan_naive` on short generated caves."""

from __future__ import annotations

import time
from typing import Any

from experiments.bench.stats import fmt, median

CAVE_KINDS = ("shaft", "crevasse", "rockfall")
SHORT_CAVE = (4.5, 5.0)  # m, the footstep section's cave length


def run_footstep(caves: int, max_expansions: int, seed: int) -> dict[str, Any]:
    """RBP's footstep planner against the naive baseline on short generated caves (kinds in
    turn, seeds 1, 2, ...): RBP expands at most `max_expansions` stances, the naive planner
    takes at most as many regrasps (its own cap, `max_steps`)."""
    from planning.baseline import plan_naive
    from planning.footsteps import FootstepConfig, plan_footsteps
    from planning.plan import build_plan
    from planning.plan_model import plan_dict
    from rb_drake.generate import CaveConfig, generate_cave

    print(f"\nfootstep: {caves} caves of length {SHORT_CAVE} m, max_expansions "
          f"{max_expansions}", flush=True)
    cfg = FootstepConfig(max_expansions=max_expansions, seed=seed)
    rows = []
    for k in range(caves):
        kind = CAVE_KINDS[k % len(CAVE_KINDS)]
        scn = generate_cave(kind, k + 1, CaveConfig(length=SHORT_CAVE))
        planners = (("rbp", plan_footsteps),
                    ("naive", lambda scn, cfg: plan_naive(scn, cfg, max_steps=max_expansions)))
        for name, planner in planners:
            t = time.perf_counter()
            fp = planner(scn, cfg)
            seconds = time.perf_counter() - t
            plan = plan_dict(build_plan(scn, fp, name))
            rows.append({"cave": scn.name, "planner": name, "seconds": seconds,
                         "success": bool(plan["success"]), "p_path": plan["p_path"],
                         "regrasps": plan["regrasps"], "reason": plan["reason"]})
            print(f"  {scn.name:11s} {name:5s}: {seconds:6.2f} s, success "
                  f"{plan['success']!s:5s}, p_path {fmt(plan['p_path'], '.3f')}", flush=True)
    summary: dict[str, Any] = {}
    for name in ("rbp", "naive"):
        mine = [r for r in rows if r["planner"] == name]
        summary[name] = {"caves": len(mine), "successes": sum(r["success"] for r in mine),
                         "seconds_median": median(r["seconds"] for r in mine),
                         "p_path_median": median(r["p_path"] for r in mine if r["success"])}
    rbp = {r["cave"]: r for r in rows if r["planner"] == "rbp"}
    pairs = [(rbp[r["cave"]], r) for r in rows if r["planner"] == "naive"]
    summary["time_ratio_median"] = median(a["seconds"] / b["seconds"] for a, b in pairs)
    summary["p_path_ratio_median"] = median(
        a["p_path"] / b["p_path"] for a, b in pairs
        if a["success"] and b["success"] and b["p_path"])
    print(f"footstep: rbp {summary['rbp']['successes']}/{caves} succeeded, median "
          f"{fmt(summary['rbp']['seconds_median'], '.2f')} s, p_path "
          f"{fmt(summary['rbp']['p_path_median'], '.3f')}; naive "
          f"{summary['naive']['successes']}/{caves}, "
          f"{fmt(summary['naive']['seconds_median'], '.2f')} s, p_path "
          f"{fmt(summary['naive']['p_path_median'], '.3f')}; rbp/naive time "
          f"{fmt(summary['time_ratio_median'], '.2f')}, p_path "
          f"{fmt(summary['p_path_ratio_median'], '.2f')}")
    return {"summary": summary, "cases": rows}
