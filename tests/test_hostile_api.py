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
    (STEP_T, True, "phases[0].steps[1].t", "not of type 'number'"),
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
    with pytest.raises(ConfigError, match=r"^config: dt: must be a number from 0\.25"):
        rbp.plan("demo-shaft", rbp.PipelineConfig(dt=0.0), footsteps_done=calls.append)
    footstep = dataclasses.replace(rbp.FootstepConfig(), max_expansions=-5)
    with pytest.raises(ConfigError, match=r"^config: footstep.max_expansions: must be a whole"):
        rbp.plan("demo-shaft", rbp.PipelineConfig(footstep=footstep), footsteps_only=True,
                 footsteps_done=calls.append)
    with pytest.raises(RbpInputError, match=r"^config: expected a planning.pipeline"):
        rbp.plan("demo-shaft", "x", footsteps_only=True)  # type: ignore[arg-type]
    assert calls == []  # refused before the footstep search


def _phase(plan: rbp.Plan, **changes: Any) -> rbp.Plan:
    phases = list(plan.phases)
    phases[0] = dataclasses.replace(phases[0], **changes)
    return plan.replace(phases=tuple(phases))


def _step(plan: rbp.Plan, **changes: Any) -> rbp.Plan:
    steps = list(plan.phases[0].steps)
    steps[1] = dataclasses.replace(steps[1], **changes)
    return _phase(plan, steps=tuple(steps))


@pytest.fixture(scope="module")
def plan_obj(plan_dict: dict[str, Any]) -> rbp.Plan:
    return rbp.Plan.from_dict(plan_dict)


@pytest.mark.parametrize(("edit", "field"), [
    (lambda p: _step(p, pose=(float("nan"), 1.0, 0.0)), "phases[0].steps[1].pose[0]"),
    (lambda p: _step(p, pose=(1.0,)), "phases[0].steps[1].pose"),
    (lambda p: _step(p, pose=None), "phases[0].steps[1].pose"),
    (lambda p: _step(p, t="x"), "phases[0].steps[1].t"),
    (lambda p: _step(p, tension=(1e308,) * 4), "phases[0].steps[1].tension["),
    (lambda p: _phase(p, steps=()), "phases[0].steps"),
    (lambda p: _phase(p, kind="zzz"), "phases[0].kind"),
    (lambda p: p.replace(phases=None), "phases"),
    (lambda p: p.replace(scenario=None), "scenario"),
    (lambda p: p.replace(scenario="x"), "scenario"),
    (lambda p: p.replace(format="x"), "format"),
    (lambda p: p.replace(timing="x"), "timing"),
    (lambda p: p.replace(success="x"), "success"),
    (lambda p: p.replace(time_step=5e-324), "time_step"),
    (lambda p: p.replace(robot={**p.robot, "body_mass": float("nan")}), "robot.body_mass"),
])
def test_plan_objects_are_read_as_plan_files(plan_obj: rbp.Plan, edit: Any, field: str,
                                             tmp_path: Path) -> None:
    """A Plan's fields are the caller's to replace: checked as its file would be read (a NaN
    pose ended rbp.simulate in Drake's abort, a SystemExit; others in numpy's errors)."""
    bad = edit(plan_obj)
    for call in (rbp.check, rbp.simulate, lambda p: rbp.write_plan(p, tmp_path / "w.json"),
                 lambda p: rbp.draw(p, tmp_path / "w.png")):
        with pytest.raises(PlanFileError) as e:
            call(bad)
        assert (e.value.field or "").startswith(field)  # which of 4 tensions: jsonschema's choice
    assert list(tmp_path.iterdir()) == []


def test_a_valid_plan_object_is_unchanged(plan_obj: rbp.Plan) -> None:
    from planning.plan_file import plan_from

    assert plan_from(plan_obj) == plan_obj
    assert rbp.check(plan_obj) == []


@pytest.mark.parametrize("path", [5, b"plan.json", None, ["plan.json"]])
def test_paths_of_a_wrong_type_name_the_argument(path: Any) -> None:
    with pytest.raises(RbpInputError, match=r"^path: expected a file path \(str or Path\)"):
        rbp.read_plan(path)
    with pytest.raises(RbpInputError, match=r"^path: expected a file path \(str or Path\)"):
        rbp.import_scenario(path)
    with pytest.raises(RbpInputError, match=r"^path_or_name: expected a file path"):
        rbp.load_scenario(path)


@pytest.mark.parametrize(("changes", "field"), [
    ({"start_pose": (float("nan"), 0.0, 0.0)}, "start.pose[0]"),
    ({"start_stance": ("x",)}, "start.stance"),
    ({"goal_tolerance": -1.0}, "goal.tolerance"),
    ({"start_pose": None}, "(top level)"),
    ({"robot": None}, "(top level)"),
])
def test_scenario_objects_are_read_as_scenario_files(changes: dict[str, Any], field: str,
                                                     tmp_path: Path) -> None:
    bad = dataclasses.replace(rbp.load_scenario("demo-shaft"), **changes)
    with pytest.raises(ScenarioError, match=r"^\(scenario argument\): ") as e:
        rbp.plan(bad, footsteps_only=True)
    assert e.value.field == field
    with pytest.raises(ScenarioError, match=r"^\(scenario_or_plan argument\): "):
        rbp.draw(bad, tmp_path / "x.png")
    assert list(tmp_path.iterdir()) == []


def test_a_valid_scenario_object_is_read_back_unchanged() -> None:
    from rb_drake.scenario import checked_scenario

    scn = rbp.load_scenario("demo-shaft")
    assert checked_scenario(scn, "(x)").to_dict() == scn.to_dict()  # overrides kept
    heavy = dataclasses.replace(scn, robot=dataclasses.replace(scn.robot,
                                                               body_mass=float("nan")))
    with pytest.raises(ScenarioError, match=r"^\(x\): robot.body_mass: must be finite"):
        checked_scenario(heavy, "(x)")  # a replaced robot, not its overrides


def test_flags_must_be_bools() -> None:
    with pytest.raises(RbpInputError, match=r"^check_start: expected True or False"):
        rbp.load_scenario("demo-shaft", check_start="no")  # type: ignore[arg-type]
    with pytest.raises(RbpInputError, match=r"^footsteps_only: expected True or False"):
        rbp.plan("demo-shaft", footsteps_only="x")  # type: ignore[arg-type]


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"length": (4.0, 5.0, 6.0)}, "length"),
    ({"length": 5.0}, "length"),
    ({"config": "x"}, "config"),
    ({"config": rbp.CaveConfig(roughness=float("nan"))}, "config.roughness"),
    ({"config": rbp.CaveConfig(width=(-1.0, 1.0))}, "config.width"),
    ({"config": rbp.CaveConfig(limit_normal=None)}, "config.limit_normal"),  # type: ignore
    ({"config": rbp.CaveConfig(max_redraws=-1)}, "config.max_redraws"),
    ({"config": rbp.CaveConfig(max_redraws=10**9)}, "config.max_redraws"),
    ({"config": rbp.CaveConfig(gravity=(float("nan"), 0.0))}, "config.gravity"),
    ({"config": rbp.CaveConfig(sigma_normal=(10**400, 1.0))}, "config.sigma_normal"),
])
def test_generate_scenario_checks_its_config_before_any_draw(
        kwargs: dict[str, Any], field: str, monkeypatch: pytest.MonkeyPatch) -> None:
    import rb_drake.generate

    def no_draw(*args: Any) -> None:
        raise AssertionError("drew a cave")

    monkeypatch.setattr(rb_drake.generate, "_shaft", no_draw)
    with pytest.raises(RbpInputError) as e:
        rbp.generate_scenario(**kwargs)
    assert e.value.field == field
