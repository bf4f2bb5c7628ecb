"""The rig interface's guards (because it drives hardware), each against a misbehaving fake rig
on `memq://`: commands within the boom limits, no non-finite command, a hold when the rig
stops answering, bad statuses logged but ignored, and command changes within the rate bounds.

The fake rig replaces `RigSimulatorLcm` inside `run_rig` (same constructor), so the runs are
the real `run_rig` on the in-process bus; each run takes about 0.1 s.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import lcm
import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

import systems.rig_interface as rig_interface
from rb_drake import geometry
from rb_drake.scenario import Scenario
from systems.reachbot_lcm import rig_command_t, rig_status_t
from systems.rig import RigSimConfig, load_rig_scenario, rig_plan
from systems.rig_interface import (
    GraspMonitor,
    RigRun,
    StatusFilter,
    body_phase,
    run_rig,
)
from systems.rig_log import RigInputError, RigLcmConfig, replay_log

CONFIG = RigLcmConfig()
NO_RATE_BOUND = RigLcmConfig(max_length_rate=math.inf, max_tension_rate=math.inf)
# What a misbehaving rig sends for command k given the simulated status: bytes, or None.
Misbehaviour = Callable[[int, rig_status_t], bytes | None]


@pytest.fixture(scope="module", autouse=True)
def no_network_lcm() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LCM_DEFAULT_URL", "memq://")
        yield


@pytest.fixture(scope="module")
def scn() -> Scenario:
    return load_rig_scenario()


@pytest.fixture(scope="module")
def plan(scn: Scenario) -> dict[str, Any]:
    return rig_plan(scn)


class Sent:
    """What the fake rig put on the status channel, in order."""

    def __init__(self) -> None:
        self.payloads: list[bytes] = []


def fake_rig(misbehave: Misbehaviour, sent: Sent) -> type:
    """A stand-in for `RigSimulatorLcm` that lets `misbehave` alter or drop each answer."""

    class FakeRigLcm:
        def __init__(self, simulator, bus, command_channel: str, status_channel: str):
            self.count = 0

            def on_command(data: bytes) -> None:
                out = misbehave(self.count, simulator.handle(rig_command_t.decode(data)))
                self.count += 1
                if out is not None:
                    sent.payloads.append(out)
                    bus.Publish(status_channel, out)

            bus.Subscribe(command_channel, on_command)

    return FakeRigLcm


def run_with(plan: dict[str, Any], misbehave: Misbehaviour, log: Path,
             config: RigLcmConfig = CONFIG, check_rates: bool = True) -> tuple[RigRun, Sent]:
    sent = Sent()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(rig_interface, "RigSimulatorLcm", fake_rig(misbehave, sent))
        run = run_rig(plan, 0, config, log, sim_rig=RigSimConfig(seed=3),
                      check_rates=check_rates)
    return run, sent


def honest(_k: int, status: rig_status_t) -> bytes:
    return status.encode()


def logged(log: Path) -> tuple[list[rig_command_t], list[bytes]]:
    """The commands (decoded) and the statuses (raw bytes) in a run's log."""
    commands, statuses = [], []
    for event in lcm.EventLog(str(log), "r"):
        if event.channel == CONFIG.command_channel:
            commands.append(rig_command_t.decode(event.data))
        elif event.channel == CONFIG.status_channel:
            statuses.append(event.data)
    return commands, statuses


def command_arrays(commands: list[rig_command_t]) -> tuple[np.ndarray, ...]:
    return (np.array([c.utime * 1e-6 for c in commands]),
            np.array([c.boom_length for c in commands]),
            np.array([c.tension_setpoint for c in commands]))


def planned(plan: dict[str, Any], times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The plan's unguarded boom lengths and tensions at `times`."""
    phase = body_phase(plan, 0)
    robot, anchors = phase.scenario.robot, phase.stance.positions
    lengths = np.array([geometry.boom_geometry(robot, phase.pose.value(t).ravel(),
                                               anchors).length[0] for t in times])
    return lengths, np.array([phase.tension.value(t).ravel() for t in times])


# ---------------------------------------------------------------------------------------------
# Commands


def test_commands_are_clamped_to_the_limits(scn: Scenario, plan: dict[str, Any],
                                            tmp_path: Path) -> None:
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    steps[4]["tension"] = [50.0, -5.0, 3.0, 3.0]  # beyond the 20 N limit, and pushing
    steps[6]["pose"] = [2.0, 0.0, 0.0]            # far outside the frame: booms over 2 m
    run, _ = run_with(bad, honest, tmp_path / "clamp.lcm", NO_RATE_BOUND)  # the clamp alone
    times, lengths, tensions = command_arrays(logged(tmp_path / "clamp.lcm")[0])
    lo_len, hi_len = scn.robot.boom_length
    lo_ten, hi_ten = scn.robot.boom_tension
    raw_len, raw_ten = planned(bad, times)
    assert raw_len.max() > hi_len + 0.1 and raw_ten.max() > hi_ten + 10, "the plan must exceed"
    assert raw_ten.min() < 0.0, "the plan must ask for a negative tension"
    assert np.all((lengths >= lo_len) & (lengths <= hi_len)), (
        f"boom lengths {lengths.min():.3f}..{lengths.max():.3f} m outside {lo_len}..{hi_len}")
    assert np.all((tensions >= lo_ten) & (tensions <= hi_ten)), (
        f"tensions {tensions.min():.3f}..{tensions.max():.3f} N outside {lo_ten}..{hi_ten}")
    np.testing.assert_allclose(lengths, np.clip(raw_len, lo_len, hi_len), atol=1e-9,
                               err_msg="a command is not the plan clamped to the limits")
    np.testing.assert_allclose(tensions, np.clip(raw_ten, lo_ten, hi_ten), atol=1e-9,
                               err_msg="a tension is not the plan clamped to the limits")
    outside = np.any((raw_len > hi_len + 1e-9) | (raw_ten > hi_ten + 1e-9)
                     | (raw_ten < lo_ten - 1e-9), axis=1)
    assert run.safety.clamped == int(outside.sum()), (
        f"{run.safety.clamped} commands reported clamped, {int(outside.sum())} were")
    assert run.safety.refused == run.safety.held == run.safety.bad_statuses == 0, run.safety
    assert any("clamped" in line for line in run.safety.messages(CONFIG)), "no clamp message"


def test_commands_change_at_most_the_rate_bounds(scn: Scenario, plan: dict[str, Any],
                                                 tmp_path: Path) -> None:
    """A plan that jumps (a pose 0.3 m off and tensions from one limit to the other, 0.05 s
    after the step before) becomes a ramp: no two successive commands differ by more than
    rate x period, and all stay within the limits."""
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    steps[6]["t"] = steps[5]["t"] + 0.05  # 0.05 s after the step before
    steps[6]["tension"] = [20.0, 0.5, 20.0, 0.5]
    steps[6]["pose"][0] += 0.3
    with pytest.raises(RigInputError, match="faster than the rig's max_"):  # rbp rig-run
        run_with(bad, honest, tmp_path / "refused.lcm")
    # `rbp rig-run --no-verify`: flown, the guard slowing it
    run, _ = run_with(bad, honest, tmp_path / "rate.lcm", check_rates=False)
    times, lengths, tensions = command_arrays(logged(tmp_path / "rate.lcm")[0])
    raw_len, raw_ten = planned(bad, times)
    step_len = CONFIG.max_length_rate * CONFIG.period  # m per command
    step_ten = CONFIG.max_tension_rate * CONFIG.period  # N per command
    assert np.abs(np.diff(raw_len, axis=0)).max() > 2 * step_len, "the plan must jump in length"
    assert np.abs(np.diff(raw_ten, axis=0)).max() > 2 * step_ten, "the plan must jump in tension"
    d_len, d_ten = np.abs(np.diff(lengths, axis=0)), np.abs(np.diff(tensions, axis=0))
    assert d_len.max() <= step_len + 1e-9, f"a boom length changed {d_len.max():.4f} m at once"
    assert d_ten.max() <= step_ten + 1e-9, f"a tension changed {d_ten.max():.3f} N at once"
    lo_ten, hi_ten = scn.robot.boom_tension
    assert np.all((tensions >= lo_ten - 1e-9) & (tensions <= hi_ten + 1e-9)), "outside limits"
    assert run.safety.rate_limited > 0, run.safety
    assert any("rate bounds" in line for line in run.safety.messages(CONFIG)), "no rate message"


def test_a_valid_plan_is_not_slowed(plan: dict[str, Any], tmp_path: Path) -> None:
    run, _ = run_with(plan, honest, tmp_path / "ok.lcm")
    assert run.safety.rate_limited == run.safety.clamped == 0, run.safety


@pytest.mark.parametrize(("field", "value"), [("tension", math.nan), ("pose", math.inf)])
def test_non_finite_plan_values_are_never_published(plan: dict[str, Any], tmp_path: Path,
                                                    field: str, value: float) -> None:
    bad = copy.deepcopy(plan)
    steps = bad["phases"][0]["steps"]
    steps[5][field][1] = value
    run, _ = run_with(bad, honest, tmp_path / "nan.lcm")
    commands = logged(tmp_path / "nan.lcm")[0]
    times, lengths, tensions = command_arrays(commands)
    assert np.all(np.isfinite(lengths)) and np.all(np.isfinite(tensions)), "non-finite command"
    raw_len, raw_ten = planned(bad, times)
    refused = ~(np.all(np.isfinite(raw_len), axis=1) & np.all(np.isfinite(raw_ten), axis=1))
    assert refused.sum() >= 2, f"the plan must be non-finite around step 5: {refused.sum()}"
    assert run.safety.refused == int(refused.sum()), (
        f"{run.safety.refused} refusals reported, {int(refused.sum())} non-finite commands")
    first = int(np.flatnonzero(refused)[0])
    for k in np.flatnonzero(refused):  # each refused command repeats the last safe one
        np.testing.assert_array_equal(lengths[k], lengths[first - 1],
                                      err_msg=f"command {k} is not the last safe one")
        np.testing.assert_array_equal(tensions[k], tensions[first - 1],
                                      err_msg=f"command {k} is not the last safe one")
    assert len(commands) == run.commands == run.statuses, "one status per command"


def test_a_non_finite_first_step_is_refused(plan: dict[str, Any]) -> None:
    bad = copy.deepcopy(plan)
    bad["phases"][0]["steps"][0]["tension"][2] = math.nan
    with pytest.raises(RigInputError, match=r"^phases\[0\]\.steps\[0\]: .*finite"):
        body_phase(bad, 0)


# ---------------------------------------------------------------------------------------------
# A rig that stops answering


def test_silent_rig_makes_the_commands_hold(plan: dict[str, Any], tmp_path: Path) -> None:
    answers = 8
    config = RigLcmConfig(status_timeout=0.35)

    def stops(k: int, status: rig_status_t) -> bytes | None:
        return status.encode() if k < answers else None

    run, sent = run_with(plan, stops, tmp_path / "silent.lcm", config)
    commands, statuses = logged(tmp_path / "silent.lcm")
    times, lengths, tensions = command_arrays(commands)
    assert len(statuses) == answers == len(run.live.time), "statuses logged and monitored"
    last_status = rig_status_t.decode(sent.payloads[-1]).utime * 1e-6
    # Silence is measured from the status's arrival (with its command, the same period).
    late = times > last_status + config.status_timeout + config.period + 1e-6
    assert late.sum() >= 5, f"the plan must go on well past the timeout: {late.sum()}"
    held_len, held_ten = lengths[late][0], tensions[late][0]
    np.testing.assert_array_equal(lengths[late], np.tile(held_len, (late.sum(), 1)),
                                  err_msg="boom lengths move after the timeout")
    np.testing.assert_array_equal(tensions[late], np.tile(held_ten, (late.sum(), 1)),
                                  err_msg="tensions move after the timeout")
    # The held setpoint was sent within the timeout of the last status's arrival (which the
    # bus pump delivers up to a period after its command).
    same = np.flatnonzero(np.all(lengths == held_len, axis=1))
    assert times[same[0]] <= last_status + config.status_timeout + config.period + 1e-6, (
        f"held setpoint first sent at {times[same[0]]:.2f} s, last status {last_status:.2f} s")
    raw_len, _ = planned(plan, times[late])
    assert np.abs(raw_len[-1] - held_len).max() > 1e-3, "the plan must have moved on"
    assert run.safety.held > 0 and run.safety.held == len(commands) - 1 - same[0], (
        f"held {run.safety.held}, identical tail {len(commands) - 1 - same[0]}")
    assert any("status timeout" in line for line in run.safety.messages(config)), "message"


# ---------------------------------------------------------------------------------------------
# A rig that sends bad statuses


def bad_payloads(status: rig_status_t) -> list[bytes]:
    """Garbage, another message type, and four out-of-range statuses."""
    command = rig_command_t()
    command.utime = status.utime
    out = [b"\x00garbage\xff" * 3, command.encode()]
    for field, index, value in (("load_cell_force", 0, math.nan), ("winch_length", 2, -0.1),
                                ("load_cell_force", 3, 1e4), ("hinge_angle", 1, math.inf)):
        broken = rig_status_t.decode(status.encode())
        values = list(getattr(broken, field))
        values[index] = value
        setattr(broken, field, values)
        out.append(broken.encode())
    return out


def test_bad_statuses_are_logged_and_ignored(plan: dict[str, Any], tmp_path: Path) -> None:
    good: list[bytes] = []

    def every_third_is_bad(k: int, status: rig_status_t) -> bytes:
        if k % 3 == 2:
            kinds = bad_payloads(status)
            return kinds[(k // 3) % len(kinds)]
        good.append(status.encode())
        return good[-1]

    log = tmp_path / "bad.lcm"
    run, sent = run_with(plan, every_third_is_bad, log)
    commands, statuses = logged(log)
    assert statuses == sent.payloads, "the log must keep every status as received"
    n_bad = len(sent.payloads) - len(good)
    assert n_bad >= 6, f"every kind of bad status must be sent: {n_bad}"
    assert run.safety.bad_statuses == n_bad, f"{run.safety.bad_statuses} ignored, {n_bad} bad"
    assert run.safety.held == 0, "bad statuses between good ones must not trip the timeout"
    expected_times = [rig_status_t.decode(d).utime * 1e-6 for d in good]
    np.testing.assert_array_equal(run.live.time, expected_times,
                                  err_msg="the monitor must see the good statuses only")
    assert np.all(np.isfinite(run.live.p_grasp)), "a bad status reached the monitor"
    replay = replay_log(log).replay
    for name in ("time", "p_grasp", "pull_angle", "force"):
        np.testing.assert_array_equal(getattr(replay, name), getattr(run.live, name),
                                      err_msg=f"replay != live: {name}")
    assert len(commands) == run.commands, "the run must go to the end"


def test_monitor_keeps_the_last_good_status(scn: Scenario, plan: dict[str, Any]) -> None:
    """StatusFilter -> GraspMonitor, fed good and bad bytes: after each, the monitor's output
    is the monitor's output for the last good status."""
    stance = body_phase(plan, 0).stance
    builder = DiagramBuilder()
    status_filter = builder.AddSystem(StatusFilter(scn.robot))
    monitor = builder.AddSystem(GraspMonitor(stance))
    builder.Connect(status_filter.status_port, monitor.status_port)
    builder.ExportInput(status_filter.raw_port, "raw")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    reference = GraspMonitor(stance)
    ref_context = reference.CreateDefaultContext()

    def status(utime: int, force: float) -> rig_status_t:
        msg = rig_status_t()
        msg.utime = utime
        msg.winch_length = [0.7, 0.8, 0.8, 0.7]
        msg.load_cell_force = [force, 3.0, 2.0, 1.5]
        msg.hinge_angle = [-2.4, -0.7, 0.7, 2.4]
        return msg

    sequence = [status(1, 4.0).encode(), b"junk", status(2, 5.0).encode()]
    sequence += bad_payloads(status(3, 6.0))
    good_messages = {0, 2}  # by construction; the rest are bad
    last_good = None
    simulator.Initialize()
    for k, data in enumerate(sequence):
        diagram.get_input_port(0).FixValue(root, AbstractValue.Make(data))
        simulator.AdvanceTo(0.1 * (k + 1))
        if k in good_messages:
            last_good = rig_status_t.decode(data)
        reference.status_port.FixValue(ref_context, last_good)
        mon_context = monitor.GetMyContextFromRoot(root)
        np.testing.assert_array_equal(monitor.p_grasp_port.Eval(mon_context),
                                      reference.p_grasp_port.Eval(ref_context),
                                      err_msg=f"p_grasp after message {k}")
        np.testing.assert_array_equal(monitor.pull_angle_port.Eval(mon_context),
                                      reference.pull_angle_port.Eval(ref_context),
                                      err_msg=f"pull angle after message {k}")
    memory = status_filter.memory(status_filter.GetMyContextFromRoot(root))
    assert (memory.good, memory.bad) == (2, len(sequence) - 2), memory[3:]
    assert memory.status.utime == 2, "the last good status is the one with utime 2"


def test_damaged_log_headers_and_wild_commands_refused(tmp_path: Path, scn: Scenario,
                                                      plan: dict[str, Any]) -> None:
    """Event headers are checked before lcm reads a log (a data length of 2**31 - 1 crashed
    lcm's C reader with signal 11; a bad channel length printed its complaint on stderr), and a
    command out of the robot's limits (tension 1e308 overflowed the report's plot) is refused
    naming its event."""
    import struct
    import subprocess
    import sys

    header = struct.Struct(">IqqII")
    cases = {
        "hugelen": (header.pack(0xEDA1DA01, 0, 0, 9, 0x7FFFFFFF) + b"RIG_SETUPxx",
                    "event 0 is damaged or not an LCM event: data length 2147483647"),
        "hugechan": (header.pack(0xEDA1DA01, 0, 0, 0x7FFFFFFF, 2) + b"xx", "channel length"),
        "negdata": (header.pack(0xEDA1DA01, 0, 0, 9, 0xFFFFFFFF) + b"RIG_SETUP", "data length"),
        "nosync": (b"hello, this is not a log at all", "no LCM sync word"),
        "short": (header.pack(0xEDA1DA01, 0, 0, 9, 2)[:20], "a header of 20 bytes"),
    }
    for name, (data, words) in cases.items():
        path = tmp_path / f"{name}.lcm"
        path.write_bytes(data)
        with pytest.raises(RigInputError, match=r"^\(file\): .*" + words):
            replay_log(path)
    # the crash itself, in a process of its own: one line, exit 2, nothing from lcm's C side
    path = tmp_path / "hugelen.lcm"
    result = subprocess.run([sys.executable, "-m", "rbp", "rig-replay", str(path)],
                            capture_output=True, text=True, timeout=120, check=False,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1, result.stderr

    log = tmp_path / "good.lcm"
    run_rig(plan, 0, CONFIG, log, sim_rig=RigSimConfig())
    events = list(lcm.EventLog(str(log), "r"))
    number = next(k for k, e in enumerate(events) if e.channel == CONFIG.command_channel)
    for value in (1e308, math.inf, math.nan, -1.0):
        command = rig_command_t.decode(events[number].data)
        command.tension_setpoint = [value, 1.0, 1.0, 1.0]
        wild = tmp_path / "wild.lcm"
        out = lcm.EventLog(str(wild), "w", overwrite=True)
        for k, e in enumerate(events):
            out.write_event(e.timestamp, e.channel, command.encode() if k == number else e.data)
        out.close()
        with pytest.raises(RigInputError, match=rf"^RIG_COMMAND: event {number}: "
                                                "tension_setpoint .* not within"):
            replay_log(wild)
    assert len(replay_log(log).command_time) > 0, "rbp's own log still replays"
