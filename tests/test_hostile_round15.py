"""Probe 15: plans that `rbp check` accepted while claiming something false or skipping a
release: a failed plan stating a success probability, a body phase carrying a reach's anchors
or a free boom's shoulder torque, and a climb from the scenario's start that opens a gripper
at t = 0 (a first reach phase, no release ramp); and `rbp check --scenario CAVE`, which holds
a plan to the cave and robot it was made for (the verifier alone trusts the ones it embeds)."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from planning.check import verify_plan
from planning.plan_file import validated
from planning.plan_model import Plan
from planning.probability import Configuration, path_probability

DATA = Path(__file__).parent / "data"
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> PlanFile:
    return json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())


def problems_of(plan: PlanFile) -> list[Any]:
    """The verifier's problems with a plan read as a file is (schema, times) first."""
    return verify_plan(validated(json.loads(json.dumps(plan))))


def rules(plan: PlanFile) -> set[str]:
    return {p.rule for p in problems_of(plan)}


def rescored(plan: PlanFile) -> PlanFile:
    """The plan's summary recomputed from its own steps (so that only the fault shows)."""
    model = Plan.from_dict(plan)
    configs = [(phase.stance, step.p_grasp, step.p_success)
               for phase in model.phases for step in phase.steps]
    score = path_probability([Configuration(*c) for c in configs],
                             model.robot["attach_failure"])
    plan["p_path"], plan["p_grasps"], plan["p_min"] = score.p_path, score.p_grasps, score.p_min
    plan["regrasps"] = sum(phase["kind"] == "reach" for phase in plan["phases"])
    return plan


def test_the_golden_plan_verifies(golden: PlanFile) -> None:
    assert problems_of(copy.deepcopy(golden)) == []


def test_a_failed_plan_states_no_probabilities(golden: PlanFile) -> None:
    """`success: false` without `partial` kept p_path 0.92, p_min and p_grasps: accepted, a
    failed plan claiming how likely its climb is (the planner writes null there)."""
    plan = copy.deepcopy(golden)
    plan["success"], plan["reason"] = False, "no route"
    problems = problems_of(plan)
    assert {p.rule for p in problems} == {"summary"}, "\n".join(map(str, problems))
    assert {p.text.split(":")[0] for p in problems} == {"p_path", "p_min", "p_grasps"}
    for name in ("p_path", "p_min", "p_grasps"):
        plan[name] = None
    assert problems_of(plan) == [], "a failed plan with null probabilities was refused"


def test_a_body_phase_holds_no_reach_anchors(golden: PlanFile) -> None:
    """A body phase with `from_anchor`/`to_anchor` (even anchors the cave lacks) passed."""
    plan = copy.deepcopy(golden)
    plan["phases"][2]["from_anchor"], plan["phases"][2]["to_anchor"] = "a1", "nowhere"
    problems = problems_of(plan)
    assert any(p.rule == "phase-form" and p.phase == 2 and "from_anchor" in p.text
               for p in problems), "\n".join(map(str, problems))


def test_a_body_step_has_no_free_booms_torque(golden: PlanFile) -> None:
    """A body step recording a shoulder torque of 999 N m (no boom is free) passed."""
    plan = copy.deepcopy(golden)
    plan["phases"][0]["steps"][2]["shoulder_torque"] = 999.0
    problems = problems_of(plan)
    assert any(p.rule == "phase-form" and p.phase == 0 and "shoulder_torque" in p.text
               for p in problems), "\n".join(map(str, problems))


def test_a_climb_from_the_start_does_not_open_a_gripper_at_once(golden: PlanFile) -> None:
    """The first body phase cut and the cave's start moved to the first reach's pose (times
    from 0, summary rescored): the climb began with boom 2 free at t = 0, its gripper opened
    under load with no release ramp and the start 4-stance never verified; it passed."""
    plan = copy.deepcopy(golden)
    phases = plan["phases"][1:]
    t0 = phases[0]["steps"][0]["t"]
    for phase in phases:
        for step in phase["steps"]:
            step["t"] = round(step["t"] - t0, 6)
    first = phases[0]
    held = list(first["stance"])
    held[first["free_boom"]] = first["from_anchor"]
    plan["phases"] = phases
    plan["scenario"]["start"] = {"pose": list(first["steps"][0]["pose"]), "stance": held}
    rescored(plan)
    problems = problems_of(plan)
    assert [(p.rule, p.phase, p.step) for p in problems] == [("release", 0, 0)], \
        "\n".join(map(str, problems))
    # a continuation (after a failed grasp) may start with the boom free
    plan["start"] = copy.deepcopy(plan["scenario"]["start"])
    for phase in plan["phases"][:1]:
        phase.pop("motion", None)
    assert problems_of(plan) == [], "a continuation starting mid-reach was refused"


def test_a_plan_is_held_to_the_cave_it_names(golden: PlanFile, tmp_path: Path) -> None:
    """The verifier checks a plan against the cave and robot it embeds: the robot's body
    shrunk (only rule collision reads body_size), its p_min lowered, an anchor's limit raised
    or the goal moved all pass `rbp check`, as an edit that makes a plan 'pass' would.
    `rbp check --scenario CAVE` holds the plan to CAVE's cave and robot (rule scenario)."""
    import rbp
    from planning.verify_climb import scenario_problems

    cave = rbp.load_scenario("demo-shaft")
    assert scenario_problems(Plan.from_dict(golden), cave) == []
    edits = {"robot.body_size": ("robot", "body_size", [0.2, 0.2]),
             "robot.p_min": ("robot", "p_min", 0.5)}
    for what, (block, name, value) in edits.items():
        plan = copy.deepcopy(golden)
        plan[block][name] = value
        assert problems_of(plan) == [], f"{what}: the verifier alone saw it"
        found = scenario_problems(Plan.from_dict(plan), cave)
        assert [p.rule for p in found] == ["scenario"] and name in found[0].text, found
    plan = copy.deepcopy(golden)
    plan["scenario"]["anchors"][3]["limit"]["normal"] *= 2
    plan["scenario"]["goal"]["tolerance"] = 5.0
    found = scenario_problems(Plan.from_dict(plan), cave)
    assert len(found) == 1 and "goal" in found[0].text and "anchors[a3]" in found[0].text, found
    # the command line: exit 1 with the rule named, and ok with the cave it names
    path = tmp_path / "edited.json"
    plan = copy.deepcopy(golden)
    plan["robot"]["body_size"] = [0.2, 0.2]
    path.write_text(json.dumps(plan))
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")
    done = subprocess.run([sys.executable, "-m", "rbp", "check", "-q", str(path), "--scenario",
                           "demo-shaft"], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 1 and "plan: scenario: the plan's robot differs" in done.stdout, \
        done.stdout[-400:] + done.stderr[-400:]
    path.write_text(json.dumps(golden))
    done = subprocess.run([sys.executable, "-m", "rbp", "check", "-q", str(path), "--scenario",
                           "demo-shaft"], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0 and "made for the cave and robot of demo-shaft" in done.stdout, \
        done.stdout[-400:] + done.stderr[-400:]


def test_a_plan_without_phases_makes_no_regrasps(golden: PlanFile) -> None:
    """A failed plan of no phases said `regrasps: 5` and passed (the count was checked only
    against the phases of a plan that has some)."""
    plan = copy.deepcopy(golden)
    plan.update(phases=[], success=False, reason="no route", p_path=None, p_min=None,
                p_grasps=None, regrasps=5)
    problems = problems_of(plan)
    assert [p.rule for p in problems] == ["summary"] and "regrasps" in problems[0].text, \
        "\n".join(map(str, problems))
    plan["regrasps"] = 0
    assert problems_of(plan) == []


@pytest.mark.parametrize("edit", [{"quality": "optimal"}, {"bound": 1.0},
                                  {"lower_bound": 0.2}], ids=str)
def test_the_search_record_agrees_with_itself(golden: PlanFile, edit: dict[str, Any]) -> None:
    """`rbp check` prints the search record's claims on its ok line ("route optimal", "within
    2.03x of the optimum"): a plan edited to say optimal (cost twice its lower bound), or a
    bound that is not cost / lower_bound, passed. The lower bound itself (the search's proof)
    is not in the plan, so not verified."""
    plan = copy.deepcopy(golden)
    plan["search"].update(edit)
    problems = problems_of(plan)
    assert problems and {p.rule for p in problems} == {"summary"}, \
        "\n".join(map(str, problems))
    assert all(p.text.startswith("search.") for p in problems), problems


def test_the_executors_hold_a_plan_to_its_cave(tmp_path: Path, capsys) -> None:
    """rig-run clamps its commands to the embedded robot's boom_length and boom_tension: a
    rig plan with both copies of its robot widened (to 4 m and 5000 N) verified and flew.
    `--scenario CAVE` of simulate and rig-run refuses it, before any simulation or LCM
    traffic (exit 1, rule scenario named)."""
    from rbp.cli import main

    plan = json.loads((DATA / "golden" / "rig.json").read_text())
    for robot in (plan["robot"], plan["scenario"]["robot"]):
        robot["boom_length"], robot["boom_tension"] = [0.01, 4.0], [0.5, 5000.0]
    assert problems_of(plan) == [], "the verifier alone saw the widened robot"
    path = tmp_path / "wide.json"
    path.write_text(json.dumps(plan))
    for command in (["rig-run", str(path), "--sim-rig", "--log", str(tmp_path / "r.lcm")],
                    ["simulate", str(path), "--trials", "0"]):
        capsys.readouterr()
        assert main([*command, "--scenario", "rig"]) == 1, command
        err = capsys.readouterr().err
        assert "plan: scenario: the plan's robot differs from rig" in err, err[-400:]
        assert "['boom_length', 'boom_tension']" in err and "refused" in err, err[-400:]
    assert not (tmp_path / "r.lcm").exists(), "rig-run logged a refused plan"
