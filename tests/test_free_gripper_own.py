"""A free gripper may touch rock only near its OWN anchors, the one it leaves and the one it
reaches (`rb_drake.feasibility.reach_world`), not near any anchor of the cave: a rock nub
carrying an unrelated anchor was crossed unseen (/tmp/probe10 F4).

Built on the golden demo-shaft plan (tests/data/golden/demo-shaft-current.json): its phase 1
reaches with boom 2 from anchor a1 to a3; a small rock nub with an anchor of its own is put in
the gripper's way.
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

from planning.between import dense_problem
from planning.plan_model import Plan
from planning.reach_seeds import reach_seed
from planning.verify_between import phase_world
from rb_drake.feasibility import ReachWorld, Reason, check_poses, reach_world
from rb_drake.kernel.scoring import score_poses
from rb_drake.scenario import Scenario


@pytest.fixture(scope="module")
def golden() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text())


def _nub(plan: dict[str, Any], centre: np.ndarray, half: float) -> dict[str, Any]:
    """`plan` with a square rock nub of side 2 `half` at `centre` carrying an anchor `zz`
    that the plan does not use."""
    out = copy.deepcopy(plan)
    x, y = float(centre[0]), float(centre[1])
    out["scenario"]["walls"].append([[x - half, y - half], [x + half, y - half],
                                     [x + half, y + half], [x - half, y + half]])
    anchor = copy.deepcopy(out["scenario"]["anchors"][0])
    anchor.update(id="zz", position=[x, y])
    out["scenario"]["anchors"].append(anchor)
    return out




def _own(plan: dict[str, Any], scn: Scenario) -> np.ndarray:
    phase = plan["phases"][REACH]
    return scn.anchor_positions[[scn.anchor_index[phase["from_anchor"]],
                                 scn.anchor_index[phase["to_anchor"]]]]


def test_the_reach_world_holds_the_phase_own_anchors(golden: dict[str, Any]) -> None:
    scn = _scenario(golden)
    own = _own(golden, scn)
    world = phase_world(scn, Plan.from_dict(golden).phases[REACH])
    assert world.anchor_positions == pytest.approx(own)
    assert reach_world(scn, None) is scn  # no free gripper: the world as it is
    body = Plan.from_dict(golden).phases[0]
    assert phase_world(scn, body) is scn


def test_a_nub_with_an_unrelated_anchor_stops_the_gripper(golden: dict[str, Any]) -> None:
    pose, tip = _step(golden, MID)
    nubbed = _scenario(_nub(golden, tip, 0.005))
    stance = nubbed.stance(tuple(golden["phases"][REACH]["stance"]))
    # the cave's anchors (the rule before): the nub's anchor `zz` at the tip hid the nub
    assert check_poses(nubbed, stance, pose, tip).feasible[0]
    # its own anchors only: the gripper is in rock
    world = reach_world(nubbed, _own(golden, nubbed))
    check = check_poses(world, stance, pose, tip)
    kernel = score_poses(world, stance, pose[None], tip)
    assert not check.feasible[0] and not kernel.feasible[0]
    assert check.reason[0] == kernel.reason[0] == Reason.BOOM_COLLISION


def test_at_its_own_anchor_the_allowance_holds(golden: dict[str, Any]) -> None:
    pose, tip = _step(golden, LAST)  # the gripper at a3, in its rock
    scn = _scenario(golden)
    stance = scn.stance(tuple(golden["phases"][REACH]["stance"]))
    world = reach_world(scn, _own(golden, scn))
    assert check_poses(world, stance, pose, tip).feasible[0]
    assert score_poses(world, stance, pose[None], tip).feasible[0]
    # with no anchor of its own the gripper's boom would touch a3's rock
    none = ReachWorld(scn.robot, scn.rock, scn.gravity_vector, np.zeros((0, 2)))
    assert not check_poses(none, stance, pose, tip).feasible[0]


def test_rbp_check_refuses_a_crossing_of_a_nub_with_an_anchor(golden: dict[str, Any],
                                                               tmp_path: Path) -> None:
    # a 10 mm nub carrying anchor zz where the gripper passes between steps MID and MID + 1
    # (/tmp/probe10's nub_anchor): rule `between`
    _, a = _step(golden, MID)
    _, b = _step(golden, MID + 1)
    assert np.linalg.norm(b - a) > 0.012  # both steps' grippers lie outside the nub
    path = tmp_path / "nub.json"
    path.write_text(json.dumps(_nub(golden, (a + b) / 2, 0.005)))
    result = run_rbp("check", str(path), cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert f"phases[{REACH}] (reach) step {MID}" in result.stdout
    assert "between" in result.stdout and "boom 2: boom collides with rock" in result.stdout
    # the nub around the gripper at a step: rule `collision` at that step
    path.write_text(json.dumps(_nub(golden, a, 0.006)))
    result = run_rbp("check", str(path), cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert (f"phases[{REACH}] (reach) step {MID} " in result.stdout
            and "collision: boom 2 collides with rock" in result.stdout)


def test_the_reach_seed_does_not_cross_the_nub(golden: dict[str, Any]) -> None:
    """The planner decides as the verifier: its reach seed either fails or its motion passes
    rule `between`'s samples in the phase's own world."""
    _, a = _step(golden, MID)
    _, b = _step(golden, MID + 1)
    plan = _nub(golden, (a + b) / 2, 0.005)
    scn = _scenario(plan)
    phase = plan["phases"][REACH]
    four = tuple(plan["phases"][REACH - 1]["stance"])
    pose = np.array(phase["steps"][0]["pose"], dtype=float)
    seed = reach_seed(scn, four, phase["free_boom"], phase["to_anchor"], pose)
    if seed.success:
        assert seed.tips is not None
        stance = scn.stance(tuple(phase["stance"]))
        assert dense_problem(reach_world(scn, seed.tips), stance, seed.poses, seed.tips) == ""
