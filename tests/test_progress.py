"""Progress lines: shown (tqdm) on a terminal, silent with --quiet and when stderr is not one."""

from __future__ import annotations

import io
import sys

from experiments.sweep import ProgressDisplay
from rbp.progress import SearchProgress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def record(name: str, error: str | None = None) -> dict:
    return {"name": name, "error": error, "timing": {"trial": 0.5}}


def test_search_progress_on_a_terminal(monkeypatch) -> None:
    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with SearchProgress("rbp on cave", budget=100) as bar:
        bar.search(3, 10)
        bar.search(7, 25, 1.234)
        bar.phase("phase 1/5: body movement")
    text = term.getvalue()
    assert "7/100 stances expanded" in text and "25 transitions tested" in text, repr(text)
    assert "phase 1/5: body movement" in text, repr(text)
    assert "nearest 1.23 m from the goal" in text, repr(text)


def test_search_progress_quiet_or_not_a_terminal(monkeypatch) -> None:
    for stream, quiet in ((Terminal(), True), (io.StringIO(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        with SearchProgress("rbp on cave", budget=100, quiet=quiet) as bar:
            bar.search(3, 10)
            bar.phase("phase 1/5")
        assert stream.getvalue() == "", f"quiet={quiet}: {stream.getvalue()!r}"


def test_sweep_progress_bar_on_a_terminal() -> None:
    term = Terminal()
    progress = ProgressDisplay(4, 1, term)
    progress.update(record("a"))
    progress.update(record("b", "ValueError: boom"))
    progress.close()
    text = term.getvalue()
    assert text.startswith("resuming: 1 of 4 trials already finished"), repr(text)
    assert "3/4" in text and "1 error" in text and "1 errors" not in text, repr(text)


def test_sweep_progress_lines_in_a_log() -> None:
    log = io.StringIO()
    progress = ProgressDisplay(2, 0, log)
    progress.update(record("a"))
    progress.update(record("b", "ValueError: boom\nmore"))
    progress.close()
    assert log.getvalue().splitlines() == ["[1/2] a: done (0.5 s)",
                                           "[2/2] b: ERROR ValueError: boom (0.5 s)"]


def test_check_progress_on_a_terminal_after_its_delay(monkeypatch) -> None:
    """`rbp check`'s line: phases verified of the plan's, on a terminal (issue 32: a 300-phase
    plan was checked for 111 s with no sign of life); none with --quiet or off a terminal."""
    from rbp.progress import CheckProgress

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with CheckProgress("checking plan.json", delay=0.0) as bar:
        for k in range(1, 301):
            bar(k, 300)
    text = term.getvalue()
    assert "checking plan.json: 300/300 phases verified" in text, repr(text[-300:])
    for stream, quiet, delay in ((Terminal(), True, 0.0), (io.StringIO(), False, 0.0),
                                 (Terminal(), False, 60.0)):
        monkeypatch.setattr(sys, "stderr", stream)
        with CheckProgress("checking plan.json", quiet=quiet, delay=delay) as bar:
            bar(1, 3)
        assert stream.getvalue() == "", f"quiet={quiet}, delay {delay}: {stream.getvalue()!r}"


def test_rbp_check_reports_each_phase(monkeypatch) -> None:
    """The verifier calls the progress once per phase, ending at the plan's phase count."""
    from pathlib import Path

    from planning.check import check_plan
    from planning.plan_file import read_plan_file

    plan = read_plan_file(Path(__file__).parent / "data" / "golden" / "rig.json")
    calls: list[tuple[int, int]] = []
    assert check_plan(plan, progress=lambda done, total: calls.append((done, total))) == []
    n = len(plan["phases"])
    assert calls == [(k, n) for k in range(1, n + 1)], calls
