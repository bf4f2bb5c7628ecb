"""Probe 23: execution. `rbp simulate` (the deterministic climb, Monte Carlo, replanning,
Meshcat), `rbp rig-run` and `rbp.simulate` / `rbp.meshcat`: options and plans that crashed,
hung or reported numbers that contradict each other. Each test shows the input, what the
command or function does with it now, and that valid uses still work."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
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
