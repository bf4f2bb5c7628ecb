"""How fast a plan's tensions may change (rule `tension-rate`, the rig's winch bound), the
ramps stretched to it, and the rig commanding a released boom's 0 N as verified."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import lcm
import numpy as np
import pytest

from planning.plan_model import Step, plan_of, plan_scenario
from planning.ramps import RAMP_DURATION, RAMP_STEPS, TENSION_RATE_MAX, ramp_timing
from planning.verify_climb import RULES, climb_problems
from systems.reachbot_lcm import rig_command_t
from systems.rig import RigSimConfig
from systems.rig_interface import body_phase, run_rig
from systems.rig_log import RigLcmConfig

GOLDEN = Path(__file__).parent / "data" / "golden" / "demo-shaft-current.json"


@pytest.fixture(scope="module")
def plan() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text())


@pytest.fixture(scope="module", autouse=True)
def no_network_lcm() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LCM_DEFAULT_URL", "memq://")
        yield


def rate_problems(plan: dict[str, Any]) -> list[str]:
    p = plan_of(plan)
    return [str(q) for q in climb_problems(p, plan_scenario(p, "test"))
            if q.rule == "tension-rate"]


def step(tension: list[float | None]) -> Step:
    return Step(t=0.0, pose=(0.0, 0.0, 0.0), tension=tuple(tension), p_grasp=(), p_success=1.0)


def test_the_rig_bound_is_the_rule() -> None:
    assert RigLcmConfig().max_tension_rate == TENSION_RATE_MAX
    assert "tension-rate" in RULES


def test_the_default_plan_keeps_to_the_rate(plan: dict[str, Any]) -> None:
    assert rate_problems(plan) == []


def test_a_tension_jump_is_refused(plan: dict[str, Any]) -> None:
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    steps[3]["tension"] = [f + 30.0 for f in steps[3]["tension"]]  # 60 N/s at dt 0.5 s
    found = rate_problems(bad)
    # up into step 3 and down into step 4: one problem, at the faster
    assert len(found) == 1 and "phases[0] (body) step " in found[0], found
    assert "over 25 N/s (and 1 more steps)" in found[0], found


def test_a_small_ramp_lasts_its_duration() -> None:
    a, b = step([3.0, 4.0, 5.0, 6.0]), step([3.0, 4.0, 0.0, None])
    assert ramp_timing(a, b, 0.5, RAMP_DURATION) == (2, 0.5)
    assert ramp_timing(a, b, None, RAMP_DURATION) == (RAMP_STEPS, RAMP_DURATION / RAMP_STEPS)


@pytest.mark.parametrize("dt", [0.5, 0.25, None])
def test_a_heavy_ramp_is_stretched_to_the_rate(dt: float | None) -> None:
    """1000 N released: at least 40 s, every step within the rate."""
    a, b = step([900.0, 1000.0, 50.0, 700.0]), step([950.0, 0.0, 80.0, None])
    n, gap = ramp_timing(a, b, dt, RAMP_DURATION)
    assert n * gap >= 1000.0 / TENSION_RATE_MAX - 1e-9
    assert 1000.0 / n <= TENSION_RATE_MAX * gap + 1e-9
    assert dt is None or gap == dt


def test_the_rig_releases_at_zero_newtons(plan: dict[str, Any], tmp_path: Path) -> None:
    """Phase 0 ends with boom 2's release ramp at 0 N: commanded as verified, not raised to
    boom_tension's minimum, and nothing clamped."""
    phase = body_phase(plan, 0)
    free = plan["phases"][1]["free_boom"]
    assert free in phase.ramped
    assert plan["phases"][0]["steps"][-1]["tension"][free] <= 0.05
    log = tmp_path / "rig.lcm"
    run = run_rig(plan, 0, RigLcmConfig(), log, sim_rig=RigSimConfig(seed=3))
    sent = [rig_command_t.decode(e.data) for e in lcm.EventLog(str(log), "r")
            if e.channel == RigLcmConfig().command_channel]
    tensions = np.array([c.tension_setpoint for c in sent])
    assert tensions[-1, free] <= 0.05, tensions[-1]
    held = [i for i in range(4) if i != free]
    assert tensions[:, held].min() >= plan["robot"]["boom_tension"][0] - 1e-9
    assert run.safety.clamped == 0 and run.safety.rate_limited == 0, run.safety
