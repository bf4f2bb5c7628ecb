"""The plan as a Drake diagram (systems.diagram), stochastic execution and Monte Carlo
(systems.montecarlo) and `rbp simulate` (rbp.commands.simulate).

The plans are written here, not planned (the footstep planner's output changes with its
tuning, and a whole cave takes ~10 s to plan and ~15 s to simulate): on a short generated shaft,
one regrasp found by sampling poses that hold all four configurations of the move, between two
body phases, built like planning.plan builds them. `good`'s straight-line body phases hold
everywhere, so executing it must succeed as often as its p_path says; `straight`'s last body
phase crosses poses where the grasps hold far less than at its ends, which only a simulation
shows (p_path sees the phases' end configurations). Every diagram is built once per module:
Python systems are never freed in pydrake 1.51.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydrake.multibody.plant import DiscreteContactApproximation
from pydrake.trajectories import PiecewisePolynomial
from scipy.stats import norm

from planning.plan import (
    BODY_SPEED,
    FORMAT,
    REACH_DURATION,
    TURN_SPEED,
    plan_configurations,
    validate,
)
from planning.plan_model import Plan, plan_dict, plan_of
from planning.probability import path_probability
from planning.ramps import RELEASE_TENSION, add_ramps
from rb_drake.feasibility import check_poses
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario
from rb_drake.statics import statics_problem
from rbp.commands.simulate import add_simulate_command, cmd_simulate
from systems.control import BodyStatics, control_bounds
from systems.diagram import PLANT_TIME_STEP, ClimbSimulator, SimulationRecord
from systems.holdings import StrengthDraws
from systems.montecarlo import (
    FootstepReplanner,
    ReplanRequest,
    configuration,
    draw_strengths,
    first_failures,
    monte_carlo,
    retry_replanner,
    wilson_interval,
)
from systems.trajectory import (
    DWELL_MOTION,
    FREE_LIMB_SIZE,
    PlanTrajectory,
    plan_scenario,
    rest_to_rest,
)

SHORT = CaveConfig(length=(3.0, 3.2))
LINE = 41  # configurations checked along a body phase


def trial_draws(record: SimulationRecord, quantiles: np.ndarray,
                attach_draws: np.ndarray) -> StrengthDraws:
    """One trial's draws laid out for `GraspFailures` (the in-diagram run); only these tests
    run a trial in the diagram (systems.montecarlo draws outside it)."""
    return StrengthDraws.for_trial(record.plan, quantiles, attach_draws,
                                   record.plan.scenario.robot.attach_failure)


def _duration(a: np.ndarray, b: np.ndarray) -> float:
    return max(1.0, float(np.linalg.norm(b[:2] - a[:2])) / BODY_SPEED,
               abs(float(b[2] - a[2])) / TURN_SPEED)


def _lines(scn: Scenario, stance: tuple, a: np.ndarray, ends: np.ndarray):
    """Per end pose: the fraction of the line from a where statics hold, and the line's
    smallest P less the smaller of its two ends' P."""
    s = np.linspace(0.0, 1.0, LINE)[None, :, None]
    poses = (a + s * (ends[:, None, :] - a)).reshape(-1, 3)
    check = check_poses(scn, scn.stance(stance), poses, full=True)
    ok = check.allocation.statics_ok.reshape(len(ends), LINE)
    p = np.where(ok, check.probability.reshape(len(ends), LINE), 0.0)
    return ok.mean(axis=1), p.min(axis=1) - np.minimum(p[:, 0], p[:, -1])


def hand_plan(line_holds: bool, seed: int = 1, samples: int = 200) -> dict[str, Any]:
    """A plan file of one regrasp on shaft `seed`: body phase, reach phase, body phase. The
    last body phase's line holds everywhere (no worse than its ends) or crosses poses where
    the grasps hold with P below their ends' by 0.5 or more, or no tensions hold the body (P
    counted 0), as `line_holds` asks."""
    scn = generate_cave("shaft", seed, SHORT)
    rng = np.random.default_rng(seed)
    start, S = np.array(scn.start_pose), tuple(scn.start_stance)
    for j in range(4):
        old = scn.anchors[scn.anchor_index[S[j]]]
        near = np.argsort(np.linalg.norm(scn.anchor_positions - np.array(old.position), axis=1))
        for k in near[1:6]:
            to = scn.anchors[k]
            if to.id in S:
                continue
            new = tuple(to.id if i == j else a for i, a in enumerate(S))
            three = tuple(None if i == j else a for i, a in enumerate(S))
            tips = np.array(old.position), np.array(to.position)
            poses = start + rng.normal(0.0, [0.2, 0.2, 0.15], (samples, 3))
            ok = check_poses(scn, scn.stance(S), poses).feasible
            for stance, tip in ((three, tips[0]), (three, tips[1]), (new, None)):
                ok &= check_poses(scn, scn.stance(stance), poses, tip).feasible
            for q in poses[ok][:5]:
                holds, gap = _lines(scn, S, start, q[None])
                if holds[0] < 1.0 or gap[0] < -1e-3:
                    continue
                ends = q + rng.normal(0.0, [0.4, 0.4, 0.2], (samples, 3)) + [0.0, 0.3, 0.0]
                ends = ends[check_poses(scn, scn.stance(new), ends).feasible]
                holds, gap = _lines(scn, new, q, ends)
                fit = ((holds == 1.0) & (gap > -1e-3)) if line_holds else gap < -0.5
                if fit.any():
                    e = ends[np.flatnonzero(fit)[0]]
                    return _plan(scn, [(S, None, start, q), (three, tips, q, q), (new, None, q, e)],
                                 j, old.id, to.id)
    raise AssertionError(f"no {'good' if line_holds else 'bad'} regrasp found on shaft {seed}")


def _plan(scn: Scenario, phases: list, boom: int, a: str, b: str) -> dict[str, Any]:
    out, t = [], 0.0
    for stance, tips, p, q in phases:
        dt = REACH_DURATION if tips is not None else _duration(p, q)
        steps = [configuration(scn, stance, p, None if tips is None else tips[0], t),
                 configuration(scn, stance, q, None if tips is None else tips[1], t + dt)]
        assert all(ok for _, ok in steps), f"an infeasible configuration in {stance}"
        phase = {"kind": "body" if tips is None else "reach", "stance": list(stance),
                 "free_boom": None if tips is None else boom,
                 "steps": [s.to_dict() for s, _ in steps]}
        if tips is not None:
            phase |= {"from_anchor": a, "to_anchor": b}
        out.append(phase)
        t += dt
    plan = {"format": FORMAT, "planner": "rbp", "success": True, "reason": "", "p_min": None,
            "p_path": None, "regrasps": 0,
            "timing": dict.fromkeys(("footstep", "seed_body", "scp_body", "seed_reach",
                                     "scp_reach", "total"), 0.0),
            "scenario": scn.to_dict(resolved=True), "robot": scn.robot.to_dict(),
            "phases": out}
    ramped = add_ramps(Plan.from_dict(plan), scn)
    prob = path_probability(plan_configurations(ramped), scn.robot.attach_failure)
    plan = plan_dict(ramped.replace(p_path=prob.p_path, p_min=prob.p_min,
                                    regrasps=prob.regrasps))
    validate(plan)
    return plan


@pytest.fixture(scope="module")
def good_plan() -> dict[str, Any]:
    return hand_plan(line_holds=True)


@pytest.fixture(scope="module")
def sim(good_plan: dict[str, Any]) -> ClimbSimulator:
    return ClimbSimulator(plan_scenario(good_plan))


@pytest.fixture(scope="module")
def body_sim(good_plan: dict[str, Any]) -> ClimbSimulator:
    """The body-only plant (the booms' tensions applied at the shoulders)."""
    return ClimbSimulator(plan_scenario(good_plan), plant="body")


@pytest.fixture(scope="module")
def good(good_plan: dict[str, Any], sim: ClimbSimulator) -> SimulationRecord:
    return sim.run(PlanTrajectory(good_plan, sim.scenario))


@pytest.fixture(scope="module")
def good_body(good_plan: dict[str, Any], body_sim: ClimbSimulator) -> SimulationRecord:
    return body_sim.run(PlanTrajectory(good_plan, body_sim.scenario))


@pytest.fixture(scope="module")
def straight_plan() -> dict[str, Any]:
    return hand_plan(line_holds=False)


@pytest.fixture(scope="module")
def straight(straight_plan: dict[str, Any], sim: ClimbSimulator) -> SimulationRecord:
    """The same cave, so the same diagram serves."""
    return sim.run(PlanTrajectory(straight_plan, plan_scenario(straight_plan)))


@pytest.fixture(scope="module")
def straight_body(straight_plan: dict[str, Any], body_sim: ClimbSimulator) -> SimulationRecord:
    return body_sim.run(PlanTrajectory(straight_plan, plan_scenario(straight_plan)))


# ---------------------------------------------------------------------------------------------
# The systems' model


def test_body_statics_equals_rb_drake(good_plan: dict[str, Any]) -> None:
    """The per-configuration statics of the systems equal statics_problem (4- and 3-stances)."""
    scn = plan_scenario(good_plan)
    fast = BodyStatics(scn.robot, scn.gravity_vector)
    rng = np.random.default_rng(5)
    for phase in good_plan["phases"]:
        stance = scn.stance(phase["stance"])
        for step in phase["steps"]:
            tip = np.array(step["free_tip"]) if "free_tip" in step else None
            limb = np.zeros(FREE_LIMB_SIZE)
            limb[5] = -1.0
            if tip is not None:
                limb[:2], limb[5], limb[6] = tip, phase["free_boom"], 1.0
            for _ in range(5):
                pose = np.array(step["pose"]) + rng.normal(0, [0.05, 0.05, 0.1])
                ref = statics_problem(scn.robot, scn.gravity_vector, pose, stance, tip)
                np.testing.assert_allclose(fast.wrench_matrix(pose, stance), ref.A[0],
                                           atol=1e-12, err_msg=f"A at {pose}")
                np.testing.assert_allclose(fast.load(pose, stance, limb), ref.b[0], atol=1e-12,
                                           err_msg=f"b at {pose}, free tip {tip}")


@pytest.mark.parametrize("kind", ["body", "full"])
def test_booms_make_the_wanted_wrench(good_plan: dict[str, Any], sim: ClimbSimulator,
                                      body_sim: ClimbSimulator, kind: str) -> None:
    """On the plan (pose and velocity) at each of its steps, the body accelerates as the plan
    wants, with the plan's tensions: the booms pull the way the statics say (signs, moments,
    the planar joint's generalized forces, the free limb's load). The full plant weighs what
    the model's robot weighs (its body lighter by the 40 g of arm links at its shoulders; they
    made its tensions differ by up to ~0.2 N before), and its acceleration is one discrete
    step's velocity change (SAP)."""
    sim = {"body": body_sim, "full": sim}[kind]
    f_tol, a_tol = {"body": (1e-2, 1e-4), "full": (0.02, 5e-3)}[kind]
    traj = PlanTrajectory(good_plan, sim.scenario)
    ctx = sim.diagram.CreateDefaultContext()
    sim.source.set_plan(sim.source.GetMyMutableContextFromRoot(ctx), traj)
    plant_ctx = sim.plant.GetMyMutableContextFromRoot(ctx)
    base = slice(0, 3) if sim.robot_plant is None else (
        sim.robot_plant.base.velocity_start() + np.arange(3))
    for k, phase in enumerate(good_plan["phases"]):
        for n, step in enumerate(phase["steps"]):
            t = step["t"] if n == 0 else step["t"] - 1e-9  # inside phase k
            ctx.SetTime(t)
            sim.place(traj, t, np.r_[step["pose"], traj.velocity.value(t).ravel()], ctx)
            tension = sim.controller.GetOutputPort("tension").Eval(
                sim.controller.GetMyContextFromRoot(ctx))
            plan_f = np.array([f if f is not None else 0.0 for f in step["tension"]])
            np.testing.assert_allclose(tension, plan_f, atol=f_tol,
                                       err_msg=f"phases[{k}] step {n}: controller on the plan")
            if sim.robot_plant is None:
                vdot = sim.plant.EvalTimeDerivatives(plant_ctx).CopyToVector()[3:]
            else:
                vdot = sim.plant.get_generalized_acceleration_output_port().Eval(
                    plant_ctx)[base]
            np.testing.assert_allclose(vdot, traj.acceleration.value(t).ravel(), atol=a_tol,
                                       err_msg=f"phases[{k}] step {n}: acceleration")


def _one_phase_through(good_plan: dict[str, Any], scn: Scenario, path: list[np.ndarray],
                       dt: float) -> tuple[PlanTrajectory, np.ndarray, np.ndarray]:
    """A plan of one trajectory phase in good_plan's first stance through the poses of `path`,
    `dt` apart, ending in a dwell (the last step repeated, as planning.plan writes them): its
    trajectory, step times and poses, after checking that the pose passes through every step
    before the last motion."""
    first = good_plan["phases"][0]
    stance = tuple(first["stance"])
    steps = [configuration(scn, stance, q, None, k * dt)[0].to_dict() for k, q in enumerate(path)]
    steps.append(dict(steps[-1], t=len(path) * dt))
    plan = copy.deepcopy(good_plan)
    plan["phases"] = [dict(first, steps=steps)]
    traj = PlanTrajectory(plan, scn)
    times = np.array([s["t"] for s in steps])
    poses = np.array([s["pose"] for s in steps])
    for t, q in zip(times[:-2], poses[:-2], strict=True):
        np.testing.assert_allclose(traj.pose.value(t).ravel(), q, atol=1e-12, err_msg=f"t={t}")
    return traj, times, poses


def test_a_smooth_path_straying_from_the_straight_motion_is_refused(
        good_plan: dict[str, Any]) -> None:
    """Steps far apart around a corner: the smooth path rbp simulate would follow strays
    further than DEPARTURE_LIMIT from the straight motion rbp check verifies, and the
    verifier's line names the phase; steps along a line at an even pace do not stray."""
    from systems.trajectory import DEPARTURE_LIMIT

    scn = plan_scenario(good_plan)
    a = np.array(good_plan["phases"][0]["steps"][0]["pose"])
    corner = [a + np.array(d) for d in ([0, 0, 0], [0.08, 0, 0], [0.08, 0.08, 0], [0, 0.08, 0])]
    traj, _, _ = _one_phase_through(good_plan, scn, corner, 0.5)
    assert traj.departure > DEPARTURE_LIMIT, f"strays only {traj.departure}"
    problem = traj.departure_problem()
    assert problem is not None and problem.startswith("phases[0] (body): between:"), problem
    straight = [a + k * np.array([0.004, 0.002, 0.001]) for k in range(5)]
    traj, _, _ = _one_phase_through(good_plan, scn, straight, 0.5)
    assert traj.departure < 0.05, f"a straight even motion strays {traj.departure}"
    assert traj.departure_problem() is None


def test_the_last_motion_of_a_trajectory_phase_uses_its_dwell(good_plan: dict[str, Any]) -> None:
    """A phase of several steps ending in a dwell (the last step repeated, as planning.plan
    writes them): the pose passes through every earlier step, reaches the last configuration
    DWELL_MOTION into the dwell and rests there until the phase ends, and brakes less than a
    spline stopping at the dwell's start (the plan's knots) would."""
    scn = plan_scenario(good_plan)
    first = good_plan["phases"][0]
    a, b = (np.array(first["steps"][n]["pose"]) for n in (0, -1))
    dt, n = 0.5, 6
    path = [a + (b - a) * (k / n) ** 0.5 for k in range(n + 1)]  # slowing: moving at the end
    traj, times, poses = _one_phase_through(good_plan, scn, path, dt)
    end = times[-1]
    arrival = times[-2] + DWELL_MOTION * (end - times[-2])
    for t in np.linspace(arrival, end, 5):
        np.testing.assert_allclose(traj.pose.value(t).ravel(), poses[-1], atol=1e-12)
        np.testing.assert_allclose(traj.velocity.value(t).ravel(), 0.0, atol=1e-12)
    assert np.linalg.norm(traj.pose.value(times[-2]).ravel()[:2] - poses[-1][:2]) > 1e-4
    knots = PiecewisePolynomial.CubicShapePreserving(times, poses.T, True).derivative(2)
    grid = np.linspace(times[-3], end, 200)
    ours = max(np.linalg.norm(traj.acceleration.value(t).ravel()[:2]) for t in grid)
    theirs = max(np.linalg.norm(knots.value(t).ravel()[:2]) for t in grid)
    assert ours < 0.6 * theirs, f"braking {ours} m/s^2, stopping at the dwell {theirs}"


def test_a_turning_body_path_has_a_continuous_acceleration(good_plan: dict[str, Any]) -> None:
    """A phase whose body first turns, then translates: the executed path passes through every
    step, its acceleration is continuous at the steps where the motion turns (a shape-preserving
    spline's jumps there, by a feed-forward that moved 1 N onto a weak grasp in crevasse-s6),
    and it rests at the dwell that ends the phase."""
    scn = plan_scenario(good_plan)
    a = np.array(good_plan["phases"][0]["steps"][0]["pose"])
    dt = 0.5
    # rotate by 0.06 rad over three steps, then translate 3 cm over three, then dwell
    path = [a + np.array([0.0, 0.0, 0.02 * k]) for k in range(4)]
    path += [path[-1] + np.array([0.01 * k, 0.0, 0.0]) for k in range(1, 4)]
    traj, times, poses = _one_phase_through(good_plan, scn, path, dt)
    eps = 1e-7
    pchip = PiecewisePolynomial.CubicShapePreserving(times, poses.T, True).derivative(2)
    pchip_jump = 0.0
    for t in times[1:4]:  # the rotation's steps and the turn to translating
        left = traj.acceleration.value(t - eps).ravel()
        right = traj.acceleration.value(t + eps).ravel()
        np.testing.assert_allclose(left, right, atol=1e-4, err_msg=f"acceleration jumps at {t}")
        pchip_jump = max(pchip_jump, float(np.abs(pchip.value(t - eps).ravel()
                                                  - pchip.value(t + eps).ravel()).max()))
    assert pchip_jump > 0.01, f"the case does not turn sharply (pchip's jump {pchip_jump})"
    end = times[-1]
    for t in np.linspace(times[-2] + DWELL_MOTION * (end - times[-2]), end, 4):
        np.testing.assert_allclose(traj.velocity.value(t).ravel(), 0.0, atol=1e-12)


def test_rest_to_rest_timing() -> None:
    t, s, ds = rest_to_rest(2.0, 7.0, 0.05)
    assert t[0] == 2.0 and t[-1] == 7.0 and np.all(np.diff(t) <= 0.05 + 1e-12)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0, abs=1e-15)
    assert ds[0] == 0.0 and ds[-1] == pytest.approx(0.0, abs=1e-15)
    assert np.all(np.diff(s) > 0), "progress must increase"
    mid = np.gradient(s, t)[1:-1]
    np.testing.assert_allclose(mid, ds[1:-1], atol=5e-3, err_msg="ds is not the rate of s")


# ---------------------------------------------------------------------------------------------
# The deterministic run


def test_full_diagram_holds_the_tips_with_ball_constraints(sim: ClimbSimulator,
                                                           good: SimulationRecord) -> None:
    """The default diagram simulates rb_drake's whole robot: a discrete SAP plant with four
    tips and a ball constraint per boom, the tensions on the prismatic joints, the free limb's
    controller; after a run the holds are the last phase's stance, the anchors locked."""
    diagram = sim.diagram
    for name in ("plan", "controller", "limb", "boom_forces", "generalized_force", "plant",
                 "monitor", "failures", "body_state", "joints"):
        assert diagram.HasSubsystemNamed(name), f"no subsystem {name!r}"
    rb, plant = sim.robot_plant, sim.plant
    assert rb is not None and plant is rb.plant and plant.time_step() == PLANT_TIME_STEP
    assert plant.get_discrete_contact_approximation() == DiscreteContactApproximation.kSap
    assert [t.name() for t in rb.tips] == [f"tip{i}" for i in range(4)]
    assert sorted(plant.GetConstraintIds(), key=repr) == sorted(rb.holds, key=repr)
    assert plant.num_constraints() == 4
    ctx = plant.GetMyContextFromRoot(sim.context)
    last = good.plan.phases[-1].stance
    assert [plant.GetConstraintActiveStatus(ctx, h) for h in rb.holds] == list(last.attached)
    assert all(j.is_locked(ctx) for j in rb.anchors)
    for i in np.flatnonzero(last.attached):
        np.testing.assert_allclose(rb.anchors[i].get_translation(ctx), last.positions[i], atol=0)
    assert good.joints is not None and good.joints.shape == (len(good.times), 8)
    with pytest.raises(ValueError, match="plant"):
        ClimbSimulator(sim.scenario, plant="rigid")


def test_tips_stay_on_their_anchors(good: SimulationRecord,
                                    straight: SimulationRecord) -> None:
    """Over both plans: every attached tip within 1 mm of its anchor; the free tip within
    5 mm of its planned path and 1 mm of the new anchor when the reach ends; the joints within
    their limits (the simulation's plant has none: plans may sit on them) to 0.5 deg, 1 mm."""
    for record in (good, straight):
        robot = record.plan.scenario.robot
        tips = record.tip_positions()
        for s in range(len(record.times)):
            phase = record.plan.phases[record.phase[s]]
            att = phase.stance.attached
            off = np.linalg.norm(tips[s, att] - phase.stance.positions[att], axis=1)
            assert off.max() < 1e-3, f"t={record.times[s]}: tips {off} m off their anchors"
            j = phase.stance.free_boom
            if j is not None:
                planned = phase.free_tip.value(record.times[s]).ravel()
                gap = np.linalg.norm(tips[s, j] - planned)
                assert gap < 5e-3, f"t={record.times[s]}: free tip {gap} m off its path"
        for k, phase in enumerate(record.plan.phases):
            if phase.stance.free_boom is not None:
                s = np.flatnonzero(record.phase == k)[-1]
                end = phase.free_tip.value(phase.end).ravel()
                gap = np.linalg.norm(tips[s, phase.stance.free_boom] - end)
                assert gap < 1e-3, f"phase {k}: the reach ends {gap} m from the new anchor"
        theta, length = np.abs(record.joints[:, 0::2]), record.joints[:, 1::2]
        assert theta.max() < robot.shoulder_range + math.radians(0.5), np.degrees(theta.max())
        lo, hi = robot.boom_length
        assert lo - 1e-3 < length.min() and length.max() < hi + 1e-3


def test_full_and_body_plants_agree(good: SimulationRecord, good_body: SimulationRecord,
                                    straight: SimulationRecord,
                                    straight_body: SimulationRecord) -> None:
    """The full robot and the body alone, on the same plans: both track within 5 mm, 0.5 deg
    where the plan holds, and every holding's smallest P agrees within 2e-3 where the plan
    holds (0.02 where it does not: there the body's dynamics, limb and all, matter)."""
    for full, body, p_tol in ((good, good_body, 2e-3), (straight, straight_body, 0.02)):
        assert full.failure is None and body.failure is None
        np.testing.assert_allclose(full.times, body.times, atol=1e-9)
        np.testing.assert_allclose(full.holding_minimum(), body.holding_minimum(), atol=p_tol,
                                   err_msg="per-holding minimum P, full vs body")
        assert abs(full.implied_p_path() - body.implied_p_path()) < p_tol
    for record in (good, good_body):
        assert record.position_error.max() < 5e-3, record.position_error.max()
        assert record.heading_error.max() < math.radians(0.5), record.heading_error.max()


def test_tracking_error_bounded(good: SimulationRecord, straight: SimulationRecord) -> None:
    traj = good.plan
    assert good.times[0] == 0.0 and good.times[-1] >= traj.end_time - 0.021
    assert good.failure is None
    assert good.position_error.max() < 0.005, f"max error {good.position_error.max():.4f} m"
    assert good.heading_error.max() < math.radians(0.5), good.heading_error.max()
    # Even through the stretch where no tensions hold the body, the error stays bounded.
    assert straight.position_error.max() < 0.02, straight.position_error.max()
    assert straight.heading_error.max() < math.radians(3.0), straight.heading_error.max()


def test_record_follows_the_plan(good: SimulationRecord) -> None:
    traj = good.plan
    lo, hi = control_bounds(traj.scenario.robot)  # the controller's floor: 0.1 N
    for s in range(0, len(good.times), 7):
        k = good.phase[s]
        phase = traj.phases[k]
        assert phase.start <= good.times[s] + 1e-9 and good.times[s] <= phase.end + 1e-9
        att = phase.stance.attached
        f = good.tension[s]
        # a boom in a release or attach ramp may go slack
        ramped = att & (phase.share.value(good.times[s]).ravel() > 0)
        low = np.where(ramped, 0.0, lo)
        assert np.all(f[att] >= low[att] - 1e-6) and np.all(f[att] <= hi + 1e-6), (
            f"t={good.times[s]}")
        assert np.all(f[~att] == 0.0)
        assert np.all(np.isnan(good.probability[s, ~att])) and np.all(
            np.isfinite(good.probability[s, att]))
        held = att & ~ramped
        np.testing.assert_allclose(good.force[s, held], f[held], atol=0)
    assert set(np.unique(good.phase)) == set(range(len(traj.phases)))


def _paper_probability(anchor, force: float, psi: float) -> float:
    """P of a grasp by the paper's formulas, written here independently (half-ellipse mean,
    sigma linear in |psi|, Phi by scipy.stats)."""
    if not abs(psi) < math.pi / 2:
        return 0.0
    fn, ft = anchor.f_normal, anchor.f_lateral
    mu = fn * ft / math.sqrt((ft * math.cos(psi)) ** 2 + (fn * math.sin(psi)) ** 2)
    sigma = anchor.sigma_normal + abs(psi) / (math.pi / 2) * (
        anchor.sigma_lateral - anchor.sigma_normal)
    return float(norm.cdf((mu - force) / sigma))


@pytest.mark.parametrize("kind", ["body", "full"])
def test_monitor_probabilities_equal_the_model(good: SimulationRecord,
                                               good_body: SimulationRecord, kind: str) -> None:
    """P_i recomputed with the paper's formulas from the logged state and tensions: exactly
    for the body plant, whose monitor takes the tension along shoulder -> anchor; the full
    plant's monitor reads each boom's pull from the joint reaction forces, so there P_i is
    recomputed from the logged force and pull angle, and those equal the tension and the
    geometric pull angle of the logged pose within 1e-3 N and 1e-3 rad."""
    record = {"body": good_body, "full": good}[kind]
    scn = record.plan.scenario
    shoulders = np.asarray(scn.robot.shoulders)
    checked = 0
    for s in range(0, len(record.times), 5):
        stance = record.plan.phases[record.phase[s]].stance
        x, y, phi = record.state[s, :3]
        R = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
        for i in np.flatnonzero(stance.attached):
            anchor = scn.anchors[scn.anchor_index[stance.ids[i]]]
            pull = np.array([x, y]) + R @ shoulders[i] - np.array(anchor.position)
            n = np.array(anchor.normal)
            psi = math.atan2(n[0] * pull[1] - n[1] * pull[0], n @ pull)
            at = f"t={record.times[s]} boom {i}"
            if kind == "body":
                assert record.pull_angle[s, i] == pytest.approx(psi, abs=1e-12), at
                assert record.force[s, i] == record.tension[s, i], at
            else:
                assert record.pull_angle[s, i] == pytest.approx(psi, abs=1e-3), at
                assert record.force[s, i] == pytest.approx(record.tension[s, i], abs=1e-3), at
            p = _paper_probability(anchor, record.force[s, i], record.pull_angle[s, i])
            assert record.probability[s, i] == pytest.approx(p, rel=1e-9, abs=1e-14), (
                f"{at}: monitor {record.probability[s, i]}, model {p}")
            checked += 1
    assert checked > 200


def test_simulated_probability_matches_plan(good: SimulationRecord,
                                            good_plan: dict[str, Any]) -> None:
    """Tracked closely on lines that hold, the climb's implied probability is the plan's, and
    so is each holding's smallest P_i (which the run sees on the whole line, not only at the
    plan's end configurations)."""
    p_sim, p_path = good.implied_p_path(), good_plan["p_path"]
    assert abs(p_sim - p_path) < 0.01, f"p_sim {p_sim}, plan p_path {p_path}"
    planned = {(b, a): p for b, a, p in path_probability(_configurations(good_plan),
                                                          0.0).holdings}
    simulated = good.holding_minimum()
    assert len(planned) == len(simulated) == len(good.plan.holdings)
    for hold, p in zip(good.plan.holdings, simulated, strict=True):
        plan_p = planned[(hold.boom, hold.anchor)]
        assert plan_p - 0.01 < p < plan_p + 1e-3, f"{hold}: simulated {p}, planned {plan_p}"


def _configurations(plan: dict[str, Any]):
    return plan_configurations(plan_of(plan))


def test_straight_line_plan_is_exposed(straight: SimulationRecord) -> None:
    """A footstep plan whose body phase crosses poses no tensions hold: the simulation shows it
    (the plan's p_path only sees the phases' end configurations)."""
    p_path, p_sim = straight.plan.plan.p_path, straight.implied_p_path()
    assert p_path > 0.9 and p_sim < p_path - 0.5, f"p_path {p_path}, simulated {p_sim}"


# ---------------------------------------------------------------------------------------------
# Stochastic execution


def test_wilson_interval_solves_the_score_equation() -> None:
    for successes, trials in ((0, 10), (3, 10), (50, 100), (904, 1000), (1000, 1000)):
        lo, hi = wilson_interval(successes, trials)
        p = successes / trials
        assert 0.0 <= lo <= p <= hi <= 1.0
        for end in (lo, hi):  # |p - end| = z sqrt(end (1 - end) / n)
            gap = abs(p - end) - 1.959963984540054 * math.sqrt(end * (1 - end) / trials)
            assert abs(gap) < 1e-12, f"{successes}/{trials}: end {end}"
    assert np.diff(wilson_interval(500, 1000)) < np.diff(wilson_interval(50, 100))


def test_in_diagram_failures_equal_vectorised(good: SimulationRecord,
                                              sim: ClimbSimulator) -> None:
    """GraspFailures in the diagram and the vectorised rule agree for the same draws: an
    overload (u just above a holding's P early on) and an attach failure (a = 0)."""
    traj = good.plan
    H = len(traj.holdings)
    overload_u, overload_a = np.zeros(H), np.ones(H)
    h0 = next(h for h, hold in enumerate(traj.holdings) if not hold.attach)
    rows = np.flatnonzero(good.phase == 0)
    target = rows[2 * len(rows) // 3]
    overload_u[h0] = float(np.min(good.probability[rows[:2 * len(rows) // 3 + 1],
                                                   traj.holdings[h0].boom])) + 1e-12
    attach_u, attach_a = np.zeros(H), np.ones(H)
    h1 = next(h for h, hold in enumerate(traj.holdings) if hold.attach)
    attach_a[h1] = 0.0
    U, A = np.vstack([overload_u, attach_u]), np.vstack([overload_a, attach_a])
    vec = first_failures(good, U, A)
    assert vec.sample[0] <= target and vec.cause[0] == 1 and vec.holding[0] == h0
    assert vec.cause[1] == 2 and vec.holding[1] == h1
    assert vec.sample[1] == np.flatnonzero(good.phase == traj.holdings[h1].first)[0]
    for n in range(2):
        run = sim.run(traj, trial_draws(good, U[n], A[n]))
        f = run.failure
        assert f is not None, f"trial {n}: no failure in the diagram"
        hold = traj.holdings[vec.holding[n]]
        assert f.time == pytest.approx(good.times[vec.sample[n]], abs=1e-9), (n, f)
        assert (f.boom, f.anchor, f.cause) == (hold.boom, hold.anchor,
                                               ("overload", "attach")[vec.cause[n] - 1])
        assert run.times[-1] < good.times[-1], "the run must stop at the failure"


def test_monte_carlo_is_seeded_and_reproducible(good: SimulationRecord) -> None:
    a, b = monte_carlo(good, 500, 11), monte_carlo(good, 500, 11)
    assert a.successes == b.successes and a.failures == b.failures
    c = monte_carlo(good, 500, 12)
    assert [f.trial for f in c.failures] != [f.trial for f in a.failures]


def test_rate_agrees_with_p_path(good: SimulationRecord, good_plan: dict[str, Any]) -> None:
    res = monte_carlo(good, 4000, 3)
    lo, hi = res.ci95
    assert lo <= res.p_sim <= hi, f"p_sim {res.p_sim} outside [{lo}, {hi}]"
    assert lo <= good_plan["p_path"] <= hi, f"p_path {good_plan['p_path']} outside [{lo}, {hi}]"
    assert res.successes + len(res.failures) == res.trials


def test_near_zero_plan_fails_nearly_always(good: SimulationRecord,
                                            good_plan: dict[str, Any]) -> None:
    """attach_failure 0.99: p_path ~0.01. It enters only the draws, not the dynamics, so the
    same run serves (the record's plan is swapped for the changed one)."""
    plan = copy.deepcopy(good_plan)
    plan["robot"]["attach_failure"] = 0.99
    plan["p_path"] = path_probability(_configurations(plan), 0.99).p_path
    assert plan["p_path"] < 0.02
    scn = plan_scenario(plan)
    record = good._replace(plan=PlanTrajectory(plan, scn))
    res = monte_carlo(record, 2000, 0)
    assert res.rate < 0.03, f"rate {res.rate} for p_path {plan['p_path']}"
    assert res.ci95[0] <= res.p_sim <= res.ci95[1]
    causes = [f.cause for f in res.failures]
    assert causes.count("attach") > 0.9 * len(causes)


def test_failures_report_where_and_why(straight: SimulationRecord) -> None:
    res = monte_carlo(straight, 300, 1)
    assert res.ci95[1] < straight.plan.plan.p_path - 0.3, "the straight line should fail"
    U, A = draw_strengths(np.random.default_rng(1), 300, len(straight.plan.holdings))
    for f in res.failures:
        s = int(np.flatnonzero(np.isclose(straight.times, f.time, atol=1e-9))[0])
        h = int(np.flatnonzero([(x.boom, x.anchor) == (f.boom, f.anchor)
                                and x.first <= f.phase <= x.last
                                for x in straight.plan.holdings])[0])
        hold = straight.plan.holdings[h]
        assert straight.phase[s] == f.phase
        assert straight.plan.phases[f.phase].kind == f.kind
        assert straight.plan.phases[f.phase].stance.ids[f.boom] == f.anchor
        rows = np.flatnonzero((straight.phase >= hold.first) & (straight.phase <= hold.last))
        before = rows[rows < s]
        if f.cause == "overload":
            assert f.draw == U[f.trial, h] and straight.probability[s, f.boom] < f.draw
            assert np.all(straight.probability[before, f.boom] >= f.draw), "not the first"
            assert f.limit is not None and f.force > f.limit, f.describe()
        else:
            assert f.draw == A[f.trial, h] < straight.plan.scenario.robot.attach_failure
            assert s == rows[0] and hold.attach
    worst = res.failure_sites()[0]
    assert worst["count"] > 0.6 * len(res.failures), "failures concentrate where P collapses"
    assert (worst["phase"], worst["cause"]) == (2, "overload"), worst


# ---------------------------------------------------------------------------------------------
# Replanning


def _retry_then_stop(request: ReplanRequest) -> Plan | None:
    """A cheap fake replanner: re-grasp the failed anchor and finish the failed phase only."""
    plan = retry_replanner(request)
    if plan is not None:
        plan = plan.replace(phases=plan.phases[:2])
    return plan


def test_replanning_is_pluggable_and_counts_saved_climbs(good: SimulationRecord,
                                                         sim: ClimbSimulator) -> None:
    trials = 400
    base = monte_carlo(good, trials, 8)
    calls: list[ReplanRequest] = []

    def never(request: ReplanRequest) -> None:
        calls.append(request)
        return None

    none = monte_carlo(good, trials, 8, never, "never", sim)
    r = none.replanning
    assert r is not None and r.saved == 0 and r.successes == base.successes
    assert r.attempted == r.outcomes.get("no plan", 0) > 0
    assert len(calls) == r.replans <= r.attempted, "one call per distinct failure state"
    for req in calls:
        assert sum(a is None for a in req.stance) == 1 and req.stance[req.boom] is None
        assert req.plan.phases[req.phase].kind == "body"
    fake = monte_carlo(good, trials, 8, _retry_then_stop, "retry-then-stop", sim)
    r = fake.replanning
    assert fake.successes == base.successes and fake.failures == base.failures
    assert r.attempted > 0 and 0 < r.saved <= r.attempted
    assert r.successes == base.successes + r.saved
    assert r.saved + sum(r.outcomes.values()) == trials - base.successes


def test_replan_cache_key_is_the_plans_content(good: SimulationRecord,
                                               good_plan: dict[str, Any]) -> None:
    """monte_carlo caches replans by the plan's content (not by id(record), which Python reuses
    once a record is collected): equal plans share a key, an edited one does not."""
    scn = good.plan.scenario
    assert PlanTrajectory(copy.deepcopy(good_plan), scn).content_key == good.plan.content_key
    edited = copy.deepcopy(good_plan)
    edited["phases"][0]["steps"][-1]["t"] += 1.0
    for phase in edited["phases"][1:]:
        for step in phase["steps"]:
            step["t"] += 1.0
    assert PlanTrajectory(edited, scn).content_key != good.plan.content_key


def _failure_at_first_release(good: SimulationRecord) -> ReplanRequest:
    """The reaching boom's grasp fails at the end of the first body phase: the transition pose,
    which holds the 3-stance that frees that boom with its gripper on its old anchor."""
    plan = good.plan.plan
    s = int(np.flatnonzero(good.phase == 0)[-1])
    ids = good.plan.phases[0].stance.ids
    boom = plan.phases[1].free_boom
    assert boom is not None
    three = tuple(None if i == boom else a for i, a in enumerate(ids))
    return ReplanRequest(good.plan.scenario, plan, 0, float(good.times[s]),
                         good.state[s, :3].copy(), three, boom, ids[boom], "overload")


def test_retry_replanner_builds_a_continuing_plan(good: SimulationRecord) -> None:
    """From a failure in a body phase: re-grasp the same anchor where the body is, finish the
    phase, go on with the plan (times shifted). From a reach phase: nothing (two booms left)."""
    plan, scn = plan_dict(good.plan.plan), good.plan.scenario
    request = _failure_at_first_release(good)
    ids, boom = good.plan.phases[0].stance.ids, request.boom
    continued = retry_replanner(request)
    assert continued is not None, "the 3-stance holds here: retrying must give a plan"
    new = plan_dict(continued)
    validate(new)
    first, second = new["phases"][:2]
    assert first["kind"] == "reach" and first["free_boom"] == boom
    assert first["from_anchor"] == first["to_anchor"] == ids[boom]
    np.testing.assert_allclose(first["steps"][0]["pose"], request.pose, atol=1e-12)
    assert first["steps"][0]["t"] == 0.0 and second["stance"] == list(ids)
    np.testing.assert_allclose(second["steps"][-1]["pose"], plan["phases"][0]["steps"][-1]["pose"])
    rest = new["phases"][2:]
    assert [p["stance"] for p in rest] == [p["stance"] for p in plan["phases"][1:]]
    shift = rest[0]["steps"][0]["t"] - plan["phases"][1]["steps"][0]["t"]
    for a, b in zip(rest, plan["phases"][1:], strict=True):
        assert [x["t"] - shift for x in a["steps"]] == pytest.approx([x["t"] for x in b["steps"]])
    PlanTrajectory(new, scn)  # times continuous, anchors known
    k = next(k for k, p in enumerate(good.plan.phases) if p.kind == "reach")
    held = next(i for i, a in enumerate(good.plan.phases[k].stance.ids) if a is not None)
    reach = request._replace(phase=k, boom=held, stance=tuple(
        None if i == held else a for i, a in enumerate(good.plan.phases[k].stance.ids)))
    assert retry_replanner(reach) is None


def test_footstep_replanner_continues_with_a_full_verified_plan(good: SimulationRecord) -> None:
    """The real replanner (no stand-in): boom j's grasp fails at the end of the first body
    phase; the continuation moves j to another anchor from where the body is, then the whole
    pipeline plans on to the goal. Every configuration must pass `rbp check`'s verifier, with
    tensions on every step, and the climb must end within the goal tolerance."""
    from planning.check import check_plan

    scn = good.plan.scenario
    request = _failure_at_first_release(good)
    ids, boom = good.plan.phases[0].stance.ids, request.boom
    continued = FootstepReplanner()(request)
    assert continued is not None, "the 3-stance holds here and the shaft is short: expected a plan"
    new = plan_dict(continued)
    validate(new)
    first = new["phases"][0]
    assert first["kind"] == "reach" and first["free_boom"] == boom
    assert first["from_anchor"] == ids[boom] and first["to_anchor"] != ids[boom], first
    np.testing.assert_allclose(first["steps"][0]["pose"], request.pose, atol=1e-12)
    problems = check_plan(new)
    assert problems == [], f"the continuation fails the verifier: {problems[:5]}"
    body = [p for p in new["phases"][1:] if p["kind"] == "body"]
    assert body and all(len(p["steps"]) > 2 for p in body), (
        "body phases should carry trajectories, not only their end poses")
    end = np.asarray(new["phases"][-1]["steps"][-1]["pose"])[:2]
    gap = float(np.linalg.norm(end - np.asarray(scn.goal_position)))
    assert gap <= scn.goal_tolerance + 1e-9, f"the climb ends {gap:.2f} m from the goal"
    times = [st["t"] for p in new["phases"] for st in p["steps"]]
    assert times[0] == 0.0 and np.all(np.diff(times) >= 0.0), "times must start at 0 and grow"
    PlanTrajectory(new, scn)  # the simulation can run it


# ---------------------------------------------------------------------------------------------
# The command line


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rbp")
    add_simulate_command(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["simulate", *argv])


def _short_plan(plan: dict[str, Any]) -> dict[str, Any]:
    """The first body phase alone (a 5 s run): a valid plan for the command-line tests, its
    goal where that phase ends (`rbp simulate` verifies the plan first)."""
    short = copy.deepcopy(plan)
    short["phases"] = short["phases"][:1]
    # no reach follows: its release ramp goes too
    short["phases"][0]["steps"] = [s for s in short["phases"][0]["steps"] if "ramp" not in s]
    short["scenario"]["goal"]["position"] = short["phases"][0]["steps"][-1]["pose"][:2]
    prob = path_probability(_configurations(short), short["robot"]["attach_failure"])
    short["p_path"], short["p_min"], short["regrasps"] = prob.p_path, prob.p_min, prob.regrasps
    validate(short)
    return short


def test_cli_writes_json(good_plan: dict[str, Any], tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(_short_plan(good_plan)))
    out = tmp_path / "sim" / "result.json"
    assert cmd_simulate(_args(str(path), "--trials", "300", "--seed", "4",
                              "--json", str(out))) == 0
    data = json.loads(out.read_text())
    for field in ("trials", "successes", "rate", "ci95", "p_path", "p_sim"):
        assert field in data, f"{field} missing from {sorted(data)}"
    assert data["trials"] == 300 and data["rate"] == data["successes"] / 300
    assert data["ci95"][0] <= data["rate"] <= data["ci95"][1]
    assert data["ci95"][0] <= data["p_path"] <= data["ci95"][1]
    text = capsys.readouterr().out
    assert "95% CI" in text and "p_path" in text and "tracking error" in text
    assert [p.name for p in out.parent.iterdir()] == ["result.json"], "temporary files left"


@pytest.mark.parametrize("content, field", [
    (None, "(file)"),
    ("{ not json", "line 1, column 3"),  # a syntax error names its place
    ('{"format": "reachbot-plan/1"}', "(top level)"),
])
def test_cli_user_errors_name_file_and_field(tmp_path: Path, good_plan: dict[str, Any],
                                             content: str | None, field: str) -> None:
    from rbp.commands.common import UserError

    path = tmp_path / "plan.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(UserError) as err:
        cmd_simulate(_args(str(path)))
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: {field}:"), message


@pytest.mark.parametrize("verify", [True, False])
def test_cli_refuses_a_wrong_plan_before_simulating(
        good_plan: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str], verify: bool) -> None:
    """A plan that fails `rbp check` is refused (exit 1, the verifier's problems on stderr)
    before any simulator is built; --no-verify skips the check and says so on stderr."""
    import systems.diagram

    bad = _short_plan(good_plan)
    bad["phases"][0]["steps"][1]["p_grasp"][0] = 0.5
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(bad))

    class BuiltError(Exception):
        pass

    def no_simulator(*_args, **_kwargs):
        raise BuiltError

    monkeypatch.setattr(systems.diagram, "ClimbSimulator", no_simulator)
    if verify:
        assert cmd_simulate(_args(str(path), "--trials", "0")) == 1
        err = capsys.readouterr().err
        assert ": recorded-value: p_grasp[0] 0.5" in err and "phases[0] (body) step 1" in err, err
    else:
        with pytest.raises(BuiltError):
            cmd_simulate(_args(str(path), "--trials", "0", "--no-verify"))
        assert "WARNING" in capsys.readouterr().err


def test_cli_rejects_negative_trials(tmp_path: Path) -> None:
    from rbp.commands.common import UserError

    with pytest.raises(UserError, match="--trials"):
        cmd_simulate(_args(str(tmp_path / "plan.json"), "--trials", "-1"))


@pytest.mark.parametrize("change, field", [
    (lambda p: p["phases"][0]["steps"][1].update(t=-1.0), "phases[0].steps[1].t"),
    (lambda p: p["phases"][1]["stance"].__setitem__(2, "nowhere"), "phases[1].stance"),
    (lambda p: p["phases"][2]["steps"][0].update(t=p["phases"][2]["steps"][0]["t"] + 0.25),
     "phases[2].steps[0].t"),
    (lambda p: p["phases"][0]["steps"][0]["tension"].__setitem__(1, None),
     "phases[0].steps[0].tension[1]"),
])
def test_plan_errors_name_the_field(good_plan: dict[str, Any], change, field: str) -> None:
    from systems.trajectory import PlanError

    plan = copy.deepcopy(good_plan)
    change(plan)
    with pytest.raises(PlanError) as err:
        PlanTrajectory(plan, plan_scenario(plan))
    assert err.value.field == field, str(err.value)


# ---------------------------------------------------------------------------------------------
# Release and attach


def test_grippers_open_and_close_only_on_slack_booms(good: SimulationRecord) -> None:
    """Executing a plan with ramps: the freed boom's tension on the last sample before its
    gripper opens and on the first after it closes is below RELEASE_TENSION, and during the
    ramps the ramped grasp's load (the monitor's, less the limb's weight its shoulder holds) is
    its boom's tension."""
    traj = good.plan
    assert good.failure is None, good.failure
    checked = 0
    for phase in traj.phases:
        j = phase.stance.free_boom
        if j is None:
            continue
        before = np.flatnonzero(good.times < phase.start - 1e-9)[-1]
        after = np.flatnonzero(good.times > phase.end + 1e-9)[0]
        for s, what in ((before, "opens"), (after, "closes")):
            assert good.tension[s, j] <= RELEASE_TENSION, (
                f"t={good.times[s]}: boom {j} pulls {good.tension[s, j]} N as its gripper {what}")
        checked += 1
    assert checked == traj.regrasps
    for phase in traj.phases:
        for t0, t1, j in phase.ramps:
            rows = np.flatnonzero((good.times > t0 + 1e-9) & (good.times < t1 - 1e-9))
            assert len(rows) > 10
            np.testing.assert_allclose(good.force[rows, j], good.tension[rows, j], atol=0.02,
                                       err_msg=f"ramp of boom {j} over [{t0}, {t1}]")


def test_a_plan_without_its_release_ramp_stops_there(good_plan: dict[str, Any],
                                                     sim: ClimbSimulator) -> None:
    """The release ramp taken out (plan_faults.ramp_removed): the gripper would open on a boom
    still pulling, so it stays shut, the run stops with a `handover` failure at that phase and
    no Monte Carlo climb gets past it."""
    from planning.plan_faults import ramp_removed

    fault = next(f for f in (ramp_removed(good_plan, np.random.default_rng(seed))
                             for seed in range(20))
                 if "release" in f.what)
    traj = PlanTrajectory(fault.plan, plan_scenario(fault.plan))
    record = sim.run(traj)
    failure = record.failure
    assert failure is not None and failure.cause == "handover", failure
    j = traj.phases[fault.phase + 1].stance.free_boom
    assert (failure.phase, failure.boom) == (fault.phase, j), failure
    assert failure.draw > RELEASE_TENSION, f"its boom pulled {failure.draw} N"
    assert record.times[-1] <= traj.phases[fault.phase].end + 1e-9
    assert record.implied_p_path() == 0.0
    mc = monte_carlo(record, 200, 3)
    assert mc.successes == 0 and mc.to_json()["failures"]["handover"] > 0, mc.to_json()["failures"]


def test_rest_to_rest_grid_scales_with_steps_not_duration() -> None:
    """A plan's times may reach 1e7 s: a grid every 0.05 s of such an interval asked 8.9 million
    points per phase (`rbp simulate` failed to allocate; `rbp check` took 9 GB)."""
    from planning.smooth_motion import MAX_GRID

    t, s, _ = rest_to_rest(0.0, 1e7, 0.05)
    assert len(t) == MAX_GRID + 1 and t[-1] == 1e7 and s[-1] == pytest.approx(1.0, abs=1e-15)
    assert np.all(np.diff(s) > 0)
    assert len(rest_to_rest(2.0, 7.0, 0.05)[0]) == 101  # a short interval keeps its 0.05 s grid
