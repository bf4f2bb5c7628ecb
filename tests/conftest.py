"""Shared fixtures: a vertical-shaft scenario built in code (no files outside the repository).

The shaft is two counter-clockwise rock polygons either side of x = 0, with four microspine
anchors on the walls (two at y = 2, two at y = 0.3), Mars gravity and the start pose (0, 1, 0).
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

# The package is not installed in the test virtualenv: make the repository importable.
ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from rb_drake.params import RobotParams  # noqa: E402
from rb_drake.scenario import Scenario, scenario_from_dict  # noqa: E402
from rb_drake.stance import Stance  # noqa: E402

GRASP = {"limit": {"normal": 40, "lateral": 20}, "sigma": {"normal": 3, "lateral": 5}}

SHAFT: dict[str, Any] = {
    "format": "reachbot-scenario/1",
    "name": "test-shaft",
    "gravity": [0.0, -3.71],
    "robot": {},
    "walls": [
        [[-2.0, 0.0], [-1.2, 0.0], [-1.1, 8.0], [-2.0, 8.0]],
        [[1.2, 0.0], [2.0, 0.0], [2.0, 8.0], [1.2, 8.0]],
    ],
    "anchors": [
        {"id": "a0", "position": [1.2, 2.0], "normal": 180, **GRASP},
        {"id": "a1", "position": [-1.175, 2.0], "normal": [1.0, 0.0], **GRASP},
        {"id": "a2", "position": [-1.2, 0.3], "normal": [1.0, 0.0], **GRASP},
        {"id": "a3", "position": [1.2, 0.3], "normal": 180, **GRASP},
    ],
    "start": {"pose": [0.0, 1.0, 0.0], "stance": ["a0", "a1", "a2", "a3"]},
    "goal": {"position": [0.0, 7.0], "tolerance": 0.5},
}

ScenarioFactory = Callable[..., Scenario]


def build_shaft(robot: Mapping[str, Any] | None = None,
                extra_walls: Sequence[Sequence[Sequence[float]]] = (),
                anchor_updates: Mapping[str, Mapping[str, Any]] | None = None) -> Scenario:
    """The shaft, optionally with robot overrides, extra rock polygons and changed anchors."""
    data = copy.deepcopy(SHAFT)
    if robot:
        data["robot"] = dict(robot)
    data["walls"] = data["walls"] + [[list(p) for p in poly] for poly in extra_walls]
    for anchor in data["anchors"]:
        anchor.update(copy.deepcopy(dict((anchor_updates or {}).get(anchor["id"], {}))))
    return scenario_from_dict(data, source="<test-shaft>", check_start=False)


@pytest.fixture(scope="session")
def shaft() -> Scenario:
    return build_shaft()


@pytest.fixture
def make_scenario() -> ScenarioFactory:
    """A factory: make_scenario(robot=..., extra_walls=..., anchor_updates=...)."""
    return build_shaft


@pytest.fixture(scope="session")
def robot(shaft: Scenario) -> RobotParams:
    return shaft.robot


@pytest.fixture(scope="session")
def gravity(shaft: Scenario) -> np.ndarray:
    return shaft.gravity_vector


@pytest.fixture(scope="session")
def start_stance(shaft: Scenario) -> Stance:
    return shaft.stance(shaft.start_stance)


@pytest.fixture
def start_pose(shaft: Scenario) -> np.ndarray:
    return np.array(shaft.start_pose, dtype=float)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


MUTATION_CAVES = ("demo-shaft", "demo-crevasse", "rockfall-3")


@pytest.fixture(scope="session")
def cave_plans() -> dict[str, dict]:
    """Full plans (`rbp plan`'s pipeline) of three bundled caves, planned once per session:
    the valid plans the verifier tests damage, as plan-file objects (what a file holds).
    Tests deep-copy before changing one."""
    from planning.pipeline import plan_climb
    from planning.plan_model import plan_dict
    from rb_drake.scenario import bundled_caves, load_scenario

    plans = {}
    for name in MUTATION_CAVES:
        plan = plan_dict(plan_climb(load_scenario(bundled_caves()[name])))
        assert plan["success"], f"{name}: {plan['reason']}"
        plans[name] = plan
    return plans
