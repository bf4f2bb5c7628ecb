"""Transition feasibility (planning.transition): find_transition and reachable_anchors.

Feasible transitions are taken from the wide-shaft test cave's start stance (the moves
`planning.footsteps.candidate_moves` proposes, each searched with its own `edge_rng`), and every
accepted pose is re-checked independently with `rb_drake.feasibility.check_poses` in the four
configurations of the move. Rejections use anchors added to the scenario: one far out of reach,
and a "weak" twin of a feasible target (same place, a limit surface of 1 N / 0.5 N).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planning.footsteps import candidate_moves, edge_rng
from planning.transition import (
    CONFIG_NAMES,
    Transition,
    TransitionConfig,
    find_transition,
    polish_transition,
    reachable_anchors,
    transition_stances,
)
from rb_drake.feasibility import PoseCheck, Reason, check_poses
from rb_drake.scenario import Scenario, load_scenario, scenario_from_dict

SEED = 0
PROB_RTOL = 1e-9
WEAK_LIMIT = {"normal": 1.0, "lateral": 0.5}
Move = tuple[int, str]


def with_anchors(scn: Scenario, *anchors: dict[str, Any]) -> Scenario:
    """`scn` with extra anchors, through the validating parser (each must sit on a wall)."""
    data = scn.to_dict()
    data["anchors"] = data["anchors"] + [dict(a) for a in anchors]
    return scenario_from_dict(data, source=f"<{scn.name} + extra anchors>", check_start=False)


def twin(scn: Scenario, anchor_id: str, new_id: str, limit: dict[str, float]) -> dict[str, Any]:
    """An anchor at `anchor_id`'s place and normal with a different limit surface."""
    a = scn.anchors[scn.anchor_index[anchor_id]].to_dict()
    return {**a, "id": new_id, "limit": dict(limit)}


def search(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
           config: TransitionConfig | None = None, seed: int = SEED) -> Transition:
    return find_transition(scn, stance, boom, anchor, edge_rng(seed, stance, boom, anchor),
                           guess=np.asarray(scn.start_pose, dtype=float), config=config)


def four_checks(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
                pose: np.ndarray, ignore_grasps: bool = False) -> list[PoseCheck]:
    """check_poses at `pose` in the move's four configurations, CONFIG_NAMES order."""
    s_old, s_three, s_new = transition_stances(scn, stance, boom, anchor)
    return [check_poses(scn, s_old, pose, ignore_grasps=ignore_grasps),
            check_poses(scn, s_three, pose, s_old.positions[boom], ignore_grasps=ignore_grasps),
            check_poses(scn, s_three, pose, s_new.positions[boom], ignore_grasps=ignore_grasps),
            check_poses(scn, s_new, pose, ignore_grasps=ignore_grasps)]


def reasons(checks: list[PoseCheck]) -> list[str]:
    return [Reason(int(c.reason[0])).name for c in checks]


@pytest.fixture(scope="module")
def demo() -> Scenario:
    # A fixed copy (tests/data), so that regenerating the bundled caves cannot move these cases.
    return load_scenario(Path(__file__).parent / "data" / "wide-shaft.yaml")


@pytest.fixture(scope="module")
def start_moves(demo: Scenario) -> dict[Move, Transition]:
    """Every candidate move from the demo-shaft's start stance, searched once."""
    stance = demo.start_stance
    moves = candidate_moves(demo, stance, np.asarray(demo.start_pose, dtype=float), per_boom=6,
                            seed=SEED)
    assert moves, "candidate_moves proposed nothing from the demo-shaft start"
    return {(j, a): search(demo, stance, j, a) for j, a in moves}


@pytest.fixture(scope="module")
def feasible_move(start_moves: dict[Move, Transition]) -> Move:
    """A feasible move of boom 2 (a lower boom: usually feasible) from the start stance."""
    ok = [m for m, tr in start_moves.items() if tr.feasible and m[0] == 2]
    assert ok, f"no feasible boom-2 move from the demo-shaft start among {list(start_moves)}"
    return ok[0]


# ---------------------------------------------------------------------------------------------
# (a) accepted transitions, verified independently


def test_some_lower_boom_moves_are_feasible(start_moves: dict[Move, Transition]) -> None:
    lower = [m for m, tr in start_moves.items() if tr.feasible and m[0] in (2, 3)]
    assert len(lower) >= 2, f"feasible lower-boom moves: {lower} (of {list(start_moves)})"
    for move, tr in start_moves.items():
        if tr.feasible:
            assert tr.reason == "", f"{move}: feasible with reason {tr.reason!r}"
        else:
            assert tr.pose is None and tr.probabilities is None, f"{move}: {tr}"
            assert tr.reason.startswith("no pose found"), f"{move}: reason {tr.reason!r}"


def test_feasible_transition_pose_verified_independently(
        demo: Scenario, start_moves: dict[Move, Transition]) -> None:
    """At the returned pose all four configurations pass check_poses, and the returned
    probabilities are theirs."""
    stance = demo.start_stance
    checked = 0
    for (j, a), tr in start_moves.items():
        if not tr.feasible:
            continue
        checked += 1
        assert tr.pose is not None and tr.pose.shape == (3,), f"{(j, a)}: pose {tr.pose!r}"
        assert np.all(np.isfinite(tr.pose)), f"{(j, a)}: pose {tr.pose}"
        checks = four_checks(demo, stance, j, a, tr.pose)
        for name, c in zip(CONFIG_NAMES, checks, strict=True):
            assert c.feasible[0], (
                f"boom {j} -> {a}: returned pose {tr.pose} infeasible in the {name} "
                f"({Reason(int(c.reason[0])).name})")
        p = np.array([c.probability[0] for c in checks])
        np.testing.assert_allclose(
            tr.probabilities, p, rtol=PROB_RTOL, atol=0.0,
            err_msg=f"boom {j} -> {a}: returned probabilities differ from check_poses'")
        p_min = demo.robot.p_min
        assert np.all(p >= p_min), f"boom {j} -> {a}: probabilities {p} below p_min {p_min}"
    assert checked >= 1, "no feasible transition to verify"


def test_polish_raises_worst_configuration_and_stays_feasible(
        demo: Scenario, start_moves: dict[Move, Transition]) -> None:
    """polish_transition never lowers the worst of the four probabilities, its pose passes all
    four configurations independently, and it raises the worst one for some move."""
    stance = demo.start_stance
    raised = 0
    for (j, a), tr in start_moves.items():
        if not tr.feasible:
            continue
        pose, p = polish_transition(demo, stance, j, a, tr.pose, edge_rng(SEED, stance, j, "p"))
        checks = four_checks(demo, stance, j, a, pose)
        for name, c in zip(CONFIG_NAMES, checks, strict=True):
            assert c.feasible[0], f"boom {j} -> {a}: polished pose {pose} infeasible in the {name}"
        np.testing.assert_allclose(p, [c.probability[0] for c in checks], rtol=PROB_RTOL,
                                   err_msg=f"boom {j} -> {a}: returned probabilities differ")
        # Robustness is the sum of log P, so compare the worst configuration's robustness.
        r_before = min(float(c.allocation.robustness[0])
                       for c in four_checks(demo, stance, j, a, tr.pose))
        r_after = min(float(c.allocation.robustness[0]) for c in checks)
        assert r_after >= r_before - 1e-12, (
            f"boom {j} -> {a}: polish lowered the worst robustness {r_before} -> {r_after}")
        raised += r_after > r_before + 1e-6
        # Joined to the found pose by a straight segment feasible in both 4-stances.
        s_old, _, s_new = transition_stances(demo, stance, j, a)
        link = tr.pose + np.linspace(0.0, 1.0, 41)[:, None] * (pose - tr.pose)
        for name, st in (("old", s_old), ("new", s_new)):
            ok = check_poses(demo, st, link).feasible
            assert ok.all(), (f"boom {j} -> {a}: segment from the found to the polished pose "
                              f"infeasible in the {name} 4-stance at {np.flatnonzero(~ok)}")
    assert raised >= 1, "polish raised no transition's worst robustness"


def test_polish_rejects_infeasible_pose(demo: Scenario, feasible_move: Move) -> None:
    j, a = feasible_move
    far = np.array([50.0, 50.0, 0.0])
    with pytest.raises(ValueError, match="feasible"):
        polish_transition(demo, demo.start_stance, j, a, far, np.random.default_rng(0))


# ---------------------------------------------------------------------------------------------
# (b) rejections with the right reason, and determinism


@pytest.mark.parametrize("boom", range(4))
def test_anchor_out_of_reach_rejected(demo: Scenario, boom: int) -> None:
    """An anchor on the left wall 5 m above the start pose: no boom reaches it."""
    far = {"id": "far", "position": [-1.3355, 6.0171], "normal": [1.0, 0.0],
           "limit": {"normal": 40.0, "lateral": 20.0}, "sigma": {"normal": 3.0, "lateral": 3.0}}
    scn = with_anchors(demo, far)
    distance = float(np.linalg.norm(np.array(far["position"]) - np.array(demo.start_pose[:2])))
    assert distance >= 5.0, f"the far anchor is only {distance:.2f} m from the start pose"
    tr = search(scn, scn.start_stance, boom, "far")
    assert not tr.feasible, f"boom {boom} reaches an anchor {distance:.1f} m away: {tr.pose}"
    assert tr.pose is None and tr.probabilities is None, tr
    assert "reach" in tr.reason and "boom length" in tr.reason, (
        f"boom {boom}: reason {tr.reason!r} does not name reach / boom length")


def _weak_twin_case(demo: Scenario, start_moves: dict[Move, Transition],
                    move: Move) -> tuple[Scenario, Transition]:
    """The scenario with a weak twin 'weak' of `move`'s target; the strong move's transition."""
    j, a = move
    strong = start_moves[move]
    assert strong.feasible, f"boom {j} -> {a} should be feasible: {strong.reason}"
    scn = with_anchors(demo, twin(demo, a, "weak", WEAK_LIMIT))
    # The weak twin fails only where it should: at the strong move's pose the old 4-stance and
    # both 3-stances still pass, and the new 4-stance fails on probability.
    got = reasons(four_checks(scn, scn.start_stance, j, "weak", strong.pose))
    named = dict(zip(CONFIG_NAMES, got, strict=True))
    assert got == ["FEASIBLE", "FEASIBLE", "FEASIBLE", "PROBABILITY"], (
        f"boom {j} -> weak twin of {a} at {strong.pose}: {named}")
    return scn, strong


def test_weak_anchor_rejected_for_probability(
        demo: Scenario, start_moves: dict[Move, Transition], feasible_move: Move) -> None:
    j, a = feasible_move
    scn, _ = _weak_twin_case(demo, start_moves, feasible_move)
    tr = search(scn, scn.start_stance, j, "weak")
    assert not tr.feasible, (
        f"boom {j} -> weak twin of {a} (limit 1 N / 0.5 N) accepted at {tr.pose}, "
        f"probabilities {tr.probabilities}")
    assert tr.pose is None and tr.probabilities is None, tr
    assert "probability" in tr.reason or "p_min" in tr.reason, (
        f"boom {j} -> weak twin of {a}: reason {tr.reason!r} names neither probability nor "
        "p_min")


def test_weak_anchor_reason_names_probability_for_boom_3(
        demo: Scenario, start_moves: dict[Move, Transition]) -> None:
    move = (3, "a24")
    assert move in start_moves, f"{move} is no longer a candidate move: {list(start_moves)}"
    scn, _ = _weak_twin_case(demo, start_moves, move)
    tr = search(scn, scn.start_stance, 3, "weak")
    assert not tr.feasible, f"weak twin of a24 accepted at {tr.pose}"
    assert "probability" in tr.reason or "p_min" in tr.reason, f"reason {tr.reason!r}"


def test_same_seed_same_result(demo: Scenario, start_moves: dict[Move, Transition],
                               feasible_move: Move) -> None:
    """find_transition depends only on its generator: edge_rng(seed, edge) fixes the result."""
    j, a = feasible_move
    scn = with_anchors(demo, twin(demo, a, "weak", WEAK_LIMIT))
    for anchor in (a, "weak"):
        first = search(scn, scn.start_stance, j, anchor)
        again = search(scn, scn.start_stance, j, anchor)
        assert first.feasible == again.feasible, f"boom {j} -> {anchor}: {first} vs {again}"
        assert first.reason == again.reason, (first.reason, again.reason)
        assert first.evaluated == again.evaluated, (first.evaluated, again.evaluated)
        if first.feasible:
            np.testing.assert_array_equal(first.pose, again.pose,
                                          err_msg=f"boom {j} -> {anchor}: pose differs")
            np.testing.assert_array_equal(first.probabilities, again.probabilities,
                                          err_msg=f"boom {j} -> {anchor}: P differs")
    # The cached search on the unmodified cave (same edge, same seed) agrees too.
    np.testing.assert_array_equal(search(demo, demo.start_stance, j, a).pose,
                                  start_moves[feasible_move].pose,
                                  err_msg="same seed, same edge, different pose")


# ---------------------------------------------------------------------------------------------
# (c) the naive baseline ignores the limit surfaces


def test_ignore_grasps_accepts_weak_anchor(
        demo: Scenario, start_moves: dict[Move, Transition], feasible_move: Move) -> None:
    j, a = feasible_move
    scn, _ = _weak_twin_case(demo, start_moves, feasible_move)
    aware = search(scn, scn.start_stance, j, "weak")
    assert not aware.feasible, "the grasp-aware search should reject the weak anchor"
    naive = search(scn, scn.start_stance, j, "weak", TransitionConfig(ignore_grasps=True))
    assert naive.feasible, f"ignore_grasps rejected boom {j} -> weak twin of {a}: {naive.reason}"
    assert naive.pose is not None, naive
    naive_checks = four_checks(scn, scn.start_stance, j, "weak", naive.pose, ignore_grasps=True)
    assert all(c.feasible[0] for c in naive_checks), (
        f"naive pose {naive.pose} fails the naive checks: {reasons(naive_checks)}")
    # What the naive planner accepts, the grasp-aware check rejects at the same pose.
    aware_checks = four_checks(scn, scn.start_stance, j, "weak", naive.pose)
    assert not aware_checks[3].feasible[0], (
        f"the new 4-stance with the weak anchor passes grasp-aware checks at {naive.pose}")
    assert naive.probabilities[3] < demo.robot.p_min, (
        f"naive pose's new 4-stance P {naive.probabilities[3]} not below p_min")


# ---------------------------------------------------------------------------------------------
# reachable_anchors


def _shaft_with_anchors(shaft: Scenario) -> Scenario:
    """conftest's shaft plus anchors at y = 2.4 on both walls (reachable by the upper booms)
    and one 6.5 m up the left wall (reachable by none)."""
    grasp = {"limit": {"normal": 40.0, "lateral": 20.0}, "sigma": {"normal": 3.0, "lateral": 5.0}}
    left_normal = [8.0 / math.hypot(8.0, 0.1), -0.1 / math.hypot(8.0, 0.1)]  # x = -1.2 + y/80
    return with_anchors(
        shaft,
        {"id": "L2.4", "position": [-1.2 + 2.4 / 80, 2.4], "normal": left_normal, **grasp},
        {"id": "R2.4", "position": [1.2, 2.4], "normal": [-1.0, 0.0], **grasp},
        {"id": "far", "position": [-1.2 + 7.5 / 80, 7.5], "normal": left_normal, **grasp})


@pytest.mark.parametrize("seed", range(3))
def test_reachable_anchors_exclude_stance_and_far(shaft: Scenario, seed: int) -> None:
    scn = _shaft_with_anchors(shaft)
    stance = scn.start_stance
    held = {scn.anchor_index[a] for a in stance}
    pose = np.asarray(scn.start_pose, dtype=float)
    for boom in range(4):
        idx = reachable_anchors(scn, stance, boom, pose, np.random.default_rng([seed, boom]))
        assert idx.dtype.kind == "i", f"indices of dtype {idx.dtype}"
        ids = [scn.anchors[k].id for k in idx]
        assert not held & set(idx.tolist()), f"boom {boom}: held anchors among {ids}"
        assert "far" not in ids, f"boom {boom}: the anchor 6.5 m away is 'reachable': {ids}"


@pytest.mark.parametrize("boom, anchor", [(0, "R2.4"), (1, "L2.4")])
def test_reachable_anchors_include_feasible_transition_shaft(shaft: Scenario, boom: int,
                                                             anchor: str) -> None:
    scn = _shaft_with_anchors(shaft)
    stance = scn.start_stance
    tr = search(scn, stance, boom, anchor)
    assert tr.feasible, f"shaft: boom {boom} -> {anchor} should be feasible: {tr.reason}"
    for centre in (np.asarray(scn.start_pose, dtype=float), tr.pose):
        idx = reachable_anchors(scn, stance, boom, centre, np.random.default_rng(SEED))
        assert scn.anchor_index[anchor] in idx, (
            f"boom {boom}: {anchor} (feasible at {tr.pose}) not among reachable "
            f"{[scn.anchors[k].id for k in idx]} sampled around {centre}")


def test_reachable_anchors_include_feasible_transitions_demo(
        demo: Scenario, start_moves: dict[Move, Transition]) -> None:
    stance = demo.start_stance
    held = {demo.anchor_index[a] for a in stance}
    for (j, a), tr in start_moves.items():
        if not tr.feasible:
            continue
        idx = reachable_anchors(demo, stance, j, tr.pose, np.random.default_rng(SEED))
        assert demo.anchor_index[a] in idx, (
            f"boom {j}: {a} (feasible at {tr.pose}) not among reachable "
            f"{[demo.anchors[k].id for k in idx]}")
        assert not held & set(idx.tolist()), f"boom {j}: held anchors reachable"


def test_boom_costs_are_the_four_configurations_worst_log_p() -> None:
    """boom_costs (one compiled call) gives, bit for bit, what scoring the transition's four
    configurations with score_rows gives: per boom the worst -log P, a free boom's entry 0 and
    an impossible grasp (-inf) the largest float, on feasible and infeasible poses alike."""
    from experiments.common import make_cave
    from planning.search_cost import boom_costs
    from planning.transition_score import pack_rows
    from rb_drake.kernel.scoring import score_rows

    scn = make_cave("rockfall", 12, (4.5, 5.0))
    table = scn.anchor_table
    rng = np.random.default_rng(7)
    ids = [a.id for a in scn.anchors]
    kinds = {"finite": 0, "infinite": 0}
    for _ in range(300):
        stance = tuple(rng.choice(ids, 4, replace=False))
        anchor = str(rng.choice([a for a in ids if a not in stance]))
        boom = int(rng.integers(4))
        centre = scn.anchor_positions[[scn.anchor_index[a] for a in stance]].mean(axis=0)
        pose = np.r_[centre + rng.normal(0.0, 0.1, 2), rng.normal(0.0, 0.3)]
        held = [table.row[a] for a in stance]
        three, new = list(held), list(held)
        three[boom], new[boom] = len(table.row), table.row[anchor]
        stances, tips = pack_rows(table, [held, three, new], [held[boom], table.row[anchor]])
        lp = score_rows(scn, stances, tips, pose.reshape(1, 3), np.zeros(4, np.int64),
                        np.array([0, 1, 1, 2]), np.array([0, 0, 1, 0])).log_probs
        want = np.maximum(0.0, -np.nan_to_num(lp, nan=0.0).min(axis=0))
        got = boom_costs(scn, stance, boom, anchor, pose)
        np.testing.assert_array_equal(got, want, err_msg=f"{stance} boom {boom} -> {anchor}")
        kinds["finite" if np.all(want < 1e300) else "infinite"] += 1
    assert min(kinds.values()) >= 20, f"too few of one kind of pose: {kinds}"
