"""The time axis of a plan (probe 10): steps at least MIN_STEP_GAP apart (rule `time-order`),
phase joins within TIME_TOL merged by the smooth path, a phase of attach-ramp steps only, and
rule `speed` on every pair of successive steps; the planner's --dt range keeps its plans
within that rule."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from planning.check import verify_plan
from planning.config_ranges import FIELDS, Range
from planning.plan_model import MIN_TIME_STEP, plan_of, plan_scenario
from planning.verify_climb import (
    BODY_SPEED_MAX,
    DEFAULT_LIMITS,
    GRIPPER_SPEED_MAX,
    MIN_STEP_GAP,
    RULES,
    STEP_STRETCH,
    TURN_SPEED_MAX,
    climb_problems,
)
from systems.plan_check import plan_problems

GOLDEN = Path(__file__).parent / "data" / "golden"
Plan = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> Plan:
    return json.loads((GOLDEN / "demo-shaft-current.json").read_text())


@pytest.fixture
def plan(golden: Plan) -> Plan:
    return copy.deepcopy(golden)


def rules_at(plan: Plan) -> dict[str, set[tuple[int | None, int | None]]]:
    out: dict[str, set[tuple[int | None, int | None]]] = {}
    for p in verify_plan(plan):
        out.setdefault(p.rule, set()).add((p.phase, p.step))
    return out


def shift(plan: Plan, first: int, dt: float) -> None:
    for phase in plan["phases"][first:]:
        for step in phase["steps"]:
            step["t"] += dt


def as_continuation(plan: Plan) -> None:
    """`start` = the scenario's start: phases without `motion` may be spliced in."""
    plan["start"] = {"pose": list(plan["phases"][0]["steps"][0]["pose"]),
                     "stance": list(plan["scenario"]["start"]["stance"])}


@pytest.mark.parametrize("dt", [-9e-7, -1e-8, 9e-7])
def test_phases_joined_within_the_time_tolerance_verify(plan: Plan, dt: float) -> None:
    """Phase 2 starting 0.9 us before phase 1 ended raised Drake's "Times must be in increasing
    order" from the smooth path; `phase-join` allows 1e-6 s, and the path merges the join."""
    shift(plan, 2, dt)
    assert plan_problems(plan)[0] == []


@pytest.mark.parametrize("keep", [1, 2])
def test_a_body_phase_of_attach_ramp_steps_only(plan: Plan, keep: int) -> None:
    """The last phase cut to its first steps (all attach-ramp steps): an IndexError before."""
    plan["phases"][-1]["steps"] = plan["phases"][-1]["steps"][:keep]
    plan["phases"][-1].pop("motion")
    rules = rules_at(plan)
    assert (14, keep - 1) in rules["attach"], rules


@pytest.mark.parametrize("t", [5e-324, 1e-30, 1e-16, 1e-9, MIN_STEP_GAP / 2])
def test_steps_closer_than_the_least_gap(plan: Plan, t: float) -> None:
    """A spliced phase's step 1e-30 s after the one before: Drake's "Times must be at least
    2.2e-16 apart" before; the body moving 0.41 m in 1e-9 s verified."""
    as_continuation(plan)
    phase = plan["phases"][0]
    phase.pop("motion")
    last = max(n for n, s in enumerate(phase["steps"]) if "ramp" not in s)
    phase["steps"] = [phase["steps"][0], *phase["steps"][last:]]
    gap = t - phase["steps"][1]["t"]
    for step in phase["steps"][1:]:
        step["t"] += gap
    shift(plan, 1, gap)
    rules = rules_at(plan)
    assert (0, 1) in rules["time-order"], rules
    assert (0, 1) in rules["speed"], rules
    assert set(rules) <= {"time-order", "speed", "between"}, rules


def test_a_footstep_plan_step_in_no_time(golden: Plan) -> None:
    plan = json.loads((GOLDEN / "rig.json").read_text())
    plan["phases"][0]["steps"][1]["t"] = 1e-20
    rules = rules_at(plan)
    assert {(0, 1)} <= rules["time-order"] and {(0, 1)} <= rules["speed"], rules


def test_a_spliced_reach_run_in_a_millisecond(plan: Plan) -> None:
    """A continuation's spliced reach phase, first and last step 1 ms apart: the gripper
    moves 0.57 m in it (a microsecond before MIN_STEP_GAP, which verified)."""
    as_continuation(plan)
    phase = plan["phases"][5]
    phase.pop("motion")
    a, b = phase["steps"][0], phase["steps"][-1]
    gap = a["t"] + MIN_STEP_GAP - b["t"]
    b["t"] = a["t"] + MIN_STEP_GAP
    phase["steps"] = [a, b]
    shift(plan, 6, gap)
    problems = [p for p in verify_plan(plan) if p.rule == "speed"]
    assert [(p.phase, p.step) for p in problems] == [(5, 1)], problems
    assert "the free gripper moves 0.5707 m in 0.001 s" in str(problems[0])


def test_a_body_phase_run_at_ten_times_the_speed(plan: Plan) -> None:
    """Every time of phase 0 divided by 10 (5 cm in 0.05 s) and the rest shifted to join."""
    phase = plan["phases"][0]
    end = phase["steps"][-1]["t"]
    for step in phase["steps"]:
        step["t"] /= 10
    plan["time_step"] /= 10
    shift(plan, 1, end / 10 - end)
    plan["phases"][0]["steps"][-1]["t"] = end / 10
    assert any(p.rule == "speed" and p.phase == 0 for p in verify_plan(plan))


def test_the_planners_plans_keep_within_the_speed_rule(golden: Plan) -> None:
    """Its steps are at most `limits.step` and `turn_step` (twice the seeds' 0.05 m, 0.05 rad)
    every time_step, at least MIN_TIME_STEP: within the limits by construction; the bundled
    plans verify (no `speed` problem)."""
    assert "speed" in RULES
    dt = FIELDS["PipelineConfig"]["dt"]
    assert isinstance(dt, Range) and dt.lo == MIN_TIME_STEP
    assert DEFAULT_LIMITS["step"] == STEP_STRETCH * 0.05
    assert DEFAULT_LIMITS["step"] / MIN_TIME_STEP <= min(BODY_SPEED_MAX, GRIPPER_SPEED_MAX)
    assert DEFAULT_LIMITS["turn_step"] / MIN_TIME_STEP <= TURN_SPEED_MAX
    for name in ("demo-shaft-current", "demo-crevasse", "shaft-1", "rockfall-3", "rig"):
        model = plan_of(json.loads((GOLDEN / f"{name}.json").read_text()))
        assert not [p for p in climb_problems(model, plan_scenario(model, name))
                    if p.rule in ("speed", "time-order")], name


@pytest.mark.parametrize("args, field", [
    (["--dt", str(MIN_TIME_STEP / 2)], "--dt"),
    (["--dt", "0.01"], "--dt"),
])
def test_rbp_plan_refuses_a_dt_below_the_speed_rule(tmp_path: Path, args: list[str],
                                                    field: str) -> None:
    result = subprocess.run([sys.executable, "-m", "rbp", "plan", "demo-shaft", "-q",
                             "--no-pictures", "-o", str(tmp_path / "p.json"), *args],
                            capture_output=True, text=True, timeout=120,
                            env={"LCM_DEFAULT_URL": "memq://", "PATH": "/usr/bin:/bin"})
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {field}: "), result.stderr
    assert not (tmp_path / "p.json").exists()


def test_a_configuration_whose_seed_steps_outrun_the_rule(tmp_path: Path) -> None:
    """seed.step 0.3 m (stretched to 0.6 m by SCP) every 0.5 s would move at 1.2 m/s."""
    config = tmp_path / "c.yaml"
    step = math.ceil(BODY_SPEED_MAX * 0.5 / STEP_STRETCH * 1.2 * 100) / 100
    config.write_text(f"seed:\n  step: {step}\n")
    result = subprocess.run([sys.executable, "-m", "rbp", "plan", "demo-shaft", "-q",
                             "--no-pictures", "-o", str(tmp_path / "p.json"), "--config",
                             str(config)], capture_output=True, text=True, timeout=120,
                            env={"LCM_DEFAULT_URL": "memq://", "PATH": "/usr/bin:/bin"})
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "dt: " in lines[0] and "rule speed" in lines[0], result.stderr
