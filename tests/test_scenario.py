"""Scenario files: bundled caves load and round-trip; bad input is refused with a ScenarioError
naming the file, the field and the reason (in the library and on the command line); output
files are written atomically.

Bad files are built from the bundled demo-shaft.yaml: loaded with yaml.safe_load, mutated, and
written to tmp_path.
"""

from __future__ import annotations

import copy
import functools
import locale
import math
import os
import stat
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from rb_drake.collision import signed_area
from rb_drake.files import atomic_write, atomic_write_text
from rb_drake.params import RobotParams
from rb_drake.scenario import (
    Scenario,
    ScenarioError,
    bundled_caves,
    load_scenario,
    scenario_from_dict,
    scenario_to_yaml,
)

ROOT = Path(__file__).resolve().parents[1]
CAVES = bundled_caves()
DEMO = CAVES["demo-shaft"]

Mutation = Callable[[dict[str, Any]], None]


# ---------------------------------------------------------------------------------------------
# Helpers


@functools.cache
def _demo_data() -> dict[str, Any]:
    data = yaml.safe_load(DEMO.read_text())
    assert isinstance(data, dict), f"{DEMO} does not hold a mapping"
    return data


def demo_dict() -> dict[str, Any]:
    """A fresh copy of demo-shaft.yaml's contents (parsed once: PyYAML is slow)."""
    return copy.deepcopy(_demo_data())


def write_yaml(folder: Path, name: str, data: Any) -> Path:
    path = folder / name
    path.write_text(yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper),
                              sort_keys=False))
    return path


def bad_file(folder: Path, mutate: Mutation, name: str = "bad.yaml") -> Path:
    data = demo_dict()
    mutate(data)
    return write_yaml(folder, name, data)


def set_field(path: tuple[Any, ...], value: Any) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        target: Any = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = copy.deepcopy(value)

    return mutate


def drop_field(path: tuple[Any, ...]) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        target: Any = data
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return mutate


def reverse_wall(k: int) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        data["walls"][k] = data["walls"][k][::-1]

    return mutate


def bow_tie_wall(k: int) -> Mutation:
    """Swap the last two vertices of wall k: its closing edges now cross (a bow-tie)."""

    def mutate(data: dict[str, Any]) -> None:
        wall = data["walls"][k]
        wall[-1], wall[-2] = wall[-2], wall[-1]

    return mutate


def refused(path: Path, check_start: bool = True) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, check_start=check_start)
    return info.value


def run_rbp(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "rbp", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def assert_same_scenario(a: Scenario, b: Scenario, tol: float = 1e-12) -> None:
    """Same anchors, walls, start, goal, gravity and robot (normals up to `tol`)."""
    assert a.name == b.name, f"name {a.name!r} != {b.name!r}"
    assert a.gravity == b.gravity, f"gravity {a.gravity} != {b.gravity}"
    assert a.robot == b.robot, f"robot {a.robot} != {b.robot}"
    assert len(a.walls) == len(b.walls), f"{len(a.walls)} walls != {len(b.walls)}"
    for k, (wa, wb) in enumerate(zip(a.walls, b.walls, strict=True)):
        assert np.array_equal(wa, wb), f"walls[{k}] differ:\n{wa}\n{wb}"
    assert [x.id for x in a.anchors] == [x.id for x in b.anchors], "anchor ids differ"
    for x, y in zip(a.anchors, b.anchors, strict=True):
        assert x.position == y.position, f"anchor {x.id}: position {x.position} != {y.position}"
        assert np.allclose(x.normal, y.normal, rtol=0.0, atol=tol), (
            f"anchor {x.id}: normal {x.normal} != {y.normal} (atol {tol})")
        assert (x.f_normal, x.f_lateral, x.sigma_normal, x.sigma_lateral) == (
            y.f_normal, y.f_lateral, y.sigma_normal, y.sigma_lateral), f"anchor {x.id}: limits"
    assert a.start_pose == b.start_pose, f"start pose {a.start_pose} != {b.start_pose}"
    assert a.start_stance == b.start_stance, f"stance {a.start_stance} != {b.start_stance}"
    assert a.goal_position == b.goal_position, f"goal {a.goal_position} != {b.goal_position}"
    assert a.goal_tolerance == b.goal_tolerance


# ---------------------------------------------------------------------------------------------
# Bundled caves


def test_bundled_caves_present():
    assert {"demo-shaft", "crevasse-2", "rockfall-3"} <= set(CAVES), f"bundled: {sorted(CAVES)}"
    for name, path in CAVES.items():
        assert path.is_file(), f"{name}: {path} is not a file"


@pytest.mark.parametrize("name", sorted(CAVES))
def test_bundled_cave_loads(name):
    scn = load_scenario(CAVES[name], check_start=True)
    assert scn.name == name, f"name {scn.name!r}, expected the file stem {name!r}"
    assert scn.source == str(CAVES[name])
    assert len(scn.anchors) >= 4, f"{name}: only {len(scn.anchors)} anchors"
    assert len(set(scn.start_stance)) == 4 and set(scn.start_stance) <= set(scn.anchor_index)
    norms = np.linalg.norm(scn.anchor_normals, axis=1)
    assert np.allclose(norms, 1.0, atol=1e-12), f"{name}: normal norms {norms}"
    for k, wall in enumerate(scn.walls):
        assert signed_area(wall) > 0, f"{name}: walls[{k}] is not counter-clockwise"
    assert np.allclose(scn.gravity_vector, [0.0, -3.71], atol=1e-12)


@pytest.mark.parametrize("name", sorted(CAVES))
def test_bundled_cave_round_trips(name):
    scn = load_scenario(CAVES[name])
    text = scenario_to_yaml(scn)
    again = scenario_from_dict(yaml.safe_load(text), source=f"{name}-again.yaml",
                               check_start=True)
    assert_same_scenario(scn, again)
    # A second trip is stable too.
    third = scenario_from_dict(yaml.safe_load(scenario_to_yaml(again)), check_start=False)
    assert_same_scenario(again, third)


def test_round_trip_keeps_robot_overrides(tmp_path):
    path = bad_file(tmp_path, set_field(("robot",), {"body_mass": 2.5, "p_min": 0.9}),
                    name="heavy.yaml")
    scn = load_scenario(path)
    assert scn.robot == RobotParams(body_mass=2.5, p_min=0.9), f"robot {scn.robot}"
    again = scenario_from_dict(yaml.safe_load(scenario_to_yaml(scn)))
    assert again.robot == scn.robot, f"overrides lost: {again.robot}"
    resolved = scenario_from_dict(scn.to_dict(resolved=True), check_start=False)
    assert resolved.robot == scn.robot, "resolved robot parameters do not load back"


def test_normal_in_degrees_is_a_unit_vector(tmp_path):
    path = bad_file(tmp_path, set_field(("anchors", 2, "normal"), 10.0), name="deg.yaml")
    a = load_scenario(path, check_start=False).anchors[2]
    expected = (math.cos(math.radians(10.0)), math.sin(math.radians(10.0)))
    assert np.allclose(a.normal, expected, atol=1e-12), f"normal {a.normal}, expected {expected}"


# ---------------------------------------------------------------------------------------------
# Bad input, in the library

# (id, mutation, field, words the reason must contain (case-insensitive))
BAD_CASES: list[tuple[str, Mutation, str, tuple[str, ...]]] = [
    ("missing-walls", drop_field(("walls",)), "walls", ("missing",)),
    ("missing-anchors", drop_field(("anchors",)), "anchors", ("missing",)),
    ("missing-start", drop_field(("start",)), "start", ("missing",)),
    ("missing-goal", drop_field(("goal",)), "goal", ("missing",)),
    ("missing-anchor-position", drop_field(("anchors", 2, "position")), "anchors[2].position",
     ("missing",)),
    ("missing-start-pose", drop_field(("start", "pose")), "start.pose", ("missing",)),
    ("string-limit", set_field(("anchors", 2, "limit", "normal"), "forty"),
     "anchors[2].limit.normal", ("number", "forty")),
    ("string-gravity", set_field(("gravity", 1), "down"), "gravity[1]", ("number", "down")),
    ("walls-not-a-list", set_field(("walls",), "granite"), "walls", ("list",)),
    ("negative-sigma", set_field(("anchors", 4, "sigma", "lateral"), -2.0),
     "anchors[4].sigma.lateral", ("positive",)),
    ("zero-normal", set_field(("anchors", 1, "normal"), [0.0, 0.0]), "anchors[1].normal",
     ("zero",)),
    ("unknown-stance-id", set_field(("start", "stance", 1), "a999"), "start.stance[1]",
     ("unknown", "a999")),
    ("repeated-stance-id", lambda d: d["start"]["stance"].__setitem__(1, d["start"]["stance"][0]),
     "start.stance",
     ("own anchor",)),
    ("nan-position", set_field(("anchors", 3, "position", 0), math.nan),
     "anchors[3].position[0]", ("finite",)),
    ("bow-tie-wall", bow_tie_wall(0), "walls[0]", ("simple", "cross")),
    ("clockwise-wall", reverse_wall(0), "walls[0]", ("clockwise",)),
    ("anchor-inside-rock", set_field(("anchors", 2, "position"), [-1.8, 0.8]),
     "anchors[2].position", ("inside rock", "a2")),
    ("normal-into-rock", set_field(("anchors", 2, "normal"), [-1.0, 0.0]), "anchors[2].normal",
     ("into the rock", "a2")),
    ("anchor-off-its-wall", set_field(("anchors", 2, "position"), [0.0, 0.5]),
     "anchors[2].position", ("off its wall", "a2", "0.05 m")),
    # demo-shaft's left wall is rock from x = -1.94 to about -0.94
    ("goal-inside-rock", set_field(("goal", "position"), [-1.2, 2.0]), "goal.position",
     ("inside rock", "free space")),
    ("goal-disc-wholly-in-rock", set_field(("goal",), {"position": [-1.44, 2.0],
                                                      "tolerance": 0.2}),
     "goal.position", ("inside rock", "whole tolerance disc", "0.2 m")),
    ("duplicate-anchor-id", set_field(("anchors", 5, "id"), "a2"), "anchors[5].id",
     ("duplicate", "a2")),
    ("unknown-top-level", set_field(("colour",), "red"), "colour", ("unknown field",)),
    ("unknown-anchor-field", set_field(("anchors", 0, "colour"), "red"), "anchors[0].colour",
     ("unknown field",)),
    ("wrong-format", set_field(("format",), "reachbot-scenario/0"), "format",
     ("reachbot-scenario/1",)),
    ("robot-unknown-name", set_field(("robot",), {"wings": 2}), "robot.wings",
     ("unknown", "robot parameter")),
    ("robot-negative-mass", set_field(("robot",), {"body_mass": -1.0}), "robot.body_mass",
     ("-1.0",)),
    ("robot-boom-length-reversed", set_field(("robot",), {"boom_length": [2.0, 1.0]}),
     "robot.boom_length", ("min < max",)),
    ("robot-boom-length-equal", set_field(("robot",), {"boom_length": [1.0, 1.0]}),
     "robot.boom_length", ("min < max",)),
    ("robot-p-min-over-one", set_field(("robot",), {"p_min": 1.5}), "robot.p_min", ("<= 1",)),
    # degenerate values that passed and broke the model: a ZeroDivisionError in the wrench
    # conditioning, p_path 0 reported as a success, NaN probabilities from the grasp model
    ("robot-shoulders-at-centre", set_field(("robot",), {"shoulders": [[0, 0]] * 4}),
     "robot.shoulders[0]", ("body's centre",)),
    ("robot-shoulders-same", set_field(("robot",), {"shoulders": [[0.1, 0.1]] * 4}),
     "robot.shoulders[1]", ("shoulder 0", "apart")),
    ("robot-attach-failure-one", set_field(("robot",), {"attach_failure": 1}),
     "robot.attach_failure", ("< 1",)),
    ("sigma-tiny", set_field(("anchors", 0, "sigma", "normal"), 5e-324),
     "anchors[0].sigma.normal", ("at least 0.001",)),
    ("limit-tiny", set_field(("anchors", 1, "limit", "lateral"), 1e-200),
     "anchors[1].limit.lateral", ("at least 0.001",)),
    # unknown keys below the top level were ignored: a misspelt one left its default in force
    ("goal-misspelt-key", set_field(("goal", "tolerence"), 0.1), "goal.tolerence",
     ("unknown field", "tolerance")),
    ("start-extra-key", set_field(("start", "phi"), 0.1), "start.phi", ("unknown field",)),
    ("limit-extra-key", set_field(("anchors", 0, "limit", "tangential"), 5),
     "anchors[0].limit.tangential", ("unknown field",)),
    ("sigma-extra-key", set_field(("anchors", 0, "sigma", "x"), 5), "anchors[0].sigma.x",
     ("unknown field",)),
    ("robot-false", set_field(("robot",), False), "robot", ("mapping",)),
    ("robot-empty-string", set_field(("robot",), ""), "robot", ("mapping",)),
]


@pytest.mark.parametrize(("mutate", "field", "words"), [c[1:] for c in BAD_CASES],
                         ids=[c[0] for c in BAD_CASES])
def test_bad_input_refused(tmp_path, mutate, field, words):
    data = demo_dict()
    mutate(data)
    path = write_yaml(tmp_path, "bad.yaml", data)
    err = refused(path)
    assert err.source == str(path), f"source {err.source!r}, expected {str(path)!r}"
    assert err.field == field, f"field {err.field!r}, expected {field!r} (reason: {err.reason})"
    for word in words:
        assert word.lower() in err.reason.lower(), f"reason {err.reason!r} lacks {word!r}"
    text = str(err)
    assert "\n" not in text, f"message is not one line: {text!r}"
    assert text == f"{path}: {field}: {err.reason}", f"message {text!r}"
    # The same data refused without the file: source is the one given.
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, source="given.yaml")
    assert (info.value.source, info.value.field) == ("given.yaml", field)


def test_nan_written_as_yaml_nan_is_refused(tmp_path):
    path = tmp_path / "nan.yaml"
    text = DEMO.read_text()
    x, y = load_scenario(DEMO, check_start=False).anchors[3].position
    old = f"position: [{x}, {y}]"
    assert old in text, f"anchor a3's position {old!r} not found in demo-shaft.yaml"
    path.write_text(text.replace(old, f"position: [{x}, .nan]"))
    err = refused(path)
    assert (err.source, err.field) == (str(path), "anchors[3].position[1]"), str(err)
    assert "finite" in err.reason, err.reason


def test_infeasible_start_pose_refused_with_why(tmp_path):
    path = bad_file(tmp_path, set_field(("start", "pose"), [0.0, 5.0, 0.0]))
    err = refused(path)
    assert err.source == str(path)
    assert err.field == "start", f"field {err.field!r}"
    reason = err.reason.lower()
    assert "not feasible" in reason, err.reason
    assert "boom" in reason and "length" in reason, f"reason does not say why: {err.reason}"
    # Without the start check the same file loads.
    scn = load_scenario(path, check_start=False)
    assert scn.start_pose == (0.0, 5.0, 0.0)


def test_invalid_yaml_syntax(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("format: reachbot-scenario/1\nwalls: [[1, 2]\nanchors: {a: }\n  b: c\n")
    err = refused(path)
    assert err.source == str(path)
    assert err.field.startswith("line "), f"field {err.field!r} should give the line"
    assert "yaml" in err.reason.lower(), err.reason
    assert "\n" not in str(err), repr(str(err))


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.yaml"
    err = refused(path)
    assert (err.source, err.field) == (str(path), "(file)"), str(err)
    assert "no such file" in err.reason, err.reason


@pytest.mark.parametrize("text", ["", "just a string\n", "- 1\n- 2\n"],
                         ids=["empty", "str", "list"])
def test_top_level_not_a_mapping(tmp_path, text):
    path = tmp_path / "flat.yaml"
    path.write_text(text)
    err = refused(path)
    assert (err.source, err.field) == (str(path), "(top level)"), str(err)
    assert "mapping" in err.reason, err.reason


def test_robot_not_a_mapping_names_field_robot(tmp_path):
    path = bad_file(tmp_path, set_field(("robot",), "big"))
    err = refused(path)
    assert err.field == "robot", f"field {err.field!r}"


def test_control_character_message_is_one_line(tmp_path):
    path = tmp_path / "ctrl.yaml"
    path.write_text("format: reachbot-scenario/1\x07\n")
    err = refused(path)
    assert err.source == str(path)
    assert "\n" not in str(err), f"message spans lines: {str(err)!r}"


@pytest.mark.skipif(locale.getpreferredencoding(False).lower().replace("-", "") != "utf8",
                    reason="needs a UTF-8 locale to make the bytes undecodable")
def test_undecodable_file_refused(tmp_path):
    path = tmp_path / "binary.yaml"
    path.write_bytes(b"format: \xff\xfe reachbot\n")
    err = refused(path)
    assert err.source == str(path)


def test_mixed_type_unknown_keys_refused(tmp_path):
    path = tmp_path / "keys.yaml"
    path.write_text(DEMO.read_text() + "1: one\ncolour: red\n")
    err = refused(path)
    assert err.field in {"1", "colour"}, f"field {err.field!r}"


# ---------------------------------------------------------------------------------------------
# Bad input, on the command line

CLI_CASES = [
    ("clockwise-wall", reverse_wall(0), "walls[0]"),
    ("unknown-stance-id", set_field(("start", "stance", 1), "a999"), "start.stance[1]"),
    ("string-limit", set_field(("anchors", 2, "limit", "normal"), "forty"),
     "anchors[2].limit.normal"),
]


def assert_one_line_error(proc: subprocess.CompletedProcess[str], name: str, field: str) -> None:
    assert proc.returncode == 2, f"exit {proc.returncode}; stderr:\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip("\n").splitlines()
    assert len(lines) == 1, f"stderr is not one line:\n{proc.stderr}"
    assert lines[0].startswith("error:"), lines[0]
    assert name in lines[0] and field in lines[0], f"{lines[0]!r} lacks {name!r} or {field!r}"


@pytest.mark.parametrize(("mutate", "field"), [c[1:] for c in CLI_CASES],
                         ids=[c[0] for c in CLI_CASES])
def test_cli_check_bad_input(tmp_path, mutate, field):
    bad_file(tmp_path, mutate, name="BAD.yaml")
    proc = run_rbp("scenario", "check", "BAD.yaml", cwd=tmp_path)
    assert_one_line_error(proc, "BAD.yaml", field)
    assert "ok" not in proc.stdout, proc.stdout


def test_cli_check_missing_file(tmp_path):
    proc = run_rbp("scenario", "check", "GONE.yaml", cwd=tmp_path)
    assert_one_line_error(proc, "GONE.yaml", "(file)")


def test_cli_show_bad_input_writes_nothing(tmp_path):
    bad_file(tmp_path, reverse_wall(1), name="BAD.yaml")
    proc = run_rbp("scenario", "show", "BAD.yaml", "-o", "out.png", cwd=tmp_path)
    assert_one_line_error(proc, "BAD.yaml", "walls[1]")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["BAD.yaml"], f"files left in the folder: {left}"


@pytest.mark.skipif(locale.getpreferredencoding(False).lower().replace("-", "") != "utf8",
                    reason="needs a UTF-8 locale to make the bytes undecodable")
def test_cli_check_undecodable_file(tmp_path):
    (tmp_path / "BIN.yaml").write_bytes(b"format: \xff\xfe reachbot\n")
    proc = run_rbp("scenario", "check", "BIN.yaml", cwd=tmp_path)
    assert_one_line_error(proc, "BIN.yaml", "(file)")


# ---------------------------------------------------------------------------------------------
# Atomic writes


class WriterFailedError(Exception):
    pass


@pytest.mark.parametrize("exc", [WriterFailedError, KeyboardInterrupt])
def test_atomic_write_failure_keeps_old_file(tmp_path, exc):
    target = tmp_path / "plan.json"
    target.write_text("old content\n")

    def writer(f):
        f.write(b"new, half-")
        f.flush()
        raise exc("interrupted midway")

    with pytest.raises(exc):
        atomic_write(target, writer)
    assert target.read_text() == "old content\n", f"old file damaged: {target.read_text()!r}"
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["plan.json"], f"temporary files left: {left}"


def test_atomic_write_failure_creates_nothing(tmp_path):
    target = tmp_path / "sub" / "new.png"

    def writer(f):
        f.write(b"\x89PNG partial")
        raise WriterFailedError("disk full")

    with pytest.raises(WriterFailedError):
        atomic_write(target, writer)
    assert not target.exists(), "a half-written file was left at the target"
    left = sorted(p.name for p in (tmp_path / "sub").iterdir())
    assert left == [], f"temporary files left: {left}"


def test_atomic_write_replaces_content(tmp_path):
    target = tmp_path / "cave.yaml"
    target.write_text("old\n")
    out = atomic_write_text(target, "new content\n")
    assert out == target
    assert target.read_text() == "new content\n"
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["cave.yaml"], f"temporary files left: {left}"


def test_atomic_write_respects_umask(tmp_path):
    old = os.umask(0o022)
    try:
        target = atomic_write_text(tmp_path / "start.json", "{}\n")
    finally:
        os.umask(old)
    mode = stat.S_IMODE(target.stat().st_mode)
    assert mode == 0o644, f"mode {oct(mode)}, expected 0o644 under umask 022"


def test_a_start_angle_a_full_turn_away_is_the_same_start() -> None:
    """A start at phi + 2 pi is the same pose as at phi, but the lattice joined it to none of
    its poses (their straight paths from it turned the body a full circle): "no route". The
    start's angle is kept within [-pi, pi], so both plan the same route."""
    import dataclasses

    from planning.footsteps import FootstepConfig, plan_footsteps

    scn = load_scenario(bundled_caves()["demo-shaft"])
    x, y, phi = scn.start_pose
    turned = dataclasses.replace(scn, start_pose=(x, y, phi + 2.0 * math.pi))
    assert abs(turned.start_pose[2] - phi) < 1e-12, turned.start_pose
    config = FootstepConfig(max_expansions=40, anytime=None)
    a, b = plan_footsteps(scn, config), plan_footsteps(turned, config)
    assert a.success and b.success, (a.reason, b.reason)
    assert a.stances == b.stances, "a start a full turn away planned another route"
