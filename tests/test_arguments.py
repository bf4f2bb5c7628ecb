"""Arguments checked before the work, with a stated range, and messages that help (issue 32)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.cli_helpers import run_rbp


@pytest.mark.parametrize(("args", "flag"), [
    (("--seed", "-1"), "--seed"),
    (("--length", "1e308", "1e308"), "--length"),
    (("--anchor-density", "1e5"), "--anchor-density"),
    (("--anchor-density", "0"), "--anchor-density"),
])
def test_generate_refuses_out_of_range_arguments_at_once(tmp_path: Path, args, flag) -> None:
    start = time.perf_counter()
    result = run_rbp("scenario", "generate", *args, "-o", "cave.yaml", cwd=tmp_path)
    assert result.returncode == 2, (args, result.returncode, result.stderr[-1500:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and flag in lines[0], result.stderr
    assert time.perf_counter() - start < 30, f"{args} was refused only after the work"
    assert not (tmp_path / "cave.yaml").exists()


def test_generate_help_explains_kind_and_seed(tmp_path: Path) -> None:
    text = " ".join(run_rbp("scenario", "generate", "--help", cwd=tmp_path).stdout.split())
    assert "a vertical shaft to climb" in text, text
    assert "the same seed gives the same cave" in text, text


def test_scenario_list_names_the_rig(tmp_path: Path) -> None:
    names = [line.split()[0] for line in
             run_rbp("scenario", "list", cwd=tmp_path).stdout.splitlines() if line.strip()]
    assert "rig" in names and "demo-shaft" in names, names


def test_a_budget_stop_says_how_to_search_on(tmp_path: Path) -> None:
    result = run_rbp("plan", "demo-shaft", "--footsteps-only", "--max-expansions", "3",
                     "--no-pictures", "-o", "p.json", cwd=tmp_path)
    assert result.returncode == 1, result.stderr[-1500:]
    assert "--thorough" in result.stdout and "--max-expansions" in result.stdout, result.stdout


@pytest.mark.parametrize(("args", "words"), [
    (("--phase-figure", "-1"), "must be 0 or more"),
    (("--phase-figure", "2", "--footsteps-only"), "--footsteps-only"),
])
def test_phase_figure_refused_before_planning(tmp_path: Path, args, words) -> None:
    start = time.perf_counter()
    result = run_rbp("plan", "demo-shaft", "-o", "p.json", *args, cwd=tmp_path)
    assert result.returncode == 2 and words in result.stderr, result.stderr[-1500:]
    assert time.perf_counter() - start < 30 and not (tmp_path / "p.json").exists()


def test_phase_figure_beyond_the_plan_keeps_the_plan_and_its_picture(tmp_path: Path) -> None:
    result = run_rbp("plan", "demo-shaft", "-o", "p.json", "--phase-figure", "999",
                     cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-1500:]
    assert "phase 999 has no trajectory" in result.stderr, result.stderr
    assert (tmp_path / "p.json").exists() and (tmp_path / "p.png").exists(), \
        "the plan and its picture must be written before the phase is refused"


def test_a_plan_given_as_a_scenario_points_to_from_plan(tmp_path: Path) -> None:
    plan = Path(__file__).parent / "data" / "golden" / "demo-shaft.json"
    result = run_rbp("plan", str(plan), "-o", "again.json", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-1500:]
    assert "this is a plan" in result.stderr and "--from-plan" in result.stderr, result.stderr


@pytest.mark.parametrize("dt", ["1e-6", "0", "-1", "1e9", "nan"])
def test_dt_refused_up_front_with_its_range(tmp_path: Path, dt: str) -> None:
    """--dt 1e-6 ran past 120 s printing the solver's numerical errors."""
    start = time.perf_counter()
    result = run_rbp("plan", "demo-shaft", "--dt", dt, "-o", "p.json", cwd=tmp_path)
    assert result.returncode == 2, (dt, result.returncode, result.stderr[-1500:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --dt:"), result.stderr
    assert "at least 0.25" in lines[0] and "at most 60" in lines[0], lines[0]
    assert time.perf_counter() - start < 30 and not (tmp_path / "p.json").exists()


def test_dt_of_a_configuration_file_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "fast.yaml").write_text("dt: 1.0e-6\n")
    result = run_rbp("plan", "demo-shaft", "--config", "fast.yaml", "-o", "p.json",
                     cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-1500:]
    assert result.stderr.startswith("error: fast.yaml: dt:"), result.stderr


GOLDEN = Path(__file__).parent / "data" / "golden"


@pytest.mark.parametrize(("args", "flag"), [
    (("plan", "demo-shaft", "--seed", "-1", "-o", "p.json"), "--seed"),
    (("plan", "demo-shaft", "--config", "seed.yaml", "-o", "p.json"), "seed.yaml: footstep.seed"),
    (("simulate", str(GOLDEN / "demo-shaft.json"), "--seed", "-1"), "--seed"),
    (("rig-run", str(GOLDEN / "rig.json"), "--sim-rig", "--seed", "-1"), "--seed"),
    (("rig-run", str(GOLDEN / "rig.json"), "--sim-rig", "--period", "1e-9"), "--period"),
    (("rig-run", str(GOLDEN / "rig.json"), "--sim-rig", "--period", "0"), "--period"),
    (("scenario", "show", "demo-shaft", "-o", "s.png", "--dpi", "0"), "--dpi"),
    (("scenario", "show", "demo-shaft", "-o", "s.png", "--dpi", "100000"), "--dpi"),
    (("rig-report", "missing.lcm", "-o", "r.png", "--dpi", "-5"), "--dpi"),
])
def test_seeds_periods_and_resolutions_refused_with_their_range(tmp_path: Path, args,
                                                                 flag: str) -> None:
    """A negative seed ended in numpy's traceback, --dpi 0 in matplotlib's and --dpi 100000
    in a MemoryError, and rig-run --period 1e-9 sent commands without end: each is refused
    before any work with one line naming the flag and its range."""
    (tmp_path / "seed.yaml").write_text("footstep: {seed: -1}\n")
    start = time.perf_counter()
    result = run_rbp(*args, cwd=tmp_path)
    assert result.returncode == 2, (args, result.returncode, result.stderr[-1500:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {flag}: must be "), result.stderr
    assert time.perf_counter() - start < 60, f"{args} was refused only after the work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seed.yaml"], "an output was written"


@pytest.mark.parametrize("animation", ["a.json", "a.png", "a"])
def test_animation_suffix_refused_before_planning(tmp_path: Path, animation: str) -> None:
    """--animate picks its writer by the suffix: another one was written by ffmpeg (or failed
    with a traceback) after the whole plan."""
    result = run_rbp("plan", "demo-shaft", "-o", "p.json", "--animate", animation,
                     cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-1500:]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--animate: must end in .gif or .mp4" in lines[0], lines
    assert list(tmp_path.iterdir()) == []


def test_a_failed_plan_with_animate_says_why_there_is_no_animation(tmp_path: Path) -> None:
    """A search that found no route has nothing to animate: one line (was a traceback)."""
    result = run_rbp("plan", "demo-shaft", "--footsteps-only", "--max-expansions", "3",
                     "-o", "p.json", "--animate", "p.gif", cwd=tmp_path)
    assert result.returncode == 1, result.stderr[-1500:]
    assert "Traceback" not in result.stderr, result.stderr[-1500:]
    assert "--animate: p.gif not written: the plan has no configurations" in result.stderr
    assert (tmp_path / "p.json").exists() and not (tmp_path / "p.gif").exists()


@pytest.mark.parametrize("value", ["abc", "0", "-2", "1.5", "99999"])
def test_a_malformed_rbp_threads_is_refused_in_one_line(tmp_path: Path, value: str,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RBP_THREADS", value)  # the subprocess inherits it
    result = run_rbp("plan", "demo-shaft", "--footsteps-only", "-o", str(tmp_path / "p.json"),
                     cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (value, result.returncode, result.stderr)
    assert len(lines) == 1 and "RBP_THREADS" in lines[0] and repr(value) in lines[0], \
        (value, result.stderr)
    assert not (tmp_path / "p.json").exists(), "a refused run wrote its plan"


@pytest.mark.parametrize("trials", ["-1", "1000001"])
def test_simulate_trials_refused_beyond_their_range(tmp_path: Path, trials: str) -> None:
    result = run_rbp("simulate", "nothing.json", "--trials", trials, cwd=tmp_path)
    assert result.returncode == 2, (trials, result.returncode, result.stderr)
    assert "--trials" in result.stderr and "1,000,000" in result.stderr, result.stderr
