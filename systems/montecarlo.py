"""Stochastic execution of a plan: grasp strengths drawn per holding, attach failures, trials.

The model of `rb_drake.grasp` says a grasp pulled with force f at pull angle psi holds with
probability P = Phi(z), z = (mu(psi) - f) / sigma(psi). A holding (boom i on one anchor, from
attach to detach; planning/probability.py) draws its strength once: a quantile u ~ U(0, 1),
the same through the whole holding, which gives the limit

    f_max(psi) = mu(psi) + sigma(psi) Phi^-1(1 - u),

and the grasp fails at the first instant its force exceeds that limit, i.e. when
z(t) < Phi^-1(u), i.e. when P_i(t) < u (a pull with |psi| >= pi/2 has P = 0 and always fails).
The holding survives iff u <= min_t P_i(t), which has probability min_t P_i(t) exactly: the
path-probability model. Each regrasp also draws an attach variable a ~ U(0, 1) and fails on
contact (the first sample of the phase the new grasp starts) when a < attach_failure.

Speed. Until the first failure nothing stochastic feeds back into the dynamics, and the first
failure ends the climb (unless it is replanned). So the dynamics run once per plan
(deterministic, `ClimbSimulator.run`), the monitor records each holding's P_i(t) on the sample
grid, and the outcome of a trial is a function of its draws and those curves alone: the first
sample where a running minimum of P_i falls below u (a binary search per holding), vectorised
over all trials at once. `GraspFailures` in the diagram applies the same rule during a run with
the draws of one trial, and the tests hold the two equal. The estimate's target is the
probability the simulated forces imply, `SimulationRecord.implied_p_path()`; it equals the
plan's p_path when the plan is tracked closely and its straight-line phases hold everywhere.

Replanning (beyond the paper). When a grasp fails in a 4-stance (under load, or a new grasp on
contact) and the 3-stance left still holds the body (`check_poses` with the failed boom free and
its gripper at the failed anchor), a pluggable `Replanner` is asked for a new plan from that
state; the trial continues on it (simulated once per distinct failure state, with the body at
rest where it failed), holdings that carry on keep their drawn strengths, new ones draw afresh.
`retry_replanner` re-grasps the same anchor and resumes the plan (cheap);
`FootstepReplanner` moves the free boom to another anchor and runs the footstep planner from
there (10-60 s per call on a whole cave); both are in `systems.replanning`.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from scipy.special import ndtri

from planning.bounded_cache import BoundedCache, array_bytes
from rb_drake import grasp
from systems.diagram import ClimbSimulator, SimulationRecord
from systems.monitors import Cause
from systems.replanning import FootstepReplanner as FootstepReplanner  # re-exported
from systems.replanning import Replanner, ReplanRequest, still_holds
from systems.replanning import configuration as configuration  # re-exported
from systems.replanning import retry_replanner as retry_replanner  # re-exported
from systems.trajectory import PlanTrajectory

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson_interval(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion (95 % by default)."""
    if trials <= 0:
        return 0.0, 1.0
    p = successes / trials
    denom = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    # the interval contains p; clamp the rounding at p = 0 or 1
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))


def draw_strengths(rng: np.random.Generator, trials: int,
                   holdings: int) -> tuple[np.ndarray, np.ndarray]:
    """Per trial and holding: the strength quantile u and the attach variable a, U(0, 1)."""
    return rng.random((trials, holdings)), rng.random((trials, holdings))


def strength_limit(record: SimulationRecord, sample: int, boom: int, u: float) -> float | None:
    """The force the holding of `boom` could take at `sample` for quantile u (None when
    |psi| >= pi/2: no force is held)."""
    stance = record.plan.phases[record.phase[sample]].stance
    psi = float(record.pull_angle[sample, boom])
    if not abs(psi) < grasp.HALF_PI:
        return None
    mu = grasp.mean_limit(np.asarray(psi), stance.f_normal[boom], stance.f_lateral[boom])
    sigma = grasp.sigma_limit(np.asarray(psi), stance.sigma_normal[boom],
                              stance.sigma_lateral[boom])
    return float(mu + sigma * ndtri(1.0 - u))


class FirstFailures(NamedTuple):
    """Per trial: the sample of the first failure (-1: none), its holding and cause."""

    sample: np.ndarray   # (n,) int
    holding: np.ndarray  # (n,) int, -1 when none
    cause: np.ndarray    # (n,) int, Cause.* or 0


def first_failures(record: SimulationRecord, quantiles: np.ndarray,
                   attach_draws: np.ndarray) -> FirstFailures:
    """The first failure of each trial (rows of the draws, columns per holding), from the
    recorded P_i curves. Ties at one sample: an attach failure first, then the lowest boom
    (the order of `GraspFailures`)."""
    plan = record.plan
    af = plan.scenario.robot.attach_failure
    n = quantiles.shape[0]
    key = np.full((n, len(plan.holdings)), np.inf)
    for h, hold in enumerate(plan.holdings):
        rows = np.flatnonzero((record.phase >= hold.first) & (record.phase <= hold.last))
        if len(rows) == 0:
            continue
        running_min = np.minimum.accumulate(np.nan_to_num(record.probability[rows, hold.boom]))
        # first j with running_min[j] < u: -running_min is sorted ascending
        j = np.searchsorted(-running_min, -quantiles[:, h], side="right")
        over = j < len(rows)
        key[over, h] = rows[j[over]] * 8.0 + 4.0 + hold.boom
        if hold.attach:
            failed = attach_draws[:, h] < af
            key[failed, h] = rows[0] * 8.0 + hold.boom
    # A run the simulator stopped at a gripper that could not open or close unloaded
    # (`ClimbSimulator._gripper_may_switch`) fails every trial that gets that far.
    stopped = record.failure is not None and record.failure.cause == "handover"
    last = (len(record.times) - 1) * 8.0 + 7.0 if stopped else np.inf
    key = np.column_stack([key, np.full(n, last)])
    h = np.argmin(key, axis=1)
    best = key[np.arange(n), h]
    failed = np.isfinite(best)
    best = np.where(failed, best, 0.0)
    sample = np.where(failed, best // 8, -1).astype(int)
    handover = failed & (h == len(plan.holdings))
    cause = np.where(failed, np.where((best % 8) >= 4, Cause.OVERLOAD, Cause.ATTACH), 0)
    cause = np.where(handover, Cause.HANDOVER, cause)
    return FirstFailures(sample, np.where(failed & ~handover, h, -1), cause)


class TrialFailure(NamedTuple):
    """Where and why one trial's climb failed (time and phase in the executed plan)."""

    trial: int
    time: float
    phase: int
    kind: str
    boom: int
    anchor: str
    cause: str
    probability: float    # P_i at that sample
    draw: float           # u (overload) or a (attach)
    force: float          # N
    limit: float | None   # N, the drawn limit (overload)
    pull_angle: float     # rad

    def describe(self) -> str:
        why = (f"force {self.force:.2f} N over its drawn limit "
               f"{self.limit:.2f} N" if self.cause == "overload" and self.limit is not None
               else "pulled at |psi| >= 90 deg" if self.cause == "overload"
               else f"its boom still pulled {self.force:.2f} N: the gripper stayed as it was"
               if self.cause == "handover"
               else "the new grasp did not take hold")
        return (f"phase {self.phase} ({self.kind}), t = {self.time:.2f} s, boom {self.boom} on "
                f"{self.anchor}: {self.cause} ({why}; P = {self.probability:.4f})")


def describe_failures(record: SimulationRecord, first: FirstFailures, quantiles: np.ndarray,
                      attach_draws: np.ndarray, offset: float = 0.0) -> list[TrialFailure]:
    out = []
    for trial in np.flatnonzero(first.sample >= 0):
        s, h = int(first.sample[trial]), int(first.holding[trial])
        if first.cause[trial] == Cause.HANDOVER:
            stop = record.failure
            if stop is None:
                raise ValueError("a handover failure without the simulation's failure record")
            out.append(TrialFailure(
                int(trial), offset + stop.time, stop.phase, record.plan.phases[stop.phase].kind,
                stop.boom, stop.anchor, "handover", 1.0, 0.0, stop.draw, None, 0.0))
            continue
        hold = record.plan.holdings[h]
        attach = first.cause[trial] == Cause.ATTACH
        u = float(attach_draws[trial, h] if attach else quantiles[trial, h])
        k = int(record.phase[s])
        out.append(TrialFailure(
            int(trial), offset + float(record.times[s]), k, record.plan.phases[k].kind,
            hold.boom, hold.anchor, Cause.NAMES[int(first.cause[trial])],
            float(record.probability[s, hold.boom]), u, float(record.force[s, hold.boom]),
            None if attach else strength_limit(record, s, hold.boom, u),
            float(record.pull_angle[s, hold.boom])))
    return out


# ---------------------------------------------------------------------------------------------
# Monte Carlo


class ReplanSummary(NamedTuple):
    strategy: str
    attempted: int      # failed trials whose 3-stance still held: a replan was asked for
    replans: int        # distinct replanner calls (cached per failure state)
    saved: int          # trials that failed on the plan but reached the goal after replanning
    successes: int      # successes with replanning
    rate: float
    ci95: tuple[float, float]
    outcomes: dict[str, int]  # how the other failed trials ended


class MonteCarloResult(NamedTuple):
    trials: int
    successes: int
    rate: float
    ci95: tuple[float, float]
    p_path: float | None  # the plan's
    p_sim: float          # implied by the simulated forces
    seed: int
    failures: list[TrialFailure]
    replanning: ReplanSummary | None

    def failure_sites(self) -> list[dict[str, Any]]:
        """Failures grouped by (phase, kind, boom, anchor, cause), most frequent first."""
        count = Counter((f.phase, f.kind, f.boom, f.anchor, f.cause) for f in self.failures)
        first: dict[tuple, float] = {}
        for f in self.failures:
            key = (f.phase, f.kind, f.boom, f.anchor, f.cause)
            first[key] = min(first.get(key, math.inf), f.time)
        return [{"phase": k[0], "kind": k[1], "boom": k[2], "anchor": k[3], "cause": k[4],
                 "count": n, "earliest_time": first[k]} for k, n in count.most_common()]

    def to_json(self) -> dict[str, Any]:
        causes = Counter(f.cause for f in self.failures)
        out: dict[str, Any] = {
            "trials": self.trials, "successes": self.successes, "rate": self.rate,
            "ci95": list(self.ci95), "p_path": self.p_path, "p_sim": self.p_sim,
            "seed": self.seed,
            "failures": {"attach": causes.get("attach", 0),
                         "overload": causes.get("overload", 0),
                         "handover": causes.get("handover", 0)},
            "failure_sites": self.failure_sites(),
            "replanning": None,
        }
        if self.replanning is not None:
            r = self.replanning
            out["replanning"] = {"strategy": r.strategy, "attempted": r.attempted,
                                 "replans": r.replans, "saved": r.saved,
                                 "successes": r.successes, "rate": r.rate,
                                 "ci95": list(r.ci95), "outcomes": r.outcomes}
        return out


REPLAN_CACHE_MB = 256  # the replanned climbs kept at once (a whole demo climb: about 3.5 MB)


def _replan_bytes(value: tuple[ReplanRequest, SimulationRecord | None]) -> int:
    """What a replanned climb holds: its samples, a quarter more for its plan and trajectory
    (measured on the demo plan), and its request."""
    record = value[1]
    return 1024 + (0 if record is None else array_bytes(record) * 5 // 4)


class _Replanning:
    """Continues failed trials on replanned climbs (see the module docstring)."""

    def __init__(self, simulator: ClimbSimulator, replanner: Replanner, seed: int,
                 max_replans: int, progress: Callable[[int, int], None] | None,
                 cap_mb: float = REPLAN_CACHE_MB):
        self.simulator = simulator
        self.replanner = replanner
        self.seed = seed
        self.max_replans = max_replans
        self.progress = progress
        # replans by the failure state they continue from (`_replanned`): (the request, its
        # simulated climb or None), at most `cap_mb` of climbs kept; one dropped is planned
        # and simulated again from its request when asked for (the replanners are
        # deterministic). Kept whole, 1,000 distinct failures of a long climb held gigabytes.
        self.cache: BoundedCache[tuple, tuple[ReplanRequest, SimulationRecord | None]] = \
            BoundedCache(_replan_bytes, lambda key, request: self._replan(request),
                         tombstone=lambda value: value[0], cap_bytes=cap_mb * 2**20,
                         name="replans")

    def _replan(self, request: ReplanRequest) -> tuple[ReplanRequest, SimulationRecord | None]:
        new_plan = self.replanner(request)
        if new_plan is None:
            return request, None
        traj = PlanTrajectory(new_plan, request.scenario)
        return request, self.simulator.run(
            traj, initial_state=np.concatenate([request.pose, np.zeros(3)]))

    def _replanned(self, record: SimulationRecord, sample: int, boom: int, anchor: str,
                   cause: str) -> tuple[SimulationRecord | None, str]:
        k = int(record.phase[sample])
        stance = tuple(None if i == boom else a
                       for i, a in enumerate(record.plan.phases[k].stance.ids))
        pose = record.state[sample, :3]
        scn = record.plan.scenario
        if not still_holds(scn, stance, pose, boom, anchor):
            return None, "fell"
        # By content, not by id(record): an id is reused once its record is collected.
        key = (record.plan.content_key, float(record.times[sample]),
               record.state[sample].tobytes(), boom, cause)
        if key not in self.cache:
            self.cache[key] = self._replan(ReplanRequest(
                scn, record.plan.plan, k, float(record.times[sample]), pose.copy(), stance,
                boom, anchor, cause))
        new = self.cache[key][1]
        return new, ("no plan" if new is None else "")

    def continue_trial(self, trial: int, record: SimulationRecord, first: FirstFailures,
                       quantiles: np.ndarray, attach_draws: np.ndarray) -> str:
        """'success' or how the trial ended after its first failure."""
        u_row = quantiles[trial]
        s, h, cause = (int(first.sample[trial]), int(first.holding[trial]),
                       Cause.NAMES[int(first.cause[trial])])
        for depth in range(self.max_replans):
            if h < 0:  # a gripper that could not hand its load over: no state to replan from
                return "handover" if depth == 0 else "failed again, handover"
            hold = record.plan.holdings[h]
            new, why = self._replanned(record, s, hold.boom, hold.anchor, cause)
            if new is None:
                return why if depth == 0 else f"failed again, {why}"
            # Holdings that carry on into the new plan keep their strength; others draw anew.
            k = int(record.phase[s])
            rng = np.random.default_rng([self.seed, trial, depth])
            u_new, a_new = draw_strengths(rng, 1, len(new.plan.holdings))
            for n, nh in enumerate(new.plan.holdings):
                old = record.plan.holding_of[k, nh.boom]
                if (nh.first == 0 and nh.boom != hold.boom and old >= 0
                        and record.plan.holdings[old].anchor == nh.anchor):
                    u_new[0, n] = u_row[old]
            ff = first_failures(new, u_new, a_new)
            if ff.sample[0] < 0:
                return "success"
            record, u_row = new, u_new[0]
            s, h, cause = int(ff.sample[0]), int(ff.holding[0]), Cause.NAMES[int(ff.cause[0])]
        return "replan limit"


def monte_carlo(record: SimulationRecord, trials: int, seed: int,
                replanner: Replanner | None = None, strategy: str = "",
                simulator: ClimbSimulator | None = None, max_replans: int = 3,
                progress: Callable[[int, int], None] | None = None,
                replan_cache_mb: float = REPLAN_CACHE_MB) -> MonteCarloResult:
    """`trials` stochastic executions of the simulated plan (`record`, a deterministic run);
    with a `replanner` (and the `simulator` to run its plans), failed trials whose remaining
    3-stance holds are continued, with the same draws, to count the climbs replanning saves
    (at most `replan_cache_mb` of replanned climbs kept at once: one dropped is made again)."""
    rng = np.random.default_rng(seed)
    quantiles, attach_draws = draw_strengths(rng, trials, len(record.plan.holdings))
    first = first_failures(record, quantiles, attach_draws)
    successes = int(np.sum(first.sample < 0))
    failures = describe_failures(record, first, quantiles, attach_draws)
    summary = None
    if replanner is not None:
        if simulator is None:
            raise ValueError("replanning needs the simulator that runs the new plans")
        rp = _Replanning(simulator, replanner, seed, max_replans, progress,
                         replan_cache_mb)
        outcomes: Counter[str] = Counter()
        failed = np.flatnonzero(first.sample >= 0)
        for n, trial in enumerate(failed):
            outcomes[rp.continue_trial(int(trial), record, first, quantiles,
                                       attach_draws)] += 1
            if progress is not None:
                progress(n + 1, len(failed))
        saved = outcomes.pop("success", 0)
        total = successes + saved
        # asked for a replan: not those whose 3-stance fell, nor those stopped at a gripper
        # that could not hand over (no state to replan from: counted "still held" before)
        asked = len(failed) - outcomes.get("fell", 0) - outcomes.get("handover", 0)
        summary = ReplanSummary(strategy, asked,
                                len(rp.cache), saved, total, total / trials,
                                wilson_interval(total, trials), dict(outcomes))
    p_path = record.plan.plan.p_path
    return MonteCarloResult(trials, successes, successes / trials,
                            wilson_interval(successes, trials), p_path,
                            record.implied_p_path(), seed, failures, summary)
