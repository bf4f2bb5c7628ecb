"""Seeded random caves: deterministic per seed, valid anchors and walls, a feasible start stance,
and files that load back (with the start check) unchanged.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import yaml

from rb_drake.collision import polygon_is_simple, signed_area
from rb_drake.feasibility import check_poses
from rb_drake.generate import KINDS, generate_cave
from rb_drake.params import RobotParams
from rb_drake.scenario import ANCHOR_DEPTH_TOL, Scenario, scenario_from_dict, scenario_to_yaml

SEEDS = (0, 1)
CASES = [(kind, seed) for kind in KINDS for seed in SEEDS]
CASE_IDS = [f"{kind}-{seed}" for kind, seed in CASES]
NORMAL_TOL = 1e-5   # generated normals are rounded to 6 decimals
DEPTH_TOL = 0.01    # m, an anchor may not sit deeper than this inside rock


@functools.cache
def cave(kind: str, seed: int) -> Scenario:
    """Generated once per (kind, seed) for the whole module: generation takes up to ~1 s."""
    return generate_cave(kind, seed)


def test_kinds():
    assert set(KINDS) == {"shaft", "crevasse", "rockfall"}, f"KINDS {KINDS}"


@pytest.mark.parametrize("kind", KINDS)
def test_same_seed_same_cave(kind):
    first = cave(kind, SEEDS[0])
    again = generate_cave(kind, SEEDS[0])
    assert again.to_dict() == first.to_dict(), f"{kind}: seed {SEEDS[0]} gave two caves"
    assert again.to_dict(resolved=True) == first.to_dict(resolved=True)
    assert again.source == first.source == f"generated:{kind}:{SEEDS[0]}"


@pytest.mark.parametrize("kind", KINDS)
def test_different_seeds_differ(kind):
    a, b = (cave(kind, s) for s in SEEDS)
    assert a.name != b.name, f"names {a.name!r} and {b.name!r}"
    da, db = a.to_dict(), b.to_dict()
    assert da["walls"] != db["walls"], f"{kind}: seeds {SEEDS} gave the same walls"
    assert da["anchors"] != db["anchors"], f"{kind}: seeds {SEEDS} gave the same anchors"


@pytest.mark.parametrize(("kind", "seed"), CASES, ids=CASE_IDS)
def test_start_pose_feasible(kind, seed):
    scn = cave(kind, seed)
    ids = scn.start_stance
    assert len(ids) == 4 and len(set(ids)) == 4, f"start stance {ids}"
    assert set(ids) <= set(scn.anchor_index), f"stance {ids} names unknown anchors"
    pose = np.array(scn.start_pose, dtype=float)
    assert pose.shape == (3,) and np.all(np.isfinite(pose)), f"start pose {pose}"
    check = check_poses(scn, scn.stance(ids), pose)
    assert check.feasible[0], f"{kind}-{seed}: start infeasible, reason {check.reason[0]!r}"
    p = float(check.probability[0])
    assert scn.robot.p_min <= p <= 1.0 + 1e-12, f"P = {p} below p_min {scn.robot.p_min}"
    lo, hi = scn.robot.boom_length
    assert np.all((check.lengths >= lo) & (check.lengths <= hi)), f"lengths {check.lengths}"
    t = check.allocation.tensions[0]
    t_lo, t_hi = scn.robot.boom_tension
    assert np.all((t >= t_lo - 1e-6) & (t <= t_hi + 1e-6)), f"tensions {t} out of bounds"


@pytest.mark.parametrize(("kind", "seed"), CASES, ids=CASE_IDS)
def test_anchors_valid(kind, seed):
    scn = cave(kind, seed)
    assert len(scn.anchors) >= 4, f"{len(scn.anchors)} anchors"
    ids = [a.id for a in scn.anchors]
    assert len(set(ids)) == len(ids), "duplicate anchor ids"
    pos, nrm = scn.anchor_positions, scn.anchor_normals
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))
    norms = np.linalg.norm(nrm, axis=1)
    assert np.allclose(norms, 1.0, rtol=0.0, atol=NORMAL_TOL), (
        f"normal norms off by up to {np.abs(norms - 1.0).max():.2e}")
    depth = np.where(scn.rock.contains(pos), scn.rock.distance(pos), 0.0)
    assert depth.max() <= DEPTH_TOL, (
        f"anchor {ids[int(depth.argmax())]} is {depth.max():.4f} m inside rock")
    assert DEPTH_TOL <= ANCHOR_DEPTH_TOL, "the loader is stricter than this test"
    facing_in = scn.rock.contains(pos + 0.05 * nrm)
    assert not facing_in.any(), f"normals point into rock at {np.array(ids)[facing_in]}"
    near = scn.rock.distance(pos)
    assert near.max() <= 0.05, f"an anchor floats {near.max():.3f} m away from the rock"
    for a in scn.anchors:
        assert a.f_normal > 0 and a.f_lateral > 0, f"anchor {a.id}: limits {a}"
        assert a.sigma_normal > 0 and a.sigma_lateral > 0, f"anchor {a.id}: sigmas {a}"
        assert a.f_lateral < a.f_normal, f"anchor {a.id}: lateral limit over normal limit"


@pytest.mark.parametrize(("kind", "seed"), CASES, ids=CASE_IDS)
def test_walls_counter_clockwise_and_simple(kind, seed):
    scn = cave(kind, seed)
    assert len(scn.walls) >= 2, f"{len(scn.walls)} walls"
    for k, wall in enumerate(scn.walls):
        assert wall.ndim == 2 and wall.shape[1] == 2 and len(wall) >= 3, f"walls[{k}] {wall.shape}"
        assert signed_area(wall) > 1e-6, f"walls[{k}]: signed area {signed_area(wall)}"
        simple, why = polygon_is_simple(wall)
        assert simple, f"walls[{k}] is not simple: {why}"
    assert not scn.rock.contains(np.array(scn.goal_position)), "the goal is inside rock"
    assert not scn.rock.contains(np.array(scn.start_pose[:2])), "the start is inside rock"


@pytest.mark.parametrize(("kind", "seed"), CASES, ids=CASE_IDS)
def test_yaml_round_trip(kind, seed):
    scn = cave(kind, seed)
    text = scenario_to_yaml(scn)
    back = scenario_from_dict(yaml.safe_load(text), source=f"{kind}-{seed}.yaml",
                              check_start=True)
    assert back.name == scn.name and back.gravity == scn.gravity
    assert back.robot == scn.robot, f"robot {back.robot} != {scn.robot}"
    assert len(back.walls) == len(scn.walls)
    for k, (wa, wb) in enumerate(zip(scn.walls, back.walls, strict=True)):
        assert np.array_equal(wa, wb), f"walls[{k}] changed in the round trip"
    assert [a.id for a in back.anchors] == [a.id for a in scn.anchors]
    assert np.array_equal(back.anchor_positions, scn.anchor_positions)
    assert np.allclose(back.anchor_normals, scn.anchor_normals, rtol=0.0, atol=NORMAL_TOL)
    for a, b in zip(scn.anchors, back.anchors, strict=True):
        assert (a.f_normal, a.f_lateral, a.sigma_normal, a.sigma_lateral) == (
            b.f_normal, b.f_lateral, b.sigma_normal, b.sigma_lateral), f"anchor {a.id}"
    assert back.start_pose == scn.start_pose and back.start_stance == scn.start_stance
    assert back.goal_position == scn.goal_position
    assert back.goal_tolerance == scn.goal_tolerance


@pytest.mark.parametrize("kind", ["volcano", "", "Shaft", "shafts"])
def test_unknown_kind_refused(kind):
    with pytest.raises(ValueError, match="kind: must be one of"):
        generate_cave(kind, 0)


def test_custom_robot_survives_round_trip():
    robot = RobotParams(body_mass=2.5, p_min=0.9)
    scn = generate_cave("crevasse", 3, robot=robot)
    assert scn.robot == robot
    back = scenario_from_dict(yaml.safe_load(scenario_to_yaml(scn)), check_start=False)
    assert back.robot == robot, f"loaded robot {back.robot}, generated with {robot}"


def _simple_by_all_pairs(poly: np.ndarray) -> tuple[bool, str]:
    """polygon_is_simple's n x n test, as it was: the reference for the sweep."""
    from rb_drake.collision import _segments_cross

    n, q = len(poly), np.roll(poly, -1, axis=0)
    if np.any(np.linalg.norm(q - poly, axis=1) < 1e-12):
        return False, "has a repeated vertex (an edge of zero length)"
    idx = np.arange(n)
    gap = np.abs(idx[:, None] - idx[None, :])
    bad = np.argwhere(_segments_cross(poly, q, poly, q) & ~((gap <= 1) | (gap == n - 1)))
    if len(bad):
        return False, f"edges {bad[0][0]} and {bad[0][1]} intersect (the polygon crosses itself)"
    return (False, "has zero area") if abs(signed_area(poly)) < 1e-12 else (True, "")


def test_polygon_is_simple_sweep_matches_all_pairs_and_scales(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The sweep gives the n x n test's answer and message (touching, collinear and crossing
    edges on a small lattice, random and star polygons), and on a 50,000-vertex wall (the
    drawings' limit; the n x n test took 3.2 s and 1.2 GB at 5,000) it tests a few pairs of
    edges per edge, counted (a time would depend on the machine), not n^2 / 2."""
    import rb_drake.collision as collision
    from rb_drake.collision import _first_crossing

    rng = np.random.default_rng(0)
    for trial in range(1500):
        n = int(rng.integers(3, 25))
        if trial % 3 == 0:
            poly = rng.integers(0, 4, (n, 2)).astype(float)
        elif trial % 3 == 1:
            poly = rng.normal(size=(n, 2))
        else:
            angle = np.sort(rng.uniform(0, 2 * np.pi, n))
            poly = rng.uniform(0.5, 1.0, (n, 1)) * np.c_[np.cos(angle), np.sin(angle)]
        assert polygon_is_simple(poly) == _simple_by_all_pairs(poly), poly.tolist()
        q = np.roll(poly, -1, axis=0)
        assert _first_crossing(poly, q, block=3) == _first_crossing(poly, q), poly.tolist()
    t = np.linspace(0, 2 * np.pi, 50_000, endpoint=False)
    wall = (1 + 0.01 * np.sin(300 * t))[:, None] * np.c_[np.cos(t), 40 * np.sin(t)]
    tested = []
    orient = collision._orient

    def counted(*args):
        tested.append(len(args[0]))
        return orient(*args)

    monkeypatch.setattr(collision, "_orient", counted)
    assert polygon_is_simple(wall) == (True, "")
    wall[25_000] = wall[10]  # a spike across the wall
    assert polygon_is_simple(wall)[1].startswith("edges ")
    pairs = sum(tested) // 4  # _orient is called four times per batch of pairs
    assert 0 < pairs < 100 * len(wall), f"{pairs:,} pairs of edges tested for {len(wall):,}"
