"""Answers under rigid motions smaller than a lattice cell: does moving a cave change its label?

Each benchmark cave (`baseline_comparison`'s: kinds alternating shaft, crevasse, shaft,
rockfall; seed = trial + 1; 4.5 to 5 m), and `--motions` copies of it rotated about the origin
and shifted by random amounts smaller than one cell of the default lattice (|angle| < 2.5 deg,
|dx|, |dy| < 2 cm; walls, anchors, normals, start, goal and gravity together, so that the
physics is the same), planned by each named footstep variant (`route_quality`'s: "default",
today's `rbp plan`; "lattice", the same without refinement). A cave's answer is stable when
every copy gets the unmoved cave's: a route or none. The motions are seeded by the cave's seed.

    python -m experiments.rigid_motion --trials 100 --motions 3 --variants lattice,default \
        --out out/rigid_motion.json
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import sys
import time
from typing import Any

import numpy as np

from experiments.arguments import MAX_TRIALS, MAX_WORKERS, OneLineParser, path_name, whole
from experiments.common import ROUTE_VARIANTS, cave_kind, make_cave, variant_config
from experiments.sweep import machine_info
from rb_drake.errors import EXIT_OK
from rb_drake.files import atomic_write_text

MAX_MOTIONS = 100
CELL = (0.02, 2.5)  # the default lattice's steps: m, deg


def rigid_motion(rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """A rotation (rad) and shift (m) each smaller than one default lattice cell."""
    angle = math.radians(rng.uniform(-CELL[1], CELL[1]))
    return angle, rng.uniform(-CELL[0], CELL[0], 2)


def moved_scenario(scn: Any, angle: float, shift: np.ndarray) -> Any:
    """`scn` rotated by `angle` about the origin, then shifted by `shift`: every position,
    direction and the gravity vector with it, so nothing but where the lattice falls changes."""
    from rb_drake.scenario import scenario_from_dict

    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])

    def point(p: Any) -> list[float]:
        return [float(v) for v in rot @ np.asarray(p, dtype=float) + shift]

    def direction(v: Any) -> list[float]:
        return [float(x) for x in rot @ np.asarray(v, dtype=float)]

    data = scn.to_dict()
    data["name"] = f"{data['name']}-moved"
    data["gravity"] = direction(data["gravity"])
    data["walls"] = [[point(p) for p in wall] for wall in data["walls"]]
    for anchor in data["anchors"]:
        anchor["position"] = point(anchor["position"])
        anchor["normal"] = direction(anchor["normal"])
    x, y, phi = data["start"]["pose"]
    data["start"]["pose"] = [*point((x, y)), float(phi) + angle]
    data["goal"]["position"] = point(data["goal"]["position"])
    return scenario_from_dict(data, f"{data['name']} (moved)")


def run_cave(job: tuple[str, int, tuple[float, float], list[str], int]) -> dict[str, Any]:
    from planning.footsteps import plan_footsteps

    kind, seed, length, variants, motions = job
    cave = make_cave(kind, seed, length)
    rng = np.random.default_rng([seed, 30])
    copies = [(0.0, np.zeros(2))] + [rigid_motion(rng) for _ in range(motions)]
    out: dict[str, Any] = {"kind": kind, "seed": seed,
                           "motions": [[math.degrees(a), *map(float, d)] for a, d in copies]}
    for variant in variants:
        runs = []
        for angle, shift in copies:
            scn = cave if angle == 0.0 and not shift.any() else moved_scenario(cave, angle,
                                                                               shift)
            t0 = time.perf_counter()
            fp = plan_footsteps(scn, variant_config(variant, None))
            runs.append({"success": bool(fp.success), "stop": str(fp.stop),
                         "regrasps": len(fp.steps) if fp.success else None,
                         "expansions": int(fp.expansions),
                         "refined": [[c.position_step, c.angle_step_deg] for c in fp.refined],
                         "seconds": time.perf_counter() - t0})
        out[variant] = runs
    return out


def summary(caves: list[dict[str, Any]], variants: list[str]) -> dict[str, Any]:
    """Per variant: caves whose copies all got the same answer (a route or none), and those
    that did not: where a copy's answer was a proof against another's route (`noroute`, the
    lattice's doing) and where it was a budget stop (the search's effort)."""
    def name(c: dict[str, Any]) -> str:
        return f"{c['kind']} {c['seed']}"

    out: dict[str, Any] = {}
    for v in variants:
        changed = [c for c in caves if len({r["success"] for r in c[v]}) > 1]
        proofs = [name(c) for c in changed if any(r["stop"] == "noroute" for r in c[v])]
        out[v] = {"caves": len(caves),
                  "routes_unmoved": sum(c[v][0]["success"] for c in caves),
                  "stable": len(caves) - len(changed),
                  "changed": [name(c) for c in changed],
                  "changed_against_a_proof": proofs,
                  "changed_against_a_budget_stop": [name(c) for c in changed
                                                    if name(c) not in proofs],
                  "stop_changed": [name(c) for c in caves
                                   if len({r["stop"] for r in c[v]}) > 1],
                  "runs": sum(len(c[v]) for c in caves)}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m experiments.rigid_motion",
                           description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=whole(1, MAX_TRIALS), default=100,
                        help="caves (default 100)")
    parser.add_argument("--seeds", default=None,
                        help="comma-separated seeds of the benchmark to run, instead of --trials")
    parser.add_argument("--motions", type=whole(1, MAX_MOTIONS), default=3,
                        help="moved copies of each cave (default 3)")
    parser.add_argument("--variants", default="lattice,default",
                        help=f"comma-separated, of {', '.join(ROUTE_VARIANTS)}")
    parser.add_argument("--workers", type=whole(1, MAX_WORKERS), default=1)
    parser.add_argument("--out", type=path_name, default="out/rigid_motion.json")
    args = parser.parse_args(argv)
    variants = args.variants.split(",")
    bad = [v for v in variants if v not in ROUTE_VARIANTS and not v.startswith("x-")]
    if bad:
        parser.error(f"--variants: unknown {bad}; choose from {list(ROUTE_VARIANTS)}")
    try:
        indices = (list(range(args.trials)) if args.seeds is None
                   else [int(v) - 1 for v in args.seeds.split(",")])
    except ValueError:
        parser.error(f"--seeds: whole numbers separated by commas, got {args.seeds!r}")
    if any(not 0 <= i < MAX_TRIALS for i in indices):
        parser.error(f"--seeds: each from 1 to {MAX_TRIALS}")
    jobs = [(cave_kind(i, "mixed"), i + 1, (4.5, 5.0), variants, args.motions) for i in indices]
    if args.workers > 1:  # a search per core
        os.environ.setdefault("RBP_THREADS", "1")
    caves: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        for k, cave in enumerate(pool.imap(run_cave, jobs), 1):
            caves.append(cave)
            line = " ".join(f"{v}:" + "".join("R" if r["success"] else "-" for r in cave[v])
                            for v in variants)
            print(f"[{k}/{len(jobs)}] {cave['kind']} {cave['seed']}: {line}", file=sys.stderr)
    result = {"variants": variants, "machine": machine_info(), "args": vars(args),
              "wall_seconds": time.perf_counter() - t0, "summary": summary(caves, variants),
              "caves": caves}
    out = atomic_write_text(args.out, json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["summary"], indent=1))
    print(f"wrote {out}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
