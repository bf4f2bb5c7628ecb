"""SCP of body and reach phases (planning.scp).

Cases: a body phase on the bundled demo-shaft (the start pose moved 0.26 m up and right along a
straight line, every seed pose checked feasible), and a reach phase on the wide-shaft test cave
(boom 3's move from the start stance to a24, found by `find_transition`, with the free gripper on
a parabola between the two anchors and the body held at the transition pose). Every returned
trajectory is re-verified with `check_poses` and `statics_problem`, not with the planner's
bookkeeping.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from planning.footsteps import edge_rng
from planning.scp import (
    Iterate,
    PhaseProgram,
    ScpConfig,
    ScpResult,
    optimise_body,
    optimise_reach,
)
from planning.transition import find_transition, transition_stances
from rb_drake import geometry
from rb_drake.feasibility import Reason, check_poses
from rb_drake.scenario import Scenario, load_scenario
from rb_drake.stance import Stance
from rb_drake.statics import STATICS_TOL, allocate, statics_problem

ROOT = Path(__file__).resolve().parents[1]
DT = 0.2          # s per step
STEPS = 24
BOUND_TOL = 1e-9  # N, m, rad


class Case(NamedTuple):
    scn: Scenario
    stance: Stance
    poses: np.ndarray         # the seed (N, 3)
    tips: np.ndarray | None   # (N, 2) in a reach phase
    boom: int | None          # the free boom

    def optimise(self, config: ScpConfig | None = None,
                 poses: np.ndarray | None = None) -> ScpResult:
        poses = self.poses if poses is None else poses
        if self.boom is None:
            return optimise_body(self.scn, self.stance.ids, poses, DT, config)
        return optimise_reach(self.scn, self.stance.ids, self.boom, poses, self.tips, DT, config)

    def program(self, config: ScpConfig | None = None) -> PhaseProgram:
        return PhaseProgram(self.scn, self.stance, len(self.poses), DT, config, self.tips)


def _check_seed(case: Case) -> Case:
    check = check_poses(case.scn, case.stance, case.poses, case.tips)
    assert check.feasible.all(), (
        f"seed infeasible at steps {np.flatnonzero(~check.feasible).tolist()}: "
        f"{[Reason(int(r)).name for r in check.reason[~check.feasible]]}")
    return case


@pytest.fixture(scope="module")
def body() -> Case:
    scn = load_scenario(ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml")
    start = np.asarray(scn.start_pose, dtype=float)
    goal = start + np.array([0.237, 0.216, 0.02])
    poses = start + np.linspace(0.0, 1.0, STEPS)[:, None] * (goal - start)
    return _check_seed(Case(scn, scn.stance(scn.start_stance), poses, None, None))


@pytest.fixture(scope="module")
def reach() -> Case:
    scn = load_scenario(ROOT / "tests" / "data" / "wide-shaft.yaml")
    old, boom, anchor = scn.start_stance, 3, "a24"
    tr = find_transition(scn, old, boom, anchor, edge_rng(0, old, boom, anchor),
                         guess=np.asarray(scn.start_pose, dtype=float))
    assert tr.feasible, f"boom {boom} -> {anchor} should be a feasible transition: {tr.reason}"
    s_old, s_three, s_new = transition_stances(scn, old, boom, anchor)
    a, b = s_old.positions[boom], s_new.positions[boom]
    away = geometry.perp((b - a) / np.linalg.norm(b - a))
    if away @ (tr.pose[:2] - a) < 0.0:  # bulge into the cave, towards the body
        away = -away
    s = np.linspace(0.0, 1.0, STEPS)[:, None]
    tips = a + s * (b - a) + 4.0 * s * (1.0 - s) * 0.2 * away
    return _check_seed(Case(scn, s_three, np.tile(tr.pose, (STEPS, 1)), tips, boom))


@pytest.fixture(scope="module")
def results(body: Case, reach: Case) -> dict[str, ScpResult]:
    return {"body": body.optimise(), "reach": reach.optimise()}


CASES = ("body", "reach")


def _case(name: str, body: Case, reach: Case) -> Case:
    return body if name == "body" else reach


# ---------------------------------------------------------------------------------------------
# The linearisation against central differences


def _perturbed_iterate(case: Case, program: PhaseProgram, seed: int) -> Iterate:
    """A generic point: poses and tensions off the seed, velocities random, so that the
    statics residual, the dynamics residual and every pose increment are nonzero."""
    rng = np.random.default_rng(seed)
    poses = case.poses + rng.normal(0.0, [0.01, 0.01, 0.02], case.poses.shape)
    alloc = allocate(case.scn.robot, case.scn.gravity_vector, case.poses, case.stance, case.tips)
    tensions = alloc.tensions[:, program.att] + rng.normal(0.0, 0.5, (len(poses),
                                                                      len(program.att)))
    return Iterate(poses, rng.normal(0.0, 0.05, poses.shape), tensions)


@pytest.mark.parametrize("name", CASES)
def test_linearisation_matches_central_differences(name: str, body: Case, reach: Case) -> None:
    case = _case(name, body, reach)
    program = case.program()
    it = _perturbed_iterate(case, program, seed=1)
    lin = program.linearise(it)
    psi = lin.pull_angle[:, program.att]
    assert np.abs(psi).min() > 1e-3, "test point on the kink of sigma(|psi|) at psi = 0"
    h = 1e-6
    # Pose derivatives: coordinate c of every step at once (the steps are independent).
    pose_fields = ("length", "shoulder_angle", "pull_angle", "moment_arm", "mu", "sigma", "z",
                   "wrench", "torque")
    for c in range(3):
        step = np.zeros(3)
        step[c] = h
        up = program.linearise(it._replace(poses=it.poses + step))
        down = program.linearise(it._replace(poses=it.poses - step))
        for field in pose_fields:
            fd = (getattr(up, field) - getattr(down, field)) / (2.0 * h)
            analytic = getattr(lin, f"{field}_dq")[..., c]
            scale = max(1.0, np.abs(fd).max())
            np.testing.assert_allclose(
                analytic, fd, rtol=0.0, atol=1e-6 * scale,
                err_msg=f"{name}: d {field} / d pose[{c}] differs from central differences")
    # Tension derivatives: z and the statics residual are affine in each tension.
    for a, boom in enumerate(program.att):
        step = np.zeros(len(program.att))
        step[a] = h
        up = program.linearise(it._replace(tensions=it.tensions + step))
        down = program.linearise(it._replace(tensions=it.tensions - step))
        np.testing.assert_allclose(lin.z_df[:, boom], (up.z - down.z)[:, boom] / (2 * h),
                                   rtol=0.0, atol=1e-7, err_msg=f"{name}: dz/df boom {boom}")
        np.testing.assert_allclose(lin.wrench_df[:, :, a], (up.wrench - down.wrench) / (2 * h),
                                   rtol=0.0, atol=1e-7, err_msg=f"{name}: dA f/df boom {boom}")
    # The statics residual is the library's A f - b.
    prob = statics_problem(case.scn.robot, case.scn.gravity_vector, it.poses, case.stance,
                           case.tips)
    f4 = np.where(case.stance.attached, program.tensions4(it.tensions), 0.0)
    np.testing.assert_allclose(lin.wrench, np.einsum("nrb,nb->nr", prob.A, f4) - prob.b,
                               rtol=0.0, atol=1e-12, err_msg=f"{name}: e != A f - b")
    np.testing.assert_allclose(lin.torque, prob.shoulder_torque, rtol=0.0, atol=1e-12,
                               err_msg=f"{name}: shoulder torque differs from limb_load's")


@pytest.mark.parametrize("name", CASES)
def test_dynamics_and_merit_models_match_central_differences(name: str, body: Case,
                                                             reach: Case) -> None:
    """Along random directions in (poses, velocities, tensions), the slope of the exact
    dynamics residual and merit equals that of their models (central differences cancel the
    model's quadratic terms)."""
    case = _case(name, body, reach)
    program = case.program()
    it = _perturbed_iterate(case, program, seed=2)
    lin = program.linearise(it)
    rng = np.random.default_rng(3)
    h = 1e-6
    for trial in range(3):
        d = Iterate(*(rng.normal(0.0, 1.0, np.shape(x)) for x in it))

        def at(t: float, d: Iterate = d) -> Iterate:
            return Iterate(*(x + t * dx for x, dx in zip(it, d, strict=True)))

        def exact_dynamics(x: Iterate) -> np.ndarray:
            return program.evaluate(x).dynamics

        fd = (exact_dynamics(at(h)) - exact_dynamics(at(-h))) / (2 * h)
        model = (program.linear_dynamics(lin, it, at(h))
                 - program.linear_dynamics(lin, it, at(-h))) / (2 * h)
        np.testing.assert_allclose(model, fd, rtol=0.0, atol=1e-6 * max(1.0, np.abs(fd).max()),
                                   err_msg=f"{name}: dynamics slope, direction {trial}")
        fd = (program.evaluate(at(h)).merit - program.evaluate(at(-h)).merit) / (2 * h)
        model = (program.model_merit(lin, it, at(h))
                 - program.model_merit(lin, it, at(-h))) / (2 * h)
        assert abs(model - fd) <= 1e-6 * max(1.0, abs(fd)), (
            f"{name}: merit slope {fd} by central differences, {model} by the model "
            f"(direction {trial})")
        assert program.model_merit(lin, it, it) == pytest.approx(
            program.evaluate(it).merit, rel=1e-12, abs=1e-12), f"{name}: model != merit at it"


# ---------------------------------------------------------------------------------------------
# The trust-region loop


@pytest.mark.parametrize("name", CASES)
def test_accepted_steps_never_lower_the_exact_merit(name: str, body: Case, reach: Case,
                                                    results: dict[str, ScpResult]) -> None:
    res = results[name]
    case = _case(name, body, reach)
    assert res.history, f"{name}: no iterations recorded ({res.status})"
    assert any(h.accepted for h in res.history), f"{name}: no step accepted: {res.history}"
    previous = None
    for k, rec in enumerate(res.history):
        if rec.accepted:
            assert rec.actual_gain >= 0.0, f"{name}: step {k} accepted with {rec}"
            assert rec.actual_gain >= ScpConfig().accept_ratio * rec.predicted_gain, (
                f"{name}: step {k} accepted below the ratio: {rec}")
        if previous is not None:
            assert rec.merit >= previous, f"{name}: merit fell at iteration {k}: {res.history}"
        previous = rec.merit
    # Independently: the exact merit of the returned trajectory beats the seed's.
    program = case.program()
    seed = Iterate(case.poses, program.velocities_for(case.poses),
                   res.seed_tensions[:, program.att])
    mine = Iterate(res.poses, res.velocities, res.tensions[:, program.att])
    assert program.evaluate(mine).merit > program.evaluate(seed).merit, name
    assert program.evaluate(mine).merit == pytest.approx(res.history[-1].merit, abs=1e-12)


@pytest.mark.parametrize("name", CASES)
def test_trust_region_shrinks_on_rejected_steps(name: str, body: Case, reach: Case) -> None:
    """An acceptance ratio no step can reach (10 x the predicted gain) rejects every step: the
    radius halves each time, the iterate never changes, and the seed is returned."""
    cfg = ScpConfig(accept_ratio=10.0, radius_pose=0.2, radius_angle=0.4, radius_tension=20.0)
    res = _case(name, body, reach).optimise(cfg)
    trials = [h for h in res.history if np.isfinite(h.actual_gain)]
    assert len(trials) >= 3, f"{name}: too few trial steps: {res.history}"
    assert not any(h.accepted for h in res.history), f"{name}: {res.history}"
    radii = np.array([h.radius for h in res.history])
    np.testing.assert_allclose(radii, cfg.shrink ** np.arange(len(radii)), rtol=1e-12,
                               err_msg=f"{name}: radius sequence")
    merits = np.array([h.merit for h in res.history])
    np.testing.assert_array_equal(merits, merits[0], err_msg=f"{name}: the iterate changed")
    assert res.status.startswith("seed returned") and not res.improved, res.status
    last = res.history[-1]
    assert (last.radius * cfg.shrink < cfg.radius_min
            or last.predicted_gain <= cfg.tolerance), f"{name}: stopped early: {res.status}"
    np.testing.assert_array_equal(res.poses, _case(name, body, reach).poses)


@pytest.mark.parametrize("name", CASES)
def test_optimal_seed_is_left_unchanged(name: str, body: Case, reach: Case,
                                        results: dict[str, ScpResult]) -> None:
    """SCP from its own optimum predicts no gain and returns that trajectory unchanged."""
    first = results[name]
    assert first.improved and first.status == "converged", (name, first.status)
    again = _case(name, body, reach).optimise(poses=first.poses)
    assert not again.improved, f"{name}: the optimum was improved again: {again.history}"
    assert again.history[0].predicted_gain <= ScpConfig().tolerance, again.history
    np.testing.assert_array_equal(again.poses, first.poses, err_msg=f"{name}: poses changed")
    # Its tensions are the library's optimum for those poses: at least as robust as SCP's.
    assert np.all(again.log_probs >= first.log_probs - 1e-9), (
        f"{name}: re-allocated tensions less robust: {again.log_probs - first.log_probs}")


# ---------------------------------------------------------------------------------------------
# The result, re-verified


@pytest.mark.parametrize("name", CASES)
def test_result_is_feasible_and_at_least_as_robust_as_the_seed(
        name: str, body: Case, reach: Case, results: dict[str, ScpResult]) -> None:
    case, res = _case(name, body, reach), results[name]
    robot = case.scn.robot
    N = len(case.poses)
    assert res.improved, f"{name}: {res.status}"
    assert res.log_probs.min() >= res.seed_log_probs.min() - 1e-12, (
        f"{name}: least robustness {res.log_probs.min()} below the seed's "
        f"{res.seed_log_probs.min()}")
    assert res.log_probs.sum() > res.seed_log_probs.sum(), name
    np.testing.assert_array_equal(res.poses[[0, -1]], case.poses[[0, -1]],
                                  err_msg=f"{name}: start or goal pose moved")
    np.testing.assert_array_equal(res.velocities[[0, -1]], 0.0,
                                  err_msg=f"{name}: start or goal velocity not zero")
    check = check_poses(case.scn, case.stance, res.poses, case.tips)
    assert check.feasible.all(), (
        f"{name}: infeasible steps {np.flatnonzero(~check.feasible).tolist()}: "
        f"{[Reason(int(r)).name for r in check.reason[~check.feasible]]}")
    prob = statics_problem(robot, case.scn.gravity_vector, res.poses, case.stance, case.tips)
    att = case.stance.attached
    assert np.isnan(res.tensions[:, ~att]).all() and np.isfinite(res.tensions[:, att]).all()
    f = np.where(att, res.tensions, 0.0)
    residual = np.abs(np.einsum("nrb,nb->nr", prob.A, f) - prob.b).max()
    assert residual <= STATICS_TOL, f"{name}: statics residual {residual:.2e} N"
    lo, hi = robot.boom_tension
    fa = res.tensions[:, att]
    assert fa.min() >= lo - BOUND_TOL and fa.max() <= hi + BOUND_TOL, (
        f"{name}: tensions in [{fa.min()}, {fa.max()}] outside [{lo}, {hi}]")
    lp = case.stance.log_prob(f, np.nan_to_num(prob.pull_angles))[:, att].sum(axis=1)
    np.testing.assert_allclose(res.log_probs, lp, rtol=0.0, atol=1e-12,
                               err_msg=f"{name}: reported log-probabilities")
    assert res.log_probs.min() >= robot.log_p_min, name
    seed = allocate(robot, case.scn.gravity_vector, case.poses, case.stance, case.tips)
    np.testing.assert_allclose(res.seed_log_probs, seed.robustness, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(res.seed_tensions, seed.tensions, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(res.effort, np.nansum(res.tensions, axis=1), rtol=0, atol=0)
    if case.boom is None:
        assert res.free_force is None and res.shoulder_torque is None
    else:
        load = geometry.limb_load(robot, res.poses, case.boom, case.tips,
                                  case.scn.gravity_vector)
        np.testing.assert_allclose(res.shoulder_torque, load.shoulder_torque, rtol=0, atol=0)
        assert np.abs(res.shoulder_torque).max() <= robot.shoulder_torque_max
        assert res.free_force is not None and res.free_force.shape == (N,)
        # The axial force balances the limb's weight along the boom (it weighs ~0.3 N).
        assert np.abs(res.free_force).max() <= np.linalg.norm(load.force, axis=1).max() + 1e-12


def test_clarabel_and_osqp_agree(body: Case, results: dict[str, ScpResult]) -> None:
    clarabel = results["body"]
    osqp = body.optimise(ScpConfig(solver="osqp"))
    assert osqp.improved, osqp.status
    assert osqp.history[-1].merit == pytest.approx(clarabel.history[-1].merit, abs=2e-4), (
        osqp.history[-1].merit, clarabel.history[-1].merit)
    np.testing.assert_allclose(osqp.log_probs, clarabel.log_probs, rtol=0.0, atol=1e-3,
                               err_msg="per-step robustness differs between the solvers")
    np.testing.assert_allclose(osqp.poses, clarabel.poses, rtol=0.0, atol=0.02,
                               err_msg="poses differ between the solvers by over 2 cm")


def test_same_input_same_result(body: Case, results: dict[str, ScpResult]) -> None:
    again = body.optimise()
    for field in ("poses", "velocities", "tensions", "log_probs"):
        np.testing.assert_array_equal(getattr(again, field), getattr(results["body"], field),
                                      err_msg=f"{field} differs between identical runs")
    np.testing.assert_array_equal(np.array([h[:5] for h in again.history], dtype=float),
                                  np.array([h[:5] for h in results["body"].history],
                                           dtype=float), err_msg="histories differ")


def test_infeasible_subproblem_names_its_constraints(body: Case) -> None:
    """With p_min raised to 0.999 the seed's goal pose (fixed) cannot meet r >= r_min: the first
    subproblem is infeasible, its robustness floor at the last step is named, and the seed is
    returned."""
    robot = body.scn.robot.replace(p_min=0.999)
    case = body._replace(scn=dataclasses.replace(body.scn, robot=robot))
    seed_r = allocate(robot, case.scn.gravity_vector, case.poses, case.stance).robustness
    assert seed_r[-1] < robot.log_p_min, "the goal pose should be below the raised p_min"
    for solver in ("clarabel", "osqp"):
        res = case.optimise(ScpConfig(solver=solver))
        assert not res.improved and "infeasible" in res.status, (solver, res.status)
        names = res.infeasible_constraints
        last = f"robustness_floor[{len(case.poses) - 1}]"
        assert any(n.startswith(last) for n in names), f"{solver}: {last} not in {names}"
        assert all(n.startswith("robustness_floor[") for n in names), (solver, names)
        np.testing.assert_array_equal(res.poses, case.poses, err_msg="the seed is not returned")
        np.testing.assert_array_equal(res.log_probs, res.seed_log_probs)


def test_program_names_its_variables_and_constraints(reach: Case) -> None:
    program = reach.program()
    prog = program.prog
    names = {b.evaluator().get_description() for b in prog.GetAllConstraints()}
    assert names == {"statics", "robustness_floor", "boom_length", "shoulder_angle",
                     "shoulder_torque", "smoothness", "trust_region_pose",
                     "trust_region_velocity", "trust_region_tension"}, names
    costs = {b.evaluator().get_description() for b in prog.GetAllCosts()}
    assert costs == {"robustness_model", "dynamics_penalty", "smoothness"}, costs
    variables = {v.get_name().split("(")[0] for v in prog.decision_variables()}
    assert variables == {"pose", "velocity", "tension", "largest_increment"}, variables
    assert program.f.shape == (len(reach.poses), 3), "a reach phase has three tensions"
