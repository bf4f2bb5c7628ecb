"""Probe 20 (session 29): scenarios, planner configurations and the Python API as a researcher
would misuse them. `--partial` with `--min-success` wrote no partial climb and said nothing; a
partial climb whose search expanded no stance said nothing either; a goal tolerance under the
lattice's step was answered "no route ... the body meets rock, or some boom reaches no
anchor" where the sampled search found a route; numpy's bools were refused as flags;
`rbp.meshcat` named simulate's argument; an OpenMP variable libgomp cannot read printed its
warning before every command's output."""

from __future__ import annotations

import ctypes.util
import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line

import rbp
from planning.pipeline import PipelineConfig
from rb_drake.errors import RbpInputError, apart
from rb_drake.scenario import ScenarioError, bundled_caves

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str, cwd: Path = ROOT, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1",
                                   **env), cwd=cwd, timeout=300)


def demo_with_goal(tmp_path: Path, position: list[float], tolerance: float) -> Path:
    """demo-shaft with its goal moved (a file, as a user would write it)."""
    data = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    data["goal"] = {"position": position, "tolerance": tolerance}
    path = tmp_path / "cave.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_partial_with_min_success_is_refused(tmp_path):
    """--min-success's search has no partial route: `--partial --min-success 0.99` wrote a plan
    of no climb, exit 1, the flag silently ignored (as --partial with the sampled search was)."""
    out = tmp_path / "p.json"
    line = one_error_line(run("plan", "demo-shaft", "-o", str(out), "--partial",
                              "--min-success", "0.99"), "--partial", "--min-success")
    assert "gives none" in line, f"the reason is not said: {line}"
    config = tmp_path / "planner.yaml"
    config.write_text("footstep: {min_success: 0.99}\n")
    line = one_error_line(run("plan", "demo-shaft", "-o", str(out), "--partial", "--config",
                              str(config)), f"{config}: footstep.min_success")
    assert not out.exists(), "a refused command wrote its plan"
    cfg = PipelineConfig()
    cfg = dataclasses.replace(cfg, footstep=dataclasses.replace(cfg.footstep, min_success=0.99))
    with pytest.raises(RbpInputError, match=r"^partial: "):
        rbp.plan("demo-shaft", cfg, partial=True)


def test_a_partial_climb_whose_search_expanded_nothing_says_so(tmp_path):
    """A goal no lattice pose can hold ends the search before its first expansion: with
    --partial the plan held no climb and its reason did not say why there was none."""
    cave = demo_with_goal(tmp_path, [0.0, 9000.0], 0.5)
    plan = rbp.plan(str(cave), partial=True)
    assert not plan.success and plan.partial is None, "a climb toward an unreachable goal"
    assert "no partial climb" in plan.reason, f"the missing climb is not said: {plan.reason}"
    assert rbp.check(plan) == [], "the plan of no climb does not verify"


def test_a_goal_tolerance_holding_no_lattice_point_says_so(tmp_path):
    """A tolerance of 5 mm about a point off the lattice: the complete search answered that
    no pose there could hold a stance (the body meets rock, or some boom reaches no anchor),
    while the sampled search climbed to it."""
    cave = demo_with_goal(tmp_path, [0.005, 2.505], 0.005)
    plan = rbp.plan(str(cave), footsteps_only=True)
    assert not plan.success, "a lattice pose reached a disc that holds none"
    assert "no lattice point lies within the goal tolerance (0.005 m)" in plan.reason, \
        f"the tolerance is not named as the cause: {plan.reason}"
    assert "body meets rock" not in plan.reason, f"a wrong cause given: {plan.reason}"
    wider = rbp.plan(str(demo_with_goal(tmp_path, [0.005, 2.505], 0.015)), footsteps_only=True)
    assert "no lattice point" not in wider.reason, f"a disc holding one refused: {wider.reason}"


def test_numpy_bools_are_flags():
    """numpy 2's bool type is `numpy.bool`: np.False_ was refused as "expected True or False"."""
    cave = rbp.load_scenario("demo-shaft", check_start=np.False_)
    assert cave.name == "demo-shaft"
    with pytest.raises(RbpInputError, match="check_start"):
        rbp.load_scenario("demo-shaft", check_start=np.int64(0))


def test_meshcat_names_its_own_argument():
    """`rbp.meshcat("demo-shaft")` was refused as "plan: expected a Plan": an argument it has
    not."""
    for what in ("demo-shaft", None, 5):
        with pytest.raises(RbpInputError) as refused:
            rbp.meshcat(what)  # type: ignore[arg-type]
        assert str(refused.value).startswith("what: "), f"not named as given: {refused.value}"


@pytest.mark.skipif(ctypes.util.find_library("gomp") is None, reason="no libgomp here")
@pytest.mark.parametrize("variable,value", [("OMP_WAIT_POLICY", "bogus"),
                                            ("OMP_SCHEDULE", "bogus"),
                                            ("GOMP_CPU_AFFINITY", "bogus")])
def test_an_openmp_value_libgomp_cannot_read_is_refused(tmp_path, variable, value):
    """libgomp printed "libgomp: Invalid value for environment variable ..." before the output
    of every command that loads it (rbp check, rbp plan), and went on."""
    line = one_error_line(run("scenario", "list", **{variable: value}),
                          f"{variable} (environment)", repr(value))
    assert "libgomp" in line, f"the reader of the value is not named: {line}"
    ok = run("scenario", "list", OMP_STACKSIZE="2M", OMP_WAIT_POLICY="passive")
    assert ok.returncode == 0 and ok.stderr == "", f"valid values refused: {ok.stderr!r}"



def test_a_dxf_unit_rbp_does_not_convert_is_refused(tmp_path):
    """A drawing declaring decimetres ($INSUNITS 14; microns, km, US survey feet, ...) was read
    as metres, silently: a cave ten times too large. --unit still reads it as told."""
    ezdxf = pytest.importorskip("ezdxf")
    rock = yaml.safe_load((ROOT / "rb_drake/data/terrain/lava-tube-shaft.geojson").read_text())
    for code, words in ((14, "decimetres (code 14)"), (99, "code 99")):
        drawing = ezdxf.new()
        drawing.header["$INSUNITS"] = code
        for feature in rock["features"]:
            drawing.modelspace().add_lwpolyline(feature["geometry"]["coordinates"][0][:-1],
                                                close=True)
        path = tmp_path / f"section{code}.dxf"
        drawing.saveas(path)
        out = tmp_path / "cave.yaml"
        one_error_line(run("scenario", "import", str(path), "-o", str(out)),
                       f"{path}: $INSUNITS: ", words, "--unit")
        assert not out.exists(), "a refused import wrote its cave"
    told = run("scenario", "import", str(path), "-o", str(out), "--unit", "m")
    assert told.returncode == 0 and out.exists(), f"--unit m refused: {told.stderr[-300:]}"


def test_a_point_clouds_resolution_with_a_drawing_is_refused(tmp_path):
    """--resolution (a point cloud's outline) was ignored for a drawing, silently, while
    --plane-origin and --plane-normal were refused."""
    drawing = ROOT / "rb_drake/data/terrain/lava-tube-shaft.geojson"
    out = tmp_path / "cave.yaml"
    one_error_line(run("scenario", "import", str(drawing), "-o", str(out), "--resolution",
                       "0.1"), f"{drawing}: --resolution: ", "point cloud")
    assert not out.exists(), "a refused import wrote its cave"
    with pytest.raises(RbpInputError, match="--resolution"):
        rbp.import_scenario(drawing, resolution=0.1)


def test_a_solvers_stop_is_not_printed_beside_the_plans_lines(tmp_path):
    """`scp.dynamics_weight: 1e6` (in its range) printed "INFO:drake:Clarabel returns
    InsufficientProgress" three times on stderr; SCP reads the status and rejects the step."""
    cave, config = tmp_path / "cave.yaml", tmp_path / "planner.yaml"
    made = run("scenario", "generate", "--kind", "shaft", "--seed", "3", "--length", "3.5", "4",
               "-o", str(cave))
    assert made.returncode == 0, made.stderr
    config.write_text("scp: {dynamics_weight: 1000000.0}\n")
    planned = run("plan", str(cave), "-o", str(tmp_path / "p.json"), "--config", str(config),
                  "--no-pictures", "-q")
    assert planned.returncode == 0, f"exit {planned.returncode}: {planned.stderr[-300:]}"
    assert planned.stderr == "", f"stray lines on stderr: {planned.stderr[-300:]!r}"


def test_rbp_plan_checks_a_scenario_objects_start_as_rbp_plan_does(tmp_path):
    """A cave loaded with check_start=False (or its start replaced) was searched by rbp.plan
    and answered "no route ... the start joined to none of its poses", where `rbp plan`
    refuses the start in one line: the same check now, before any search."""
    data = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    data["gravity"] = [0.0, -1000.0]  # no tensions within the booms' bounds hold the body
    path = tmp_path / "heavy.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    line = one_error_line(run("plan", str(path), "-o", str(tmp_path / "p.json")), "start: ")
    cave = rbp.load_scenario(path, check_start=False)
    with pytest.raises(ScenarioError) as refused:
        rbp.plan(cave, footsteps_only=True)
    assert refused.value.field == "start", f"not the start named: {refused.value}"
    assert str(refused.value).split("start: ", 1)[1] == line.split("start: ", 1)[1], \
        "the API's refusal differs from the command line's"
    turned = dataclasses.replace(rbp.load_scenario("demo-shaft"), start_pose=(0.0, 1.0, 3.0))
    with pytest.raises(ScenarioError, match="start"):
        rbp.plan(turned, footsteps_only=True)
    assert rbp.draw(cave, tmp_path / "cave.png").exists(), "a cave's picture needs no start"


def test_a_long_file_name_is_no_name_too_long(tmp_path):
    """A scenario gives no name: its file's stem is its name, and a stem of 220 characters (a
    file name the system allows) was refused, "name: 220 characters; at most 200"; so was
    `rbp scenario import` of such a file without --name."""
    stem = "c" * 220
    data = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    del data["name"]
    cave = tmp_path / f"{stem}.yaml"
    cave.write_text(yaml.safe_dump(data, sort_keys=False))
    checked = run("scenario", "check", str(cave))
    assert checked.returncode == 0, f"refused: {checked.stderr[-200:]}"
    assert rbp.load_scenario(cave).name == stem[:200], "not the stem's first 200 characters"
    drawing = tmp_path / f"{stem}.geojson"
    drawing.write_bytes((ROOT / "rb_drake/data/terrain/lava-tube-shaft.geojson").read_bytes())
    imported = run("scenario", "import", str(drawing), "-o", str(tmp_path / "cave.yaml"))
    assert imported.returncode == 0, f"refused: {imported.stderr[-200:]}"
    assert rbp.load_scenario(tmp_path / "cave.yaml").name == stem[:200]


def test_a_probability_refused_below_p_min_reads_below_it(tmp_path):
    """p_min 0.9999999999: the start's P of 0.999999x was printed "probability 1.000 below
    p_min 0.9999999999", a number above the limit it is said to be below."""
    data = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    data["robot"] = {"p_min": 0.9999999999}
    cave = tmp_path / "cave.yaml"
    cave.write_text(yaml.safe_dump(data, sort_keys=False))
    line = one_error_line(run("scenario", "check", str(cave)), "start: ", "below p_min")
    shown = float(line.split("probability ", 1)[1].split(" ", 1)[0])
    assert shown < 0.9999999999, f"P printed on the wrong side of p_min: {line}"
    assert float(apart(0.99999999985, 0.9999999999)) < 0.9999999999
    assert float(apart(1.00000000015, 1.0000000001)) > 1.0000000001
    assert apart(0.5, 0.9) == "0.500", "more digits than a clear case needs"


@pytest.mark.parametrize("segments,field", [
    ("{tolerance: 100.0}", "footstep.segments.tolerance"),
    ("{lookahead: 0.1, commit: 0.1, min_climb: 0.1}", "footstep.segments.tolerance")])
def test_a_sub_goal_holding_its_segments_start_is_refused(tmp_path, segments, field):
    """A sub-goal disc as wide as the lookahead holds the segment's start: each segment was
    reached where it began, the climb moved on a commit at a time, searching from the start
    again each time (37 s and 22 s under --time-limit 20 on a 20 m crevasse, said "gave up
    after 0.001 s")."""
    config = tmp_path / "planner.yaml"
    config.write_text(f"footstep: {{segments: {segments}}}\n")
    one_error_line(run("plan", "demo-shaft", "-o", str(tmp_path / "p.json"), "--config",
                       str(config)), f"{config}: {field}: ", "below lookahead")
    from planning.segmented import SegmentConfig

    with pytest.raises(RbpInputError, match=r"footstep\.segments\.tolerance"):
        SegmentConfig(lookahead=0.5, commit=0.5, tolerance=0.5)


def test_segments_stop_at_the_time_limit_and_say_how_long_they_searched():
    """The segments went on searching past the time limit, each later search given 1 ms, and
    the answer said "gave up after 0.001 s"."""
    from planning.complete_config import CompleteConfig
    from planning.segmented import SegmentConfig, segmented_search

    cave = rbp.generate_scenario("crevasse", seed=5003, length=(20.0, 20.0))
    config = dataclasses.replace(CompleteConfig(), time_limit=3.0)
    segment = SegmentConfig(min_climb=0.1, lookahead=0.1, commit=0.1, tolerance=0.01)
    started = time.perf_counter()
    result = segmented_search(cave, config, segment, lambda scenario: None)
    took = time.perf_counter() - started
    assert not result.success and took < 3.0 + 5.0, f"searched {took:.1f} s under a 3 s limit"
    assert "gave up after 3 s" in result.reason, f"not the limit's time: {result.reason}"


def test_the_hybrid_search_says_the_time_both_stages_searched():
    """--search hybrid --time-limit 5 searched 5 s in all and said "gave up after 1.83 s (302
    expansions)", the complete stage's share and count."""
    cave = rbp.generate_scenario("crevasse", seed=5003, length=(20.0, 20.0))
    cfg = PipelineConfig()
    cfg = dataclasses.replace(cfg, footstep=dataclasses.replace(cfg.footstep, search="hybrid",
                                                                time_limit=3.0))
    plan = rbp.plan(cave, cfg, footsteps_only=True)
    assert not plan.success and plan.search is not None
    assert plan.reason.startswith(f"gave up after 3 s ({plan.search.expansions} expansions)"), \
        f"not the whole search's time and expansions: {plan.reason}"
