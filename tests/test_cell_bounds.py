"""cell_bounds (issue 30 prototype): bounds over a cell of poses hold for every pose sampled
in it (soundness), and shrink to the pose's own values as the cell shrinks (usefulness)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rb_drake import cell_bounds as cb
from rb_drake import cell_exclusion as ce
from rb_drake.feasibility import Reason, check_poses, pull_within
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario, load_scenario
from rb_drake.stance import Stance

CAVES = Path(__file__).resolve().parents[1] / "rb_drake" / "data" / "caves"
LATTICE_HALF = np.array([0.01, 0.01, math.radians(1.25)])  # half a lattice step
SCALES = (0.5, 1.0, 2.0)
SAMPLES = 200


def _caves() -> list[tuple[str, Scenario]]:
    out = [(p.stem, load_scenario(p)) for p in sorted(CAVES.glob("*.yaml"))]
    for seed in (3, 11):
        out.append((f"shaft-gen-{seed}",
                    generate_cave("shaft", seed, CaveConfig(length=(4.5, 5.0)))))
    return out


def _stances(scn: Scenario) -> list[tuple[Stance, np.ndarray | None]]:
    """The start stance and its 3-stances, each free gripper at its anchor."""
    st = scn.stance(scn.start_stance)
    out: list[tuple[Stance, np.ndarray | None]] = [(st, None)]
    for j in range(4):
        out.append((st.without(j), st.positions[j].copy()))
    return out


def _cell_samples(rng: np.random.Generator, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """SAMPLES poses uniform in the cell, plus its 8 corners."""
    inner = centre + rng.uniform(-1.0, 1.0, (SAMPLES, 3)) * half
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    return np.vstack([inner, centre + signs * half])


def _rule_fails(scn: Scenario, stance: Stance, check, reason: Reason) -> np.ndarray:
    """Per pose, whether it fails `reason`'s rule itself (not only as its first failure)."""
    robot = scn.robot
    used = stance.attached.copy()
    if stance.free_boom is not None:
        used[stance.free_boom] = True
    if reason == Reason.BOOM_LENGTH:
        lo, hi = robot.boom_length
        length = check.lengths
        return ((length < lo) | (length > hi))[:, used].any(axis=1)
    if reason == Reason.SHOULDER_ANGLE:
        return (np.abs(check.shoulder_angles) > robot.shoulder_range + 1e-12)[:, used].any(axis=1)
    assert reason == Reason.PULL_ANGLE
    psi = check.problem.pull_angles
    return (~pull_within(robot, psi) & stance.attached).any(axis=1)


@pytest.mark.parametrize("name_scn", _caves(), ids=lambda c: c[0])
def test_bounds_hold_for_every_sampled_pose(name_scn):
    name, scn = name_scn
    rng = np.random.default_rng(sum(map(ord, name)))  # fixed per cave
    p0 = np.array(scn.start_pose)
    log_p_min = scn.robot.log_p_min
    seen = {"cells": 0, "geometry": 0, "proven": 0, "proven_finite": 0, "finite_r": 0,
            "feasible": 0, "fast_proven": 0}
    for stance, tip in _stances(scn):
        centres = np.vstack([
            p0 + rng.normal(0.0, 1.0, (3, 3)) * np.array([0.04, 0.04, math.radians(4)]),
            p0 + rng.uniform(-1.0, 1.0, (3, 3)) * np.array([0.35, 0.35, math.radians(35)]),
        ])
        for centre in centres:
            for scale in SCALES:
                half = LATTICE_HALF * scale
                poses = _cell_samples(rng, centre, half)
                check = check_poses(scn, stance, poses, free_tip=tip, full=True)
                r = check.allocation.robustness
                geo = cb.cell_geometry(scn.robot, stance, centre, half, tip)
                reason = cb.cell_geometry_excluded(scn.robot, stance, centre, half, tip, geo)
                bound = cb.robustness_bound(scn, stance, centre, half, tip, geo=geo)
                where = f"{name} stance {stance.ids} centre {centre.tolist()} half {half.tolist()}"
                seen["cells"] += 1
                seen["finite_r"] += int(np.isfinite(r).any())
                seen["feasible"] += int(check.feasible.any())
                bad = r > bound.upper + 1e-9
                assert not bad.any(), (
                    f"{where}: r {r[bad].max():.6f} above the bound {bound.upper:.6f} at "
                    f"{poses[bad][0].tolist()}")
                assert bound.upper <= bound.simple + 2 * cb.LP_SLACK, where
                # geometry intervals hold every sampled pose's values
                used = np.isfinite(geo.targets[:, 0])
                length = check.lengths[:, used]
                assert np.all(length >= geo.length_lo[used] - 1e-12) and np.all(
                    length <= geo.length_hi[used] + 1e-12), f"{where}: length outside its interval"
                dth = np.abs(cb._wrap(check.shoulder_angles - geo.theta_c))[:, used]
                assert np.all(dth <= geo.theta_half[used] + 1e-12), (
                    f"{where}: shoulder angle moved {dth.max():.3g} > {geo.theta_half.max():.3g}")
                att = stance.attached
                apsi = np.abs(check.problem.pull_angles[:, att])
                assert np.all(apsi >= geo.abs_psi_lo[att] - 1e-12) and np.all(
                    apsi <= geo.abs_psi_hi[att] + 1e-12), f"{where}: |psi| outside its interval"
                if reason is not None:
                    seen["geometry"] += 1
                    assert not check.feasible.any(), (
                        f"{where}: excluded for {reason.name} but a sampled pose is feasible")
                    fails = _rule_fails(scn, stance, check, reason)
                    assert fails.all(), (
                        f"{where}: excluded for {reason.name} but {int((~fails).sum())} sampled "
                        "poses pass that rule")
                if tip is None:  # a 4-stance: the bound without a linear program
                    fast4 = ce.four_stance_bound(scn, stance, centre, half, geo=geo)
                    bad = r > fast4 + 1e-9
                    assert not bad.any(), (
                        f"{where}: r {r[bad].max():.6f} above the 4-stance bound {fast4:.6f} "
                        f"at {poses[bad][0].tolist()}")
                    seen["fast_proven"] += int(fast4 < log_p_min)
                if tip is not None:  # a 3-stance: the bound without a linear program
                    fast = ce.three_stance_bound(scn, stance, centre, half, tip, geo=geo)
                    bad = r > fast.upper + 1e-9
                    assert not bad.any(), (
                        f"{where}: r {r[bad].max():.6f} above the 3-stance bound "
                        f"{fast.upper:.6f} at {poses[bad][0].tolist()}")
                    f = check.allocation.tensions[:, stance.attached]
                    held = check.allocation.statics_ok
                    if np.isfinite(fast.f_lo).any() and held.any():
                        lo, hi = fast.f_lo[stance.attached], fast.f_hi[stance.attached]
                        out = ((f[held] < lo - 1e-9) | (f[held] > hi + 1e-9)).any(axis=1)
                        assert not out.any(), (
                            f"{where}: tensions {f[held][out][0].tolist()} outside the "
                            f"enclosure [{lo.tolist()}, {hi.tolist()}]")
                    seen["fast_proven"] += int(fast.upper < log_p_min)
                if bound.upper < log_p_min:
                    seen["proven"] += 1
                    seen["proven_finite"] += int(np.isfinite(r).any())
                    assert not check.feasible.any(), (
                        f"{where}: U {bound.upper:.4f} < log p_min but a sampled pose is feasible")
    # the test is not vacuous: each kind of cell occurs
    assert seen["finite_r"] > 0, f"{name}: no cell with a pose that balances: {seen}"
    assert seen["geometry"] > 0, f"{name}: no cell excluded by geometry: {seen}"
    assert seen["feasible"] > 0, f"{name}: no cell with a feasible sampled pose: {seen}"
    assert seen["fast_proven"] > 0, f"{name}: the LP-free bounds proved no cell: {seen}"


def test_bound_shrinks_to_the_pose_value():
    """As the cell shrinks to a point, U tends to the centre pose's own r."""
    rng = np.random.default_rng(7)
    checked = 0
    for _name, scn in _caves()[:4]:
        p0 = np.array(scn.start_pose)
        for stance, tip in _stances(scn)[:3]:
            centres = p0 + rng.normal(0.0, 1.0, (6, 3)) * np.array([0.05, 0.05, 0.05])
            check = check_poses(scn, stance, centres, free_tip=tip, full=True)
            for centre, r in zip(centres, check.allocation.robustness, strict=True):
                if not (np.isfinite(r) and r > -20.0):
                    continue
                bound = cb.robustness_bound(scn, stance, centre, LATTICE_HALF * 1e-6, tip)
                assert bound.upper >= r - 1e-9, f"point cell at {centre}: U {bound.upper} < r {r}"
                assert bound.upper - r <= 1e-3 + 1e-4 * abs(r), (
                    f"{stance.ids} at {centre.tolist()}: U {bound.upper:.6f} for r {r:.6f}")
                checked += 1
                ups = [cb.robustness_bound(scn, stance, centre, LATTICE_HALF * s, tip).upper
                       for s in (1.0, 0.1, 0.01)]
                assert ups[0] >= ups[1] - 1e-6 >= ups[2] - 2e-6, (
                    f"{stance.ids} at {centre.tolist()}: U not shrinking with the cell: {ups}")
    assert checked >= 10, f"only {checked} poses with finite r"


def test_interval_helpers_contain_every_value():
    rng = np.random.default_rng(3)
    for _ in range(300):
        c = rng.uniform(-10.0, 10.0)
        h = rng.choice([rng.uniform(0.0, 0.1), rng.uniform(0.0, 4.0)])
        t = np.linspace(c - h, c + h, 2001)
        lo, hi = cb._angle_interval_cos(np.array(c), np.array(h))
        assert lo <= np.cos(t).min() + 1e-12 and np.cos(t).max() <= hi + 1e-12, (c, h)
        assert hi - lo <= np.cos(t).max() - np.cos(t).min() + 1e-5, f"cos interval loose {c} {h}"
        lo, hi = cb._angle_interval_sin(np.array(c), np.array(h))
        assert lo <= np.sin(t).min() + 1e-12 and np.sin(t).max() <= hi + 1e-12, (c, h)


def test_taylor_model_remainder_holds():
    """|A(q) - A_0 - J (q - q_c)| <= E at poses sampled in cells of several sizes."""
    rng = np.random.default_rng(5)
    for _name, scn in _caves()[:3]:
        p0 = np.array(scn.start_pose)
        for stance, tip in _stances(scn)[:2]:
            for scale in (0.5, 2.0, 8.0):
                centre = p0 + rng.normal(0.0, 1.0, 3) * np.array([0.1, 0.1, 0.1])
                half = LATTICE_HALF * scale
                geo = cb.cell_geometry(scn.robot, stance, centre, half, tip)
                tm = cb.cell_taylor(scn.robot, stance, centre, half, geo)
                poses = _cell_samples(rng, centre, half)
                A = check_poses(scn, stance, poses, free_tip=tip, full=True).problem.A
                lin = tm.A0[None] + np.einsum("rik,pk->pri", tm.J, poses - centre)
                err = np.abs(A - lin)
                assert np.all(err <= tm.E[None] + 1e-12), (
                    f"remainder {err.max():.3g} over E at scale {scale}")
                cs = cb.cell_statics(scn.robot, scn.gravity_vector, stance, centre, half, geo)
                assert np.all(np.abs(A - cs.A_c[None]) <= cs.A_delta[None] + 1e-12)
                b = check_poses(scn, stance, poses, free_tip=tip, full=True).problem.b
                assert np.all(np.abs(b - cs.b_c[None]) <= cs.b_delta[None] + 1e-12), (
                    f"load outside its interval by {np.abs(b - cs.b_c).max():.3g}")


def test_split_proof_holds_for_every_sampled_pose():
    """cell_probability_excluded with splitting: no sampled pose of a proven cell has
    r >= log p_min, and splitting proves at least what the bound alone proves."""
    rng = np.random.default_rng(11)
    proven = {0: 0, 2: 0}
    for _name, scn in _caves()[:3]:
        p0 = np.array(scn.start_pose)
        stance = scn.stance(scn.start_stance)
        centres = p0 + rng.normal(0.0, 1.0, (12, 3)) * np.array([0.08, 0.08, 0.1])
        for centre in centres:
            half = LATTICE_HALF * 2.0
            r = check_poses(scn, stance, _cell_samples(rng, centre, half),
                            full=True).allocation.robustness
            plain = ce.cell_probability_excluded(scn, stance, centre, half)
            split = ce.cell_probability_excluded(scn, stance, centre, half, depth=2)
            assert split or not plain, f"{centre.tolist()}: splitting proved less"
            if split:
                assert np.all(r < scn.robot.log_p_min), (
                    f"{centre.tolist()}: proven, but a sampled pose has r {r.max():.4f}")
            proven[0] += plain
            proven[2] += split
    assert proven[2] >= proven[0] and proven[2] > 0, f"cells proven (by depth): {proven}"


def test_four_stance_bound_proves_much_of_what_the_lp_proves():
    """Usefulness: on 4-stance cells near the start of three caves, the LP-free bound proves at
    least half the cells `robustness_bound` proves (measured 76 %), and `probability_upper`
    proves exactly what either proves."""
    rng = np.random.default_rng(31)
    lp_proven = both = 0
    for _name, scn in _caves()[:3]:
        stance = scn.stance(scn.start_stance)
        log_p_min = scn.robot.log_p_min
        centres = np.array(scn.start_pose) + rng.uniform(-1.0, 1.0, (60, 3)) * np.array(
            [0.3, 0.3, 0.5])
        for centre in centres:
            geo = cb.cell_geometry(scn.robot, stance, centre, LATTICE_HALF)
            if cb.cell_geometry_excluded(scn.robot, stance, centre, LATTICE_HALF, None,
                                         geo) is not None:
                continue
            lp = cb.robustness_bound(scn, stance, centre, LATTICE_HALF, geo=geo).upper
            fast = ce.four_stance_bound(scn, stance, centre, LATTICE_HALF, geo=geo)
            either = ce.probability_upper(scn, stance, centre, LATTICE_HALF, geo=geo)
            assert (either < log_p_min) == (min(lp, fast) < log_p_min), (
                f"{centre.tolist()}: probability_upper {either}, LP {lp}, 4-stance {fast}")
            lp_proven += lp < log_p_min
            both += (lp < log_p_min) and (fast < log_p_min)
    assert lp_proven >= 20, f"too few cells proven to compare: {lp_proven}"
    assert both >= 0.5 * lp_proven, (
        f"the 4-stance bound proved {both} of the {lp_proven} cells the LP proves")


def test_three_stance_bound_proves_most_of_what_the_lp_proves():
    """Usefulness: on cells near the start of two caves, the LP-free 3-stance bound proves at
    least half the cells that `robustness_bound` proves (measured 55-82 %), and
    `probability_upper` (which tries it first) proves every one of them."""
    rng = np.random.default_rng(30)
    lp_proven = fast_proven = both = 0
    for _name, scn in _caves()[:2]:
        p0 = np.array(scn.start_pose)
        log_p_min = scn.robot.log_p_min
        for stance, tip in _stances(scn)[1:]:
            centres = p0 + rng.uniform(-1.0, 1.0, (40, 3)) * np.array([0.3, 0.3, 0.5])
            for centre in centres:
                geo = cb.cell_geometry(scn.robot, stance, centre, LATTICE_HALF, tip)
                if cb.cell_geometry_excluded(scn.robot, stance, centre, LATTICE_HALF, tip,
                                             geo) is not None:
                    continue
                lp = cb.robustness_bound(scn, stance, centre, LATTICE_HALF, tip, geo=geo).upper
                fast = ce.three_stance_bound(scn, stance, centre, LATTICE_HALF, tip,
                                             geo=geo).upper
                either = ce.probability_upper(scn, stance, centre, LATTICE_HALF, tip, geo=geo)
                assert (either < log_p_min) == (min(lp, fast) < log_p_min), (
                    f"{centre.tolist()}: probability_upper {either}, LP {lp}, 3-stance {fast}")
                lp_proven += lp < log_p_min
                fast_proven += fast < log_p_min
                both += (lp < log_p_min) and (fast < log_p_min)
    assert lp_proven >= 20, f"too few cells proven to compare: {lp_proven}"
    assert both >= 0.5 * lp_proven, (
        f"the 3-stance bound proved {both} of the {lp_proven} cells the LP proves")
