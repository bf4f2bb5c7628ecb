"""Probe 17: the long-running commands (`rbp experiment`, `rbp bench`, `rbp simulate`, the rig
commands) given hostile options, output folders and resumed trial records.

Each finding is refused in one line naming the option or file (exit status 2) before the work,
or fixed:
- an empty `--out` (`--json`, `--compare`, `--ompl-log`) of an experiment or `rbp bench` was
  read as the current folder: a sweep wrote results.json and its trial records there and its
  figure at /baseline.png (f"{out}/baseline.png"), and `rbp bench --json ''` was ignored;
- an output whose missing folders cannot be made (`-o /sys/kernel/x/plan.json`, an
  experiment's `--out /proc/x`) failed only after the work, naming no option;
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from cli_helpers import run_rbp

from experiments.sweep import SweepError, Trial, run_sweep
from rb_drake.files import output_problem


def one_error(result) -> str:
    """The single `error: ` line of a refused command (no traceback, nothing else)."""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr[-800:]
    assert "Traceback" not in result.stderr
    return lines[0]


@pytest.mark.parametrize("args, option", [
    (["experiment", "baseline_comparison", "--planners", "naive", "--trials", "1",
      "--out", ""], "--out"),
    (["experiment", "baseline_comparison", "--planners", "naive", "--trials", "1",
      "--ompl-log", ""], "--ompl-log"),
    (["experiment", "snapshots", "--out", ""], "--out"),
    (["bench", "--only", "allocation", "--samples", "1", "--out", ""], "--out"),
    (["bench", "--only", "allocation", "--samples", "1", "--json", ""], "--json"),
    (["bench", "--only", "allocation", "--samples", "1", "--compare", ""], "--compare"),
])
def test_an_empty_output_name_is_refused_naming_its_option(tmp_path: Path, args: list[str],
                                                           option: str) -> None:
    result = run_rbp(*args, cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-800:]
    assert one_error(result).startswith(f"error: {option}: an empty path")
    assert list(tmp_path.iterdir()) == [], "written into the current folder"


def test_a_folder_that_cannot_be_made_is_refused_before_the_work(tmp_path: Path) -> None:
    """/proc takes no new folder (as root, too: os.access said it was writable)."""
    problem = output_problem("/proc/rbp-probe-17/trials/a.json")
    assert problem is not None and "/proc" in problem, problem
    with pytest.raises(SweepError, match=r"^/proc/rbp-probe-17/trials/t\.json: --out: "):
        run_sweep([Trial("t", "experiments.no_such_module:f", {})], "/proc/rbp-probe-17",
                  workers=1)
    start = time.perf_counter()
    result = run_rbp("plan", "demo-shaft", "-o", "/proc/rbp-probe-17/plan.json",
                     "--footsteps-only", "--quiet", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-800:]
    assert one_error(result).startswith("error: /proc/rbp-probe-17/plan.json: -o: ")
    assert time.perf_counter() - start < 5, "refused only after planning"
