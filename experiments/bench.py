"""Benchmark rbp against what a user would write instead, side by side on the same inputs.

Three sections, each run in this one process, cases interleaved so that a noisy shared machine
slows every method alike; times are medians over cases.

* allocation: the most robust tensions at a pose. Ours: `statics.allocate` (per pose, and
  vectorised over a batch), `statics.ForceAllocator` (Drake + OSQP / Clarabel). Theirs: the
  public ReachBot code's formulation, cvxpy maximising sum cp.log_normcdf(z_i) subject to
  A f = b and the tension bounds (a DPP problem built once, re-solved with Clarabel and ECOS),
  and scipy SLSQP on the exact objective (log_ndtr). All maximise the same J = sum log Phi(z_i)
  - REGULARISATION/2 |f|^2; every answer is scored with the exact J, against the best answer
  of the case. cp.log_normcdf is a piecewise quadratic approximation (exactly 0 for z >= 3),
  so cvxpy's own objective value is compared with the exact one too. Cases: random poses and
  stances on the bundled caves, feasible by `check_poses` (4- and 3-stances), plus 4-stances
  whose statics hold but whose probability is below p_min (the planner allocates those too).
* scp: one phase's trajectory. Ours: `scp.optimise_body` / `optimise_reach` on seeds from
  `seeds.body_seed` / `reach_seed` along the first moves of a climb on the bundled caves.
  Theirs: one nonlinear program of the same phase solved by IPOPT (bundled with Drake; allowed
  here, never in the product): the exact geometry, written here independently of rb_drake as
  a function of the poses that Drake differentiates (AutoDiffXd), the statics A(q) f = b(q),
  boom length, shoulder angle, pull angle and shoulder torque limits as constraints, r_k >=
  log p_min, fixed start and goal states and the merit of `planning.scp` (robustness, dynamics
  penalty, smoothness), from the same seed. Differences, each forced by the method: collisions
  are not modelled (not smooth); the floor is log p_min, not SCP's max(log p_min, the seed's
  least r_k), which starves the interior-point method where the seed is near certain; poses
  and velocities are boxed far from the seed (interior-point methods diverge on unbounded
  variables here). Both answers are re-checked with `check_poses` and scored with the merit
  of `PhaseProgram.evaluate`; the program's own merit is checked equal to it at the seed.
* footstep: `footsteps.plan_footsteps` against `baseline.plan_naive` on short generated caves.

Writes every case and a summary to a JSON file; `--compare OLD.json` prints new/old ratios of
every summary metric.

    python -m experiments.bench --only allocation,scp --samples 300 --out out/bench
    rbp bench --compare out/bench/bench-old.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_ndtr

from rb_drake import geometry
from rb_drake.feasibility import Reason, check_poses
from rb_drake.files import atomic_write_text
from rb_drake.grasp import log_ndtr_derivatives, mills_ratio
from rb_drake.scenario import Scenario, bundled_caves, load_scenario
from rb_drake.stance import Stance
from rb_drake.statics import REGULARISATION, STATICS_TOL, ForceAllocator, allocate, statics_problem

SECTIONS = ("allocation", "scp", "footstep")
FORMAT = "rbp-bench/1"
BOUND_TOL = 1e-9     # N: tensions this far outside their bounds still count as within
CURVED = -1e-3       # r below this: log Phi is curved enough that the tensions are well defined
CAVE_KINDS = ("shaft", "crevasse", "rockfall")
SHORT_CAVE = (4.5, 5.0)  # m, the footstep section's cave length
POSE_BOX = np.array([0.5, 0.5, 0.5])  # m, m, rad: IPOPT's box around the seed's extent
SPEED_BOX = 1.0          # m/s, rad/s: IPOPT's bound on velocities (seeds move at 0.1 m/s)


def _quantiles(values: Iterable[float]) -> dict[str, float | None]:
    """Median, 90th percentile and maximum of the finite values (None when there are none)."""
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if not len(v):
        return {"median": None, "p90": None, "max": None}
    return {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
            "max": float(v.max())}


def _median(values: Iterable[float]) -> float | None:
    return _quantiles(values)["median"]


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else a / b


# ---------------------------------------------------------------------------------------------
# Force allocation


class AllocationCase(NamedTuple):
    cave: str
    group: str                    # "4-stance" | "3-stance" | "low-p" (statics hold, P < p_min)
    scn: Scenario
    stance: Stance
    pose: np.ndarray              # (3,)
    free_tip: np.ndarray | None   # (2,) in a 3-stance


def allocation_cases(count: int, seed: int = 0, batch: int = 64,
                     max_rounds: int = 200) -> list[AllocationCase]:
    """About `count` seeded random cases over the bundled caves: 40% feasible 4-stances, 40%
    feasible 3-stances (a boom of a feasible 4-stance let go, its gripper still at the anchor),
    20% 4-stances whose statics hold but whose probability is below p_min.

    Poses are drawn uniformly over each cave's anchors' bounding box (phi ~ N(0, 0.3)); each
    boom takes a random anchor within its reach; `check_poses` decides."""
    quota = {"4-stance": round(0.4 * count), "3-stance": round(0.4 * count)}
    quota["low-p"] = max(0, count - quota["4-stance"] - quota["3-stance"])
    caves = [(name, load_scenario(path)) for name, path in sorted(bundled_caves().items())]
    per_cave = {g: math.ceil(n / len(caves)) for g, n in quota.items()}
    rng = np.random.default_rng(seed)
    cases: list[AllocationCase] = []

    def wants(name: str, group: str) -> bool:
        mine = sum(c.group == group and c.cave == name for c in cases)
        return mine < per_cave[group] and sum(c.group == group for c in cases) < quota[group]

    for _ in range(max_rounds):
        if all(sum(c.group == g for c in cases) >= n for g, n in quota.items()):
            break
        for name, scn in caves:
            if any(wants(name, g) for g in quota):
                _sample_cave(scn, name, rng, batch, lambda g, name=name: wants(name, g),
                             cases.append)
    return cases


def _sample_cave(scn: Scenario, name: str, rng: np.random.Generator, batch: int,
                 wants: Callable[[str], bool], add: Callable[[AllocationCase], None]) -> None:
    """One batch of candidate poses in one cave; `add` the cases of the groups it `wants`."""
    robot, pos = scn.robot, scn.anchor_positions
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    poses = np.column_stack([rng.uniform(lo[0], hi[0], batch), rng.uniform(lo[1], hi[1], batch),
                             rng.normal(0.0, 0.3, batch)])
    reachable = np.stack([geometry.reach(robot, poses, pos, np.full(len(pos), i)).violation == 0
                          for i in range(4)], axis=1)                    # (batch, 4, anchors)
    for p, pose in enumerate(poses):
        ids, used = [""] * 4, []
        for i in rng.permutation(4):  # booms in a random order, each a distinct anchor
            free = np.setdiff1d(np.flatnonzero(reachable[p, i]), used)
            if not len(free):
                break
            used.append(int(rng.choice(free)))
            ids[i] = scn.anchors[used[-1]].id
        if len(used) < 4:
            continue
        stance = scn.stance(ids)
        check = check_poses(scn, stance, pose)
        reason = int(check.reason[0])
        if reason == Reason.PROBABILITY and wants("low-p"):
            add(AllocationCase(name, "low-p", scn, stance, pose, None))
        if reason != Reason.FEASIBLE:
            continue
        if wants("4-stance"):
            add(AllocationCase(name, "4-stance", scn, stance, pose, None))
        if wants("3-stance"):
            for j in rng.permutation(4):
                three, tip = stance.without(int(j)), stance.positions[j].copy()
                if check_poses(scn, three, pose, tip).feasible[0]:
                    add(AllocationCase(name, "3-stance", scn, three, pose, tip))
                    break


class Answer(NamedTuple):
    """One method's tensions for one case, and what it cost."""

    tensions: np.ndarray         # (4,), NaN for the free boom and when the method failed
    seconds: float
    model_value: float = math.nan  # the method's own optimal value (cvxpy: its approximation)


def _problem(case: AllocationCase):
    return statics_problem(case.scn.robot, case.scn.gravity_vector, case.pose, case.stance,
                           case.free_tip)


def _margin_terms(stance: Stance, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """mu(psi) and sigma(psi) of the attached booms."""
    att = stance.attached
    return stance.mean_limit(psi)[att], stance.sigma(psi)[att]


def exact_objective(stance: Stance, tensions: np.ndarray, psi: np.ndarray) -> tuple[float, float]:
    """(J, r): J = r - REGULARISATION/2 |f|^2 with r = sum log Phi(z_i) by log_ndtr."""
    att = stance.attached
    f = np.nan_to_num(tensions)
    r = float(stance.log_prob(f, np.nan_to_num(psi))[att].sum())
    return r - 0.5 * REGULARISATION * float(np.sum(f[att] ** 2)), r


class CvxpyAllocator:
    """The public ReachBot code's tension problem (reachbot_manipulation's TensionPlanner):
    maximise sum cp.log_normcdf(z_i) subject to A f = b and the tension bounds, a DPP problem
    built once and re-solved with new parameter values. z = c - w f with c = mu / sigma and
    w = 1 / sigma, so that every product is a parameter times a variable (DPP)."""

    def __init__(self, cp: Any, n: int, bounds: tuple[float, float], solver: str):
        self.cp, self.solver = cp, solver
        self.f = cp.Variable(n)
        self.A, self.b = cp.Parameter((3, n)), cp.Parameter(3)
        self.c, self.w = cp.Parameter(n), cp.Parameter(n, nonneg=True)
        margins = self.c - cp.multiply(self.w, self.f)
        objective = cp.Maximize(cp.sum(cp.log_normcdf(margins))
                                - 0.5 * REGULARISATION * cp.sum_squares(self.f))
        lo, hi = bounds
        self.problem = cp.Problem(objective, [self.A @ self.f == self.b, self.f >= lo,
                                              self.f <= hi])
        if not self.problem.is_dpp():
            raise RuntimeError("the cvxpy allocation problem should be DPP")

    def solve(self, A: np.ndarray, b: np.ndarray, mu: np.ndarray,
              sigma: np.ndarray) -> tuple[np.ndarray, float]:
        self.A.value, self.b.value = A, b
        self.c.value, self.w.value = mu / sigma, 1.0 / sigma
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.problem.solve(solver=self.solver)
        except self.cp.error.SolverError:
            return np.full(A.shape[1], np.nan), math.nan
        if self.problem.status not in (self.cp.OPTIMAL, self.cp.OPTIMAL_INACCURATE):
            return np.full(A.shape[1], np.nan), math.nan
        return np.asarray(self.f.value, dtype=float), float(self.problem.value)


def slsqp_allocation(A: np.ndarray, b: np.ndarray, mu: np.ndarray, sigma: np.ndarray,
                     bounds: tuple[float, float]) -> np.ndarray:
    """scipy SLSQP on the exact objective (log_ndtr, analytic gradient), started from the
    least-squares statics solution clipped to the bounds."""
    lo, hi = bounds

    def negative_objective(f: np.ndarray) -> tuple[float, np.ndarray]:
        lp, slope, _ = log_ndtr_derivatives((mu - f) / sigma)
        value = lp.sum() - 0.5 * REGULARISATION * f @ f
        return -value, slope / sigma + REGULARISATION * f

    start = np.clip(np.linalg.lstsq(A, b, rcond=None)[0], lo, hi)
    result = minimize(negative_objective, start, jac=True, method="SLSQP",
                      bounds=[(lo, hi)] * len(start),
                      constraints=[{"type": "eq", "fun": lambda f: A @ f - b,
                                    "jac": lambda f: A}],
                      options={"ftol": 1e-12, "maxiter": 500})
    return result.x if result.success else np.full(len(start), np.nan)


def _allocation_methods(cp: Any | None) -> dict[str, Callable[[AllocationCase], Answer]]:
    """Every method as case -> Answer, each timed from the pose and stance (the geometry
    included: every method starts from the same inputs)."""
    allocators: dict[tuple, ForceAllocator] = {}
    cvx: dict[tuple, CvxpyAllocator] = {}

    def ours(case: AllocationCase) -> Answer:
        t0 = time.perf_counter()
        alloc = allocate(case.scn.robot, case.scn.gravity_vector, case.pose, case.stance,
                         case.free_tip)
        return Answer(alloc.tensions[0], time.perf_counter() - t0)

    def drake(solver: str) -> Callable[[AllocationCase], Answer]:
        def run(case: AllocationCase) -> Answer:
            key = (case.scn.robot, solver)
            if key not in allocators:
                allocators[key] = ForceAllocator(case.scn.robot, solver=solver)
            t0 = time.perf_counter()
            alloc = allocators[key].solve(case.scn.gravity_vector, case.pose, case.stance,
                                          case.free_tip)
            return Answer(alloc.tensions[0], time.perf_counter() - t0)
        return run

    def external(name: str) -> Callable[[AllocationCase], Answer]:
        def run(case: AllocationCase) -> Answer:
            att = case.stance.attached
            bounds = case.scn.robot.boom_tension
            key = (name, int(att.sum()), bounds)
            if name != "slsqp" and key not in cvx:
                cvx[key] = CvxpyAllocator(cp, int(att.sum()), bounds, name)
            t0 = time.perf_counter()
            prob = _problem(case)
            A, b = prob.A[0][:, att], prob.b[0]
            mu, sigma = _margin_terms(case.stance, prob.pull_angles[0])
            value = math.nan
            if name == "slsqp":
                f = slsqp_allocation(A, b, mu, sigma, bounds)
            else:
                f, value = cvx[key].solve(A, b, mu, sigma)
            seconds = time.perf_counter() - t0
            f4 = np.full(4, np.nan)
            f4[att] = f
            return Answer(f4, seconds, value)
        return run

    methods = {"allocate": ours, "ForceAllocator-osqp": drake("osqp"),
               "ForceAllocator-clarabel": drake("clarabel")}
    if cp is not None:
        for solver in ("CLARABEL", "ECOS"):
            if solver in cp.installed_solvers():
                methods[f"cvxpy-{solver.lower()}"] = external(solver)
    methods["scipy-slsqp"] = external("slsqp")
    return methods


def batch_allocate(cases: list[AllocationCase], repeats: int = 3) -> tuple[np.ndarray, float]:
    """`allocate` once per group of cases with the same robot, gravity and free boom, each
    group's stances stacked row by row: the tensions (len(cases), 4) and the median over
    `repeats` of the total time."""
    groups: dict[tuple, list[int]] = {}
    for k, c in enumerate(cases):
        key = (c.scn.robot, tuple(c.scn.gravity_vector), c.stance.free_boom)
        groups.setdefault(key, []).append(k)
    tensions = np.full((len(cases), 4), np.nan)
    totals = []
    for _ in range(repeats):
        total = 0.0
        for (robot, gravity, free), rows in groups.items():
            stances = [cases[k].stance for k in rows]
            stacked = Stance(stances[0].ids, stances[0].attached,
                             *(np.stack([getattr(s, field) for s in stances])
                               for field in Stance._fields[2:]))
            poses = np.stack([cases[k].pose for k in rows])
            tips = None if free is None else np.stack([cases[k].free_tip for k in rows])
            t0 = time.perf_counter()
            alloc = allocate(robot, np.asarray(gravity), poses, stacked, tips)
            total += time.perf_counter() - t0
            tensions[rows] = alloc.tensions
        totals.append(total)
    return tensions, statistics.median(totals)


def run_allocation(samples: int, seed: int) -> dict[str, Any]:
    """The allocation section: cases, every method on every case, scores against the best."""
    try:
        import cvxpy as cp
    except ImportError:
        cp = None
    t0 = time.perf_counter()
    cases = allocation_cases(samples, seed)
    print(f"allocation: {len(cases)} cases in {time.perf_counter() - t0:.1f} s "
          f"({_count(c.group for c in cases)})", flush=True)
    if cp is None:
        print("allocation: cvxpy is not installed (pip install 'rbp[bench]'): skipping the "
              "cvxpy formulations", flush=True)
    methods = _allocation_methods(cp)
    # Warm-up on one case per stance size, untimed: first solves build programs and compile
    # cvxpy's parameterised problem (reported apart, as setup).
    setup = {name: 0.0 for name in methods}
    for n in (3, 4):
        first = next((c for c in cases if c.stance.attached.sum() == n), None)
        for name, method in methods.items():
            if first is not None:
                t = time.perf_counter()
                method(first)
                setup[name] += time.perf_counter() - t
    records = []
    for case in cases:  # every method on a case before the next case: noise hits all alike
        answers = {name: method(case) for name, method in methods.items()}
        records.append((case, answers))
    batch, batch_seconds = batch_allocate(cases)
    per_solve = batch_seconds / max(len(cases), 1)
    for k, (_, answers) in enumerate(records):
        answers["allocate-batch"] = Answer(batch[k], per_solve)
    rows = [_score_case(case, answers) for case, answers in records]
    names = [*methods, "allocate-batch"]
    groups = ("4-stance", "3-stance", "low-p")
    summary: dict[str, Any] = {
        "cases": {g: sum(c.group == g for c in cases) for g in groups},
        "cvxpy": cp is not None and any(n.startswith("cvxpy") for n in names),
        "setup_seconds": setup,
        "methods": {name: {g: _allocation_metrics(name, [r for r in rows if g in ("all",
                                                                                r["group"])])
                           for g in ("all", *groups)} for name in names},
    }
    base = summary["methods"]["allocate"]["all"]["ms_median"]
    summary["time_ratio_to_allocate"] = {
        name: _ratio(m["all"]["ms_median"], base) for name, m in summary["methods"].items()}
    _print_allocation(summary)
    return {"summary": summary, "cases": rows}


def _count(items: Iterable[str]) -> str:
    out: dict[str, int] = {}
    for item in items:
        out[item] = out.get(item, 0) + 1
    return ", ".join(f"{n} {k}" for k, n in out.items())


def _score_case(case: AllocationCase, answers: dict[str, Answer]) -> dict[str, Any]:
    """Per method: exact J and r, statics residual, bounds; the best is the highest J among
    the answers that hold the statics within bounds."""
    prob = _problem(case)
    A, b, psi = prob.A[0], prob.b[0], prob.pull_angles[0]
    lo, hi = case.scn.robot.boom_tension
    att = case.stance.attached
    scored = {}
    for name, ans in answers.items():
        f = ans.tensions
        fa = f[att]
        residual = float(np.abs(A @ np.nan_to_num(f) - b).max())
        ok = bool(np.isfinite(fa).all() and residual < STATICS_TOL
                  and (fa >= lo - BOUND_TOL).all() and (fa <= hi + BOUND_TOL).all())
        J, r = exact_objective(case.stance, f, psi) if ok else (None, None)
        scored[name] = {"ok": ok, "J": J, "r": r, "residual": residual, "seconds": ans.seconds,
                        "tensions": [None if not np.isfinite(x) else float(x) for x in f],
                        "model_value": None if not np.isfinite(ans.model_value)
                        else ans.model_value}
    valid = [name for name in scored if scored[name]["ok"]]
    best = max(valid, key=lambda n: scored[n]["J"]) if valid else None
    fb = np.array(scored[best]["tensions"] if best else [np.nan] * 4, dtype=float)
    for s in scored.values():
        if s["ok"]:
            f = np.array(s["tensions"], dtype=float)
            s["J_gap"] = scored[best]["J"] - s["J"]
            s["r_error"] = abs(scored[best]["r"] - s["r"])
            s["f_error"] = float(np.nanmax(np.abs(f - fb)))
            if s["model_value"] is not None:
                s["model_error"] = abs(s["model_value"] - s["J"])
    return {"cave": case.cave, "group": case.group, "pose": case.pose.tolist(),
            "stance": list(case.stance.ids), "best": best,
            "r_best": scored[best]["r"] if best else None, "methods": scored}


def _allocation_metrics(name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    m = [r["methods"][name] for r in rows]
    ok = [x for x in m if x["ok"]]
    curved = [r["methods"][name] for r in rows
              if r["best"] and r["r_best"] < CURVED and r["methods"][name]["ok"]]
    ms = _quantiles(1e3 * x["seconds"] for x in m)
    out = {"solves": len(m), "failed": len(m) - len(ok), "ms_median": ms["median"],
           "ms_p90": ms["p90"]}
    for key in ("J_gap", "r_error", "f_error"):
        q = _quantiles(x[key] for x in ok)
        out[f"{key}_median"], out[f"{key}_max"] = q["median"], q["max"]
    q = _quantiles(x["f_error"] for x in curved)
    out["curved"] = len(curved)
    out["f_error_curved_median"], out["f_error_curved_max"] = q["median"], q["max"]
    q = _quantiles(x.get("model_error") for x in ok)
    out["model_error_median"], out["model_error_max"] = q["median"], q["max"]
    return out


def _fmt(x: float | None, spec: str = ".2g") -> str:
    return "-" if x is None else format(x, spec)


def _print_allocation(summary: dict[str, Any]) -> None:
    print("\nforce allocation: median ms per solve (x ours: over allocate's); errors against the"
          "\nbest answer of each case: |dr| in log-probability, |df| in N where r < -1e-3 (where"
          "\nthe tensions are well defined); model: the method's own objective minus the exact")
    print(f"{'method':24s} {'ms':>8s} {'x ours':>7s} {'fail':>4s} {'|dr| med':>9s} "
          f"{'|dr| max':>9s} {'|df| med':>9s} {'|df| max':>9s} {'model max':>9s}")
    for name, m in summary["methods"].items():
        a = m["all"]
        print(f"{name:24s} {_fmt(a['ms_median'], '8.3f')} "
              f"{_fmt(summary['time_ratio_to_allocate'][name], '7.2f')} {a['failed']:4d} "
              f"{_fmt(a['r_error_median'], '9.1e')} {_fmt(a['r_error_max'], '9.1e')} "
              f"{_fmt(a['f_error_curved_median'], '9.1e')} "
              f"{_fmt(a['f_error_curved_max'], '9.1e')} {_fmt(a['model_error_max'], '9.1e')}")


# ---------------------------------------------------------------------------------------------
# SCP against one nonlinear solve (IPOPT)


class Segment(NamedTuple):
    """One phase of a climb with its seed: the inputs both optimisers get."""

    cave: str
    kind: str                      # "body" | "reach"
    scn: Scenario
    stance_ids: tuple[str, ...]    # the 4-stance (a reach phase frees `boom`)
    boom: int | None
    poses: np.ndarray              # (N, 3) the seed
    tips: np.ndarray | None        # (N, 2) the free gripper's path (reach)

    @property
    def stance(self) -> Stance:
        st = self.scn.stance(self.stance_ids)
        return st if self.boom is None else st.without(self.boom)


def scp_segments(moves: int, seed: int = 0, min_steps: int = 3) -> list[Segment]:
    """The phases of the first `moves` regrasps of greedy climbs on the bundled caves (round
    robin): from the current stance the first feasible move toward the goal (as the footstep
    planner orders them), then the body phase to its transition pose and the reach phase, with
    the pipeline's seeds (`PipelineConfig().seed`). Phases of fewer than `min_steps` steps are
    left out."""
    from planning.footsteps import candidate_moves, edge_rng
    from planning.pipeline import PipelineConfig
    from planning.seeds import body_seed, reach_seed
    from planning.transition import find_transition

    cfg = PipelineConfig().seed
    climbs = []
    for name, path in sorted(bundled_caves().items()):
        scn = load_scenario(path)
        climbs.append([name, scn, tuple(scn.start_stance), np.asarray(scn.start_pose, float),
                       {tuple(scn.start_stance)}])
    segments: list[Segment] = []
    done = 0
    while done < moves and climbs:
        for climb in list(climbs):
            if done >= moves:
                break
            name, scn, stance, pose, seen = climb
            step = None
            for j, anchor in candidate_moves(scn, stance, pose, per_boom=3, seed=seed):
                new = tuple(anchor if i == j else a for i, a in enumerate(stance))
                if new in seen:
                    continue
                tr = find_transition(scn, stance, j, anchor, edge_rng(seed, stance, j, anchor),
                                     guess=pose)
                if tr.feasible:
                    step = (j, anchor, new, tr.pose)
                    break
            if step is None:
                climbs.remove(climb)
                continue
            j, anchor, new, goal = step
            body = body_seed(scn, stance, pose, goal, cfg, seed=seed)
            reach = reach_seed(scn, stance, j, anchor, goal, cfg, seed=seed)
            if body.success and len(body.poses) >= min_steps:
                segments.append(Segment(name, "body", scn, stance, None, body.poses, None))
            if reach.success and len(reach.poses) >= min_steps:
                segments.append(Segment(name, "reach", scn, stance, j, reach.poses, reach.tips))
            climb[2], climb[3] = new, np.asarray(goal, dtype=float)
            seen.add(new)
            done += 1
    return segments


def _log_ndtr_any(z: Any) -> Any:
    """log Phi for floats and for Drake's AutoDiffXd (value by log_ndtr, slope the Mills
    ratio), so that Drake can differentiate the exact objective."""
    from pydrake.autodiffutils import AutoDiffXd

    if isinstance(z, AutoDiffXd):
        v = z.value()
        return AutoDiffXd(float(log_ndtr(v)), float(mills_ratio(v)) * z.derivatives())
    return log_ndtr(z)


class NonlinearPhase:
    """One phase as a single nonlinear program for IPOPT (see the module doc).

    Variables per step k: pose q_k, velocity v_k, attached tensions f_k and r_k (the step's
    robustness, tied to the geometry by an equality, so that the cost is linear and the floor
    a bound); w bounds the largest pose increment per coordinate (smoothness epigraph, as in
    planning.scp). Per step one vector constraint, exact and smooth away from the kinks of
    |psi| and of the limits: statics residual A f - b = 0, boom lengths and shoulder angles
    within limits, cos psi_i >= 1e-3 (a grasp pulled at 90 degrees has P = 0), r_k equal to
    sum log Phi(z_i) and, in a reach phase, the free limb's shoulder torque within its limit.
    The cost is planning.scp's merit, negated."""

    def __init__(self, segment: Segment, dt: float, config: Any, floor: float,
                 max_iterations: int = 1000):
        from pydrake.solvers import IpoptSolver, MathematicalProgram, SolverOptions

        scn, stance = segment.scn, segment.stance
        self.robot = robot = scn.robot
        self.g = np.asarray(scn.gravity_vector, dtype=float)
        self.stance, self.free, self.tips = stance, stance.free_boom, segment.tips
        self.att = np.flatnonzero(stance.attached)
        N, n = len(segment.poses), len(self.att)
        self.N, self.n = N, n
        self.targets = np.broadcast_to(np.where(stance.attached[:, None], stance.positions, 0.0),
                                       (N, 4, 2)).copy()
        if self.free is not None:
            self.targets[:, self.free] = segment.tips
        prog = MathematicalProgram()
        self.q = prog.NewContinuousVariables(N, 3, "pose")
        self.v = prog.NewContinuousVariables(N, 3, "velocity")
        self.f = prog.NewContinuousVariables(N, n, "tension")
        self.r = prog.NewContinuousVariables(N, "robustness")
        self.w = prog.NewContinuousVariables(3, "largest_increment")
        start, goal = segment.poses[0], segment.poses[-1]
        prog.AddBoundingBoxConstraint(start, start, self.q[0])
        prog.AddBoundingBoxConstraint(goal, goal, self.q[-1])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), self.v[0])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), self.v[-1])
        lo, hi = robot.boom_tension
        prog.AddBoundingBoxConstraint(lo, hi, self.f.ravel())
        prog.AddBoundingBoxConstraint(floor, 0.0, self.r)
        # Interior-point methods need bounded variables: a box far from anything optimal
        # (the seed's extent grown by POSE_BOX, speeds up to SPEED_BOX).
        low = segment.poses.min(axis=0) - POSE_BOX
        high = segment.poses.max(axis=0) + POSE_BOX
        prog.AddBoundingBoxConstraint(np.tile(low, N), np.tile(high, N), self.q.ravel())
        prog.AddBoundingBoxConstraint(-SPEED_BOX, SPEED_BOX, self.v.ravel())
        prog.AddBoundingBoxConstraint(0.0, 2.0 * POSE_BOX.max(), self.w)
        lb, ub = self._limits()
        for k in range(N):
            prog.AddConstraint(lambda x, k=k: self._timed_step_values(k, x), lb, ub,
                               np.concatenate([self.q[k], self.f[k], [self.r[k]]]))
        for k in range(N - 1):  # |q_{k+1,c} - q_{k,c}| <= w_c
            d = np.hstack([-np.eye(3), np.eye(3)])
            x = np.concatenate([self.q[k], self.q[k + 1], self.w])
            prog.AddLinearConstraint(np.hstack([d, -np.eye(3)]), np.full(3, -np.inf),
                                     np.zeros(3), x)
            prog.AddLinearConstraint(np.hstack([d, np.eye(3)]), np.zeros(3),
                                     np.full(3, np.inf), x)
        self.config = cfg = config
        self.dynamics = dynamics_matrix(robot, N, dt)
        prog.AddQuadraticCost(cfg.dynamics_weight * self.dynamics.T @ self.dynamics,
                              np.zeros(6 * N), np.concatenate([self.q.ravel(), self.v.ravel()]),
                              is_convex=True)
        prog.AddLinearCost(np.full(N, -cfg.robustness_weight), 0.0, self.r)
        prog.AddLinearCost(np.full(3, cfg.smoothness_weight), 0.0, self.w)
        self.prog = prog
        self.callback_seconds = 0.0  # spent in step_values called by IPOPT (Python, AutoDiff)
        self.solver = IpoptSolver()
        self.options = SolverOptions()
        # Stop on a small gradient, or once the merit stalls (it changes by less than 1e-6 for
        # 10 acceptable iterations; SCP stops when its model predicts a gain below 1e-4).
        for key, val in (("tol", 1e-6), ("acceptable_tol", 1e-4), ("acceptable_iter", 10),
                         ("acceptable_obj_change_tol", 1e-6), ("constr_viol_tol", 1e-9),
                         ("max_iter", int(max_iterations)), ("print_level", 0)):
            self.options.SetOption(IpoptSolver.id(), key, val)
        self.options.SetOption(IpoptSolver.id(), "sb", "yes")

    def _limits(self) -> tuple[np.ndarray, np.ndarray]:
        robot = self.robot
        L_lo, L_hi = robot.boom_length
        rng = robot.shoulder_range
        lb = [0.0] * 3 + [L_lo] * 4 + [-rng] * 4 + [1e-3] * self.n + [0.0]
        ub = [0.0] * 3 + [L_hi] * 4 + [rng] * 4 + [1.0] * self.n + [0.0]
        if self.free is not None:
            lb.append(-robot.shoulder_torque_max)
            ub.append(robot.shoulder_torque_max)
        return np.array(lb), np.array(ub)

    def _timed_step_values(self, k: int, x: np.ndarray) -> np.ndarray:
        t = time.perf_counter()
        out = self.step_values(k, x)
        self.callback_seconds += time.perf_counter() - t
        return out

    def step_values(self, k: int, x: np.ndarray) -> np.ndarray:
        """Step k's constraint values from [q_k, f_k, r_k] (floats or AutoDiffXd): written out
        boom by boom from docs/model.md, independently of rb_drake.geometry."""
        robot, st, g = self.robot, self.stance, self.g
        X, Y, phi = x[0], x[1], x[2]
        c, s = np.cos(phi), np.sin(phi)
        ex, ey, mz = robot.body_mass * g[0], robot.body_mass * g[1], 0.0
        r, torque = 0.0, 0.0
        lengths, angles, pulls = [], [], []
        a = 0
        for i in range(4):
            sx, sy = robot.shoulders[i]
            rx, ry = c * sx - s * sy, s * sx + c * sy           # R(phi) s_i
            tx, ty = self.targets[k, i]
            dx, dy = tx - X - rx, ty - Y - ry                   # shoulder -> target
            length = np.sqrt(dx * dx + dy * dy)
            ca, sa = math.cos(robot.shoulder_directions[i]), math.sin(robot.shoulder_directions[i])
            axis_x, axis_y = c * ca - s * sa, s * ca + c * sa   # equilibrium direction
            lengths.append(length)
            angles.append(np.arctan2(axis_x * dy - axis_y * dx, axis_x * dx + axis_y * dy))
            if i == self.free:
                # the cantilevered limb: boom mass at its midpoint, gripper at the tip
                m_b, m_g = robot.boom_linear_density * length, robot.gripper_mass
                px, py = X + rx, Y + ry
                mx, my = 0.5 * (px + tx), 0.5 * (py + ty)
                ex, ey = ex + (m_b + m_g) * g[0], ey + (m_b + m_g) * g[1]
                mz = mz + m_b * ((mx - X) * g[1] - (my - Y) * g[0]) + m_g * (
                    (tx - X) * g[1] - (ty - Y) * g[0])
                torque = m_b * ((mx - px) * g[1] - (my - py) * g[0]) + m_g * (
                    (tx - px) * g[1] - (ty - py) * g[0])
                continue
            f = x[3 + a]
            a += 1
            ux, uy = dx / length, dy / length
            ex, ey, mz = ex + f * ux, ey + f * uy, mz + f * (rx * uy - ry * ux)
            nx, ny = st.normals[i]
            cos_psi, sin_psi = -(nx * ux + ny * uy), -(nx * uy - ny * ux)  # pulled along -u
            psi = np.arctan2(sin_psi, cos_psi)
            fn, ft = st.f_normal[i], st.f_lateral[i]
            mu = fn * ft / np.sqrt((ft * cos_psi) ** 2 + (fn * sin_psi) ** 2)
            sigma = st.sigma_normal[i] + abs(psi) / (0.5 * math.pi) * (
                st.sigma_lateral[i] - st.sigma_normal[i])
            r = r + _log_ndtr_any((mu - f) / sigma)
            pulls.append(cos_psi)
        out = [ex, ey, mz, *lengths, *angles, *pulls, r - x[3 + self.n]]
        if self.free is not None:
            out.append(torque)
        return np.array(out)

    def robustness(self, poses: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """r_k = sum log Phi(z_i) at every step, by this program's own model."""
        # the row "sum log Phi - r_k" (before the torque row), evaluated with r_k = 0
        row = len(self._limits()[0]) - (2 if self.free is not None else 1)
        return np.array([self.step_values(k, np.concatenate([poses[k], tensions[k], [0.0]]))[
            row] for k in range(self.N)])

    def merit(self, poses: np.ndarray, velocities: np.ndarray, tensions: np.ndarray) -> float:
        """This program's merit (negated cost) at a trajectory whose statics hold."""
        x = np.concatenate([poses.ravel(), velocities.ravel()])
        D = self.dynamics @ x
        r = self.robustness(poses, tensions)
        cfg = self.config
        return float(cfg.robustness_weight * r.sum() - 0.5 * cfg.dynamics_weight * D @ D
                     - cfg.smoothness_weight * np.abs(np.diff(poses, axis=0)).max(axis=0).sum())

    def solve(self, poses: np.ndarray, velocities: np.ndarray,
              tensions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
        """IPOPT from the guess: poses, velocities, attached tensions and its status."""
        guess = np.zeros(self.prog.num_vars())
        for var, value in ((self.q, poses), (self.v, velocities), (self.f, tensions),
                           (self.r, self.robustness(poses, tensions)),
                           (self.w, np.abs(np.diff(poses, axis=0)).max(axis=0))):
            self.prog.SetDecisionVariableValueInVector(var, value, guess)
        result = self.solver.Solve(self.prog, guess, self.options)
        status = result.get_solution_result().name
        details = result.get_solver_details().ConvertStatusToString()
        if details:
            status = f"{status}: {details}"
        return (result.GetSolution(self.q), result.GetSolution(self.v),
                result.GetSolution(self.f).reshape(self.N, self.n), status)


def dynamics_matrix(robot: Any, N: int, dt: float) -> np.ndarray:
    """D = Dmat [q; v] with the statics holding (planning.scp's dynamics residual): per step
    the kinematic defect (M/dt)((q_{k+1} - q_k)/dt - (v_k + v_{k+1})/2), then the
    Newton-Euler defect (M/dt)(v_{k+1} - v_k); M = diag(m, m, m (w^2 + h^2) / 12)."""
    w, h = robot.body_size
    m = robot.body_mass
    scale = np.array([m, m, m * (w * w + h * h) / 12.0]) / dt
    D = np.zeros((N - 1, 6, 2, N, 3))
    for k in range(N - 1):
        for c in range(3):
            D[k, c, 0, k + 1, c], D[k, c, 0, k, c] = scale[c] / dt, -scale[c] / dt
            D[k, c, 1, k + 1, c] = D[k, c, 1, k, c] = -0.5 * scale[c]
            D[k, 3 + c, 1, k + 1, c], D[k, 3 + c, 1, k, c] = scale[c], -scale[c]
    return D.reshape(6 * (N - 1), 6 * N)


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
              f"{_fmt(ours['merit'], '.4f')} r_min {_fmt(ours['r_min'], '.4f')} "
              f"{'ok' if ours['feasible'] and ours['check_poses'] else 'INFEASIBLE'} | ipopt "
              f"{ipopt_seconds:6.2f} s merit {_fmt(ipopt['merit'], '.4f')} r_min "
              f"{_fmt(ipopt['r_min'], '.4f')} "
              f"{'ok' if ipopt['feasible'] and ipopt['check_poses'] else 'infeasible'} "
              f"({status})", flush=True)
    summary = _scp_summary(rows)
    print(f"scp: median {_fmt(summary['ours_seconds_median'], '.3f')} s (ours) against "
          f"{_fmt(summary['ipopt_seconds_median'], '.3f')} s (IPOPT), IPOPT/ours "
          f"{_fmt(summary['time_ratio_median'], '.1f')}x; feasible {summary['ours_feasible']}"
          f"/{len(rows)} (ours), {summary['ipopt_feasible']}/{len(rows)} (IPOPT); merit "
          f"IPOPT - ours median {_fmt(summary['merit_difference_median'], '.2e')}, r_sum "
          f"{_fmt(summary['r_sum_difference_median'], '.2e')}, r_min "
          f"{_fmt(summary['r_min_difference_median'], '.2e')}")
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
        "ours_seconds_median": _median(r["ours"]["seconds"] for r in rows),
        "ipopt_seconds_median": _median(r["ipopt"]["seconds"] for r in rows),
        "time_ratio_median": _median(r["ipopt"]["seconds"] / r["ours"]["seconds"]
                                     for r in rows),
        "ours_feasible": sum(ok(r["ours"]) for r in rows),
        "ipopt_feasible": sum(ok(r["ipopt"]) for r in rows),
        "ipopt_callback_share_median": _median(r["ipopt"]["callback_seconds"]
                                               / r["ipopt"]["seconds"] for r in rows),
        "ipopt_solved": sum(r["ipopt"]["status"].startswith("kSolutionFound") for r in rows),
        "ours_merit_gain_median": _median(r["ours"]["merit"] - r["seed"]["merit"]
                                          for r in rows if ok(r["ours"])),
        "ipopt_merit_gain_median": _median(r["ipopt"]["merit"] - r["seed"]["merit"]
                                           for r in rows if ok(r["ipopt"])),
        "both_feasible": len(both),
        "merit_difference_median": _median(r["ipopt"]["merit"] - r["ours"]["merit"]
                                           for r in both),
        "r_sum_difference_median": _median(r["ipopt"]["r_sum"] - r["ours"]["r_sum"]
                                           for r in both),
        "r_min_difference_median": _median(r["ipopt"]["r_min"] - r["ours"]["r_min"]
                                           for r in both),
        "ipopt_better": sum(r["ipopt"]["merit"] > r["ours"]["merit"] + 1e-6 for r in both),
    }


# ---------------------------------------------------------------------------------------------
# Footsteps


def run_footstep(caves: int, max_expansions: int, seed: int) -> dict[str, Any]:
    """RBP's footstep planner against the naive baseline on short generated caves (kinds in
    turn, seeds 1, 2, ...): RBP expands at most `max_expansions` stances, the naive planner
    takes at most as many regrasps (its own cap, `max_steps`)."""
    from planning.baseline import plan_naive
    from planning.footsteps import FootstepConfig, plan_footsteps
    from planning.plan import build_plan
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
            plan = build_plan(scn, fp, name)
            rows.append({"cave": scn.name, "planner": name, "seconds": seconds,
                         "success": bool(plan["success"]), "p_path": plan["p_path"],
                         "regrasps": plan["regrasps"], "reason": plan["reason"]})
            print(f"  {scn.name:11s} {name:5s}: {seconds:6.2f} s, success "
                  f"{plan['success']!s:5s}, p_path {_fmt(plan['p_path'], '.3f')}", flush=True)
    summary: dict[str, Any] = {}
    for name in ("rbp", "naive"):
        mine = [r for r in rows if r["planner"] == name]
        summary[name] = {"caves": len(mine), "successes": sum(r["success"] for r in mine),
                         "seconds_median": _median(r["seconds"] for r in mine),
                         "p_path_median": _median(r["p_path"] for r in mine if r["success"])}
    rbp = {r["cave"]: r for r in rows if r["planner"] == "rbp"}
    pairs = [(rbp[r["cave"]], r) for r in rows if r["planner"] == "naive"]
    summary["time_ratio_median"] = _median(a["seconds"] / b["seconds"] for a, b in pairs)
    summary["p_path_ratio_median"] = _median(
        a["p_path"] / b["p_path"] for a, b in pairs
        if a["success"] and b["success"] and b["p_path"])
    print(f"footstep: rbp {summary['rbp']['successes']}/{caves} succeeded, median "
          f"{_fmt(summary['rbp']['seconds_median'], '.2f')} s, p_path "
          f"{_fmt(summary['rbp']['p_path_median'], '.3f')}; naive "
          f"{summary['naive']['successes']}/{caves}, "
          f"{_fmt(summary['naive']['seconds_median'], '.2f')} s, p_path "
          f"{_fmt(summary['naive']['p_path_median'], '.3f')}; rbp/naive time "
          f"{_fmt(summary['time_ratio_median'], '.2f')}, p_path "
          f"{_fmt(summary['p_path_ratio_median'], '.2f')}")
    return {"summary": summary, "cases": rows}


# ---------------------------------------------------------------------------------------------
# Results, comparison, command line


def flat_metrics(result: dict[str, Any]) -> dict[str, float]:
    """Every numeric summary value as section.path.to.value -> number (booleans left out)."""
    out: dict[str, float] = {}

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for key, v in value.items():
                walk(f"{prefix}.{key}", v)
        elif isinstance(value, int | float) and not isinstance(value, bool):
            out[prefix] = float(value)

    for name, section in result.get("sections", {}).items():
        walk(name, section.get("summary", {}))
    return out


def compare(old: dict[str, Any], new: dict[str, Any]) -> list[tuple[str, float, float,
                                                                  float | None]]:
    """(metric, old, new, new/old) for every summary metric in both results."""
    a, b = flat_metrics(old), flat_metrics(new)
    return [(key, a[key], b[key], _ratio(b[key], a[key])) for key in b if key in a]


def print_comparison(old: dict[str, Any], new: dict[str, Any], label: str) -> None:
    rows = compare(old, new)
    print(f"\ncompared with {label} ({old.get('created', '?')}): new/old per metric")
    width = max((len(k) for k, *_ in rows), default=10)
    for key, a, b, ratio in rows:
        # Four significant digits: a fixed number of decimals loses a ratio far below 1.
        print(f"  {key:{width}s} {a:11.4g} -> {b:11.4g}  {_fmt(ratio, '10.4g')}")
    if not rows:
        print("  no metric in common")


def machine() -> dict[str, Any]:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model or platform.processor(), "cores": os.cpu_count(),
            "machine": platform.machine(),
            "python": f"{platform.python_implementation()} {platform.python_version()}"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections (default: {','.join(SECTIONS)})")
    parser.add_argument("--samples", type=int, default=300,
                        help="allocation cases (default 300)")
    parser.add_argument("--moves", type=int, default=4,
                        help="scp: regrasps along climbs of the bundled caves; each gives a "
                             "body and a reach phase (default 4)")
    parser.add_argument("--ipopt-iterations", type=int, default=1000,
                        help="scp: IPOPT's iteration cap per phase (default 1000)")
    parser.add_argument("--caves", type=int, default=3,
                        help="footstep: generated caves (default 3)")
    parser.add_argument("--max-expansions", type=int, default=60,
                        help="footstep: the planners' cap (default 60)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out/bench", help="output folder (default out/bench)")
    parser.add_argument("--json", metavar="FILE", help="results file (default OUT/bench.json)")
    parser.add_argument("--compare", metavar="OLD", help="an earlier results file: print the "
                        "ratio new/old of every summary metric")


def run(args: argparse.Namespace) -> int:
    sections = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = sorted(set(sections) - set(SECTIONS))
    if unknown:
        print(f"error: unknown section(s) {unknown}; choose from {list(SECTIONS)}",
              file=sys.stderr)
        return 2
    old = None
    if args.compare:  # read first: a bad file should fail before minutes of benchmarking
        try:
            old = json.loads(Path(args.compare).read_text())
        except (OSError, ValueError) as e:
            print(f"error: --compare {args.compare}: {e}", file=sys.stderr)
            return 2
    result: dict[str, Any] = {
        "format": FORMAT, "created": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(),
        "options": {k: v for k, v in vars(args).items() if k != "func"}, "sections": {}}
    started = time.perf_counter()
    for name in SECTIONS:
        if name not in sections:
            continue
        if name == "allocation":
            result["sections"][name] = run_allocation(args.samples, args.seed)
        elif name == "scp":
            result["sections"][name] = run_scp(args.moves, args.seed, args.ipopt_iterations)
        else:
            result["sections"][name] = run_footstep(args.caves, args.max_expansions, args.seed)
    result["seconds"] = time.perf_counter() - started
    out = Path(args.json) if args.json else Path(args.out) / "bench.json"
    atomic_write_text(out, json.dumps(result, indent=1, default=_jsonable))
    print(f"\nwrote {out} ({result['seconds']:.0f} s)")
    if old is not None:
        print_comparison(old, result, args.compare)
    return 0


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def add_bench_command(subparsers: Any) -> argparse.ArgumentParser:
    """Register `bench` on the `rbp` sub-command parsers."""
    p = subparsers.add_parser("bench", help="benchmark rbp against the alternatives a user "
                              "would write (cvxpy, SLSQP, IPOPT, the naive planner)",
                              description=__doc__.split("\n\n")[0])
    add_arguments(p)
    p.set_defaults(func=run)
    return p


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
