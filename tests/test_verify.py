"""`rbp check` verifies the whole climb (planning.verify_climb + planning.check): the faults of
issue 16, each rejected with its rule, phase and step; NaN and Infinity refused when a plan is
read (exit 2, one line naming file and field); the stamp of `rbp check --stamp`."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest

from planning.check import verify_plan
from planning.plan import score_plan
from planning.plan_file import (
    PlanFileError,
    content_hash,
    has_valid_stamp,
    parse_plan_text,
)
from planning.plan_model import plan_of
from planning.verify_climb import RULES
from rbp.cli import main

Plan = dict[str, Any]


@pytest.fixture
def plan(cave_plans: dict[str, Plan]) -> Plan:
    return copy.deepcopy(cave_plans["demo-shaft"])


def rules_at(problems) -> dict[str, set[tuple[int | None, int | None]]]:
    out: dict[str, set] = {}
    for p in problems:
        out.setdefault(p.rule, set()).add((p.phase, p.step))
    return out


def test_the_planned_plans_verify(cave_plans: dict[str, Plan]) -> None:
    for name, plan in cave_plans.items():
        problems = verify_plan(plan)
        assert problems == [], f"{name}: " + "\n".join(map(str, problems[:5]))
        assert plan["limits"] == {"step": 0.1, "turn_step": 0.1}, plan.get("limits")


def test_every_problem_names_a_documented_rule() -> None:
    text = (Path(__file__).resolve().parents[1] / "docs" / "formats.md").read_text()
    for rule in RULES:
        assert f"`{rule}`" in text, f"rule {rule} is not documented in docs/formats.md"


def _body(plan: Plan, min_steps: int = 4) -> int:
    return next(k for k, p in enumerate(plan["phases"])
                if p["kind"] == "body" and len(p["steps"]) >= min_steps)


# The faults issue 16 found accepted, each with the rule (and phase) that must now reject it.

def test_a_deleted_step(plan: Plan) -> None:
    k = _body(plan)
    del plan["phases"][k]["steps"][2]
    found = rules_at(verify_plan(plan))
    assert (k, 2) in found.get("time-order", set()), found


def test_a_duplicated_body_phase(plan: Plan) -> None:
    k = _body(plan)
    plan["phases"].insert(k, copy.deepcopy(plan["phases"][k]))
    found = rules_at(verify_plan(plan))
    assert (k + 1, None) in found.get("phase-order", set()), found
    assert (k + 1, 0) in found.get("phase-join", set()), found


def test_reversed_steps(plan: Plan) -> None:
    k = _body(plan)
    plan["phases"][k]["steps"].reverse()
    found = rules_at(verify_plan(plan))
    assert (k, 1) in found.get("time-order", set()), found


def test_a_step_replaced_by_a_later_one(plan: Plan) -> None:
    k = _body(plan)
    steps = plan["phases"][k]["steps"]
    steps[1] = copy.deepcopy(steps[3])
    found = rules_at(verify_plan(plan))
    assert (k, 2) in found.get("time-order", set()), found


@pytest.mark.parametrize("shift", [-0.25, +0.1])
def test_a_time_set_back_or_forward(plan: Plan, shift: float) -> None:
    k = _body(plan)
    plan["phases"][k]["steps"][2]["t"] += shift
    found = rules_at(verify_plan(plan))
    assert {(k, 2), (k, 3)} & found.get("time-order", set()), found


def test_the_goal_moved_next_to_the_start(plan: Plan) -> None:
    plan["scenario"]["goal"]["position"] = plan["scenario"]["start"]["pose"][:2]
    problems = verify_plan(plan)
    last = len(plan["phases"]) - 1
    assert any(p.rule == "goal" and p.phase == last for p in problems), problems
    assert "goal" in str(next(p for p in problems if p.rule == "goal"))


def test_the_start_moved(plan: Plan) -> None:
    plan["scenario"]["start"]["pose"][0] += 1.5
    found = rules_at(verify_plan(plan))
    assert (0, 0) in found.get("start", set()), found


def test_half_the_phases_with_the_summary_recomputed(plan: Plan) -> None:
    plan["phases"] = plan["phases"][:len(plan["phases"]) // 2]
    scored = score_plan(plan_of(plan), plan["robot"]["attach_failure"])
    plan.update(p_path=scored.p_path, p_grasps=scored.p_grasps, p_min=scored.p_min,
                regrasps=scored.regrasps)
    found = rules_at(verify_plan(plan))
    assert "goal" in found or "phase-order" in found, found


def test_a_grasp_probability_raised(plan: Plan) -> None:
    k = _body(plan)
    step = plan["phases"][k]["steps"][1]
    step["p_grasp"][0] = 0.999 if step["p_grasp"][0] != 0.999 else 0.998
    found = rules_at(verify_plan(plan))
    assert (k, 1) in found.get("recorded-value", set()), found


def test_a_recorded_shoulder_torque_of_99(plan: Plan) -> None:
    k = next(k for k, p in enumerate(plan["phases"]) if p["kind"] == "reach")
    plan["phases"][k]["steps"][1]["shoulder_torque"] = 99.0
    found = rules_at(verify_plan(plan))
    assert (k, 1) in found.get("recorded-value", set()), found


def test_a_heavier_robot_under_scenario(plan: Plan) -> None:
    """A `reachbot-plan/1` file keeps a second copy of the robot under `scenario`: the verifier
    refuses one that differs from the robot (a plan of today's format stores it once)."""
    assert "robot" not in plan["scenario"], "the robot is stored once"
    plan["scenario"]["robot"] = dict(plan["robot"], body_mass=plan["robot"]["body_mass"] * 1.5)
    problems = verify_plan(plan)
    assert any(p.rule == "robot" and "body_mass" in p.text for p in problems), problems


def test_a_jump_in_a_trajectory(plan: Plan) -> None:
    k = _body(plan)
    plan["phases"][k]["steps"][2]["pose"][1] += 0.3
    found = rules_at(verify_plan(plan))
    assert {(k, 2), (k, 3)} <= found.get("continuity", set()), found


def test_a_jump_of_the_free_tip(plan: Plan) -> None:
    k = next(k for k, p in enumerate(plan["phases"])
             if p["kind"] == "reach" and len(p["steps"]) >= 4)
    plan["phases"][k]["steps"][2]["free_tip"][0] += 0.3
    found = rules_at(verify_plan(plan))
    assert (k, 2) in found.get("continuity", set()), found


@pytest.mark.parametrize("drop", ["time_step", "motion"])
def test_a_trajectory_cannot_shed_its_time_step_or_motion(plan: Plan, drop: str) -> None:
    """Without them the trajectory's continuity and spacing would go unchecked."""
    k = _body(plan)
    del (plan if drop == "time_step" else plan["phases"][k])[drop]
    found = rules_at(verify_plan(plan))
    assert (0 if drop == "time_step" else k, None) in found.get("phase-form", set()), found


def test_messages_name_phase_step_and_rule(plan: Plan, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    k = _body(plan)
    del plan["phases"][k]["steps"][2]
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"{path}: phases[{k}] (body) step 2 (t=" in out and ": time-order: " in out, out


# Bad numbers

@pytest.mark.parametrize("text, field", [
    ('{"a": NaN}', "a"),
    ('{"a": [1, {"b": Infinity}]}', "a[1].b"),
    ('{"a": -Infinity}', "a"),
    ('{"a": {"b": 1e999}}', "a.b"),
])
def test_non_finite_numbers_are_refused_on_reading(text: str, field: str) -> None:
    with pytest.raises(PlanFileError) as err:
        parse_plan_text(text)
    assert err.value.field == field, str(err.value)
    assert "finite" in err.value.reason


@pytest.mark.parametrize("where", ["pose", "t", "tension", "gravity"])
def test_rbp_check_refuses_nan_with_one_line(plan: Plan, tmp_path: Path, where: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    step = plan["phases"][0]["steps"][1]
    field = {"pose": "phases[0].steps[1].pose[0]", "t": "phases[0].steps[1].t",
             "tension": "phases[0].steps[1].tension[0]", "gravity": "scenario.gravity[1]"}[where]
    if where == "pose":
        step["pose"][0] = math.nan
    elif where == "t":
        step["t"] = math.inf
    elif where == "tension":
        step["tension"][0] = -math.inf
    else:
        plan["scenario"]["gravity"][1] = math.nan
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))  # allow_nan: Python writes NaN and Infinity
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"error: {path}: {field}: must be a finite number"), err


# The stamp

def test_check_stamp_marks_a_verified_plan_and_an_edit_unmarks_it(
        plan: Plan, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    assert main(["check", "--stamp", str(path)]) == 0
    stamped = json.loads(path.read_text())
    assert has_valid_stamp(stamped), stamped.get("verified")
    assert stamped["verified"]["sha256"] == content_hash(plan)
    edited = copy.deepcopy(stamped)
    edited["phases"][0]["steps"][1]["pose"][0] += 1e-6
    assert not has_valid_stamp(edited), "an edited plan keeps its stamp"
    assert main(["check", str(path)]) == 0, capsys.readouterr()


def test_a_wrong_plan_is_not_stamped(plan: Plan, tmp_path: Path) -> None:
    plan["p_path"] *= 0.5
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    assert main(["check", "--stamp", str(path)]) == 1
    assert "verified" not in json.loads(path.read_text())



# Wrong files: never a traceback

def _weird(plan: Plan, case: str) -> Any:
    k = _body(plan)
    reach = next(k for k, p in enumerate(plan["phases"]) if p["kind"] == "reach")
    if case == "motion not a record":
        plan["phases"][k]["motion"] = 5
    elif case == "motion lists short":
        plan["phases"][k]["motion"]["effort"] = [1.0]
    elif case == "unknown anchors":
        plan["phases"][k]["stance"] = ["x", "y", "z", "w"]
    elif case == "reach frees another boom":
        j = plan["phases"][reach]["free_boom"]
        plan["phases"][reach]["free_boom"] = (j + 1) % 4
    elif case == "body with a free tip":
        plan["phases"][k]["steps"][0]["free_tip"] = [0.0, 0.0]
    elif case == "body with a free boom":
        plan["phases"][k]["stance"][1] = None
    elif case == "bad robot":
        plan["robot"]["boom_length"] = [2.0, 1.0]
    elif case == "scenario robot not a mapping":
        plan["scenario"]["robot"] = [1, 2]
    elif case == "huge pose":
        plan["phases"][k]["steps"][1]["pose"] = [1e300, -1e300, 1e300]
    elif case == "no phases":
        plan["phases"] = []
    elif case == "nested":
        return "[" * 10_000 + "]" * 10_000
    elif case == "empty start":
        plan["start"] = {"pose": [0.0, 0.0, 0.0], "stance": ["a", "b", "c", "d"]}
    return plan


@pytest.mark.parametrize("case", [
    "motion not a record", "motion lists short", "unknown anchors", "reach frees another boom",
    "body with a free tip", "body with a free boom", "bad robot", "scenario robot not a mapping",
    "huge pose", "no phases", "nested", "empty start"])
def test_wrong_files_give_a_message_not_a_traceback(
        plan: Plan, tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]) -> None:
    content = _weird(plan, case)
    path = tmp_path / "plan.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    code = main(["check", str(path)])  # an exception here fails the test
    out, err = capsys.readouterr()
    assert code in (1, 2), f"{case}: exit {code}\n{out}{err}"
    assert "Traceback" not in out + err
    if code == 2:
        assert err.count("\n") == 1 and err.startswith(f"error: {path}"), err
    else:
        assert f"{path}: " in out and "problem" in out, out


def test_a_bad_scenario_in_a_plan_names_its_field_in_the_plan(
        plan: Plan, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plan["scenario"]["goal"]["tolerance"] = -1.0
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: scenario.goal.tolerance: ") and err.count("\n") == 1, err
