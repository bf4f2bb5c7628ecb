"""The model is mirror-symmetric: reflecting a cave about x = 0 (booms 0 <-> 1 and 2 <-> 3, the
pose's x and phi negated, anchors and their normals reflected) must not change any decision.

The robot is left-right symmetric, so a sign error in a pull angle, a moment arm, the free
limb's moment or a shoulder limit shows up as a difference between a configuration and its
mirror image. Both the numpy path (`check_poses`) and the compiled kernel (`score_poses`) are
held to it: every pose's verdict and first failing test must agree, and robustness to 1e-9.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rb_drake.feasibility import check_poses
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.kernel.scoring import score_poses
from rb_drake.scenario import Scenario

MIRROR_BOOM = np.array([1, 0, 3, 2])  # boom i's mirror image is boom MIRROR_BOOM[i]
SAMPLES = 3000


def mirrored(scn: Scenario) -> Scenario:
    """The cave reflected about x = 0 (walls re-ordered to stay counter-clockwise)."""
    walls = tuple(np.asarray(w, dtype=float)[::-1] * [-1.0, 1.0] for w in scn.walls)
    anchors = tuple(dataclasses.replace(a, position=(-a.position[0], a.position[1]),
                                        normal=(-a.normal[0], a.normal[1]))
                    for a in scn.anchors)
    return dataclasses.replace(scn, walls=walls, anchors=anchors)


@pytest.fixture(scope="module", params=[("shaft", 1), ("crevasse", 2)],
                ids=lambda p: f"{p[0]}-{p[1]}")
def case(request) -> tuple[Scenario, Scenario, tuple[str, ...], np.ndarray]:
    kind, seed = request.param
    scn = generate_cave(kind, seed, CaveConfig(length=(4.5, 5.0)))
    rng = np.random.default_rng(seed)
    centre = np.asarray(scn.start_pose)
    poses = np.column_stack([centre[0] + rng.normal(0.0, 0.3, SAMPLES),
                             centre[1] + rng.normal(0.0, 0.3, SAMPLES),
                             rng.uniform(-1.0, 1.0, SAMPLES)])
    return scn, mirrored(scn), tuple(scn.start_stance), poses


@pytest.mark.parametrize("free", [None, 0, 1, 2, 3])
def test_feasibility_is_mirror_symmetric(case, free: int | None) -> None:
    scn, mirror, stance_ids, poses = case
    mirror_ids = tuple(stance_ids[MIRROR_BOOM[i]] for i in range(4))
    stance, mirror_stance = scn.stance(stance_ids), mirror.stance(mirror_ids)
    tip = mirror_tip = None
    if free is not None:
        tip = stance.positions[free]
        mirror_tip = tip * [-1.0, 1.0]
        stance, mirror_stance = stance.without(free), mirror_stance.without(MIRROR_BOOM[free])
    mirror_poses = poses * [-1.0, 1.0, -1.0]

    ours, theirs = check_poses(scn, stance, poses, tip), check_poses(mirror, mirror_stance,
                                                                      mirror_poses, mirror_tip)
    assert 0 < ours.feasible.sum() < SAMPLES or free is not None, (
        "the sample should mix feasible and infeasible poses to test anything")
    differ = np.flatnonzero(ours.reason != theirs.reason)
    assert differ.size == 0, (
        f"{differ.size} of {SAMPLES} poses fail differently from their mirror images, e.g. "
        f"pose {poses[differ[0]]}: {ours.reason[differ[0]]} against {theirs.reason[differ[0]]}")
    both = ours.feasible & theirs.feasible
    np.testing.assert_allclose(ours.allocation.robustness[both],
                               theirs.allocation.robustness[both], rtol=1e-9, atol=1e-12,
                               err_msg="robustness differs from the mirror image's")

    kernel = score_poses(scn, stance, poses, tip)
    mirror_kernel = score_poses(mirror, mirror_stance, mirror_poses, mirror_tip)
    np.testing.assert_array_equal(kernel.feasible, mirror_kernel.feasible,
                                  err_msg="the kernel's verdicts are not mirror-symmetric")
    np.testing.assert_array_equal(kernel.feasible, ours.feasible,
                                  err_msg="the kernel disagrees with check_poses")
