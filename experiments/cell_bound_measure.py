"""Measure `rb_drake.cell_bounds` on benchmark caves with no route (issue 30, a prototype).

For the start stance and a few 4-stances next to it (one boom moved to the nearest other
anchor), the lattice points (2 cm, 2.5 deg) within +-0.3 m and +-30 deg of the start pose that
`check_poses` finds infeasible for the probability rule (first failure PROBABILITY): of a seeded
sample of them, how many cells the bound proves infeasible (U < log p_min), U - r_centre, the
time per cell; and, from 200 poses sampled in each cell, how many cells hold a feasible pose
(no sound bound can prove those) and U - (the largest sampled r), the bound's looseness.

    RBP_THREADS=1 python -m experiments.cell_bound_measure [--per-stance 120]

With `--lp-free`: the start stance and its four 3-stances (each free gripper at its anchor),
the LP-free bounds (`three_stance_bound`, `four_stance_bound`) beside `robustness_bound` on
the same cells.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.ndimage import binary_dilation

from experiments.common import make_cave
from rb_drake import cell_bounds as cb
from rb_drake import cell_exclusion as ce
from rb_drake.feasibility import Reason, check_poses

CAVES = (("crevasse", 30), ("shaft", 51), ("crevasse", 42))
DX, DPHI = 0.02, math.radians(2.5)
HALF = np.array([DX / 2, DX / 2, DPHI / 2])
SHAPE = (31, 31, 25)  # the lattice points of lattice_around


def neighbour_stances(scn, ids: tuple[str, ...], count: int) -> list[tuple[str, ...]]:
    """Up to `count` 4-stances that move one boom of `ids` to the anchor nearest its own."""
    pos = {a.id: np.asarray(a.position, dtype=float) for a in scn.anchors}
    out = []
    for j in range(4):
        d = sorted((float(np.linalg.norm(p - pos[ids[j]])), a) for a, p in pos.items()
                   if a not in ids)
        if d:
            out.append(tuple(d[0][1] if i == j else ids[i] for i in range(4)))
    return out[:count]


def lattice_around(pose: np.ndarray) -> np.ndarray:
    i0, k0, m0 = round(pose[0] / DX), round(pose[1] / DX), round(pose[2] / DPHI)
    ii = np.arange(i0 - 15, i0 + 16)
    kk = np.arange(k0 - 15, k0 + 16)
    mm = np.arange(m0 - 12, m0 + 13)
    g = np.stack(np.meshgrid(ii * DX, kk * DX, mm * DPHI, indexing="ij"), axis=-1)
    return g.reshape(-1, 3)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--per-stance", type=int, default=120)
    ap.add_argument("--neighbours", type=int, default=3)
    ap.add_argument("--depth", type=int, default=0,
                    help="also try splitting unproven cells (branch and bound) to this depth")
    ap.add_argument("--lp-free", action="store_true",
                    help="compare the LP-free bounds with the LP bound on the start stance and "
                         "its 3-stances")
    args = ap.parse_args()
    rng = np.random.default_rng(30)
    if args.lp_free:
        lp_free_comparison(args.per_stance, rng)
        return
    rows = []
    split_time: list[float] = []
    for kind, seed in CAVES:
        scn = make_cave(kind, seed, (4.5, 5.0))
        log_p_min = scn.robot.log_p_min
        p0 = np.array(scn.start_pose)
        grid = lattice_around(p0)
        start = tuple(scn.start_stance)
        for ids in [start, *neighbour_stances(scn, start, args.neighbours)]:
            stance = scn.stance(ids)
            chk = check_poses(scn, stance, grid, full=True)
            prob = np.flatnonzero(chk.reason == Reason.PROBABILITY)
            n_feas = int(chk.feasible.sum())
            # lattice points with a feasible lattice neighbour (26-connectivity)
            near = binary_dilation(chk.feasible.reshape(SHAPE), np.ones((3, 3, 3), bool)).ravel()
            pick = rng.choice(prob, size=min(args.per_stance, len(prob)), replace=False)
            for k in pick:
                centre = grid[k]
                t = time.perf_counter()
                bound = cb.robustness_bound(scn, stance, centre, HALF)
                elapsed = time.perf_counter() - t
                samp = centre + rng.uniform(-1, 1, (200, 3)) * HALF
                c = check_poses(scn, stance, samp, full=True)
                split = bound.upper < log_p_min
                if args.depth and not split and not c.feasible.any():
                    t = time.perf_counter()
                    split = ce.cell_probability_excluded(scn, stance, centre, HALF,
                                                         depth=args.depth)
                    split_time.append(time.perf_counter() - t)
                rows.append((kind, seed, ids, chk.allocation.robustness[k], bound.upper,
                             float(c.allocation.robustness.max()), bool(c.feasible.any()), elapsed,
                             log_p_min, bool(near[k]), split))
            print(f"{kind} {seed} {ids}: {len(grid)} lattice points, {n_feas} feasible, "
                  f"{len(prob)} infeasible for probability, {len(pick)} cells bounded",
                  flush=True)
    r_c = np.array([r[3] for r in rows])
    upper = np.array([r[4] for r in rows])
    r_s = np.array([r[5] for r in rows])
    feas = np.array([r[6] for r in rows])
    dt = np.array([r[7] for r in rows])
    lpm = np.array([r[8] for r in rows])
    near = np.array([r[9] for r in rows])
    split = np.array([r[10] for r in rows])
    if args.depth:
        print(f"with splitting to depth {args.depth}: proven {split.mean():.3f}, among cells "
              f"without a feasible sample {split[~feas].mean():.3f}, next to a feasible lattice "
              f"point {split[near].mean():.3f}, not {split[~near].mean():.3f}; time per split "
              f"cell median {1e3 * np.median(split_time or [0.0]):.0f} ms, max "
              f"{1e3 * max(split_time or [0.0]):.0f} ms")
    proven = upper < lpm
    fin = np.isfinite(upper)
    print(f"cells {len(rows)}: proven {proven.mean():.3f} ({proven.sum()}); "
          f"holding a sampled feasible pose (unprovable) {feas.mean():.3f}; "
          f"proven among the rest {proven[~feas].mean():.3f}")
    gap = upper[fin] - r_c[fin]
    print(f"U - r_centre (finite U, {fin.sum()} cells): median {np.median(gap):.4f}"
          f" p90 {np.percentile(gap, 90):.4f}")
    print(f"U - max sampled r: median {np.median(upper[fin] - r_s[fin]):.4f} "
          f"p90 {np.percentile(upper[fin] - r_s[fin], 90):.4f}")
    print(f"r_centre - log p_min: median {np.median(r_c - lpm):.4f}; "
          f"time per cell: median {1e3 * np.median(dt):.1f} ms, mean {1e3 * dt.mean():.1f} ms")
    for label, sel in (("next to a feasible lattice point", near), ("not next to one", ~near)):
        if sel.any():
            print(f"  {label}: {sel.sum()} cells, proven {proven[sel].mean():.3f}, unprovable "
                  f"(feasible sample) {feas[sel].mean():.3f}")
    for lo, hi in ((-math.inf, -1.0), (-1.0, -0.2), (-0.2, -0.05), (-0.05, 0.0)):
        sel = (r_c - lpm >= lo) & (r_c - lpm < hi)
        if sel.any():
            print(f"  r_c - log p_min in [{lo}, {hi}): {sel.sum()} cells, proven "
                  f"{proven[sel].mean():.3f}, unprovable (feasible sample) {feas[sel].mean():.3f}")
    for slack in (0.054,):  # p_min 0.95 -> 0.90: is U < log p_min + slack where r_c is?
        sel = r_c < lpm - slack
        print(f"  cells with r_c < log p_min - {slack}: {sel.sum()}, proven below log p_min: "
              f"{proven[sel].mean():.3f}, U < log p_min - {slack}: "
              f"{(upper[sel] < lpm[sel] - slack).mean():.3f}")


def lp_free_comparison(per_stance: int, rng: np.random.Generator) -> None:
    """On each cave's start stance and its 3-stances: cells at lattice points within +-0.3 m
    and +-30 deg of the start pose, infeasible at their centre and not excluded by geometry;
    the share that each bound proves (U < log p_min) and its time per cell."""
    rows: dict[str, list] = {"4-stance": [], "3-stance": []}
    for kind, seed in CAVES:
        scn = make_cave(kind, seed, (4.5, 5.0))
        grid = lattice_around(np.array(scn.start_pose))
        whole = scn.stance(tuple(scn.start_stance))
        configs = [(whole, None)] + [(whole.without(j), whole.positions[j].copy())
                                     for j in range(4)]
        for stance, tip in configs:
            chk = check_poses(scn, stance, grid, free_tip=tip)
            cand = np.flatnonzero(~chk.feasible)
            rng.shuffle(cand)
            picked = 0
            for k in cand:
                if picked >= per_stance:
                    break
                centre = grid[k]
                geo = cb.cell_geometry(scn.robot, stance, centre, HALF, tip)
                if cb.cell_geometry_excluded(scn.robot, stance, centre, HALF, tip, geo):
                    continue
                picked += 1
                t = time.perf_counter()
                fast = (ce.four_stance_bound(scn, stance, centre, HALF, geo=geo) if tip is None
                        else ce.three_stance_bound(scn, stance, centre, HALF, tip,
                                                   geo=geo).upper)
                t_fast = time.perf_counter() - t
                t = time.perf_counter()
                lp = cb.robustness_bound(scn, stance, centre, HALF, tip, geo=geo).upper
                t_lp = time.perf_counter() - t
                rows["4-stance" if tip is None else "3-stance"].append(
                    (fast, lp, t_fast, t_lp, scn.robot.log_p_min))
            print(f"{kind} {seed} {stance.ids}: {picked} cells", flush=True)
    for label, got in rows.items():
        table = np.array(got, dtype=float)
        fast, lp, t_fast, t_lp, lpm = table.T
        pf, pl = fast < lpm, lp < lpm
        print(f"{label}, {len(got)} cells: LP proves {pl.mean():.3f}, LP-free bound "
              f"{pf.mean():.3f} ({(pf & pl).sum()} of the LP's {pl.sum()}; {(pf & ~pl).sum()} "
              f"the LP does not); time per cell: LP-free median {1e3 * np.median(t_fast):.2f} "
              f"ms (mean {1e3 * t_fast.mean():.2f}), LP median {1e3 * np.median(t_lp):.1f} ms "
              f"(mean {1e3 * t_lp.mean():.1f})")


if __name__ == "__main__":
    main()
