"""The golden demo-shaft plan's first reach phase, shared by the free-gripper tests
(tests/test_free_gripper.py, tests/test_free_gripper_own.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rb_drake.scenario import Scenario, scenario_from_dict

GOLDEN = Path(__file__).resolve().parent / "data" / "golden" / "demo-shaft-current.json"
REACH = 1  # the golden plan's first reach phase: boom 2 from anchor a1 to a3
MID = 25   # a step in the middle of it, its gripper 7 cm from every anchor
LAST = 49  # a step with the gripper at the new anchor, which sits in its rock


def plan_scenario(plan: dict[str, Any]) -> Scenario:
    return scenario_from_dict(plan["scenario"], check_start=False)


def reach_step(plan: dict[str, Any], n: int) -> tuple[np.ndarray, np.ndarray]:
    """Step n of the reach phase: its pose and free gripper position."""
    step = plan["phases"][REACH]["steps"][n]
    return np.array(step["pose"], dtype=float), np.array(step["free_tip"], dtype=float)
