"""The cores other processes leave free, sampled while a search runs (issue 32).

numba's OpenMP threads spin for a few milliseconds after each parallel region (libgomp's
default), which is what makes a second thread pay on an idle machine: the search's parallel
regions are short, and a thread that has gone to sleep wakes too late for them (waiting
passively, two threads were no faster than one here). When another process holds a core,
the same spinning takes the CPU from the thread doing the work (a search ran up to 10x
slower). So the kernels use as many threads as there are cores the other processes leave
free, read from the machine's CPU counters (`/proc/stat`) less the process's own CPU time,
over the last fifth of a second: one thread when another job holds a core, every allowed
thread when the machine is idle. The thread count never changes a result (the kernels score
each row on its own), only the time. RBP_THREADS_ADAPT=0 turns this off (every allowed
thread, always: for measuring a fixed count).
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

SAMPLE_SECONDS = 0.2  # how often the estimate is refreshed (and the window it is taken over)
# A second thread only where a core is free with this margin to spare: a thread too many on a
# busy core costs far more (its spinning takes the working thread's CPU) than one too few on
# an idle machine, and a 0.2 s window of 10 ms clock ticks is noisy.
MARGIN = 0.25
STALE_PERIODS = 5  # a window longer than this many periods is started again
_PROC_STAT = Path("/proc/stat")


def _busy_jiffies() -> tuple[float, float] | None:
    """(busy, total) CPU time of the whole machine since boot, in clock ticks (None where the
    system has no /proc/stat)."""
    try:
        with _PROC_STAT.open() as f:
            fields = f.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu":
        return None
    values = [float(v) for v in fields[1:9]]
    idle = values[3] + (values[4] if len(values) > 4 else 0.0)  # idle, iowait
    return sum(values) - idle, sum(values)


def _own_seconds() -> float:
    """This process's CPU time (all its threads), in seconds."""
    t = os.times()
    return t.user + t.system


class FreeCores:
    """An estimate, refreshed at most every `period` seconds, of how many of the machine's
    `cores` the other processes left free over the last window."""

    def __init__(self, cores: int | None = None, period: float = SAMPLE_SECONDS,
                 enabled: bool = True, stale_after: float | None = None) -> None:
        self.cores = cores or os.cpu_count() or 1
        self.stale_after = STALE_PERIODS * period if stale_after is None else stale_after
        self.enabled = enabled
        self.period = period
        self._ticks = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
        self._last = time.monotonic()
        self._sample = _busy_jiffies()
        self._own = _own_seconds()
        self.free: float = float(self.cores)

    def update(self) -> float:
        """The cores free of other processes' work (refreshed when the window has passed)."""
        now = time.monotonic()
        if now - self._last < self.period or self._sample is None:
            return self.free
        sample, own = _busy_jiffies(), _own_seconds()
        if sample is None:
            return self.free
        if now - self._last > self.stale_after:
            # this process did no kernel work for a while (other stages, or waiting for its
            # next job): the window shows what ran meanwhile, not now; start a fresh one and
            # keep the last estimate until it has passed
            self._last, self._sample, self._own = now, sample, own
            return self.free
        busy = (sample[0] - self._sample[0]) / self._ticks
        elapsed = (sample[1] - self._sample[1]) / self._ticks / self.cores
        if elapsed > 0:
            others = max(0.0, busy - (own - self._own)) / elapsed
            self.free = min(float(self.cores), max(0.0, self.cores - others))
        self._last, self._sample, self._own = now, sample, own
        return self.free

    def threads(self, allowed: int) -> int:
        """Threads to use out of `allowed`: the free cores (whole ones, `MARGIN` to spare), at
        least one."""
        if allowed <= 1 or not self.enabled:
            return max(1, allowed)
        return max(1, min(allowed, math.floor(self.update() + MARGIN)))
