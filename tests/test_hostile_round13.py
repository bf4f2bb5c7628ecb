"""Probe 13 (session 28): command-line numbers and file names as a person types them, and an
import refusal that names its option."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cli_helpers import one_error_line

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)


@pytest.mark.parametrize("text", ["2_0", "４.5", "0x10", "5.", "1e"])
def test_a_number_with_underscores_or_other_digits_is_refused(tmp_path, text):
    """float() reads "2_0" as 20 and full-width digits as digits; "5." is a plain number."""
    out = tmp_path / "c.yaml"
    result = run("scenario", "generate", "--kind", "shaft", "--length", text, "21", "-o", str(out))
    if text == "5.":
        assert result.returncode == 0, f"'5.' refused: {result.stderr[-300:]}"
        return
    one_error_line(result, "--length", repr(text))
    assert not out.exists(), "a refused command wrote its output"


def test_a_file_name_with_a_trailing_slash_is_refused(tmp_path):
    """pathlib.Path("plan.json/") is Path("plan.json"): the slash must not be dropped."""
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"format": "reachbot-plan/1"}))
    line = one_error_line(run("check", f"{plan}/"), "plan", "ends with '/'", "not a directory")
    assert f"'{plan}/'" in line, f"the name is not shown as given: {line}"
    line = one_error_line(run("scenario", "check", f"{DEMO}/"), "scenario", "ends with '/'")
    assert f"'{DEMO}/'" in line, f"the name is not shown as given: {line}"
    # a directory given with its slash is still a directory, refused by the reader
    line = one_error_line(run("check", f"{tmp_path}/"), "is a directory")
    assert "ends with '/'" not in line, f"a folder's slash called a typo: {line}"


def test_an_import_with_too_few_anchors_names_the_option(tmp_path):
    pytest.importorskip("shapely")
    rock = tmp_path / "rock.geojson"
    ring = [[-3, -1], [3, -1], [3, 6], [-3, 6], [-3, -1]]
    hole = [[-1, 0], [1, 0], [1, 5], [-1, 5], [-1, 0]]
    rock.write_text(json.dumps({"type": "Polygon", "coordinates": [ring, hole]}))
    out = tmp_path / "cave.yaml"
    line = one_error_line(run("scenario", "import", str(rock), "--anchor-density", "0.1",
                              "-o", str(out)), "--anchor-density", "anchors")
    assert line.startswith(f"error: {rock}: --anchor-density: "), line
    assert not out.exists(), "a refused import wrote its output"


def test_a_search_without_the_grasps_prints_no_overflow_warning():
    """`footstep.transition.ignore_grasps: true`: benchmark crevasse 30's search met poses
    whose -log P summed past the largest float, and numpy's "overflow encountered in reduce"
    reached the user's terminal (the edge's cost is infinite, as meant, now silently)."""
    import dataclasses
    import warnings

    from experiments.common import make_cave, variant_config
    from planning.footsteps import plan_footsteps

    base = variant_config("lattice", None)
    cfg = dataclasses.replace(base, transition=dataclasses.replace(base.transition,
                                                                   ignore_grasps=True))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        fp = plan_footsteps(make_cave("crevasse", 30, (4.5, 5.0)), cfg)
    assert fp.success, f"no route without the grasps on crevasse 30: {fp.reason}"


def test_rbp_check_says_the_route_quality_is_the_search_record(tmp_path):
    """A plan edited consistently (lower_bound = cost, bound 1, quality optimal) passes every
    rule: the verifier cannot prove optimality without searching again, so its ok line says
    the claim is the plan's record, not its own finding."""
    golden = json.loads((ROOT / "tests" / "data" / "golden" / "demo-shaft-current.json")
                        .read_text())
    golden.pop("verified", None)
    search = golden["search"]
    search["lower_bound"], search["bound"], search["quality"] = search["cost"], 1.0, "optimal"
    if search.get("history"):
        search["history"][-1]["lower_bound"] = search["cost"]
    path = tmp_path / "forged.json"
    path.write_text(json.dumps(golden))
    result = run("check", str(path))
    assert result.returncode == 0, result.stderr[-500:]
    assert "route optimal" in result.stdout and "not searched again" in result.stdout, \
        result.stdout


@pytest.mark.parametrize("args, needle", [
    (("baseline_comparison", "--planners", "naive,naive"), "--planners: each planner once"),
    (("baseline_comparison", "--planners", "naive,,rbp"), "--planners"),
    (("param_sweep", "--param", "p_min", "--values", "0.5,,0.6"), "--values: an empty item")])
def test_sweep_lists_with_repeats_or_empty_items_are_refused(tmp_path, args, needle):
    """A repeated planner ran its trials twice; an empty item of --values was dropped."""
    out = tmp_path / "out"
    one_error_line(run("experiment", *args, "--trials", "1", "--out", str(out)), needle)
    assert not out.exists(), "a refused sweep wrote its output folder"


def test_the_hybrid_search_keeps_to_a_budget_its_sampled_stage_spent(tmp_path):
    """`--search hybrid --max-expansions 2`: the sampled stage spent both expansions, then the
    complete stage ran one more and said "max_expansions 1", a budget the user never gave."""
    out = tmp_path / "hy.json"
    result = run("plan", "demo-shaft", "--footsteps-only", "--search", "hybrid",
                 "--max-expansions", "2", "--no-pictures", "-o", str(out))
    assert result.returncode == 1, result.stderr[-500:]
    plan = json.loads(out.read_text())
    assert plan["search"]["expansions"] <= 2, plan["search"]
    assert "max_expansions 1)" not in plan["reason"], plan["reason"]


@pytest.mark.parametrize("module", ["footstep_ab", "search_memory", "terrain_import"])
def test_the_scripts_refuse_an_empty_out(module):
    """`--out ''` was read by pathlib as the current folder in these three scripts."""
    env = dict(os.environ, RBP_THREADS="1")
    result = subprocess.run([sys.executable, "-m", f"experiments.{module}", "--out", ""],
                            capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    line = one_error_line(result, "--out", "an empty path")
    assert line.startswith("error: --out: "), f"the option is not named first: {line}"
