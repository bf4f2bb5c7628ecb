"""The scp section of `rbp bench`: `scp.optimise_body` / `optimise_reach` against one
nonlinear program of the same phase solved by IPOPT, both scored with planning.scp's exact
merit and re-checked with `check_poses`."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from experiments.bench.ipopt import NonlinearPhase
from experiments.bench.phases import Segment, scp_segments
from experiments.bench.stats import fmt, median
from rb_drake.feasibility import check_poses
from rb_drake.statics import allocate


def run_scp(moves: int, seed: int, ipopt_iterations: int = 1000) -> dict[str, Any]:
    """The SCP section: ours and IPOPT on every phase of `scp_segments`, both scored with
    planning.scp's exact merit (`PhaseProgram.evaluate`) and re-checked with `check_poses`.
    IPOPT stops after `ipopt_iterations` iterations per phase (an iteration cap, not a time
    limit: it is reproducible, and IPOPT's max_cpu_time misfires in later solves of a process
    once one solve has hit it)."""
    from planning.pipeline import PipelineConfig
    from planning.scp import Iterate, PhaseProgram, optimise_body, optimise_reach

    pipeline = PipelineConfig()
    dt, cfg = pipeline.dt, pipeline.scp
    t0 = time.perf_counter()
    segments = scp_segments(moves, seed)
    print(f"\nscp: {len(segments)} phases from {moves} moves in "
          f"{time.perf_counter() - t0:.1f} s", flush=True)
    rows = []
    for seg in segments:
        scn, stance, N = seg.scn, seg.stance, len(seg.poses)
        program = PhaseProgram(scn, stance, N, dt, cfg, seg.tips)
        seed_alloc = allocate(scn.robot, scn.gravity_vector, seg.poses, stance, seg.tips)
        seed_it = Iterate(seg.poses, program.velocities_for(seg.poses),
                          seed_alloc.tensions[:, program.att])
        seed_ev = program.evaluate(seed_it)

        t = time.perf_counter()
        if seg.boom is None:
            res = optimise_body(scn, seg.stance_ids, seg.poses, dt, cfg)
        else:
            assert seg.tips is not None  # a reach phase's free gripper path
            res = optimise_reach(scn, seg.stance_ids, seg.boom, seg.poses, seg.tips, dt, cfg)
        ours_seconds = time.perf_counter() - t
        ours = _score_trajectory(program, seg, Iterate(res.poses, res.velocities,
                                                       res.tensions[:, program.att]))
        ours.update(seconds=ours_seconds, status=res.status, improved=bool(res.improved))

        # IPOPT's floor is log p_min, not SCP's default max(log p_min, the seed's least r_k):
        # where the seed is near certain (r_k ~ -1e-8) that squeezes r_k into [floor, 0] and
        # the interior-point method crawls (10-50x slower, measured); r_min is reported.
        t = time.perf_counter()
        nlp = NonlinearPhase(seg, dt, cfg, scn.robot.log_p_min, ipopt_iterations)
        q, v, f, status = nlp.solve(seed_it.poses, seed_it.velocities, seed_it.tensions)
        ipopt_seconds = time.perf_counter() - t
        # The same objective, checked: this program's merit equals planning.scp's at the seed.
        mismatch = abs(nlp.merit(seed_it.poses, seed_it.velocities, seed_it.tensions)
                       - seed_ev.merit)
        prob = program.statics_at(q)
        raw_residual = float(np.abs(np.einsum("nrb,nb->nr", prob.A[:, :, program.att], f)
                                    - prob.b).max())
        # IPOPT holds the statics to its tolerance; the minimum-norm correction SCP applies to
        # every iterate makes them exact before scoring.
        restored = program.restore(Iterate(q, v, f))
        ipopt = (_score_trajectory(program, seg, restored) if restored is not None
                 else {"merit": None, "r_min": None, "r_sum": None, "feasible": False,
                       "reason": "statics cannot be restored", "check_poses": False,
                       "poses": q.tolist()})
        ipopt.update(seconds=ipopt_seconds, status=status, raw_residual=raw_residual,
                     callback_seconds=nlp.callback_seconds)
        row = {"cave": seg.cave, "kind": seg.kind, "steps": N, "stance": list(seg.stance_ids),
               "boom": seg.boom, "tips": None if seg.tips is None else seg.tips.tolist(),
               "merit_mismatch_at_seed": mismatch,
               "seed": {"merit": seed_ev.merit, "r_min": float(seed_ev.robustness.min()),
                        "r_sum": float(seed_ev.robustness.sum())},
               "ours": ours, "ipopt": ipopt}
        rows.append(row)
        print(f"  {seg.cave:11s} {seg.kind:5s} N={N:3d}: ours {ours_seconds:6.2f} s merit "
              f"{fmt(ours['merit'], '.4f')} r_min {fmt(ours['r_min'], '.4f')} "
              f"{'ok' if ours['feasible'] and ours['check_poses'] else 'INFEASIBLE'} | ipopt "
              f"{ipopt_seconds:6.2f} s merit {fmt(ipopt['merit'], '.4f')} r_min "
              f"{fmt(ipopt['r_min'], '.4f')} "
              f"{'ok' if ipopt['feasible'] and ipopt['check_poses'] else 'infeasible'} "
              f"({status})", flush=True)
    summary = _scp_summary(rows)
    print(f"scp: median {fmt(summary['ours_seconds_median'], '.3f')} s (ours) against "
          f"{fmt(summary['ipopt_seconds_median'], '.3f')} s (IPOPT), IPOPT/ours "
          f"{fmt(summary['time_ratio_median'], '.1f')}x; feasible {summary['ours_feasible']}"
          f"/{len(rows)} (ours), {summary['ipopt_feasible']}/{len(rows)} (IPOPT); merit "
          f"IPOPT - ours median {fmt(summary['merit_difference_median'], '.2e')}, r_sum "
          f"{fmt(summary['r_sum_difference_median'], '.2e')}, r_min "
          f"{fmt(summary['r_min_difference_median'], '.2e')}")
    return {"summary": summary, "cases": rows}


def _score_trajectory(program: Any, seg: Segment, it: Any) -> dict[str, Any]:
    ev = program.evaluate(it)
    check = check_poses(seg.scn, seg.stance, it.poses, seg.tips)
    return {"merit": ev.merit, "r_min": float(ev.robustness.min()),
            "r_sum": float(ev.robustness.sum()), "feasible": bool(ev.feasible),
            "reason": ev.reason, "check_poses": bool(check.feasible.all()),
            "poses": it.poses.tolist()}


def _scp_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    def ok(side: dict[str, Any]) -> bool:
        return side["feasible"] and side["check_poses"]

    both = [r for r in rows if ok(r["ours"]) and ok(r["ipopt"])]
    return {
        "phases": len(rows),
        "ours_seconds_median": median(r["ours"]["seconds"] for r in rows),
        "ipopt_seconds_median": median(r["ipopt"]["seconds"] for r in rows),
        "time_ratio_median": median(r["ipopt"]["seconds"] / r["ours"]["seconds"]
                                     for r in rows),
        "ours_feasible": sum(ok(r["ours"]) for r in rows),
        "ipopt_feasible": sum(ok(r["ipopt"]) for r in rows),
        "ipopt_callback_share_median": median(r["ipopt"]["callback_seconds"]
                                               / r["ipopt"]["seconds"] for r in rows),
        "ipopt_solved": sum(r["ipopt"]["status"].startswith("kSolutionFound") for r in rows),
        "ours_merit_gain_median": median(r["ours"]["merit"] - r["seed"]["merit"]
                                          for r in rows if ok(r["ours"])),
        "ipopt_merit_gain_median": median(r["ipopt"]["merit"] - r["seed"]["merit"]
                                           for r in rows if ok(r["ipopt"])),
        "both_feasible": len(both),
        "merit_difference_median": median(r["ipopt"]["merit"] - r["ours"]["merit"]
                                           for r in both),
        "r_sum_difference_median": median(r["ipopt"]["r_sum"] - r["ours"]["r_sum"]
                                           for r in both),
        "r_min_difference_median": median(r["ipopt"]["r_min"] - r["ours"]["r_min"]
                                           for r in both),
        "ipopt_better": sum(r["ipopt"]["merit"] > r["ours"]["merit"] + 1e-6 for r in both),
    }
