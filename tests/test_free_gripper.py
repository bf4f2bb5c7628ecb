"""A free gripper holds nothing: it may touch rock only within ANCHOR_CLEARANCE of an anchor
(`rb_drake.collision.free_clearance`), in check_poses, the kernel and `rbp check` alike.

Built on the golden demo-shaft plan (tests/data/golden/demo-shaft-current.json): its phase 1
reaches with boom 2 from one anchor to another; a small rock square is put in the gripper's way.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import run_rbp
from golden_reach import GOLDEN, LAST, MID, REACH
from golden_reach import plan_scenario as _scenario
from golden_reach import reach_step as _step

from rb_drake import geometry
from rb_drake.collision import ANCHOR_CLEARANCE, boom_clearances, free_clearance
from rb_drake.feasibility import Reason, check_poses
from rb_drake.kernel.scoring import score_poses


@pytest.fixture(scope="module")
def golden() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text())


def _square(centre: np.ndarray, half: float) -> list[list[float]]:
    x, y = float(centre[0]), float(centre[1])
    return [[x - half, y - half], [x + half, y - half], [x + half, y + half], [x - half, y + half]]


def _with_rock(plan: dict[str, Any], polygon: list[list[float]]) -> dict[str, Any]:
    out = copy.deepcopy(plan)
    out["scenario"]["walls"].append(polygon)
    return out




def test_free_clearance_shrinks_with_the_distance_to_the_nearest_anchor() -> None:
    anchors = np.array([[0.0, 0.0], [1.0, 0.0]])
    tips = np.array([[0.0, 0.0], [0.005, 0.0], [1.0, 0.012], [0.5, 0.0], [np.nan, np.nan]])
    got = free_clearance(anchors, tips)
    assert got == pytest.approx([ANCHOR_CLEARANCE, ANCHOR_CLEARANCE - 0.005,
                                 ANCHOR_CLEARANCE - 0.012, 0.0, ANCHOR_CLEARANCE])
    assert free_clearance(np.zeros((0, 2)), tips[:1]) == pytest.approx([0.0])  # no anchor near
    # held booms keep the anchor's allowance
    both = boom_clearances(anchors, 2, 3, tips[3])
    assert both[:, :3] == pytest.approx(np.full((2, 3), ANCHOR_CLEARANCE))
    assert both[:, 3] == pytest.approx([0.0, 0.0])


def test_a_free_gripper_inside_rock_mid_reach_is_infeasible(golden: dict[str, Any]) -> None:
    pose, tip = _step(golden, MID)
    scn = _scenario(golden)
    stance = scn.stance(tuple(golden["phases"][REACH]["stance"]))
    assert check_poses(scn, stance, pose, tip).feasible[0]  # the plan's own step
    # a 12 mm pebble around the gripper: inside ANCHOR_CLEARANCE of the tip, so the old rule
    # (every boom checked to 2 cm short of its tip) let it through
    pebbled = _scenario(_with_rock(golden, _square(tip, 0.006)))
    check = check_poses(pebbled, stance, pose, tip)
    kernel = score_poses(pebbled, stance, pose[None], tip)
    assert not check.feasible[0] and not kernel.feasible[0]
    assert check.reason[0] == kernel.reason[0] == Reason.BOOM_COLLISION
    assert check.boom[0] == stance.free_boom


def test_at_an_anchor_the_gripper_keeps_the_anchor_allowance(golden: dict[str, Any]) -> None:
    pose, tip = _step(golden, LAST)
    scn = _scenario(golden)
    stance = scn.stance(tuple(golden["phases"][REACH]["stance"]))
    assert np.linalg.norm(scn.anchor_positions - tip, axis=1).min() == 0.0
    assert free_clearance(scn.anchor_positions, tip)[()] == ANCHOR_CLEARANCE
    # the gripper at the anchor lies in its rock, and the boom's last 2 cm touch it ...
    u = geometry.boom_geometry(scn.robot, pose, np.broadcast_to(tip, (4, 2))).u[0, 2]
    assert scn.rock.segments_hit(tip - ANCHOR_CLEARANCE * u, tip)[()]
    # ... which the anchor's allowance admits, as before
    assert check_poses(scn, stance, pose, tip).feasible[0]
    assert score_poses(scn, stance, pose[None], tip).feasible[0]


def test_rbp_check_refuses_a_gripper_through_a_rock_spike(golden: dict[str, Any],
                                                            tmp_path: Path) -> None:
    # a 10 mm rock square where the gripper passes between steps MID and MID + 1 (not at
    # either step), as /tmp/probe9's spike10mm: only the motion between steps meets it
    _, a = _step(golden, MID)
    _, b = _step(golden, MID + 1)
    spiked = _with_rock(golden, _square((a + b) / 2, 0.005))
    assert np.linalg.norm(b - a) > 0.012  # both steps' grippers lie outside the square
    path = tmp_path / "spike.json"
    path.write_text(json.dumps(spiked))
    result = run_rbp("check", str(path), cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert f"phases[{REACH}] (reach) step {MID}" in result.stdout
    assert "between" in result.stdout and "boom 2: boom collides with rock" in result.stdout
    # and the pebble around the gripper at a step: rule `collision` at that step
    _, c = _step(golden, MID)
    path.write_text(json.dumps(_with_rock(golden, _square(c, 0.006))))
    result = run_rbp("check", str(path), cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert (f"phases[{REACH}] (reach) step {MID} " in result.stdout
            and "collision: boom 2 collides with rock" in result.stdout)


def test_kernel_and_check_poses_agree_near_an_anchor(golden: dict[str, Any]) -> None:
    """Tips around the new anchor, 0 to 3 cm from it, in and out of its rock: the kernel's
    per-tip clearance decides as check_poses' does, pose for pose."""
    pose, anchor = _step(golden, LAST)
    scn = _scenario(golden)
    stance = scn.stance(tuple(golden["phases"][REACH]["stance"]))
    rng = np.random.default_rng(3)
    radius = rng.uniform(0.0, 0.03, 400)
    angle = rng.uniform(0.0, 2 * np.pi, 400)
    tips = anchor + np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    poses = np.broadcast_to(pose, (len(tips), 3))
    check = check_poses(scn, stance, poses, tips, full=True)
    kernel = score_poses(scn, stance, poses, tips)
    np.testing.assert_array_equal(kernel.reason, check.reason)
    hit = check.reason == Reason.BOOM_COLLISION
    assert hit.any() and (~hit).any(), "the sample should hold tips both clear and in rock"
