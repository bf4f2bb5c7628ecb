"""Refinement (planning.refinement): a complete search that finds no route on its lattice
searches again on the lattice of half the steps. Benchmark shaft 71 has no route through the
points of the 2 cm / 2.5 deg lattice and one through those of 1 cm / 1.25 deg."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rbp
from planning.footsteps import FootstepConfig, FootstepMemo, plan_footsteps
from planning.lattice import LatticeConfig, pack, poses_of, unpack
from planning.refinement import RefinementState, Refuted, finer_lattices
from planning.search_outcome import Stop
from rb_drake.scenario import Scenario

BASE = LatticeConfig()
FINE = LatticeConfig(position_step=0.01, angle_step_deg=1.25)


@pytest.fixture(scope="module")
def shaft71() -> Scenario:
    return rbp.generate_scenario("shaft", seed=71, length=(4.5, 5.0))


@pytest.fixture(scope="module")
def refined(shaft71: Scenario):
    memo = FootstepMemo()
    return plan_footsteps(shaft71, FootstepConfig(), memo=memo), memo


def test_finer_lattices_halve_both_steps_within_their_ranges(shaft71: Scenario) -> None:
    assert finer_lattices(shaft71, BASE, 0) == [BASE]
    assert finer_lattices(shaft71, BASE, 1) == [BASE, FINE]
    # 2 cm -> 1 cm -> 5 mm, and no further: 2.5 mm is below the least position step
    chain = finer_lattices(shaft71, BASE, 4)
    assert [c.position_step for c in chain] == [0.02, 0.01, 0.005], chain
    assert [c.angle_step_deg for c in chain] == [2.5, 1.25, 0.625], chain


def test_every_coarse_point_is_a_point_of_the_finer_lattice() -> None:
    rng = np.random.default_rng(5)
    idx = np.column_stack([rng.integers(-500, 500, 200), rng.integers(-500, 500, 200),
                           rng.integers(-BASE.angle_count // 2, BASE.angle_count // 2, 200)])
    coarse = poses_of(unpack(pack(idx, BASE.angle_count), BASE.angle_count), BASE)
    fine = poses_of(unpack(pack(2 * idx, FINE.angle_count), FINE.angle_count), FINE)
    np.testing.assert_allclose(fine, coarse, atol=1e-12,
                               err_msg="a coarse pose is not a point of the finer lattice")


def test_a_refuted_lattice_is_skipped_only_under_more_exclusions() -> None:
    state = RefinementState([Refuted(BASE, frozenset({("s", 0, "a")}), 10, 20)])
    lattices = [BASE, FINE]
    assert state.first_open(lattices, frozenset({("s", 0, "a"), ("t", 1, "b")})) == 1
    assert state.first_open(lattices, frozenset()) == 0, "fewer exclusions: search it again"
    assert state.first_open(lattices, frozenset({("t", 1, "b")})) == 0
    assert RefinementState().first_open(lattices, frozenset()) == 0
    # the finest lattice is always searched, so that an answer comes back
    both = RefinementState([Refuted(BASE, frozenset(), 1, 1), Refuted(FINE, frozenset(), 1, 1)])
    assert both.first_open(lattices, frozenset()) == 1


def test_the_lattice_alone_has_no_route_on_shaft_71(shaft71: Scenario) -> None:
    fp = plan_footsteps(shaft71, FootstepConfig(refine=0))
    assert not fp.success and fp.stop == Stop.NOROUTE, (fp.stop, fp.reason)
    assert fp.reason.startswith("no route at resolution 2 cm / 2.5 deg"), fp.reason
    assert fp.refined == ()


def test_refinement_finds_the_route_between_the_points(refined, shaft71: Scenario) -> None:
    fp, memo = refined
    assert fp.success and fp.stop == Stop.ROUTE, (fp.stop, fp.reason)
    assert fp.refined == (FINE,), fp.refined
    assert memo.lattice.config == FINE, "the memo serves the lattice that answered"
    assert [r.lattice for r in memo.refinement.refuted] == [BASE]
    # the route holds: every transition's four configurations at least p_min
    p_min = shaft71.robot.p_min
    for step in fp.steps:
        assert np.all(step.probabilities >= p_min - 1e-12), (step, p_min)
    assert len(fp.steps) >= 1 and fp.expansions > memo.refinement.refuted[0].expansions


def test_a_search_again_starts_on_the_refined_lattice(refined, shaft71: Scenario) -> None:
    """The pipeline excludes a move whose motion fails and searches again: the coarse lattice,
    refuted with fewer exclusions, is not searched again."""
    fp, memo = refined
    first = fp.steps[0]
    move = (tuple(fp.stances[0]), first.boom, first.to_anchor)
    again = plan_footsteps(shaft71, FootstepConfig(), exclude=[move], memo=memo)
    assert len(memo.refinement.refuted) == 1, memo.refinement.refuted
    assert again.refined == (FINE,), again.refined
    if again.success:
        taken = {(tuple(a), s.boom, s.to_anchor) for a, s in zip(again.stances, again.steps,
                                                                  strict=False)}
        assert move not in taken, "the excluded move was taken"
    else:
        assert again.stop == Stop.EXHAUSTED, (again.stop, again.reason)


def test_no_route_on_either_lattice_says_both() -> None:
    scn = rbp.generate_scenario("shaft", seed=51, length=(4.5, 5.0))
    fp = plan_footsteps(scn, FootstepConfig())
    assert not fp.success and fp.stop == Stop.NOROUTE, (fp.stop, fp.reason)
    assert fp.reason.startswith("no route at resolution 2 cm / 2.5 deg ("), fp.reason
    assert "nor, refined, at 1 cm / 1.25 deg: all " in fp.reason, fp.reason
    assert fp.refined == (FINE,)
    coarse = plan_footsteps(scn, dataclasses.replace(FootstepConfig(), refine=0))
    assert fp.expansions > coarse.expansions, "the work of both lattices is counted"


def test_min_success_answers_on_the_lattice_asked(shaft71: Scenario) -> None:
    fp = plan_footsteps(shaft71, FootstepConfig(min_success=0.5))
    assert fp.refined == () and fp.stop == Stop.NOROUTE, (fp.stop, fp.reason)


def test_progress_counts_on_across_the_lattices(shaft71: Scenario) -> None:
    seen: list[tuple[int, int]] = []
    fp = plan_footsteps(shaft71, FootstepConfig(anytime=None),
                        progress=lambda n, t, *_, **__: seen.append((n, t)))
    assert fp.success and fp.refined == (FINE,)
    expansions = [n for n, _ in seen]
    assert expansions == sorted(expansions), "the count went back at the refined lattice"
    assert max(expansions) <= fp.expansions, (max(expansions), fp.expansions)


def test_a_start_joined_to_no_lattice_pose_is_refined_too() -> None:
    """Benchmark crevasse 78 moved by less than a cell (the rigid-motion run's second copy):
    its start pose joins no pose of the 2 cm / 2.5 deg lattice, and the 1 cm / 1.25 deg one
    climbs it, as the unmoved cave climbs on the coarse lattice."""
    import math

    from experiments.common import make_cave
    from experiments.rigid_motion import moved_scenario, rigid_motion

    rng = np.random.default_rng([78, 30])
    motion = [rigid_motion(rng) for _ in range(2)][-1]
    scn = moved_scenario(make_cave("crevasse", 78, (4.5, 5.0)), *motion)
    assert abs(math.degrees(motion[0])) < 2.5
    lattice = plan_footsteps(scn, FootstepConfig(refine=0, anytime=None))
    assert lattice.stop == Stop.NOSTART, (lattice.stop, lattice.reason)
    fp = plan_footsteps(scn, FootstepConfig(anytime=None))
    assert fp.success and fp.refined == (FINE,), (fp.stop, fp.reason)


def test_a_refined_start_joins_wherever_the_coarse_one_did(shaft71: Scenario) -> None:
    """The start joins the corners of the coarse cell too (`start_cell_steps`): every
    component the coarse lattice joins holds a pose the fine lattice joins."""
    from planning.lattice_moves import start_components
    from planning.lattice_search import LatticeMemo, stance_components

    coarse_memo, fine_memo = LatticeMemo(), LatticeMemo()
    coarse_memo.bind(shaft71, BASE, False)
    fine_memo.bind(shaft71, FINE, False)
    stance = tuple(shaft71.start_stance)
    coarse = start_components(shaft71, stance_components(shaft71, coarse_memo, stance, BASE,
                                                         False), BASE)
    fine_lat = stance_components(shaft71, fine_memo, stance, FINE, False)
    fine = start_components(shaft71, fine_lat, FINE, cell_steps=2)
    assert coarse, "the start joins the coarse lattice"
    joined = {tuple(np.round(p, 9)) for p in fine.values()}
    for pose in coarse.values():
        comp = int(fine_lat.component_of(pack(np.round(np.asarray(pose) / np.array(
            [FINE.position_step, FINE.position_step, FINE.angle_step])).astype(np.int64),
            FINE.angle_count))[0])
        assert comp in fine, (pose, comp, joined)
