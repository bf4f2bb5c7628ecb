"""What keeps the rig's commands safe for the hardware: `RigCommandSource` clamps them to the
robot's boom-length and tension limits, bounds their change from one command to the next
(`max_length_rate`, `max_tension_rate`: no plan can command a jump), refuses a non-finite
command (the last safe one is repeated) and holds still when no status has come back for
`status_timeout`; `SafetyReport` says what these guards did in a run.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.trajectories import PiecewisePolynomial

from rb_drake import geometry
from rb_drake.params import RobotParams
from systems.reachbot_lcm import rig_command_t
from systems.rig_messages import RigLcmConfig

CLAMP_REPORT_TOL = 1e-9  # m or N: smaller corrections by the limit clamp are not counted


class CommandMemory(NamedTuple):
    """`RigCommandSource`'s state: the last command sent and what the guards did so far."""

    boom_length: np.ndarray | None  # (4,) m, of the last command sent (None before the first)
    tension: np.ndarray | None      # (4,) N
    refused: int = 0                # commands that were not finite: the last one repeated
    held: int = 0                   # commands held still because no status came back
    clamped: int = 0                # commands clamped to the boom limits
    rate_limited: int = 0           # commands whose change was cut to the rate bounds


class RigCommandSource(LeafSystem):
    """Input `last_status_time` (1, s of context time) -> output `command` (rig_command_t):
    the plan at plan time `time_offset` + context time, made safe for the hardware.

    Boom lengths are the shoulder-anchor distances at the planned pose; the tension setpoints
    are the plan's tensions, both interpolated linearly in time and clamped to the robot's
    `boom_length` and `boom_tension` limits (down to 0 N for the `ramped` booms, which a
    release or attach ramp takes to 0 N as verified); each then moves from the last command
    sent by at most `max_length_rate` x `period` (m) and `max_tension_rate` x `period` (N),
    so a jump in the plan becomes a ramp. A command with a NaN or inf is refused and the
    last one sent is repeated; so is the last one when no status came back for
    `status_timeout` (the rig holds still). The state (`CommandMemory`) changes only in the
    periodic update, which stores the command the publisher just sent.
    """

    def __init__(self, robot: RobotParams, anchors: np.ndarray, pose: PiecewisePolynomial,
                 tension: PiecewisePolynomial, time_offset: float = 0.0, period: float = 0.1,
                 status_timeout: float = float("inf"), max_length_rate: float = float("inf"),
                 max_tension_rate: float = float("inf"), ramped: Sequence[int] = ()):
        if not (np.all(np.isfinite(pose.value(time_offset)))
                and np.all(np.isfinite(tension.value(time_offset)))):
            raise ValueError("the first command must be finite: nothing safe comes before it")
        super().__init__()
        self._robot = robot
        self._anchors = np.asarray(anchors, dtype=float)
        self._pose = pose
        self._tension = tension
        self._time_offset = time_offset
        self._status_timeout = status_timeout
        self._max_step = (max_length_rate * period, max_tension_rate * period)  # m, N
        lo, hi = robot.boom_tension
        self._tension_low = np.array([0.0 if i in ramped else lo for i in range(4)])  # N
        self._tension_high = hi
        self._memory = self.DeclareAbstractState(AbstractValue.Make(CommandMemory(None, None)))
        self.last_status_time_port = self.DeclareVectorInputPort("last_status_time", 1)
        self.command_port = self.DeclareAbstractOutputPort(
            "command", lambda: AbstractValue.Make(rig_command_t()), self._calc_command,
            prerequisites_of_calc={self.all_sources_ticket()})
        # Stores what the publisher sent at the same period (publishing comes first).
        self.DeclareInitializationUnrestrictedUpdateEvent(self._remember)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._remember)

    def memory(self, context) -> CommandMemory:
        return context.get_abstract_state(self._memory).get_value()

    def _decide(self, context) -> tuple[np.ndarray, np.ndarray, str]:
        """(boom lengths, tensions, what happened: "ok", "clamped", "rate-limited", "refused"
        or "held")."""
        t = self._time_offset + context.get_time()
        memory = self.memory(context)
        if memory.boom_length is not None and self.last_status_time_port.HasValue(context):
            silence = context.get_time() - self.last_status_time_port.Eval(context)[0]
            if silence > self._status_timeout:
                assert memory.tension is not None  # stored with boom_length
                return memory.boom_length, memory.tension, "held"
        pose = self._pose.value(t).ravel()
        length = geometry.boom_geometry(self._robot, pose, self._anchors).length[0]
        tension = self._tension.value(t).ravel()
        if not (np.all(np.isfinite(length)) and np.all(np.isfinite(tension))):
            # the first one is finite (__init__ checks it), so a command was sent before
            assert memory.boom_length is not None and memory.tension is not None
            return memory.boom_length, memory.tension, "refused"
        safe_length = np.clip(length, *self._robot.boom_length)
        safe_tension = np.clip(tension, self._tension_low, self._tension_high)
        # A plan on a limit may miss it by round-off: that is not worth reporting.
        clamped = max(np.abs(safe_length - length).max(),
                      np.abs(safe_tension - tension).max()) > CLAMP_REPORT_TOL
        if memory.boom_length is None:  # the first command: the plan's start, nothing before
            return safe_length, safe_tension, "clamped" if clamped else "ok"
        # Both ends lie within the limits, so the ramp between them does too.
        dl, df = self._max_step
        ramp_length = memory.boom_length + np.clip(safe_length - memory.boom_length, -dl, dl)
        ramp_tension = memory.tension + np.clip(safe_tension - memory.tension, -df, df)
        limited = max(np.abs(ramp_length - safe_length).max(),
                      np.abs(ramp_tension - safe_tension).max()) > CLAMP_REPORT_TOL
        what = "rate-limited" if limited else "clamped" if clamped else "ok"
        return ramp_length, ramp_tension, what

    def _calc_command(self, context, output) -> None:
        length, tension, _ = self._decide(context)
        msg = rig_command_t()
        msg.utime = round((self._time_offset + context.get_time()) * 1e6)
        msg.boom_length = length
        msg.tension_setpoint = tension
        output.set_value(msg)

    def _remember(self, context, state) -> None:
        length, tension, what = self._decide(context)
        memory = self.memory(context)
        state.get_mutable_abstract_state(self._memory).set_value(CommandMemory(
            length.copy(), tension.copy(), memory.refused + (what == "refused"),
            memory.held + (what == "held"), memory.clamped + (what == "clamped"),
            memory.rate_limited + (what == "rate-limited")))


class SafetyReport(NamedTuple):
    """What the guards of a run did (counts of commands and statuses)."""

    clamped: int            # commands clamped to the boom-length or tension limits
    refused: int            # non-finite commands replaced by the last safe one
    held: int               # commands held still: no good status for status_timeout
    bad_statuses: int       # statuses ignored: undecodable or out of range
    rate_limited: int = 0   # commands whose change was cut to the rate bounds

    def messages(self, config: RigLcmConfig) -> list[str]:
        """One line per guard that acted, for the run's output."""
        lines = []
        if self.held:
            lines.append(f"  status timeout: no good status for {config.status_timeout:g} s; "
                         f"held the last safe setpoint for {self.held} commands")
        if self.refused:
            lines.append(f"  refused {self.refused} non-finite commands (repeated the last "
                         "safe one)")
        if self.clamped:
            lines.append(f"  clamped {self.clamped} commands to the boom limits")
        if self.rate_limited:
            lines.append(f"  slowed {self.rate_limited} commands to the rate bounds "
                         f"({config.max_length_rate:g} m/s, {config.max_tension_rate:g} N/s)")
        if self.bad_statuses:
            lines.append(f"  ignored {self.bad_statuses} bad statuses (kept in the log)")
        return lines
