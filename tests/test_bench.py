"""`rbp bench` (experiments.bench) run end to end at a tiny size, through runpy, in a temporary
folder: every section's results, ours against SLSQP on the exact objective, the SCP answers
re-checked with check_poses, --compare's ratios, and a run without cvxpy."""

from __future__ import annotations

import importlib.util
import json
import math
import runpy
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rb_drake.feasibility import check_poses
from rb_drake.scenario import bundled_caves, load_scenario

TINY = ["--samples", "10", "--moves", "1", "--ipopt-iterations", "150", "--caves", "1",
        "--max-expansions", "3"]
OURS = ("allocate", "allocate-batch", "ForceAllocator-osqp", "ForceAllocator-clarabel")
# Ours against SLSQP (ftol 1e-12 on J, the exact objective). J is a sum of log-probabilities:
# 1e-6 is a relative error of 1e-6 in the configuration's probability, far below what any
# p_min decision needs. Tensions are compared only where log Phi is curved (r < -1e-3): there
# the curvature of J along the statics family is at least ~1e-4 N^-2, so an objective within
# 1e-12 pins f to ~1e-4 N; 1e-2 N leaves room for SLSQP's own stopping rule.
J_TOL = 1e-6
F_TOL = 1e-2    # N
HAS_CVXPY = importlib.util.find_spec("cvxpy") is not None


def run_bench(args: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "argv", ["bench", *args])
    with pytest.raises(SystemExit) as done:
        runpy.run_module("experiments.bench", run_name="__main__")
    assert done.value.code == 0, f"bench {args} exited with {done.value.code}"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("bench")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(out)
        run_bench([*TINY, "--out", str(out)], mp)
    return out, json.loads((out / "bench.json").read_text())


def finite(x: Any) -> bool:
    return x is not None and math.isfinite(x)


def test_every_section_reports_times_and_finite_errors(tiny) -> None:
    _, result = tiny
    assert set(result["sections"]) == {"allocation", "scp", "footstep"}, result["sections"]
    alloc = result["sections"]["allocation"]
    assert len(alloc["cases"]) >= 8, f"only {len(alloc['cases'])} allocation cases"
    methods = alloc["summary"]["methods"]
    expected = {*OURS, "scipy-slsqp"} | ({"cvxpy-clarabel"} if HAS_CVXPY else set())
    assert expected <= set(methods), f"methods {sorted(methods)} miss {expected - set(methods)}"
    for name, groups in methods.items():
        m = groups["all"]
        assert m["solves"] == len(alloc["cases"]), (name, m)
        assert m["ms_median"] > 0.0, f"{name}: time {m['ms_median']}"
        for key in ("J_gap_max", "r_error_max", "f_error_max"):
            assert finite(m[key]) and m[key] >= 0.0, f"{name}: {key} = {m[key]}"
    if HAS_CVXPY:
        model = methods["cvxpy-clarabel"]["all"]["model_error_max"]
        assert finite(model), f"cvxpy's approximation error must be reported, got {model}"

    scp = result["sections"]["scp"]
    assert scp["cases"], "no SCP phase"
    for row in scp["cases"]:
        for side in ("ours", "ipopt"):
            assert row[side]["seconds"] > 0.0, (side, row[side]["seconds"])
    for key in ("ours_seconds_median", "ipopt_seconds_median", "time_ratio_median"):
        assert scp["summary"][key] > 0.0, (key, scp["summary"][key])

    foot = result["sections"]["footstep"]
    assert {r["planner"] for r in foot["cases"]} == {"rbp", "naive"}, foot["cases"]
    for row in foot["cases"]:
        assert row["seconds"] > 0.0, row
        if row["success"]:
            assert 0.0 <= row["p_path"] <= 1.0, row
        else:
            assert row["p_path"] is None and row["reason"], row


def test_ours_agree_with_slsqp_on_the_exact_objective(tiny) -> None:
    _, result = tiny
    for case in result["sections"]["allocation"]["cases"]:
        slsqp = case["methods"]["scipy-slsqp"]
        where = f"{case['cave']} {case['group']} pose {case['pose']} stance {case['stance']}"
        assert slsqp["ok"], f"SLSQP failed at {where}"
        for name in OURS:
            ours = case["methods"][name]
            assert ours["ok"], f"{name} failed at {where}"
            assert abs(ours["J"] - slsqp["J"]) <= J_TOL, (
                f"{name}: J {ours['J']:.9f} against SLSQP's {slsqp['J']:.9f} at {where}")
            if case["r_best"] < -1e-3:
                df = np.abs(np.array(ours["tensions"], dtype=float)
                            - np.array(slsqp["tensions"], dtype=float))
                assert np.nanmax(df) <= F_TOL, f"{name}: tensions differ by {df} N at {where}"


def test_scp_answers_are_feasible_and_ipopt_is_reported(tiny) -> None:
    _, result = tiny
    caves = bundled_caves()
    for row in result["sections"]["scp"]["cases"]:
        where = f"{row['cave']} {row['kind']} phase, {row['steps']} steps"
        assert abs(row["merit_mismatch_at_seed"]) < 1e-9, (
            f"IPOPT's objective differs from planning.scp's merit at the seed by "
            f"{row['merit_mismatch_at_seed']} ({where})")
        ours = row["ours"]
        assert ours["feasible"], f"ours infeasible ({where}): {ours['reason']}"
        scn = load_scenario(caves[row["cave"]])
        stance = scn.stance(row["stance"])
        if row["boom"] is not None:
            stance = stance.without(row["boom"])
        tips = None if row["tips"] is None else np.array(row["tips"])
        check = check_poses(scn, stance, np.array(ours["poses"]), tips)
        assert check.feasible.all(), (
            f"ours: check_poses rejects steps {np.flatnonzero(~check.feasible).tolist()} "
            f"({where})")
        ipopt = row["ipopt"]
        assert ipopt["status"], f"IPOPT's status is missing ({where})"
        assert finite(ipopt["raw_residual"]), f"IPOPT's statics residual ({where})"
        for key in ("merit", "r_min", "r_sum"):
            assert finite(ours[key]), f"ours {key} = {ours[key]} ({where})"
            assert ipopt[key] is None or finite(ipopt[key]), f"ipopt {key} = {ipopt[key]}"
    summary = result["sections"]["scp"]["summary"]
    if summary["both_feasible"]:
        for key in ("merit_difference_median", "r_sum_difference_median",
                    "r_min_difference_median"):
            assert finite(summary[key]), f"{key} = {summary[key]} though both were feasible"


def test_compare_prints_new_over_old(tiny, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    out, first = tiny
    capsys.readouterr()
    monkeypatch.chdir(tmp_path)
    second = tmp_path / "second.json"
    run_bench(["--only", "footstep", "--caves", "1", "--max-expansions", "3", "--json",
               str(second), "--compare", str(out / "bench.json")], monkeypatch)
    printed = capsys.readouterr().out
    new = json.loads(second.read_text())
    assert set(new["sections"]) == {"footstep"}, new["sections"]
    key = "footstep.rbp.seconds_median"
    line = next((ln for ln in printed.splitlines() if ln.strip().startswith(key + " ")), None)
    assert line is not None, f"no ratio line for {key} in:\n{printed}"
    old_v = first["sections"]["footstep"]["summary"]["rbp"]["seconds_median"]
    new_v = new["sections"]["footstep"]["summary"]["rbp"]["seconds_median"]
    # Printed to 4 significant digits: the rounding error is at most 5e-4 of the value, whatever
    # the ratio (a fixed count of decimals failed whenever the first run compiled the kernel).
    assert float(line.split()[-1]) == pytest.approx(new_v / old_v, rel=5.01e-4), (
        f"printed ratio {line!r}, want {new_v / old_v:.6g}")
    assert not any(ln.strip().startswith("allocation.") for ln in printed.splitlines()), (
        "metrics of sections not run again must not be compared")


def test_without_cvxpy_the_allocation_section_skips_it(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    monkeypatch.setitem(sys.modules, "cvxpy", None)  # import cvxpy now raises ImportError
    monkeypatch.chdir(tmp_path)
    run_bench(["--only", "allocation", "--samples", "4", "--out", str(tmp_path)], monkeypatch)
    printed = capsys.readouterr().out
    assert "cvxpy is not installed" in printed, printed
    summary = json.loads((tmp_path / "bench.json").read_text())["sections"]["allocation"][
        "summary"]
    assert summary["cvxpy"] is False, summary["cvxpy"]
    assert not [m for m in summary["methods"] if m.startswith("cvxpy")], summary["methods"]
    assert {"allocate", "scipy-slsqp"} <= set(summary["methods"]), summary["methods"]


def test_unknown_section_is_refused(monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(sys, "argv", ["bench", "--only", "allocation,nope"])
    with pytest.raises(SystemExit) as done:
        runpy.run_module("experiments.bench", run_name="__main__")
    assert done.value.code == 2, done.value.code
    assert "nope" in capsys.readouterr().err


def test_rbp_bench_hands_every_option_to_experiments_bench(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """`rbp bench` is registered once, in rbp/cli.py, and forwards its options unchanged."""
    import experiments.bench
    from rbp.cli import main

    seen = []
    monkeypatch.setattr(experiments.bench, "run", lambda args: seen.append(args) or 0)
    assert main(["bench", "--only", "scp", "--moves", "2", "--samples", "7", "--caves", "5",
                 "--compare", "old.json"]) == 0
    (args,) = seen
    assert (args.only, args.moves, args.samples, args.caves, args.compare) == (
        "scp", 2, 7, 5, "old.json"), vars(args)
    assert args.json is None and args.out == "out/bench", vars(args)


def test_compare_refuses_a_file_that_is_not_a_bench_result(tmp_path, capsys) -> None:
    """A GeoJSON given to --compare was compared ('no metric in common', exit 0): a results
    file has its format (when given) and its sections."""
    from experiments.bench import main

    for text, words in (('{"type": "FeatureCollection", "features": []}', "sections: missing"),
                        ('{"format": "geojson", "sections": {}}', "format: must be 'rbp-bench/1'")):
        old = tmp_path / "old.json"
        old.write_text(text)
        assert main(["--only", "allocation", "--compare", str(old), "--out",
                     str(tmp_path / "b")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err, err
