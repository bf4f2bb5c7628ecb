"""Seed trajectories (planning.seeds): body_seed, reach_seed, tip_arc, subdivide.

Every returned seed is verified independently: each configuration re-checked with
`rb_drake.feasibility.check_poses` (reach phases one configuration at a time, with the documented
single free tip), exact endpoints, the step bounds between successive configurations, and a
collision-free tip path. Body cases are pose pairs in conftest's shaft (one whose straight line
leaves the feasible set, solved by local sampling and, with local sampling switched off, by
OMPL) and a shaft with a rock post between two poses that no path joins (every boom is a tether
to its anchor, so the body cannot go around the post). Reach cases are the feasible transitions
from the wide-shaft test cave's start stance, and one demo-shaft transition whose pose cannot be
held for the whole arc.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from planning import reach_seeds
from planning.body_seeds import _ReachFilter
from planning.footsteps import candidate_moves, edge_rng
from planning.seeds import (
    Seed,
    SeedConfig,
    body_seed,
    reach_seed,
    retract_path,
    subdivide,
    tip_arc,
)
from planning.transition import find_transition
from rb_drake import geometry
from rb_drake.collision import Rock
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import Reason, check_poses
from rb_drake.scenario import Scenario, load_scenario, scenario_from_dict

STEP_TOL = 1e-9       # m or rad over the step bounds
PROB_RTOL = 1e-9
CFG = SeedConfig()
OMPL_ONLY = SeedConfig(local_rounds=0)  # RRTConnect stops once solved (~0.1 s)
# Both poses feasible in the shaft's start stance; the straight line between them is not.
BLOCKED_PAIR = (np.array([0.774, 1.182, 0.272]), np.array([0.206, 1.134, 0.106]))
POST = [[-0.05, 0.95], [0.05, 0.95], [0.05, 1.05], [-0.05, 1.05]]
# Either side of POST: both feasible with the post, the straight line through it.
SEPARATED_PAIR = (np.array([-0.35, 1.0, 0.0]), np.array([0.35, 1.0, 0.0]))
Move = tuple[int, str]


def straight_line(scn: Scenario, stance_ids: tuple[str, ...], start: np.ndarray,
                  goal: np.ndarray) -> np.ndarray:
    """Feasibility of the straight line between two poses at the seed resolution."""
    line = np.linspace(start, goal, 200)
    return check_poses(scn, scn.stance(stance_ids), line).feasible


def assert_steps(seed: Seed, cfg: SeedConfig) -> None:
    d = np.diff(seed.poses, axis=0)
    moved = np.linalg.norm(d[:, :2], axis=1)
    turned = np.abs(geometry.wrap_angle(d[:, 2]))
    assert moved.max() <= cfg.step + STEP_TOL, f"body moved {moved.max():.4f} m in one step"
    assert turned.max() <= cfg.turn_step + STEP_TOL, f"body turned {turned.max():.4f} rad"
    if seed.tips is not None:
        tip_moved = np.linalg.norm(np.diff(seed.tips, axis=0), axis=1).max()
        assert tip_moved <= cfg.step + STEP_TOL, f"tip moved {tip_moved:.4f} m in one step"


def assert_body_seed(scn: Scenario, stance_ids: tuple[str, ...], seed: Seed, start: np.ndarray,
                     goal: np.ndarray, cfg: SeedConfig = CFG) -> None:
    assert seed.success, f"body seed failed: {seed.reason}"
    assert seed.reason == "", seed.reason
    assert seed.tips is None, "a body seed has no free tip"
    n = len(seed.poses)
    assert n >= 2 and seed.poses.shape == (n, 3) and seed.log_probs.shape == (n,), (
        f"shapes {seed.poses.shape}, {seed.log_probs.shape}")
    np.testing.assert_array_equal(seed.poses[0], start, err_msg="does not start at start_pose")
    np.testing.assert_array_equal(seed.poses[-1], goal, err_msg="does not end at goal_pose")
    assert_steps(seed, cfg)
    check = check_poses(scn, scn.stance(stance_ids), seed.poses)
    bad = np.flatnonzero(~check.feasible)
    assert not len(bad), (f"pose {bad[0]} {seed.poses[bad[0]]} infeasible: "
                          f"{Reason(int(check.reason[bad[0]])).name}")
    np.testing.assert_allclose(seed.log_probs, check.allocation.robustness, rtol=PROB_RTOL,
                               err_msg="log_probs differ from check_poses' robustness")
    p_min = scn.robot.p_min
    assert np.exp(seed.log_probs).min() >= p_min, f"P below p_min {p_min}"


def assert_same(a: Seed, b: Seed) -> None:
    assert (a.success, a.method, a.reason) == (b.success, b.method, b.reason), (a, b)
    np.testing.assert_array_equal(a.poses, b.poses, err_msg="same seed, different poses")
    np.testing.assert_array_equal(a.log_probs, b.log_probs, err_msg="same seed, different P")
    if a.tips is not None:
        np.testing.assert_array_equal(a.tips, b.tips, err_msg="same seed, different tips")


# ---------------------------------------------------------------------------------------------
# subdivide


def test_subdivide_keeps_waypoints_and_bounds_steps() -> None:
    w = np.array([[0.0, 0.0, 0.0, 1.0, 1.0], [0.3, 0.1, 0.05, 1.0, 1.0],
                  [0.3, 0.1, 0.5, 1.0, 1.0], [0.3, 0.1, 0.5, 1.5, 1.2]])
    out = subdivide(w, 0.02, 0.03)
    for k, p in enumerate(w):
        assert np.any(np.all(out == p, axis=1)), f"waypoint {k} {p} not kept exactly"
    d = np.diff(out, axis=0)
    assert np.linalg.norm(d[:, :2], axis=1).max() <= 0.02 + STEP_TOL
    assert np.abs(d[:, 2]).max() <= 0.03 + STEP_TOL
    assert np.linalg.norm(d[:, 3:], axis=1).max() <= 0.02 + STEP_TOL
    # no more parts than needed: each piece's count is ceil(its largest ratio)
    expected = 1 + sum(int(np.ceil(max(np.hypot(*s[:2]) / 0.02, abs(s[2]) / 0.03,
                                       np.hypot(*s[3:]) / 0.02))) for s in np.diff(w, axis=0))
    assert len(out) == expected, f"{len(out)} configurations, expected {expected}"


# ---------------------------------------------------------------------------------------------
# body_seed


def test_straight_body_seed(shaft: Scenario) -> None:
    ids = shaft.start_stance
    start, goal = np.array(shaft.start_pose), np.array([0.2, 1.25, 0.06])
    assert straight_line(shaft, ids, start, goal).all(), "precondition: the line is feasible"
    seed = body_seed(shaft, ids, start, goal)
    assert seed.method == "straight", seed.method
    assert_body_seed(shaft, ids, seed, start, goal)
    # the straight line itself, with the fewest steps the bounds allow
    d = goal - start
    n = int(np.ceil(max(np.hypot(*d[:2]) / CFG.step, abs(d[2]) / CFG.turn_step))) + 1
    assert len(seed.poses) == n, f"{len(seed.poses)} poses, expected {n}"
    off_line = np.abs(geometry.cross2(seed.poses[:, :2] - start[:2], d[:2])) / np.hypot(*d[:2])
    assert off_line.max() < 1e-12, f"poses leave the straight line by {off_line.max()} m"


@pytest.fixture(scope="module")
def blocked_local(shaft: Scenario) -> Seed:
    return body_seed(shaft, shaft.start_stance, *BLOCKED_PAIR, seed=3)


@pytest.fixture(scope="module")
def blocked_ompl(shaft: Scenario) -> Seed:
    return body_seed(shaft, shaft.start_stance, *BLOCKED_PAIR, OMPL_ONLY,
                     seed=3)


def test_blocked_straight_line_solved_by_local_sampling(shaft: Scenario,
                                                        blocked_local: Seed) -> None:
    ids = shaft.start_stance
    line = straight_line(shaft, ids, *BLOCKED_PAIR)
    assert line[[0, -1]].all() and not line.all(), "precondition: only the line is infeasible"
    assert blocked_local.method in ("local", "ompl"), blocked_local.method
    assert_body_seed(shaft, ids, blocked_local, *BLOCKED_PAIR)


def test_blocked_straight_line_solved_by_ompl(shaft: Scenario, blocked_ompl: Seed) -> None:
    assert blocked_ompl.method == "ompl", (blocked_ompl.method, blocked_ompl.reason)
    assert_body_seed(shaft, shaft.start_stance, blocked_ompl, *BLOCKED_PAIR)


def test_body_seed_deterministic(shaft: Scenario, blocked_local: Seed,
                                 blocked_ompl: Seed) -> None:
    ids = shaft.start_stance
    assert_same(blocked_local, body_seed(shaft, ids, *BLOCKED_PAIR, seed=3))
    assert_same(blocked_ompl, body_seed(shaft, ids, *BLOCKED_PAIR, OMPL_ONLY,
                                        seed=3))


def test_ompl_seed_does_not_depend_on_the_machines_speed(shaft: Scenario, blocked_ompl: Seed,
                                                         monkeypatch) -> None:
    """RRTConnect stops on the poses it checked, not on the clock: with every check 50 ms
    slower (a loaded machine; the 0.5 s it had before ended its search after 10 checks, with
    no path) the same seed gives the same path."""
    import time

    import planning.body_seeds as body_seeds

    def slow_check(*args, **kwargs):
        time.sleep(0.05)
        return check_poses(*args, **kwargs)

    monkeypatch.setattr(body_seeds, "check_poses", slow_check)
    slowed = body_seed(shaft, shaft.start_stance, *BLOCKED_PAIR, OMPL_ONLY, seed=3)
    assert slowed.method == "ompl", (slowed.method, slowed.reason)
    assert_same(blocked_ompl, slowed)


def test_ompl_seed_budget_is_checked() -> None:
    for bad in (0, -5, 2.5, True, 10**18):
        with pytest.raises(RbpInputError, match=r"seed\.ompl_checks"):
            SeedConfig(ompl_checks=bad)
    with pytest.raises(RbpInputError, match=r"seed\.ompl_time"):
        SeedConfig(ompl_time=0.0)


def test_rock_between_poses_fails_with_reason(make_scenario) -> None:
    scn = make_scenario(extra_walls=[POST])
    ids = scn.start_stance
    start, goal = SEPARATED_PAIR
    stance = scn.stance(ids)
    line = np.linspace(start, goal, 200)
    check = check_poses(scn, stance, line)
    assert check.feasible[[0, -1]].all(), "precondition: both poses feasible next to the post"
    assert Reason.BODY_COLLISION in check.reason, "precondition: the body hits the post"
    seed = body_seed(scn, ids, start, goal, SeedConfig(ompl_checks=300))
    assert not seed.success and seed.method == "", f"a path around the post: {seed.method}"
    assert seed.poses.shape == (0, 3) and seed.log_probs.shape == (0,), seed
    for words in ("straight line infeasible", "collides with rock", "local samples", "OMPL"):
        assert words in seed.reason, f"{words!r} not in reason {seed.reason!r}"


@pytest.mark.parametrize("which", ["start", "goal"])
def test_infeasible_endpoint_named(shaft: Scenario, which: str) -> None:
    good, bad = np.array(shaft.start_pose), np.array([0.0, 1.0, 0.9])  # shoulders over range
    start, goal = (bad, good) if which == "start" else (good, bad)
    seed = body_seed(shaft, shaft.start_stance, start, goal)
    assert not seed.success, "an infeasible endpoint was accepted"
    assert seed.reason.startswith(f"{which} pose infeasible"), seed.reason
    assert "shoulder angle" in seed.reason, seed.reason


def test_ompl_reach_filter_matches_geometry(shaft: Scenario) -> None:
    """The scalar pre-filter of OMPL's checker rejects exactly the poses out of reach."""
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(-0.8, 0.8, 2000), rng.uniform(0.3, 1.8, 2000),
                             rng.uniform(-0.8, 0.8, 2000)])
    stance = shaft.stance(shaft.start_stance)
    expected = geometry.reach(shaft.robot, poses, stance.positions,
                              np.arange(4)).violation.max(axis=1) == 0.0
    assert expected.any() and not expected.all(), "precondition: both kinds of pose sampled"
    reach = _ReachFilter(shaft, stance)
    got = np.array([reach(*p) for p in poses])
    wrong = np.flatnonzero(got != expected)
    assert not len(wrong), f"{len(wrong)} poses judged differently, e.g. {poses[wrong[0]]}"


# ---------------------------------------------------------------------------------------------
# tip_arc


# (start, its normal, end, its normal) as on cave walls: up one wall, across a shaft, wall to
# ceiling
ARC_CASES = [([1.2, 0.3], [-1.0, 0.0], [1.1, 1.4], [-1.0, 0.0]),
             ([1.2, 0.3], [-1.0, 0.0], [-1.2, 1.4], [1.0, 0.0]),
             ([1.2, 0.3], [-1.0, 0.0], [0.5, 2.0], [-0.6, -0.8])]


@pytest.mark.parametrize("case", ARC_CASES)
def test_tip_arc_shape(case) -> None:
    a, na, b, nb = (np.array(v, dtype=float) for v in case)
    height, n = 0.2, 80
    tips = tip_arc(a, b, na, nb, height, n)
    assert tips.shape == (n, 2), tips.shape
    np.testing.assert_array_equal(tips[[0, -1]], [a, b], err_msg="arc ends off the anchors")
    gaps = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    assert gaps.max() / gaps.min() < 1.02, f"uneven spacing {gaps.min()} .. {gaps.max()}"
    m = na + nb
    m = m if np.linalg.norm(m) > 0.1 else np.array([-(b - a)[1], (b - a)[0]])
    m = m / np.linalg.norm(m)
    # its bulge along m over the chord is `height` (the vertex of the parabola)
    t = np.linalg.lstsq(np.column_stack([b - a, m]), (tips - a).T, rcond=None)[0][1]
    assert abs(t.max() - height) < 2e-3, f"bulge {t.max():.4f} m, asked {height} m"
    assert (tips[1] - a) @ na > 0, "the arc does not leave the start anchor's rock"
    assert (tips[-2] - b) @ nb > 0, "the arc does not come back from in front of the rock"


# ---------------------------------------------------------------------------------------------
# reach_seed


@pytest.fixture(scope="module")
def wide() -> Scenario:
    return load_scenario(Path(__file__).parent / "data" / "wide-shaft.yaml")


def transition(scn: Scenario, move: Move) -> np.ndarray:
    stance, (j, a) = scn.start_stance, move
    tr = find_transition(scn, stance, j, a, edge_rng(0, stance, j, a),
                         guess=np.asarray(scn.start_pose, dtype=float))
    assert tr.feasible, f"precondition: boom {j} -> {a} should be feasible: {tr.reason}"
    return tr.pose


@pytest.fixture(scope="module")
def wide_reaches(wide: Scenario) -> dict[Move, tuple[np.ndarray, Seed]]:
    """reach_seed for every feasible move from the wide shaft's start stance."""
    stance = wide.start_stance
    out = {}
    for j, a in candidate_moves(wide, stance, np.asarray(wide.start_pose, dtype=float),
                                per_boom=6, seed=0):
        tr = find_transition(wide, stance, j, a, edge_rng(0, stance, j, a),
                             guess=np.asarray(wide.start_pose, dtype=float))
        if tr.feasible:
            out[(j, a)] = tr.pose, reach_seed(wide, stance, j, a, tr.pose)
    assert len(out) >= 3, f"only {len(out)} feasible moves from the wide-shaft start"
    return out


def assert_reach_seed(scn: Scenario, move: Move, pose: np.ndarray, seed: Seed) -> None:
    j, anchor = move
    ids = scn.start_stance
    assert seed.success, f"boom {j} -> {anchor}: {seed.reason}"
    n = len(seed.poses)
    assert n >= 2 and seed.tips is not None and seed.tips.shape == (n, 2), seed.tips
    old = scn.anchor_positions[scn.anchor_index[ids[j]]]
    new = scn.anchor_positions[scn.anchor_index[anchor]]
    np.testing.assert_array_equal(seed.tips[[0, -1]], [old, new], err_msg="tip ends off anchors")
    np.testing.assert_array_equal(seed.poses[[0, -1]], [pose, pose],
                                  err_msg="the body does not start and end at the transition")
    assert_steps(seed, CFG)
    # every configuration on its own, with the documented single free tip
    three = scn.stance(ids).without(j)
    for k in range(n):
        c = check_poses(scn, three, seed.poses[k], seed.tips[k])
        assert c.feasible[0], (f"boom {j} -> {anchor}: configuration {k} (pose {seed.poses[k]}, "
                               f"tip {seed.tips[k]}) {Reason(int(c.reason[0])).name}")
        np.testing.assert_allclose(seed.log_probs[k], c.allocation.robustness[0], rtol=PROB_RTOL,
                                   err_msg=f"configuration {k}: log_probs differ")
    assert np.exp(seed.log_probs).min() >= scn.robot.p_min, "P below p_min"
    # the tip path stays off the rock between the anchors it grips
    inner = seed.tips[1:-1]
    assert not scn.rock.contains(inner).any(), "a tip position inside rock"
    assert not scn.rock.segments_hit(inner[:-1], inner[1:]).any(), "the tip path crosses rock"


def test_reach_seeds_from_wide_shaft_start(wide: Scenario, wide_reaches) -> None:
    for move, (pose, seed) in wide_reaches.items():
        assert_reach_seed(wide, move, pose, seed)
        if seed.method == "hold":
            assert np.all(seed.poses == pose), f"{move}: 'hold' but the body moves"


def test_reach_seed_deterministic(wide: Scenario, wide_reaches) -> None:
    for (j, a), (pose, seed) in list(wide_reaches.items())[:3]:
        assert_same(seed, reach_seed(wide, wide.start_stance, j, a, pose))


def test_reach_seed_sways_when_pose_cannot_be_held() -> None:
    """Demo shaft, boom 2 to a3: at the transition pose some tip positions on the arc leave the
    3-stance unbalanced; the body must move along the arc and come back."""
    scn = load_scenario(Path(__file__).parents[1] / "rb_drake" / "data" / "caves"
                        / "demo-shaft.yaml")
    move = (2, "a3")
    three = scn.stance(scn.start_stance).without(2)
    # Transition poses differ by generator; take the first that cannot be held along the arc.
    for k in range(20):
        tr = find_transition(scn, scn.start_stance, *move, np.random.default_rng(k),
                             guess=np.asarray(scn.start_pose, dtype=float))
        if not tr.feasible:
            continue
        pose = tr.pose
        seed = reach_seed(scn, scn.start_stance, *move, pose, seed=1)
        held = check_poses(scn, three, np.broadcast_to(pose, (len(seed.tips), 3)), seed.tips)
        if not held.feasible.all():
            break
    else:
        raise AssertionError("precondition: every transition pose found can be held along the "
                             "whole arc")
    assert_reach_seed(scn, move, pose, seed)
    assert seed.method == "local", seed.method
    assert np.abs(seed.poses - pose).max() > 0.0, "'local' but the body never moves"
    assert_same(seed, reach_seed(scn, scn.start_stance, *move, pose, seed=1))


def test_reach_seed_infeasible_transition_pose_named(wide: Scenario, wide_reaches) -> None:
    (j, a), (pose, _) = next(iter(wide_reaches.items()))
    far = pose + np.array([0.0, 0.8, 0.0])
    seed = reach_seed(wide, wide.start_stance, j, a, far)
    assert not seed.success and seed.method == "", seed
    assert seed.tips is not None and seed.tips.shape == (0, 2), seed.tips
    assert seed.reason.startswith("transition pose with the tip at the old anchor infeasible"), (
        seed.reason)


def test_reach_seed_without_clear_arc(wide: Scenario, wide_reaches, monkeypatch) -> None:
    """A rock block over the arc's middle: the gripper retracts round it; with the retracted
    swing blocked too, no tip path is clear and the reason says so."""
    (j, a), (pose, _) = next(iter(wide_reaches.items()))
    old = wide.anchor_positions[wide.anchor_index[wide.start_stance[j]]]
    new = wide.anchor_positions[wide.anchor_index[a]]
    cfg = SeedConfig(arc_heights=(0.1,))
    tips = tip_arc(old, new, wide.anchor_normals[wide.anchor_index[wide.start_stance[j]]],
                   wide.anchor_normals[wide.anchor_index[a]], 0.1 * np.linalg.norm(new - old), 50)
    mid = tips[25]
    block = mid + 0.01 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    assert Rock([block]).contains(mid), "precondition: the block covers the arc's middle"

    data = wide.to_dict()
    data["walls"].append(block.tolist())
    blocked = scenario_from_dict(data, source="<wide-shaft + block>", check_start=False)
    # The arc is blocked, so the gripper retracts along its boom, swings, and extends.
    seed = reach_seed(blocked, wide.start_stance, j, a, pose, cfg)
    assert seed.success, seed.reason
    assert not Rock([block]).segments_hit(seed.tips[:-1], seed.tips[1:]).any(), (
        "the tip path crosses the block")
    # Block the retracted swing as well (one radius tried, mid-swing): no tip path is clear.
    monkeypatch.setattr(reach_seeds, "RETRACT_RADII", (0.2,))  # where reach_seed reads it
    shoulder = geometry.shoulder_positions(wide.robot, pose)[0, j]
    for radius in reach_seeds.RETRACT_RADII:
        swing = retract_path(old, new, shoulder, radius, cfg.step)
        on = np.flatnonzero(np.isclose(np.linalg.norm(swing - shoulder, axis=1), radius))
        mid = swing[on[len(on) // 2]]
        data["walls"].append((mid + 0.004 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
                              ).tolist())
    both = scenario_from_dict(data, source="<wide-shaft + blocks>", check_start=False)
    seed = reach_seed(both, wide.start_stance, j, a, pose, cfg)
    assert not seed.success, f"a tip path through the blocks was accepted: {seed.method}"
    assert "no collision-free tip path" in seed.reason, seed.reason


def test_retract_path_runs_anchor_to_anchor_round_the_shoulder() -> None:
    a, b, shoulder = np.array([1.0, 0.0]), np.array([0.0, 1.2]), np.array([0.1, 0.1])
    step, radius = 0.05, 0.1
    tips = retract_path(a, b, shoulder, radius, step)
    assert np.allclose(tips[0], a) and np.allclose(tips[-1], b), (tips[0], tips[-1])
    gaps = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    assert gaps.max() <= step + 1e-9, f"tip steps up to {gaps.max():.4f} m > {step}"
    distance = np.linalg.norm(tips - shoulder, axis=1)
    assert distance.min() == pytest.approx(radius, abs=1e-9), distance.min()
    # the tip never goes further from the shoulder than the farther anchor
    assert distance.max() <= max(np.linalg.norm(a - shoulder), np.linalg.norm(b - shoulder)) + 1e-9


def test_a_gripper_path_may_touch_its_own_rock_only_in_its_last_2_cm() -> None:
    """The tip path's rule is the boom's (rb_drake.collision): within ANCHOR_CLEARANCE of the
    anchor it grips, the gripper may touch the rock; any further out, it may not."""
    from types import SimpleNamespace

    from planning.reach_seeds import _arc_is_clear
    from rb_drake.collision import ANCHOR_CLEARANCE

    # A floor block with its top at y = 0; the anchor at the origin, normal up. The path comes
    # down to the anchor along a line that dips below the floor `depth_at` metres before it.
    world = SimpleNamespace(rock=Rock([np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 0.0],
                                                 [-1.0, 0.0]])]))
    up, anchor = np.array([0.0, 1.0]), np.array([0.0, 0.0])
    for before, clear in ((0.5 * ANCHOR_CLEARANCE, True), (2.5 * ANCHOR_CLEARANCE, False)):
        dip = np.array([before, -0.002])  # 2 mm into the rock, `before` from the anchor
        tips = np.array([[0.5, 0.5], [before + 0.05, 0.01], dip, anchor])
        assert _arc_is_clear(world, tips, up, up) is clear, (
            f"a path dipping into rock {before * 100:.0f} cm before its anchor: clear should "
            f"be {clear}")


def test_local_sampling_at_the_configuration_maxima_checks_in_bounded_batches(
        shaft: Scenario, monkeypatch: pytest.MonkeyPatch) -> None:
    """The largest local sampling a configuration may ask (16 rounds of 100 samples, 100
    modes, the spread doubling each round to 1.6 km, 5 mm steps) once built detours of millions of
    poses and checked them in one call (gigabytes): detours over MAX_DETOUR_POSES are not
    tried, and no check sees more than a batch."""
    from planning import body_seeds

    sizes: list[int] = []

    def counted(scn: Scenario, stance: object, configs: np.ndarray) -> SimpleNamespace:
        sizes.append(len(configs))  # all infeasible: every round runs
        n = len(configs)
        return SimpleNamespace(feasible=np.zeros(n, bool),
                               allocation=SimpleNamespace(robustness=np.zeros(n)))

    monkeypatch.setattr(body_seeds, "check_configurations", counted)
    cfg = SeedConfig(local_rounds=16, local_samples=100, local_modes=100, local_spread=0.05,
                     step=0.005, turn_step=0.005)
    stance = shaft.stance(shaft.start_stance)
    line = subdivide(np.vstack(BLOCKED_PAIR), cfg.step, cfg.turn_step)
    assert body_seeds._local(shaft, stance, line, cfg, np.random.default_rng(0)) is None
    assert sizes and max(sizes) <= body_seeds.CHECK_BATCH + body_seeds.MAX_DETOUR_POSES
