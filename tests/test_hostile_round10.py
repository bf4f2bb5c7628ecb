"""Issue 28, probe 10: numba's threading layers that cannot load and its configuration file,
usage errors of `rbp bench` and the experiments, a plan's recorded configuration of the wrong
type, and outputs checked before the work (each refused in one line, exit 2)."""

from __future__ import annotations

import copy
import dataclasses
import json
import types
import typing
from pathlib import Path
from typing import Any

import pytest

import rbp
from tests.cli_helpers import run_rbp

EXPERIMENTS = ("baseline_comparison", "timing_table", "snapshots", "seed_vs_scp",
               "rig_experiment", "monte_carlo", "calibration", "param_sweep")


@pytest.mark.parametrize("layer", ["tbb", "safe", "threadsafe"])
def test_a_threading_layer_that_cannot_load_is_refused_before_any_work(
        layer: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """NUMBA_THREADING_LAYER=tbb without TBB ended the first parallel kernel in numba's
    77-line traceback."""
    import rb_drake.environment
    from rbp.cli import main

    monkeypatch.setattr(rb_drake.environment, "_loads", lambda library: False)
    monkeypatch.setenv("NUMBA_THREADING_LAYER", layer)
    assert main(["scenario", "check", "demo-shaft"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: NUMBA_THREADING_LAYER (environment): {layer!r} needs ") \
        and err.count("\n") == 1, err


@pytest.mark.parametrize("layer", ["default", "forksafe", "workqueue"])
def test_a_threading_layer_with_a_fallback_is_accepted(
        layer: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import rb_drake.environment
    from rbp.cli import main

    monkeypatch.setattr(rb_drake.environment, "_loads", lambda library: False)
    monkeypatch.setenv("NUMBA_THREADING_LAYER", layer)
    assert main(["scenario", "check", "demo-shaft"]) == 0
    assert capsys.readouterr().err == ""


def test_numbas_configuration_file_in_the_current_folder_is_refused(tmp_path: Path) -> None:
    """numba applied `.numba_config.yaml`'s keys past the NUMBA_* check: `opt: abc` printed a
    traceback-shaped warning, `disable_jit: 1` ran for minutes."""
    (tmp_path / ".numba_config.yaml").write_text("disable_jit: 1\n")
    done = run_rbp("plan", "demo-shaft", "-o", "p.json", "--no-pictures", cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.startswith(
        "error: .numba_config.yaml: numba's configuration file") \
        and done.stderr.count("\n") == 1, done.stderr
    assert not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("args,start", [
    (["bench", "--bad"], "error: unrecognized arguments: --bad (see rbp bench --help)"),
    (["bench", "--samples", "x"], "error: --samples: must be a whole number"),
    *[(["experiment", name, "--bad"], "error: ") for name in EXPERIMENTS],
    (["experiment", "monte_carlo", "--trials", "x"], "error: --trials: must be a whole number"),
    (["experiment", "calibration", "--workers", "1.5"], "error: --workers: "),
    (["experiment", "param_sweep", "--param", "dt", "--values", "1"],
     "error: --param: invalid choice: 'dt'")])
def test_bench_and_experiment_usage_errors_are_one_line(
        args: list[str], start: str, capsys: pytest.CaptureFixture[str]) -> None:
    """They printed argparse's usage block and `rbp experiment NAME: error: ...`."""
    from rbp.cli import main

    with pytest.raises(SystemExit) as ended:
        main(args)
    assert ended.value.code == 2
    err = capsys.readouterr().err
    prog = " ".join(args[:2] if args[0] == "experiment" else args[:1])
    assert err.startswith(start) and err.endswith(f" (see rbp {prog} --help)\n") \
        and err.count("\n") == 1, err


@pytest.fixture(scope="module")
def plan_dict() -> dict[str, Any]:
    """A footstep plan of demo-shaft as a plan-file object (seconds to plan)."""
    plan = rbp.plan("demo-shaft", footsteps_only=True)
    assert plan.success
    return plan.to_dict()


@pytest.mark.parametrize("section,key,value,words", [
    ("footstep", "fallback_after", None, "expected a number, got null"),
    ("footstep", "fallback_weight", "x", "expected a number, got str 'x'"),
    ("footstep", "fallback_weight", True, "expected a number, got bool True"),
    ("scp", "max_iterations", "ten", "expected an integer, got str 'ten'"),
    ("footstep", "search", 5, "expected a string, got int 5")])
def test_check_refuses_a_recorded_value_of_the_wrong_type_as_from_plan_does(
        plan_dict: dict[str, Any], section: str, key: str, value: Any, words: str,
        tmp_path: Path) -> None:
    """`rbp check` said ok to a provenance.config that `rbp plan --from-plan` refused."""
    from planning.config_io import config_to_dict
    from planning.pipeline import PipelineConfig

    plan = copy.deepcopy(plan_dict)
    config = config_to_dict(PipelineConfig())
    config[section][key] = value
    plan["provenance"] = {"rbp_version": "test", "command": "rbp plan demo-shaft",
                          "planner": "rbp", "motion": False, "seed": 0,
                          "scenario_source": "demo-shaft", "config": config}
    (tmp_path / "p.json").write_text(json.dumps(plan))
    for args in (["check", "p.json"], ["plan", "--from-plan", "p.json", "-o", "q.json"]):
        done = run_rbp(*args, cwd=tmp_path)
        assert done.stderr == f"error: p.json: provenance.config.{section}.{key}: {words}\n", \
            (args, done.stderr)
        assert done.returncode == 2


def _config_classes() -> dict[str, type]:
    from planning.complete_config import AnytimeConfig
    from planning.footsteps import FootstepConfig
    from planning.lattice import LatticeConfig
    from planning.pipeline import PipelineConfig
    from planning.route_repair import RepairConfig
    from planning.scp_program import ScpConfig
    from planning.seed_common import SeedConfig
    from planning.segmented import SegmentConfig
    from planning.transition import TransitionConfig

    return {c.__name__: c for c in (PipelineConfig, FootstepConfig, LatticeConfig,
                                     AnytimeConfig, RepairConfig, SegmentConfig,
                                     TransitionConfig, SeedConfig, ScpConfig)}


def test_the_nullable_fields_are_the_classes_optional_ones() -> None:
    from planning.config_ranges import NULLABLE, SECTIONS

    classes = _config_classes()
    assert set(classes) == set(SECTIONS)
    for name, cls in classes.items():
        hints = typing.get_type_hints(cls)
        optional = {f.name for f in dataclasses.fields(cls) if f.init
                    and typing.get_origin(hints[f.name]) in (typing.Union, types.UnionType)
                    and type(None) in typing.get_args(hints[f.name])}
        assert optional == set(NULLABLE.get(name, ())), name


@pytest.mark.parametrize("value", [None, "x", "inf", True, 7, 0.5, [1.0], {}, float("nan"),
                                   10 ** 400])
def test_the_early_check_says_what_the_reader_says_for_every_field(value: Any) -> None:
    """config_ranges.range_problem (before the planner's imports) and config_io's reader name
    the same problem, in the same words, for every field and any JSON value."""
    from planning.config_io import ConfigError, config_from_dict
    from planning.config_ranges import SECTIONS, range_problem, section_keys
    from planning.pipeline import PipelineConfig

    for prefix in SECTIONS.values():
        for key in section_keys(prefix):
            if f"{prefix}{key}." in SECTIONS.values():
                continue
            data: dict[str, Any] = {key: value}
            for part in reversed(prefix.rstrip(".").split(".") if prefix else []):
                data = {part: data}
            try:
                config_from_dict(PipelineConfig, data, "f")
                reader = None
            except ConfigError as e:
                reader = (e.field, e.reason)
            early = range_problem(data)
            if early is None and reader is not None:
                continue  # a check of two keys together (the lattice's angle step): later
            assert early == reader, (prefix + key, value)


@pytest.mark.parametrize("name", ["snapshots", "rig_experiment"])
def test_experiment_outputs_are_checked_before_the_work(name: str, tmp_path: Path) -> None:
    """A read-only --out was refused only after the planning, without the option's name."""
    (tmp_path / "afile").write_text("")
    done = run_rbp("experiment", name, "--out", "afile", cwd=tmp_path)
    assert done.returncode == 2 and done.stderr == \
        "error: afile/plan.json: --out: afile is not a folder\n", done.stderr


def test_check_stamp_checks_the_folder_before_the_verification(
        plan_dict: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A read-only folder was refused after the verification and its ok line."""
    import rb_drake.files
    import systems.plan_check
    from rbp.cli import main

    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan_dict))
    monkeypatch.setattr(rb_drake.files, "output_problem",
                        lambda *args: f"the folder {tmp_path} is not writable")
    monkeypatch.setattr(systems.plan_check, "plan_problems", None)  # never reached
    assert main(["check", "--stamp", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"error: {path}: --stamp: the folder {tmp_path} is not writable\n"
    assert captured.out == ""


@pytest.mark.parametrize("args,line", [
    (["--version"], "error: unrecognized arguments: --version (see rbp --help)"),
    (["plan", "--bad"], "error: unrecognized arguments: --bad (see rbp plan --help)"),
    (["check", "--bad"], "error: unrecognized arguments: --bad (see rbp check --help)"),
    (["scenario", "check", "--bad", "x"],
     "error: unrecognized arguments: --bad (see rbp scenario check --help)"),
    (["plan", "demo-shaft"],
     "error: the following arguments are required: -o/--output (see rbp plan --help)")])
def test_a_usage_error_names_the_unknown_option_and_the_commands_help(
        args: list[str], line: str, capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown option was reported as a missing argument, and a subcommand's unknown
    option pointed at `rbp --help`."""
    from rbp.cli import main

    with pytest.raises(SystemExit) as ended:
        main(args)
    assert ended.value.code == 2
    assert capsys.readouterr().err == line + "\n"
