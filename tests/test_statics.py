"""Statics, force allocation (vectorised and Drake/QP reference) and pose feasibility."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rb_drake import feasibility, geometry, grasp, statics
from rb_drake.feasibility import Reason
from rb_drake.stance import Stance

NAN = math.nan


# ---------------------------------------------------------------------------------------------
# Helpers: an independent statics model written out by hand, and the allocation objective.


def hand_statics(robot, gravity, pose, stance, free_tip=None):
    """A (3, 4) and b (3,) for one pose, built boom by boom without the geometry module."""
    x, y, phi = pose
    c, s = math.cos(phi), math.sin(phi)
    centre = np.array([x, y])
    g = np.asarray(gravity, dtype=float)
    A = np.zeros((3, 4))
    for i in range(4):
        if not stance.attached[i]:
            continue
        sx, sy = robot.shoulders[i]
        r = np.array([c * sx - s * sy, s * sx + c * sy])
        d = stance.positions[i] - (centre + r)
        u = d / math.hypot(*d)
        A[:, i] = [u[0], u[1], r[0] * u[1] - r[1] * u[0]]
    b = np.zeros(3)
    b[:2] = -robot.body_mass * g
    j = stance.free_boom
    if j is not None:
        sx, sy = robot.shoulders[j]
        shoulder = centre + np.array([c * sx - s * sy, s * sx + c * sy])
        tip = np.asarray(free_tip, dtype=float)
        m_boom = robot.boom_linear_density * math.hypot(*(tip - shoulder))
        m_grip = robot.gripper_mass
        mid = 0.5 * (shoulder + tip)
        b[:2] -= (m_boom + m_grip) * g

        def moment(p, m):
            a = p - centre
            return m * (a[0] * g[1] - a[1] * g[0])

        b[2] -= moment(mid, m_boom) + moment(tip, m_grip)
    return A, b


def regularised_objective(stance, f, psi):
    """sum_i log Phi(z_i) - REGULARISATION/2 |f|^2 over the attached booms (f: (..., 4))."""
    att = stance.attached
    lp = grasp.log_prob(f[..., att], psi[att], stance.f_normal[att], stance.f_lateral[att],
                        stance.sigma_normal[att], stance.sigma_lateral[att])
    return lp.sum(axis=-1) - 0.5 * statics.REGULARISATION * np.sum(f[..., att] ** 2, axis=-1)


# A 3-stance with boom 3 free whose gripper hangs below the body: positive tensions.
FREE_TIP_3 = np.array([-0.2, 0.5])


@pytest.fixture(scope="module")
def sample_poses(shaft, start_stance):
    """~30 seeded random poses near the start at which the 4-stance statics are feasible."""
    rng = np.random.default_rng(7)
    cand = np.column_stack([rng.uniform(-0.7, 0.7, 400), rng.uniform(0.5, 1.8, 400),
                            rng.uniform(-0.4, 0.4, 400)])
    alloc = statics.allocate(shaft.robot, shaft.gravity_vector, cand, start_stance)
    good = cand[alloc.statics_ok & np.isfinite(alloc.robustness)]
    assert len(good) >= 30, f"only {len(good)} of 400 sampled poses balance; need 30"
    poses = good[:30]
    r = statics.allocate(shaft.robot, shaft.gravity_vector, poses, start_stance).robustness
    # The sample must exercise the curved part of log Phi, not only the regulariser.
    assert r.min() < -1e-2, f"sample too safe to test the optimiser: min robustness {r.min()}"
    return poses


@pytest.fixture(scope="module", params=["osqp", "clarabel"])
def allocator(request, shaft):
    return statics.ForceAllocator(shaft.robot, solver=request.param)


# ---------------------------------------------------------------------------------------------
# Three anchors: a unique solution.


def test_three_stance_unique_solution(shaft, start_stance, start_pose):
    st3 = start_stance.without(3)
    alloc = statics.allocate(shaft.robot, shaft.gravity_vector, start_pose, st3, FREE_TIP_3)
    prob = statics.statics_problem(shaft.robot, shaft.gravity_vector, start_pose, st3,
                                   FREE_TIP_3)
    f = alloc.tensions[0]
    assert np.isnan(f[3]), f"the free boom's tension must be NaN, got {f[3]}"
    att = st3.attached
    resid = prob.A[0][:, att] @ f[att] - prob.b[0]
    assert np.max(np.abs(resid)) < 1e-9, f"A f = b violated by {resid}"
    A, b = hand_statics(shaft.robot, shaft.gravity_vector, start_pose, st3, FREE_TIP_3)
    np.testing.assert_allclose(prob.A[0], A, atol=1e-12,
                               err_msg="statics_problem A against the hand-built wrench matrix")
    np.testing.assert_allclose(prob.b[0], b, atol=1e-12,
                               err_msg="statics_problem b against gravity + free-limb load")
    want = np.linalg.solve(A[:, att], b)
    np.testing.assert_allclose(f[att], want, atol=1e-9,
                               err_msg="3-stance tensions against an independent 3x3 solve")
    lo, hi = shaft.robot.boom_tension
    assert np.all((f[att] >= lo) & (f[att] <= hi)), f"tensions {f[att]} outside [{lo}, {hi}]"
    assert alloc.statics_ok[0], "a balancing in-bounds 3-stance must report statics_ok"
    assert alloc.residual[0] < 1e-9, f"reported residual {alloc.residual[0]}"
    lp = st3.log_prob(f, alloc.pull_angles[0])
    assert alloc.robustness[0] == pytest.approx(lp.sum(), abs=1e-15), (
        "robustness of a 3-stance is sum log P_i of its unique tensions")
    load = geometry.limb_load(shaft.robot, start_pose, 3, FREE_TIP_3, shaft.gravity_vector)
    assert alloc.shoulder_torque[0] == pytest.approx(float(load.shoulder_torque[0]), abs=1e-15)


def test_three_stance_vectorised_matches_per_pose(shaft, start_stance, rng):
    st3 = start_stance.without(2)
    poses = np.column_stack([rng.uniform(-0.4, 0.4, 20), rng.uniform(0.8, 1.4, 20),
                             rng.uniform(-0.3, 0.3, 20)])
    tip = np.array([-0.5, 0.5])
    batch = statics.allocate(shaft.robot, shaft.gravity_vector, poses, st3, tip)
    for k, pose in enumerate(poses):
        A, b = hand_statics(shaft.robot, shaft.gravity_vector, pose, st3, tip)
        att = st3.attached
        want = np.linalg.solve(A[:, att], b)
        np.testing.assert_allclose(batch.tensions[k, att], want, rtol=1e-9, atol=1e-9,
                                   err_msg=f"pose {k}: batch 3-stance tensions vs 3x3 solve")


def test_three_stance_negative_tension_is_infeasible(shaft, start_stance, start_pose):
    # Boom 0 free (upper right): the two lower booms would have to push.
    st3 = start_stance.without(0)
    tip = np.array([0.6, 1.6])
    alloc = statics.allocate(shaft.robot, shaft.gravity_vector, start_pose, st3, tip)
    f = alloc.tensions[0, 1:]
    assert np.all(np.isfinite(f)), f"the 3x3 system is regular here, tensions {f}"
    assert f.min() < 0.0, f"expected a compressive (negative) tension, got {f}"
    assert alloc.residual[0] < 1e-9, "the unique solution still satisfies A f = b"
    assert not alloc.statics_ok[0], "negative tensions must not count as statics_ok"
    assert alloc.robustness[0] == -math.inf, f"robustness {alloc.robustness[0]}, expected -inf"


def test_three_stance_singular_geometry(shaft, start_pose):
    """Three booms whose lines all pass through the body centre cannot resist a moment."""
    stance = Stance(
        ids=(None, "b1", "b2", "b3"),
        attached=np.array([False, True, True, True]),
        # Anchors on the shoulders' diagonals through the centre (0, 1).
        positions=np.array([[NAN, NAN], [-1.0, 2.0], [-1.0, 0.0], [1.0, 0.0]]),
        normals=np.array([[NAN, NAN], [1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]]),
        f_normal=np.array([NAN, 40.0, 40.0, 40.0]),
        f_lateral=np.array([NAN, 20.0, 20.0, 20.0]),
        sigma_normal=np.array([NAN, 3.0, 3.0, 3.0]),
        sigma_lateral=np.array([NAN, 5.0, 5.0, 5.0]),
    )
    tip = np.array([0.8, 1.8])
    prob = statics.statics_problem(shaft.robot, shaft.gravity_vector, start_pose, stance, tip)
    det = np.linalg.det(prob.A[0][:, 1:])
    assert abs(det) < 1e-12, f"concurrent boom lines must give a singular matrix, det {det}"
    assert abs(prob.b[0, 2]) > 0.1, "the free limb loads a moment the booms cannot resist"
    alloc = statics.allocate(shaft.robot, shaft.gravity_vector, start_pose, stance, tip)
    assert np.all(np.isnan(alloc.tensions)), f"singular statics: NaN tensions, got {alloc}"
    assert not alloc.statics_ok[0], "singular statics must not be statics_ok"
    assert alloc.robustness[0] == -math.inf, "singular statics must give robustness -inf"


def test_allocate_rejects_bad_stances(shaft, start_stance, start_pose):
    with pytest.raises(ValueError, match="free gripper"):
        statics.allocate(shaft.robot, shaft.gravity_vector, start_pose, start_stance.without(1))
    with pytest.raises(ValueError, match="3 or 4 anchors"):
        statics.allocate(shaft.robot, shaft.gravity_vector, start_pose,
                         start_stance.without(1).without(2), np.zeros(2))


# ---------------------------------------------------------------------------------------------
# Four anchors: a one-parameter family, the most robust member.


def test_null_vector_spans_null_space(shaft, start_stance, sample_poses):
    prob = statics.statics_problem(shaft.robot, shaft.gravity_vector, sample_poses, start_stance)
    n = statics.null_vector(prob.A)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    resid = np.einsum("pij,pj->pi", prob.A, n)
    assert np.max(np.abs(resid)) < 1e-12, f"A n must vanish, max |A n| = {np.abs(resid).max()}"
    # Against SVD: the last right-singular vector, up to sign.
    for k in range(len(sample_poses)):
        v = np.linalg.svd(prob.A[k])[2][-1]
        assert abs(abs(float(v @ n[k])) - 1.0) < 1e-10, f"pose {k}: null vector differs from SVD"


def test_four_stance_statics_bounds_and_optimality(shaft, start_stance, sample_poses):
    robot, g = shaft.robot, shaft.gravity_vector
    poses = np.vstack([np.array(shaft.start_pose), sample_poses])
    alloc = statics.allocate(robot, g, poses, start_stance)
    prob = statics.statics_problem(robot, g, poses, start_stance)
    n_all = statics.null_vector(prob.A)
    lo, hi = robot.boom_tension
    for k, pose in enumerate(poses):
        f = alloc.tensions[k]
        A, b = hand_statics(robot, g, pose, start_stance)
        resid = A @ f - b
        assert np.max(np.abs(resid)) < 1e-6, f"pose {k} {pose}: |A f - b| = {resid} > 1e-6 N"
        assert np.all(f >= lo - 1e-9) and np.all(f <= hi + 1e-9), (
            f"pose {k}: tensions {f} outside [{lo}, {hi}] N")
        # Perturb along the null vector within the bounds: never better than the optimum.
        n = n_all[k] / np.linalg.norm(n_all[k])
        t_lo = max(((lo if ni > 0 else hi) - fi) / ni for fi, ni in zip(f, n, strict=True))
        t_hi = min(((hi if ni > 0 else lo) - fi) / ni for fi, ni in zip(f, n, strict=True))
        assert t_lo <= 1e-9 and t_hi >= -1e-9, f"pose {k}: optimum outside its own interval"
        ts = np.concatenate([np.linspace(t_lo, t_hi, 41),
                             np.clip([-1e-3, -1e-6, 1e-6, 1e-3], t_lo, t_hi)])
        psi = alloc.pull_angles[k]
        best = regularised_objective(start_stance, f, psi)
        others = regularised_objective(start_stance, f + ts[:, None] * n, psi)
        tol = 1e-12 * (1.0 + abs(best))
        worst = float(np.max(others - best))
        assert worst <= tol, (
            f"pose {k}: moving along the null vector raises the objective by {worst:.3e} "
            f"(optimum {best:.6e})")
        assert alloc.robustness[k] == pytest.approx(
            float(np.sum(start_stance.log_prob(f, psi))), abs=1e-15), "robustness = sum log P_i"


def test_allocate_vectorised_equals_single_pose(shaft, start_stance, sample_poses):
    batch = statics.allocate(shaft.robot, shaft.gravity_vector, sample_poses[:5], start_stance)
    for k in range(5):
        one = statics.allocate(shaft.robot, shaft.gravity_vector, sample_poses[k], start_stance)
        np.testing.assert_allclose(one.tensions[0], batch.tensions[k], rtol=0, atol=1e-12,
                                   err_msg=f"pose {k}: batched and single allocation differ")


def test_allocate_agrees_with_force_allocator(allocator, shaft, start_stance, sample_poses):
    g = shaft.gravity_vector
    fast = statics.allocate(shaft.robot, g, sample_poses, start_stance)
    for k, pose in enumerate(sample_poses):
        ref = allocator.solve(g, pose, start_stance)
        assert allocator.last_infeasible == [], (
            f"pose {k}: feasible solve reported infeasible constraints "
            f"{allocator.last_infeasible}")
        assert ref.statics_ok[0], f"pose {k}: reference allocator lost statics"
        np.testing.assert_allclose(ref.tensions[0], fast.tensions[k], atol=1e-4, rtol=0,
                                   err_msg=f"pose {k} {pose}: tensions differ")
        assert ref.robustness[0] == pytest.approx(fast.robustness[k], abs=1e-7), (
            f"pose {k}: robustness {ref.robustness[0]} (QP) vs {fast.robustness[k]} (allocate)")


def test_force_allocator_three_stance(allocator, shaft, start_stance, start_pose):
    st3 = start_stance.without(3)
    fast = statics.allocate(shaft.robot, shaft.gravity_vector, start_pose, st3, FREE_TIP_3)
    ref = allocator.solve(shaft.gravity_vector, start_pose, st3, FREE_TIP_3)
    assert ref.statics_ok[0], "the reference allocator must solve a feasible 3-stance"
    np.testing.assert_allclose(ref.tensions[0, :3], fast.tensions[0, :3], atol=1e-4,
                               err_msg="3-stance: QP and closed form disagree")
    assert np.isnan(ref.tensions[0, 3]), "the free boom's tension must be reported as NaN"


def test_weak_booms_cannot_hold_gravity(shaft, make_scenario, start_pose):
    # Four booms of at most 1 N cannot carry 2 kg * 3.71 m/s^2 = 7.42 N.
    weak = shaft.robot.replace(boom_tension=(0.5, 1.0))
    stance = shaft.stance(shaft.start_stance)
    alloc = statics.allocate(weak, shaft.gravity_vector, start_pose, stance)
    assert not alloc.statics_ok[0], "statics must fail with 1 N booms"
    assert alloc.robustness[0] == -math.inf, f"robustness {alloc.robustness[0]}, expected -inf"
    assert np.all(np.isnan(alloc.tensions)), f"no tensions exist, got {alloc.tensions}"
    # The same robot through a scenario's robot overrides.
    scn = make_scenario(robot={"boom_tension": [0.5, 1.0]})
    assert scn.robot == weak, f"override gives {scn.robot}, replace gives {weak}"
    alloc2 = statics.allocate(scn.robot, scn.gravity_vector, start_pose, stance)
    assert not alloc2.statics_ok[0] and alloc2.robustness[0] == -math.inf, (
        "boom_tension [0.5, 1.0] from the scenario must also be infeasible")


@pytest.mark.parametrize("solver", ["osqp", "clarabel"])
def test_force_allocator_reports_infeasible_constraints(solver, shaft, start_stance, start_pose):
    weak = shaft.robot.replace(boom_tension=(0.5, 1.0))
    fa = statics.ForceAllocator(weak, solver=solver)
    alloc = fa.solve(shaft.gravity_vector, start_pose, start_stance)
    assert not alloc.statics_ok[0], f"{solver}: infeasible statics reported as ok"
    assert alloc.robustness[0] == -math.inf, f"{solver}: robustness {alloc.robustness[0]}"
    assert np.all(np.isnan(alloc.tensions)), f"{solver}: tensions {alloc.tensions}"
    names = fa.last_infeasible
    assert names, f"{solver}: an infeasible QP must name its violated constraints"
    prefixes = {name.split("[")[0] for name in names}
    assert prefixes <= {"statics", "tension_bounds"}, (
        f"{solver}: unexpected constraint names {names}")
    assert "tension_bounds" in prefixes, f"{solver}: the tension bounds are binding: {names}"
    # A later feasible solve with a capable robot clears the report.
    fa_ok = statics.ForceAllocator(shaft.robot, solver=solver)
    fa_ok.last_infeasible = ["stale"]
    fa_ok.solve(shaft.gravity_vector, start_pose, start_stance)
    assert fa_ok.last_infeasible == [], f"{solver}: stale infeasibility report not cleared"


def test_force_allocator_rejects_unknown_solver(shaft):
    with pytest.raises(ValueError, match="osqp"):
        statics.ForceAllocator(shaft.robot, solver="gurobi")


# ---------------------------------------------------------------------------------------------
# Feasibility: the first failing test per pose, and the words for it.


def _check_one(scn, stance, pose, free_tip=None):
    chk = feasibility.check_poses(scn, stance, np.asarray(pose, dtype=float), free_tip)
    words = feasibility.diagnose_pose(scn, stance, np.asarray(pose, dtype=float), free_tip)
    return Reason(int(chk.reason[0])), int(chk.boom[0]), chk, words


def test_start_pose_is_feasible(shaft, start_stance, start_pose):
    reason, boom, chk, words = _check_one(shaft, start_stance, start_pose)
    assert reason is Reason.FEASIBLE and chk.feasible[0], f"start pose fails with {reason.name}"
    assert boom == -1, f"a feasible pose names no boom, got {boom}"
    assert words == [], f"diagnose_pose of a feasible pose must be empty, got {words}"
    assert chk.probability[0] >= shaft.robot.p_min, f"P = {chk.probability[0]} < p_min"


def test_boom_too_long(shaft, start_stance):
    # Body at (-0.3, 2.3): boom 3's shoulder (-0.15, 2.15) is sqrt(1.35^2 + 1.85^2) = 2.290 m
    # from a3 (1.2, 0.3); the other booms are <= 2 m (boom 2: 1.996 m).
    pose = [-0.3, 2.3, 0.0]
    reason, boom, chk, words = _check_one(shaft, start_stance, pose)
    assert reason is Reason.BOOM_LENGTH, f"expected BOOM_LENGTH, got {reason.name}"
    assert boom == 3, f"boom 3 is the long one, got boom {boom}"
    assert chk.lengths[0, 3] == pytest.approx(math.hypot(1.35, 1.85), abs=1e-12)
    assert not chk.feasible[0], "an over-long boom is infeasible"
    msg = [w for w in words if w.startswith("boom 3: length")]
    assert msg, f"diagnose_pose must name boom 3's length, got {words}"
    assert "2.290" in msg[0] and "[0.01, 2.0]" in msg[0], (
        f"the message must give the length and the limit, got {msg[0]!r}")


def test_shoulder_angle_out_of_range(shaft, start_stance):
    # Turn the body a quarter turn: boom 0 would have to bend -102.8 deg from its equilibrium.
    pose = [0.0, 1.0, math.pi / 2]
    reason, boom, chk, words = _check_one(shaft, start_stance, pose)
    assert reason is Reason.SHOULDER_ANGLE, f"expected SHOULDER_ANGLE, got {reason.name}"
    assert boom == 0, f"boom 0 is the first out of range, got {boom}"
    assert np.all(chk.lengths[0] <= shaft.robot.boom_length[1]), "lengths must be fine here"
    d = np.array([1.2, 2.0]) - np.array([-0.15, 1.15])  # shoulder 0 after a quarter turn
    want = math.atan2(d[1], d[0]) - math.pi / 2 - math.pi / 4
    assert chk.shoulder_angles[0, 0] == pytest.approx(want, abs=1e-12), "shoulder angle value"
    msg = [w for w in words if w.startswith("boom 0: shoulder angle")]
    assert msg, f"diagnose_pose must name boom 0's shoulder angle, got {words}"
    assert "-102.8 deg" in msg[0] and "+-45.0 deg" in msg[0], (
        f"the message must give the angle and the limit, got {msg[0]!r}")


@pytest.mark.parametrize(("label", "rock"), [
    ("body inside rock", [[-0.5, 0.5], [0.5, 0.5], [0.5, 1.5], [-0.5, 1.5]]),
    ("rock inside body", [[-0.05, 0.95], [0.05, 0.95], [0.05, 1.05], [-0.05, 1.05]]),
    ("rock across an edge", [[0.1, 0.9], [0.4, 0.9], [0.4, 1.1], [0.1, 1.1]]),
])
def test_body_collision(label, rock, make_scenario, start_pose):
    scn = make_scenario(extra_walls=[rock])
    stance = scn.stance(scn.start_stance)
    reason, boom, _, words = _check_one(scn, stance, start_pose)
    assert reason is Reason.BODY_COLLISION, f"{label}: expected BODY_COLLISION, got {reason.name}"
    assert boom == -1, f"{label}: a body collision names no boom, got {boom}"
    assert "body collides with rock" in words, f"{label}: diagnose_pose said {words}"


def test_boom_collision(make_scenario, start_pose):
    # A pebble on boom 0's line from (0.15, 1.15) to a0 (1.2, 2.0).
    scn = make_scenario(extra_walls=[[[0.6, 1.5], [0.7, 1.5], [0.7, 1.7], [0.6, 1.7]]])
    reason, boom, _, words = _check_one(scn, scn.stance(scn.start_stance), start_pose)
    assert reason is Reason.BOOM_COLLISION and boom == 0, (
        f"expected BOOM_COLLISION on boom 0, got {reason.name} on boom {boom}")
    assert words == ["boom 0: collides with rock"], f"diagnose_pose said {words}"


def test_pull_angle_beyond_ninety_degrees(shaft, start_stance, start_pose):
    # a0's normal turned to point away from the robot, into the wall: the pull from a0 toward
    # shoulder 0 (direction (-1.05, -0.85)) is 180 - atan2(0.85, 1.05) = 141.0 deg from it.
    normals = start_stance.normals.copy()
    normals[0] = [1.0, 0.0]
    stance = start_stance._replace(normals=normals)
    reason, boom, chk, words = _check_one(shaft, stance, start_pose)
    assert reason is Reason.PULL_ANGLE, f"expected PULL_ANGLE, got {reason.name}"
    assert boom == 0, f"a0 is held by boom 0, got {boom}"
    want = -(math.pi - math.atan2(0.85, 1.05))
    assert chk.allocation.pull_angles[0, 0] == pytest.approx(want, abs=1e-12), "pull angle"
    assert chk.allocation.robustness[0] == -math.inf, "a grasp pulled past 90 deg has P = 0"
    msg = [w for w in words if w.startswith("boom 0: anchor a0 pulled")]
    assert msg and "-141.0 deg" in msg[0] and "+-88.0" in msg[0], (
        f"diagnose_pose must name boom 0, anchor a0, the angle and the limit, got {words}")


def test_shoulder_torque_of_free_limb(make_scenario, start_pose):
    # Boom 2 free, 0.5 m long at 225 deg: torque 3.71 (0.06 * 0.1768 + 0.1 * 0.3536) = 0.1706.
    scn = make_scenario(robot={"shoulder_torque_max": 0.1})
    stance = scn.stance(scn.start_stance).without(2)
    shoulder = np.array([-0.15, 0.85])
    tip = shoulder + 0.5 * np.array([-math.sqrt(0.5), -math.sqrt(0.5)])
    reason, _, chk, words = _check_one(scn, stance, start_pose, tip)
    arm = 0.5 * math.sqrt(0.5)
    want = 3.71 * (0.12 * 0.5 * arm / 2 + 0.10 * arm)
    assert chk.allocation.shoulder_torque[0] == pytest.approx(want, abs=1e-12), "hand torque"
    assert reason is Reason.SHOULDER_TORQUE, f"expected SHOULDER_TORQUE, got {reason.name}"
    assert any(w.startswith("boom 2 (free): shoulder torque 0.17 N m over the limit 0.1")
               for w in words), f"diagnose_pose said {words}"


def test_statics_failure_reported(make_scenario, start_pose):
    scn = make_scenario(robot={"boom_tension": [0.5, 1.0]})
    reason, boom, chk, words = _check_one(scn, scn.stance(scn.start_stance), start_pose)
    assert reason is Reason.STATICS, f"expected STATICS, got {reason.name}"
    assert boom == -1, f"statics concerns the whole pose, got boom {boom}"
    assert chk.probability[0] == 0.0, "robustness -inf means probability 0"
    assert any("no tensions within [0.5, 1.0] N" in w for w in words), (
        f"diagnose_pose must give the tension limits, got {words}")


def test_probability_below_p_min(make_scenario, start_pose):
    weak = {"limit": {"normal": 8, "lateral": 20}}
    scn = make_scenario(anchor_updates={a: weak for a in ("a0", "a1", "a2", "a3")})
    stance = scn.stance(scn.start_stance)
    assert np.all(stance.f_normal == 8.0), "the anchors' normal limit must now be 8 N"
    reason, boom, chk, words = _check_one(scn, stance, start_pose)
    assert reason is Reason.PROBABILITY, f"expected PROBABILITY, got {reason.name}"
    assert boom == -1, f"probability concerns the whole pose, got boom {boom}"
    assert chk.allocation.statics_ok[0], "statics hold; only the probability is too low"
    p = float(chk.probability[0])
    assert 0.0 < p < scn.robot.p_min, f"P = {p} should be in (0, p_min = {scn.robot.p_min})"
    msg = [w for w in words if w.startswith("probability")]
    assert msg and f"{p:.3f} below p_min 0.95" in msg[0], f"diagnose_pose said {words}"
    for i in range(4):
        assert f"boom {i} " in msg[0], f"the message must list boom {i}: {msg[0]!r}"


def test_check_poses_vectorised(shaft, start_stance):
    poses = np.array([[0.0, 1.0, 0.0], [-0.3, 2.3, 0.0], [0.0, 1.0, math.pi / 2]])
    chk = feasibility.check_poses(shaft, start_stance, poses)
    want = [Reason.FEASIBLE, Reason.BOOM_LENGTH, Reason.SHOULDER_ANGLE]
    assert [Reason(int(r)) for r in chk.reason] == want, f"reasons {chk.reason}"
    assert chk.boom.tolist() == [-1, 3, 0], f"booms {chk.boom}"
    assert chk.feasible.tolist() == [True, False, False], f"feasible {chk.feasible}"


def test_check_poses_full_and_staged_agree(shaft, start_stance):
    poses = np.array([[0.0, 1.0, 0.0], [-0.3, 2.3, 0.0], [0.0, 1.0, math.pi / 2],
                      [0.2, 1.2, 0.1]])
    staged = feasibility.check_poses(shaft, start_stance, poses)
    full = feasibility.check_poses(shaft, start_stance, poses, full=True)
    np.testing.assert_array_equal(staged.reason, full.reason,
                                  err_msg="the staged and full checks must find the same reason")
    np.testing.assert_array_equal(staged.boom, full.boom, err_msg="same boom concerned")
    alone = statics.allocate(shaft.robot, shaft.gravity_vector, poses, start_stance)
    for k in np.flatnonzero(staged.feasible):
        np.testing.assert_allclose(staged.allocation.tensions[k], alone.tensions[k], atol=1e-12,
                                   err_msg=f"pose {k}: check_poses' allocation is allocate's")
    rejected = ~staged.feasible & (staged.reason <= Reason.BOOM_COLLISION)
    assert np.all(staged.allocation.robustness[rejected] == -math.inf), (
        "poses rejected before the statics stage carry robustness -inf")
    np.testing.assert_allclose(full.allocation.tensions, alone.tensions, atol=1e-12,
                               err_msg="full=True allocates at every pose")


def test_ignore_grasps_skips_grasp_tests(make_scenario, shaft, start_stance, start_pose):
    normals = start_stance.normals.copy()
    normals[0] = [1.0, 0.0]
    turned = start_stance._replace(normals=normals)
    chk = feasibility.check_poses(shaft, turned, start_pose, ignore_grasps=True)
    assert Reason(int(chk.reason[0])) is Reason.FEASIBLE, (
        f"without grasp tests a bad pull angle is no failure, got {Reason(int(chk.reason[0]))}")
    weak = make_scenario(anchor_updates={a: {"limit": {"normal": 8, "lateral": 20}}
                                         for a in ("a0", "a1", "a2", "a3")})
    chk = feasibility.check_poses(weak, weak.stance(weak.start_stance), start_pose,
                                  ignore_grasps=True)
    assert Reason(int(chk.reason[0])) is Reason.FEASIBLE, "a low probability is no failure"
    strong = make_scenario(robot={"boom_tension": [0.5, 1.0]})
    chk = feasibility.check_poses(strong, strong.stance(strong.start_stance), start_pose,
                                  ignore_grasps=True)
    assert Reason(int(chk.reason[0])) is Reason.STATICS, "statics are still checked"


# ---------------------------------------------------------------------------------------------
# Regressions pinned at poses where the implementations were seen to disagree (library bugs).

# Kinematically feasible poses of the shaft's start stance (check_poses: FEASIBLE), found by
# seeded sampling; exact floats, since the failures depend on the iterates.
POSE_NEWTON = np.array([0.4160925716742798, 0.6029961838773118, 0.08692798944305569])
POSE_OSQP = np.array([0.49607498128325034, 0.7988068897367645, 0.1732150817144409])


def test_pinned_poses_are_feasible(shaft, start_stance):
    chk = feasibility.check_poses(shaft, start_stance, np.vstack([POSE_NEWTON, POSE_OSQP]))
    assert chk.feasible.all(), f"pinned poses must be feasible, reasons {chk.reason}"


def test_allocate_converges_at_pinned_pose(shaft, start_stance):
    g = shaft.gravity_vector
    ref = statics.ForceAllocator(shaft.robot, solver="clarabel").solve(g, POSE_NEWTON,
                                                                       start_stance)
    fast = statics.allocate(shaft.robot, g, POSE_NEWTON, start_stance)
    np.testing.assert_allclose(fast.tensions[0], ref.tensions[0], atol=1e-4, rtol=0,
                               err_msg="allocate vs Clarabel reference tensions")
    assert fast.robustness[0] == pytest.approx(ref.robustness[0], abs=1e-7), "robustness"


def test_allocate_with_more_newton_steps_matches_reference(shaft, start_stance):
    g = shaft.gravity_vector
    ref = statics.ForceAllocator(shaft.robot, solver="clarabel").solve(g, POSE_NEWTON,
                                                                       start_stance)
    fast = statics.allocate(shaft.robot, g, POSE_NEWTON, start_stance, newton_steps=40)
    np.testing.assert_allclose(fast.tensions[0], ref.tensions[0], atol=1e-4, rtol=0,
                               err_msg="converged allocate vs Clarabel reference tensions")
    assert fast.robustness[0] == pytest.approx(ref.robustness[0], abs=1e-9), "robustness"


def test_force_allocator_osqp_converges_at_pinned_pose(shaft, start_stance):
    g = shaft.gravity_vector
    ref = statics.ForceAllocator(shaft.robot, solver="clarabel").solve(g, POSE_OSQP, start_stance)
    fa = statics.ForceAllocator(shaft.robot, solver="osqp")
    got = fa.solve(g, POSE_OSQP, start_stance)
    assert got.statics_ok[0], "statics hold at this pose"
    np.testing.assert_allclose(got.tensions[0], ref.tensions[0], atol=1e-4, rtol=0,
                               err_msg="OSQP vs Clarabel tensions")
    assert fa.last_infeasible == [], f"a feasible solve reported {fa.last_infeasible}"


def test_force_allocator_osqp_on_ill_conditioned_statics() -> None:
    """OSQP stalls on the least-effort QP here (a singular value of A near 0.12); the allocator
    must still find the robust tensions (found by rbp bench)."""
    from rb_drake.scenario import bundled_caves, load_scenario

    scn = load_scenario(bundled_caves()["demo-crevasse"])
    stance = scn.stance(["a16", "a5", "a30", "a25"])
    pose = np.array([2.9255045796625025, 0.9798010798028924, -0.11633288949927399])
    want = statics.allocate(scn.robot, scn.gravity_vector, pose, stance)
    assert want.statics_ok[0], "precondition: the pose holds"
    for solver in ("osqp", "clarabel"):
        got = statics.ForceAllocator(scn.robot, solver).solve(scn.gravity_vector, pose, stance)
        assert got.statics_ok[0], f"{solver}: no tensions found"
        np.testing.assert_allclose(got.tensions, want.tensions, atol=1e-4,
                                   err_msg=f"{solver} disagrees with allocate")


def test_wrench_conditioning_vanishes_when_boom_lines_meet() -> None:
    """Three booms whose lines pass through one point resist no moment about it: rank 2."""
    from rb_drake.params import RobotParams

    robot = RobotParams()
    pose = np.zeros((1, 3))
    meet = np.array([0.0, 0.6])  # every boom line passes through this point
    shoulders = geometry.shoulder_positions(robot, pose)[0]
    anchors = shoulders + 3.0 * (meet - shoulders)
    u = (anchors - shoulders) / np.linalg.norm(anchors - shoulders, axis=1, keepdims=True)
    A = geometry.wrench_matrix(robot, pose, u[None])
    three = np.array([True, True, True, False])
    kappa = feasibility.wrench_conditioning(robot, A, three)[0]
    assert kappa < 1e-9, f"lines through one point: conditioning {kappa}"
    # Moving one anchor off that line gives the stance a moment arm again.
    anchors[0] += np.array([0.5, 0.0])
    u = (anchors - shoulders) / np.linalg.norm(anchors - shoulders, axis=1, keepdims=True)
    A = geometry.wrench_matrix(robot, pose, u[None])
    kappa = feasibility.wrench_conditioning(robot, A, three)[0]
    assert kappa > feasibility.MIN_CONDITIONING, f"off the point: conditioning {kappa}"


def test_demo_start_stance_is_well_conditioned() -> None:
    from rb_drake.scenario import bundled_caves, load_scenario

    scn = load_scenario(bundled_caves()["demo-shaft"])
    check = feasibility.check_poses(scn, scn.stance(scn.start_stance), np.array(scn.start_pose))
    kappa = feasibility.wrench_conditioning(scn.robot, check.problem.A,
                                            scn.stance(scn.start_stance).attached)[0]
    assert kappa > 3 * feasibility.MIN_CONDITIONING, f"demo start conditioning {kappa}"
