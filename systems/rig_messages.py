"""The rig's side of LCM: where it is (`RigLcmConfig`, channels and timing), receiving its
status (`RawSerializer` hands the bytes on undecoded, `decode_status` decodes and range-checks
them, `StatusFilter` keeps the last good one) and logging every message (`LogWriter`).

A status that does not decode or is out of range is logged as received but ignored.
"""

from __future__ import annotations

import contextlib
import dataclasses
import struct
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import lcm
import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import LeafSystem
from pydrake.systems.lcm import SerializerInterface

from rb_drake.params import RobotParams
from systems.reachbot_lcm import rig_command_t, rig_status_t

MEMQ = "memq://"

# A log's events, at most: a rig run logs a command and a status each period (0.1 s), so this
# is over 2.5 hours of running, and replaying it takes seconds, not the minutes a log of
# millions of tiny events would.
MAX_LOG_EVENTS = 200_000
# An LCM event's header: sync word, event number, timestamp, channel and data lengths.
_EVENT_HEADER = struct.Struct(">Iqqii")
_LOG_SYNC = 0xEDA1DA01
MAX_CHANNEL_LENGTH = 255  # bytes; LCM's own channels are at most 63


@dataclasses.dataclass(frozen=True)
class RigLcmConfig:
    """Where the rig is on LCM. The default bus is in-process (`memq://`), never the network:
    pass a `udpm://` URL explicitly to reach the hardware."""

    url: str = MEMQ
    command_channel: str = "RIG_COMMAND"
    status_channel: str = "RIG_STATUS"
    setup_channel: str = "RIG_SETUP"
    period: float = 0.1  # s between commands
    status_timeout: float = 0.5  # s without a good status before the command holds still
    # The largest change of a command per second: the simulated winch's speed, 4x the boom
    # rates of the bundled plans (about 0.13 m/s); twice their tension rates (about 13 N/s).
    max_length_rate: float = 0.5    # m/s per boom
    max_tension_rate: float = 25.0  # N/s per boom


class FixedMessage(NamedTuple):
    """A message type whose encoding has one size, so a header scan can tell whether an event
    of its channel decodes: exactly `size` bytes beginning with its `fingerprint`."""

    name: str
    fingerprint: bytes
    size: int


def fixed_message(message_type: Any) -> FixedMessage:
    """The FixedMessage of an lcm-gen type without variable-length fields."""
    return FixedMessage(message_type.__name__, message_type._get_packed_fingerprint(),
                        len(message_type().encode()))


def scan_log(path: Path, fixed: Mapping[str, FixedMessage] | None = None
             ) -> tuple[str, str] | None:
    """None if every event header of the LCM log at `path` is sound, else (field, reason) for
    the first that is not (`read_log`)."""
    return read_log(path, (), fixed)[1]


LogEvent = tuple[int, str, bytes]  # (event number, channel, data)


def read_log(path: Path, channels: Collection[str], fixed: Mapping[str, FixedMessage] | None
             = None) -> tuple[list[LogEvent], tuple[str, str] | None]:
    """The events of `channels` in the LCM log at `path`, and None if every event header is
    sound, else (field, reason) for the first that is not: ("(file)", "event N: ..."), or
    (channel, "event N does not decode ...") for an event of a channel in `fixed` that is not
    its type's size and fingerprint (so a damaged last command is refused before rbp decodes
    the 200,000 events before it). Read here, from one read of the file (bounded by the input
    limit), not by lcm's reader: its C code trusts the header's lengths (a data length of
    2**31 - 1 crashes it) and prints its own complaints on stderr, its Python side fails on a
    channel name that is not UTF-8 and on a file name it cannot encode. A channel of another
    name (not UTF-8 either) is skipped, as a rig run's log of another system's messages."""
    by_name = {name.encode(): message for name, message in (fixed or {}).items()}
    wanted = {name.encode(): name for name in channels}
    with open(path, "rb") as f:
        buf = f.read()
    size, pos, number = len(buf), 0, 0
    events: list[LogEvent] = []
    while pos < size:
        if number >= MAX_LOG_EVENTS:
            return events, ("(file)", f"more than {MAX_LOG_EVENTS:,} events: longer than any "
                            "rig run rbp writes")
        bad = f"event {number} is damaged or not an LCM event:"
        if size - pos < _EVENT_HEADER.size:
            return events, ("(file)", f"{bad} a header of {size - pos} bytes, not "
                            f"{_EVENT_HEADER.size}")
        sync, _, _, channel, data = _EVENT_HEADER.unpack_from(buf, pos)
        if sync != _LOG_SYNC:
            return events, ("(file)", f"{bad} no LCM sync word (0x{sync:08x})")
        if not 0 < channel <= MAX_CHANNEL_LENGTH:
            return events, ("(file)", f"{bad} channel length {channel} is not 1 to "
                            f"{MAX_CHANNEL_LENGTH} bytes")
        start = pos + _EVENT_HEADER.size + channel
        if not 0 <= data <= size - start:
            return events, ("(file)", f"{bad} data length {data} is not 0 to the "
                            f"{max(size - start, 0)} bytes left in the file")
        name = buf[pos + _EVENT_HEADER.size:start]
        message = by_name.get(name)
        if message is not None and (data != message.size or buf[start:start + 8]
                                    != message.fingerprint):
            return events, (name.decode(), f"event {number} does not decode as "
                            f"{message.name}: the log is damaged or not rbp's")
        if name in wanted:
            events.append((number, wanted[name], buf[start:start + data]))
        pos = start + data
        number += 1
    return events, None


class RawSerializer(SerializerInterface):
    """Hands a subscriber's message on as the bytes received, so a message that does not
    decode reaches `StatusFilter` instead of raising inside the LCM pump."""

    def __init__(self):
        SerializerInterface.__init__(self)

    def CreateDefaultValue(self):  # noqa: N802 (Drake's name)
        return AbstractValue.Make(b"")

    def Deserialize(self, buffer, abstract_value) -> None:  # noqa: N802
        abstract_value.set_value(bytes(buffer))

    def Serialize(self, abstract_value):  # noqa: N802
        return abstract_value.get_value()


def decode_status(data: bytes, robot: RobotParams) -> rig_status_t | None:
    """The status in `data`, or None if it does not decode (another message type, garbage)
    or is out of range: not finite, a negative winch length, or a force beyond ten times the
    tension limit."""
    try:
        status = rig_status_t.decode(data)
    except (ValueError, struct.error, IndexError, OverflowError):  # garbage, truncated
        return None
    values = np.array([*status.winch_length, *status.load_cell_force, *status.hinge_angle])
    if not np.all(np.isfinite(values)):
        return None
    if np.any(np.asarray(status.winch_length) < 0.0):
        return None
    if np.any(np.abs(status.load_cell_force) > 10.0 * robot.boom_tension[1]):
        return None
    return status


def command_problem(command: rig_command_t, robot: RobotParams) -> str | None:
    """None if `command` is one rbp could have sent to `robot` (finite, within its boom-length
    and tension limits, as `RigCommandSource` clamps them), else what is wrong with it."""
    for name, values, (low, high) in (("boom_length", command.boom_length, robot.boom_length),
                                      ("tension_setpoint", command.tension_setpoint,
                                       robot.boom_tension)):
        array = np.asarray(values, dtype=float)
        slack = 1e-6 * high  # rounding, never a different command
        if not np.all(np.isfinite(array)) or np.any(array < low - slack) or np.any(
                array > high + slack):
            return (f"{name} {[float(v) for v in array]} is not within the robot's limits "
                    f"{low:g} to {high:g}")
    return None


# The encodings of rbp's fixed-size messages, to decode a log's thousands of them at once
STATUS_ROW = np.dtype([("fingerprint", "S8"), ("utime", ">i8"), ("winch_length", ">f8", 4),
                       ("load_cell_force", ">f8", 4), ("hinge_angle", ">f8", 4)])
COMMAND_ROW = np.dtype([("fingerprint", "S8"), ("utime", ">i8"), ("boom_length", ">f8", 4),
                        ("tension_setpoint", ">f8", 4)])


def good_statuses(raw: list[bytes], robot: RobotParams) -> np.ndarray:
    """The statuses among `raw` that `decode_status` takes, in order, as STATUS_ROW rows:
    decoded and range-checked as arrays (one by one, 30,000 statuses took 1.5 s)."""
    fingerprint = rig_status_t._get_packed_fingerprint()
    fits = [d if len(d) == STATUS_ROW.itemsize and d[:8] == fingerprint  # as rbp writes them
            else None if (s := decode_status(d, robot)) is None else s.encode() for d in raw]
    rows = np.frombuffer(b"".join(d for d in fits if d is not None), dtype=STATUS_ROW)
    values = np.concatenate([rows["winch_length"], rows["load_cell_force"],
                             rows["hinge_angle"]], axis=1)
    with np.errstate(invalid="ignore"):
        good = (np.all(np.isfinite(values), axis=1) & np.all(rows["winch_length"] >= 0.0, axis=1)
                & np.all(np.abs(rows["load_cell_force"]) <= 10.0 * robot.boom_tension[1],
                         axis=1))
    return rows[good]


def first_bad_command(rows: np.ndarray, robot: RobotParams) -> tuple[int, str] | None:
    """(index, `command_problem`) of the first of the COMMAND_ROW `rows` that rbp could not
    have sent to `robot`, or None: checked as arrays."""
    bad = np.zeros(len(rows), dtype=bool)
    for name, (low, high) in (("boom_length", robot.boom_length),
                              ("tension_setpoint", robot.boom_tension)):
        values, slack = rows[name], 1e-6 * high
        with np.errstate(invalid="ignore"):
            bad |= ~np.all(np.isfinite(values) & (values >= low - slack)
                           & (values <= high + slack), axis=1)
    if not bad.any():
        return None
    k = int(np.argmax(bad))
    return k, str(command_problem(rig_command_t.decode(rows[k].tobytes()), robot))


class StatusMemory(NamedTuple):
    """`StatusFilter`'s state."""

    raw: bytes                  # the subscriber's last message, as received
    status: rig_status_t        # the last good status (a default one before any)
    time: float                 # s of context time when it came (the start before any)
    good: int = 0
    bad: int = 0


class StatusFilter(LeafSystem):
    """Input `raw` (bytes of the last status message) -> outputs `status` (rig_status_t, the
    last good one) and `last_status_time` (1, s of context time when it came).

    A message that does not decode or is out of range (`decode_status`) is counted and
    ignored. The outputs already see the subscriber's newest message (`current`); the state
    stores that view in a per-step update.
    """

    def __init__(self, robot: RobotParams):
        super().__init__()
        self._robot = robot
        self.raw_port = self.DeclareAbstractInputPort("raw", AbstractValue.Make(b""))
        self._memory = self.DeclareAbstractState(
            AbstractValue.Make(StatusMemory(b"", rig_status_t(), 0.0)))
        self.status_port = self.DeclareAbstractOutputPort(
            "status", lambda: AbstractValue.Make(rig_status_t()),
            lambda context, out: out.set_value(self.current(context).status))
        self.last_status_time_port = self.DeclareVectorOutputPort(
            "last_status_time", 1,
            lambda context, out: out.SetAtIndex(0, self.current(context).time))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._start)
        self.DeclarePerStepUnrestrictedUpdateEvent(self._update)

    def memory(self, context) -> StatusMemory:
        return context.get_abstract_state(self._memory).get_value()

    def _start(self, context, state) -> None:
        state.get_mutable_abstract_state(self._memory).set_value(
            StatusMemory(b"", rig_status_t(), context.get_time()))

    def current(self, context) -> StatusMemory:
        """The stored memory updated with the subscriber's message, if it is a new one."""
        memory = self.memory(context)
        raw = self.raw_port.Eval(context)
        if not raw or raw == memory.raw:
            return memory
        status = decode_status(raw, self._robot)
        if status is None:
            return memory._replace(raw=raw, bad=memory.bad + 1)
        return StatusMemory(raw, status, context.get_time(), memory.good + 1, memory.bad)

    def _update(self, context, state) -> None:
        state.get_mutable_abstract_state(self._memory).set_value(self.current(context))


class LogWriter:
    """Every message on the rig's channels, into an LCM event log stamped with its utime (a
    message that does not decode keeps its bytes and the previous event's stamp)."""

    def __init__(self, bus: DrakeLcm, config: RigLcmConfig, path: Path):
        self.events = lcm.EventLog(str(path), "w", overwrite=True)
        self.counts = {config.command_channel: 0, config.status_channel: 0}
        self.utime = 0
        for channel, kind in ((config.command_channel, rig_command_t),
                              (config.status_channel, rig_status_t)):
            bus.Subscribe(channel, lambda data, c=channel, k=kind: self.write(c, data, k))

    def write(self, channel: str, data: bytes, kind) -> None:
        with contextlib.suppress(ValueError):  # garbage: logged as received all the same
            self.utime = kind.decode(data).utime
        self.events.write_event(self.utime, channel, data)
        self.counts[channel] += 1
