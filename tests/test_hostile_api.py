"""The Python API (`import rbp`) given hostile arguments: each is refused with rbp's own error
(RbpInputError and its PlanFileError, ScenarioError, ConfigError) naming the argument or field,
before any work, never a numpy/Drake/json exception nor an abort of the interpreter (a NaN pose
given to rbp.simulate ended the process in Drake's `AllFinite(q)`)."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path
from typing import Any

import pytest

import rbp
from planning.config_io import ConfigError
from planning.plan_file import PlanFileError
from rb_drake.errors import RbpInputError
from rb_drake.scenario import ScenarioError


@pytest.fixture(scope="module")
def plan_dict() -> dict[str, Any]:
    """A footstep plan of demo-shaft as a plan-file object (seconds to plan)."""
    plan = rbp.plan("demo-shaft", footsteps_only=True)
    assert plan.success
    return plan.to_dict()


def _with(plan: dict[str, Any], path: list[Any], value: Any) -> dict[str, Any]:
    bad = copy.deepcopy(plan)
    where = bad
    for key in path[:-1]:
        where = where[key]
    where[path[-1]] = value
    return bad


STEP_T = ["phases", 0, "steps", 1, "t"]
POSE_X = ["phases", 0, "steps", 1, "pose", 0]


@pytest.mark.parametrize(("path", "value", "field", "reason"), [
    (POSE_X, float("nan"), "phases[0].steps[1].pose[0]", "finite"),
    (POSE_X, float("inf"), "phases[0].steps[1].pose[0]", "finite"),
    (STEP_T, 10**400, "phases[0].steps[1].t", "beyond a float's range"),
    (STEP_T, True, "phases/0/steps/1/t", "not of type 'number'"),
    (["phases"], "x", "phases", "not of type 'array'"),
])
def test_plan_dicts_are_read_as_plan_files(plan_dict: dict[str, Any], path: list[Any],
                                           value: Any, field: str, reason: str) -> None:
    bad = _with(plan_dict, path, value)
    for call in (rbp.check, rbp.simulate):
        with pytest.raises(PlanFileError) as e:
            call(bad)
        assert e.value.field == field and reason in e.value.reason


def test_plan_of_a_wrong_type_or_missing_keys(plan_dict: dict[str, Any]) -> None:
    wrong: object
    for wrong in ("x", [], None, 5):
        with pytest.raises(RbpInputError, match=r"^plan: expected a Plan"):
            rbp.check(wrong)  # type: ignore[arg-type]
    with pytest.raises(PlanFileError, match="required property"):
        rbp.check({})
    with pytest.raises(RbpInputError, match=r"^scenario_or_plan: expected a Scenario"):
        rbp.draw("demo-shaft", "x.png")  # type: ignore[arg-type]
    # a tuple is what a Python caller writes for a list: accepted as JSON writes it
    assert rbp.check(_with(plan_dict, ["phases", 0, "steps", 1, "pose"],
                           tuple(plan_dict["phases"][0]["steps"][1]["pose"]))) == []


def test_check_takes_a_scenario_by_name(plan_dict: dict[str, Any]) -> None:
    assert rbp.check(plan_dict, scenario="demo-shaft") == []
    with pytest.raises(RbpInputError, match=r"^scenario: expected a Scenario"):
        rbp.check(plan_dict, scenario=5)  # type: ignore[arg-type]


def test_write_plan_refuses_bad_plans_and_paths(plan_dict: dict[str, Any],
                                                tmp_path: Path) -> None:
    with pytest.raises(PlanFileError, match=r"^phases: 'x' is not of type"):
        rbp.write_plan(_with(plan_dict, ["phases"], "x"), tmp_path / "w.json")
    with pytest.raises(PlanFileError, match="finite"):
        rbp.write_plan(_with(plan_dict, POSE_X, float("nan")), tmp_path / "w.json")
    with pytest.raises(RbpInputError, match=f"^{tmp_path}: is a directory"):
        rbp.write_plan(plan_dict, tmp_path)
    assert not (tmp_path / "w.json").exists()


def test_draw_refuses_bad_suffix_and_dpi(tmp_path: Path) -> None:
    scn = rbp.load_scenario("demo-shaft")
    with pytest.raises(RbpInputError, match="a picture's suffix must be one of"):
        rbp.draw(scn, tmp_path / "x.weird")
    for dpi in (0, -5, 19, 601, 100000, float("nan"), 100.0, True):
        with pytest.raises(RbpInputError, match=r"^dpi: must be a whole number from 20 to 600"):
            rbp.draw(scn, tmp_path / "x.png", dpi=dpi)  # type: ignore[arg-type]
    with pytest.raises(PlanFileError, match=r"^format: "):
        rbp.draw({"format": "x"}, tmp_path / "x.png")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["a\x00b", "x" * 5000])
def test_unreadable_names_name_the_file(name: str) -> None:
    with pytest.raises(ScenarioError, match="cannot read"):
        rbp.load_scenario(name)
    with pytest.raises(PlanFileError, match="cannot read") as e:
        rbp.read_plan(name)
    assert e.value.file == name and e.value.field == "(file)"
    with pytest.raises(RbpInputError, match=r"^path_or_name: expected"):
        rbp.load_scenario(name.encode())  # type: ignore[arg-type]


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"anchor_density": 1e308}, "anchor_density"),
    ({"anchor_density": float("inf")}, "anchor_density"),
    ({"anchor_density": "3"}, "anchor_density"),
    ({"anchor_density": 20.5}, "anchor_density"),
    ({"length": ("a", 5.0)}, "length"),
    ({"seed": -1}, "seed"),
    ({"seed": 1.5}, "seed"),
    ({"seed": 2**80}, "seed"),
])
def test_generate_scenario_takes_the_command_lines_ranges(kwargs: dict[str, Any],
                                                          field: str) -> None:
    with pytest.raises(RbpInputError) as e:
        rbp.generate_scenario(**kwargs)
    assert e.value.field == field


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"trials": 10**30}, "trials"), ({"trials": 1_000_001}, "trials"),
    ({"trials": 1.5}, "trials"), ({"trials": True}, "trials"), ({"trials": "3"}, "trials"),
    ({"trials": -1}, "trials"), ({"seed": 1.5}, "seed"), ({"seed": 2**63}, "seed"),
])
def test_simulate_takes_the_command_lines_ranges(plan_dict: dict[str, Any],
                                                 kwargs: dict[str, Any], field: str) -> None:
    with pytest.raises(RbpInputError, match=rf"^{field}: must be a whole number from 0 to "):
        rbp.simulate(plan_dict, **kwargs)


def test_plan_checks_its_configuration_before_any_work() -> None:
    calls: list[object] = []
    with pytest.raises(ConfigError, match=r"^config: dt: must be a number from 0\.01"):
        rbp.plan("demo-shaft", rbp.PipelineConfig(dt=0.0), footsteps_done=calls.append)
    footstep = dataclasses.replace(rbp.FootstepConfig(), max_expansions=-5)
    with pytest.raises(ConfigError, match=r"^config: footstep.max_expansions: must be a whole"):
        rbp.plan("demo-shaft", rbp.PipelineConfig(footstep=footstep), footsteps_only=True,
                 footsteps_done=calls.append)
    with pytest.raises(RbpInputError, match=r"^config: expected a planning.pipeline"):
        rbp.plan("demo-shaft", "x", footsteps_only=True)  # type: ignore[arg-type]
    assert calls == []  # refused before the footstep search
