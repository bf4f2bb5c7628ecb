"""Every experiment script end to end at a tiny size (short caves, small caps, one or two
trials, in this process), run as `python -m experiments.NAME` through runpy in a temporary
folder: each must exit 0 and write its results.json and its figures, with consistent numbers.
"""

from __future__ import annotations

import argparse
import json
import runpy
import sys
from pathlib import Path
from typing import Any

import pytest

from experiments.cli import EXPERIMENTS, add_experiment_command

TINY = ["--length", "3.0", "3.2", "--max-expansions", "10", "--workers", "1"]
ROOT = Path(__file__).resolve().parents[1]
PNG = b"\x89PNG\r\n\x1a\n"

pytestmark = pytest.mark.filterwarnings(
    "ignore:.*found in sys.modules after import of package:RuntimeWarning")


def run_experiment(name: str, args: list[str], out: Path,
                   monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Run experiments.NAME as a script with --out OUT and return its results.json."""
    monkeypatch.chdir(out.parent)
    monkeypatch.setattr(sys, "argv", [f"{name}.py", *args, "--out", str(out)])
    with pytest.raises(SystemExit) as done:
        runpy.run_module(f"experiments.{name}", run_name="__main__")
    assert done.value.code == 0, f"{name} exited with {done.value.code}"
    return json.loads((out / "results.json").read_text())


def assert_png(path: Path) -> None:
    assert path.is_file() and path.read_bytes()[:8] == PNG, f"{path}: no PNG written"


def assert_quantiles(q: dict[str, Any], what: str) -> None:
    if q["n"]:
        assert q["min"] <= q["q1"] <= q["median"] <= q["q3"] <= q["max"], f"{what}: {q}"
    else:
        assert q["median"] is None, f"{what}: {q}"


def test_baseline_comparison(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "baseline"
    result = run_experiment("baseline_comparison", ["--trials", "2", *TINY, "--oracle-time",
                                                    "20"], out, monkeypatch)
    assert_png(out / "baseline.png")
    names = sorted(f.stem for f in (out / "trials").glob("*.json"))
    assert len(names) == 4 and sum(n.startswith("oracle-") for n in names) == 2, (
        f"one record per cave and one per cave for the oracle, which runs alone: {names}")
    assert [t["kind"] for t in result["trials"]] == ["shaft", "crevasse"], "kinds alternate"
    oracle = result["oracle"]
    assert sum(oracle["labels"].values()) == 2, oracle
    for t in result["trials"]:
        assert t["label"] in ("route", "noroute", "undecided"), t
        assert (t["label"] == "route") == t["oracle"]["success"], t
        assert (t["label"] == "noroute") == (t["oracle"]["stop"] in ("noroute", "nostart")), t
    for planner, line in oracle["planned_of_route"].items():
        assert line["planned"] <= line["route"] == oracle["labels"]["route"], (planner, line)
    for planner in ("rbp", "rbp-sampled", "oracle", "naive"):
        s = result["summary"][planner]
        assert s["p_path_over_0.95"] <= s["p_path_over_0.90"] <= s["successes"] <= s["trials"] \
            == 2, s
        assert_quantiles(s["p_path"], planner)
        for t in result["trials"]:
            row = t[planner]
            if row["success"]:  # the naive planner ignores grasps: its p_path may be 0
                lowest = 0.0 if planner == "naive" else 1e-12
                assert lowest <= row["p_path"] <= 1.0, row
            else:
                assert row["p_path"] is None and row["reason"], f"a failure says why: {row}"


def test_timing_table(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "timing"
    result = run_experiment("timing_table", ["--trials", "1", *TINY], out, monkeypatch)
    assert_png(out / "timing.png")
    table = (out / "timing_table.md").read_text()
    for paper in ("66.19", "0.0123", "0.0839", "10.8", "0.0417", "50.09"):
        assert paper in table, f"the paper's {paper} s missing from the table"
    assert result["machine"]["cpu"] in table and "Drake" in table, table
    rows = result["timing"]
    assert set(rows) == {"footstep", "seed_body", "scp_body", "seed_reach", "scp_reach"}, rows
    assert rows["footstep"]["rbp"]["n"] == rows["footstep"]["naive"]["n"] == 1, rows["footstep"]
    for key, row in rows.items():
        assert_quantiles(row["rbp"], key)
        assert row["rbp"]["n"] <= result["summary"]["rbp_successes"] or key == "footstep", row


def test_snapshots(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from planning.plan import validate

    out = tmp_path / "snapshots"
    result = run_experiment("snapshots", ["--kind", "crevasse", "--seed", "2", "--length",
                                          "3.0", "3.2", "--max-expansions", "10"],
                            out, monkeypatch)
    assert_png(out / "snapshots.png")
    plan = json.loads((out / "plan.json").read_text())
    validate(plan)
    assert result["plan"]["success"] == plan["success"], result["plan"]
    assert result["attempts"][-1]["seed"] == int(plan["scenario"]["name"].split("-")[-1]), (
        "the plan drawn is the last cave tried")


def test_seed_vs_scp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "scp"
    result = run_experiment("seed_vs_scp", ["--trials", "1", "--kind", "shaft", *TINY], out,
                            monkeypatch)
    assert_png(out / "scp.png")
    rows, summary = result["phases"], result["summary"]
    assert summary["plans"] == 1, "the tiny shaft (seed 1) has a plan"
    assert sum(summary[k]["phases"] for k in ("body", "reach")) == len(rows) > 0, summary
    for r in rows:
        assert 0.0 <= r["seed_min"] <= r["seed_mean"] <= 1.0 + 1e-12, r
        assert 0.0 <= r["min"] <= r["mean"] <= 1.0 + 1e-12, r
    for kind in ("body", "reach"):
        s = summary[kind]
        assert s["min_raised"] + s["min_lowered"] <= s["phases"], s
        assert_quantiles(s["gain_mean"], kind)
    fig6 = result["fig6"]
    assert fig6["reproduces_trial"], "planning the trial's cave again must give its record"
    assert set(fig6["phases"]) == {"body", "reach"}, fig6
    for kind, entry in fig6["phases"].items():
        assert_png(Path(entry["figure"]))
        assert any(r["phase"] == entry["phase"] and r["kind"] == kind for r in rows), entry


def test_rig_experiment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "rig"
    result = run_experiment("rig_experiment", [], out, monkeypatch)
    assert_png(out / "rig.png")
    assert (out / "rig.lcm").stat().st_size > 0, "the run's log"
    rig = result["rig"]
    assert rig["simulated"] and rig["lcm_url"].startswith("memq://"), rig
    assert rig["statuses"] == rig["commands"] > 0, rig
    for anchor, p in result["anchors"].items():
        assert 0.0 < p["min"] <= min(p["start"], p["end"]) <= 1.0, (anchor, p)
        assert result["min_p_all_grasps"] <= p["min"] + 1e-12, (anchor, p)
    assert result["plan"]["p_min"] >= 0.95, f"every planned configuration holds: {result['plan']}"


def test_monte_carlo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "mc"
    result = run_experiment("monte_carlo", ["--trials", "1", "--kind", "crevasse",
                                            "--first-seed", "2", "--runs", "50", *TINY],
                            out, monkeypatch)
    assert_png(out / "calibration.png")
    plans = result["plans"]
    assert len(plans) + len(result["failed_plans"]) == 1, result
    for p in plans:
        lo, hi = p["ci95"]
        assert p["runs"] == 50 and 0 <= p["successes"] <= 50, p
        assert lo <= p["rate"] <= hi, f"the interval holds the rate: {p}"
    pooled = result["summary"]["pooled"]
    assert sum(b["runs"] for b in pooled) == 50 * len(plans), pooled
    assert result["summary"]["p_path_inside_ci95"] <= len(plans), result["summary"]


def test_param_sweep(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "sweep"
    result = run_experiment("param_sweep", ["--param", "anchor_density", "--values", "2,3",
                                            "--trials", "1", "--kind", "crevasse",
                                            "--first-seed", "2", *TINY], out, monkeypatch)
    assert_png(out / "param_sweep-anchor_density.png")
    assert [s["value"] for s in result["summary"]] == [2.0, 3.0], result["summary"]
    for s in result["summary"]:
        assert s["trials"] == 1 and 0 <= s["successes"] <= 1, s
        lo, hi = s["success_ci95"]
        assert lo <= s["success_rate"] <= hi, s
    assert {t["value"] for t in result["trials"]} == {2.0, 3.0}, result["trials"]


def test_rbp_experiment_command_runs_the_script(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    parser = argparse.ArgumentParser(prog="rbp")
    add_experiment_command(parser.add_subparsers(dest="command", required=True))
    out = tmp_path / "cli"
    args = parser.parse_args(["experiment", "baseline_comparison", "--trials", "1",
                              "--planners", "naive", "--length", "2.5", "2.6", "--workers",
                              "1", "--out", str(out)])
    assert args.func(args) == 0
    result = json.loads((out / "results.json").read_text())
    assert list(result["summary"]) == ["naive"], result["summary"]
    with pytest.raises(SystemExit) as bad:
        parser.parse_args(["experiment", "no_such_experiment"])
    assert bad.value.code == 2
    for name in EXPERIMENTS:
        module = ROOT / "experiments" / f"{name}.py"
        assert "def main(" in module.read_text(), f"{module}: no main()"


def test_calibration_intervals_are_simultaneous() -> None:
    """The intervals of n plans hold all n rates with probability at least 95 %: each misses
    with probability at most 0.05 / n (the union bound), and one plan's is the 95 % interval."""
    from scipy.stats import norm

    from experiments.calibration import simultaneous_z

    assert abs(simultaneous_z(1) - 1.959963984540054) < 1e-9
    for n in (1, 2, 12, 100):
        miss = 2.0 * norm.sf(simultaneous_z(n))
        assert abs(n * miss - 0.05) < 1e-12, (n, miss)


def test_calibration(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                     capsys: pytest.CaptureFixture[str]) -> None:
    """The calibration experiment on one short cave (the set patched in): a row per plan whose
    interval holds its rate, `calibrated` as defined, the figure, and a second run that
    resumes from the trial records; an unknown cave is refused with exit status 2."""
    import experiments.calibration as calibration

    monkeypatch.setattr(calibration, "CAVES", {"short": {"kind": "shaft", "seed": 2,
                                                         "length": [3.0, 3.2]}})
    out = tmp_path / "cal"
    args = ["--runs", "200", "--workers", "1", "--out", str(out)]
    assert calibration.main(args) == 0
    result = json.loads((out / "results.json").read_text())
    assert_png(out / "calibration.png")
    assert len(result["plans"]) + len(result["failed_plans"]) == 1, result
    for row in result["plans"]:
        lo, hi = row["ci95"]
        assert row["runs"] == 200 and lo <= row["rate"] <= hi, row
        flo, fhi = row["ci_simultaneous"]  # one plan: the simultaneous interval is the 95 %
        assert abs(flo - lo) < 1e-9 and abs(fhi - hi) < 1e-9, row
        expected = lo <= row["p_path"] <= hi and abs(row["p_sim"] - row["p_path"]) <= 0.005
        assert row["calibrated"] == expected, row
        assert row["verified"], f"the plan passes rbp check: {row}"
    capsys.readouterr()
    assert calibration.main(args) == 0
    assert "already finished" in capsys.readouterr().err
    with pytest.raises(SystemExit) as bad:
        calibration.main([*args, "--caves", "nowhere"])
    assert bad.value.code == 2


def test_long_climbs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two short shafts, the first-route variant: a table row per length, and the figure."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "long.json"
    monkeypatch.setattr(sys, "argv", ["long_climbs.py", "--lengths", "4", "5", "--kinds",
                                      "shaft", "--seeds", "5002", "--variants", "first",
                                      "--out", str(out)])
    with pytest.raises(SystemExit) as done:
        runpy.run_module("experiments.long_climbs", run_name="__main__")
    assert done.value.code == 0
    result = json.loads(out.read_text())
    assert [r["length"] for r in result["table"]] == [4.0, 5.0]
    for cave in result["caves"]:
        run = cave["first"]
        assert cave["climb"] > 0
        if run["success"]:
            assert run["regrasps"] >= 1 and 0 < run["p_path"] <= 1, run
    for row in result["table"]:
        assert row["routes"] <= row["caves"] == 1, row
        if row["routes"]:
            cave = next(c for c in result["caves"] if c["length"] == row["length"])
            assert row["regrasps_per_metre"] == pytest.approx(
                cave["first"]["regrasps"] / cave["climb"], rel=1e-12), row
    assert_png(out.with_suffix(".png"))
