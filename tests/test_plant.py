"""The Drake plant of ReachBot against the hand-written kinematics in rb_drake.geometry."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import DiscreteContactApproximation
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from rb_drake import geometry
from rb_drake.params import RobotParams, robot_from_dict
from rb_drake.plant import ARM_MASS, MIN_MASS, ReachBotPlant, build_plant, robot_urdf

GRAVITY = (0.0, -3.71)


# What the plant and geometry would offer only to these tests, so kept here: Drake's q from the
# canonical joint values, and the tips' Jacobians from the plant and by hand.

def q_from(rb: ReachBotPlant, pose, shoulder_angles, lengths) -> np.ndarray:
    """Drake's q vector for pose (x, y, phi), shoulder angles (4,) and boom lengths (4,)."""
    q = np.zeros(rb.plant.num_positions())
    q[rb.q_order] = rb.canonical_q(pose, shoulder_angles, lengths)
    return q


def plant_tip_jacobian(rb: ReachBotPlant, context, boom: int) -> np.ndarray:
    """d tip_boom / d q (x-y rows), columns in the canonical q order, shape (2, nq)."""
    world = rb.plant.world_frame()
    J = rb.plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kQDot, rb.tips[boom].body_frame(), np.zeros(3),
        world, world)
    return J[:2, rb.q_order]


def geometry_tip_jacobian(robot: RobotParams, pose: np.ndarray, shoulder_angles: np.ndarray,
                          lengths: np.ndarray, boom: int) -> np.ndarray:
    """d tip / d q, q = [x, y, phi, theta_0, L_0, ..., theta_3, L_3] (Drake's order): (2, 11)."""
    pose = np.asarray(pose, dtype=float)
    a = pose[2] + robot.shoulder_directions[boom] + shoulder_angles[boom]
    e = np.array([np.cos(a), np.sin(a)])
    r = geometry.shoulder_offsets(robot, pose)[0, boom]
    J = np.zeros((2, 11))
    J[:, 0] = [1.0, 0.0]
    J[:, 1] = [0.0, 1.0]
    J[:, 2] = geometry.perp(r) + lengths[boom] * geometry.perp(e)
    J[:, 3 + 2 * boom] = lengths[boom] * geometry.perp(e)
    J[:, 4 + 2 * boom] = e
    return J


@pytest.fixture(scope="module")
def robot() -> RobotParams:
    return RobotParams()


@pytest.fixture(scope="module")
def rb(robot):
    return build_plant(robot, GRAVITY)


def random_configs(robot: RobotParams, n: int, seed: int):
    """n random (pose, shoulder_angles, lengths) within the joint limits."""
    rng = np.random.default_rng(seed)
    lo, hi = robot.boom_length
    r = robot.shoulder_range
    for _ in range(n):
        pose = np.array([*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi)])
        yield pose, rng.uniform(-r, r, 4), rng.uniform(lo, hi, 4)


def test_joint_names_and_count(rb):
    plant = rb.plant
    names = [plant.get_joint(j).name() for j in plant.GetJointIndices(rb.model)]
    expected = ["base"] + [f"{kind}{i}" for i in range(4) for kind in ("shoulder", "boom")]
    assert sorted(names) == sorted(expected), f"joints {names}, expected {expected}"
    assert plant.num_joints() == 9, f"num_joints {plant.num_joints()}"
    assert plant.num_positions() == 11 and plant.num_velocities() == 11
    assert rb.base.type_name() == "planar"
    assert [j.type_name() for j in rb.shoulders] == ["revolute"] * 4
    assert [j.type_name() for j in rb.booms] == ["prismatic"] * 4
    assert sorted(rb.q_order.tolist()) == list(range(11)), f"q_order {rb.q_order}"


def test_default_positions_within_limits(rb):
    plant = rb.plant
    q0 = plant.GetDefaultPositions()
    lo, hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    assert np.all((lo <= q0) & (q0 <= hi)), f"default q {q0} outside [{lo}, {hi}]"


def test_tip_positions_match_geometry(robot, rb):
    ctx = rb.plant.CreateDefaultContext()
    for k, (pose, th, L) in enumerate(random_configs(robot, 20, seed=1)):
        rb.plant.SetPositions(ctx, q_from(rb, pose, th, L))
        got = rb.tip_positions(ctx)
        want = geometry.tip_positions(robot, pose, th, L)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12,
                                   err_msg=f"config {k}: plant FK != geometry.tip_positions")


def test_q_from_uses_position_start(rb):
    pose, th, L = [1.0, 2.0, 0.3], [0.1, 0.2, 0.3, 0.4], [1.1, 1.2, 1.3, 1.4]
    q = q_from(rb, pose, th, L)
    s = rb.base.position_start()
    assert q[s:s + 3].tolist() == pose, f"base q {q[s:s + 3]}"
    for i in range(4):
        assert q[rb.shoulders[i].position_start()] == th[i], f"shoulder{i} in q {q}"
        assert q[rb.booms[i].position_start()] == L[i], f"boom{i} in q {q}"


def test_tip_jacobian_matches_geometry_and_finite_differences(robot, rb):
    plant = rb.plant
    ctx = plant.CreateDefaultContext()
    h = 1e-6
    for k, (pose, th, L) in enumerate(random_configs(robot, 20, seed=2)):
        qc = rb.canonical_q(pose, th, L)
        plant.SetPositions(ctx, q_from(rb, pose, th, L))
        J_plant = [plant_tip_jacobian(rb, ctx, b) for b in range(4)]
        # central differences of the plant's FK, in canonical q order
        J_fd = np.zeros((4, 2, 11))
        for j in range(11):
            dq = np.zeros(11)
            dq[j] = h
            for sign in (1.0, -1.0):
                q = qc + sign * dq
                plant.SetPositions(ctx, q_from(rb, q[:3], q[3::2], q[4::2]))
                J_fd[:, :, j] += sign * rb.tip_positions(ctx) / (2 * h)
        for b in range(4):
            J_geo = geometry_tip_jacobian(robot, pose, th, L, b)
            np.testing.assert_allclose(J_plant[b], J_geo, rtol=0, atol=1e-10,
                                       err_msg=f"config {k} boom {b}: plant J != geometry J")
            np.testing.assert_allclose(J_plant[b], J_fd[b], rtol=0, atol=1e-6,
                                       err_msg=f"config {k} boom {b}: plant J != finite diff")
            np.testing.assert_allclose(J_geo, J_fd[b], rtol=0, atol=1e-6,
                                       err_msg=f"config {k} boom {b}: geometry J != finite diff")


def test_overrides_change_the_plant(robot, rb):
    other = robot_from_dict({
        "body_mass": 5.0,
        "gripper_mass": 0.25,
        "shoulders": [[0.2, 0.1], [-0.2, 0.1], [-0.2, -0.1], [0.2, -0.1]],
        "shoulder_range_deg": 30.0,
        "boom_length": [0.05, 3.0],
    })
    rb2 = build_plant(other, GRAVITY)
    assert robot_urdf(other) != robot_urdf(robot)
    m_default = rb.plant.CalcTotalMass(rb.plant.CreateDefaultContext())
    m_other = rb2.plant.CalcTotalMass(rb2.plant.CreateDefaultContext())
    assert m_default == pytest.approx(2.0 + 4 * (ARM_MASS + 0.10), abs=1e-12), m_default
    assert m_other == pytest.approx(5.0 + 4 * (ARM_MASS + 0.25), abs=1e-12), m_other
    for i in range(4):
        boom, sh = rb2.booms[i], rb2.shoulders[i]
        assert boom.position_upper_limits()[0] == pytest.approx(3.0, abs=1e-15)
        assert boom.position_lower_limits()[0] == pytest.approx(0.05, abs=1e-15)
        assert sh.position_upper_limits()[0] == pytest.approx(np.radians(30.0), abs=1e-15)
        assert sh.position_lower_limits()[0] == pytest.approx(-np.radians(30.0), abs=1e-15)
        assert rb.booms[i].position_upper_limits()[0] == pytest.approx(2.0, abs=1e-15)
        assert boom.get_default_translation() == pytest.approx(1.525, abs=1e-12)
    # the new shoulders show up in the FK
    ctx = rb2.plant.CreateDefaultContext()
    for k, (pose, th, L) in enumerate(random_configs(other, 5, seed=3)):
        rb2.plant.SetPositions(ctx, q_from(rb2, pose, th, L))
        np.testing.assert_allclose(rb2.tip_positions(ctx),
                                   geometry.tip_positions(other, pose, th, L), rtol=0, atol=1e-12,
                                   err_msg=f"config {k}: overridden plant FK != geometry")


def test_zero_gripper_mass_is_replaced_by_a_tiny_mass(robot):
    rb0 = build_plant(robot.replace(gripper_mass=0.0))
    m = rb0.plant.CalcTotalMass(rb0.plant.CreateDefaultContext())
    assert m == pytest.approx(robot.body_mass + 4 * (ARM_MASS + MIN_MASS), abs=1e-12), m


@pytest.mark.parametrize("gravity", [(0.0, -3.71), (0.0, -9.81), (1.2, -2.5)])
def test_gravity_generalized_forces(robot, gravity):
    rb = build_plant(robot, gravity)
    plant = rb.plant
    ctx = plant.CreateDefaultContext()
    m_tot = plant.CalcTotalMass(ctx)
    for k, (pose, th, L) in enumerate(random_configs(robot, 10, seed=4)):
        plant.SetPositions(ctx, q_from(rb, pose, th, L))
        v0 = rb.base.velocity_start()  # planar joint: v = (xdot, ydot, phidot)
        tau = plant.CalcGravityGeneralizedForces(ctx)[v0:v0 + 2]
        np.testing.assert_allclose(tau, m_tot * np.asarray(gravity), rtol=0, atol=1e-9,
                                   err_msg=f"gravity {gravity} config {k}: base force")


def test_builder_adds_scene_graph(robot):
    builder = DiagramBuilder()
    rb = build_plant(robot, GRAVITY, time_step=1e-3, builder=builder)
    assert rb.scene_graph is not None
    assert rb.plant.is_finalized() and rb.plant.time_step() == 1e-3
    builder.Build()
    standalone = build_plant(robot)
    assert standalone.scene_graph is None and standalone.plant.is_finalized()


# ---------------------------------------------------------------------------------------------
# Tips held at anchors (the simulation's plant)


@pytest.fixture(scope="module")
def held(robot):
    return build_plant(robot, GRAVITY, time_step=1e-2, hold_tips=True)


def test_hold_tips_adds_anchor_bodies_and_ball_constraints(robot, held):
    plant = held.plant
    assert plant.num_constraints() == 4 and len(held.holds) == 4 and len(held.anchors) == 4
    assert plant.get_discrete_contact_approximation() == DiscreteContactApproximation.kSap
    assert plant.num_positions() == 11 + 4 * 3, "each anchor body on a planar joint"
    ctx = plant.CreateDefaultContext()
    # the default context is consistent: every tip held where the default configuration has it
    for i, tip in enumerate(held.tip_positions(ctx)):
        np.testing.assert_allclose(held.anchors[i].get_translation(ctx), tip, atol=1e-12,
                                   err_msg=f"default anchor {i}")
    anchors = [[1.5, 1.5], None, [-1.5, -1.5], [1.5, -1.5]]
    held.hold_tips(ctx, anchors)
    for i, anchor in enumerate(anchors):
        assert plant.GetConstraintActiveStatus(ctx, held.holds[i]) == (anchor is not None)
        assert held.anchors[i].is_locked(ctx), f"anchor {i} must stay locked"
        if anchor is not None:
            np.testing.assert_allclose(held.anchors[i].get_translation(ctx), anchor, atol=0)
    with pytest.raises(ValueError, match="hold_tips"):
        build_plant(robot, GRAVITY).hold_tips(ctx, anchors)
    with pytest.raises(ValueError, match="discrete"):
        build_plant(robot, GRAVITY, hold_tips=True)


def test_held_tips_stay_on_their_anchors_while_the_body_falls(robot, held):
    """No tensions: the body falls on its passive joints, the held tips do not move (SAP
    ball constraints, 10 ms steps: within 1 mm through the booms' stops), the free tip falls
    with the body."""
    plant = held.plant
    simulator = Simulator(plant)
    ctx = simulator.get_mutable_context()
    pose = np.array([0.0, 0.0, 0.1])
    tips = geometry.tip_positions(robot, pose, np.zeros(4), np.full(4, 1.0))
    held.hold_tips(ctx, [tips[0], tips[1], tips[2], None])
    q = plant.GetPositions(ctx)
    q[held.q_order] = held.canonical_q(pose, np.zeros(4), np.full(4, 1.0))
    plant.SetPositions(ctx, q)
    plant.get_applied_generalized_force_input_port().FixValue(
        ctx, np.zeros(plant.num_velocities()))
    simulator.AdvanceTo(0.5)
    now = held.tip_positions(ctx)
    moved = np.linalg.norm(plant.GetPositions(ctx)[held.base.position_start():][:2] - pose[:2])
    assert moved > 0.05, f"the body should fall, moved {moved}"
    np.testing.assert_allclose(now[:3], tips[:3], atol=1e-3, err_msg="held tips moved")
    assert np.linalg.norm(now[3] - tips[3]) > 0.05, "the free tip should fall"


def test_boom_masses_weigh_like_the_free_limb_of_the_model(robot, held):
    """Half of a boom's mass at its tip and half at its shoulder: its weight, its moment about
    the shoulder and about the body centre are those of geometry.limb_load's uniform boom."""
    plant = held.plant
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(6)
    bare = robot.replace(gripper_mass=0.0)  # limb_load's boom part alone
    for k, (pose, th, L) in enumerate(random_configs(robot, 6, seed=7)):
        q = plant.GetPositions(ctx)
        q[held.q_order] = held.canonical_q(pose, th, L)
        plant.SetPositions(ctx, q)
        boom = int(rng.integers(4))
        masses = np.zeros(4)
        masses[boom] = robot.boom_linear_density * L[boom]
        held.set_boom_masses(ctx, np.zeros(4))
        before = plant.CalcGravityGeneralizedForces(ctx)
        held.set_boom_masses(ctx, masses)
        delta = plant.CalcGravityGeneralizedForces(ctx) - before
        tip = geometry.tip_positions(robot, pose, th, L)[boom]
        want = geometry.limb_load(bare, pose, boom, tip, np.asarray(GRAVITY))
        v0 = held.base.velocity_start()
        np.testing.assert_allclose(delta[v0:v0 + 2], want.force[0], atol=1e-12,
                                   err_msg=f"config {k}: weight")
        assert delta[v0 + 2] == pytest.approx(want.moment[0], abs=1e-12), f"config {k}: moment"
        shoulder = delta[held.shoulders[boom].velocity_start()]
        assert shoulder == pytest.approx(want.shoulder_torque[0], abs=1e-12), f"config {k}"
        assert held.tips[boom].get_mass(ctx) == pytest.approx(
            robot.gripper_mass + 0.5 * masses[boom], abs=1e-15)


def test_plant_options_limits_and_live_outputs(robot):
    free = build_plant(robot, GRAVITY, time_step=1e-2, hold_tips=True, live_outputs=True,
                       joint_limits=False)
    for joint in (*free.shoulders, *free.booms):
        assert joint.position_lower_limits()[0] == -np.inf, joint.name()
        assert joint.position_upper_limits()[0] == np.inf, joint.name()
    # live outputs: the reaction forces of a fresh context (5 N in each held boom); sampled
    # ones (Drake's default) read zero until the first step
    for rb, live in ((free, True), (build_plant(robot, GRAVITY, 1e-2, hold_tips=True), False)):
        ctx = rb.plant.CreateDefaultContext()
        rb.hold_tips(ctx, rb.tip_positions(ctx))
        u = np.zeros(rb.plant.num_velocities())
        u[[b.velocity_start() for b in rb.booms]] = -5.0
        rb.plant.get_applied_generalized_force_input_port().FixValue(ctx, u)
        reactions = rb.plant.get_reaction_forces_output_port().Eval(ctx)
        axial = np.array([reactions[b.index()].translational()[0] for b in rb.booms])
        want = -5.0 if live else 0.0
        np.testing.assert_allclose(axial, want, atol=0.05, err_msg=f"live={live}")


def test_lightest_body_keeps_a_positive_inertia_in_the_simulator(tmp_path) -> None:
    """The simulator's body carries the four shoulder links (ARM_MASS each) out of the
    robot's body_mass: the least body_mass a scenario may give leaves it most of its mass
    (a body of 0.03 kg was simulated with negative inertia, Drake warning in 8 lines), and a
    lighter one is refused at reading."""
    from rb_drake.params import MIN_BODY_MASS, NUM_BOOMS, ParamError

    assert MIN_BODY_MASS - NUM_BOOMS * ARM_MASS >= 0.5 * MIN_BODY_MASS, \
        "the simulator's body would keep under half the lightest body's mass"
    with pytest.raises(ParamError, match=r"body_mass.*must be >= 0\.1, got 0\.03"):
        robot_from_dict({"body_mass": 0.03})
