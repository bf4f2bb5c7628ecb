"""The typed plan model (planning.plan_model): the schema generated from it, the golden plans.

`tests/data/golden/` holds plans of the bundled caves made before the model existed (format
`reachbot-plan/1`, the robot stored twice): `rbp plan CAVE -o CAVE.json` for demo-shaft,
demo-crevasse, shaft-1 and rockfall-3, and `systems.rig.rig_plan` on the rig's scenario
(rig.json; `rbp plan rig` failed on that commit). Each must read through the model and write
back to the same content. `demo-shaft-current.json` is what `rbp plan demo-shaft` makes today,
in today's format (the robot stored once): planning demo-shaft again must give it again. It is
made anew only when the planner's plans change on purpose (session 18: the planner tests the
smooth path `rbp simulate` follows between steps, issue 28), with
`rbp plan demo-shaft -o tests/data/golden/demo-shaft-current.json --no-pictures`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT

from planning.plan import write_plan
from planning.plan_file import PlanFileError, content_hash, has_valid_stamp, read_plan, stamp
from planning.plan_model import FORMAT, Plan, Step, plan_scenario
from planning.plan_schema_gen import SCHEMA_FILE, schema_text

GOLDEN = ROOT / "tests" / "data" / "golden"
CAVES = ("demo-shaft", "demo-crevasse", "shaft-1", "rockfall-3", "rig")
# Fields that depend on when, where and how fast a plan was made, not on what was planned.
VOLATILE = ("timing", "provenance")
SOLVER_REL = SOLVER_ABS = 1e-6  # a planned plan's numbers, across machines


def assert_close(a: Any, b: Any, where: str = "plan", rel: float = 1e-9,
                 abs_tol: float = 1e-9) -> None:
    """`a` equals `b` but for floating-point noise in their numbers."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert set(a) == set(b), f"{where}: keys {sorted(set(a) ^ set(b))} differ"
        for k in a:
            assert_close(a[k], b[k], f"{where}.{k}", rel, abs_tol)
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), f"{where}: {len(a)} items, not {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_close(x, y, f"{where}[{i}]", rel, abs_tol)
    elif isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        assert math.isclose(a, b, rel_tol=rel, abs_tol=abs_tol), f"{where}: {a} != {b}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def test_the_committed_schema_is_the_generated_one() -> None:
    """plan_schema.json is generated from the model: run `python -m planning.plan_schema_gen`
    after changing planning/plan_model.py."""
    assert SCHEMA_FILE.read_text() == schema_text(), (
        "planning/plan_schema.json is stale: run python -m planning.plan_schema_gen")


def test_the_schema_is_closed() -> None:
    """Every object the model describes refuses unknown fields; the motion block is in it."""
    schema = json.loads(SCHEMA_FILE.read_text())
    assert schema["additionalProperties"] is False
    for name in ("phase", "step", "ramp", "motion", "searchrecord", "searchpoint", "limits",
                 "start", "provenance", "verified", "robot", "scenario"):
        assert schema["$defs"][name]["additionalProperties"] is False, name
    assert schema["$defs"]["phase"]["properties"]["motion"] == {"$ref": "#/$defs/motion"}


@pytest.mark.parametrize("cave", CAVES)
def test_golden_plan_reads_and_writes_back_unchanged(cave: str, tmp_path: Path) -> None:
    """An old plan file (format 1) reads into the model and writes back to the same content,
    so that its stamp (the hash of its content) still holds."""
    source = GOLDEN / f"{cave}.json"
    original = json.loads(source.read_text())
    assert original["format"] == "reachbot-plan/1"
    plan = read_plan(source)
    assert isinstance(plan, Plan) and plan.scenario_robot == plan.robot
    assert all(isinstance(s, Step) for p in plan.phases for s in p.steps)
    out = write_plan(plan, tmp_path / "again.json")
    again = json.loads(out.read_text())
    assert again == original, f"{cave}: the plan changed on its way through the model"
    assert content_hash(again) == content_hash(original)
    assert has_valid_stamp(stamp(original)) and read_plan(out) == plan


@pytest.mark.parametrize("cave", CAVES)
def test_golden_plan_in_todays_format_stores_the_robot_once(cave: str, tmp_path: Path) -> None:
    """Upgraded, the plan has one robot, the same scenario, and reads back to the same model."""
    old = read_plan(GOLDEN / f"{cave}.json")
    new = old.upgraded()
    data = new.to_dict()
    assert data["format"] == FORMAT and "robot" not in data["scenario"]
    path = write_plan(new, tmp_path / "new.json")
    assert read_plan(path) == new
    assert plan_scenario(new).to_dict(resolved=True) == plan_scenario(old).to_dict(resolved=True)


@pytest.mark.parametrize("cave", CAVES)
def test_golden_plan_verifies_in_either_format(cave: str) -> None:
    """rbp check's verifier, which reads the typed model, finds the same in the golden plans
    as they are (format 1, two robots) and upgraded (format 2, one robot): every rule holds
    but, in plans made before the planner tested the smooth path between steps, rule
    `between` on that path (their SCP steps ride a shoulder limit the path crosses)."""
    from planning.check import verify_plan

    plan = read_plan(GOLDEN / f"{cave}.json")
    problems = [str(p) for p in verify_plan(plan)]
    assert problems == [str(p) for p in verify_plan(plan.upgraded().to_dict())]
    other = [p for p in problems if ": between: " not in p or "smooth path" not in p]
    assert other == [], other


def test_an_unknown_field_is_refused(tmp_path: Path) -> None:
    data = json.loads((GOLDEN / "rig.json").read_text())
    data["phases"][0]["steps"][0]["speed"] = 1.0
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(data))
    with pytest.raises(PlanFileError) as e:
        read_plan(path)
    assert e.value.field == "phases[0].steps[0]" and "speed" in e.value.reason, str(e.value)


def _comparable(plan: Plan) -> dict[str, Any]:
    """The plan's content without what depends on the machine and the clock."""
    data = plan.upgraded().to_dict()
    for key in VOLATILE:
        data.pop(key, None)
    for point in (data.get("search") or {}).get("history", []):
        point.pop("seconds")
    for key in ("peak_memory_mb", "kept_memory_mb"):
        (data.get("search") or {}).pop(key, None)
    return data


# settings that change no plan: the memo's cap (what it drops is rebuilt with the same answer)
# and the search's ordering at its default (the distance estimate, as always); refinement
# searches again only where the lattice has no route (the golden caves have one)
RESULT_NEUTRAL = {"footstep.search_memory_mb", "footstep.ordering", "footstep.refine"}


def test_planning_demo_shaft_again_gives_its_golden_plan(tmp_path: Path) -> None:
    """`rbp plan demo-shaft` today makes its golden plan again (to floating-point noise), in
    today's format; slow (a whole plan)."""
    from rbp import cli

    out = tmp_path / "demo-shaft.json"
    assert cli.main(["plan", "demo-shaft", "-o", str(out), "--no-pictures", "--quiet"]) == 0
    new, golden = read_plan(out), read_plan(GOLDEN / "demo-shaft-current.json")
    assert new.format == FORMAT and new.scenario_robot is None
    added = _added_settings(new.provenance.config, golden.provenance.config)
    # footstep.search_memory_mb caps the search's memo; what it drops is rebuilt with the same
    # answer (issue 31), so it is on by default and changes no plan
    assert all(value is None or key in RESULT_NEUTRAL for key, value in added.items()), \
        f"settings added since the golden plan must default to off (None): {added}"
    assert new.provenance.threads >= 1 and new.provenance.cores >= 1, new.provenance
    assert new.provenance.load is None or new.provenance.load >= 0, new.provenance
    machine = {"threads": None, "cores": None, "load": None}  # what it ran under
    # result-neutral settings may also change their defaults (the memo's cap did, session 21)
    neutral = dict.fromkeys(RESULT_NEUTRAL)
    assert dataclasses.replace(new.provenance, command="", scenario_source="", **machine,
                               config=_without(new.provenance.config, added | neutral)) == \
        dataclasses.replace(golden.provenance, command="", scenario_source="", **machine,
                            config=_without(golden.provenance.config, neutral))
    # The numbers come out of Clarabel's and OSQP's solves (tolerances about 1e-8), whose last
    # digits differ between CPUs' floating-point paths (a tension 0.50072803542 here, 0.50072803082
    # on another machine): equal to 1e-6, far below anything a change of the planner moves.
    assert_close(_comparable(new), _comparable(golden), rel=SOLVER_REL, abs_tol=SOLVER_ABS)


def _added_settings(config: dict, golden: dict, prefix: str = "") -> dict[str, object]:
    """The settings of `config` that `golden` (an older plan's) lacks: dotted path -> value."""
    added: dict[str, object] = {}
    for key, value in config.items():
        if key not in golden:
            added[prefix + key] = value
        elif isinstance(value, dict) and isinstance(golden[key], dict):
            added.update(_added_settings(value, golden[key], f"{prefix}{key}."))
    return added


def _without(config: dict, paths: dict[str, object]) -> dict:
    out = {}
    for key, value in config.items():
        inner = {p.split(".", 1)[1]: v for p, v in paths.items() if p.startswith(key + ".")}
        if key in paths:
            continue
        out[key] = _without(value, inner) if isinstance(value, dict) and inner else value
    return out


def test_the_rig_plan_again_gives_its_golden_plan() -> None:
    """systems.rig.rig_plan (the rig's straight-line body plan, built by plan_header and
    allocation_step) makes the golden rig plan again, in today's format."""
    from systems.rig import load_rig_scenario, rig_plan

    new = Plan.from_dict(rig_plan(load_rig_scenario()))
    golden = read_plan(GOLDEN / "rig.json")
    assert new.format == FORMAT and new.scenario_robot is None
    assert_close(_comparable(new), _comparable(golden))


def test_an_absent_p_grasps_stays_absent_and_null_is_not_absent() -> None:
    """Plans from before p_grasps leave it out: such a plan writes back without it and
    verifies; a successful plan whose p_grasps is null breaks rule `summary`, as before."""
    from planning.check import verify_plan

    data = json.loads((GOLDEN / "rig.json").read_text())
    older = {k: v for k, v in data.items() if k != "p_grasps"}
    assert Plan.from_dict(older).to_dict() == older
    assert verify_plan(older) == []
    problems = verify_plan(data | {"p_grasps": None})
    assert [p.rule for p in problems] == ["summary"] and "p_grasps" in problems[0].text


def test_the_scenario_and_robot_sub_schemas_name_what_their_readers_accept() -> None:
    """The plan schema's scenario and robot parts are written in planning.plan_schema_gen, not
    generated from a dataclass (the scenario reader is hand-written too): they must name
    exactly the fields the readers know, so that a field added to one is added to the other."""
    from rb_drake.params import RobotParams
    from rb_drake.scenario import TOP_LEVEL, bundled_caves, load_scenario

    defs = json.loads(SCHEMA_FILE.read_text())["$defs"]
    robot = defs["robot"]
    assert set(robot["properties"]) == set(RobotParams().to_dict()), (
        f"robot schema {sorted(robot['properties'])} vs RobotParams "
        f"{sorted(RobotParams().to_dict())}")
    assert robot["additionalProperties"] is False
    scenario = defs["scenario"]
    assert set(scenario["properties"]) == TOP_LEVEL, (
        f"scenario schema {sorted(scenario['properties'])} vs the reader's {sorted(TOP_LEVEL)}")
    assert scenario["additionalProperties"] is False
    anchor = scenario["properties"]["anchors"]["items"]
    written = load_scenario(bundled_caves()["demo-shaft"]).to_dict()["anchors"][0]
    assert set(anchor["properties"]) == set(written), (
        f"anchor schema {sorted(anchor['properties'])} vs a written anchor {sorted(written)}")
    assert anchor["additionalProperties"] is False
