"""Hostile inputs bounded in memory and refused in one line: JSON of many small objects, and
command-line paths and numbers (docs/formats.md "Reading limits")."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import pytest

from rb_drake.input_files import MAX_JSON_UNITS, InputFileError, json_units, load_json

GOLDEN = Path(__file__).parent / "data" / "golden"


def test_json_of_many_small_objects_refused_before_parsing():
    """990,000 `{"a":0}` in 8 MB were under the value bound and parsed to 192 MB; the units
    limit is a quarter of the 8 MiB size limit."""
    text = "[" + ",".join(['{"a":0}'] * 990_000) + "]"
    tracemalloc.start()
    try:
        with pytest.raises(InputFileError, match="over the limit of 2,097,152"):
            load_json(text)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 2**20, f"refusing it allocated {peak / 2**20:.1f} MB"


def test_json_of_many_keys_refused():
    text = "{" + ",".join(f'"{i:x}":0' for i in range(400_000)) + "}"
    with pytest.raises(InputFileError, match="units"):
        load_json(text)


@pytest.mark.parametrize("path", [p for p in sorted(GOLDEN.glob("*.json"))
                                  if p.stat().st_size > 100_000], ids=lambda p: p.name)
def test_plans_of_8_mib_stay_readable(path):
    """Plans at their density scaled to 8 MiB stay within the units (about 1 M per 8 MiB)."""
    text = path.read_text()
    assert json_units(text) * 8 * 2**20 / len(text) < 0.6 * MAX_JSON_UNITS
    assert load_json(text) == json.loads(text)


def test_a_long_plan_of_steps_reads():
    """28,000 steps in one phase (a 7.4 MB plan) reads; it counts about 1.4 M units."""
    plan = json.loads((GOLDEN / "rig.json").read_text())
    step = plan["phases"][0]["steps"][0]
    plan["phases"][0]["steps"] = [dict(step, t=float(i)) for i in range(28_000)]
    text = json.dumps(plan)
    assert len(text) > 5_000_000
    assert len(load_json(text)["phases"][0]["steps"]) == 28_000


def _one_line(result, *words: str) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr[-2000:]
    assert all(w in lines[0] for w in words), (words, lines[0])
    return lines[0]


def test_no_verify_refusal_is_one_line_naming_the_step(tmp_path):
    """simulate --no-verify printed its warning, then every step time as np.float64(...)."""
    from tests.cli_helpers import run_rbp

    plan = json.loads((GOLDEN / "demo-shaft.json").read_text())
    steps = plan["phases"][0]["steps"]
    steps[1]["t"], steps[2]["t"] = steps[2]["t"], steps[1]["t"]
    path = tmp_path / "ooo.json"
    path.write_text(json.dumps(plan))
    line = _one_line(run_rbp("simulate", "--trials", "0", "--no-verify", str(path),
                             cwd=tmp_path), "phases[0].steps[2].t: times must increase")
    assert "np.float64" not in line and len(line) < 300, line
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps(dict(plan, phases=[])))
    _one_line(run_rbp("rig-run", "--sim-rig", "--no-verify", "--log",
                      str(tmp_path / "a.lcm"), str(empty), cwd=tmp_path), str(empty))


@pytest.mark.parametrize("argv, name", [
    (("check", ""), "plan: (argument)"),
    (("plan", "", "-o", "a.json"), "scenario: (argument)"),
    (("plan", "demo-shaft", "-o", ""), "-o"),
    (("plan", "demo-shaft", "-o", "a.json", "--config", ""), "--config"),
    (("demo", "--scenario", ""), "--scenario"),
    (("scenario", "check", ""), "scenario: (argument)"),
    (("simulate", "p.json", "--json", ""), "--json"),
])
def test_empty_path_refused_naming_the_option(tmp_path, capsys, monkeypatch, argv, name):
    """'' was read as `.` (a directory), and `--config ''` silently planned with defaults."""
    from rbp.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(list(argv)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {name}: an empty path (''): give a file name"], err
    assert not (tmp_path / "a.json").exists()


def test_yaml_exponent_forms_without_a_dot_are_numbers():
    """YAML 1.1 (PyYAML) read `1e308` as a string: "expected a number, got str '1e308'"."""
    from rb_drake.input_files import load_yaml

    data = load_yaml("a: 1e308\nb: 1e-300\nc: 1E3\nd: 10\ne: -2e+5\nf: 1.0e3\ng: '1e3'\nh: 1_000\n")
    assert data == {"a": 1e308, "b": 1e-300, "c": 1000.0, "d": 10, "e": -2e5, "f": 1000.0,
                    "g": "1e3", "h": 1000}
    assert type(data["d"]) is int and type(data["h"]) is int and type(data["c"]) is float


def test_config_exponent_without_a_dot_is_range_checked(tmp_path):
    from planning.config_io import ConfigError, load_config
    from planning.pipeline import PipelineConfig

    path = tmp_path / "c.yaml"
    path.write_text("footstep: {heuristic_weight: 1e308}\n")
    with pytest.raises(ConfigError, match="heuristic_weight: must be a number from"):
        load_config(str(path), PipelineConfig)
    path.write_text("footstep: {heuristic_weight: 2e0}\n")
    assert load_config(str(path), PipelineConfig).footstep.heuristic_weight == 2.0


@pytest.mark.parametrize("given", ["scenario", "--from-plan"])
def test_plan_refuses_a_bad_scenario_before_the_planners_imports(tmp_path, given):
    """`rbp plan` read its scenario after importing the planner (0.6 s, 170 MB): a near-limit
    scenario with an error at its end took 1.1 s and 232 MB to refuse (scenario check: 100 MB).
    Now nothing of the planner is imported before the refusal."""
    import os
    import subprocess
    import sys

    from rb_drake.scenario import bundled_caves
    from tests.cli_helpers import ROOT

    bad = tmp_path / "bad.yaml"
    bad.write_text(bundled_caves()["demo-shaft"].read_text() + "zzz: 1\n")
    inputs = [str(bad)]
    if given == "--from-plan":  # a plan whose last step is wrong (--from-plan: 238 MB)
        plan = json.loads((GOLDEN / "demo-shaft.json").read_text())
        plan["phases"][-1]["steps"][-1]["pose"] = [0.0]
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(plan))
        inputs = ["--from-plan", str(bad)]
    code = ("import sys; from rbp.cli import main; rc = main(sys.argv[1:]); "
            "print(rc, 'planning.pipeline' in sys.modules, 'planning.plan' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code, "plan", *inputs, "-o",
                             str(tmp_path / "p.json"), "--footsteps-only", "-q"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300,
                            env={**os.environ, "LCM_DEFAULT_URL": "memq://"})
    assert result.stdout.split() == ["2", "False", "False"], (result.stdout, result.stderr)
    assert result.stderr.strip().splitlines()[0].startswith(f"error: {bad}: "), result.stderr


def test_json_units_grow_with_the_size_limit(monkeypatch):
    """rbp wrote a 24 MiB plan (a 20 m climb at --dt 0.01) and said which RBP_MAX_INPUT_MB
    reads it back, but a fixed 2,000,000 units refused it (rbp's plans count about 0.12 units a
    byte): the units limit is a quarter of the size limit's bytes, at least MAX_JSON_UNITS."""
    plan = json.loads((GOLDEN / "demo-shaft.json").read_text())
    plan["phases"] = plan["phases"] * 100  # about 25 MB of rbp's own density
    text = json.dumps(plan)
    assert json_units(text) > MAX_JSON_UNITS, "the plan should be over the default's units"
    with pytest.raises(InputFileError, match="units"):
        load_json(text)
    monkeypatch.setenv("RBP_MAX_INPUT_MB", str(len(text) // 2**20 + 1))
    assert len(load_json(text)["phases"]) == len(plan["phases"])
