"""Vectorised planar geometry: shoulders, angle conventions, Jacobians, free-limb loads."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rb_drake import geometry
from rb_drake.params import RobotParams


def test_shoulder_positions_rotated_pose_by_hand(robot):
    # Pose (1, 2, 30 deg): p_i = (1, 2) + R(30) s_i with c = cos 30 = sqrt(3)/2, s = sin 30 = 1/2.
    c, s = math.sqrt(3.0) / 2.0, 0.5
    a = 0.15
    want = np.array([
        [1.0 + a * c - a * s, 2.0 + a * s + a * c],   # s_0 = ( a,  a)
        [1.0 - a * c - a * s, 2.0 - a * s + a * c],   # s_1 = (-a,  a)
        [1.0 - a * c + a * s, 2.0 - a * s - a * c],   # s_2 = (-a, -a)
        [1.0 + a * c + a * s, 2.0 + a * s - a * c],   # s_3 = ( a, -a)
    ])
    # Numerically: s_0 -> (1.054904, 2.204904), s_2 -> (0.945096, 1.795096).
    assert want[0] == pytest.approx([1.0549038105676658, 2.2049038105676658], abs=1e-12)
    got = geometry.shoulder_positions(robot, np.array([1.0, 2.0, math.pi / 6]))
    assert got.shape == (1, 4, 2), f"shape {got.shape}, expected (1, 4, 2)"
    np.testing.assert_allclose(got[0], want, atol=1e-12,
                               err_msg="shoulders of pose (1, 2, 30 deg) against R(phi) s_i")


def test_shoulder_positions_quarter_turn(robot):
    # A quarter turn maps (x, y) -> (-y, x): s_0 (0.15, 0.15) -> (-0.15, 0.15), and so on.
    got = geometry.shoulder_positions(robot, np.array([1.0, 2.0, math.pi / 2]))[0]
    want = np.array([[0.85, 2.15], [0.85, 1.85], [1.15, 1.85], [1.15, 2.15]])
    np.testing.assert_allclose(got, want, atol=1e-12, err_msg="shoulders after a +90 deg turn")
    corners = geometry.body_corners(robot, np.array([1.0, 2.0, math.pi / 2]))[0]
    area = 0.5 * np.sum(corners[:, 0] * np.roll(corners[:, 1], -1)
                        - np.roll(corners[:, 0], -1) * corners[:, 1])
    assert area == pytest.approx(0.09, abs=1e-12), (
        f"body corners must be counter-clockwise with area 0.3 * 0.3, signed area {area}")


def test_shoulder_and_pull_angle_signs(robot):
    """Boom 0 of the body at the origin (shoulder (0.15, 0.15), equilibrium direction 45 deg)."""
    pose = np.zeros(3)
    sh = np.array([0.15, 0.15])
    normal = np.array([-1.0, 0.0])  # a wall on the right, facing the robot
    cases = [
        # (boom direction, shoulder angle, pull angle): both counter-clockwise positive.
        ((1.0, 0.0), -math.pi / 4, 0.0),                       # along +x: 45 deg clockwise
        ((0.5, 1.0), math.atan(2.0) - math.pi / 4, math.atan(2.0)),  # +18.4 deg, +63.4 deg
        ((1.0, 1.0), 0.0, +math.pi / 4),                       # along the equilibrium direction
        ((1.0, -1.0), -math.pi / 2, -math.pi / 4),
    ]
    for direction, theta_want, psi_want in cases:
        target = sh + np.array(direction)
        targets = np.tile(target, (4, 1))
        geo = geometry.boom_geometry(robot, pose, targets)
        theta = float(geo.shoulder_angle[0, 0])
        assert theta == pytest.approx(theta_want, abs=1e-12), (
            f"shoulder angle toward {target}: {theta}, expected {theta_want}")
        psi = float(geometry.pull_angles(geo.u, np.tile(normal, (4, 1)))[0, 0])
        # The grasp is pulled along anchor -> shoulder, i.e. -(target - shoulder).
        assert psi == pytest.approx(psi_want, abs=1e-12), (
            f"pull angle for anchor {target} with normal {normal}: {psi}, expected {psi_want}")
    # Rotating the body by phi subtracts phi from the shoulder angle.
    geo = geometry.boom_geometry(robot, np.array([0.0, 0.0, 0.1]), np.tile(sh + 5.0, (4, 1)))
    r0 = geometry.shoulder_positions(robot, np.array([0.0, 0.0, 0.1]))[0, 0]
    d = sh + 5.0 - r0
    want = math.atan2(d[1], d[0]) - 0.1 - math.pi / 4
    assert float(geo.shoulder_angle[0, 0]) == pytest.approx(want, abs=1e-12), (
        "shoulder angle of a rotated body: atan2(d) - phi - 45 deg")


def test_boom_geometry_lengths_and_units(robot, start_stance, start_pose):
    geo = geometry.boom_geometry(robot, start_pose, start_stance.positions)
    # Boom 0: shoulder (0.15, 1.15) -> a0 (1.2, 2.0): d = (1.05, 0.85), |d| = sqrt(1.825).
    assert float(geo.length[0, 0]) == pytest.approx(math.sqrt(1.05**2 + 0.85**2), abs=1e-12)
    np.testing.assert_allclose(np.linalg.norm(geo.u, axis=-1), 1.0, atol=1e-14,
                               err_msg="boom directions must be unit vectors")
    np.testing.assert_allclose(geo.d, geo.length[..., None] * geo.u, atol=1e-14,
                               err_msg="d = length * u")


def _random_poses(rng, n):
    return np.column_stack([rng.uniform(-0.5, 0.5, n), rng.uniform(0.6, 1.6, n),
                            rng.uniform(-0.6, 0.6, n)])


def test_pose_jacobians_finite_difference(robot, start_stance, rng):
    poses = _random_poses(rng, 25)
    targets = start_stance.positions
    normals = start_stance.normals
    jac = geometry.pose_jacobians(robot, poses, targets)
    h = 1e-6

    def quantities(p):
        geo = geometry.boom_geometry(robot, p, targets)
        return geo.length, geo.shoulder_angle, geometry.pull_angles(geo.u, normals)

    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus, minus = quantities(poses + step), quantities(poses - step)
        fd_len = (plus[0] - minus[0]) / (2 * h)
        fd_theta = geometry.wrap_angle(plus[1] - minus[1]) / (2 * h)
        fd_psi = geometry.wrap_angle(plus[2] - minus[2]) / (2 * h)
        name = "xyz"[k] if k < 2 else "phi"
        np.testing.assert_allclose(jac.length[..., k], fd_len, atol=1e-6,
                                   err_msg=f"d length / d {name} vs central difference")
        np.testing.assert_allclose(jac.shoulder_angle[..., k], fd_theta, atol=1e-6,
                                   err_msg=f"d shoulder angle / d {name} vs central difference")
        np.testing.assert_allclose(jac.pull_angle[..., k], fd_psi, atol=1e-6,
                                   err_msg=f"d pull angle / d {name} vs central difference")


def test_limb_load_horizontal_free_boom(robot, gravity):
    # Body at (0, 1, 0); boom 0's shoulder is (0.15, 1.15); the free boom lies horizontal, 1 m
    # long, gripper at (1.15, 1.15). Boom mass 0.12 kg/m * 1 m at (0.65, 1.15), gripper 0.1 kg.
    pose = np.array([0.0, 1.0, 0.0])
    tip = np.array([1.15, 1.15])
    g = 3.71
    load = geometry.limb_load(robot, pose, 0, tip, gravity)
    # Weight: (0.12 + 0.10) * (0, -3.71) = (0, -0.8162) N.
    np.testing.assert_allclose(load.force[0], [0.0, -0.8162], atol=1e-12,
                               err_msg="free limb weight (0, -(m_boom + m_grip) g)")
    # Moment about the body centre: -g (0.12 * 0.65 + 0.10 * 1.15) = -3.71 * 0.193 = -0.71603.
    assert float(load.moment[0]) == pytest.approx(-g * (0.12 * 0.65 + 0.10 * 1.15), abs=1e-12)
    assert float(load.moment[0]) == pytest.approx(-0.71603, abs=1e-12), "moment about centre"
    # Moment about the shoulder: -g (0.12 * 0.5 + 0.10 * 1.0) = -3.71 * 0.16 = -0.5936 N m.
    assert float(load.shoulder_torque[0]) == pytest.approx(-0.5936, abs=1e-12), (
        f"shoulder torque {load.shoulder_torque[0]}, hand value -0.5936 N m")
    # Mirrored to the left (boom 1, shoulder (-0.15, 1.15)): the moments change sign.
    mirrored = geometry.limb_load(robot, pose, 1, np.array([-1.15, 1.15]), gravity)
    assert float(mirrored.moment[0]) == pytest.approx(0.71603, abs=1e-12), "mirrored moment"
    assert float(mirrored.shoulder_torque[0]) == pytest.approx(0.5936, abs=1e-12), (
        "mirrored shoulder torque")


def test_limb_load_hanging_boom_has_no_shoulder_torque(robot, gravity):
    pose = np.array([0.3, 1.0, 0.0])
    tip = geometry.shoulder_positions(robot, pose)[0, 2] + [0.0, -0.8]
    load = geometry.limb_load(robot, pose, 2, tip, gravity)
    assert abs(float(load.shoulder_torque[0])) < 1e-12, (
        f"a boom hanging straight down has no torque about its shoulder, got "
        f"{load.shoulder_torque[0]}")
    # Its moment about the centre: weight (0.12 * 0.8 + 0.1) g at lever arm -0.15 in x.
    want = -0.15 * -(0.12 * 0.8 + 0.10) * 3.71
    assert float(load.moment[0]) == pytest.approx(want, abs=1e-12), "hanging boom's moment"


def test_wrench_matrix_columns(robot, start_stance, start_pose):
    geo = geometry.boom_geometry(robot, start_pose, start_stance.positions)
    W = geometry.wrench_matrix(robot, start_pose, geo.u)[0]
    r = robot.shoulder_array  # phi = 0: R s_i = s_i
    for i in range(4):
        u = geo.u[0, i]
        np.testing.assert_allclose(W[:2, i], u, atol=1e-14, err_msg=f"force part of column {i}")
        assert W[2, i] == pytest.approx(r[i, 0] * u[1] - r[i, 1] * u[0], abs=1e-14), (
            f"moment part of column {i} must be s_i x u_i")


def test_wrap_angle_range(rng):
    a = np.concatenate([rng.uniform(-100.0, 100.0, 10_000),
                        np.pi * np.arange(-9, 10), [0.0, -np.pi, np.pi]])
    w = geometry.wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi), "wrap_angle must land in [-pi, pi)"
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12,
                               err_msg="wrapping must not change the angle (cos)")
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12,
                               err_msg="wrapping must not change the angle (sin)")
    assert float(geometry.wrap_angle(np.pi)) == pytest.approx(-np.pi, abs=0), "pi wraps to -pi"
    inner = np.linspace(-3.0, 3.0, 13)
    np.testing.assert_allclose(geometry.wrap_angle(inner), inner, atol=1e-15,
                               err_msg="angles already inside (-pi, pi) are unchanged")


def test_wrap_angle_range_one_ulp_below_minus_pi():
    a = np.nextafter(-np.pi, -np.inf)
    w = float(geometry.wrap_angle(a))
    assert -np.pi <= w < np.pi, f"wrap_angle({a!r}) = {w!r}, outside [-pi, pi)"


def test_custom_robot_shoulders_follow_params():
    robot = RobotParams(shoulders=((0.2, 0.0), (0.0, 0.2), (-0.2, 0.0), (0.0, -0.2)))
    got = geometry.shoulder_positions(robot, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, math.pi]]))
    assert got.shape == (2, 4, 2), f"two poses -> shape (2, 4, 2), got {got.shape}"
    np.testing.assert_allclose(got[0], robot.shoulder_array, atol=1e-15,
                               err_msg="identity pose leaves shoulders in place")
    np.testing.assert_allclose(got[1], 1.0 * np.array([1.0, 0.0]) - robot.shoulder_array,
                               atol=1e-12, err_msg="a half turn negates the shoulder offsets")


def test_rock_of_many_small_polygons_counts_parity_in_little_memory() -> None:
    """Rock.contains counts each polygon's crossings by its edges' group: the former (edges x
    polygons) indicator took 384 MB for 4,000 small rocks (a scenario check of 922 MB). The
    answer is the even-odd rule's, checked against shapely point by point."""
    import tracemalloc

    from shapely.geometry import Point, Polygon

    from rb_drake.collision import Rock

    rng = np.random.default_rng(3)
    polygons = []
    for _ in range(4000):
        centre, size = rng.uniform(-50.0, 50.0, 2), rng.uniform(0.05, 0.5)
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, 3))
        polygons.append(centre + size * np.c_[np.cos(angles), np.sin(angles)])
    points = np.concatenate([rng.uniform(-50.0, 50.0, (300, 2)),
                             [p.mean(axis=0) for p in polygons[:300]]])  # inside, most
    tracemalloc.start()
    try:
        rock = Rock(polygons)
        inside = rock.contains(points)
        peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    assert peak_mb < 60, f"Rock of 4,000 triangles and 600 points took {peak_mb:.0f} MB"
    shapes = [Polygon(p) for p in polygons]
    expected = [any(s.contains(Point(q)) for s in shapes) for q in points]
    assert inside.tolist() == expected, "a point's inside/outside differs from shapely's"
    assert inside[300:].all(), "a triangle's centroid was found outside it"
