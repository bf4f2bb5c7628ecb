"""The kernels' thread count follows the cores other processes leave free (issue 32)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

import rb_drake.kernel.free_cores as free_cores
from rb_drake.errors import RbpInputError
from rb_drake.kernel.free_cores import FreeCores


def _counters(monkeypatch: pytest.MonkeyPatch, machine: list[tuple[float, float]],
              own: list[float]) -> None:
    """Feed FreeCores these (busy, total) clock-tick samples and own CPU seconds, in order."""
    machine_it, own_it = iter(machine), iter(own)
    monkeypatch.setattr(free_cores, "_busy_jiffies", lambda: next(machine_it))
    monkeypatch.setattr(free_cores, "_own_seconds", lambda: next(own_it))


@pytest.mark.parametrize("others, expected", [(0.0, 2), (0.2, 2), (0.8, 1), (1.0, 1), (2.0, 1)])
def test_threads_from_the_cores_others_leave(monkeypatch: pytest.MonkeyPatch, others: float,
                                             expected: int) -> None:
    # 2 cores, a 1 s window (200 ticks at 100 a second), this process used 1 CPU-second
    ticks = 100.0
    busy = (1.0 + others) * ticks
    _counters(monkeypatch, [(0.0, 0.0), (busy, 2 * ticks)], [0.0, 1.0])
    fc = FreeCores(cores=2, period=0.0, stale_after=math.inf)
    fc._ticks = ticks
    assert fc.threads(2) == expected, (
        f"others using {others} cores of 2 should leave {expected} thread(s), got "
        f"{fc.threads(2)} (free estimate {fc.free:.2f})")
    assert abs(fc.free - max(0.0, 2.0 - others)) < 1e-9, fc.free


def test_never_more_than_allowed_nor_fewer_than_one(monkeypatch: pytest.MonkeyPatch) -> None:
    _counters(monkeypatch, [(0.0, 0.0), (0.0, 800.0)], [0.0, 0.0])
    fc = FreeCores(cores=8, period=0.0, stale_after=math.inf)
    fc._ticks = 100.0
    assert fc.threads(3) == 3, "an idle 8-core machine gives every allowed thread, no more"
    assert fc.threads(1) == 1 and fc.threads(0) == 1, "at least one thread"


def test_estimate_held_between_refreshes(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def sample() -> tuple[float, float]:
        calls.append(1)
        return (0.0, 0.0)

    monkeypatch.setattr(free_cores, "_busy_jiffies", sample)
    fc = FreeCores(cores=2, period=3600.0)
    for _ in range(100):
        fc.threads(2)
    assert len(calls) == 1, f"the counters were read {len(calls)} times within one period"


def test_off_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    _counters(monkeypatch, [(0.0, 0.0), (200.0, 200.0)], [0.0, 0.0])  # others use both cores
    fc = FreeCores(cores=2, period=0.0, enabled=False, stale_after=math.inf)
    fc._ticks = 100.0
    assert fc.threads(2) == 2, "RBP_THREADS_ADAPT=0 keeps every allowed thread"


def test_malformed_setting_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from rb_drake.environment import threads_adapt_setting

    monkeypatch.setenv("RBP_THREADS_ADAPT", "yes")
    with pytest.raises(RbpInputError, match="RBP_THREADS_ADAPT"):
        threads_adapt_setting()
    monkeypatch.setenv("RBP_THREADS_ADAPT", "0")
    assert threads_adapt_setting() is False


def test_machine_counters_read_from_proc_stat(monkeypatch: pytest.MonkeyPatch,
                                              tmp_path) -> None:
    """/proc/stat's first line: busy = all but idle and iowait, total = all eight fields."""
    stat = tmp_path / "stat"
    stat.write_text("cpu  100 5 40 800 30 2 3 7 0 0\ncpu0 50 2 20 400 15 1 1 3 0 0\n")
    monkeypatch.setattr(free_cores, "_PROC_STAT", stat)
    assert free_cores._busy_jiffies() == (157.0, 987.0), free_cores._busy_jiffies()
    stat.write_text("intr 1 2 3\n")
    assert free_cores._busy_jiffies() is None, "a file that is not /proc/stat's is not read"
    monkeypatch.setattr(free_cores, "_PROC_STAT", tmp_path / "missing")
    assert free_cores._busy_jiffies() is None, "no /proc/stat: no estimate"


def test_rbp_refuses_a_malformed_adapt_setting(tmp_path) -> None:
    out = subprocess.run([sys.executable, "-m", "rbp", "scenario", "list"],
                         env={"RBP_THREADS_ADAPT": "2", "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, (out.returncode, out.stderr)
    assert "RBP_THREADS_ADAPT" in out.stderr and "Traceback" not in out.stderr, out.stderr


def test_a_stale_window_is_started_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """After a pause (the process did no kernel work), the window shows what ran meanwhile:
    it is started again and the last estimate kept until a fresh window has passed."""
    clock = [0.0]
    monkeypatch.setattr(free_cores.time, "monotonic", lambda: clock[0])
    # others: idle for the first window, both cores during the pause, idle after it
    _counters(monkeypatch, [(0.0, 0.0), (20.0, 40.0), (820.0, 840.0), (840.0, 880.0)],
              [0.0, 0.2, 0.2, 0.6])
    fc = FreeCores(cores=2, period=0.2)
    fc._ticks = 100.0
    clock[0] = 0.2
    assert fc.threads(2) == 2, f"an idle first window gives 2 threads (free {fc.free:.2f})"
    clock[0] = 4.2  # a 4 s pause while others used both cores
    assert fc.threads(2) == 2, "the stale window is not read: the last estimate stands"
    clock[0] = 4.4
    assert fc.threads(2) == 2, f"the fresh window is idle (free {fc.free:.2f})"
