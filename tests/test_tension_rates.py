"""How fast the rig's commands may change (its winch bounds, `max_tension_rate` and
`max_length_rate`): `rbp rig-run` refuses a phase they would slow, the planner's ramps are
stretched to them, and the rig commands a released boom's 0 N as verified."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import lcm
import numpy as np
import pytest

from planning.plan_model import Step
from planning.ramps import RAMP_DURATION, RAMP_STEPS, TENSION_RATE_MAX, ramp_timing
from systems.reachbot_lcm import rig_command_t
from systems.rig import RigSimConfig
from systems.rig_interface import body_phase, rate_problem, run_rig
from systems.rig_log import RigInputError, RigLcmConfig

GOLDEN = Path(__file__).parent / "data" / "golden" / "demo-shaft-current.json"


@pytest.fixture(scope="module")
def plan() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text())


@pytest.fixture(scope="module", autouse=True)
def no_network_lcm() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LCM_DEFAULT_URL", "memq://")
        yield


def too_fast(plan: dict[str, Any], index: int) -> str:
    problem = rate_problem(body_phase(plan, index), RigLcmConfig(), index)
    return "" if problem is None else str(problem)


def step(tension: list[float | None]) -> Step:
    return Step(t=0.0, pose=(0.0, 0.0, 0.0), tension=tuple(tension), p_grasp=(), p_success=1.0)


def test_the_ramps_keep_to_the_rig_bound() -> None:
    assert RigLcmConfig().max_tension_rate == TENSION_RATE_MAX


def test_the_default_plan_keeps_to_the_rig_rates(plan: dict[str, Any]) -> None:
    body = [k for k, p in enumerate(plan["phases"]) if p["kind"] == "body"]
    assert len(body) >= 3, body
    for k in body:
        assert too_fast(plan, k) == "", (k, too_fast(plan, k))


def test_a_tension_jump_is_refused_by_the_rig(plan: dict[str, Any], tmp_path: Path) -> None:
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    steps[3]["tension"] = [f + 30.0 for f in steps[3]["tension"]]  # 60 N/s at dt 0.5 s
    found = too_fast(bad, 0)
    # up into step 3 and down into step 4: one problem, at the faster of the two
    assert found.startswith(("phases[0].steps[3]: boom ", "phases[0].steps[4]: boom ")), found
    assert "(and 1 more steps)" in found and "max_tension_rate of 25 N/s" in found, found
    log = tmp_path / "rig.lcm"
    with pytest.raises(RigInputError, match="max_tension_rate"):
        run_rig(bad, 0, RigLcmConfig(), log, sim_rig=RigSimConfig(seed=3))
    assert not log.exists(), "nothing is flown, no log written"
    # --no-verify flies it: the guard slows the commands and says so
    run = run_rig(bad, 0, RigLcmConfig(), log, sim_rig=RigSimConfig(seed=3), check_rates=False)
    assert run.safety.rate_limited > 0, run.safety


def test_a_boom_length_jump_is_refused_by_the_rig(plan: dict[str, Any]) -> None:
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    x, y, phi = steps[3]["pose"]
    steps[3]["pose"] = [x + 0.4, y, phi]  # 0.8 m/s at dt 0.5 s
    found = too_fast(bad, 0)
    assert found.startswith("phases[0].steps[") and "max_length_rate of 0.5 m/s" in found, found


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
