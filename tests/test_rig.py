"""The rig over LCM (paper section V-B): its scenario and straight-line plan, the simulated rig,
a full `rig-run --sim-rig` on the in-process bus, its log, replay and report, and the CLI's
refusals. Everything runs on `memq://`: no test touches UDP multicast.

One simulated run (module fixture, about 0.1 s) feeds most tests; Python LeafSystems are never
freed in pydrake 1.51, so the tests build few diagrams.
"""

from __future__ import annotations

import argparse
import copy
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import lcm
import numpy as np
import pytest

from rb_drake import geometry
from rb_drake.errors import RbpInputError
from rb_drake.feasibility import check_poses
from rb_drake.scenario import Scenario
from rbp.commands.common import UserError
from rbp.commands.rig import add_rig_commands, cmd_rig_replay, cmd_rig_report, cmd_rig_run
from systems.reachbot_lcm import rig_command_t, rig_status_t
from systems.rig import RigSimConfig, RigSimulator, fit_pose, load_rig_scenario, rig_plan
from systems.rig_interface import (
    GraspMonitor,
    RigRun,
    body_phase,
    run_rig,
)
from systems.rig_log import RigLcmConfig, replay_log

SIM = RigSimConfig(seed=7)
# Measured minus planned tension is the load-cell noise alone while the winches keep up (the
# plan moves the booms at <= 0.1 m/s, the winches at 0.5 m/s), so no sample may be 5 sigma off
# (P < 6e-7 per sample) and the mean error per boom stays within 4 sigma / sqrt(N).
NOISE_SIGMAS = 5.0


@pytest.fixture(scope="module", autouse=True)
def no_network_lcm() -> Iterator[None]:
    """A default-constructed LCM would fall back to UDP multicast: pin it to memq://."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LCM_DEFAULT_URL", "memq://")
        yield


@pytest.fixture(scope="module")
def scn() -> Scenario:
    return load_rig_scenario()


@pytest.fixture(scope="module")
def plan(scn: Scenario) -> dict[str, Any]:
    return rig_plan(scn)


@pytest.fixture(scope="module")
def plan_file(plan: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rig") / "plan.json"
    path.write_text(json.dumps(plan))
    return path


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rbp")
    add_rig_commands(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(list(argv))


@pytest.fixture(scope="module")
def sim_run(plan_file: Path) -> tuple[RigRun, Path]:
    """`rbp rig-run plan.json --phase 0 --sim-rig --log rig.lcm`, through the CLI handler."""
    import systems.rig_interface as rig_interface

    runs: list[RigRun] = []
    real = rig_interface.run_rig

    def spy(*args, **kwargs) -> RigRun:
        runs.append(real(*args, **kwargs))
        return runs[-1]

    log = plan_file.parent / "rig.lcm"
    args = parse("rig-run", str(plan_file), "--phase", "0", "--sim-rig", "--seed",
                 str(SIM.seed), "--log", str(log))
    with pytest.MonkeyPatch.context() as mp:  # keep the run's result for the tests
        mp.setattr(rig_interface, "run_rig", spy)
        assert cmd_rig_run(args) == 0, "rig-run --sim-rig reported no status"
    assert len(runs) == 1, "cmd_rig_run must call run_rig once"
    return runs[0], log


# ---------------------------------------------------------------------------------------------
# Scenario and plan


def test_rig_scenario(scn: Scenario) -> None:
    assert scn.gravity == (0.0, -9.81), "the rig is on Earth"
    assert len(scn.anchors) == 4 and len(set(scn.start_stance)) == 4, "four fixed anchors"
    inner = np.array([[-0.8, -0.75], [0.8, 0.75]])  # the frame's inside
    goal = np.array(scn.goal_position)
    assert np.all((inner[0] < goal) & (goal < inner[1])), f"goal {goal} outside the frame"
    check = check_poses(scn, scn.stance(scn.start_stance), np.array(scn.start_pose))
    assert check.feasible[0], "load_scenario accepted an infeasible start"


def test_rig_plan_is_a_feasible_straight_line(scn: Scenario, plan: dict[str, Any]) -> None:
    assert plan["success"], plan["reason"]
    (phase,) = plan["phases"]
    assert phase["kind"] == "body" and phase["stance"] == list(scn.start_stance)
    poses = np.array([s["pose"] for s in phase["steps"]])
    goal = np.array([*scn.goal_position, scn.start_pose[2]])
    np.testing.assert_allclose(poses[0], scn.start_pose, atol=1e-12, err_msg="first pose")
    np.testing.assert_allclose(poses[-1], goal, atol=1e-12, err_msg="last pose")
    along = geometry.cross2(poses[:, :2] - poses[0, :2], goal[:2] - poses[0, :2])
    np.testing.assert_allclose(along, 0.0, atol=1e-12, err_msg="poses leave the straight line")
    times = np.array([s["t"] for s in phase["steps"]])
    assert np.all(np.diff(times) > 0), f"times must increase: {times}"
    check = check_poses(scn, scn.stance(phase["stance"]), poses)
    assert check.feasible.all(), f"infeasible poses: {np.flatnonzero(~check.feasible)}"
    p_success = np.array([s["p_success"] for s in phase["steps"]])
    assert np.all(p_success >= scn.robot.p_min), f"P below p_min: {p_success.min()}"
    assert plan["p_min"] == pytest.approx(p_success.min(), abs=1e-12), "p_min"


def test_rig_plan_reports_an_infeasible_line(scn: Scenario) -> None:
    far = np.array([0.5, 0.0, 0.0])  # far off centre: no tensions balance the moment
    plan = rig_plan(scn, goal_pose=far, num_steps=5)
    assert not plan["success"] and "pose" in plan["reason"], plan["reason"]
    assert plan["p_min"] is None, "a failed plan has no p_min"


# ---------------------------------------------------------------------------------------------
# The simulated rig, without LCM


def command(utime: int, lengths: np.ndarray, tensions: np.ndarray) -> rig_command_t:
    msg = rig_command_t()
    msg.utime, msg.boom_length, msg.tension_setpoint = utime, lengths, tensions
    return msg


def test_simulator_without_noise_reproduces_the_plan(scn: Scenario,
                                                     plan: dict[str, Any]) -> None:
    """Noise-free: load cells read the setpoints, hinges the boom directions, and the monitor
    gives back the plan's own probabilities."""
    phase = body_phase(plan, 0)
    stance = phase.stance
    quiet = RigSimConfig(force_noise=0.0, hinge_noise=0.0)
    rig = RigSimulator(scn.robot, stance.positions, np.array(scn.start_pose), quiet)
    monitor = GraspMonitor(stance)
    context = monitor.CreateDefaultContext()
    for step in plan["phases"][0]["steps"]:
        pose = np.array(step["pose"])
        geo = geometry.boom_geometry(scn.robot, pose, stance.positions)
        status = rig.handle(command(round(step["t"] * 1e6), geo.length[0], step["tension"]))
        np.testing.assert_allclose(rig.pose, pose, atol=1e-9, err_msg="fitted pose")
        np.testing.assert_allclose(status.load_cell_force, step["tension"], atol=1e-6,
                                   err_msg=f"forces at t = {step['t']}")
        monitor.status_port.FixValue(context, status)
        psi = geometry.pull_angles(geo.u, stance.normals)[0]
        np.testing.assert_allclose(monitor.pull_angle_port.Eval(context), psi, atol=1e-9,
                                   err_msg="pull angle from the hinge angle")
        np.testing.assert_allclose(monitor.p_grasp_port.Eval(context), step["p_grasp"],
                                   atol=1e-7, err_msg=f"p_grasp at t = {step['t']}")


def test_simulator_rate_limit_and_stretch(scn: Scenario) -> None:
    """A winch commanded to pay out 0.1 m at once moves winch_speed * dt per step; the booms
    that are stretched meanwhile pull harder than their setpoints, and none pushes."""
    stance = scn.stance(scn.start_stance)
    pose = np.array(scn.start_pose)
    lengths = geometry.boom_geometry(scn.robot, pose, stance.positions).length[0]
    setpoints = np.array([3.0, 3.0, 1.0, 1.0])
    cfg = RigSimConfig(winch_speed=0.2, stiffness=100.0, force_noise=0.0, hinge_noise=0.0)
    rig = RigSimulator(scn.robot, stance.positions, pose, cfg)
    rig.handle(command(0, lengths, setpoints))
    target = lengths + np.array([0.1, 0.0, 0.0, 0.0])
    previous = lengths
    for k in range(1, 8):
        status = rig.handle(command(k * 100_000, target, setpoints))
        moved = np.asarray(status.winch_length) - previous
        expected = np.minimum(0.02, target - previous)  # 0.2 m/s * 0.1 s per command
        np.testing.assert_allclose(moved, expected, atol=1e-12, err_msg=f"winch step {k}")
        previous = np.asarray(status.winch_length)
        force = np.asarray(status.load_cell_force)
        assert np.all(force >= 0), f"a boom pushes: {force}"
        geo = geometry.boom_geometry(scn.robot, rig.pose, stance.positions)
        stretch = geo.length[0] - previous
        np.testing.assert_allclose(force, np.maximum(0, setpoints + 100.0 * stretch),
                                   atol=1e-9, err_msg="tension = setpoint + k * stretch")
    # Four lengths for three pose coordinates: the fit leaves some booms stretched.
    assert np.abs(stretch).max() > 1e-4, "four inconsistent lengths must stretch some boom"


def test_fit_pose_recovers_a_pose(scn: Scenario) -> None:
    stance = scn.stance(scn.start_stance)
    truth = np.array([0.05, -0.03, 0.04])
    lengths = geometry.boom_geometry(scn.robot, truth, stance.positions).length[0]
    found = fit_pose(scn.robot, stance.positions, lengths, np.array(scn.start_pose))
    np.testing.assert_allclose(found, truth, atol=1e-9, err_msg="Gauss-Newton pose")


def test_simulator_noise_is_seeded(scn: Scenario) -> None:
    stance = scn.stance(scn.start_stance)
    pose = np.array(scn.start_pose)
    cmd = command(0, geometry.boom_geometry(scn.robot, pose, stance.positions).length[0],
                  [3.0, 3.0, 1.0, 1.0])

    def reading(seed: int) -> tuple[float, ...]:
        rig = RigSimulator(scn.robot, stance.positions, pose, RigSimConfig(seed=seed))
        return tuple(rig.handle(cmd).load_cell_force)

    assert reading(3) == reading(3), "same seed, same noise"
    assert reading(3) != reading(4), "another seed, other noise"


# ---------------------------------------------------------------------------------------------
# A full run on memq://


def test_run_uses_the_in_process_bus(sim_run: tuple[RigRun, Path]) -> None:
    run, _ = sim_run
    assert RigLcmConfig().url == "memq://", "the default bus must be in-process"
    assert parse("rig-run", "p.json").lcm_url == "memq://", "the CLI default must be memq://"
    assert run.lcm_url.startswith("memq://") and "udpm" not in run.lcm_url, run.lcm_url


def test_log_holds_commands_and_statuses_in_time_order(sim_run: tuple[RigRun, Path],
                                                       plan: dict[str, Any]) -> None:
    run, log = sim_run
    cfg = RigLcmConfig()
    events = [(e.channel, e.timestamp, e.data) for e in lcm.EventLog(str(log), "r")]
    assert events[0][0] == cfg.setup_channel, "the log starts with the setup message"
    stamps = np.array([t for _, t, _ in events])
    assert np.all(np.diff(stamps) >= 0), "log events out of time order"
    commands = [rig_command_t.decode(d) for c, _, d in events if c == cfg.command_channel]
    statuses = [rig_status_t.decode(d) for c, _, d in events if c == cfg.status_channel]
    duration = plan["phases"][0]["steps"][-1]["t"] - plan["phases"][0]["steps"][0]["t"]
    expected = int(np.floor(duration / cfg.period + 1e-9)) + 1
    assert len(commands) == len(statuses) == expected == run.commands == run.statuses, (
        f"{len(commands)} commands, {len(statuses)} statuses; expected {expected} each")
    assert [c.utime for c in commands] == [s.utime for s in statuses], "a status per command"
    assert all(e.timestamp == rig_command_t.decode(e.data).utime for e in lcm.EventLog(
        str(log), "r") if e.channel == cfg.command_channel), "events stamped with their utime"
    for a, b in zip(events[1::2], events[2::2], strict=True):
        assert (a[0], b[0]) == (cfg.command_channel, cfg.status_channel), "command, status"


def test_measured_tensions_track_the_plan(sim_run: tuple[RigRun, Path],
                                          plan: dict[str, Any]) -> None:
    _, log = sim_run
    phase = body_phase(plan, 0)
    rec = replay_log(log).replay
    planned = np.array([phase.tension.value(t).ravel() for t in rec.time])
    error = rec.force - planned
    sigma = SIM.force_noise
    worst = np.abs(error).max()
    assert worst <= NOISE_SIGMAS * sigma, f"max |measured - planned| {worst:.3f} N"
    bound = 4 * sigma / np.sqrt(len(rec.time))
    assert np.all(np.abs(error.mean(axis=0)) <= bound), f"biased: {error.mean(axis=0)}"
    assert error.std() > 0.5 * sigma, "the load cells must be noisy (seeded)"


def test_replay_equals_live(sim_run: tuple[RigRun, Path]) -> None:
    run, log = sim_run
    first, second = replay_log(log), replay_log(log)
    assert len(run.live.time) == run.statuses, "the live monitor missed a status"
    for name in ("time", "p_grasp", "pull_angle", "force"):
        live, replayed = getattr(run.live, name), getattr(first.replay, name)
        np.testing.assert_array_equal(replayed, live, err_msg=f"replay != live: {name}")
        np.testing.assert_array_equal(getattr(second.replay, name), replayed,
                                      err_msg=f"two replays differ: {name}")
    p = run.live.p_grasp
    assert np.all((p > 0) & (p <= 1)), "probabilities in (0, 1]"
    assert np.ptp(p, axis=0).max() > 0.01, "the movement must change some grasp's probability"


def test_replay_and_report_commands(sim_run: tuple[RigRun, Path],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    run, log = sim_run
    assert cmd_rig_replay(parse("rig-replay", str(log))) == 0
    out = capsys.readouterr().out
    for i in range(4):
        k = int(run.live.p_grasp[:, i].argmin())
        assert f"boom {i}" in out and f"min P = {run.live.p_grasp[k, i]:.5f}" in out, out
    figure = log.parent / "fig7.png"
    assert cmd_rig_report(parse("rig-report", str(log), "-o", str(figure))) == 0
    data = figure.read_bytes()
    assert len(data) > 10_000 and data.startswith(b"\x89PNG\r\n\x1a\n"), "not a PNG figure"


def test_a_setup_not_first_or_twice_is_refused(sim_run: tuple[RigRun, Path],
                                               tmp_path: Path) -> None:
    """The setup comes once, first: a second one could swap the scenario mid-log, and one that
    comes last was read as if first; both are refused naming the event."""
    _, log = sim_run
    events = list(lcm.EventLog(str(log), "r"))
    setup = events[0]

    def write(name: str, order: list) -> Path:
        path = tmp_path / name
        out = lcm.EventLog(str(path), "w", overwrite=True)
        for e in order:
            out.write_event(e.timestamp, e.channel, e.data)
        out.close()
        return path

    twice = write("twice.lcm", [*events[:3], setup, *events[3:]])
    last = write("last.lcm", [*events[1:], setup])
    with pytest.raises(RbpInputError, match=r"RIG_SETUP: event 3: a second setup message"):
        replay_log(twice)
    with pytest.raises(RbpInputError, match=rf"RIG_SETUP: event {len(events) - 1}: the setup "
                                            "message must be the log's first event"):
        replay_log(last)
    assert cmd_rig_replay(parse("rig-replay", str(write("same.lcm", events)))) == 0


def test_run_without_a_rig_receives_nothing(scn: Scenario, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Nobody answers on this memq bus: the run ends on time (real time, 1 s) and says so."""
    nearby = np.array(scn.start_pose) + np.array([0.005, 0.0, 0.0])
    path = tmp_path / "short.json"
    path.write_text(json.dumps(rig_plan(scn, goal_pose=nearby, num_steps=2)))
    log = tmp_path / "alone.lcm"
    assert cmd_rig_run(parse("rig-run", str(path), "--log", str(log), "--period", "0.5")) == 1
    assert "no status received" in capsys.readouterr().out
    channels = [e.channel for e in lcm.EventLog(str(log), "r")]
    assert channels.count("RIG_STATUS") == 0 and channels.count("RIG_COMMAND") == 3, channels


# ---------------------------------------------------------------------------------------------
# Mistakes


def with_reach_phase(plan: dict[str, Any]) -> dict[str, Any]:
    plan = copy.deepcopy(plan)
    body = plan["phases"][0]
    step = copy.deepcopy(body["steps"][-1])
    step.update(tension=[None, *step["tension"][1:]], p_grasp=[None, *step["p_grasp"][1:]],
                free_tip=[0.45, 0.75], shoulder_torque=0.0)
    plan["phases"].append({"kind": "reach", "stance": [None, *body["stance"][1:]],
                           "free_boom": 0, "from_anchor": body["stance"][0],
                           "to_anchor": body["stance"][0], "steps": [step]})
    return plan


@pytest.mark.parametrize(("case", "field"), [
    ("missing", "(file)"),
    ("not json", "line 1, column 2"),  # a syntax error names its place
    ("schema", "phases[0].steps[0].pose"),
    ("phase out of range", "phases[5]"),
    ("negative phase", "phases[-1]"),
    ("reach phase", "phases[1].kind"),
    ("unknown anchor", "phases[0].stance[2]"),
])
def test_bad_plan_input(case: str, field: str, plan: dict[str, Any], tmp_path: Path,
                        capsys: pytest.CaptureFixture[str]) -> None:
    """The rig's own reading of a plan (behind the verifier, which --no-verify skips)."""
    path = tmp_path / "plan.json"
    phase = {"phase out of range": "5", "negative phase": "-1", "reach phase": "1"}.get(case, "0")
    if case == "not json":
        path.write_text("{not json")
    elif case in ("schema", "unknown anchor"):
        bad = copy.deepcopy(plan)
        if case == "schema":
            bad["phases"][0]["steps"][0]["pose"] = [0.0, 0.0]
        else:
            bad["phases"][0]["stance"][2] = "nowhere"
        path.write_text(json.dumps(bad))
    elif case != "missing":
        path.write_text(json.dumps(with_reach_phase(plan)))
    log = tmp_path / "never.lcm"
    with pytest.raises(UserError) as err:
        cmd_rig_run(parse("rig-run", str(path), "--phase", phase, "--sim-rig", "--log",
                          str(log), "--no-verify"))
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: {field}:"), message
    assert not log.exists(), "a refused run must not write a log"
    # --no-verify warns only once the plan is accepted: a refusal is its one line
    assert "WARNING" not in capsys.readouterr().err


@pytest.mark.parametrize("fault", ["reach phase", "moved pose", "goal", "stamped then edited"])
def test_a_wrong_plan_is_refused_before_any_lcm_traffic(
        fault: str, plan: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """rig-run verifies the plan first: exit 1, the verifier's message, and no run at all."""
    import systems.rig_interface as rig_interface
    from planning.plan_file import stamp

    bad = copy.deepcopy(plan)
    if fault == "reach phase":
        bad = with_reach_phase(plan)
    elif fault == "moved pose":
        bad["phases"][0]["steps"][3]["pose"][0] += 0.05
    elif fault == "goal":
        bad["scenario"]["goal"]["position"][1] += 1.0
    else:  # a stamp does not survive an edit
        bad = stamp(plan)
        bad["phases"][0]["steps"][3]["tension"][0] += 1.0
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(bad))

    def no_run(*_args, **_kwargs):
        raise AssertionError("run_rig called for a plan that fails verification")

    monkeypatch.setattr(rig_interface, "run_rig", no_run)
    log = tmp_path / "never.lcm"
    assert cmd_rig_run(parse("rig-run", str(path), "--sim-rig", "--log", str(log))) == 1
    err = capsys.readouterr().err
    assert "fails verification" in err and f"{path}: phases[" in err, err
    assert not log.exists(), "a refused run must not write a log"


def test_a_stamped_plan_is_not_verified_again(plan: dict[str, Any], tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    import planning.check
    from planning.plan_file import stamp
    from rbp.commands.common import refuse_wrong_plan

    def no_check(*_args, **_kwargs):
        raise AssertionError("a plan with a valid stamp was verified again")

    monkeypatch.setattr(planning.check, "check_plan", no_check)
    assert refuse_wrong_plan(stamp(plan), tmp_path / "plan.json") is False


def test_sim_rig_refuses_a_network_url(plan_file: Path, tmp_path: Path) -> None:
    url = "udpm://239.255.76.67:7667?ttl=0"
    with pytest.raises(UserError, match=r"^--lcm-url: .*memq://"):
        cmd_rig_run(parse("rig-run", str(plan_file), "--sim-rig", "--lcm-url", url, "--log",
                          str(tmp_path / "x.lcm")))


def test_rig_run_checks_its_url_and_log_before_the_run(plan_file: Path, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """An LCM URL of no provider (garbage:// failed after the 9 s verification with LCM's own
    "Error:" line) and a --log that is a folder (the whole run, then "/.tmp.XXXX.tmp: Is a
    directory") are refused before the plan is read."""
    import rbp.commands.common

    def never(*_args, **_kwargs):
        raise AssertionError("the plan was read before the arguments were checked")

    monkeypatch.setattr(rbp.commands.common, "read_plan", never)
    log = str(tmp_path / "x.lcm")
    for url in ("garbage://x", "memq", "udpm:/239.255.76.67"):
        with pytest.raises(UserError, match=rf"^--lcm-url: '{re.escape(url)}' is not an LCM URL"):
            cmd_rig_run(parse("rig-run", str(plan_file), "--lcm-url", url, "--log", log))
    with pytest.raises(UserError, match=f"^{re.escape(str(tmp_path))}: --log: is a directory"):
        cmd_rig_run(parse("rig-run", str(plan_file), "--sim-rig", "--log", str(tmp_path)))


@pytest.mark.parametrize(("url", "words"), [
    ("udpm://999.1.1.1:99999", "'999.1.1.1' is not an IPv4 address"),
    ("udpm://10.0.0.1:7667", "'10.0.0.1' is not a multicast address"),
    ("udpm://239.255.76.67:0", "the port must be a whole number from 1 to 65535, got '0'"),
    ("udpm://239.255.76.67:7667?ttl=abc", "ttl must be a whole number from 0 to 255"),
    ("udpm://239.255.76.67:7667?foo=1", "unknown option 'foo=1'"),
    ("memq://x", "memq:// takes no address or options"),
    ("tcpq://:5", "expected tcpq://HOST:PORT"),
    ("file:///dev/zero?mode=r", "a log file is not a bus"),
    ("tcpq://127.0.0.1:1", "LCM cannot open it: LCM tcpq: connecting"),
])
def test_rig_run_checks_the_whole_url(url: str, words: str, plan_file: Path, tmp_path: Path,
                                      monkeypatch: pytest.MonkeyPatch,
                                      capfd: pytest.CaptureFixture[str]) -> None:
    """A URL of a known provider LCM cannot use is refused in one line before the plan is
    read: udpm://999.1.1.1:99999 printed LCM's "Error: Bad multicast IP address" and then sent
    81 commands; tcpq:// printed "LCM tcpq: connecting..." and more, file:// read a log."""
    import rbp.commands.common

    def never(*_args, **_kwargs):
        raise AssertionError("the plan was read before the URL was checked")

    monkeypatch.setattr(rbp.commands.common, "read_plan", never)
    with pytest.raises(UserError, match=rf"^--lcm-url: '{re.escape(url)}': {re.escape(words)}"):
        cmd_rig_run(parse("rig-run", str(plan_file), "--lcm-url", url, "--log",
                          str(tmp_path / "x.lcm")))
    assert capfd.readouterr().err == "", "LCM's own messages reached stderr"


def test_rig_run_refuses_a_bus_lcm_cannot_open_before_sending(plan: dict[str, Any],
                                                              tmp_path: Path) -> None:
    """run_rig opens the bus first: a URL LCM refuses sends no command and writes no log."""
    with pytest.raises(RbpInputError, match=r"--lcm-url: 'tcpq://127\.0\.0\.1:1': LCM cannot"):
        run_rig(plan, 0, RigLcmConfig(url="tcpq://127.0.0.1:1"), tmp_path / "x.lcm")
    assert not (tmp_path / "x.lcm").exists()


@pytest.mark.parametrize("command", ["rig-replay", "rig-report"])
def test_bad_log_input(command: str, tmp_path: Path) -> None:
    handler = {"rig-replay": cmd_rig_replay, "rig-report": cmd_rig_report}[command]
    extra = ["-o", str(tmp_path / "f.png")] if command == "rig-report" else []
    missing = tmp_path / "missing.lcm"
    with pytest.raises(UserError, match=f"^{re.escape(f'{missing}: (file): no such file')}$"):
        handler(parse(command, str(missing), *extra))
    junk = tmp_path / "junk.lcm"
    junk.write_text("not an LCM log\n" * 10)
    with pytest.raises(UserError, match=f"^{re.escape(f'{junk}: (file): event 0 is damaged')}"):
        handler(parse(command, str(junk), *extra))
    assert not (tmp_path / "f.png").exists(), "no figure from a bad log"


def test_rbp_plan_plans_the_rig(tmp_path) -> None:
    """The rig's goal is held in its start stance: a route of no regrasp, whose cost and proven
    lower bound are both 0 (the anytime search's progress divided one by the other)."""
    from tests.cli_helpers import run_rbp

    result = run_rbp("plan", "rig", "-o", "rig.json", "--no-pictures", cwd=tmp_path)
    assert result.returncode == 0, f"exit {result.returncode}: {result.stderr[-2000:]}"
    assert "Traceback" not in result.stderr, result.stderr
    assert "route optimal" in result.stdout, result.stdout
