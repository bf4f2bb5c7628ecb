"""Plan files (`planning.plan`), their independent verification (`planning.check`) and the
`rbp plan` / `rbp check` commands, on a short generated shaft with the goal 0.6 m above the start
(a whole cave takes tens of seconds to plan; this one a few seconds, with two regrasps).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
import os
import subprocess
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from cli_helpers import run_rbp

from planning.check import check_plan
from planning.footsteps import FootstepConfig, FootstepPlan, plan_footsteps
from planning.plan import FORMAT, build_plan, plan_configurations, schema, validate, write_plan
from planning.plan_model import Plan, plan_dict, plan_of
from planning.probability import path_probability
from rb_drake.feasibility import check_poses
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario, scenario_from_dict, scenario_to_yaml

# generate_cave("shaft", SEED, short) with the goal moved 0.9 m above the start: the complete
# search succeeds with 2 regrasps in under a second (0.6 m up, the body reaches the goal
# without one).
SEED = 4
SHORT = CaveConfig(length=(3.0, 3.2))
EXPANSIONS = 40
TOL = 1e-9


def small_shaft(seed: int = SEED, rise: float = 0.9) -> Scenario:
    scn = generate_cave("shaft", seed, SHORT)
    x, y, _ = scn.start_pose
    return dataclasses.replace(scn, goal_position=(x, y + rise), goal_tolerance=0.4)


@pytest.fixture(scope="module")
def scn() -> Scenario:
    return small_shaft()


@pytest.fixture(scope="module")
def fp(scn: Scenario) -> FootstepPlan:
    fp = plan_footsteps(scn, FootstepConfig(max_expansions=EXPANSIONS))
    assert fp.success, (f"RBP found no plan on shaft seed {SEED} with the goal 0.9 m up "
                        f"(max_expansions {EXPANSIONS}): {fp.reason}")
    assert len(fp.steps) >= 1, "the fixture scenario must need at least one regrasp"
    return fp


@pytest.fixture(scope="module")
def plan(scn: Scenario, fp: FootstepPlan) -> dict[str, Any]:
    """The plan as its file holds it (the tests below tamper with it)."""
    built = build_plan(scn, fp, "rbp")
    assert isinstance(built, Plan)
    return plan_dict(built)


@pytest.fixture
def fresh(plan: dict[str, Any]) -> dict[str, Any]:
    """A copy of the plan to tamper with."""
    return copy.deepcopy(plan)


def reach_indices(plan: dict[str, Any]) -> list[int]:
    return [k for k, ph in enumerate(plan["phases"]) if ph["kind"] == "reach"]


def all_steps(plan: dict[str, Any]):
    for k, phase in enumerate(plan["phases"]):
        for n, step in enumerate(phase["steps"]):
            yield k, n, phase, step


def hand_path_probability(plan: dict[str, Any], attach_failure: float) -> tuple[float, int]:
    """p_path per boom: each maximal run on one anchor contributes its minimum P; every reach
    phase costs one attach factor. Written independently of planning.probability."""
    configs = [(phase["stance"], step["p_grasp"]) for _, _, phase, step in all_steps(plan)]
    factors = []
    for i in range(4):
        anchor, worst = None, 1.0
        for stance, p in configs:
            if stance[i] != anchor:
                if anchor is not None:
                    factors.append(worst)
                anchor, worst = stance[i], 1.0
            if anchor is not None:
                worst = min(worst, p[i])
        if anchor is not None:
            factors.append(worst)
    regrasps = len(reach_indices(plan))
    return math.prod(factors) * (1.0 - attach_failure) ** regrasps, regrasps


# ---------------------------------------------------------------------------------------------
# The plan built from the footstep plan


def test_plan_succeeds_with_regrasps(plan: dict[str, Any], fp: FootstepPlan) -> None:
    assert plan["format"] == FORMAT
    assert plan["planner"] == "rbp"
    assert plan["success"] is True and plan["reason"] == "", plan["reason"]
    assert plan["regrasps"] == len(fp.steps) >= 1, (
        f"plan regrasps {plan['regrasps']}, footstep steps {len(fp.steps)}")


def test_plan_validates_against_schema(plan: dict[str, Any]) -> None:
    errors = [e.message for e in jsonschema.Draft202012Validator(schema()).iter_errors(plan)]
    assert errors == [], f"the plan breaks its schema: {errors}"
    validate(plan)
    text = json.dumps(plan, allow_nan=False)  # raises on NaN or infinity anywhere
    assert json.loads(text) == plan, "the plan does not survive a JSON round trip"


def test_check_plan_accepts_the_plan(plan: dict[str, Any]) -> None:
    problems = check_plan(plan)
    assert problems == [], "check_plan rejects the planner's own plan:\n" + "\n".join(problems)


def test_plan_scenario_is_the_planned_one(plan: dict[str, Any], scn: Scenario) -> None:
    data = dict(plan["scenario"])
    data["robot"] = plan["robot"]
    again = scenario_from_dict(data, "<plan>", check_start=False)
    assert again.robot == scn.robot
    assert [a.id for a in again.anchors] == [a.id for a in scn.anchors]
    np.testing.assert_allclose(again.anchor_positions, scn.anchor_positions, atol=1e-12)
    assert again.start_stance == scn.start_stance
    np.testing.assert_allclose(again.goal_position, scn.goal_position, atol=1e-12)


def test_every_configuration_feasible_by_check_poses(plan: dict[str, Any],
                                                     scn: Scenario) -> None:
    """Re-verified with the feasibility module directly, not through check_plan."""
    p_min = scn.robot.p_min
    lo, hi = scn.robot.boom_tension
    for k, n, phase, step in all_steps(plan):
        at = f"phases[{k}] ({phase['kind']}) step {n}"
        if "ramp" in step:  # a release or attach ramp blends two configurations (test_ramps)
            continue
        stance = scn.stance(tuple(phase["stance"]))
        pose = np.array(step["pose"])
        tip = np.array(step["free_tip"]) if "free_tip" in step else None
        assert (tip is not None) == (phase["kind"] == "reach"), f"{at}: free_tip iff reach"
        check = check_poses(scn, stance, pose, tip)
        assert check.feasible[0], f"{at}: infeasible, reason {int(check.reason[0])}"
        p = float(check.probability[0])
        assert p >= p_min - TOL, f"{at}: P = {p} below p_min {p_min}"
        assert step["p_success"] >= p_min - TOL, f"{at}: plan's P {step['p_success']} < p_min"
        assert math.isclose(step["p_success"], p, rel_tol=1e-9, abs_tol=1e-12), (
            f"{at}: plan says P = {step['p_success']}, check_poses {p}")
        for i, f in enumerate(step["tension"]):
            if stance.attached[i]:
                assert f is not None and lo - TOL <= f <= hi + TOL, (
                    f"{at}: boom {i} tension {f} outside [{lo}, {hi}]")
                assert step["p_grasp"][i] is not None and 0 <= step["p_grasp"][i] <= 1
            else:
                assert f is None and step["p_grasp"][i] is None, (
                    f"{at}: free boom {i} has tension {f} / P {step['p_grasp'][i]}")


def test_phases_alternate_body_and_reach(plan: dict[str, Any], scn: Scenario) -> None:
    kinds = [ph["kind"] for ph in plan["phases"]]
    expected = ["body", "reach"] * plan["regrasps"] + ["body"]
    assert kinds == expected, f"phase kinds {kinds}"
    for k, phase in enumerate(plan["phases"]):
        if phase["kind"] == "body":
            assert phase["free_boom"] is None and None not in phase["stance"], (
                f"phases[{k}]: a body phase is a 4-stance: {phase['stance']}")
        else:
            j = phase["free_boom"]
            assert [i for i, a in enumerate(phase["stance"]) if a is None] == [j], (
                f"phases[{k}]: a reach phase frees exactly boom {j}: {phase['stance']}")
    first = plan["phases"][0]
    assert tuple(first["stance"]) == scn.start_stance
    np.testing.assert_allclose(first["steps"][0]["pose"], scn.start_pose, atol=1e-12)
    end = plan["phases"][-1]["steps"][-1]["pose"]
    dist = float(np.hypot(end[0] - scn.goal_position[0], end[1] - scn.goal_position[1]))
    assert dist <= scn.goal_tolerance + TOL, f"final pose {dist:.3f} m from the goal"


def test_time_and_pose_are_continuous(plan: dict[str, Any]) -> None:
    steps = [step for _, _, _, step in all_steps(plan)]
    times = [s["t"] for s in steps]
    assert times[0] == 0.0
    assert all(b >= a for a, b in itertools.pairwise(times)), f"times {times}"
    for k in range(len(plan["phases"]) - 1):
        a, b = plan["phases"][k]["steps"][-1], plan["phases"][k + 1]["steps"][0]
        assert a["t"] == b["t"], f"phases[{k}] ends at t={a['t']}, the next starts at {b['t']}"
        np.testing.assert_allclose(a["pose"], b["pose"], atol=1e-12,
                                   err_msg=f"pose jumps between phases[{k}] and [{k + 1}]")


def test_reach_phases_consistent_with_neighbours(plan: dict[str, Any], scn: Scenario,
                                                 fp: FootstepPlan) -> None:
    phases = plan["phases"]
    moves = []
    for k in reach_indices(plan):
        before, reach, after = phases[k - 1], phases[k], phases[k + 1]
        j, old, new = reach["free_boom"], reach["from_anchor"], reach["to_anchor"]
        assert before["stance"][j] == old, (
            f"phases[{k}] leaves {old} but the body phase before holds {before['stance'][j]}")
        assert after["stance"][j] == new, (
            f"phases[{k}] reaches {new} but the body phase after holds {after['stance'][j]}")
        assert old != new
        assert reach["stance"] == [None if i == j else a for i, a in enumerate(before["stance"])]
        assert after["stance"] == [new if i == j else a for i, a in enumerate(reach["stance"])]
        np.testing.assert_allclose(reach["steps"][0]["free_tip"],
                                   scn.anchors[scn.anchor_index[old]].position, atol=1e-12,
                                   err_msg=f"phases[{k}]: the gripper starts off {old}")
        np.testing.assert_allclose(reach["steps"][-1]["free_tip"],
                                   scn.anchors[scn.anchor_index[new]].position, atol=1e-12,
                                   err_msg=f"phases[{k}]: the gripper ends off {new}")
        poses = np.array([s["pose"] for s in reach["steps"]])
        np.testing.assert_allclose(poses, poses[:1].repeat(len(poses), 0), atol=0,
                                   err_msg=f"phases[{k}]: the body moves during a reach")
        moves.append((j, old, new))
    assert moves == [(s.boom, s.from_anchor, s.to_anchor) for s in fp.steps]


def test_p_path_matches_hand_recomputation(plan: dict[str, Any], scn: Scenario) -> None:
    af = scn.robot.attach_failure
    hand, regrasps = hand_path_probability(plan, af)
    assert plan["regrasps"] == regrasps
    assert plan["p_path"] == pytest.approx(hand, rel=1e-12, abs=1e-15), (
        f"plan p_path {plan['p_path']}, hand recomputation {hand}")
    library = path_probability(plan_configurations(plan_of(plan)), af)
    assert library.p_path == pytest.approx(hand, rel=1e-12, abs=1e-15)
    assert library.regrasps == regrasps
    p_min = min(step["p_success"] for _, _, _, step in all_steps(plan))
    assert plan["p_min"] == pytest.approx(p_min, rel=1e-12), (
        f"plan p_min {plan['p_min']}, smallest step P {p_min}")
    assert 0 < plan["p_path"] <= plan["p_min"] <= 1


# ---------------------------------------------------------------------------------------------
# check_plan catches tampering


def _first_attached(step: dict[str, Any]) -> int:
    return next(i for i, f in enumerate(step["tension"]) if f is not None)


def test_check_catches_a_changed_tension(fresh: dict[str, Any]) -> None:
    step = fresh["phases"][0]["steps"][0]
    step["tension"][_first_attached(step)] += 1.0
    problems = check_plan(fresh)
    assert any(p.startswith("phases[0] (body) step 0") and "statics residual" in p
               for p in problems), f"+1 N tension not caught: {problems}"


def test_check_catches_a_wrong_p_path(fresh: dict[str, Any]) -> None:
    fresh["p_path"] = 0.99
    problems = check_plan(fresh)
    assert any(p.startswith("plan: summary: p_path") and "0.99" in p for p in problems), (
        f"p_path 0.99 not caught: {problems}")


def test_check_catches_a_wrong_p_grasps(fresh: dict[str, Any]) -> None:
    assert fresh["p_grasps"] > fresh["p_path"], "the plan's regrasps must lower p_path"
    fresh["p_grasps"] = fresh["p_path"]
    problems = check_plan(fresh)
    assert any(p.startswith("plan: summary: p_grasps") for p in problems), (
        f"p_grasps set to p_path not caught: {problems}")


def test_check_catches_a_pose_moved_3_m(fresh: dict[str, Any]) -> None:
    fresh["phases"][0]["steps"][1]["pose"][0] += 3.0
    problems = check_plan(fresh)
    assert any(p.startswith("phases[0] (body) step 1") and "length" in p for p in problems), (
        f"a pose moved 3 m is not reported as a boom length violation: {problems}")


def test_check_catches_a_changed_from_anchor(fresh: dict[str, Any], scn: Scenario) -> None:
    k = reach_indices(fresh)[0]
    reach = fresh["phases"][k]
    other = next(a.id for a in scn.anchors
                 if a.id not in (reach["from_anchor"], reach["to_anchor"]))
    reach["from_anchor"] = other
    problems = check_plan(fresh)
    assert any(p.startswith(f"phases[{k}] (reach)") and f"leaves {other}" in p
               for p in problems), f"a wrong from_anchor is not caught: {problems}"


@pytest.mark.parametrize("replacement", ["other", "no-such-anchor"])
def test_check_catches_a_changed_to_anchor(fresh: dict[str, Any], scn: Scenario,
                                           replacement: str) -> None:
    k = reach_indices(fresh)[0]
    reach = fresh["phases"][k]
    if replacement == "other":
        replacement = next(a.id for a in scn.anchors
                           if a.id not in (reach["from_anchor"], reach["to_anchor"]))
    reach["to_anchor"] = replacement
    problems = check_plan(fresh)
    assert any(p.startswith((f"phases[{k}]", f"phases[{k + 1}]")) for p in problems), (
        f"to_anchor {replacement!r} (the next body phase holds "
        f"{fresh['phases'][k + 1]['stance'][reach['free_boom']]}) accepted: {problems}")


def test_schema_requires_p_grasp(fresh: dict[str, Any]) -> None:
    for _, _, _, step in all_steps(fresh):
        del step["p_grasp"]
    with pytest.raises(jsonschema.ValidationError, match="p_grasp"):
        validate(fresh)


# ---------------------------------------------------------------------------------------------
# Schema and writing


def test_schema_rejects_missing_phases(fresh: dict[str, Any]) -> None:
    del fresh["phases"]
    with pytest.raises(jsonschema.ValidationError, match="phases"):
        validate(fresh)


def test_schema_rejects_unknown_planner(fresh: dict[str, Any]) -> None:
    fresh["planner"] = "foo"
    with pytest.raises(jsonschema.ValidationError, match="foo"):
        validate(fresh)


def test_write_plan_round_trips(plan: dict[str, Any], tmp_path: Path) -> None:
    out = write_plan(plan, tmp_path / "sub" / "plan.json")
    assert out == tmp_path / "sub" / "plan.json" and out.is_file()
    loaded = json.loads(out.read_text())
    assert loaded == json.loads(json.dumps(plan)), "the file differs from the plan"
    assert loaded["p_path"] == plan["p_path"], "floats must round-trip exactly"
    assert check_plan(loaded) == []
    assert [p.name for p in out.parent.iterdir()] == ["plan.json"], "temporary files left"


def test_write_plan_is_atomic(plan: dict[str, Any], tmp_path: Path,
                              monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "plan.json"
    out.write_text("old\n")
    bad = copy.deepcopy(plan)
    bad["planner"] = "foo"
    with pytest.raises(jsonschema.ValidationError):
        write_plan(bad, out)
    assert out.read_text() == "old\n", "an invalid plan must not be written"

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_plan(plan, out)
    monkeypatch.undo()
    assert out.read_text() == "old\n", "a failed write must leave the old file whole"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"], "temporary files left"
    write_plan(plan, out)
    assert json.loads(out.read_text())["phases"] == json.loads(json.dumps(plan["phases"]))


# ---------------------------------------------------------------------------------------------
# A cave with no route


@pytest.fixture(scope="module")
def unreachable() -> Scenario:
    return small_shaft(rise=50.0)


def test_no_route_gives_failure_with_reason(unreachable: Scenario, tmp_path: Path) -> None:
    fp = plan_footsteps(unreachable, FootstepConfig(max_expansions=5))
    assert not fp.success, "a goal 50 m away cannot be reached in 5 expansions"
    assert fp.reason, "a failed plan must say why"
    plan = plan_dict(build_plan(unreachable, fp, "rbp"))
    assert plan["success"] is False and plan["reason"] == fp.reason
    assert plan["p_path"] is None and plan["p_min"] is None
    validate(plan)
    assert check_plan(plan) == []
    out = write_plan(plan, tmp_path / "fail.json")
    assert json.loads(out.read_text())["success"] is False


# ---------------------------------------------------------------------------------------------
# The command line




def describe(proc: subprocess.CompletedProcess[str]) -> str:
    return f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"


@pytest.fixture(scope="module")
def cli_plan(tmp_path_factory: pytest.TempPathFactory, scn: Scenario):
    folder = tmp_path_factory.mktemp("cli_plan")
    (folder / "SCN.yaml").write_text(scenario_to_yaml(scn))
    proc = run_rbp("plan", "SCN.yaml", "-o", "plan.json", "--max-expansions", str(EXPANSIONS),
                   cwd=folder)
    return folder, proc


def test_cli_plan_writes_plan_and_picture(cli_plan) -> None:
    folder, proc = cli_plan
    assert proc.returncode == 0, describe(proc)
    assert "Traceback" not in proc.stderr, proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    assert last.startswith("success: true"), describe(proc)
    plan = json.loads((folder / "plan.json").read_text())
    validate(plan)
    assert plan["success"] is True and plan["planner"] == "rbp" and plan["regrasps"] >= 1
    assert check_plan(plan) == []
    png = folder / "plan.png"
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"{png} not a PNG"
    assert png.stat().st_size > 1000, f"{png} is tiny"
    assert not [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_cli_check_accepts_the_plan(cli_plan) -> None:
    folder, _ = cli_plan
    proc = run_rbp("check", "plan.json", cwd=folder)
    assert proc.returncode == 0, describe(proc)
    assert "ok" in proc.stdout, describe(proc)


def test_cli_check_rejects_a_tampered_plan(cli_plan) -> None:
    folder, _ = cli_plan
    plan = json.loads((folder / "plan.json").read_text())
    step = plan["phases"][0]["steps"][0]
    step["tension"][_first_attached(step)] += 1.0
    (folder / "tampered.json").write_text(json.dumps(plan))
    proc = run_rbp("check", "tampered.json", cwd=folder)
    assert proc.returncode == 1, describe(proc)
    assert "statics residual" in proc.stdout and "phases[0]" in proc.stdout, describe(proc)
    assert "Traceback" not in proc.stderr, proc.stderr


def test_cli_check_non_json_is_a_usage_error(tmp_path: Path) -> None:
    (tmp_path / "bad.json").write_text("{ this is not json\n")
    proc = run_rbp("check", "bad.json", cwd=tmp_path)
    assert proc.returncode == 2, describe(proc)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), describe(proc)
    assert "bad.json" in lines[0]
    assert "Traceback" not in proc.stderr


def test_cli_plan_without_route_writes_failed_plan(tmp_path: Path,
                                                   unreachable: Scenario) -> None:
    (tmp_path / "FAR.yaml").write_text(scenario_to_yaml(unreachable))
    proc = run_rbp("plan", "FAR.yaml", "-o", "far.json", "--max-expansions", "5", cwd=tmp_path)
    assert proc.returncode == 1, describe(proc)  # no route: status 1, the plan still written
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stdout.strip().splitlines()[-1].startswith("success: false"), describe(proc)
    plan = json.loads((tmp_path / "far.json").read_text())
    validate(plan)
    assert plan["success"] is False and plan["reason"], plan["reason"]
    assert (tmp_path / "far.png").is_file()


def _paths(node: Any, path: tuple = ()):
    """Every (container path, key) in a plan, for mutation."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for key, value in items:
        yield path, key
        if isinstance(value, dict | list):
            yield from _paths(value, (*path, key))


def _mutants(plan: dict[str, Any], count: int, seed: int = 0):
    """Plans with one change each: a value deleted, retyped, pushed out of range, a key added."""
    rng = np.random.default_rng(seed)
    paths = list(_paths(plan))
    replacements = [None, "x", -1, -1.5, 1.5, 2, 7.0, True, [], {}, [0.5] * 3, [0.5] * 4,
                    "rbp", "reach", "body", "naive"]
    for n in range(count):
        mutant = copy.deepcopy(plan)
        path, key = paths[rng.integers(len(paths))]
        parent = mutant
        for k in path:
            parent = parent[k]
        if n % 5 == 0 and isinstance(parent, dict):
            del parent[key]
        elif n % 5 == 1 and isinstance(parent, dict):
            parent["unknown_key"] = 1.0
        else:
            parent[key] = copy.deepcopy(replacements[rng.integers(len(replacements))])
        yield f"{path}[{key!r}]", mutant


def test_compiled_schema_gives_jsonschemas_verdicts(plan: dict[str, Any]) -> None:
    """The fast validator (fastjsonschema, draft 7) accepts and refuses what the reference
    validator (jsonschema, draft 2020-12) does, on 600 plans with one change each."""
    from planning.plan_schema import fast_verdict

    reference = jsonschema.Draft202012Validator(schema())
    assert fast_verdict(plan) and reference.is_valid(plan), "the unchanged plan must validate"
    refused = 0
    for where, mutant in _mutants(plan, 600):
        want = reference.is_valid(mutant)
        assert fast_verdict(mutant) == want, (
            f"change at {where}: jsonschema says valid={want}, fastjsonschema the opposite")
        refused += not want
    assert refused >= 200, f"only {refused} of 600 mutants invalid: the mutations are too mild"


def test_validate_names_the_field_of_a_refused_plan(fresh: dict[str, Any]) -> None:
    fresh["phases"][1]["steps"][0]["p_success"] = 1.5
    with pytest.raises(jsonschema.ValidationError, match=r"1\.5") as e:
        validate(fresh)
    assert list(e.value.absolute_path) == ["phases", 1, "steps", 0, "p_success"], e.value.path


def test_a_long_reach_takes_long_enough_for_rule_speed() -> None:
    """Benchmark rockfall 28's footstep plan reaches 2.02 m once: in the nominal 5 s that is
    over rule speed's free-gripper limit (0.4 m/s), so the reach must take longer."""
    from planning.plan import REACH_DURATION, reach_duration
    from planning.plan_model import GRIPPER_SPEED

    assert reach_duration(([0.0, 0.0], [0.3, 0.4])) == REACH_DURATION
    assert math.isclose(reach_duration(([0.0, 0.0], [3.0, 4.0])), 5.0 / GRIPPER_SPEED)
    scn = generate_cave("rockfall", 28, CaveConfig(length=(4.5, 5.0)))
    fp = plan_footsteps(scn, FootstepConfig())
    assert fp.success, f"rockfall 28 (a benchmark cave with a route) did not plan: {fp.reason}"
    built = plan_dict(build_plan(scn, fp, "rbp"))
    longest = 0.0
    for phase in built["phases"]:
        if phase["kind"] == "reach":
            first, last = phase["steps"][0], phase["steps"][-1]
            travel = math.dist(first["free_tip"], last["free_tip"])
            longest = max(longest, travel)
            assert travel <= GRIPPER_SPEED * (last["t"] - first["t"]) + 1e-5, (  # t to 1 us
                f"a reach of {travel:.3f} m in {last['t'] - first['t']:.3f} s")
    assert longest > 5.0 * 0.4, f"the longest reach is {longest:.3f} m: the test needs one > 2 m"
    problems = check_plan(built)
    assert problems == [], "rbp check refuses the footstep plan:\n" + "\n".join(problems)
