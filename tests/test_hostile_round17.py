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


def usage_error(main, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one line with which an experiment script's `main(argv)` refuses (status 2)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err[-800:]
    return lines[0]


@pytest.mark.parametrize("argv, start", [
    (["--seeds", "1,,2"], "error: --seeds: must be a whole number, got ''"),
    (["--seeds", "1,x"], "error: --seeds: must be a whole number, got 'x'"),
    (["--seeds", "-5"], "error: --seeds: must be a whole number from 0 to "),
    (["--seeds", "99999999999999999999"], "error: --seeds: must be a whole number from 0 "),
    (["--seeds", "3,1,3"], "error: --seeds: seed 3 given twice"),
    (["--kind", "foo"], "error: --kind: invalid choice: 'foo'"),
    (["--length", "5", "4"], "error: --length: need 2 <= MIN <= MAX"),
    (["--variants", "corridorx"], "error: --variants: corridorx: cannot be read"),
    (["--variants", "x-"], "error: --variants: x-: cannot be read"),
    (["--variants", "x-m0"], "error: --variants: x-m0: max_expansions: must be a whole number"),
    (["--variants", "corridor-1"], "error: --variants: corridor-1: anytime.corridor: must be"),
    (["--variants", "default,default"], "error: --variants: a variant named twice"),
    (["--variants", "default-quarter,default"],
     "error: --variants: default-quarter needs default before it"),
    (["--first-seed", str(2**63 - 1), "--trials", "2"],
     "error: --first-seed: the last cave's seed, 9223372036854775808, is beyond"),
])
def test_route_quality_refuses_its_options_before_the_caves(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], start: str) -> None:
    from experiments.route_quality import main

    out = tmp_path / "rq.json"
    line = usage_error(main, ["--trials", "1", "--out", str(out), *argv], capsys)
    assert line.startswith(start), line
    assert list(tmp_path.iterdir()) == []


def test_route_quality_refuses_a_folder_for_out_before_the_caves(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.route_quality import main

    line = usage_error(main, ["--trials", "1", "--out", str(tmp_path)], capsys)
    assert line.startswith(f"error: --out: {tmp_path}: is a directory"), line
    assert not Path(f"{tmp_path}.tmp").exists()


@pytest.mark.parametrize("values, start", [
    ("0.5000001,0.5000002", "error: --values: two values read 0.5 to 6 significant digits"),
    ("1_0", "error: --values: comma-separated numbers, got '1_0'"),
    ("\uff10.\uff15", "error: --values: comma-separated numbers"),
])
def test_param_sweep_values_are_read_as_numbers_that_name_distinct_trials(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], values: str, start: str) -> None:
    from experiments.param_sweep import main

    line = usage_error(main, ["--param", "p_min", "--values", values, "--trials", "1",
                              "--out", str(tmp_path / "out")], capsys)
    assert line.startswith(start), line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("module", ["baseline_comparison", "monte_carlo", "param_sweep",
                                    "seed_vs_scp", "timing_table"])
def test_a_sweeps_seeds_stay_within_the_seed_range(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], module: str) -> None:
    import importlib

    main = importlib.import_module(f"experiments.{module}").main
    extra = ["--param", "p_min", "--values", "0.5"] if module == "param_sweep" else []
    argv = ["--trials", "2", "--first-seed", str(2**63 - 1), "--out", str(tmp_path / "o"),
            *extra]
    line = usage_error(main, argv, capsys)
    assert line.startswith("error: --first-seed: the last trial's seed, 9223372036854775808, "
                           "is beyond 9223372036854775807"), line
    assert list(tmp_path.iterdir()) == []
    # the largest first seed that keeps every trial's seed in range is accepted by the check
    from experiments.arguments import OneLineParser
    from experiments.common import add_cave_arguments, check_cave_arguments
    from experiments.sweep import add_sweep_arguments

    parser = OneLineParser(prog="probe")
    add_sweep_arguments(parser, trials=2, out="o")
    add_cave_arguments(parser)
    check_cave_arguments(parser, parser.parse_args(["--first-seed", str(2**63 - 2)]))


def test_out_of_another_experiments_folder_is_refused_before_the_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from experiments.param_sweep import main

    results = tmp_path / "results.json"
    results.write_text(json.dumps({"experiment": "baseline_comparison", "summary": {}}))
    before = results.read_bytes()
    line = usage_error(main, ["--param", "p_min", "--values", "0.5", "--trials", "1",
                              "--workers", "1", "--out", str(tmp_path)], capsys)
    assert line == (f"error: {results}: --out: holds the results of the experiment "
                    "'baseline_comparison', which param_sweep would replace; give it another "
                    "--out folder"), line
    assert results.read_bytes() == before and sorted(tmp_path.iterdir()) == [results]
