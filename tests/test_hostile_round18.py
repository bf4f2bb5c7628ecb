"""Probe 18: partial plans (`rbp plan --partial`) and continuations (plans with `start`, written
by `systems.replanning`) that `rbp check` accepted although they are wrong. Each test mutates a
real plan, shows `rbp check` refuses it naming the rule, and that the plan unmutated passes."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planning.check import verify_plan
from planning.pipeline import PipelineConfig
from planning.plan_model import Plan, plan_dict, plan_scenario
from rb_drake.scenario import bundled_caves, load_scenario
from systems.replanning import ReplanRequest, retry_replanner

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).resolve().parents[1]
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def partial() -> PlanFile:
    """blocked-shaft's partial plan (no route; seeds without SCP, as tests/test_partial.py)."""
    from rbp.api import plan as make

    plan = make(load_scenario(bundled_caves()["blocked-shaft"]),
                PipelineConfig(optimise=False), partial=True)
    assert plan.partial is not None and plan.regrasps > 0
    return plan_dict(plan)


@pytest.fixture(scope="module")
def continuation() -> PlanFile:
    """A retry continuation (`retry_replanner`) of the golden demo-shaft plan: its first body
    phase's grasp of the boom the next reach frees fails at the last step before the release
    ramp where the 3-stance still holds; the continuation starts mid-reach."""
    golden = Plan.from_dict(json.loads((DATA / "golden" / "demo-shaft-current.json")
                                       .read_text()))
    scn = plan_scenario(golden, "golden")
    body, boom = golden.phases[0], golden.phases[1].free_boom
    assert boom is not None
    ids = tuple(body.stance)
    anchor = ids[boom]
    assert anchor is not None
    three = tuple(None if i == boom else a for i, a in enumerate(ids))
    for step in reversed(body.steps):
        if step.ramp is not None:
            continue
        request = ReplanRequest(scn, golden, 0, float(step.t), np.array(step.pose), three, boom,
                                anchor, "overload")
        if (plan := retry_replanner(request)) is not None:
            return plan_dict(plan)
    raise AssertionError("no step of the first body phase gives a retry continuation")


def check(plan: PlanFile, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """`rbp check` on the plan written to a file."""
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")
    return subprocess.run([sys.executable, "-m", "rbp", "check", "--quiet", str(path)],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)


def refused(plan: PlanFile, tmp_path: Path, rule: str, words: str) -> None:
    """`rbp check` exits 1 with a problem of `rule` whose text holds `words`."""
    done = check(plan, tmp_path)
    assert done.returncode == 1, f"exit {done.returncode}: {done.stdout[-600:]}{done.stderr}"
    lines = [ln for ln in done.stdout.splitlines() if f": {rule}: " in ln and words in ln]
    assert lines, done.stdout


def test_the_unmutated_plans_pass(partial: PlanFile, continuation: PlanFile,
                                  tmp_path: Path) -> None:
    assert verify_plan(copy.deepcopy(partial)) == []
    assert verify_plan(copy.deepcopy(continuation)) == []
    done = check(partial, tmp_path)
    assert done.returncode == 0 and "partial: ends" in done.stdout, done.stdout
    done = check(continuation, tmp_path)
    assert done.returncode == 0 and "a continuation: starts at" in done.stdout, done.stdout


def test_a_partial_plan_whose_search_found_a_route_is_refused(partial: PlanFile,
                                                              tmp_path: Path) -> None:
    """A partial climb is flown only after a failed search; its search record set to stop ""
    (a route found) passed, the plan saying both that the search found a route and that no
    route reached the goal."""
    plan = copy.deepcopy(partial)
    assert plan["search"]["stop"] != ""
    plan["search"]["stop"] = ""
    refused(plan, tmp_path, "goal", "search record says a route was found")


def _rescored(plan: PlanFile) -> PlanFile:
    from planning.plan import score_plan

    model = Plan.from_dict(plan)
    return plan_dict(score_plan(model, plan_scenario(model, "x").robot.attach_failure))


def _cut_partial(plan: PlanFile, k: int) -> PlanFile:
    """The partial plan cut to its phases up to body phase k (its release ramp removed), a
    partial climb in its own right: rescored, its `partial` record recomputed."""
    plan = copy.deepcopy(plan)
    plan["phases"] = plan["phases"][:k + 1]
    phase = plan["phases"][k]
    assert phase["kind"] == "body"
    keep = len(phase["steps"])
    while "ramp" in phase["steps"][keep - 1]:
        keep -= 1
    phase["steps"] = phase["steps"][:keep]
    for key in ("seed_p_success", "seed_tension", "seed_effort", "effort"):
        phase["motion"][key] = phase["motion"][key][:keep]
    plan = _rescored(plan)
    scn = plan_scenario(Plan.from_dict(plan), "x")
    centre = scn.anchor_positions[[scn.anchor_index[a] for a in phase["stance"]]].mean(axis=0)
    plan["partial"]["reached_stance"] = phase["stance"]
    plan["partial"]["goal_distance_m"] = float(np.linalg.norm(centre - scn.goal_position))
    return plan


def test_a_partial_plan_whose_reason_names_another_climb_is_refused(partial: PlanFile,
                                                                   tmp_path: Path) -> None:
    """The reason, which `rbp check` prints on its ok line, names the partial climb's regrasps,
    stance and distances: a partial plan cut to fewer phases (a valid partial climb, rescored,
    its record recomputed) passed still saying "partial climb: N regrasps to stance S" of the
    climb it no longer holds."""
    k = max(k for k, p in enumerate(partial["phases"][:-1]) if p["kind"] == "body")
    plan = _cut_partial(partial, k)
    assert plan["regrasps"] < partial["regrasps"]
    refused(plan, tmp_path, "goal", "the reason does not say what the partial climb is")
    n = plan["regrasps"]
    part = plan["partial"]
    plan["reason"] = plan["reason"].replace(
        partial["reason"].split("partial climb: ")[1].split(")")[0] + ")",
        f"{n} regrasp{'' if n == 1 else 's'} to stance {part['reached_stance']}, "
        f"{part['goal_distance_m']:.2f} m from the goal (the start is "
        f"{part['start_distance_m']:.2f} m)")
    assert verify_plan(plan) == [], "the cut climb, its reason told, is a partial plan"


def test_a_continuation_starting_with_an_anchor_held_twice_is_refused(
        continuation: PlanFile, tmp_path: Path) -> None:
    """A continuation's first reach leaves `from_anchor`, which its `start` stance holds; the
    phase's stance (three booms) was checked for distinct anchors but not the start stance
    with from_anchor: one held by another boom gave a start on an anchor held twice, which
    rule start did not name (on the bundled caves no such reach holds, so other rules refused
    it; a cave where one did would have passed)."""
    plan = copy.deepcopy(continuation)
    first = plan["phases"][0]
    assert first["kind"] == "reach"
    j = first["free_boom"]
    other = next(a for a in first["stance"] if a is not None)
    first["from_anchor"] = other
    plan["start"]["stance"][j] = other
    problems = verify_plan(plan)
    assert any(p.rule == "start" and "two booms" in p.text for p in problems), \
        "\n".join(map(str, problems))
    refused(plan, tmp_path, "start", "holds an anchor with two booms")


def test_a_continuation_starting_mid_reach_says_its_boom_is_free(continuation: PlanFile,
                                                                 tmp_path: Path) -> None:
    """The ok line said a continuation "starts ... in stance S" of one that starts mid-reach,
    after a failed grasp: on three booms, S (with the failed anchor) never verified."""
    done = check(continuation, tmp_path)
    first = continuation["phases"][0]
    assert done.returncode == 0, done.stdout
    assert (f"with boom {first['free_boom']} free, its gripper at {first['from_anchor']}"
            in done.stdout and "is not verified" in done.stdout), done.stdout


def test_a_continuations_route_quality_is_said_to_be_the_plan_it_continues(
        continuation: PlanFile, tmp_path: Path) -> None:
    """A continuation keeps the search record of the plan it continues: the ok line said
    "route cost C, within 2.03x of the optimum (as the plan's search record states it)" of a
    climb that is not that route (a retry's reach added; a footstep replan's other route)."""
    assert continuation["search"]["cost"] is not None
    done = check(continuation, tmp_path)
    assert done.returncode == 0, done.stdout
    assert "of the optimum" in done.stdout and "the plan this continuation continues" in \
        done.stdout and "as the plan's search record states it" not in done.stdout, done.stdout


def test_a_partial_continuation_is_refused(continuation: PlanFile, tmp_path: Path) -> None:
    """No command writes a continuation (`start`) that is partial: `rbp plan --partial` climbs
    from the cave's start (`partial.start_distance_m` measures it) and a replanner returns a
    route to the goal or none. One made of the retry continuation cut to a body phase, its
    record recomputed and its reason told, passed, saying `(the start is X m)` of the cave's
    start while the climb starts elsewhere."""
    plan = copy.deepcopy(continuation)
    k = max(k for k, p in enumerate(plan["phases"][:-1]) if p["kind"] == "body")
    plan.update(success=False, search=dict(plan["search"], stop="noroute"),
                partial={"reached_stance": plan["phases"][k]["stance"], "goal_distance_m": 0.0,
                         "start_distance_m": 0.0})
    plan = _cut_partial(plan, k)
    scn = plan_scenario(Plan.from_dict(plan), "x")
    ids = [scn.anchor_index[a] for a in scn.start_stance]
    part, n = plan["partial"], plan["regrasps"]
    part["start_distance_m"] = float(np.linalg.norm(scn.anchor_positions[ids].mean(axis=0)
                                                    - scn.goal_position))
    plan["reason"] = (f"no route; partial climb: {n} regrasps to stance "
                      f"{part['reached_stance']}, {part['goal_distance_m']:.2f} m from the goal "
                      f"(the start is {part['start_distance_m']:.2f} m)")
    problems = verify_plan(copy.deepcopy(plan))
    assert [p.rule for p in problems] == ["goal"], "\n".join(map(str, problems))
    refused(plan, tmp_path, "goal", "is not a partial plan")
