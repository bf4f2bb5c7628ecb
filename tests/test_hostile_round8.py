"""Issue 28, probe 8: integers written as floats, closed standard streams, numba's variables,
non-ASCII names on an ASCII stdout, outputs that cannot be written, the Python API's callbacks,
early range checks and argparse's usage errors (each refused in one line, exit 2)."""

from __future__ import annotations

import copy
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import rbp
from planning.plan_file import PlanFileError
from tests.cli_helpers import ROOT, run_rbp


@pytest.fixture(scope="module")
def plan_dict() -> dict[str, Any]:
    """A footstep plan of demo-shaft as a plan-file object (seconds to plan)."""
    plan = rbp.plan("demo-shaft", footsteps_only=True)
    assert plan.success
    return plan.to_dict()


def _reach(plan: dict[str, Any]) -> int:
    return next(k for k, p in enumerate(plan["phases"]) if p["kind"] == "reach")


@pytest.mark.parametrize("where", ["free_boom", "regrasps", "expansions"])
def test_integers_written_as_floats_are_refused_by_every_reader(
        plan_dict: dict[str, Any], where: str, tmp_path: Path) -> None:
    plan = copy.deepcopy(plan_dict)
    k = _reach(plan)
    if where == "free_boom":
        plan["phases"][k]["free_boom"] = float(plan["phases"][k]["free_boom"])
        field = f"phases[{k}].free_boom"
    elif where == "regrasps":
        plan["regrasps"], field = float(plan["regrasps"]), "regrasps"
    else:
        plan["search"]["expansions"] = float(plan["search"]["expansions"])
        field = "search.expansions"
    with pytest.raises(PlanFileError, match=f"^{re.escape(field)}: expected an integer, got "):
        rbp.check(plan)
    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan))
    with pytest.raises(PlanFileError, match="expected an integer"):
        rbp.read_plan(path)
    if where == "free_boom":  # the commands: one line, exit 2 (a traceback before)
        for args in (["check", "p.json"], ["simulate", "p.json", "--trials", "1"]):
            done = run_rbp(*args, cwd=tmp_path)
            assert done.returncode == 2, done.stderr
            assert done.stderr.endswith(f"error: p.json: {field}: expected an integer, "
                                        f"got {plan['phases'][k]['free_boom']}\n"), done.stderr
            assert done.stderr.count("\n") == 1, done.stderr


def _shell(command: str, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    """`python -m rbp` through sh, for redirections such as `>&-` (a closed stdout)."""
    full = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
            "PYTHONPATH": str(ROOT), **env}
    return subprocess.run(["sh", "-c", f"exec '{sys.executable}' -m rbp {command}"], cwd=cwd,
                          env=full, capture_output=True, text=True, timeout=300, check=False)


def test_a_closed_stdout_or_stderr_ends_cleanly(tmp_path: Path) -> None:
    done = _shell("scenario check demo-shaft >&-", tmp_path)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    (tmp_path / "bad.yaml").write_text("format: reachbot-scenario/1\nname: [\n")
    done = _shell("scenario check bad.yaml 2>&-", tmp_path)
    assert (done.returncode, done.stdout) == (2, ""), done.stdout  # the line went to stdout
    done = _shell("scenario check demo-shaft >&- 2>&-", tmp_path)
    assert done.returncode == 0


def test_non_ascii_names_on_an_ascii_stdout_are_escaped(tmp_path: Path) -> None:
    from rb_drake.scenario import bundled_caves

    cave = tmp_path / "é洞.yaml"
    cave.write_text(bundled_caves()["demo-shaft"].read_text())
    done = _shell("scenario check 'é洞.yaml'", tmp_path, PYTHONIOENCODING="ascii")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("\\xe9\\u6d1e.yaml: ok"), done.stdout


@pytest.mark.parametrize("variable,value", [
    ("NUMBA_THREADING_LAYER_PRIORITY", "foo"), ("NUMBA_THREADING_LAYER_PRIORITY", "omp tbb"),
    ("NUMBA_OPT", "abc"), ("NUMBA_BOUNDSCHECK", "abc"), ("NUMBA_CPU_NAME", "bogus"),
    ("NUMBA_CPU_FEATURES", "+garbage"), ("NUMBA_DISABLE_JIT", "1"), ("NUMBA_OPT", "3")])
def test_numba_variables_rbp_does_not_support_are_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        variable: str, value: str) -> None:
    """A traceback (a wrong priority), a traceback-shaped warning (NUMBA_OPT=abc), every kernel
    recompiled (NUMBA_CPU_NAME: 47 s) or a run of minutes (NUMBA_DISABLE_JIT=1): refused
    before any work, naming the variable."""
    from rbp.cli import main

    monkeypatch.setenv(variable, value)
    out = tmp_path / "p.json"
    assert main(["plan", "demo-shaft", "--no-pictures", "-o", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {variable} (environment): "), lines
    assert not out.exists()


def test_a_threading_layer_priority_in_another_order_is_accepted(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from rbp.cli import main

    monkeypatch.setenv("NUMBA_THREADING_LAYER_PRIORITY", "workqueue omp tbb")
    assert main(["scenario", "check", "demo-shaft"]) == 0
    assert capsys.readouterr().err == ""


def test_a_full_disk_names_the_output_and_its_option(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """ENOSPC while writing was `error: : No space left on device` (no file, no option)."""
    import errno

    import rb_drake.files
    from rbp.cli import main

    def full(path: str | Path, write: Any) -> Path:
        def no_room(data: bytes) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(path, lambda f: no_room(b""))

    real = rb_drake.files.atomic_write
    monkeypatch.setattr(rb_drake.files, "atomic_write", full)
    out = tmp_path / "c.png"
    assert main(["scenario", "show", "demo-shaft", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {out}: -o: cannot write: {os.strerror(errno.ENOSPC)}\n", err
    assert list(tmp_path.iterdir()) == []  # no temporary file left


def test_a_folder_that_refuses_new_files_is_refused_before_the_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """/proc/self/fd is writable by its mode, yet no file can be made there: refused after
    the planning before, without the option's name."""
    from rbp.cli import main

    out = "/proc/self/fd/rbp-probe.json"
    assert main(["plan", "demo-shaft", "--no-pictures", "-o", out]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {out}: -o: cannot write a file there ("), err


@pytest.mark.parametrize("kwargs,field", [({"footsteps_done": 5}, "footsteps_done"),
                                          ({"progress": "no"}, "progress")])
def test_plan_refuses_a_callback_or_flag_of_a_wrong_type_up_front(
        kwargs: dict[str, Any], field: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """footsteps_done=5 was called after the footstep search: builtins TypeError."""
    import planning.pipeline

    def never(*args: Any, **kw: Any) -> None:
        raise AssertionError("planned before the arguments were checked")

    monkeypatch.setattr(planning.pipeline, "plan_climb", never)
    with pytest.raises(rbp.RbpInputError, match=f"^{field}: expected "):
        rbp.plan("demo-shaft", **kwargs)


def test_check_refuses_a_progress_flag_of_a_wrong_type(plan_dict: dict[str, Any]) -> None:
    with pytest.raises(rbp.RbpInputError, match=r"^progress: expected True or False"):
        rbp.check(plan_dict, progress="no")


@pytest.mark.parametrize("args,start", [
    (["plan", "demo-shaft", "-o", "p.json", "--seed", "1e3"], "error: --seed: invalid int "),
    (["plan", "-o", "-o"], "error: -o/--output: expected one argument"),
    (["scenario", "generate", "--length", "300"], "error: --length: expected 2 arguments"),
    (["nosuch"], "error: command: invalid choice: 'nosuch'")])
def test_usage_errors_are_one_line(args: list[str], start: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    """argparse printed its usage block and `rbp plan: error: argument --seed: ...`."""
    from rbp.cli import main

    with pytest.raises(SystemExit) as ended:
        main(args)
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(start) and err.count("\n") == 1, err


def _with_provenance(plan: dict[str, Any], **config: Any) -> dict[str, Any]:
    from planning.config_io import config_to_dict
    from planning.pipeline import PipelineConfig

    plan = copy.deepcopy(plan)
    recorded = config_to_dict(PipelineConfig()) | config
    plan["provenance"] = {"rbp_version": "test", "command": "rbp plan demo-shaft",
                          "planner": "rbp", "motion": False, "seed": 0,
                          "scenario_source": "demo-shaft", "config": recorded}
    return plan


@pytest.mark.parametrize("config,words", [
    ({"dt": 1e308}, "provenance.config.dt: must be a number from "),
    ({"motion_retries": 10.0}, "provenance.config.motion_retries: expected an integer")])
def test_check_reads_provenance_config_as_from_plan_does(
        plan_dict: dict[str, Any], config: dict[str, Any], words: str, tmp_path: Path) -> None:
    """`rbp check` said ok to a recorded configuration that `rbp plan --from-plan` refused."""
    (tmp_path / "p.json").write_text(json.dumps(_with_provenance(plan_dict, **config)))
    for args in (["check", "p.json"], ["plan", "--from-plan", "p.json", "-o", "q.json"]):
        done = run_rbp(*args, cwd=tmp_path)
        assert done.returncode == 2 and done.stderr.startswith(f"error: p.json: {words}"), \
            (args, done.stderr)
        assert not (tmp_path / "q.json").exists()


def test_from_plan_refuses_two_robots_that_disagree(plan_dict: dict[str, Any],
                                                    tmp_path: Path) -> None:
    """A reachbot-plan/1 file's scenario.robot differing from its robot: rbp check's rule
    robot refused it; --from-plan planned with the top-level robot without a word."""
    plan = _with_provenance(plan_dict)
    plan["format"] = "reachbot-plan/1"
    plan["scenario"]["robot"] = copy.deepcopy(plan["robot"]) | {"p_min": 0.5}
    (tmp_path / "p.json").write_text(json.dumps(plan))
    done = run_rbp("plan", "--from-plan", "p.json", "-o", "q.json", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr == ("error: p.json: robot: the robot under scenario differs from the "
                           "top-level robot in ['p_min']\n"), done.stderr
    done = run_rbp("check", "p.json", cwd=tmp_path)
    assert done.returncode == 1 and "plan: robot: the robot under scenario differs" in done.stdout


@pytest.mark.parametrize("args,words", [
    (["--seed", "-1"], "--seed: must be 0 or more"),
    (["--dt", "0.00999"], "--dt: seconds between trajectory steps"),
    (["--min-success", "1.0000001"], "--min-success: must lie strictly between 0 and 1"),
    (["--time-limit", "nan"], "--time-limit: must be a number above 0"),
    (["--max-expansions", "0"], "--max-expansions: must be a whole number from 1")])
def test_plan_options_are_refused_before_the_planners_imports(
        args: list[str], words: str, tmp_path: Path) -> None:
    """Refused after importing the planner (1.3-2 s, 170 MB) while --phase-figure -1 took
    0.3 s: checked by counting what was imported, not by the clock."""
    code = ("import sys; from rbp.cli import main; status = main(sys.argv[1:]); "
            "print('pipeline' if 'planning.pipeline' in sys.modules else 'light'); "
            "sys.exit(status)")
    full = {**os.environ, "LCM_DEFAULT_URL": "memq://", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code, "plan", "demo-shaft", "-o", "p.json",
                           "--no-pictures", *args], cwd=tmp_path, env=full,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 2 and done.stderr.startswith(f"error: {words}"), done.stderr
    assert done.stdout == "light\n"


def test_rig_run_refuses_its_phase_and_bus_before_the_verifiers_imports(
        plan_dict: dict[str, Any], tmp_path: Path) -> None:
    (tmp_path / "p.json").write_text(json.dumps(plan_dict))
    code = ("import sys; from rbp.cli import main; status = main(sys.argv[1:]); "
            "print('rig' if 'systems.rig' in sys.modules else 'light'); sys.exit(status)")
    full = {**os.environ, "LCM_DEFAULT_URL": "memq://", "PYTHONPATH": str(ROOT)}
    n = len(plan_dict["phases"])
    for extra, words in ((["--phase", "999"], "error: p.json: phases[999]: no such phase"),
                         (["--phase", str(_reach(plan_dict))], "a reach phase"),
                         (["--lcm-url", ""], "error: --lcm-url: the simulated rig runs "
                                             "in-process on memq://, not on ''")):
        done = subprocess.run([sys.executable, "-c", code, "rig-run", "p.json", "--sim-rig",
                               "--log", "r.lcm", *extra], cwd=tmp_path, env=full,
                              capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 2 and words in done.stderr, (extra, n, done.stderr)
        assert done.stdout == "light\n", extra


@pytest.mark.parametrize("text,words", [
    ("footstep: {time_limit: .inf}\n", "footstep.time_limit: must be a number above 0"),
    ("footstep: {max_expansions: 1000.0}\n",
     "footstep.max_expansions: expected an integer, got float 1000.0"),
    ("footstep: {transition: [1]}\n", "footstep.transition: expected a mapping, got list [1]"),
    ("footstep: {search: quantum}\n", "footstep.search: must be one of hybrid, complete"),
    ("dt: 1.0e+308\n", "dt: must be a number from 0.25 to 60 s")])
def test_config_values_are_refused_before_the_planners_imports(
        text: str, words: str, tmp_path: Path) -> None:
    """In the reader's words (the same line after the imports), without them."""
    from planning.config_io import ConfigError, load_config
    from planning.pipeline import PipelineConfig

    (tmp_path / "c.yaml").write_text(text)
    with pytest.raises(ConfigError) as late:
        load_config(tmp_path / "c.yaml", PipelineConfig)
    code = ("import sys; from rbp.cli import main; status = main(sys.argv[1:]); "
            "print('pipeline' if 'planning.pipeline' in sys.modules else 'light'); "
            "sys.exit(status)")
    full = {**os.environ, "LCM_DEFAULT_URL": "memq://", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code, "plan", "demo-shaft", "-o", "p.json",
                           "--no-pictures", "--config", "c.yaml"], cwd=tmp_path, env=full,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 2 and done.stderr == f"error: c.yaml: {words}" + \
        done.stderr[len(f"error: c.yaml: {words}"):], done.stderr
    assert done.stderr.strip().endswith(late.value.reason), (done.stderr, late.value.reason)
    assert done.stdout == "light\n"
