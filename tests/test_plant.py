"""The Drake plant of ReachBot against the hand-written kinematics in rb_drake.geometry."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from rb_drake import geometry
from rb_drake.params import RobotParams, robot_from_dict
from rb_drake.plant import ARM_MASS, MIN_MASS, build_plant, robot_urdf

GRAVITY = (0.0, -3.71)


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
        rb.plant.SetPositions(ctx, rb.q_from(pose, th, L))
        got = rb.tip_positions(ctx)
        want = geometry.tip_positions(robot, pose, th, L)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12,
                                   err_msg=f"config {k}: plant FK != geometry.tip_positions")


def test_q_from_uses_position_start(rb):
    pose, th, L = [1.0, 2.0, 0.3], [0.1, 0.2, 0.3, 0.4], [1.1, 1.2, 1.3, 1.4]
    q = rb.q_from(pose, th, L)
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
        plant.SetPositions(ctx, rb.q_from(pose, th, L))
        J_plant = [rb.tip_jacobian(ctx, b) for b in range(4)]
        # central differences of the plant's FK, in canonical q order
        J_fd = np.zeros((4, 2, 11))
        for j in range(11):
            dq = np.zeros(11)
            dq[j] = h
            for sign in (1.0, -1.0):
                q = qc + sign * dq
                plant.SetPositions(ctx, rb.q_from(q[:3], q[3::2], q[4::2]))
                J_fd[:, :, j] += sign * rb.tip_positions(ctx) / (2 * h)
        for b in range(4):
            J_geo = geometry.tip_jacobian(robot, pose, th, L, b)
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
        rb2.plant.SetPositions(ctx, rb2.q_from(pose, th, L))
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
        plant.SetPositions(ctx, rb.q_from(pose, th, L))
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
