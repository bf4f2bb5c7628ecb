"""Hostile rig logs, plans and arguments (probe round 4: T1-T3, Q2, Q7, M2, M3, S2): each
refused in one line naming the field, or read as valid; none a traceback."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np
import pytest

from rb_drake.input_files import InputFileError, load_json, load_yaml
from rb_drake.scenario import bundled_caves, load_scenario

STANCE = ["a30", "a6", "a1", "a20"]
_HEADER = struct.Struct(">Iqqii")


def _event(number: int, channel: bytes, data: bytes) -> bytes:
    """One LCM log event, written by hand (lcm's writer takes only str channels)."""
    return _HEADER.pack(0xEDA1DA01, number, 0, len(channel), len(data)) + channel + data


def _setup(scenario_json: str | None = None, stance: list[str] = STANCE) -> bytes:
    from systems.reachbot_lcm import rig_setup_t

    msg = rig_setup_t()
    msg.scenario_json = scenario_json or json.dumps(
        load_scenario(bundled_caves()["demo-shaft"]).to_dict())
    msg.stance, msg.plan_source = stance, "test"
    return msg.encode()


def _status(t: int, force: float) -> bytes:
    from systems.reachbot_lcm import rig_status_t

    msg = rig_status_t()
    msg.utime, msg.winch_length, msg.load_cell_force = t, [1.0] * 4, [force] * 4
    msg.hinge_angle = [0.1, -0.2, 0.3, -0.4]
    return msg.encode()


def _write(path: Path, events: list[tuple[bytes, bytes]]) -> Path:
    path.write_bytes(b"".join(_event(i, c, d) for i, (c, d) in enumerate(events)))
    return path


def test_non_utf8_channel_skipped_as_any_other_channel_and_non_utf8_file_name(tmp_path):
    """A channel named b'OTHER\\xff' was a UnicodeDecodeError traceback from lcm's reader; a
    file name that is not UTF-8 was refused as 'not an LCM log'."""
    from systems.rig_log import replay_log

    events = [(b"RIG_SETUP", _setup()), (b"OTHER\xff\n", b"x"), (b"OTHER", b"y"),
              (b"RIG_STATUS", _status(0, 2.0)), (b"RIG_STATUS", b"garbage")]
    name = os.fsdecode(b"bad\xff.lcm")  # the byte as a surrogate, as argv gives it
    log = replay_log(_write(tmp_path / name, events))
    assert len(log.replay.time) == 1 and log.stance_ids == tuple(STANCE)


def test_replay_as_arrays_equals_the_monitor(tmp_path):
    """The array replay gives GraspMonitor's outputs, status by status."""
    from pydrake.common.value import AbstractValue

    from systems.reachbot_lcm import rig_status_t
    from systems.rig_interface import GraspMonitor
    from systems.rig_log import replay_log

    statuses = [_status(k * 100_000, 2.0 + k) for k in range(5)]
    log = replay_log(_write(tmp_path / "run.lcm", [(b"RIG_SETUP", _setup())]
                            + [(b"RIG_STATUS", s) for s in statuses]))
    monitor = GraspMonitor(log.scenario.stance(log.stance_ids))
    context = monitor.CreateDefaultContext()
    for k, data in enumerate(statuses):
        monitor.status_port.FixValue(context, AbstractValue.Make(rig_status_t.decode(data)))
        np.testing.assert_allclose(log.replay.p_grasp[k], monitor.p_grasp_port.Eval(context),
                                   rtol=1e-12)
        np.testing.assert_allclose(log.replay.pull_angle[k],
                                   monitor.pull_angle_port.Eval(context), rtol=1e-12)


def test_non_utf8_stance_id_escaped(tmp_path):
    """lcm's decoder puts U+FFFD for bytes that are not UTF-8: shown escaped."""
    from systems.rig_log import RigInputError, replay_log

    setup = _setup(stance=["aXY", "a6", "a1", "a20"]).replace(b"aXY", b"a\xff\xfe")
    path = _write(tmp_path / "run.lcm", [(b"RIG_SETUP", setup)])
    with pytest.raises(RigInputError, match=r"unknown anchor 'a\\ufffd\\ufffd'"):
        replay_log(path)


def test_setup_scenario_bounded_by_a_scenario_files_values(tmp_path):
    """A setup scenario padded with 900,000 objects was parsed (354 MB) before refusal."""
    from systems.rig_log import RigInputError, replay_log

    padded = json.dumps({"zzz": [{"a": 0}] * 60_000})
    path = _write(tmp_path / "run.lcm", [(b"RIG_SETUP", _setup(padded))])
    with pytest.raises(RigInputError, match=r"RIG_SETUP\.scenario_json: may hold up to 120,002 "
                       r"values .* over the limit of 50,000"):
        replay_log(path)


def test_bad_last_command_found_among_many(tmp_path):
    """The commands are checked as arrays; the first bad one is named by its event."""
    from systems.reachbot_lcm import rig_command_t
    from systems.rig_log import RigInputError, replay_log

    good, bad = rig_command_t(), rig_command_t()
    good.boom_length, good.tension_setpoint = [1.0] * 4, [5.0] * 4
    bad.boom_length, bad.tension_setpoint = [float("nan")] * 4, [5.0] * 4
    events = [(b"RIG_SETUP", _setup())] + [(b"RIG_COMMAND", good.encode())] * 3000
    path = _write(tmp_path / "run.lcm", [*events, (b"RIG_COMMAND", bad.encode())])
    with pytest.raises(RigInputError, match=r"RIG_COMMAND: event 3001: boom_length \[nan"):
        replay_log(path)


@pytest.mark.parametrize("load, text, field", [
    (load_json, '{"a": [1, {"b": "x\\ud800"}], "c": "\\udfff"}', "a[1].b"),
    (load_json, '{"\\udc00": 1}', "\udc00"),
])
def test_lone_surrogates_refused_at_reading(load, text, field):
    """A plan's anchor id "\\ud800" passed rbp check, then rig-run's log encoder raised."""
    with pytest.raises(InputFileError, match="a lone surrogate") as caught:
        load(text)
    assert caught.value.field == field
    assert load_json('{"a": "\\ud83d\\ude00"}') == {"a": "\U0001f600"}  # a pair is fine
    with pytest.raises(InputFileError):  # YAML's reader refuses the escape itself
        load_yaml('a:\n  b: "x\\ud800"\n')


def test_rig_run_plan_source_of_a_non_utf8_file_name(tmp_path):
    """rig-run's plan_source of a file name that is not UTF-8 raised in the log's encoder."""
    from systems.rig import RigSimConfig, load_rig_scenario, rig_plan
    from systems.rig_interface import run_rig
    from systems.rig_log import RigLcmConfig, replay_log

    plan = rig_plan(load_rig_scenario())
    run = run_rig(plan, 0, RigLcmConfig(period=0.5), tmp_path / "run.lcm",
                  sim_rig=RigSimConfig(), plan_source=os.fsdecode(b"bad\xff.json phase 0"))
    assert replay_log(run.log).plan_source == "bad\\udcff.json phase 0"


def test_rig_experiment_checks_the_url_before_heavy_imports(capsys):
    """--lcm-url file:// was refused by run_rig, after planning (1.1 s, 267 MB)."""
    from experiments.rig_experiment import main

    for url in ("file:///tmp/x", "udpm://239.1.1.1:7667"):
        with pytest.raises(SystemExit) as caught:
            main(["--lcm-url", url, "--out", "/nonexistent/never"])
        assert caught.value.code == 2
        assert "--lcm-url: the simulated rig runs in-process" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--hardware", "--lcm-url", "udpm://999.1.1.1:99999", "--out", "/nonexistent/x"])
    assert "'999.1.1.1' is not an IPv4 address" in capsys.readouterr().err


_HEAVY = ("pydrake", "matplotlib", "lcm")  # Drake alone took rig-replay's refusal to 190 MB


def _bad_last_command_log(path: Path) -> Path:
    from systems.reachbot_lcm import rig_command_t

    good, bad = rig_command_t(), rig_command_t()
    good.boom_length, good.tension_setpoint = [1.0] * 4, [5.0] * 4
    bad.boom_length, bad.tension_setpoint = [float("nan")] * 4, [5.0] * 4
    return _write(path, [(b"RIG_SETUP", _setup()), *[(b"RIG_COMMAND", good.encode())] * 50,
                         (b"RIG_COMMAND", bad.encode()), (b"RIG_STATUS", _status(0, 2.0))])


def test_rig_log_read_and_refused_without_drake(tmp_path):
    """A damaged log is read, checked and refused through `systems.rig_log`, and `rbp
    rig-replay` replays a good one, without importing Drake, matplotlib or lcm (a refusal
    took 211 MB with them, over the 200 MB of the reading limits); the refusal is one line."""
    import subprocess
    import sys

    from tests.cli_helpers import ROOT, run_rbp

    bad = _bad_last_command_log(tmp_path / "bad.lcm")
    good = _write(tmp_path / "good.lcm", [(b"RIG_SETUP", _setup()),
                                          (b"RIG_STATUS", _status(0, 2.0))])
    code = f"""if True:
        import sys
        from systems.rig_log import RigInputError, replay_log
        try:
            replay_log({str(bad)!r})
        except RigInputError as e:
            print(e)
        from rbp.cli import main
        assert main(["rig-replay", {str(good)!r}]) == 0
        print(sorted({{m.split(".")[0] for m in sys.modules}} & set({_HEAVY!r})))
    """
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LCM_DEFAULT_URL": "memq://"}
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    assert lines[0].startswith("RIG_COMMAND: event 51: boom_length [nan"), lines
    assert "1 statuses" in lines[1] and lines[-1] == "[]", lines

    refused = run_rbp("rig-replay", str(bad), cwd=tmp_path)
    assert refused.returncode == 2, refused.stderr
    assert refused.stderr.splitlines() == [f"error: {bad}: {lines[0]}"]
