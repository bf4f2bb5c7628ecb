"""Probe 23: execution. `rbp simulate` (the deterministic climb, Monte Carlo, replanning,
Meshcat), `rbp rig-run` and `rbp.simulate` / `rbp.meshcat`: options and plans that crashed,
hung or reported numbers that contradict each other. Each test shows the input, what the
command or function does with it now, and that valid uses still work."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from cli_helpers import run_rbp
from test_simulation import _args, _short_plan

import rbp
from rb_drake.errors import RbpInputError
from rbp.commands.simulate import cmd_simulate

DATA = Path(__file__).parent / "data"
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def short() -> PlanFile:
    """The golden demo plan's first body phase alone (5 s of climb): quick to simulate."""
    return _short_plan(json.loads((DATA / "golden" / "demo-shaft-current.json").read_text()))


@pytest.fixture(scope="module")
def short_result(short: PlanFile) -> rbp.SimulationResult:
    return rbp.simulate(short, plant="body")


def test_a_replay_too_slow_for_drakes_frame_numbers_is_refused(
        short_result: rbp.SimulationResult) -> None:
    """`rbp.meshcat(result, speedup=1e-300)` ended in numpy's "ValueError: Maximum allowed
    size exceeded" (a grid of 1e304 frame times), 1e-6 asked for 29 GB of frame times on the
    demo, and a slow replay's frames past 2^31 (time x 20 frames a second) wrapped round in
    Drake without a word (a frame at 1e12 s became frame -2^31). speedup is now 0.1 or more,
    named in one line; 0.1 replays every sample, each at its own time."""
    for speedup in (1e-300, 1e-6, 0.05):
        with pytest.raises(RbpInputError) as refused:
            rbp.meshcat(short_result, speedup=speedup)
        message = str(refused.value)
        assert message.startswith("speedup: ") and "0.1 or more" in message, message
    samples = len(short_result.record.times)
    with rbp.meshcat(short_result, speedup=0.1) as view:
        assert view.frames == samples, f"{view.frames} frames for {samples} samples at 0.1x"
    with rbp.meshcat(short_result, speedup=4.0) as view:
        duration = float(short_result.record.times[-1])
        assert abs(view.frames - duration / 4.0 * 20.0) <= 2, (view.frames, duration)


def test_end_of_input_at_the_meshcat_prompt_quits_as_enter_does(
        short: PlanFile, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp simulate plan.json --meshcat` on a terminal waits for Enter; Ctrl-D there ended in
    a traceback (EOFError from input()). It now quits as Enter does, exit status 0."""
    import builtins

    path = tmp_path / "plan.json"
    path.write_text(json.dumps(short))

    def ctrl_d(prompt: str = "") -> str:
        print(prompt, end="")
        raise EOFError

    monkeypatch.setattr("sys.stdin.isatty", lambda: True)
    monkeypatch.setattr(builtins, "input", ctrl_d)
    assert cmd_simulate(_args(str(path), "--trials", "0", "--meshcat", "--no-verify")) == 0
    out = capsys.readouterr().out
    assert "Meshcat: http://" in out and "press Enter to quit" in out, out


@pytest.mark.parametrize("period", [1.0, 0.3])
def test_rig_run_commands_the_phase_to_its_end(period: float, tmp_path: Path) -> None:
    """`rbp rig-run rig.json --period 1` sent commands at 0, 1 and 2 s of the rig plan's
    2.8 s phase and stopped: the rig never got the verified end pose (its last 0.8 s were never
    commanded) and the run reported its minima without it. The last command now goes out at
    the first k * period at or after the phase's end, the end pose's boom lengths."""
    import numpy as np

    from planning.plan_file import plan_from
    from rb_drake import geometry
    from systems.rig_interface import body_phase
    from systems.rig_log import replay_log

    path = tmp_path / "rig.json"
    path.write_text((DATA / "golden" / "rig.json").read_text())
    log = tmp_path / "rig.lcm"
    result = run_rbp("rig-run", str(path), "--sim-rig", "--period", str(period), "--log",
                     str(log), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    phase = body_phase(plan_from(json.loads(path.read_text())), 0)
    read = replay_log(log)
    assert read.command_time[-1] >= phase.end_time - 1e-9, (
        f"the last command at {read.command_time[-1]} s, the phase ends at {phase.end_time} s")
    assert read.command_time[-2] < phase.end_time - 1e-9, "one command past the end, no more"
    end = geometry.boom_geometry(phase.scenario.robot, phase.pose.value(phase.end_time).ravel(),
                                 phase.stance.positions).length[0]
    np.testing.assert_allclose(read.boom_length[-1], end, atol=1e-9,
                               err_msg="the last command must be the end pose's boom lengths")
    plain = run_rbp("rig-run", str(path), "--sim-rig", "--log", str(log), cwd=tmp_path)
    assert "29 commands sent" in plain.stdout, f"0.1 s divides 2.8 s: as before {plain.stdout}"


def test_trials_stopped_at_a_handover_are_not_counted_as_replanned() -> None:
    """A plan flown with --no-verify whose release ramp is missing stops at that gripper
    (`handover`) in every trial that gets there; `rbp simulate --replan retry` said "1 of 50
    failed climbs saved (50 still held on 3 booms, 1 replans)": 49 of those trials never asked
    for a replan (no state to replan from). attempted now counts only the trials that asked."""
    import numpy as np

    from planning.plan_faults import ramp_removed
    from systems.diagram import ClimbSimulator
    from systems.montecarlo import monte_carlo, retry_replanner
    from systems.trajectory import PlanTrajectory, plan_scenario

    golden = json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())
    fault = next(f for f in (ramp_removed(golden, np.random.default_rng(s)) for s in range(20))
                 if "release" in f.what)
    traj = PlanTrajectory(fault.plan, plan_scenario(fault.plan))
    sim = ClimbSimulator(traj.scenario, plant="body")
    record = sim.run(traj)
    assert record.failure is not None and record.failure.cause == "handover", record.failure
    mc = monte_carlo(record, 50, 0, retry_replanner, "retry", sim)
    r = mc.replanning
    assert r is not None
    failed = mc.trials - mc.successes
    handover = r.outcomes.get("handover", 0)
    assert handover > 0, f"the trials stop at the gripper: {r.outcomes}"
    assert r.attempted == failed - handover - r.outcomes.get("fell", 0), (
        f"{r.attempted} attempted of {failed} failed, {handover} stopped at the handover")
    assert r.replans <= r.attempted, f"{r.replans} replans for {r.attempted} asked"
    assert r.saved + sum(r.outcomes.values()) == failed, "the failed trials add up"


def test_a_climb_stopped_at_a_handover_says_so_and_fails(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The demo plan without a release ramp, flown with --no-verify: the deterministic climb
    stops at that gripper at 87 s, yet `rbp simulate --trials 0` printed "simulated 182.0 s,
    15 phases", p_sim 0.0000 without a reason, and exit status 0. It now says how far the
    climb went, one error line names the phase, time and boom, and the exit status is 1 (a
    failed execution); the --json file is still written."""
    import numpy as np

    from planning.plan_faults import ramp_removed

    golden = json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())
    fault = next(f for f in (ramp_removed(golden, np.random.default_rng(s)) for s in range(20))
                 if "release" in f.what)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(fault.plan))
    out = tmp_path / "sim.json"
    status = cmd_simulate(_args(str(path), "--trials", "0", "--no-verify", "--json", str(out)))
    text = capsys.readouterr()
    assert status == 1, f"a climb that cannot go on is a failed execution: {status}"
    first = text.out.splitlines()[0]
    assert "simulated 87.0 of 182.0 s" in first and "7 of 15 phases" in first, first
    errors = [line for line in text.err.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, text.err
    assert f"phase {fault.phase} (body) at t = 87.00 s" in errors[0], errors[0]
    assert json.loads(out.read_text())["p_sim"] == 0.0
