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
