"""The rig's side of LCM in Drake: receiving its status (`RawSerializer` hands the bytes on
undecoded, `decode_status` decodes and range-checks them, `StatusFilter` keeps the last good
one) and logging every message (`LogWriter`). Where the rig is (`RigLcmConfig`) and reading a
log back are in `systems.rig_log`, which imports no Drake; its names are here too.

A status that does not decode or is out of range is logged as received but ignored.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import NamedTuple

import lcm
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import LeafSystem
from pydrake.systems.lcm import SerializerInterface

from rb_drake.params import RobotParams
from systems.reachbot_lcm import rig_command_t, rig_status_t
from systems.rig_log import (
    RigLcmConfig,
    decode_status,
)


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
