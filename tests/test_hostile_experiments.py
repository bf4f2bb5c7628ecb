"""Hostile files given to the experiments and to `rbp bench`: finished trial records edited
since they were written, JSON files named on a script's command line, and --compare's file.
Each is accepted or refused in one line `error: FILE: FIELD: REASON` (exit status 2), never a
traceback after the work, never a hang (docs/formats.md, "Experiment outputs")."""

from __future__ import annotations

import copy
import io
import json
import os
import sys
from functools import partial
from pathlib import Path
from typing import Any

import pytest

from experiments.sweep import SweepError, Trial, finished_record, trial_path
from tests.cli_helpers import run_rbp

DEEP = "[" * 100_000 + "]" * 100_000


def _store(out: Path, trial: Trial, result: Any, timing: Any) -> None:
    path = trial_path(out, trial.name)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"format": "rbp-trial/1", "name": trial.name,
                                "function": trial.function, "params": trial.params,
                                "result": result, "error": None, "timing": timing,
                                "worker": {}}, allow_nan=True))


def _set(tree: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    """A copy of `tree` with the field at `dotted` set to `value` (or removed: ...)."""
    tree = copy.deepcopy(tree)
    *path, last = dotted.split(".")
    node = tree
    for key in path:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if value is ...:
        del node[last]
    else:
        node[last] = value
    return tree


def _refused(out: Path, trial: Trial, record: dict[str, Any], field: str) -> str:
    """Store `record` for `trial`, check that resuming refuses it in one line naming the file
    and `field`, and return the message."""
    _store(out, trial, record["result"], record["timing"])
    with pytest.raises(SweepError) as info:
        finished_record(out, trial)
    message = str(info.value)
    assert message.startswith(f"{trial_path(out, trial.name)}: {field}"), message
    assert "\n" not in message and "delete the file" in message
    return message


SIMULATED = {"runs": 10, "successes": 9, "rate": 0.9, "ci95": [0.6, 0.98], "p_sim": 0.91,
             "max_position_error": 0.001, "failures": {"attach": 1}}
MC_RECORD = {"result": {"plan": {"success": True, "reason": "", "p_path": 0.9},
                        "simulated": SIMULATED},
             "timing": {"plan": 1.0, "simulate": 2.0, "trial": 3.0}}


@pytest.mark.parametrize("field, value", [
    ("result.plan", ...), ("result.plan", "x"), ("result.simulated", ...),
    ("result.simulated", "x"), ("result.simulated", [1]), ("result.simulated.runs", 0),
    ("result.simulated.runs", ...), ("result.simulated.successes", 11),
    ("result.simulated.ci95", 5), ("result.simulated.ci95", [0.9, 0.1]),
    ("result.simulated.rate", "x"), ("result.simulated.p_sim", 1e308),
    ("result.plan.p_path", "x"), ("result.plan.p_path", None), ("result.plan.success", "yes"),
    ("timing.simulate", "x"), ("timing.trial", -1),
])
def test_monte_carlo_records_checked_on_resume(tmp_path: Path, field: str, value: Any) -> None:
    """T5: every field monte_carlo's summaries read (KeyError, ZeroDivisionError, TypeError
    after the sweep before); the record as written resumes."""
    from experiments.monte_carlo import SIMULATE_TRIAL

    trial = Trial("t", SIMULATE_TRIAL, {"runs": 10, "mc_seed": 0})
    _store(tmp_path, trial, MC_RECORD["result"], MC_RECORD["timing"])
    assert finished_record(tmp_path, trial) is not None
    _refused(tmp_path, trial, _set(MC_RECORD, field, value), field)


def test_calibration_records_checked_on_resume(tmp_path: Path) -> None:
    """T6: calibration's table reads the plan's regrasps and problems and the simulation's
    interval, errors and climb time."""
    from experiments.calibration import CALIBRATION_TRIAL

    record = {"result": {"plan": {"success": True, "reason": "", "p_path": 0.9, "regrasps": 3,
                                  "problems": []},
                         "simulated": {**SIMULATED, "max_heading_error": 0.01,
                                       "climb_seconds": 60.0}},
              "timing": {"plan": 1.0, "simulate": 2.0, "trial": 3.0}}
    trial = Trial("demo-shaft", CALIBRATION_TRIAL, {"cave": {"bundled": "demo-shaft"}})
    _store(tmp_path, trial, record["result"], record["timing"])
    assert finished_record(tmp_path, trial) is not None
    for field, value in (("result.simulated.ci95", 5), ("result.simulated", {}),
                         ("result.plan.regrasps", "x"), ("result.plan.problems", 0),
                         ("result.simulated.climb_seconds", "x"), ("result.plan", ...)):
        _refused(tmp_path, trial, _set(record, field, value), field)
    no_plan = _set(_set(record, "result.plan.success", False), "result.simulated", None)
    _store(tmp_path, trial, no_plan["result"], no_plan["timing"])
    assert finished_record(tmp_path, trial) is not None  # a failed plan is not simulated


CLIMB = {"result": {"cave": None, "naive": {
    "success": True, "reason": "", "p_path": 0.9, "p_grasps": 0.95, "regrasps": 4,
    "phases": {"body": 4, "reach": 4}, "stop": None, "expansions": 12, "cost": 3.5,
    "bound": None, "verified": False}},
    "timing": {"trial": 1.0, "cave": 0.1, "naive": {
        "footstep": 0.5, "total": 0.6, "threads": 1,
        "search": {"peak_memory_mb": None, "kept_memory_mb": 1.0,
                   "history": [{"seconds": 0.1, "cost": 3.5, "lower_bound": 3.0,
                                "expansions": 10}]}}}}


@pytest.mark.parametrize("field, value", [
    ("timing.naive", "x"), ("timing.naive.footstep", "x"), ("timing.naive.footstep", -1.0),
    ("timing.naive.footstep", ...), ("timing.naive.total", "x"), ("timing.naive.search", "x"),
    ("timing.naive.search.history", "x"), ("timing.naive.search.history.0.cost", "x"),
    ("timing.naive.search.kept_memory_mb", -1), ("timing.trial", "x"),
    ("result.naive.stop", 5), ("result.naive.expansions", "x"), ("result.naive.cost", "x"),
    ("result.naive.verified", "x"), ("result.naive.phases", "x"),
])
def test_climb_records_checked_for_every_field_read(tmp_path: Path, field: str,
                                                    value: Any) -> None:
    """T7: baseline_comparison's footstep times, the OMPL log and the trial table read these
    (TypeError, ValueError after the sweep, or garbage written into the results)."""
    from experiments.common import CLIMB_TRIAL

    trial = Trial("c", CLIMB_TRIAL, {"kind": "shaft", "seed": 1, "planners": ["naive"]})
    _store(tmp_path, trial, CLIMB["result"], CLIMB["timing"])
    assert finished_record(tmp_path, trial) is not None
    _refused(tmp_path, trial, _set(CLIMB, field, value), field)


def test_a_record_holding_nan_is_refused(tmp_path: Path) -> None:
    """NaN in a field no check reads was written into results.json (ValueError there)."""
    from experiments.common import CLIMB_TRIAL

    trial = Trial("c", CLIMB_TRIAL, {"kind": "shaft", "seed": 1, "planners": ["naive"]})
    message = _refused(tmp_path, trial, _set(CLIMB, "result.naive.extra", float("nan")),
                       r"(file): holds NaN")
    assert "NaN" in message, message


def test_monte_carlo_resume_refuses_a_bad_record_in_one_line(tmp_path: Path) -> None:
    """The command itself: one line, exit 2, before any trial runs."""
    from experiments.monte_carlo import SIMULATE_TRIAL

    params = {"kind": "shaft", "seed": 1, "length": [4.5, 5.0], "max_expansions": 1000,
              "runs": 1, "mc_seed": 0}
    bad = _set(MC_RECORD, "result.simulated.runs", 0)
    _store(tmp_path / "mc", Trial("000-shaft-s1", SIMULATE_TRIAL, params), bad["result"],
           bad["timing"])
    result = run_rbp("experiment", "monte_carlo", "--out", str(tmp_path / "mc"), "--trials",
                     "1", "--workers", "1", "--runs", "1", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stderr.count("\n") == 1 and "result.simulated.runs: must be 1 or more" \
        in result.stderr, result.stderr


def _hostile_files(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    files = {"notjson": ("{", "line 1, column 2: not JSON"), "deep": (DEEP, "(file): nested"),
             "list": ("[1]", "(file): must be an object, got a list")}
    out = {name: (tmp_path / f"{name}.json", words) for name, (_, words) in files.items()}
    for name, (text, _) in files.items():
        out[name][0].write_text(text)
    (tmp_path / "dir.json").mkdir()
    return out | {"fifo": (fifo, "(file): is a named pipe (FIFO)"),
                  "dir": (tmp_path / "dir.json", "(file): is a directory")}


def _exits_in_one_line(capsys: pytest.CaptureFixture[str], run: Any, path: Path,
                       words: str) -> None:
    with pytest.raises(SystemExit) as info:
        run()
    assert info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [lines[0]] and lines[0].startswith(f"error: {path}: ") \
        and words in lines[0], lines


def test_scripts_read_named_json_files_within_the_bounds(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """T8, T9: route_quality --against-oracle / --compare, footstep_ab --labels and
    partial_climbs' results to resume read raw: a FIFO hung, the others were tracebacks."""
    from experiments import footstep_ab, partial_climbs, route_quality

    root = str(Path(__file__).resolve().parents[1])
    out = str(tmp_path / "o")
    for path, words in _hostile_files(tmp_path).values():
        f = str(path)
        for run in (partial(route_quality.main, ["--against-oracle", f]),
                    partial(route_quality.main, ["--compare", f, "--out", out]),
                    partial(footstep_ab.main, ["--old", root, "--new", root, "--out", out,
                                               "--caves", "route", "--labels", f]),
                    partial(partial_climbs.main, ["--out", f])):
            _exits_in_one_line(capsys, run, path, words)
    assert not (tmp_path / "o").exists()
    shape = tmp_path / "shape.json"
    shape.write_text('{"variants": ["default"], "caves": [{"kind": "shaft", "seed": 1}]}')
    _exits_in_one_line(capsys, lambda: route_quality.main(["--against-oracle", str(shape)]),
                       shape, "caves.0: must be an object with kind, seed and an object per")


def test_bench_refuses_an_empty_section_list(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Q5: --only '' ran nothing and exited 0 with an empty results file."""
    from experiments.bench import main

    for only in ("", ",,,", " , "):
        assert main(["--only", only, "--out", str(tmp_path / "b")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "error: --only: no section given" in err, err
    assert not (tmp_path / "b").exists()


def test_bench_compare_created_checked_and_printed_escaped(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """T4: a lone surrogate in `created` crashed the comparison after the benchmark ran, a
    newline forged a line, an object was printed as a dict."""
    from experiments.bench import main
    from experiments.bench.report import print_comparison

    old = tmp_path / "old.json"
    old.write_text('{"sections": {}, "created": {"a": 1}}')
    assert main(["--only", "allocation", "--compare", str(old), "--out",
                 str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {old}: created: must be a string (when it was measured), got an " \
                  "object\n"
    assert not (tmp_path / "b").exists()
    for created in ("\ud800", "x\nerror: forged", "\x1b[2J"):
        stdout = io.TextIOWrapper(io.BytesIO(), encoding="utf-8")  # strict, as a UTF-8 pipe
        real, sys.stdout = sys.stdout, stdout
        try:
            print_comparison({"created": created}, {"sections": {}}, "a\udcffb.json")
            stdout.flush()
        finally:
            sys.stdout = real
        text = stdout.buffer.getvalue().decode("utf-8")
        heading = text.strip().splitlines()[0]
        assert heading.startswith("compared with a\\udcffb.json (") and "forged" not in \
            text.replace(heading, ""), text


def _write_record(out: Path, trial: Trial, **changes: Any) -> None:
    """MC_RECORD stored for `trial`, with the top-level `changes` (... removes a field)."""
    record = {"format": "rbp-trial/1", "name": trial.name, "function": trial.function,
              "params": trial.params, **MC_RECORD, "error": None, "worker": {}}
    record.update(changes)
    path = trial_path(out, trial.name)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({k: v for k, v in record.items() if v is not ...}))


@pytest.mark.parametrize("field, value", [
    ("error", ...), ("name", ...), ("name", "other"), ("name", 5),
    ("error", False), ("error", 0), ("error", ""), ("error", []),
])
def test_a_record_without_a_sound_error_or_name_is_refused(tmp_path: Path, field: str,
                                                           value: Any) -> None:
    """F2, S3: a missing `error` or `name` was a KeyError in the summaries; a falsy `error`
    (false, 0, "", []) was neither run again nor explained, and the experiment exited 1."""
    from experiments.monte_carlo import SIMULATE_TRIAL

    trial = Trial("t", SIMULATE_TRIAL, {"runs": 10, "mc_seed": 0})
    _write_record(tmp_path, trial, **{field: value})
    with pytest.raises(SweepError) as info:
        finished_record(tmp_path, trial)
    message = str(info.value)
    assert message.startswith(f"{trial_path(tmp_path, trial.name)}: {field}: "), message
    assert "\n" not in message and "delete the file" in message
    _write_record(tmp_path, trial, error="Traceback: boom")
    assert finished_record(tmp_path, trial) is None, "a trial that failed is run again"


@pytest.mark.parametrize("simulated, field", [
    ({"rate": 0.1}, "rate"), ({"ci95": [0.0, 0.5]}, "ci95"), ({"rate": 0.0}, "rate"),
    ({"rate": 1.0, "successes": 10}, "ci95"),
])
def test_a_rate_must_agree_with_its_counts_and_interval(tmp_path: Path,
                                                        simulated: dict[str, Any],
                                                        field: str) -> None:
    """F3: each field in range, the figures' error bars (rate - ci95[0], ...) were negative:
    matplotlib's ValueError after the sweep. Both experiments share the check."""
    from experiments.calibration import CALIBRATION_TRIAL
    from experiments.monte_carlo import SIMULATE_TRIAL

    trial = Trial("t", SIMULATE_TRIAL, {"runs": 10, "mc_seed": 0})
    _refused(tmp_path, trial, _set(MC_RECORD, "result.simulated",
                                   {**SIMULATED, **simulated}), f"result.simulated.{field}")
    close = _set(MC_RECORD, "result.simulated.rate", 0.9 + 1e-12)  # rounding is no problem
    _store(tmp_path, trial, close["result"], close["timing"])
    assert finished_record(tmp_path, trial) is not None
    cal = Trial("demo-shaft", CALIBRATION_TRIAL, {"cave": {"bundled": "demo-shaft"}})
    record = {"result": {"plan": {"success": True, "reason": "", "p_path": 0.9, "regrasps": 3,
                                  "problems": []},
                         "simulated": {**SIMULATED, **simulated, "max_heading_error": 0.01,
                                       "climb_seconds": 60.0}},
              "timing": {"trial": 1.0}}
    _refused(tmp_path, cal, record, f"result.simulated.{field}")


@pytest.mark.parametrize("edit, field", [
    ("timing.rbp", "timing.rbp"), ("timing.naive", "timing.naive"),
    ("result.rbp.p_grasps", "result.rbp.p_grasps"),
])
def test_a_success_holds_what_the_baseline_summaries_read(tmp_path: Path, edit: str,
                                                          field: str) -> None:
    """F4, F5: a succeeded planner's timing (the rbp / rbp-sampled ratio: KeyError) and its
    p_grasps (planner_summary's counts: TypeError); a cave never made has no timing."""
    from experiments.common import CLIMB_TRIAL

    both = _set(_set(CLIMB, "result.rbp", CLIMB["result"]["naive"]), "timing.rbp",
                CLIMB["timing"]["naive"])
    trial = Trial("c", CLIMB_TRIAL, {"kind": "shaft", "seed": 1, "planners": ["naive", "rbp"]})
    _store(tmp_path, trial, both["result"], both["timing"])
    assert finished_record(tmp_path, trial) is not None
    _refused(tmp_path, trial, _set(both, edit, None if "p_grasps" in edit else ...), field)
    failed = {"success": False, "reason": "no cave: x", "p_path": None, "p_grasps": None,
              "regrasps": 0, "phases": {"body": 0, "reach": 0}}
    no_cave = {"result": {"cave": None, "naive": failed, "rbp": failed},
               "timing": {"trial": 1.0, "cave": 0.1}}
    _store(tmp_path, trial, no_cave["result"], no_cave["timing"])
    assert finished_record(tmp_path, trial) is not None


def test_a_record_of_another_trial_names_what_differs(tmp_path: Path) -> None:
    """Q2: another trial function's record printed two identical parameter dicts; a 1 MB
    parameter made a 1 MB line."""
    from experiments.monte_carlo import SIMULATE_TRIAL

    trial = Trial("t", SIMULATE_TRIAL, {"runs": 10, "mc_seed": 0})
    _write_record(tmp_path, trial, function="x\ny")
    with pytest.raises(SweepError, match=r"t\.json: function: made by another trial function "
                       r"\('x\\ny'\), not 'experiments\.monte_carlo:simulate_trial'"):
        finished_record(tmp_path, trial)
    for params, field in (({"runs": "a" * 1_000_000, "mc_seed": 0}, "params.runs"),
                          ({"runs": 10}, "params.mc_seed"),
                          ({"runs": 10, "mc_seed": 0, "x": 1}, "params.x")):
        _write_record(tmp_path, trial, params=params)
        with pytest.raises(SweepError) as info:
            finished_record(tmp_path, trial)
        message = str(info.value)
        assert f"t.json: {field}: " in message and len(message) < 300, message[:300]


@pytest.mark.parametrize("field", ["max_position_error", "max_heading_error"])
def test_calibration_errors_are_bounded(tmp_path: Path, field: str) -> None:
    """1e308 m (or rad) was finite, then 1000x (mm) or 57.3x (degrees) in the table made inf:
    'Out of range float values are not JSON compliant' writing results.json."""
    from experiments.calibration import CALIBRATION_TRIAL

    cal = Trial("demo-shaft", CALIBRATION_TRIAL, {"cave": {"bundled": "demo-shaft"}})
    record = {"result": {"plan": {"success": True, "reason": "", "p_path": 0.9, "regrasps": 3,
                                  "problems": []},
                         "simulated": {**SIMULATED, "max_heading_error": 0.01,
                                       "climb_seconds": 60.0, field: 1e308}},
              "timing": {"trial": 1.0}}
    message = _refused(tmp_path, cal, record, f"result.simulated.{field}")
    assert "1e+308" in message, f"the refusal does not show the value: {message}"


def test_calibration_figure_draws_a_rate_off_by_the_tolerance() -> None:
    """The simultaneous interval comes from the counts: a rate 1e-10 past it drew a negative
    error bar (matplotlib ValueError) before it was widened to the rate."""
    from experiments.calibration import calibration_figure, rows_of

    sim = {**SIMULATED, "runs": 10, "successes": 0, "rate": 1e-10, "ci95": [0.0, 0.3],
           "max_heading_error": 0.01, "climb_seconds": 60.0}
    record = {"name": "c", "result": {"plan": {"success": True, "reason": "", "p_path": 0.0,
                                               "regrasps": 3, "problems": []},
                                      "simulated": sim}}
    rows = rows_of([record])
    rows[0]["ci_simultaneous"][0] = 2e-10  # as a rounding could leave it
    assert rows[0]["ci_simultaneous"][0] > rows[0]["rate"], "the case: the rate past its interval"
    import matplotlib.pyplot as plt

    fig = calibration_figure(rows)  # raised matplotlib's "'yerr' must not contain negative"
    try:
        assert len(fig.axes) == 2 and fig.axes[0].collections, "no error bars drawn"
    finally:
        plt.close(fig)
