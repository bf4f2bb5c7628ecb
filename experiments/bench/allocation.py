"""The allocation section of `rbp bench`: the most robust tensions at a pose, ours
(`statics.allocate` per pose and vectorised, `statics.ForceAllocator`) against the public
ReachBot code's cvxpy formulation and scipy SLSQP on the exact objective (see the package doc)."""

from __future__ import annotations

import functools
import math
import statistics
import time
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import minimize

from experiments.bench.stats import count, fmt, quantiles, ratio
from rb_drake import geometry
from rb_drake.feasibility import Reason, check_poses
from rb_drake.grasp import log_ndtr_derivatives
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario, bundled_caves, load_scenario
from rb_drake.stance import Stance
from rb_drake.statics import REGULARISATION, STATICS_TOL, ForceAllocator, allocate, statics_problem

BOUND_TOL = 1e-9     # N: tensions this far outside their bounds still count as within
CURVED = -1e-3       # r below this: log Phi is curved enough that the tensions are well defined



class AllocationCase(NamedTuple):
    cave: str
    group: str                    # "4-stance" | "3-stance" | "low-p" (statics hold, P < p_min)
    scn: Scenario
    stance: Stance
    pose: np.ndarray              # (3,)
    free_tip: np.ndarray | None   # (2,) in a 3-stance

    def tip(self) -> np.ndarray:
        """The free gripper's position, of a 3-stance case."""
        assert self.free_tip is not None, "a 4-stance case has no free gripper"
        return self.free_tip


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
                _sample_cave(scn, name, rng, batch, functools.partial(wants, name),
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
                          for i in range(NUM_BOOMS)], axis=1)         # (batch, 4, anchors)
    for p, pose in enumerate(poses):
        ids: list[str] = [""] * 4
        used: list[int] = []
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
            tips = None if free is None else np.stack([cases[k].tip() for k in rows])
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
          f"({count(c.group for c in cases)})", flush=True)
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
        name: ratio(m["all"]["ms_median"], base) for name, m in summary["methods"].items()}
    _print_allocation(summary)
    return {"summary": summary, "cases": rows}


def _score_case(case: AllocationCase, answers: dict[str, Answer]) -> dict[str, Any]:
    """Per method: exact J and r, statics residual, bounds; the best is the highest J among
    the answers that hold the statics within bounds."""
    prob = _problem(case)
    A, b, psi = prob.A[0], prob.b[0], prob.pull_angles[0]
    lo, hi = case.scn.robot.boom_tension
    att = case.stance.attached
    scored: dict[str, dict[str, Any]] = {}  # per method, the JSON record
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
            assert best is not None  # an ok answer is valid, so there is a best
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
    ms = quantiles(1e3 * x["seconds"] for x in m)
    out = {"solves": len(m), "failed": len(m) - len(ok), "ms_median": ms["median"],
           "ms_p90": ms["p90"]}
    for key in ("J_gap", "r_error", "f_error"):
        q = quantiles(x[key] for x in ok)
        out[f"{key}_median"], out[f"{key}_max"] = q["median"], q["max"]
    q = quantiles(x["f_error"] for x in curved)
    out["curved"] = len(curved)
    out["f_error_curved_median"], out["f_error_curved_max"] = q["median"], q["max"]
    q = quantiles(x.get("model_error") for x in ok)
    out["model_error_median"], out["model_error_max"] = q["median"], q["max"]
    return out


def _print_allocation(summary: dict[str, Any]) -> None:
    print("\nforce allocation: median ms per solve (x ours: over allocate's); errors against the"
          "\nbest answer of each case: |dr| in log-probability, |df| in N where r < -1e-3 (where"
          "\nthe tensions are well defined); model: the method's own objective minus the exact")
    print(f"{'method':24s} {'ms':>8s} {'x ours':>7s} {'fail':>4s} {'|dr| med':>9s} "
          f"{'|dr| max':>9s} {'|df| med':>9s} {'|df| max':>9s} {'model max':>9s}")
    for name, m in summary["methods"].items():
        a = m["all"]
        print(f"{name:24s} {fmt(a['ms_median'], '8.3f')} "
              f"{fmt(summary['time_ratio_to_allocate'][name], '7.2f')} {a['failed']:4d} "
              f"{fmt(a['r_error_median'], '9.1e')} {fmt(a['r_error_max'], '9.1e')} "
              f"{fmt(a['f_error_curved_median'], '9.1e')} "
              f"{fmt(a['f_error_curved_max'], '9.1e')} {fmt(a['model_error_max'], '9.1e')}")

