"""The trial runner: records per trial, resume after a kill, and local against Dask runs.

Runner mechanics use trials of the standard library (`json:loads` parses its `s` parameter into
the record's result), which cost nothing; the kill-and-resume and the Dask runs use the naive
planner on tiny generated caves, a real experiment trial of about a second.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from experiments.sweep import SweepError, Trial, run_sweep, trial_path

ROOT = Path(__file__).resolve().parents[1]


def parse_trial(name: str, value: object) -> Trial:
    return Trial(name, "json:loads", {"s": json.dumps(value)})


def tiny_climb(name: str, kind: str, seed: int) -> Trial:
    """The baseline comparison's trial, naive planner only, on a short cave."""
    return Trial(name, "experiments.baseline_comparison:climb_trial",
                 {"kind": kind, "seed": seed, "length": [2.5, 2.6], "max_expansions": 5,
                  "planners": ["naive"], "motion": False})


def test_each_trial_is_written_once_and_skipped_when_run_again(tmp_path: Path) -> None:
    trials = [parse_trial(f"t{k}", {"k": k, "timing": {"made_up": k / 10}}) for k in range(3)]
    lines = io.StringIO()
    records = run_sweep(trials, tmp_path, workers=1, stream=lines)
    assert [r["name"] for r in records] == ["t0", "t1", "t2"], records
    for k, r in enumerate(records):
        assert r["error"] is None, r
        assert r["result"] == {"k": k}, f"the timing must leave the result: {r['result']}"
        assert r["timing"]["made_up"] == k / 10 and r["timing"]["trial"] >= 0.0, r["timing"]
        stored = json.loads(trial_path(tmp_path, r["name"]).read_text())
        assert stored == r, f"the file must hold the record: {stored} != {r}"
    assert len(lines.getvalue().splitlines()) == 3, f"one line per trial: {lines.getvalue()!r}"
    stamps = {t.name: trial_path(tmp_path, t.name).stat().st_mtime_ns for t in trials}

    lines = io.StringIO()
    again = run_sweep([*trials, parse_trial("t3", {"k": 3})], tmp_path, workers=1,
                      stream=lines)
    assert again[:3] == records, "finished trials must come back as they were recorded"
    assert again[3]["result"] == {"k": 3}, again[3]
    for name, stamp in stamps.items():
        assert trial_path(tmp_path, name).stat().st_mtime_ns == stamp, f"{name} was rewritten"
    assert "resuming: 3 of 4" in lines.getvalue(), lines.getvalue()
    assert len(lines.getvalue().splitlines()) == 2, lines.getvalue()


def test_a_failing_trial_is_recorded_and_run_again(tmp_path: Path) -> None:
    bad = Trial("bad", "json:loads", {"s": "{not json"})
    good = parse_trial("good", {"x": 1})
    records = run_sweep([bad, good], tmp_path, workers=1, stream=io.StringIO())
    assert records[0]["result"] is None and "JSONDecodeError" in records[0]["error"], records[0]
    assert records[1]["error"] is None, "one failing trial must not stop the others"
    first = json.loads(trial_path(tmp_path, "bad").read_text())
    again = run_sweep([bad, good], tmp_path, workers=1, stream=io.StringIO())
    assert again[1] == records[1], "the finished trial must be kept"
    assert again[0]["timing"] != first["timing"], "a failed trial must be run again"


def test_a_folder_of_another_sweep_is_refused(tmp_path: Path) -> None:
    run_sweep([parse_trial("t0", {"v": 1})], tmp_path, workers=1, stream=io.StringIO())
    with pytest.raises(SweepError, match=r"t0\.json: params\.\w+: recorded for other parameters"):
        run_sweep([parse_trial("t0", {"v": 2})], tmp_path, workers=1, stream=io.StringIO())


@pytest.mark.parametrize("names", [["a/b"], ["a", "a"], [""]])
def test_bad_trial_names_are_refused(tmp_path: Path, names: list[str]) -> None:
    with pytest.raises(SweepError, match="trial name"):
        run_sweep([parse_trial(n, {}) for n in names], tmp_path, workers=1)
    assert not (tmp_path / "trials").exists(), "nothing may run before the names are checked"


def _script(out: Path, trials: int) -> list[str]:
    return [sys.executable, "-m", "experiments.baseline_comparison", "--trials", str(trials),
            "--planners", "naive", "--length", "2.5", "2.6", "--max-expansions", "5",
            "--workers", "1", "--out", str(out)]


def _environment() -> dict[str, str]:
    return {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def untimed(value):
    """`value` without the entries whose key ends in "seconds" (measured times)."""
    if isinstance(value, dict):
        return {k: untimed(v) for k, v in value.items() if not str(k).endswith("seconds")}
    if isinstance(value, list):
        return [untimed(v) for v in value]
    return value


def test_a_killed_sweep_resumes_without_rerunning_finished_trials(tmp_path: Path) -> None:
    trials, out = 5, tmp_path / "interrupted"
    proc = subprocess.Popen(_script(out, trials), cwd=tmp_path, env=_environment(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 60.0
        while not list((out / "trials").glob("*.json")):
            assert proc.poll() is None, f"the sweep ended ({proc.returncode}) before any trial"
            assert time.monotonic() < deadline, "no trial finished within 60 s"
            time.sleep(0.02)
    finally:
        with contextlib.suppress(ProcessLookupError):  # our own session: the sweep and children
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    kept = {p.name: (p.stat().st_mtime_ns, p.read_text()) for p in (out / "trials").glob("*")}
    assert 1 <= len(kept) < trials, f"the kill must land mid-sweep: {sorted(kept)}"
    assert all(name.endswith(".json") for name in kept), f"no partial files: {sorted(kept)}"

    env = _environment()
    resumed = subprocess.run(_script(out, trials), cwd=tmp_path, env=env, capture_output=True,
                             text=True, timeout=120, check=False)
    assert resumed.returncode == 0, resumed.stderr
    assert f"resuming: {len(kept)} of {trials}" in resumed.stderr, resumed.stderr
    for name, (stamp, text) in kept.items():
        path = out / "trials" / name
        assert path.stat().st_mtime_ns == stamp and path.read_text() == text, f"{name} rerun"

    fresh = tmp_path / "uninterrupted"
    whole = subprocess.run(_script(fresh, trials), cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=120, check=False)
    assert whole.returncode == 0, whole.stderr
    a = json.loads((out / "results.json").read_text())
    b = json.loads((fresh / "results.json").read_text())
    for key in ("summary", "trials", "params", "errors"):
        # Measured times differ from run to run; every other value must not.
        assert untimed(a[key]) == untimed(b[key]), (
            f"results.json {key}: resumed {a[key]} != whole {b[key]}")
    for k in range(trials):
        name = a["trials"][k]["name"]
        ra = json.loads((out / "trials" / f"{name}.json").read_text())
        rb = json.loads((fresh / "trials" / f"{name}.json").read_text())
        assert ra["result"] == rb["result"], f"{name}: {ra['result']} != {rb['result']}"


def test_local_pool_and_dask_cluster_give_the_in_process_results(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    trials = [tiny_climb("crevasse", "crevasse", 2), tiny_climb("shaft", "shaft", 1)]
    here = run_sweep(trials, tmp_path / "here", workers=1, stream=io.StringIO())
    pool = run_sweep(trials, tmp_path / "pool", workers=2, stream=io.StringIO())
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:"), "loopback only"
        dask = run_sweep(trials, tmp_path / "dask", cluster=cluster.scheduler_address,
                         stream=io.StringIO())
    for a, b, c in zip(here, pool, dask, strict=True):
        assert a["error"] is None and b["error"] is None and c["error"] is None, (a, b, c)
        assert a["result"] == b["result"] == c["result"], (
            f"{a['name']}: in process {a['result']}, pool {b['result']}, dask {c['result']}")
        assert a["result"]["naive"]["success"] or a["result"]["naive"]["reason"], a["result"]
    assert {r["worker"]["pid"] for r in here} == {os.getpid()}, "workers=1 runs in process"
    assert os.getpid() not in {r["worker"]["pid"] for r in pool + dask}, (
        "the pool and the cluster must run the trials in other processes")
    for r in dask:
        assert json.loads(trial_path(tmp_path / "dask", r["name"]).read_text()) == r


@pytest.mark.parametrize(("workers", "cores", "env", "threads"), [
    (1, 2, None, 2), (2, 2, None, 1), (3, 2, None, 1), (2, 8, None, 4),
    (1, 2, "8", 2), (2, 8, "2", 2), (2, 8, "16", 4), (1, 4, "1", 1)])
def test_workers_times_threads_never_exceed_the_cores(monkeypatch: pytest.MonkeyPatch,
                                                      workers: int, cores: int, env, threads
                                                      ) -> None:
    """Each worker's kernel threads: its share of the cores, lowered (never raised) by
    RBP_THREADS (issue 32)."""
    from rb_drake.kernel.threads import worker_threads

    if env is None:
        monkeypatch.delenv("RBP_THREADS", raising=False)
    else:
        monkeypatch.setenv("RBP_THREADS", env)
    got = worker_threads(workers, cores)
    assert got == threads, f"{workers} workers on {cores} cores, RBP_THREADS={env}: {got}"
    assert got * workers <= cores or got == 1


def test_a_pool_records_its_workers_threads_and_load(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Two workers started with RBP_THREADS larger than their share each run on their share
    and record it, with the cores and the load, in the trial's record."""
    monkeypatch.setenv("RBP_THREADS", "64")
    cores = os.cpu_count() or 1
    records = run_sweep([parse_trial(f"t{i}", i) for i in range(2)], tmp_path, workers=2)
    for record in records:
        worker = record["worker"]
        assert worker["threads"] == max(1, cores // 2), worker
        assert worker["cores"] == cores and (worker["load"] is None or worker["load"] >= 0)


def test_an_edited_finished_record_is_refused_naming_its_field(tmp_path: Path) -> None:
    """A finished climb record edited since (p_path "x", 1e308, NaN or missing, result null)
    ended the resumed sweep's summary in a traceback: it is refused in one line naming the
    file and the field; the record as written still resumes."""
    import math

    from experiments.common import CLIMB_TRIAL

    trial = tiny_climb("c0", "shaft", 1)
    row = {"success": True, "reason": "", "p_path": 0.92, "p_grasps": 0.99, "regrasps": 7,
           "phases": {"body": 7, "reach": 7}}

    def stored(result: object) -> None:
        trial_path(tmp_path, trial.name).parent.mkdir(parents=True, exist_ok=True)
        trial_path(tmp_path, trial.name).write_text(json.dumps(
            {"format": "rbp-trial/1", "name": trial.name, "function": CLIMB_TRIAL,
             "params": trial.params, "result": result, "error": None,
             "timing": {"naive": {"footstep": 0.5}}, "worker": {}}))

    stored({"cave": None, "naive": row})
    assert run_sweep([trial], tmp_path, workers=1, stream=io.StringIO())[0]["result"]["naive"]
    cases = [(None, r"result: expected an object, got null"),
             ({"naive": {**row, "p_path": "x"}}, r"result\.naive\.p_path: must be null or a"),
             ({"naive": {**row, "p_path": 1e308}}, r"result\.naive\.p_path: must be"),
             ({"naive": {**row, "p_path": math.nan}}, r"\(file\): holds NaN"),
             ({"naive": {k: v for k, v in row.items() if k != "p_path"}},
              r"result\.naive\.p_path: missing"),
             ({"naive": {**row, "regrasps": True}}, r"result\.naive\.regrasps: must be"),
             ({"naive": [1]}, r"result\.naive: expected an object, got a list")]
    for result, words in cases:
        stored(result)
        with pytest.raises(SweepError, match=rf"c0\.json: {words}.*delete the file"):
            run_sweep([trial], tmp_path, workers=1, stream=io.StringIO())


def test_param_sweep_values_within_the_scenario_ranges() -> None:
    """Swept values a scenario would refuse (gravity 1e4 hung the planner, 1e308 failed with
    an unrelated error) are refused with the parameter's range."""
    from experiments.param_sweep import main

    for param, value, words in (("gravity", "1e4", "at most 1000"),
                                ("gravity", "1e308", "at most 1000"),
                                ("gravity", "nan", "above 0"),
                                ("gripper_scale", "1e9", "1e-06 to 10000"),
                                ("anchor_density", "50", "at most 20"),
                                ("p_min", "1", "below 1")):
        err = io.StringIO()
        with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as exit_info:
            main(["--param", param, "--values", value, "--trials", "1"])
        assert exit_info.value.code == 2
        assert f"--values: {value} is not a valid {param}: must be" in err.getvalue()
        assert words in err.getvalue(), err.getvalue()
