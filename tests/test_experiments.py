"""Experiment scripts run end to end at a tiny size, through runpy, in a temporary folder."""

from __future__ import annotations

import json
import runpy
import sys
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def run_script(name: str, args: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "argv", [name, *args])
    with pytest.raises(SystemExit) as done:
        runpy.run_path(str(EXPERIMENTS / f"{name}.py"), run_name="__main__")
    assert done.value.code == 0, f"{name} exited with {done.value.code}"


def test_bench_footsteps_tiny(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    run_script("bench_footsteps", ["--trials", "1", "--first-seed", "4", "--length", "3.0",
                                   "3.2", "--max-expansions", "5", "--out", str(tmp_path)],
               monkeypatch)
    result = json.loads((tmp_path / "bench_footsteps.json").read_text())
    trials = result["trials"]
    assert {t["planner"] for t in trials} == {"rbp", "naive"}, trials
    for t in trials:
        assert t["seconds"] > 0.0, t
        if t["success"]:
            assert 0.0 <= t["p_path"] <= 1.0, t
        else:
            assert t["p_path"] is None and t["reason"], t
    for name in ("rbp", "naive"):
        summary = result["summary"][name]
        assert summary["trials"] == 1, summary
        assert summary["seconds_min"] <= summary["seconds_median"] <= summary["seconds_max"]


@pytest.mark.parametrize("mode", [[], ["--all-cores"]])
def test_footstep_ab_runs_both_trees(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     mode: list[str]) -> None:
    """footstep_ab runs a cave in the old and the new tree (here the same tree twice), at
    once or one after the other: both sides report the same outcome, and the ratio is the
    wall times' quotient."""
    tree = EXPERIMENTS.parent
    out = tmp_path / "ab.json"
    run_script("footstep_ab", ["--old", str(tree), "--new", str(tree), "--seeds", "51",
                               "--thorough", "--time-limit", "60", "--out", str(out), *mode],
               monkeypatch)
    result = json.loads(out.read_text())
    assert result["all_cores"] == bool(mode), result
    (row,) = result["caves"]
    assert (row["kind"], row["seed"]) == ("shaft", 51), row
    for side in ("old", "new"):
        assert row[side]["stop"] == "noroute", row  # benchmark shaft 51 has no route
        assert row[side]["wall"] > 0.0 and row[side]["cpu"] > 0.0, row
    assert row["old"]["expansions"] == row["new"]["expansions"], row
    assert row["ratio"] == pytest.approx(row["new"]["wall"] / row["old"]["wall"], rel=1e-12)
    assert result["summary"]["same_outcome"] == 1, result["summary"]


def test_footstep_ab_refuses_a_folder_that_is_not_rbp(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "argv", ["footstep_ab", "--old", str(tmp_path), "--seeds", "1",
                                      "--out", str(tmp_path / "x.json")])
    with pytest.raises(SystemExit) as done:
        runpy.run_path(str(EXPERIMENTS / "footstep_ab.py"), run_name="__main__")
    assert done.value.code == 2
    assert not (tmp_path / "x.json").exists()
