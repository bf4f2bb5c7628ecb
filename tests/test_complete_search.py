"""The complete footstep search (planning.lattice, planning.complete).

Completeness is checked against brute force: every lattice pose of a box that covers the
stance's reach, tested with the compiled kernel in its full (reference) mode, must give the same
sets as the search's sector enumeration, release sets and transition test. The tests use a
coarse lattice (5 cm x 5 deg) so that brute force over the whole box stays cheap; the code is
the same at any resolution. A planted narrow window (p_min raised until only a few lattice poses
hold a move) must be found exactly, and a cave cut in two by a slab of rock must be answered
"no route" by exhausting the vertices below it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from kernel_helpers import pack_stances
from lattice_reference import candidate_anchors, stance_lattice

from planning.complete import complete_search
from planning.complete_config import CompleteConfig
from planning.components import INFEASIBLE, UNKNOWN, StanceComponents
from planning.footsteps import FootstepConfig, FootstepMemo, plan_footsteps
from planning.lattice import LatticeConfig, pack, poses_of, reachable_lattice
from planning.lattice_kernels import reach_violation
from planning.lattice_moves import (
    goal_is_holdable,
    lattice_transition,
    move_rows,
    move_table,
    start_components,
)
from planning.lattice_search import LatticeMemo
from planning.plan import build_plan
from planning.transition import transition_stances
from rb_drake.feasibility import check_poses
from rb_drake.kernel.collision import packed_rock
from rb_drake.kernel.layout import ALL_BOOMS, ALL_SEGMENTS, robot_params
from rb_drake.kernel.scoring import score_poses, score_rows
from rb_drake.kernel.threads import score_threads
from rb_drake.scenario import Scenario, bundled_caves, load_scenario, scenario_from_dict
from rb_drake.stance import Stance
from rb_drake.statics import statics_problem

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


def box_lattice(anchors: np.ndarray, cfg: LatticeConfig, reach: float) -> np.ndarray:
    """Every lattice index within `reach` (box) of every anchor, every orientation."""
    lo = np.floor((anchors.max(axis=0) - reach) / cfg.position_step).astype(int)
    hi = np.ceil((anchors.min(axis=0) + reach) / cfg.position_step).astype(int)
    n = cfg.angle_count
    grid = itertools.product(range(lo[0], hi[0] + 1), range(lo[1], hi[1] + 1),
                             range(-n // 2, n // 2))
    return np.array(list(grid), dtype=np.int64).reshape(-1, 3)


def brute_reachable(scn: Scenario, anchors: np.ndarray, booms: np.ndarray,
                    cfg: LatticeConfig) -> set[tuple[int, int, int]]:
    idx = box_lattice(anchors, cfg, scn.robot.max_reach + cfg.position_step)
    v = reach_violation(scn.robot, poses_of(idx, cfg), anchors, booms).sum(axis=1)
    return set(map(tuple, idx[v == 0.0]))


@pytest.mark.parametrize("cave", ["demo-shaft", "crevasse-2", "rockfall-3"])
def test_sector_enumeration_equals_brute_force(cave: str) -> None:
    """The lattice poses at which a stance's booms reach are exactly those of brute force over a
    box, for the start stance and for random anchor sets (where the sectors barely meet)."""
    scn = load_scenario(bundled_caves()[cave])
    rng = np.random.default_rng(3)
    held = scn.stance(scn.start_stance).positions
    cases = [held] + [held + rng.normal(0.0, 0.6, held.shape) for _ in range(3)]
    for anchors in cases:
        got = set(map(tuple, reachable_lattice(scn.robot, anchors, np.arange(4), COARSE)))
        want = brute_reachable(scn, anchors, np.arange(4), COARSE)
        assert got == want, (f"{cave}: {len(got - want)} poses enumerated beyond reach, "
                             f"{len(want - got)} reachable poses missed")


def test_decide_only_keeps_feasibility_and_values(demo: Scenario) -> None:
    """The kernel's decide_only mode (the lattice's) agrees with its full mode on feasibility,
    and on robustness and tensions where feasible."""
    stance = demo.stance(demo.start_stance)
    idx = reachable_lattice(demo.robot, stance.positions, np.arange(4), COARSE)
    poses = poses_of(idx, COARSE)
    full = score_poses(demo, stance, poses)
    packed = pack_stances(stance)
    z = np.zeros(len(poses), np.int64)
    fast = score_rows(demo, packed, np.full((1, 2), np.nan), poses, np.arange(len(poses)), z, z,
                      decide_only=True)
    assert full.feasible.any() and (~full.feasible).any(), "need both kinds of pose"
    assert np.array_equal(full.feasible, fast.feasible), "decide_only changed feasibility"
    f = full.feasible
    assert np.array_equal(full.robustness[f], fast.robustness[f])
    assert np.array_equal(full.tensions[f], fast.tensions[f])


def test_decide_only_shoulder_range_at_its_edge(demo: Scenario) -> None:
    """decide_only decides the shoulder-angle test by its cosine where that is clear-cut: with
    the range set 1e-10 rad above and below a pose's largest shoulder angle, it still agrees
    with the full mode on every pose, and the pose passes, then fails, that test."""
    from rb_drake import geometry

    stance = demo.stance(demo.start_stance)
    idx = reachable_lattice(demo.robot, stance.positions, np.arange(4), COARSE)
    poses = poses_of(idx, COARSE)
    theta = np.abs(geometry.boom_geometry(demo.robot, poses, stance.positions).shoulder_angle)
    packed = pack_stances(stance)
    z = np.zeros(len(poses), np.int64)
    full0 = score_poses(demo, stance, poses)
    picked = np.flatnonzero(full0.feasible)[:: max(1, full0.feasible.sum() // 4)][:4]
    assert len(picked) >= 2, "need feasible poses to move the limit to"
    for k in picked:
        for side in (-1.0, 1.0):
            limit = float(theta[k].max()) + side * 1e-10
            scn = dataclasses.replace(demo, robot=demo.robot.replace(
                shoulder_range_deg=math.degrees(limit)))
            full = score_poses(scn, stance, poses)
            fast = score_rows(scn, packed, np.full((1, 2), np.nan), poses,
                              np.arange(len(poses)), z, z, decide_only=True)
            label = f"pose {k}, range {limit!r} rad"
            assert np.array_equal(full.feasible, fast.feasible), f"{label}: feasibility"
            assert fast.feasible[k] == (side > 0), f"{label}: pose {k} decided wrongly"


def test_stance_lattice_is_the_feasible_set_with_release_booms(demo: Scenario) -> None:
    """stance_lattice holds exactly the reachable poses check_poses (the numpy reference) finds
    feasible, each boom's release flag is the 3-stance's check, and the components are the
    26-connected ones."""
    stance = tuple(demo.start_stance)
    lat = stance_lattice(demo, stance, COARSE)
    idx = reachable_lattice(demo.robot, demo.stance(stance).positions, np.arange(4), COARSE)
    ref = check_poses(demo, demo.stance(stance), poses_of(idx, COARSE))
    want = set(pack(idx[ref.feasible], COARSE.angle_count).tolist())
    assert set(lat.keys.tolist()) == want, "feasible lattice set differs from check_poses"
    s4 = demo.stance(stance)
    for j in range(4):
        three = s4.without(j)
        check = check_poses(demo, three, lat.poses, s4.positions[j])
        unloaded = unloaded_log_p(demo, s4, lat.poses, j)
        rel = check.feasible & (check.allocation.robustness + unloaded >= demo.robot.log_p_min)
        assert np.array_equal(lat.release[:, j], rel), f"release set of boom {j} differs"
        # The release r is the 3-stance's with the unloaded grasp counted (the ramp's end).
        np.testing.assert_allclose(lat.release_r[rel, j],
                                   check.allocation.robustness[rel] + unloaded[rel], rtol=1e-9,
                                   atol=1e-12, err_msg=f"release r of boom {j}")
    # Components: neighbours (26-connectivity) share a label, and labels split nowhere else.
    where = {tuple(i): c for i, c in zip(lat.idx.tolist(), lat.component.tolist(), strict=True)}
    for i, c in where.items():
        for d in itertools.product((-1, 0, 1), repeat=3):
            other = where.get((i[0] + d[0], i[1] + d[1], i[2] + d[2]))
            assert other is None or other == c, f"neighbours {i} + {d} in two components"
    assert lat.n_components == len(set(where.values()))


def all_components(scn: Scenario, stance: tuple[str, ...],
                   cfg: LatticeConfig) -> StanceComponents:
    """The stance's components, every one grown (from the feasible poses stance_lattice finds)."""
    found = StanceComponents(scn, stance, cfg)
    found.component_of(stance_lattice(scn, stance, cfg).keys)
    return found


@pytest.mark.parametrize("cave", ["demo-shaft", "rockfall-3"])
def test_grown_components_are_the_lattice_components(cave: str) -> None:
    """Each component the flood fill grows from one of its poses is the component
    stance_lattice labels by scoring the whole reachable lattice: the same poses, robustness
    and release sets, for the stances a short search enters."""
    scn = load_scenario(bundled_caves()[cave])
    memo = LatticeMemo()
    complete_search(scn, CompleteConfig(COARSE, max_expansions=6), memo=memo)
    stances = list(memo.components)
    compared = 0
    for stance in stances:
        lat = stance_lattice(scn, stance, COARSE)
        grown = StanceComponents(scn, stance, COARSE)
        for comp in range(lat.n_components):
            mine = lat.component == comp
            seed = lat.keys[np.flatnonzero(mine)[len(np.flatnonzero(mine)) // 2]]
            label = int(grown.component_of(np.array([seed]))[0])
            assert label >= 0, f"{stance}: a feasible seed grew no component"
            got = grown.components[label]
            assert np.array_equal(got.keys, lat.keys[mine]), (
                f"{stance} component {comp}: {len(got.keys)} poses grown, {mine.sum()} labelled")
            for name in ("robustness", "release", "release_r"):
                assert np.array_equal(getattr(got, name), getattr(lat, name)[mine]), name
            compared += 1
        assert len(grown.components) == lat.n_components
        # A reachable pose no component holds is answered infeasible, and its neighbours in
        # the flood's boundary are known without scoring again.
        reach = reachable_lattice(scn.robot, scn.stance(stance).positions, np.arange(4), COARSE)
        keys = pack(reach, COARSE.angle_count)
        outside = keys[~np.isin(keys, lat.keys)]
        if len(outside):
            assert (grown.component_of(outside[:50]) == INFEASIBLE).all()
            assert UNKNOWN not in grown.known_component(outside[:50])
    assert compared >= 6, f"too few components to compare ({compared})"


def unloaded_log_p(scn: Scenario, four: Stance, poses: np.ndarray, boom: int) -> np.ndarray:
    """log P of boom `boom`'s grasp in the 4-stance `four` at zero tension (numpy: the pull
    angle of statics_problem, Stance.log_prob): what the release ramp's end (or the attach
    ramp's start) adds to the 3-stance, the gripper unloaded but attached."""
    psi = np.nan_to_num(statics_problem(scn.robot, scn.gravity_vector, poses, four).pull_angles)
    return four.log_prob(np.zeros((len(poses), 4)), psi)[:, boom]


def all_transition_poses(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
                         cfg: LatticeConfig) -> set[int]:
    """Brute force: every lattice pose of a box over the five anchors' reach at which all four
    configurations of the move are feasible (kernel, full mode), the two 3-stances with the
    unloaded grasp on the old and the new anchor counted (the ramps' ends)."""
    s_old, s_three, s_new = transition_stances(scn, stance, boom, anchor)
    five = np.vstack([s_old.positions, s_new.positions[boom][None]])
    booms = np.array([0, 1, 2, 3, boom])
    idx = box_lattice(five, cfg, scn.robot.max_reach + cfg.position_step)
    poses = poses_of(idx, cfg)
    ok = reach_violation(scn.robot, poses, five, booms).sum(axis=1) == 0.0
    idx, poses = idx[ok], poses[ok]
    for stance_k, tip, four in ((s_old, None, None), (s_three, s_old.positions[boom], s_old),
                                (s_three, s_new.positions[boom], s_new), (s_new, None, None)):
        if not len(poses):
            break
        check = score_poses(scn, stance_k, poses, tip)
        keep = check.feasible
        if four is not None and keep.any():
            keep[keep] = (check.robustness[keep] + unloaded_log_p(scn, four, poses[keep], boom)
                          >= scn.robot.log_p_min)
        idx, poses = idx[keep], poses[keep]
    return set(pack(idx, cfg.angle_count).tolist())


def lattice_poses_of_move(scn: Scenario, stance: tuple[str, ...], boom: int, anchor: str,
                          cfg: LatticeConfig) -> dict[int, float]:
    """The search's answer over every component: key -> worst robustness of the four."""
    out: dict[int, float] = {}
    for comp in all_components(scn, stance, cfg).components:
        tr = lattice_transition(scn, comp, stance, boom, anchor)
        out.update(zip(tr.keys.tolist(), tr.worst.tolist(), strict=True))
    return out


@pytest.fixture(scope="module")
def move(demo: Scenario) -> tuple[tuple[str, ...], int, str, dict[int, float]]:
    """A move from the demo's start stance that holds at many lattice poses."""
    stance = tuple(demo.start_stance)
    best = None
    for j in range(4):
        for comp in all_components(demo, stance, COARSE).components:
            for k in candidate_anchors(demo, comp, stance, j):
                found = lattice_poses_of_move(demo, stance, j, demo.anchors[k].id, COARSE)
                if best is None or len(found) > len(best[3]):
                    best = (stance, j, demo.anchors[k].id, found)
    assert best is not None and len(best[3]) >= 20, "the demo's start needs a roomy move"
    return best


def test_transition_test_finds_every_lattice_pose(demo: Scenario, move) -> None:
    stance, boom, anchor, found = move
    want = all_transition_poses(demo, stance, boom, anchor, COARSE)
    assert set(found) == want, (f"boom {boom} -> {anchor}: {len(want - set(found))} lattice "
                                f"poses missed, {len(set(found) - want)} wrongly accepted")


def test_transition_looked_up_in_known_arrival_components(demo: Scenario, move) -> None:
    """Where the new stance's components are already known, a move's poses are looked up in
    its release sets instead of scored: the same poses and the same four r, to the bit, for
    every arrival stance known in part (a few components grown) or whole."""
    stance, boom, anchor, found = move
    child = tuple(anchor if i == boom else a for i, a in enumerate(stance))
    whole = all_components(demo, child, COARSE)
    part = StanceComponents(demo, child, COARSE)
    part.component_of(whole.components[0].keys[:1])  # one component and its boundary
    for arrival in (part, whole):
        for comp in all_components(demo, stance, COARSE).components:
            scored = lattice_transition(demo, comp, stance, boom, anchor)
            looked = lattice_transition(demo, comp, stance, boom, anchor, arrival=arrival)
            np.testing.assert_array_equal(looked.keys, scored.keys)
            np.testing.assert_array_equal(looked.r4, scored.r4)
            np.testing.assert_array_equal(looked.worst, scored.worst)
            assert looked.tested == scored.tested
    decided = whole.known_component(np.array(list(found), dtype=np.int64))
    assert (decided != UNKNOWN).all(), "the whole arrival stance decides every move pose"


@pytest.mark.parametrize("window", [1, 3])
def test_planted_narrow_window_is_found(demo: Scenario, move, window: int) -> None:
    """Raise p_min until only the `window` most robust lattice poses hold the move (every other
    test is independent of p_min, so exactly those remain): the test must find exactly them,
    and brute force must agree that nothing else holds."""
    stance, boom, anchor, found = move
    worst = np.sort(np.array(list(found.values())))[::-1]
    assert worst[window - 1] > worst[window] + 1e-9, "ties at the window's edge"
    threshold = 0.5 * (worst[window - 1] + worst[window])
    narrow = dataclasses.replace(demo, robot=demo.robot.replace(p_min=math.exp(threshold)))
    planted = {k for k, r in found.items() if r >= threshold}
    assert len(planted) == window
    got = lattice_poses_of_move(narrow, stance, boom, anchor, COARSE)
    assert set(got) == planted, f"found {sorted(got)}, planted {sorted(planted)}"
    assert all_transition_poses(narrow, stance, boom, anchor, COARSE) == planted


def test_every_reachable_anchor_is_a_candidate(demo: Scenario) -> None:
    """candidate_anchors drops no anchor that the boom reaches from a release pose."""
    stance = tuple(demo.start_stance)
    held = {demo.anchor_index[a] for a in stance}
    for j in range(4):
        for comp in all_components(demo, stance, COARSE).components:
            rows = comp.release[:, j]
            got = set(candidate_anchors(demo, comp, stance, j).tolist())
            if not rows.any():
                assert not got
                continue
            v = reach_violation(demo.robot, comp.poses[rows], demo.anchor_positions,
                                np.full(len(demo.anchors), j))
            want = set(np.flatnonzero((v == 0.0).any(axis=0)).tolist()) - held
            assert got == want, f"boom {j}: missing {want - got}, extra {got - want}"


@pytest.mark.parametrize("kind, seed", [("rockfall", 12), ("crevasse", 46)])
def test_move_table_is_every_move_rows(kind: str, seed: int) -> None:
    """The one-pass move table of a vertex holds, for every candidate anchor, exactly the rows
    `move_rows` finds for that move (to the bit: the same tests), and leaves out only anchors
    none of whose segments is clear."""
    from experiments.common import make_cave

    scn = make_cave(kind, seed, (4.5, 5.0))
    memo = LatticeMemo()
    complete_search(scn, CompleteConfig(max_expansions=15), memo=memo)
    moves = left_out = 0
    for stance, known in memo.components.items():
        for comp in known.components:
            table = move_table(scn, comp, stance)
            for j in range(4):
                got = dict(table[j])
                cand = candidate_anchors(scn, comp, stance, j).tolist()
                assert set(got) <= set(cand), f"boom {j}: anchors beyond reach in the table"
                for k in cand:
                    want = move_rows(scn, comp, j, scn.anchors[k].id)
                    if len(want):
                        assert k in got, f"{stance} boom {j} -> anchor {k}: move left out"
                        np.testing.assert_array_equal(got[k], want)
                        moves += 1
                    else:
                        assert k not in got, f"{stance} boom {j} -> anchor {k}: blocked kept"
                        left_out += 1
    assert moves >= 50, f"only {moves} moves compared"
    if kind == "rockfall":
        assert left_out > 0, "no move blocked by rock: the segment test was not exercised"


def test_start_is_joined_to_the_lattice(demo: Scenario) -> None:
    lat = StanceComponents(demo, tuple(demo.start_stance), LatticeConfig())
    joined = start_components(demo, lat, LatticeConfig())
    assert joined, "the demo's start pose joins no lattice pose"
    for pose in joined.values():
        assert np.abs(pose[:2] - np.asarray(demo.start_pose)[:2]).max() <= 0.02 + 1e-9


def slab_cave(demo: Scenario, gap: float = 0.4, thickness: float = 0.3,
              near: float = 0.4) -> Scenario:
    """The demo shaft cut by a slab of rock `gap` m above the start stance's highest anchor:
    anchors on or in it are removed, and the goal stays above it."""
    data = demo.to_dict()
    y0 = float(demo.stance(demo.start_stance).positions[:, 1].max()) + gap
    xs = [p[0] for wall in data["walls"] for p in wall]
    slab = [[min(xs) - 1.0, y0], [max(xs) + 1.0, y0], [max(xs) + 1.0, y0 + thickness],
            [min(xs) - 1.0, y0 + thickness]]
    data["walls"] = [*data["walls"], slab]
    # Below the slab only anchors near the start stance's, so that the vertices are few.
    held = demo.stance(demo.start_stance).positions
    data["anchors"] = [a for a in data["anchors"]
                       if a["position"][1] > y0 + thickness + 0.05
                       or (a["position"][1] < y0 - 0.05
                           and np.linalg.norm(held - a["position"], axis=1).min() < near)]
    return scenario_from_dict(data, "slab-cave")


def test_a_cave_cut_in_two_has_no_route(demo: Scenario) -> None:
    """Below a slab the reachable vertices are few: the search expands them all and says that
    no route exists at its resolution, in the plan file too; the goal alone is holdable."""
    cave = slab_cave(demo)
    assert goal_is_holdable(cave, LatticeConfig()), "the goal must be holdable for this test"
    memo = FootstepMemo()
    result = complete_search(cave, memo=memo.lattice)
    assert not result.success and result.stop == "noroute", (result.stop, result.reason)
    assert "no route at resolution 2 cm / 2.5 deg" in result.reason, result.reason
    assert result.expansions == len(result.expanded) and not result.frontier
    # Nothing reached lies above the slab.
    top = float(demo.stance(demo.start_stance).positions[:, 1].max()) + 0.4
    assert all(p[1] < top for _, p in result.expanded), "a pose above the slab was reached"
    fp = plan_footsteps(cave, FootstepConfig(search="complete"), memo=memo)  # replays it
    assert fp.stop == "noroute" and build_plan(cave, fp, "rbp").search.stop == "noroute"


def test_goal_in_rock_is_no_route_at_once(demo: Scenario) -> None:
    """A goal that no stance can hold (far above the cave) is answered without a search."""
    far = dataclasses.replace(demo, goal_position=(demo.goal_position[0], 60.0))
    result = complete_search(far)
    assert result.stop == "noroute" and result.expansions == 0, (result.stop, result.reason)


def test_budget_is_not_a_proof(demo: Scenario) -> None:
    result = complete_search(demo, CompleteConfig(max_expansions=2))
    if not result.success:
        assert result.stop == "budget", result.stop


def test_same_plan_twice(demo: Scenario) -> None:
    a = plan_footsteps(demo, FootstepConfig(search="complete"))
    b = plan_footsteps(demo, FootstepConfig(search="complete"))
    assert a.success and a.stances == b.stances
    for s, t in zip(a.steps, b.steps, strict=True):
        assert np.array_equal(s.pose, t.pose)


def test_rows_scored_on_threads_equal_one_thread(demo: Scenario) -> None:
    """The flood fills and moves score rows on several threads, interleaved: every output, row
    for row and bit for bit, is the one-thread kernel's (release sets and body tests too)."""
    stance = tuple(demo.start_stance)
    idx = reachable_lattice(demo.robot, demo.stance(stance).positions, np.arange(4), COARSE)
    poses = poses_of(idx, COARSE)[:997]  # an odd count: threads get unequal shares
    P = len(poses)
    packed = pack_stances(demo.stance(stance))
    prm = robot_params(demo.robot, demo.gravity_vector)
    rows, zeros = np.arange(P), np.zeros(P, np.int64)

    def scored(threads: int) -> list[np.ndarray]:
        out = [np.empty(P, np.int64), np.empty(P), np.empty((P, 4)), np.empty((P, 4)),
               np.empty(P), np.full((P, 4), np.nan), np.zeros(P, np.int8)]
        score_threads(threads, poses, prm, *packed, np.full((1, 2), np.nan), rows, zeros,
                      zeros, np.empty(0), *packed_rock(demo.rock), False, True,
                      int(ALL_SEGMENTS), *out,
                      int(ALL_BOOMS))
        return out

    one, three = scored(1), scored(3)
    assert (one[0] == 0).sum() > 20, "too few feasible rows to compare"
    for a, b in zip(one, three, strict=True):
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), "threads changed a row"


def test_search_on_threads_equals_one_thread(demo: Scenario, monkeypatch) -> None:
    """RBP_THREADS changes how fast the complete search runs, not what it finds."""
    found = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("RBP_THREADS", threads)
        result = complete_search(demo, CompleteConfig(max_expansions=40))
        found[threads] = ([v for v, _ in result.expanded], result.transitions_tested,
                          [p.tolist() for p in result.poses])
    assert found["1"] == found["2"]


def test_alternative_poses_hold_the_move(demo: Scenario) -> None:
    """Each step of a complete-search plan carries other lattice poses for the pipeline (where
    the gripper's path fails at the first): each holds all four configurations of the move,
    the first is the pose the search found, and they are sorted by their worst robustness."""
    fp = plan_footsteps(demo, FootstepConfig(search="complete"))
    assert fp.success and fp.steps, fp.reason
    for k, step in enumerate(fp.steps):
        alt = step.alternatives
        assert alt is not None and len(alt) >= 1, f"step {k}: no alternatives"
        assert np.array_equal(alt[0], step.found_pose), f"step {k}: first is not the found pose"
        stance = fp.stances[k]
        s_old, s_three, s_new = transition_stances(demo, stance, step.boom, step.to_anchor)
        worst = np.full(len(alt), np.inf)
        for st, tip in ((s_old, None), (s_three, s_old.positions[step.boom]),
                        (s_three, s_new.positions[step.boom]), (s_new, None)):
            check = check_poses(demo, st, alt, tip)
            assert check.feasible.all(), f"step {k}: alternatives {np.flatnonzero(~check.feasible)}"
            worst = np.minimum(worst, check.allocation.robustness)
        assert np.all(np.diff(worst) <= 1e-9), f"step {k}: not sorted best first"


def test_footstep_plan_holds_its_ramps() -> None:
    """The release ramp ends with the freed grasp unloaded but attached, and its P at zero
    tension counts (rbp check's rule `release`): the complete search counts it too. On
    benchmark crevasse seed 18 a release at a pull angle near 88 deg ended at P 0.932 < p_min
    while the search ignored it; now every configuration of the footstep plan verifies."""
    from experiments.common import make_cave, plan_cave
    from planning.check import check_plan

    scn = make_cave("crevasse", 18, (4.5, 5.0))
    plan = plan_cave(scn, "rbp", 1000, False)
    assert plan["success"], plan["reason"]
    assert plan["p_min"] >= scn.robot.p_min - 1e-9, plan["p_min"]
    problems = check_plan(plan)
    assert not problems, problems[:3]
