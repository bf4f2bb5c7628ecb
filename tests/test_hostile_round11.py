"""Probe 11 (round 33): plans that cannot become a trajectory refused in one line with
--no-verify and by the API's simulate (F7)."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import rbp
from rb_drake.errors import RbpInputError
from systems.trajectory import PlanError, check_flyable

GOLDEN = Path(__file__).parent / "data" / "golden"
ROOT = Path(__file__).resolve().parents[1]
Plan = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> Plan:
    return json.loads((GOLDEN / "demo-shaft-current.json").read_text())


def tiny_gap(golden: Plan, gap: float) -> Plan:
    """A continuation whose phase 0 moves in `gap` s (mk_tiny.py of probe 11)."""
    p = copy.deepcopy(golden)
    p["start"] = {"pose": list(p["phases"][0]["steps"][0]["pose"]),
                  "stance": list(p["scenario"]["start"]["stance"])}
    ph = p["phases"][0]
    ph.pop("motion", None)
    s = ph["steps"]
    last0 = s[-1]["t"]
    ramps = [i for i, x in enumerate(s) if "ramp" in x]
    keep = [s[0], s[ramps[0] - 1]] + [s[i] for i in ramps]
    base = keep[1]["t"]
    keep[1]["t"] = gap
    for x in keep[2:]:
        x["t"] = gap + (x["t"] - base)
    d = keep[-1]["t"] - last0
    ph["steps"] = keep
    for q in p["phases"][1:]:
        for x in q["steps"]:
            x["t"] += d
    return p


def attach_only(golden: Plan, keep: int) -> Plan:
    p = copy.deepcopy(golden)
    p["phases"][-1]["steps"] = p["phases"][-1]["steps"][:keep]
    p["phases"][-1].pop("motion", None)
    return p


def run(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)


@pytest.mark.parametrize("gap", [1e-30, 5e-324, 1e-9])
def test_steps_closer_than_the_gap_cannot_be_flown(golden: Plan, gap: float) -> None:
    with pytest.raises(PlanError, match=r"phases\[0\].steps\[1\].t: .*at least 0.001 s"):
        check_flyable(tiny_gap(golden, gap))


@pytest.mark.parametrize("keep", [1, 2])
def test_a_phase_of_ramp_steps_only_cannot_be_flown(golden: Plan, keep: int) -> None:
    with pytest.raises(PlanError, match=r"phases\[14\].steps: .*ramp step\(s\) only"):
        check_flyable(attach_only(golden, keep))


def test_the_golden_plan_can_be_flown(golden: Plan) -> None:
    check_flyable(golden)


def test_api_simulate_refuses_a_plan_it_cannot_fly(golden: Plan) -> None:
    """rbp.simulate never verifies: a RuntimeError from Drake before."""
    with pytest.raises(RbpInputError, match=r"at least 0\.001 s"):
        rbp.simulate(tiny_gap(golden, 1e-30), trials=1)


@pytest.mark.parametrize("command", [["simulate", "--trials", "1"],
                                     ["rig-run", "--sim-rig", "--phase", "0"]])
@pytest.mark.parametrize("make", ["tiny", "attach"])
def test_no_verify_refuses_in_one_line(golden: Plan, tmp_path: Path, command: list[str],
                                       make: str) -> None:
    plan = tiny_gap(golden, 1e-30) if make == "tiny" else attach_only(golden, 1)
    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan))
    extra = ["--log", str(tmp_path / "r.lcm")] if command[0] == "rig-run" else []
    r = run(command[0], "--no-verify", str(path), *command[1:], *extra)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: phases["), lines


# F1, S2: one check of dt against seed.step/seed.turn_step for the CLI, the API and rbp check
SPEED = "steps of up to 2 x seed.step 0.1 m and seed.turn_step 0.05 rad every 0.25 s exceed " \
        "rule speed"


def test_api_plan_refuses_dt_too_short_for_the_seed_steps() -> None:
    from planning.config_io import ConfigError
    from planning.pipeline import PipelineConfig
    from planning.seed_common import SeedConfig

    cfg = PipelineConfig(dt=0.25, seed=SeedConfig(step=0.1, turn_step=0.05))
    with pytest.raises(ConfigError, match=r"config: dt: " + SPEED):
        rbp.plan("demo-shaft", cfg)


def test_check_and_from_plan_refuse_the_recorded_config(golden: Plan, tmp_path: Path) -> None:
    plan = copy.deepcopy(golden)
    config = plan["provenance"]["config"]
    config["dt"] = 0.25
    config["seed"].update(step=0.1, turn_step=0.05)
    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan))
    for args in (["check", str(path)],
                 ["plan", "--from-plan", str(path), "-o", str(tmp_path / "o.json"), "-q",
                  "--no-pictures"]):
        r = run(*args)
        assert r.returncode == 2, r.stderr
        assert r.stderr.splitlines() == [
            f"error: {path}: provenance.config.dt: {SPEED} (0.4 m/s, 0.4 rad/s); give dt at "
            "least 0.5"], r.stderr


def test_cli_config_refused_in_the_same_words(tmp_path: Path) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("dt: 0.25\nseed: {step: 0.1, turn_step: 0.05}\n")
    r = run("plan", "demo-shaft", "--config", str(cfg), "-o", str(tmp_path / "o.json"), "-q",
            "--no-pictures")
    assert r.returncode == 2 and r.stderr.splitlines() == [
        f"error: {cfg}: dt: {SPEED} (0.4 m/s, 0.4 rad/s); give dt at least 0.5"], r.stderr


def test_deleted_current_folder_names_the_file_and_option(tmp_path: Path) -> None:
    """F8: `error: (file): No such file or directory` named neither."""
    gone = tmp_path / "gone"
    gone.mkdir()
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1",
               PYTHONPATH=str(ROOT))  # no empty entry: Python makes it absolute at start
    r = subprocess.run(["sh", "-c", f'cd "{gone}" && rmdir "{gone}" && exec "{sys.executable}" '
                        "-m rbp plan demo-shaft -o x.json -q --no-pictures"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2 and r.stderr.splitlines() == [
        "error: x.json: -o: the current folder no longer exists (deleted while the shell was "
        "in it): give an absolute path or change folder"], r.stderr


# F4: svgelements' ZeroDivisionError ("float division by zero") named neither field nor reason
WALL = '<path d="M -3 1 L -1 1 L -1 -6 L -3 -6 Z"/>'


@pytest.mark.parametrize("svg, expected", [
    (f'<svg xmlns="http://www.w3.org/2000/svg">{WALL}<path d="M 1 1 A 1e-300 1e-300 0 1 1 3 1 '
     'L 3 -6 L 1 -6 Z"/></svg>', ": path d: an arc (A) whose radii are too small to compute"),
    (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 0 0" width="1e308" height="10">'
     f'{WALL}</svg>', ": viewBox: a zero width or height"),
])
def test_svg_division_by_zero_named(tmp_path: Path, svg: str, expected: str) -> None:
    path = tmp_path / "d.svg"
    path.write_text(svg)
    r = run("scenario", "import", str(path), "-o", str(tmp_path / "d.yaml"))
    lines = r.stderr.splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith(f"error: {path}{expected}"), lines


def test_a_boom_longer_than_the_search_can_afford_is_refused() -> None:
    """robot.boom_length [0, 20] ran demo-shaft's search past 60 s and 1 GB: refused at
    reading, in one line, up to MAX_BOOM (5 m) accepted."""
    from rb_drake.params import MAX_BOOM, ParamError, robot_from_dict

    with pytest.raises(ParamError) as err:
        robot_from_dict({"boom_length": [0, 20]})
    assert err.value.field == "boom_length[1]", err.value.field
    assert robot_from_dict({"boom_length": [0, MAX_BOOM]}).boom_length == (0.0, MAX_BOOM)
