"""OMPL benchmark logs (experiments.ompl_log): what the experiments write is read back by OMPL's
own parser, `ompl_benchmark_statistics` (shipped with the ompl package), into the SQLite
database Planner Arena plots, with a row per cave and planner, the declared property types,
and the values of the experiment's results.json.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from datetime import UTC, datetime
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from experiments.ompl_log import (
    RUN_PROPERTIES,
    STOPS,
    BenchmarkLog,
    PlannerLog,
    Run,
    baseline_log,
    log_text,
    write_log,
)

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "docs" / "figures" / "baseline-10.ompl.log"

pytest.importorskip("ompl.ompl_benchmark_statistics",
                    reason="the ompl package's ompl_benchmark_statistics parses the logs")


def parse(log: Path, tmp_path: Path) -> sqlite3.Connection:
    """The log in SQLite, by OMPL's own script run as a program (as a user would)."""
    db = tmp_path / f"{log.name}.db"
    done = subprocess.run([sys.executable, "-m", "ompl.ompl_benchmark_statistics", str(log),
                           "-d", str(db)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, f"the OMPL parser refused {log}: {done.stderr[-2000:]}"
    conn = sqlite3.connect(db)
    conn.row_factory = sqlite3.Row
    return conn


def runs_of(conn: sqlite3.Connection, planner: str) -> list[sqlite3.Row]:
    return conn.execute("SELECT runs.* FROM runs JOIN plannerConfigs ON "
                        "plannerConfigs.id = runs.plannerid WHERE plannerConfigs.name = ? "
                        "ORDER BY runs.id", (planner,)).fetchall()


def stop_names(conn: sqlite3.Connection) -> dict[int, str]:
    return {row["value"]: row["description"]
            for row in conn.execute("SELECT * FROM enums WHERE name = 'stop'")}


def column_types(conn: sqlite3.Connection, table: str) -> dict[str, str]:
    return {row["name"]: row["type"] for row in conn.execute(f"PRAGMA table_info({table})")}


def test_a_ten_cave_comparison_log_parses_into_sqlite(tmp_path: Path) -> None:
    """A real comparison, 10 short caves, rbp and the naive baseline, footsteps only: the
    database holds 10 runs per planner whose values are results.json's, and rbp's anytime
    progress ends at the cost of the route it returned."""
    from experiments.baseline_comparison import main

    out, log = tmp_path / "run", tmp_path / "baseline.ompl.log"
    code = main(["--trials", "10", "--planners", "rbp,naive", "--length", "2.0", "2.5",
                 "--max-expansions", "30", "--workers", "1", "--out", str(out),
                 "--ompl-log", str(log)])
    assert code == 0, f"the comparison exited {code}"
    results = json.loads((out / "results.json").read_text())
    conn = parse(log, tmp_path)
    planners = [row["name"] for row in conn.execute("SELECT name FROM plannerConfigs")]
    assert planners == ["rbp", "naive"], f"planners in the database: {planners}"
    types = column_types(conn, "runs")
    for declared in RUN_PROPERTIES:
        name, kind = declared.rsplit(" ", 1)
        assert types.get(name) == kind, f"runs.{name}: type {types.get(name)}, want {kind}"
    experiment = conn.execute("SELECT * FROM experiments").fetchone()
    assert experiment["name"] == "baseline_comparison" and experiment["runcount"] == 10, \
        f"experiment row: {dict(experiment)}"
    assert experiment["version"].startswith("rbp "), f"version {experiment['version']!r}"
    stops = stop_names(conn)
    codes = dict(STOPS)
    for planner in planners:
        rows = runs_of(conn, planner)
        assert len(rows) == 10, f"{planner}: {len(rows)} runs in the database, want 10"
        for row, trial in zip(rows, results["trials"], strict=True):
            want = trial[planner]
            where = f"{planner} on {trial['name']}"
            assert bool(row["solved"]) == bool(want["success"]), f"{where}: solved"
            assert stops[row["stop"]] == codes[want["stop"]], \
                f"{where}: stop {stops[row['stop']]!r}, results.json {want['stop']!r}"
            assert row["cave_seed"] == trial["seed"], f"{where}: cave seed"
            assert row["time"] >= want["footstep_seconds"] - 1e-9, \
                f"{where}: run time {row['time']} < its footstep time"
            if want["success"]:
                assert row["regrasps"] == want["regrasps"], f"{where}: regrasps"
                assert abs(row["p_path"] - want["p_path"]) <= 1e-12, f"{where}: p_path"
                assert abs(row["p_grasps"] - want["p_grasps"]) <= 1e-12, f"{where}: p_grasps"
            else:
                assert row["p_path"] is None, f"{where}: a failed plan has no p_path"
    progress = conn.execute("SELECT runs.id, runs.cost, progress.* FROM progress JOIN runs ON "
                            "runs.id = progress.runid ORDER BY runs.id, progress.time")
    by_run: dict[int, list[sqlite3.Row]] = {}
    for row in progress:
        by_run.setdefault(row["runid"], []).append(row)
    solved_rbp = [r["id"] for r in runs_of(conn, "rbp") if r["solved"]]
    assert by_run and set(by_run) <= set(solved_rbp), \
        f"progress for runs {sorted(by_run)}, rbp's solved runs are {solved_rbp}"
    for run, samples in by_run.items():
        costs = [s["best_cost"] for s in samples]
        assert all(b <= a + 1e-12 for a, b in pairwise(costs)), \
            f"run {run}: the best cost rises over time: {costs}"
        assert abs(costs[-1] - samples[-1]["cost"]) <= 1e-9, \
            f"run {run}: progress ends at {costs[-1]}, the route costs {samples[-1]['cost']}"
        assert all(s["lower_bound"] <= s["best_cost"] + 1e-12 for s in samples), \
            f"run {run}: a lower bound above the cost"


def test_the_committed_ten_cave_log_parses(tmp_path: Path) -> None:
    """docs/figures/baseline-10.ompl.log (README: the command that made it) is read by OMPL's
    parser: four planners, 10 runs each, and the oracle proves some caves have no route."""
    conn = parse(COMMITTED, tmp_path)
    counts = {row["name"]: row["n"] for row in conn.execute(
        "SELECT plannerConfigs.name AS name, COUNT(*) AS n FROM runs JOIN plannerConfigs ON "
        "plannerConfigs.id = runs.plannerid GROUP BY plannerConfigs.name")}
    assert counts == {"rbp": 10, "rbp-sampled": 10, "naive": 10, "oracle": 10}, counts
    stops = stop_names(conn)
    oracle = [stops[r["stop"]] for r in runs_of(conn, "oracle")]
    assert set(oracle) <= {"route found", "no route proved"}, f"oracle stops: {oracle}"
    assert all(bool(r["solved"]) == (stops[r["stop"]] == "route found")
               for r in runs_of(conn, "oracle")), "oracle: solved is not 'route found'"


def synthetic_records() -> list[dict[str, Any]]:
    """Trial records as baseline_comparison keeps them (experiments.common.climb_trial), with
    each way a search ends; the third cave could not be generated."""
    def planner(stop: str | None, **extra: Any) -> dict[str, Any]:
        ok = stop == ""
        return {"success": ok, "reason": "" if ok else "why", "stop": stop,
                "p_path": 0.9 if ok else 0.0, "p_grasps": 0.95 if ok else None,
                "regrasps": 6 if ok else 0, "expansions": 12, "cost": 0.1 if ok else None,
                "bound": 1.5 if ok else None, "verified": ok, **extra}

    def timing(history: list[dict[str, float]] | None) -> dict[str, Any]:
        return {"footstep": 0.5, "total": 0.6, "search": {
            "peak_memory_mb": 300.0, "kept_memory_mb": 2.5, "history": history}}

    history = [{"seconds": 0.1, "cost": 0.2, "lower_bound": 0.05, "expansions": 5},
               {"seconds": 0.3, "cost": 0.1, "lower_bound": 0.0667, "expansions": 12}]
    no_cave = {"success": False, "reason": "no cave: no start", "p_path": None,
               "p_grasps": None, "regrasps": 0}
    return [
        {"params": {"kind": "shaft", "seed": 1},
         "result": {"a": planner(""), "b": planner("budget")},
         "timing": {"a": timing(history), "b": timing(None), "trial": 1.0}},
        {"params": {"kind": "rockfall", "seed": 2},
         "result": {"a": planner("noroute"), "b": planner("exhausted")},
         "timing": {"a": timing(None), "b": timing(None), "trial": 1.0}},
        {"params": {"kind": "crevasse", "seed": 3},
         "result": {"a": dict(no_cave), "b": dict(no_cave)}, "timing": {"trial": 0.1}},
    ]


def test_every_stop_and_missing_value_reads_back(tmp_path: Path) -> None:
    """Each stop reads back as its enum name; what was not measured (a failed plan's route,
    a cave never generated) is NULL; progress is per run, empty for runs without it."""
    params = {"trials": 3, "first_seed": 1, "kind": "mixed", "length": [3.0, 3.5],
              "max_expansions": 30, "motion": False}
    log = baseline_log(synthetic_records(), ["a", "b"], params, {"a": {"planner": "a"}},
                       {"host": "test host", "cpu": "x"}, datetime(2026, 1, 2, tzinfo=UTC))
    conn = parse(write_log(tmp_path / "synthetic.log", log), tmp_path)
    stops = stop_names(conn)
    got = {p: [stops.get(r["stop"]) for r in runs_of(conn, p)] for p in ("a", "b")}
    assert got == {"a": ["route found", "no route proved", dict(STOPS)["nocave"]],
                   "b": ["budget stop (expansions or time limit)",
                         "search exhausted (no proof)", dict(STOPS)["nocave"]]}, got
    a = runs_of(conn, "a")
    assert [r["solved"] for r in a] == [1, 0, 0], f"solved: {[r['solved'] for r in a]}"
    assert a[0]["p_path"] == 0.9 and a[1]["p_path"] is None and a[1]["regrasps"] is None, \
        "a failed plan's route numbers must be NULL"
    assert a[2]["time"] is None and a[2]["memory"] is None, "no cave: nothing was measured"
    progress = conn.execute("SELECT runid, time, best_cost, bound FROM progress "
                            "ORDER BY time").fetchall()
    assert [(r["runid"], r["time"]) for r in progress] == [(a[0]["id"], 0.1), (a[0]["id"], 0.3)], \
        f"progress rows {[tuple(r) for r in progress]}"
    assert abs(progress[0]["bound"] - 4.0) <= 1e-12, "bound: cost over lower bound"
    host = conn.execute("SELECT hostname FROM experiments").fetchone()["hostname"]
    assert host == "test_host", f"a host name with a space must be one word, got {host!r}"


def one_planner(name: str = "p", value: Any = 1.0) -> BenchmarkLog:
    return BenchmarkLog(experiment="e", version="rbp version 0", host="h",
                        started=datetime(2026, 1, 1), setup="s", cpu="c", seed=1, time_limit=0.0,
                        memory_limit=0.0, total_seconds=1.0,
                        planners=(PlannerLog(name, {}, (Run({"x REAL": value}),)),))


@pytest.mark.parametrize(("log", "why"), [
    (one_planner(name="two\nlines"), "a planner name on two lines"),
    (one_planner(value="a; b"), "a run value holding the separator"),
])
def test_what_the_parser_would_misread_is_refused(log: BenchmarkLog, why: str) -> None:
    with pytest.raises(ValueError):
        log_text(log)
        pytest.fail(f"{why} was written")


def test_an_unwritable_log_path_is_refused_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.baseline_comparison import main

    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit) as stopped:
        main(["--trials", "1", "--planners", "naive", "--out", str(tmp_path / "out"),
              "--ompl-log", str(tmp_path / "file" / "log")])
    err = capsys.readouterr().err.strip().splitlines()
    assert stopped.value.code == 2, f"exit {stopped.value.code}, want 2 (usage)"
    assert err and "--ompl-log" in err[-1], f"stderr does not name the option: {err}"
    assert not (tmp_path / "out").exists(), "trials ran before the log path was checked"


def test_route_quality_variants_are_planners(tmp_path: Path) -> None:
    """route_quality's cave records (experiments.common.route_variants): a planner per variant
    in the given order, a run per cave with its seconds and kept memory, and progress only for
    the variant whose search has a history."""
    from experiments.ompl_log import route_quality_log

    def variant(seconds: float, history: list[dict[str, float]] | None) -> dict[str, Any]:
        return {"success": True, "stop": "", "regrasps": 4, "cost": 0.3, "p_path": 0.8,
                "p_grasps": 0.85, "bound": 1.0, "expansions": 40, "seconds": seconds,
                "peak_memory_mb": 200.0, "kept_memory_mb": 3.0, "history": history}

    point = {"seconds": 0.2, "cost": 0.3, "lower_bound": 0.3, "expansions": 40}
    caves = [{"kind": "shaft", "seed": s, "first": variant(0.1 * s, None),
              "default": variant(0.2 * s, [point])} for s in (1, 2)]
    log = route_quality_log(caves, ["first", "default"], {"first_seed": 1, "kind": "mixed",
                                                          "length": [3.0, 3.5]},
                            {}, {"host": "h"}, datetime(2026, 1, 2, tzinfo=UTC), 2.0)
    conn = parse(write_log(tmp_path / "rq.log", log), tmp_path)
    assert [r["name"] for r in conn.execute("SELECT name FROM plannerConfigs")] == \
        ["first", "default"], "a planner per variant, in order"
    for name, scale in (("first", 0.1), ("default", 0.2)):
        rows = runs_of(conn, name)
        assert [r["time"] for r in rows] == pytest.approx([scale, 2 * scale], abs=1e-12), \
            f"{name}: run times are not the caves' seconds"
        assert all(r["memory"] == 3.0 and r["solved"] == 1 for r in rows), name
    owners = {r["runid"] for r in conn.execute("SELECT runid FROM progress")}
    assert owners == {r["id"] for r in runs_of(conn, "default")}, \
        f"progress belongs to runs {owners}, want the default variant's"
