"""Running a body phase of a plan on the rig over LCM, and reading back what the rig measured.

Two Drake systems talk to the rig through `DrakeLcm`: `RigCommandSource` streams commands
(boom lengths from the planned pose, tension setpoints from the plan) to an
`LcmPublisherSystem`, and `GraspMonitor` turns each status an `LcmSubscriberSystem` receives
into each anchor's probability of grasp maintenance (the paper's Fig. 7) from the measured
load-cell force and hinge angle. `run_rig` executes one phase and logs every message to an LCM
log; `replay_log` computes the same monitor's outputs for a log, and `report_figure` draws
it (both in `systems.rig_log`, which reads a log without importing Drake).

Because this drives hardware: commands are clamped to the robot's boom-length and tension
limits, their change from one command to the next is bounded (`max_length_rate`,
`max_tension_rate`: no plan can command a jump), a non-finite command is refused (the last
safe one is repeated), the command holds still when no status has come back for
`status_timeout` (all in `systems.rig_safety`), and a status that does not decode or is out
of range is logged as received but ignored (`StatusFilter`, in `systems.rig_messages` with the
rest of the LCM side, keeps the last good one).

Python LeafSystems are never freed in pydrake 1.51 (STACK.md section 5): `run_rig` builds its
diagram once per run.
"""


from __future__ import annotations

import json
import math
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.trajectories import PiecewisePolynomial

from planning.plan_model import Plan, plan_of, plan_scenario
from planning.verify_between import step_motion
from rb_drake import geometry, grasp
from rb_drake.files import atomic_write, output_target
from rb_drake.scenario import Scenario, ScenarioError
from rb_drake.stance import Stance
from systems.lcm_url import open_problem, quietly
from systems.reachbot_lcm import rig_command_t, rig_setup_t, rig_status_t
from systems.rig import RigSimConfig, RigSimulator, RigSimulatorLcm
from systems.rig_log import (
    MAX_LOG_EVENTS,
    MEMQ,
    GraspRecord,
    RigInputError,
    RigLcmConfig,
)
from systems.rig_messages import LogWriter, RawSerializer, StatusFilter
from systems.rig_safety import RigCommandSource, SafetyReport

# ---------------------------------------------------------------------------------------------
# The phase to execute


class BodyPhase(NamedTuple):
    """A body phase of a plan as trajectories in plan time (pose and tensions, linear in t
    between steps: `planning.between.step_motion`)."""

    scenario: Scenario
    stance_ids: tuple[str, ...]
    pose: PiecewisePolynomial     # (3,) [x, y, phi]
    tension: PiecewisePolynomial  # (4,) N
    start_time: float
    end_time: float
    # booms released or attached in the phase (ramp steps): the rig may command them to 0 N,
    # where their gripper lets go or takes hold (rules `release`, `attach`)
    ramped: tuple[int, ...] = ()

    @property
    def stance(self) -> Stance:
        return self.scenario.stance(self.stance_ids)


def body_phase(plan: Plan | dict[str, Any], index: int) -> BodyPhase:
    """Phase `index` of a plan (a Plan, or its schema-valid file object); raises
    RigInputError."""
    plan = plan_of(plan)
    phases = plan.phases
    if not 0 <= index < len(phases):
        have = ("no phases" if not phases else "1 phase (0)" if len(phases) == 1
                else f"{len(phases)} phases (0..{len(phases) - 1})")
        raise RigInputError(f"phases[{index}]", f"no such phase; the plan has {have}")
    phase = phases[index]
    where = f"phases[{index}]"
    if phase.kind != "body":
        raise RigInputError(f"{where}.kind", f"a {phase.kind} phase; the rig runs body "
                            "phases only (its anchors are fixed)")
    steps = phase.steps
    times = np.array([s.t for s in steps], dtype=float)
    if np.any(np.diff(times) <= 0):
        k = int(np.flatnonzero(np.diff(times) <= 0)[0]) + 1
        raise RigInputError(f"{where}.steps[{k}].t", "times must increase from step to step")
    for k, s in enumerate(steps):
        if any(f is None for f in s.tension):
            raise RigInputError(f"{where}.steps[{k}].tension", "a body phase needs 4 tensions")
    try:
        scn = plan_scenario(plan, "plan scenario")
    except ScenarioError as e:
        raise RigInputError(e.field, e.reason) from None
    for i, anchor in enumerate(phase.stance):
        if anchor not in scn.anchor_index:
            raise RigInputError(f"{where}.stance[{i}]", f"{anchor!r} is not an anchor of the "
                                "plan's scenario")
    poses = np.array([s.pose for s in steps], dtype=float).T
    tensions = np.array([s.tension for s in steps], dtype=float).T
    # Later non-finite steps are refused at run time (the last safe command is repeated);
    # the first one has nothing safe before it.
    if not (np.all(np.isfinite(poses[:, 0])) and np.all(np.isfinite(tensions[:, 0]))):
        raise RigInputError(f"{where}.steps[0]", "the first pose and tensions must be finite")
    # the motion between steps that `rbp check` verifies (rule `between`); one step holds
    # still for a second
    pose, tension = step_motion(times, poses.T), step_motion(times, tensions.T)
    ramped = tuple(sorted({s.ramp.boom for s in steps if s.ramp is not None}))
    return BodyPhase(scn, tuple(str(a) for a in phase.stance),  # each checked above
                     pose, tension, float(pose.start_time()), float(pose.end_time()), ramped)


def rate_problem(phase: BodyPhase, config: RigLcmConfig, index: int) -> RigInputError | None:
    """None if every command of the phase's motion (linear between steps, as `RigCommandSource`
    interpolates it) changes within the rig's `max_tension_rate` and `max_length_rate`, else
    the fastest step. Past them the rig's guard slows the commands, and the rig would fly a
    motion other than the one `rbp check` verified, so `rbp rig-run` refuses such a phase."""
    times = np.asarray(phase.tension.get_segment_times(), dtype=float)
    gaps = np.diff(times)
    if not len(gaps):
        return None
    tensions = phase.tension.vector_values(times).T  # (K, 4)
    # a released or attached boom's command is clamped as the rig clamps it (down to 0 N)
    low = np.array([0.0 if i in phase.ramped else phase.scenario.robot.boom_tension[0]
                    for i in range(4)])
    tensions = np.clip(tensions, low, phase.scenario.robot.boom_tension[1])
    tension_rate = np.abs(np.diff(tensions, axis=0)) / gaps[:, None]  # (K-1, 4) N/s
    # lengths are nonlinear in the pose: each interval sampled (a command every `period` at
    # most; 16 samples bound a boom's rate to well within 1 % at the planner's steps)
    sub = max(2, min(16, math.ceil(float(gaps.max()) / config.period)))
    u = np.linspace(0.0, 1.0, sub + 1)
    t = (times[:-1, None] + gaps[:, None] * u[None, :]).ravel()
    poses = phase.pose.vector_values(t).T  # (samples, 3), in one call
    length = geometry.boom_geometry(phase.scenario.robot, poses,
                                    phase.stance.positions).length.reshape(len(gaps), sub + 1, 4)
    length = np.clip(length, *phase.scenario.robot.boom_length)
    length_rate = (np.abs(np.diff(length, axis=1)).max(axis=1)
                   / (gaps[:, None] / sub))  # (K-1, 4) m/s
    slack = 1.0 + 1e-6  # round-off, never a slowed command
    for rate, limit, what, unit, name in (
            (tension_rate, config.max_tension_rate, "tension", "N/s", "max_tension_rate"),
            (length_rate, config.max_length_rate, "length", "m/s", "max_length_rate")):
        over = rate > limit * slack
        if over.any():
            k, boom = np.unravel_index(int(np.argmax(np.where(over, rate, -1.0))), rate.shape)
            more = int(over.any(axis=1).sum()) - 1
            also = f" (and {more} more steps)" if more else ""
            return RigInputError(
                f"phases[{index}].steps[{k + 1}]",
                f"boom {boom}'s {what} changes at {rate[k, boom]:.4g} {unit} from the step "
                f"before{also}, faster than the rig's {name} of {limit:g} {unit}: the rig "
                "would slow its commands and fly a motion rbp check did not verify (a lighter "
                "robot, weaker gravity or a slower plan, --dt, keeps within it)")
    return None


# ---------------------------------------------------------------------------------------------
# The grasp monitor and the diagram


class GraspMonitor(LeafSystem):
    """Input `status` (rig_status_t) -> outputs `p_grasp` (4) and `pull_angle` (4, rad).

    The pull angle is the hinge angle (anchor -> robot) measured from the anchor's outward
    normal; the probability is the limit surface's at the measured load-cell force.
    """

    def __init__(self, stance: Stance):
        super().__init__()
        self._stance = stance
        self._normal_angle = np.arctan2(stance.normals[:, 1], stance.normals[:, 0])
        self.status_port = self.DeclareAbstractInputPort(
            "status", AbstractValue.Make(rig_status_t()))
        self.p_grasp_port = self.DeclareVectorOutputPort("p_grasp", 4, self._calc_p_grasp)
        self.pull_angle_port = self.DeclareVectorOutputPort("pull_angle", 4,
                                                            self._calc_pull_angle)

    def _pull_angle(self, context) -> np.ndarray:
        status = self.status_port.Eval(context)
        return geometry.wrap_angle(np.asarray(status.hinge_angle) - self._normal_angle)

    def _calc_pull_angle(self, context, output) -> None:
        output.SetFromVector(self._pull_angle(context))

    def _calc_p_grasp(self, context, output) -> None:
        force = np.asarray(self.status_port.Eval(context).load_cell_force)
        s = self._stance
        output.SetFromVector(grasp.prob(force, self._pull_angle(context), s.f_normal,
                                        s.f_lateral, s.sigma_normal, s.sigma_lateral))


class RigDiagram(NamedTuple):
    diagram: Diagram
    source: RigCommandSource
    subscriber: LcmSubscriberSystem
    status_filter: StatusFilter
    monitor: GraspMonitor


def build_rig_diagram(phase: BodyPhase, bus: DrakeLcm, config: RigLcmConfig) -> RigDiagram:
    """Command source -> LCM publisher; LCM subscriber (raw bytes) -> status filter -> grasp
    monitor, and the filter's last status time back to the source; the bus pump."""
    builder = DiagramBuilder()
    builder.AddSystem(LcmInterfaceSystem(bus))
    scn = phase.scenario
    source = builder.AddNamedSystem("command_source", RigCommandSource(
        scn.robot, phase.stance.positions, phase.pose, phase.tension, phase.start_time,
        config.period, config.status_timeout, config.max_length_rate, config.max_tension_rate,
        phase.ramped))
    publisher = builder.AddNamedSystem("command_publisher", LcmPublisherSystem.Make(
        channel=config.command_channel, lcm_type=rig_command_t, lcm=bus,
        publish_period=config.period))
    subscriber = builder.AddNamedSystem("status_subscriber", LcmSubscriberSystem(
        channel=config.status_channel, serializer=RawSerializer(), lcm=bus))
    status_filter = builder.AddNamedSystem("status_filter", StatusFilter(scn.robot))
    monitor = builder.AddNamedSystem("grasp_monitor", GraspMonitor(phase.stance))
    builder.Connect(source.command_port, publisher.get_input_port())
    builder.Connect(subscriber.get_output_port(), status_filter.raw_port)
    builder.Connect(status_filter.status_port, monitor.status_port)
    builder.Connect(status_filter.last_status_time_port, source.last_status_time_port)
    return RigDiagram(builder.Build(), source, subscriber, status_filter, monitor)


# ---------------------------------------------------------------------------------------------
# Running, logging, replaying


class RigRun(NamedTuple):
    live: GraspRecord
    commands: int           # published
    statuses: int           # received
    lcm_url: str
    log: Path
    safety: SafetyReport = SafetyReport(0, 0, 0, 0)


def _log_scratch(log: str | Path) -> tempfile.TemporaryDirectory[str]:
    """The folder the log is written to during the run (then copied to `log` atomically): a
    temporary one, or, with no usable temporary folder (TMPDIR), one beside `log`, whose folder
    was checked writable (it was "error: (file): No usable temporary directory found")."""
    try:
        return tempfile.TemporaryDirectory(prefix="rig-log-")
    except OSError:
        pass
    folder = output_target(log).parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return tempfile.TemporaryDirectory(prefix=f".{Path(log).name}.", suffix=".tmp",
                                           dir=folder)
    except OSError as e:
        raise OSError(e.errno, f"cannot make a folder for the log during the run "
                      f"({e.strerror or e})", str(log)) from None


def run_rig(plan: dict[str, Any], phase_index: int, config: RigLcmConfig, log: str | Path,
            sim_rig: RigSimConfig | None = None, plan_source: str = "",
            accepted: Callable[[], None] | None = None, check_rates: bool = True) -> RigRun:
    """Execute body phase `phase_index` of `plan` against the rig on `config.url`.

    With `sim_rig`, the rig simulator answers on the same in-process bus and the run goes as
    fast as it can; otherwise the run keeps to real time for the hardware. The log (written
    atomically when the run ends) starts with a `rig_setup_t` naming the scenario and stance.
    `accepted` is called once the plan and options are accepted, before any command is sent.
    With `check_rates`, a phase the rig's rate bounds would slow is refused (`rate_problem`).
    """
    phase = body_phase(plan, phase_index)
    too_fast = rate_problem(phase, config, phase_index) if check_rates else None
    if too_fast is not None:
        raise too_fast
    check_log_size(phase, config.period)
    if sim_rig is not None and not config.url.startswith(MEMQ):
        raise RigInputError("--lcm-url", f"the simulated rig runs in-process on {MEMQ}, "
                            f"not on {config.url}")
    problem = open_problem(config.url)  # in one line, before any command is sent
    if problem:
        raise RigInputError("--lcm-url", f"{config.url!r}: {problem}")
    bus, said = quietly(lambda: DrakeLcm(config.url))  # tcpq:// says "connecting..."
    if bus is None:
        raise RigInputError("--lcm-url", f"{config.url!r}: LCM cannot open it: {said}")
    scratch = _log_scratch(log)  # before any command is sent
    if accepted is not None:
        accepted()
    if sim_rig is not None:
        start = phase.pose.value(phase.start_time).ravel()
        rig = RigSimulator(phase.scenario.robot, phase.stance.positions, start, sim_rig)
        RigSimulatorLcm(rig, bus, config.command_channel, config.status_channel)
    parts = build_rig_diagram(phase, bus, config)
    with scratch as tmp:
        partial = Path(tmp) / "run.lcm"
        writer = LogWriter(bus, config, partial)
        setup = rig_setup_t()
        setup.utime = round(phase.start_time * 1e6)
        setup.scenario_json = json.dumps(phase.scenario.to_dict(resolved=True))
        setup.stance = list(phase.stance_ids)
        # a file name that is not UTF-8 (its bytes as surrogates) cannot be encoded as is
        setup.plan_source = plan_source.encode(errors="backslashreplace").decode()
        writer.events.write_event(setup.utime, config.setup_channel, setup.encode())
        writer.utime = setup.utime

        live, safety = _simulate(parts, phase, config, realtime=sim_rig is None)
        writer.events.close()
        with partial.open("rb") as src:
            atomic_write(log, lambda f: shutil.copyfileobj(src, f))
    return RigRun(live, writer.counts[config.command_channel],
                  writer.counts[config.status_channel], bus.get_lcm_url(), Path(log), safety)


def check_log_size(phase: BodyPhase, period: float) -> None:
    """Refuse (RigInputError on --period), before any command is sent, a run whose log would
    hold more events than rig-replay and rig-report read (MAX_LOG_EVENTS): the setup, and a
    command and a status every period over the phase (as `_simulate` runs it)."""
    events = 1 + 2 * (last_command(phase, period) + 1)
    if events > MAX_LOG_EVENTS:
        # the least period whose run fits, rounded up to 0.1 ms
        duration = phase.end_time - phase.start_time
        least = math.ceil(duration / ((MAX_LOG_EVENTS - 3) // 2) * 1e4) / 1e4
        raise RigInputError("--period", f"{period:g} s over the phase's {duration:.6g} s "
                            f"would log {events:,} events, more than the {MAX_LOG_EVENTS:,} "
                            f"rbp rig-replay and rig-report read: use at least {least:g} s")


def last_command(phase: BodyPhase, period: float) -> int:
    """The index k of the run's last command, sent at k * period: the first at or after the
    phase's end, which commands its last step (the motion holds there). Commands stopped at
    the last k * period within the phase: --period 1 over a 2.8 s phase never commanded its
    last 0.8 s, the rig stopping short of the verified end pose."""
    return math.ceil((phase.end_time - phase.start_time) / period - 1e-9)


def _simulate(parts: RigDiagram, phase: BodyPhase, config: RigLcmConfig,
              realtime: bool) -> tuple[GraspRecord, SafetyReport]:
    """Advance through the phase, recording the monitor's output for each new good status."""
    simulator = Simulator(parts.diagram)
    if realtime:
        simulator.set_target_realtime_rate(1.0)
    root = simulator.get_mutable_context()
    filter_context = parts.status_filter.GetMyContextFromRoot(root)
    mon_context = parts.monitor.GetMyContextFromRoot(root)
    rows: list[tuple] = []
    good = [0]  # good statuses recorded so far

    def record(_context) -> EventStatus:
        memory = parts.status_filter.current(filter_context)
        if memory.good != good[0]:
            good[0] = memory.good
            msg = memory.status
            rows.append((msg.utime * 1e-6, parts.monitor.p_grasp_port.Eval(mon_context).copy(),
                         parts.monitor.pull_angle_port.Eval(mon_context).copy(),
                         np.asarray(msg.load_cell_force)))
        return EventStatus.Succeeded()

    simulator.set_monitor(record)
    simulator.Initialize()
    # Commands go out at k * period until one reaches the phase's end; the half period after
    # the last one lets its status come back and reach the monitor.
    simulator.AdvanceTo((last_command(phase, config.period) + 0.5) * config.period)
    commands = parts.source.memory(parts.source.GetMyContextFromRoot(root))
    bad = parts.status_filter.current(filter_context).bad
    return _record(rows), SafetyReport(commands.clamped, commands.refused, commands.held, bad,
                                       commands.rate_limited)


def _record(rows: list[tuple]) -> GraspRecord:
    if not rows:
        return GraspRecord(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4)), np.zeros((0, 4)))
    t, p, psi, f = zip(*rows, strict=True)
    return GraspRecord(np.array(t), np.array(p), np.array(psi), np.array(f))
