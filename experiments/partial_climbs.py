"""Partial climbs (`rbp plan --partial`) on the benchmark caves without a route.

The benchmark's caves (`experiments.common.make_cave`: kinds cycling shaft, crevasse, shaft,
rockfall; seeds 1-100; 4.5 to 5 m) that the oracle labels as having no route
(docs/figures/route-oracle-all.json: its variant's `success` false) are planned as `rbp plan
--partial` plans them (the default configuration: the search stops on its budget or proves no
route) and each plan is verified as `rbp check` verifies it. Per cave: how the search stopped,
whether the start stance could move at all (the search expanded a stance besides the start's),
whether a partial climb was written, its regrasps, the stance it ends in and its distance from
the goal (beside the start's: the measure of the failed search's reason), its p_path, whether
it verifies, and the seconds. Results are written after each cave (a run again skips the caves
done).

    python -m experiments.partial_climbs --out docs/figures/partial-climbs.json
    python -m experiments.partial_climbs --seeds 71 4 --out /tmp/partial.json
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

from experiments.arguments import (
    MAX_TRIALS,
    OneLineParser,
    json_argument,
    path_name,
    seed_number,
    whole,
)
from experiments.sweep import machine_info
from rb_drake.errors import EXIT_OK, EXIT_USAGE, one_line
from rb_drake.files import atomic_write_text

LABELS = Path(__file__).resolve().parents[1] / "docs" / "figures" / "route-oracle-all.json"


def no_route_caves(labels: Path = LABELS) -> list[tuple[str, int]]:
    """(kind, seed) of the benchmark caves whose oracle found no route."""
    data = json.loads(labels.read_text())
    variant = data["variants"][0]
    return [(c["kind"], int(c["seed"])) for c in data["caves"] if not c[variant]["success"]]


def run_cave(kind: str, seed: int, length: tuple[float, float] = (4.5, 5.0)) -> dict[str, Any]:
    """One cave: `rbp plan --partial`'s plan (default configuration) and its verification."""
    from experiments.common import make_cave
    from planning.check import check_plan
    from planning.pipeline import PipelineConfig, plan_climb

    scn = make_cave(kind, seed, length)
    searches: list[Any] = []
    t0 = time.perf_counter()
    made = plan_climb(scn, "rbp", PipelineConfig(), footsteps_done=searches.append, partial=True)
    seconds = time.perf_counter() - t0
    fp = searches[0]  # the first search's: the one the partial climb comes from
    start = tuple(scn.start_stance)
    moved = any(tuple(e.stance) != start for e in fp.explored or [])
    problems = check_plan(made)
    part = made.partial
    return {"kind": kind, "seed": seed, "success": made.success, "stop": str(fp.stop),
            "expansions": int(fp.expansions), "start_can_move": moved,
            "partial": part is not None, "regrasps": made.regrasps if part else None,
            "reached_stance": list(part.reached_stance) if part else None,
            "goal_distance_m": part.goal_distance_m if part else None,
            "start_distance_m": part.start_distance_m if part else None,
            "nearest_expanded_m": (None if fp.partial is None
                                   else float(fp.partial.goal_distance)),
            "p_path": made.p_path, "verified": not problems, "problems": problems[:3],
            "reason": made.reason, "seconds": seconds}


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    movable = [r for r in rows if r["start_can_move"]]
    written = [r for r in rows if r["partial"]]
    return {"caves": len(rows), "start_can_move": len(movable),
            "partial_written": len(written),
            "partial_verified": sum(r["verified"] for r in written),
            "movable_without_partial": [f"{r['kind']}-{r['seed']}" for r in movable
                                        if not r["partial"]],
            "reached_the_nearest_expanded": sum(
                r["nearest_expanded_m"] is not None
                and abs(r["goal_distance_m"] - r["nearest_expanded_m"]) < 1e-9 for r in written),
            "any_success": sum(r["success"] for r in rows),
            "median_gain_m": _median([r["start_distance_m"] - r["goal_distance_m"]
                                      for r in written]),
            "median_regrasps": _median([r["regrasps"] for r in written]),
            "seconds": sum(r["seconds"] for r in rows)}


def _median(values: list[float]) -> float | None:
    values = sorted(values)
    if not values:
        return None
    n = len(values)
    return float(values[n // 2]) if n % 2 else float(values[n // 2 - 1] + values[n // 2]) / 2


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=path_name, required=True,
                    help="results (.json), rewritten after each cave")
    ap.add_argument("--seeds", type=seed_number, nargs="*",
                    help="only these seeds of the no-route caves (default: all of them)")
    ap.add_argument("--limit", type=whole(1, MAX_TRIALS), help="at most this many caves")
    args = ap.parse_args(argv)
    caves = no_route_caves()
    if args.seeds:
        caves = [c for c in caves if c[1] in set(args.seeds)]
    if args.limit is not None:
        caves = caves[:args.limit]
    out = Path(args.out)
    rows: list[dict[str, Any]] = []
    if out.exists():  # resuming: its own earlier output, read within the input bounds
        rows = json_argument(out).get("caves", [])
        if not (isinstance(rows, list) and all(
                isinstance(r, dict) and isinstance(r.get("kind"), str)
                and isinstance(r.get("seed"), int) for r in rows)):
            print(one_line(f"error: {out}: caves: must be a list of objects with kind and "
                           "seed (this script's own results)"), file=sys.stderr)
            return EXIT_USAGE
    done = {(r["kind"], r["seed"]) for r in rows}
    for kind, seed in caves:
        if (kind, seed) in done:
            continue
        row = run_cave(kind, seed)
        rows.append(row)
        print(f"{kind}-{seed}: stop {row['stop'] or 'route'}, start moves {row['start_can_move']},"
              f" partial {row['partial']}, regrasps {row['regrasps']}, ends "
              f"{row['goal_distance_m']} m (start {row['start_distance_m']}), verified "
              f"{row['verified']}, {row['seconds']:.0f} s", flush=True)
        data = {"machine": machine_info(), "labels": str(LABELS.name), "caves": rows,
                "summary": summary(rows)}
        atomic_write_text(out, json.dumps(data, indent=1) + "\n")
    print(json.dumps(summary(rows), indent=1))
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
