"""Probe 19: plan files and the verifier (`rbp check`, `rbp simulate`, `rbp rig-run`,
`rbp.check`). Each test builds a hostile plan from the golden demo-shaft plan, shows what the
verifier or a command does with it, and that the plan unmutated still passes."""

from __future__ import annotations

import copy
import json
import math
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import one_error_line, run_rbp

from planning import verify_between
from planning.check import verify_plan
from planning.plan_file import PlanFileError, plan_from
from planning.plan_model import Plan, plan_scenario

DATA = Path(__file__).parent / "data"
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> PlanFile:
    return json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())


def failed_plan(plan: PlanFile, phases: list[dict[str, Any]]) -> PlanFile:
    """`plan` with these phases, as a plan that found no route (no goal, no summary)."""
    out = copy.deepcopy(plan)
    out["phases"] = phases
    out.update(success=False, reason="no route", p_path=None, p_min=None, p_grasps=None,
               regrasps=0)
    out["search"] = {k: v for k, v in out["search"].items()
                     if k in ("stop", "expansions", "transitions_tested")} | {"stop": "budget"}
    return out


def spinning_phase(plan: PlanFile, steps: int, turns: int, dt: float) -> dict[str, Any]:
    """The first body phase made of its first configuration repeated, the body turned by
    `turns` full turns and back from step to step (each step the same configuration), `dt`
    apart: every step holds, and the motion between them is the most a step may move at the
    speed limits (rule `speed`)."""
    phase = copy.deepcopy(plan["phases"][0])
    first = phase["steps"][0]
    phase["steps"] = [dict(copy.deepcopy(first), t=round(n * dt, 6),
                           pose=[*first["pose"][:2], 2 * math.pi * turns * (n % 2)])
                      for n in range(steps)]
    motion = phase["motion"]
    for key in ("seed_p_success", "seed_tension", "seed_effort", "effort"):
        motion[key] = [motion[key][0]] * steps
    motion.pop("eased", None)
    return phase


def spinning_plan(golden: PlanFile, steps: int, turns: int, dt: float) -> tuple:
    """A failed plan of one `spinning_phase`, steps `dt` apart, and what the rock test between
    samples takes of it: (plan, verification world, phase, stance, samples)."""
    plan = failed_plan(golden, [spinning_phase(golden, steps, turns, dt)])
    plan["time_step"], plan["limits"] = dt, {"step": 0.1, "turn_step": 1e4}
    model = Plan.from_dict(plan)
    scn = plan_scenario(model, "spin")
    phase = model.phases[0]
    return (plan, verify_between.verification_world(scn), phase,
            scn.stance(tuple(phase.stance)), verify_between.phase_samples(scn.robot, phase))


def test_the_golden_plan_verifies(golden: PlanFile) -> None:
    assert verify_plan(golden) == [], "the golden demo-shaft plan must verify"


def test_rock_between_samples_is_tested_in_bounded_memory(golden: PlanFile) -> None:
    """A body phase turning 3 full turns and back every 48 s (2,160 samples an interval,
    within every bound of rule `between`): its paths' rock test (`travel_failures`) built
    every sample's boom geometry at once, 1.9 GB for a 0.5 MB plan of 10^6 samples (a phase's
    most); it now works in chunks of CHUNK, as the samples' checks do."""
    plan, world, phase, stance, s = spinning_plan(golden, 100, 3, 48.0)
    assert len(s.t) > 200_000, f"{len(s.t)} samples: the phase must move far between steps"
    times, poses, _ = verify_between.phase_arrays(phase)
    tracemalloc.start()
    try:
        found = verify_between.straight_travel(world, phase, stance, s, times, poses, None,
                                               set())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 120e6, f"the rock test between samples took {peak / 1e6:.0f} MB at its peak"
    assert found == [], f"no boom end or body corner crosses rock here: {found[:3]}"
    problems = verify_plan(plan)
    assert any(p.rule == "between" for p in problems), [str(p) for p in problems[:3]]


def test_the_chunked_rock_test_finds_what_one_batch_finds(golden: PlanFile,
                                                          monkeypatch) -> None:
    """The chunks share their boundary configuration: a crossing there, or in any chunk, is
    found as in one batch, each interval once at its first crossing (the body turning next to
    the wall, its corners through the rock)."""
    _, world, phase, stance, s = spinning_plan(golden, 6, 1, 16.0)
    times, poses, _ = verify_between.phase_arrays(phase)
    q = np.vstack([poses, s.poses])[np.argsort(np.concatenate([times, s.t]), kind="stable")]
    q[:, 0] = -0.75  # 0.1 m from the wall: the body's corners, 0.21 m out, sweep through it
    pair = np.clip(np.searchsorted(times, np.sort(np.concatenate([times, s.t]))[:-1],
                                   side="right") - 1, 0, len(times) - 2)
    whole = verify_between.travel_failures(world, stance, q, None, pair)
    assert len(whole) == len(times) - 1, f"each turn's corners cross rock: {whole}"
    for chunk in (1, 7, 100):
        monkeypatch.setattr(verify_between, "CHUNK", chunk)
        assert verify_between.travel_failures(world, stance, q, None, pair) == whole, (
            f"chunks of {chunk} configurations find other crossings than one batch")


def footstep_plan(plan: PlanFile) -> PlanFile:
    """`plan` without `time_step` and its `motion` records: a footstep plan, whose end
    configurations alone `rbp check` verifies."""
    out = copy.deepcopy(plan)
    del out["time_step"]
    for phase in out["phases"]:
        del phase["motion"]
    return out


def with_pebble_under_the_body(plan: PlanFile) -> PlanFile:
    """A rock 4 cm wide wholly inside the body's outline where the first reach phase holds
    it (no body edge crosses it, no body corner lies in it; the booms start at the corners)."""
    out = copy.deepcopy(plan)
    x, y = out["phases"][1]["steps"][0]["pose"][:2]
    out["scenario"]["walls"].append([[x - 0.02, y - 0.01], [x + 0.02, y - 0.01], [x, y + 0.02]])
    return out


def test_a_rock_wholly_inside_the_body_is_a_collision(golden: PlanFile, tmp_path: Path) -> None:
    """Rule `collision` at a step tested the body's edges and corners against rock, so a
    footstep plan whose body rested on a pebble (wholly inside its outline) for five steps
    passed `rbp check`; between steps, `check_poses` already saw it (`body_in_rock`)."""
    plain = footstep_plan(golden)
    assert verify_plan(plain) == [], "the golden plan as a footstep plan must verify"
    problems = verify_plan(with_pebble_under_the_body(plain))
    hits = [(p.phase, p.step) for p in problems if p.rule == "collision"]
    assert (1, 0) in hits and len(problems) == len(hits), [str(p) for p in problems]
    # the motion plan too: at its steps, not only between them
    problems = verify_plan(with_pebble_under_the_body(golden))
    assert any(p.rule == "collision" and p.phase == 1 and p.step == 0 for p in problems), (
        [str(p) for p in problems if p.rule == "collision"])
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(with_pebble_under_the_body(plain)))
    done = run_rbp("check", str(path), cwd=tmp_path)
    assert done.returncode == 1, f"exit {done.returncode}: {done.stdout[-400:]}"
    assert "phases[1] (reach) step 0 (t=8.0): collision: body collides with rock" in done.stdout


def test_a_footstep_body_move_spinning_for_hours_is_refused(golden: PlanFile,
                                                            tmp_path: Path) -> None:
    """A step may come more than 60 s after the one before only for a footstep plan's body
    move at its nominal speeds, 0.1 m/s and 0.2 rad/s; its turn counted in full, a body move
    spinning 1,500 turns in 13 hours (each end the same configuration) passed `rbp check`,
    whose footstep plans' motion is unverified, and `rbp simulate` ran it (10 turns: 405 s
    simulated in 35 s). A move's turn now counts up to a full turn."""
    plan = footstep_plan(golden)
    steps = [s for phase in plan["phases"] for s in phase["steps"]]
    first, second = steps[0], steps[1]
    spin = 2 * math.pi * 1500
    turn = abs(second["pose"][2] + spin - first["pose"][2])
    later = math.floor(turn / 0.2 * 1e6) / 1e6 - second["t"]  # just within 0.2 rad/s
    for step in steps[1:]:
        step["pose"][2] += spin
        step["t"] = round(step["t"] + later, 6)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    line = one_error_line(run_rbp("check", str(path), cwd=tmp_path),
                          "phases[0].steps[1].t", "s after the step before", "full turn")
    assert "47123" in line, line
    with pytest.raises(PlanFileError) as refused:
        plan_from(plan)
    assert refused.value.field == "phases[0].steps[1].t", refused.value.field
    assert plan_from(footstep_plan(golden)).time_step is None, "a footstep plan still reads"
