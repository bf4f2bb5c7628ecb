"""Probe 12 (session 27): a shoulder exactly on its anchor, a success its own search record
denies, a phase without motion after the replanned ones, a continuation's start said aloud, a
plan's scenario held to a scenario file's limit, a plan's total samples between steps bounded,
rig messages out of any rig's range."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import planning.smooth_motion as smooth_motion
import planning.verify_between as verify_between
from planning.check import verify_plan
from planning.plan_file import PlanFileError, validated
from planning.plan_model import Plan
from planning.verify_climb import check_note

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).resolve().parents[1]
PlanFile = dict[str, Any]


@pytest.fixture(scope="module")
def golden() -> PlanFile:
    return json.loads((DATA / "golden" / "demo-shaft-current.json").read_text())


def run(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)


def test_a_shoulder_on_its_anchor_is_refused_in_one_line() -> None:
    """The rig with shoulder 0 moved onto its anchor at the start pose: a boom of length 0 had
    no direction, and its NaN column ended in numpy's LinAlgError (and warnings)."""
    path = DATA / "hostile" / "rig-shoulder-on-anchor.yaml"
    done = run("scenario", "check", str(path))
    lines = done.stderr.strip().splitlines() + done.stdout.strip().splitlines()
    assert done.returncode == 2, f"exit {done.returncode}: {done.stderr[-400:]}"
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: start:"), lines
    assert "nan" not in lines[0].lower(), f"a NaN reached the message: {lines[0]}"


def test_success_that_the_search_record_denies_is_refused(golden: PlanFile) -> None:
    plan = copy.deepcopy(golden)
    plan["search"]["stop"] = "noroute"
    problems = verify_plan(plan)
    assert [p.rule for p in problems] == ["goal"] and "noroute" in problems[0].text, \
        "\n".join(map(str, problems))


def test_only_a_continuations_first_phases_may_lack_motion(golden: PlanFile) -> None:
    """A plan with `start` set (a continuation) may hold spliced phases without motion first;
    a later one without motion escaped rules time-order and continuity."""
    plan = copy.deepcopy(golden)
    plan["start"] = copy.deepcopy(plan["scenario"]["start"])
    k = len(plan["phases"]) // 2
    plan["phases"][k].pop("motion")
    problems = verify_plan(plan)
    assert any(p.rule == "phase-form" and p.phase == k for p in problems), \
        "\n".join(map(str, problems))
    for phase in plan["phases"][:k]:  # the same phase, spliced in with those before it
        phase.pop("motion", None)
    assert verify_plan(plan) == [], "a continuation's spliced first phases were refused"


def test_a_continuation_says_where_it_starts(golden: PlanFile) -> None:
    plan = copy.deepcopy(golden)
    assert check_note(Plan.from_dict(plan)) == "", "a plain plan got a note"
    plan["start"] = copy.deepcopy(plan["scenario"]["start"])
    note = check_note(Plan.from_dict(plan))
    assert note.startswith("a continuation: starts at pose") and "not verified" in note, note


def test_a_plans_scenario_is_held_to_a_scenario_files_limit(golden: PlanFile,
                                                              monkeypatch) -> None:
    validated(copy.deepcopy(golden))  # within the default limit
    monkeypatch.setenv("RBP_MAX_INPUT_VALUES", "500")  # it holds 994
    with pytest.raises(PlanFileError) as refused:
        validated(copy.deepcopy(golden))
    assert refused.value.field == "scenario" and "500 values" in refused.value.reason, \
        str(refused.value)


def test_a_plans_samples_between_steps_are_bounded(golden: PlanFile, monkeypatch) -> None:
    """Many phases each under MAX_PHASE_SAMPLES made an 8 MiB plan take minutes: past
    MAX_PLAN_SAMPLES in all, the phase that passes it is reported and the rest not sampled."""
    assert verify_plan(copy.deepcopy(golden)) == [], "the demo plan fails before any bound"
    monkeypatch.setattr(verify_between, "MAX_PLAN_SAMPLES", 200)
    monkeypatch.setattr(smooth_motion, "MAX_PLAN_SAMPLES", 200)
    problems = verify_plan(copy.deepcopy(golden))
    assert problems and all(p.rule == "between" and "too long to verify" in p.text
                            for p in problems), "\n".join(map(str, problems))
    assert len(problems) <= 2, f"expected one report per motion (straight, smooth): {problems}"


def test_rig_messages_out_of_any_rigs_range() -> None:
    """A command stamped at -2^63 us is refused; statuses reading a hinge at 1e300 rad are
    skipped as other unreadable statuses are (the log had reported P = 0 from them)."""
    log = DATA / "hostile" / "log-extreme-utime.lcm"
    done = run("rig-replay", str(log))
    assert done.returncode == 2 and "utime" in done.stderr, done.stderr[-400:]
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    done = run("rig-replay", str(DATA / "hostile" / "log-hinge-1e300.lcm"))
    assert done.returncode == 0 and "0 statuses" in done.stdout, \
        f"exit {done.returncode}: {done.stdout[-300:]} {done.stderr[-300:]}"


def test_a_long_polish_keeps_the_plan_verifiable(tmp_path: Path) -> None:
    """`footstep.polish_rounds: 300` (in range) pushed transition poses to where the plan's
    allocation failed: `rbp plan` said success with p_min 0 and `rbp check` refused the plan.
    A polished pose is now kept only where the plan will hold as built."""
    config = tmp_path / "polish.yaml"
    config.write_text("footstep: {polish_rounds: 300}\n")
    out = tmp_path / "plan.json"
    done = run("plan", "demo-shaft", "--config", str(config), "--footsteps-only", "-o", str(out),
               "--quiet", "--no-pictures")
    assert done.returncode == 0, done.stderr[-400:]
    problems = verify_plan(json.loads(out.read_text()))
    assert problems == [], "\n".join(map(str, problems[:5]))


def test_an_imported_name_with_a_unicode_line_break_stays_one_comment(tmp_path: Path) -> None:
    """YAML ends lines at NEL, LS and PS too: a --name holding one wrote a scenario file whose
    command comment spilled into keys, which rbp then refused to read."""
    out = tmp_path / "cave.yaml"
    done = run("scenario", "import", str(ROOT / "rb_drake/data/terrain/lava-tube-shaft.geojson"),
               "-o", str(out), "--name", "lava\u2028format: evil\u0085x")
    assert done.returncode == 0, done.stderr[-400:]
    checked = run("scenario", "check", str(out))
    assert checked.returncode == 0, checked.stdout[-300:] + checked.stderr[-300:]


@pytest.mark.parametrize("options", [{"start": ("0", "1.2")}, {"start": 5},
                                     {"start": (0, 1.2, 5)}, {"scale": "1"}, {"scale": True},
                                     {"simplify": None}, {"seed": 3.0},
                                     {"plane_normal": ("1", "0", "0")}, {"name": 5}],
                         ids=lambda o: next(iter(o)))
def test_import_scenario_refuses_arguments_of_the_wrong_kind(options: dict[str, Any]) -> None:
    import rbp
    from rb_drake.errors import RbpInputError

    field = next(iter(options))
    with pytest.raises(RbpInputError) as refused:
        rbp.import_scenario(ROOT / "rb_drake/data/terrain/lava-tube-shaft.geojson", **options)
    assert (refused.value.field or "").startswith(field), str(refused.value)


def test_write_plan_wants_a_json_name(golden: PlanFile, tmp_path: Path) -> None:
    import rbp
    from rb_drake.errors import RbpInputError

    with pytest.raises(RbpInputError, match="a plan file is JSON"):
        rbp.write_plan(golden, tmp_path / "plan.png")
    assert not (tmp_path / "plan.png").exists()


def test_a_config_object_may_hold_numpy_arrays() -> None:
    """`anytime.weights` set to a numpy array ended in numpy's ValueError (an array has no
    single item); it is read as the list it holds, then checked as a file's values are."""
    import dataclasses

    import numpy as np

    import rbp
    from planning.complete_config import AnytimeConfig
    from planning.pipeline import PipelineConfig

    config = PipelineConfig()
    config = dataclasses.replace(config, footstep=dataclasses.replace(
        config.footstep, anytime=AnytimeConfig(weights=np.array([5.0, 3.0, 2.0, 1.0]))))
    plan = rbp.plan("rig", config, footsteps_only=True)
    assert plan.success, plan.reason
