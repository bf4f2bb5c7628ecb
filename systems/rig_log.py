"""A rig run's LCM log read back, without Drake or matplotlib: a hostile log is refused (in
one line, in a fraction of a second and tens of MB) before `rbp rig-report` imports what draws.

Where the rig is (`RigLcmConfig`, channels and timing), the log's events read from one bounded
read of the file (`read_log`: a header scan lcm's own reader cannot be trusted with), its
messages decoded and range-checked (`decode_status`, `good_statuses`, `first_bad_command`),
and `replay_log`: the setup's scenario and stance, the commands and each good status's
probability of grasp maintenance, as the live run's `GraspMonitor` computes it (the same
`grasp.prob` on the same pull angle), for every status at once. `report_figure` draws it.
"""

from __future__ import annotations

import dataclasses
import json
import struct
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from planning.ramps import TENSION_RATE_MAX
from rb_drake import geometry, grasp
from rb_drake.errors import RbpInputError, one_line
from rb_drake.input_files import InputFileError, load_json, max_input_values
from rb_drake.params import RobotParams
from rb_drake.scenario import Scenario, ScenarioError, scenario_from_dict
from systems.reachbot_lcm import rig_command_t, rig_setup_t, rig_status_t

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
    # rates of the bundled plans (about 0.13 m/s); the ramps' bound (`ramps.TENSION_RATE_MAX`).
    # `rbp rig-run` refuses a phase whose motion would need faster commands (`rate_problem`).
    max_length_rate: float = 0.5    # m/s per boom
    max_tension_rate: float = TENSION_RATE_MAX  # N/s per boom


class RigInputError(RbpInputError):
    """A plan or log the rig cannot use: `field` (path in the file) and `reason`."""

    def __init__(self, field: str, reason: str):
        super().__init__(reason, field=field)


# ---------------------------------------------------------------------------------------------
# The log's events


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


# ---------------------------------------------------------------------------------------------
# Its messages, decoded and range-checked


# A message's utime (us): rbp stamps the plan's time (from about 0 s); a rig's own clock may
# stamp the epoch (1.7e15 in 2026). Outside these it is no time a rig sends.
UTIME_RANGE = (-100_000_000, 10**16)
MAX_HINGE = 4.0 * np.pi  # rad: a hinge angle beyond two turns is no angle a hinge reads


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
    if np.any(np.abs(status.hinge_angle) > MAX_HINGE) or not (
            UTIME_RANGE[0] <= status.utime <= UTIME_RANGE[1]):
        return None
    return status


def command_tension_bounds(robot: RobotParams) -> tuple[float, float]:
    """The tension setpoints rbp may send: down to 0 N, where a released boom's gripper lets
    go (`RigCommandSource` holds the other booms to boom_tension's minimum)."""
    return 0.0, robot.boom_tension[1]


def command_problem(command: rig_command_t, robot: RobotParams) -> str | None:
    """None if `command` is one rbp could have sent to `robot` (finite, within its boom-length
    and tension limits as `RigCommandSource` clamps them, 0 N for a released boom), else what
    is wrong with it."""
    for name, values, (low, high) in (("boom_length", command.boom_length, robot.boom_length),
                                      ("tension_setpoint", command.tension_setpoint,
                                       command_tension_bounds(robot))):
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
                         axis=1)
                & np.all(np.abs(rows["hinge_angle"]) <= MAX_HINGE, axis=1)
                & (rows["utime"] >= UTIME_RANGE[0]) & (rows["utime"] <= UTIME_RANGE[1]))
    return rows[good]


def first_bad_command(rows: np.ndarray, robot: RobotParams) -> tuple[int, str] | None:
    """(index, `command_problem`) of the first of the COMMAND_ROW `rows` that rbp could not
    have sent to `robot`, or None: checked as arrays."""
    bad = np.zeros(len(rows), dtype=bool)
    for name, (low, high) in (("boom_length", robot.boom_length),
                              ("tension_setpoint", command_tension_bounds(robot))):
        values, slack = rows[name], 1e-6 * high
        with np.errstate(invalid="ignore"):
            bad |= ~np.all(np.isfinite(values) & (values >= low - slack)
                           & (values <= high + slack), axis=1)
    late = (rows["utime"] < UTIME_RANGE[0]) | (rows["utime"] > UTIME_RANGE[1])
    if not (bad | late).any():
        return None
    k = int(np.argmax(bad | late))
    if late[k] and not bad[k]:  # a command past both: its values named, as before
        return k, (f"utime {int(rows['utime'][k])} us is no time a rig sends (from "
                   f"{UTIME_RANGE[0]:g} to {UTIME_RANGE[1]:g} us)")
    return k, str(command_problem(rig_command_t.decode(rows[k].tobytes()), robot))


# ---------------------------------------------------------------------------------------------
# The log replayed


class GraspRecord(NamedTuple):
    """The monitor's output per status message (N rows, in arrival order)."""

    time: np.ndarray        # (N,) s, the status's utime
    p_grasp: np.ndarray     # (N, 4)
    pull_angle: np.ndarray  # (N, 4) rad
    force: np.ndarray       # (N, 4) N, measured


class RigLog(NamedTuple):
    """A run's log, decoded, with the monitor's output per status (`replay_log`)."""

    scenario: Scenario
    stance_ids: tuple[str, ...]
    plan_source: str
    command_time: np.ndarray      # (M,) s
    boom_length: np.ndarray       # (M, 4) m, commanded
    tension_setpoint: np.ndarray  # (M, 4) N
    replay: GraspRecord           # per status, in log order
    winch_length: np.ndarray      # (N, 4) m, measured


def replay_log(path: str | Path,
               config: RigLcmConfig = RigLcmConfig()) -> RigLog:
    """Read a log written by `run_rig` and compute a `GraspMonitor`'s outputs for each good
    status (statuses that do not decode or are out of range are skipped, as the live run did). A
    setup or command message that does not decode, or a log past MAX_LOG_EVENTS events, is
    refused (RigInputError naming the channel and the event): such a log was not written by
    `run_rig`, or was damaged since."""
    path = Path(path)
    setup, commands, raw_statuses = None, [], []
    channels = (config.setup_channel, config.command_channel, config.status_channel)
    try:
        events, damage = read_log(path, channels,
                                  {config.command_channel: fixed_message(rig_command_t)})
    except OSError as e:
        raise RigInputError("(file)", f"not an LCM log: {e.strerror or e}") from None
    if damage is not None:
        raise RigInputError(*damage)
    for number, channel, data in events:
        if channel == config.setup_channel:
            if number > 0:  # run_rig writes it once, first: a later one could swap the scenario
                raise RigInputError(config.setup_channel, f"event {number}: " + (
                    "a second setup message; a log holds one, its first event" if setup
                    else "the setup message must be the log's first event, not a later one"))
            setup = _decoded(rig_setup_t, data, config.setup_channel, number)
        elif channel == config.command_channel:  # each its type's size and fingerprint
            commands.append((number, data))
        else:
            raw_statuses.append(data)
    if setup is None:
        raise RigInputError(config.setup_channel, "no setup message: not a log written by "
                            "rbp rig-run (or not an LCM log at all)")
    scn = _setup_scenario(setup.scenario_json, config.setup_channel)
    command_rows = np.frombuffer(b"".join(d for _, d in commands), dtype=COMMAND_ROW)
    bad = first_bad_command(command_rows, scn.robot)  # out of range would overflow the plots
    if bad is not None:
        raise RigInputError(config.command_channel, f"event {commands[bad[0]][0]}: {bad[1]}: "
                            "not a command rbp sends")
    stance_ids = tuple(setup.stance)
    unknown = [a for a in stance_ids if a not in scn.anchor_index]
    if unknown:
        raise RigInputError(f"{config.setup_channel}.stance",
                            f"event 0: unknown anchor {_shown(unknown[0])}")
    if len(set(stance_ids)) != len(stance_ids):  # as a scenario's start stance is checked
        raise RigInputError(f"{config.setup_channel}.stance", f"event 0: each boom needs its "
                            f"own anchor, got {list(stance_ids)}")
    statuses = good_statuses(raw_statuses, scn.robot)
    # GraspMonitor's outputs, for every status at once (through the system, one FixValue per
    # status, 30,000 took 5 s)
    stance = scn.stance(stance_ids)
    force = statuses["load_cell_force"].astype(float)
    pull = geometry.wrap_angle(statuses["hinge_angle"].astype(float) - np.arctan2(
        stance.normals[:, 1], stance.normals[:, 0]))
    p_grasp = grasp.prob(force, pull, stance.f_normal, stance.f_lateral, stance.sigma_normal,
                         stance.sigma_lateral).reshape(-1, 4)
    return RigLog(scn, stance_ids, setup.plan_source, command_rows["utime"] * 1e-6,
                  command_rows["boom_length"].astype(float).reshape(-1, 4),
                  command_rows["tension_setpoint"].astype(float).reshape(-1, 4),
                  GraspRecord(statuses["utime"] * 1e-6, p_grasp, pull.reshape(-1, 4),
                              force.reshape(-1, 4)),
                  statuses["winch_length"].astype(float).reshape(-1, 4))


def _setup_scenario(text: str, channel: str) -> Scenario:
    """The scenario of a log's setup message (RigInputError on `channel`.scenario_json), of
    at most as many values as a scenario file (a 7 MB one of 900,000 objects took 370 MB)."""
    field = f"{channel}.scenario_json"
    try:
        return scenario_from_dict(load_json(text, max_values=max_input_values()),
                                  "log scenario", check_start=False)
    except InputFileError as e:
        where = "" if e.field == "(file)" else f"{e.field}: "
        raise RigInputError(field, f"{where}{e.reason}") from None
    except (ScenarioError, json.JSONDecodeError) as e:
        raise RigInputError(field, str(e)) from None
    except RecursionError:
        raise RigInputError(field, "nested too deeply to be a scenario") from None


def _decoded(message_type: Any, data: bytes, channel: str, number: int) -> Any:
    """`data` decoded as `message_type`, or RigInputError naming the channel and the event."""
    try:
        return message_type.decode(data)
    except (ValueError, struct.error, IndexError, OverflowError):
        # lcm-gen's decoders raise ValueError on a wrong fingerprint, struct.error on a
        # truncated message and UnicodeDecodeError (a ValueError) on a damaged string
        raise RigInputError(channel, f"event {number} does not decode as "
                            f"{message_type.__name__}: the log is damaged or not rbp's"
                            ) from None


def report_figure(log: RigLog):
    """The paper's Fig. 7 for a log: each anchor's probability of grasp maintenance over
    time, and each boom's measured load-cell force against its commanded tension."""
    import matplotlib.pyplot as plt

    from rb_drake.draw import plain_label, title_name

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7.0, 6.0))
    rec = log.replay
    for i, anchor in enumerate(log.stance_ids):
        color = f"C{i}"
        top.plot(rec.time, rec.p_grasp[:, i], color=color, label=f"boom {i}: {plain_label(anchor)}")
        bottom.plot(rec.time, rec.force[:, i], color=color, label=f"boom {i} measured")
        bottom.plot(log.command_time, log.tension_setpoint[:, i], color=color, linestyle="--",
                    label=f"boom {i} commanded")
    top.set_ylabel("probability of grasp maintenance")
    top.set_title(f"{title_name(log.scenario.name)}: {title_name(log.plan_source or 'rig run')}",
                  parse_math=False)
    top.legend(loc="lower left", fontsize="small")
    top.grid(alpha=0.3)
    bottom.set_ylabel("tension (N)")
    bottom.set_xlabel("time (s)")
    bottom.legend(ncol=2, fontsize="x-small")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _shown(text: str) -> str:
    """`text` quoted for an error line: control characters escaped, and U+FFFD too (lcm's
    decoder puts one for each byte of a log's string that is not UTF-8)."""
    return one_line(repr(text)).replace("\ufffd", "\\ufffd")
