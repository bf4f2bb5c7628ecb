"""Probe 14 (session 29): `rbp plan`'s options and planner configuration. An output name
ending in '/' (pathlib dropped the slash and wrote the file), options that contradict each
other refused before the planner's imports (or silently ignored: --search sampled with
--thorough, --partial with the sampled search, the naive planner's search options,
--max-expansions with --thorough), --dt's refusal showing the digits that put it out of range,
and a configuration object whose field no copy can take named by rbp.plan."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from cli_helpers import one_error_line

import rbp
from planning.complete_config import AnytimeConfig
from planning.config_io import ConfigError, config_to_dict
from planning.footsteps import FootstepConfig
from planning.pipeline import PipelineConfig
from rb_drake.errors import RbpInputError

ROOT = Path(__file__).resolve().parents[1]


def env() -> dict[str, str]:
    return dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=env(), cwd=ROOT, timeout=120)


@pytest.mark.parametrize("command", [
    ["plan", "demo-shaft", "--footsteps-only", "-o"],
    ["plan", "demo-shaft", "--footsteps-only", "--no-pictures", "-o"],
    ["scenario", "generate", "--kind", "shaft", "-o"],
])
def test_an_output_name_ending_in_a_slash_is_refused(tmp_path, command):
    """`-o plan.json/` names a folder: pathlib dropped the slash and the plan was written to
    the file plan.json (and its picture beside it)."""
    name = "out.json" if command[0] == "plan" else "cave.yaml"
    given = f"{tmp_path / name}/"
    line = one_error_line(run(*command, given), "-o", "ends with '/'")
    assert line.startswith(f"error: {given}: -o: "), f"not named as given: {line}"
    assert list(tmp_path.iterdir()) == [], f"a refused command wrote {list(tmp_path.iterdir())}"


def test_an_existing_folder_with_its_slash_is_still_called_a_folder(tmp_path):
    line = one_error_line(run("plan", "demo-shaft", "--footsteps-only", "-o", f"{tmp_path}/"),
                          "-o", "is a directory")
    assert "ends with '/'" not in line, f"a folder's slash called a typo: {line}"
    assert list(tmp_path.iterdir()) == [], f"a refused command wrote {list(tmp_path.iterdir())}"


def test_the_api_refuses_an_output_name_ending_in_a_slash(tmp_path):
    cave = rbp.load_scenario("demo-shaft")
    with pytest.raises(RbpInputError, match="ends with '/'"):
        rbp.draw(cave, f"{tmp_path / 'cave.png'}/")
    assert list(tmp_path.iterdir()) == [], "rbp.draw wrote through a trailing slash"


# (options, the option the line names, a word of its reason)
CONFLICTS = [
    (["--thorough", "--min-success", "0.5"], "--min-success", "not both"),
    (["--partial", "--footsteps-only"], "--partial", "--footsteps-only"),
    (["--partial", "--planner", "naive"], "--partial", "--planner naive"),
    (["--partial", "--search", "sampled"], "--partial", "--search sampled"),
    (["--thorough", "--search", "sampled"], "--search", "complete search"),
    (["--min-success", "0.9", "--search", "hybrid"], "--search", "complete search"),
    (["--thorough", "--max-expansions", "50"], "--max-expansions", "without an expansion"),
    (["--planner", "naive", "--thorough"], "--thorough", "--planner naive"),
    (["--planner", "naive", "--min-success", "0.9"], "--min-success", "--planner naive"),
    (["--planner", "naive", "--repair"], "--repair", "--planner naive"),
    (["--planner", "naive", "--search", "complete"], "--search", "--planner naive"),
    (["--planner", "naive", "--max-expansions", "5"], "--max-expansions", "--planner naive"),
    (["--planner", "naive", "--time-limit", "5"], "--time-limit", "--planner naive"),
]


def main_in_a_fresh_process(args: list[str], cwd: Path,
                            modules: tuple[str, ...] = ("numba",)
                            ) -> subprocess.CompletedProcess[str]:
    """`rbp.cli.main(args)` in a new interpreter, which prints its status and whether each of
    `modules` was imported: refusals must come before the planner's imports."""
    code = ("import sys; from rbp.cli import main; "
            f"status = main({args!r}); "
            f"print(status, *(m in sys.modules for m in {modules!r}))")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env(), cwd=cwd, timeout=120)


@pytest.mark.parametrize("options, flag, reason", CONFLICTS)
def test_conflicting_options_are_refused_before_the_planner_is_imported(tmp_path, options,
                                                                        flag, reason):
    """Each pair contradicts itself: refused in one line naming the option, before the
    planner's imports (the refusals that came after them took 1.1-1.2 s and 172 MB; the
    silent ones searched completely for --search sampled, wrote no partial climb, ignored
    the naive planner's search options or dropped the expansion budget)."""
    out = tmp_path / "p.json"
    done = main_in_a_fresh_process(["plan", "demo-shaft", "-o", str(out), *options], tmp_path,
                                   ("numba", "planning.pipeline"))
    lines = done.stderr.strip().splitlines()
    assert done.stdout.strip().splitlines()[-1:] == ["2 False False"], (
        f"not refused before the imports (status, numba, planning.pipeline): {done.stdout!r} "
        f"{done.stderr[-300:]!r}")
    assert len(lines) == 1 and lines[0].startswith(f"error: {flag}: "), lines
    assert reason in lines[0], f"{reason!r} not in {lines[0]!r}"
    assert not out.exists(), "a refused run wrote a plan"


def test_a_scenario_with_from_plan_is_refused_before_the_imports(tmp_path):
    plan = tmp_path / "p.json"
    plan.write_text('{"format": "reachbot-plan/2"}')
    done = main_in_a_fresh_process(["plan", "demo-crevasse", "--from-plan", str(plan), "-o",
                                    str(tmp_path / "q.json")], tmp_path)
    assert done.stdout.strip().splitlines()[-1:] == ["2 False"], done.stdout + done.stderr
    assert "not both" in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_partial_with_a_configured_sampled_search_is_refused(tmp_path):
    """A configuration's `footstep.search: sampled` gives no partial climb: --partial was
    silently ignored. --search hybrid overrides the file and is accepted (not run here)."""
    config = tmp_path / "planner.yaml"
    config.write_text("footstep: {search: sampled}\n")
    out = tmp_path / "p.json"
    line = one_error_line(run("plan", "blocked-shaft", "--partial", "--config", str(config),
                              "-o", str(out)), "footstep.search", "--partial")
    assert line.startswith(f"error: {config}: footstep.search: "), line
    assert not out.exists(), "a refused run wrote a plan"


def test_a_dt_just_below_its_range_shows_its_digits(tmp_path):
    """`--dt 0.2499999` was refused as "got 0.25", which reads as within the range."""
    line = one_error_line(run("plan", "demo-shaft", "--dt", "0.2499999", "-o",
                              str(tmp_path / "p.json")), "--dt")
    assert line.endswith("got 0.2499999"), line


@pytest.mark.parametrize("weights", [
    (w for w in (5.0, 1.0)), threading.Lock(), {5.0, 1.0}])
def test_a_configuration_field_no_copy_takes_is_named(weights):
    """rbp.plan checks a configuration through config_to_dict, whose dataclasses.asdict
    deep-copied it: a generator or a lock ended in "TypeError: cannot pickle ..."."""
    config = PipelineConfig(footstep=FootstepConfig(anytime=AnytimeConfig(weights=weights)))
    with pytest.raises(ConfigError, match=r"footstep\.anytime\.weights: expected a list"):
        rbp.plan(rbp.load_scenario("demo-shaft"), config, footsteps_only=True)


def test_config_to_dict_is_asdict_for_a_valid_configuration():
    import dataclasses

    from planning.config_io import _plain

    config = PipelineConfig(footstep=FootstepConfig(anytime=AnytimeConfig(weights=[4.0, 1.0]),
                                                    time_limit=float("inf")))
    assert config_to_dict(config) == _plain(dataclasses.asdict(config)), (
        "the plan's provenance.config changed")


def test_from_plan_conflicts_name_the_plan_not_an_option_never_given(tmp_path):
    """--partial (or --thorough) with --from-plan of a footstep plan (or a naive plan) was
    refused as if the user had given --footsteps-only (or --planner naive)."""
    steps, naive = tmp_path / "steps.json", tmp_path / "naive.json"
    made = run("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "-o", str(steps))
    assert made.returncode == 0, made.stderr[-400:]
    made = run("plan", "demo-shaft", "--planner", "naive", "--footsteps-only", "--no-pictures",
               "-o", str(naive))
    assert made.returncode in (0, 1), made.stderr[-400:]
    out = tmp_path / "again.json"
    line = one_error_line(run("plan", "--from-plan", str(steps), "--partial", "-o", str(out)),
                          "--partial", "--from-plan's footstep plan")
    assert "which --footsteps-only" not in line, line
    for flag in ("--partial", "--thorough"):
        line = one_error_line(run("plan", "--from-plan", str(naive), flag, "-o", str(out)),
                              flag, "--from-plan's naive planner")
        assert "--planner naive" not in line, line
    assert not out.exists(), "a refused run wrote a plan"


def test_animate_with_no_pictures_is_refused(tmp_path):
    """`--animate climb.gif --no-pictures` planned, said nothing and wrote no animation."""
    out, gif = tmp_path / "p.json", tmp_path / "climb.gif"
    one_error_line(run("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "--animate",
                       str(gif), "-o", str(out)), "--animate", "--no-pictures")
    assert not out.exists() and not gif.exists(), "a refused run wrote its outputs"


def test_a_naive_failure_does_not_suggest_the_rbp_searchs_options(tmp_path):
    """The naive planner's "no goal after 80 steps" ended with "rbp plan --thorough searches on
    without a budget, --max-expansions N or --time-limit S sets another": options its search
    does not use (--thorough with --planner naive is now refused)."""
    done = run("plan", "blocked-shaft", "--planner", "naive", "--footsteps-only",
               "--no-pictures", "-o", str(tmp_path / "p.json"))
    assert done.returncode == 1, f"exit {done.returncode}: {done.stderr[-400:]}"
    summary = done.stdout.strip().splitlines()[-1]
    assert summary.startswith("success: false"), summary
    assert "--thorough" not in summary and "--max-expansions" not in summary, summary


def _plan_with(tmp_path: Path, name: str, change) -> Path:
    """A footstep plan of demo-shaft with its provenance.config changed by `change`."""
    import json

    made = tmp_path / "made.json"
    if not made.exists():
        done = run("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "-o", str(made))
        assert done.returncode == 0, done.stderr[-400:]
    plan = json.loads(made.read_text())
    change(plan["provenance"]["config"]["footstep"])
    path = tmp_path / name
    path.write_text(json.dumps(plan))
    return path


def test_a_recorded_configuration_failing_a_joint_check_is_refused_by_check_too(tmp_path):
    """A plan's provenance.config with segments' commit beyond their lookahead, or a lattice
    angle step not dividing 180 deg: `rbp check` said ok and --from-plan refused it, naming
    "provenance.config.footstep.segments.footstep.segments.commit" (the prefix twice)."""
    cases = {
        "segments.json": (lambda f: f.update(segments={"min_climb": 7.0, "lookahead": 1.0,
                                                       "commit": 2.0, "tolerance": 0.6}),
                          "provenance.config.footstep.segments.commit", "at most lookahead"),
        "lattice.json": (lambda f: f["lattice"].update(angle_step_deg=7.0),
                         "provenance.config.footstep.lattice.angle_step_deg", "divide 180"),
    }
    for name, (change, field, reason) in cases.items():
        path = _plan_with(tmp_path, name, change)
        for command in (["check", str(path)],
                        ["plan", "--from-plan", str(path), "-o", str(tmp_path / "again.json")]):
            line = one_error_line(run(*command), reason)
            assert line.startswith(f"error: {path}: {field}: "), f"{command[0]}: {line}"
    assert not (tmp_path / "again.json").exists(), "a refused --from-plan wrote a plan"


@pytest.mark.parametrize("text, field", [
    ("footstep: {lattice: {angle_step_deg: 7}}", "footstep.lattice.angle_step_deg"),
    ("footstep: {segments: {commit: 5}}", "footstep.segments.commit"),
])
def test_a_joint_check_of_a_config_file_comes_before_the_imports(tmp_path, text, field):
    config = tmp_path / "planner.yaml"
    config.write_text(text + "\n")
    done = main_in_a_fresh_process(["plan", "demo-shaft", "--config", str(config), "-o",
                                    str(tmp_path / "p.json")], tmp_path)
    assert done.stdout.strip().splitlines()[-1:] == ["2 False"], done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {config}: {field}: "), lines


def test_the_joint_checks_defaults_are_the_dataclasses():
    from planning.config_ranges import SEGMENT_DEFAULTS
    from planning.segmented import SegmentConfig

    default = SegmentConfig()
    assert {"lookahead": default.lookahead, "commit": default.commit,
            "tolerance": default.tolerance} == SEGMENT_DEFAULTS, (
        "config_ranges.SEGMENT_DEFAULTS differs from SegmentConfig's defaults")


@pytest.mark.parametrize("text, field", [
    ("~: 1", "null"),
    ("footstep: {true: 1}", "footstep.true"),
    ("footstep: {'': 1}", "footstep.''"),
    ("footstep: {segments: {null: 1}}", "footstep.segments.null"),
])
def test_an_unknown_key_is_named_as_the_file_wrote_it(tmp_path, text, field):
    """A null or boolean key was named "None" or "footstep.True", an empty one "footstep."."""
    config = tmp_path / "planner.yaml"
    config.write_text(text + "\n")
    line = one_error_line(run("plan", "demo-shaft", "--config", str(config), "-o",
                              str(tmp_path / "p.json")), "unknown key")
    assert line.startswith(f"error: {config}: {field}: unknown key"), line


def test_a_scenarios_null_key_is_named_null(tmp_path):
    cave = tmp_path / "cave.yaml"
    text = (ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml").read_text()
    cave.write_text(text.replace("\ngoal:\n", "\ngoal:\n  ~: 1\n", 1))
    line = one_error_line(run("scenario", "check", str(cave)), "unknown field")
    assert line.startswith(f"error: {cave}: goal.null: unknown field"), line


def test_the_api_refuses_a_partial_climb_of_the_sampled_search():
    """rbp.plan(..., partial=True) with footstep.search 'sampled' returned a plan without a
    partial climb and said nothing (the command line refuses the same)."""
    config = PipelineConfig(footstep=FootstepConfig(search="sampled"))
    with pytest.raises(RbpInputError, match="sampled search gives none") as caught:
        rbp.plan("blocked-shaft", config, partial=True)
    assert caught.value.field == "partial", caught.value


def test_a_min_success_just_below_one_is_shown_as_given(tmp_path):
    """--min-success 0.9999999999999999 (accepted: below 1) was reported as "no route with
    predicted success >= 1", the value the option refuses."""
    done = run("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "--min-success",
               "0.9999999999999999", "-o", str(tmp_path / "p.json"))
    assert done.returncode == 1, f"exit {done.returncode}: {done.stderr[-400:]}"
    summary = done.stdout.strip().splitlines()[-1]
    assert "predicted success >= 0.9999999999999999 " in summary, summary


def test_as_given_never_rounds_to_another_number():
    from rb_drake.errors import as_given

    for value, text in ((0.5, "0.5"), (0.9, "0.9"), (1e-300, "1e-300"),
                        (0.9999999999999999, "0.9999999999999999"), (0.1234567, "0.1234567")):
        assert as_given(value) == text, f"{value!r} shown as {as_given(value)!r}"
        assert float(as_given(value)) == value


# the hybrid states the limit and both stages' expansions (tests/test_hostile_round20.py)
@pytest.mark.parametrize("search, given_up", [("sampled", "gave up after 1e-300 s (1 "),
                                              ("hybrid", "gave up after 1e-300 s (2 ")])
def test_the_sampled_search_keeps_to_the_time_limit(tmp_path, search, given_up):
    """The sampled search (and the hybrid's sampled stage) ignored --time-limit: with
    candidates_per_boom 1000 a 10 s limit ran 44 s on shaft-1, and the hybrid's complete stage
    had the whole limit again. Here a limit no search can keep stops it after its first
    expansion; the hybrid's complete stage gets what is left (at least 1 ms)."""
    out = tmp_path / "p.json"
    done = run("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "--search", search,
               "--time-limit", "1e-300", "-o", str(out))
    assert done.returncode == 1, f"exit {done.returncode}: {done.stderr[-400:]}"
    summary = done.stdout.strip().splitlines()[-1]
    assert summary.startswith(f"success: false ({given_up}expansions)"), summary
    checked = run("check", str(out))
    assert checked.returncode == 0, f"rbp check refused the plan: {checked.stdout[-400:]}"


def test_lazy_astar_gives_up_on_its_time_limit():
    import time

    from planning.astar import Edge, lazy_astar

    def slow(node, child, key, data):
        time.sleep(0.01)
        return Edge(1.0, None)

    t0 = time.perf_counter()
    result = lazy_astar(0, lambda n, d: [(n + 1, None, 1.0)], slow, lambda n: 0.0,
                        is_goal=lambda n, d: False, max_expansions=10**9, time_limit=0.1)
    took = time.perf_counter() - t0
    assert not result.success and result.timed_out, result.reason
    assert result.reason.startswith("gave up after 0.1 s"), result.reason
    assert took < 1.0, f"a 0.1 s limit took {took:.2f} s"
    plain = lazy_astar(0, lambda n, d: [(n + 1, None, 1.0)], lambda *a: Edge(1.0, None),
                       lambda n: 0.0, is_goal=lambda n, d: n == 5)
    assert plain.success and not plain.timed_out, "no time limit, yet timed out"


def test_the_search_clock_leaves_out_numbas_compiling():
    import time

    from numba import njit

    from planning.search_clock import compile_seconds, search_clock

    wall0, clock0, compiled0 = time.perf_counter(), search_clock(), compile_seconds()

    @njit(cache=False)
    def fresh(x):  # compiled on its first call, here
        return x * 2.0 + 1.0

    assert fresh(1.0) == 3.0
    compiled = compile_seconds() - compiled0
    wall, searched = time.perf_counter() - wall0, search_clock() - clock0
    assert compiled > 0.0, "numba's compile event was not timed"
    # The two clocks are read a few microseconds apart (CI once saw 1.2 us): 1 ms tolerance,
    # far below the ~20-30 ms that compiling even this function takes.
    assert abs((wall - searched) - compiled) < 1e-3, (wall, searched, compiled)


def test_a_time_limit_is_not_spent_compiling_the_kernels(tmp_path):
    """With a cold numba cache the kernels compile (about 20-30 s) inside the first search:
    `--time-limit 5` gave up after one expansion (and took 25 s) where a warm run finds
    demo-shaft's route in about a second. A fresh NUMBA_CACHE_DIR makes the cache cold (this
    test takes as long as the compiling)."""
    out = tmp_path / "p.json"
    done = subprocess.run(
        [sys.executable, "-m", "rbp", "plan", "demo-shaft", "--footsteps-only", "--no-pictures",
         "--time-limit", "5", "-o", str(out)], capture_output=True, text=True,
        env=dict(env(), NUMBA_CACHE_DIR=str(tmp_path / "numba-cache")), cwd=ROOT, timeout=600)
    summary = done.stdout.strip().splitlines()[-1:]
    assert done.returncode == 0, f"exit {done.returncode}: {summary} {done.stderr[-300:]}"
    assert summary[0].startswith("success: true"), summary


@pytest.mark.parametrize("text, flags, field, source", [
    ("footstep: {search: sampled, min_success: 0.9}", [], "footstep.min_success", "config"),
    ("footstep: {min_success: 0.9}", ["--search", "hybrid"], "footstep.min_success",
     "--search"),
    ("footstep: {search: sampled, repair: {}}", [], "footstep.repair", "config"),
])
def test_a_complete_search_option_with_another_search_is_refused(tmp_path, text, flags, field,
                                                                  source):
    """`footstep: {search: sampled, min_success: 0.9}` planned demo-shaft with p_path 0.886
    and said success: true, the probability asked for silently ignored (repair too)."""
    config = tmp_path / "planner.yaml"
    config.write_text(text + "\n")
    out = tmp_path / "p.json"
    line = one_error_line(run("plan", "demo-shaft", "--footsteps-only", "--config", str(config),
                              *flags, "-o", str(out)), field, "complete search's")
    named = str(config) if source == "config" else source
    assert line.startswith(f"error: {named}: {field}: "), line
    assert not out.exists(), "a refused run wrote a plan"


def test_the_api_refuses_min_success_with_the_sampled_search():
    config = PipelineConfig(footstep=FootstepConfig(search="sampled", min_success=0.9))
    with pytest.raises(ConfigError, match=r"footstep\.min_success: is the complete search's"):
        rbp.plan("demo-shaft", config, footsteps_only=True)


def test_from_plan_of_a_partial_climb_names_the_option_given(tmp_path):
    """--from-plan of a partial plan with --footsteps-only (or --planner naive) was refused
    as "--partial: ...", an option the user never gave."""
    partial = tmp_path / "partial.json"
    made = run("plan", "blocked-shaft", "--partial", "--no-scp", "--no-pictures", "-q", "-o",
               str(partial))
    assert made.returncode == 1 and partial.exists(), made.stderr[-400:]
    out = tmp_path / "again.json"
    for flags in (["--footsteps-only"], ["--planner", "naive"]):
        line = one_error_line(run("plan", "--from-plan", str(partial), *flags, "-o", str(out)),
                              "is a partial climb")
        assert line.startswith(f"error: {' '.join(flags)}: {partial} "), line
    assert not out.exists(), "a refused run wrote a plan"
