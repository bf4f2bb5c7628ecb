"""Probe 21: plan files that `rbp check` accepts although what `rbp simulate` or `rbp rig-run`
executes differs. Each test builds a hostile plan from the golden demo-shaft plan, shows what
the reader, the verifier or a command does with it, and that the plan unmutated still passes."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import one_error_line, run_rbp
from test_hostile_round19 import failed_plan, footstep_plan

from planning.check import verify_plan
from planning.plan import short_way
from planning.plan_file import PlanFileError, plan_from

DATA = Path(__file__).parent / "data"
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> PlanFile:
    return json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())


def spun(plan: PlanFile, turns: int, later: float) -> PlanFile:
    """`plan` with its body turned `turns` more full turns from its second step on (each step
    the same configuration), those steps `later` s later."""
    out = copy.deepcopy(plan)
    for step in [s for phase in out["phases"] for s in phase["steps"]][1:]:
        step["pose"][2] += 2 * math.pi * turns
        step["t"] = round(step["t"] + later, 6)
    return out


def test_a_step_turning_more_than_half_a_turn_is_refused(golden: PlanFile,
                                                         tmp_path: Path) -> None:
    """A footstep plan's body move turning 3 full turns in 47.5 s (within 0.4 rad/s and the
    60 s a step may take; its end configurations the same) passed `rbp check`; `rbp simulate`
    ran it 180 deg off its heading (its controller takes the heading error the short way
    round) and `rbp rig-run` refused it. The reader now refuses a step turning the body more
    than half a turn from the step before, for all three commands and the API."""
    plain = footstep_plan(golden)
    assert verify_plan(plain) == [], "the golden plan as a footstep plan must verify"
    assert plan_from(plain).time_step is None, "the unmutated footstep plan still reads"
    spinning = spun(plain, 3, 47.0)
    assert verify_plan(spinning) == [], "the verifier alone cannot tell (its ends hold)"
    with pytest.raises(PlanFileError) as refused:
        plan_from(spinning)
    assert refused.value.field == "phases[0].steps[1].pose[2]", refused.value.field
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(spinning))
    for command in (["check", str(path)], ["simulate", str(path)],
                    ["rig-run", str(path), "--sim-rig", "--log", str(tmp_path / "r.lcm")]):
        line = one_error_line(run_rbp(*command, cwd=tmp_path), "phases[0].steps[1].pose[2]",
                              "half a turn")
        assert "18.8" in line, f"{command[0]}: the turn is not stated: {line}"
    assert not (tmp_path / "r.lcm").exists(), "rig-run logged a refused plan"
    # half a turn is still a step's (its duration within the 60 s a step may take)
    half = spun(plain, 0, 0.0)
    for step in [s for phase in half["phases"] for s in phase["steps"]][1:]:
        step["pose"][2] += math.pi - 0.01
    assert plan_from(half).time_step is None, "a step turning under half a turn reads"


def test_the_planner_writes_each_turn_the_short_way_round() -> None:
    """The search's headings lie in [-pi, pi] (the lattice's and OMPL's): a footstep plan's move
    from 3.1 rad to -3.1 rad is written as the 0.08 rad it turns, not the long way round; a
    heading within half a turn of the one before is kept to the bit."""
    poses = [np.array([0.0, 0.0, 3.1]), np.array([0.1, 0.0, -3.1]),
             np.array([0.2, 0.0, 2.9]), np.array([0.3, 0.0, 0.1 + 1e-17])]
    headings = [float(p[2]) for p in short_way(poses)]
    turns = np.abs(np.diff(headings))
    assert np.all(turns <= math.pi), f"a written turn over half a turn: {headings}"
    assert headings[1] == pytest.approx(2 * math.pi - 3.1), headings
    assert headings[2] == 2.9 and headings[3] == poses[3][2], headings
    assert [float(p[0]) for p in short_way(poses)] == [0.0, 0.1, 0.2, 0.3], "x unchanged"


def test_rig_run_refuses_a_failed_plan_that_has_phases(golden: PlanFile,
                                                       tmp_path: Path) -> None:
    """A failed plan (`success: false`, not a partial climb) that still has phases (a route
    whose motion failed) verifies, and `rbp simulate` refuses it in one line (no route,
    status 1); `rbp rig-run` flew its phase. It now refuses it as simulate does."""
    failed = failed_plan(golden, golden["phases"])
    failed.update(regrasps=golden["regrasps"], reason="motion planning failed at phase 3")
    assert verify_plan(failed) == [], "the failed plan must verify (it is valid as written)"
    path = tmp_path / "failed.json"
    path.write_text(json.dumps(failed))
    lines = {}
    for command, what in (("simulate", "nothing to simulate"), ("rig-run", "nothing to fly")):
        log = tmp_path / f"{command}.lcm"
        args = [command, str(path)] + (["--sim-rig", "--log", str(log)]
                                       if command == "rig-run" else [])
        done = run_rbp(*args, cwd=tmp_path)
        err = done.stderr.strip().splitlines()
        assert done.returncode == 1 and len(err) == 1, f"{command}: exit {done.returncode}, {err}"
        assert err[0].startswith(f"error: {path}: success: ") and what in err[0], err[0]
        assert "motion planning failed at phase 3" in err[0], err[0]
        lines[command] = err[0]
        assert not log.exists(), f"{command} logged a refused plan"
    # the plan that succeeded, the same phases: rig-run flies it
    good = tmp_path / "good.json"
    good.write_text(json.dumps(golden))
    done = run_rbp("rig-run", str(good), "--sim-rig", "--log", str(tmp_path / "g.lcm"),
                   cwd=tmp_path)
    assert done.returncode == 0, f"exit {done.returncode}: {done.stderr[-400:]}"
