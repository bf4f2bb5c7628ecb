"""What `rbp rig-run` executes is verified: a footstep plan's straight motion between steps,
which `rbp check` leaves unverified, passes rule `between` or the plan is refused; and the
smooth path `rbp simulate` follows is sampled and bounded over every interval of a phase, the
one from the last attach-ramp step to the first motion step included.

Plans are made here from the bundled demo-shaft cave; everything runs on `memq://`.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from planning.plan_model import Plan
from rbp.cli import main
from systems.plan_check import executed_motion_problems

REFUSAL = ("a footstep plan whose motion between steps, which rig-run commands and simulate "
           "follows, fails rule between")


@pytest.fixture(scope="module")
def footsteps() -> dict[str, Any]:
    """demo-shaft planned footsteps-only: its straight lines cross rock (docs/formats.md)."""
    import rbp
    from rb_drake.scenario import bundled_caves, load_scenario

    plan = rbp.plan(load_scenario(bundled_caves()["demo-shaft"]), footsteps_only=True)
    assert plan.success and plan.time_step is None
    return plan.to_dict()


@pytest.fixture(scope="module")
def full() -> dict[str, Any]:
    """demo-shaft planned with motion (`rbp plan`'s pipeline), as a plan-file object."""
    from planning.pipeline import plan_climb
    from planning.plan_model import plan_dict
    from rb_drake.scenario import bundled_caves, load_scenario

    plan = plan_dict(plan_climb(load_scenario(bundled_caves()["demo-shaft"])))
    assert plan["success"], plan["reason"]
    return plan


def _rig_run(path: Path, tmp_path: Path, *extra: str) -> int:
    return main(["rig-run", str(path), "--sim-rig", "--log", str(tmp_path / "rig.lcm"), *extra])


def test_rig_run_refuses_a_footstep_plan_whose_straight_motion_crosses_rock(
        footsteps: dict[str, Any], tmp_path: Path, capsys) -> None:
    """`rbp check` accepts the footstep plan (end configurations only); rig-run, which would
    command the straight lines between them, refuses it: one line per failing interval
    naming the file, phase, step and rule `between`, then one line saying why and what to
    do; exit 1 and no LCM log (nothing sent)."""
    expected = executed_motion_problems(footsteps)
    assert expected, "demo-shaft's footstep plan no longer crosses rock between its steps"
    path = tmp_path / "fs.json"
    path.write_text(json.dumps(footsteps))
    assert main(["check", "-q", str(path)]) == 0
    capsys.readouterr()
    assert _rig_run(path, tmp_path) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[:-1] == [f"error: {path}: {p}" for p in expected[:20]], lines
    assert all(": between: between steps " in line and "step " in line and "phases[" in line
               for line in lines[:-1]), lines
    assert lines[-1].startswith(f"error: {path}: {REFUSAL} ({len(expected)} problem"), lines[-1]
    assert "rbp plan without --footsteps-only" in lines[-1], lines[-1]
    assert not (tmp_path / "rig.lcm").exists(), "the rig ran a refused plan"


def test_a_stamp_does_not_vouch_for_a_footstep_plans_motion(
        footsteps: dict[str, Any], tmp_path: Path, capsys) -> None:
    """`rbp check --stamp` stamps the footstep plan (its end configurations verify); the stamp
    says nothing of the motion between them, so rig-run still checks and refuses it."""
    path = tmp_path / "fs.json"
    path.write_text(json.dumps(footsteps))
    assert main(["check", "-q", "--stamp", str(path)]) == 0
    assert "verified" in json.loads(path.read_text())
    capsys.readouterr()
    assert _rig_run(path, tmp_path) == 1
    assert REFUSAL in capsys.readouterr().err.strip().splitlines()[-1]


def test_no_verify_still_runs_a_footstep_plan(footsteps: dict[str, Any], tmp_path: Path,
                                              capsys) -> None:
    """--no-verify stays the explicit override: the plan runs, with its warning."""
    path = tmp_path / "fs.json"
    path.write_text(json.dumps(footsteps))
    assert _rig_run(path, tmp_path, "--no-verify") == 0
    err = capsys.readouterr().err
    assert "--no-verify" in err and "error:" not in err, err
    assert (tmp_path / "rig.lcm").exists()


def test_a_footstep_plan_whose_motion_holds_runs(tmp_path: Path, capsys) -> None:
    """The rig's straight-line plan (`systems.rig.rig_plan`: no `time_step`) is a footstep plan
    whose straight motion holds: rig-run verifies that motion and runs it."""
    from systems.rig import load_rig_scenario, rig_plan

    plan = rig_plan(load_rig_scenario())
    assert Plan.from_dict(plan).time_step is None
    assert executed_motion_problems(plan) == []
    path = tmp_path / "line.json"
    path.write_text(json.dumps(plan))
    assert _rig_run(path, tmp_path) == 0, capsys.readouterr().err
    assert "error:" not in capsys.readouterr().err


def test_the_interval_after_an_attach_ramp_is_sampled_and_bounded(full: dict[str, Any]) -> None:
    """The first motion step after an attach ramp moved by 9e-10 (rule `attach` accepts
    1e-9): the smooth path now moves on the interval from the last ramp step (the spline's
    still test is 1e-12), and that interval is among those rule `between` samples and the
    departure bound covers, with a bound no smaller than the excursion measured densely."""
    from planning.check import check_plan
    from planning.smooth_motion import plan_paths
    from planning.verify_between import TRANSLATION, smooth_departure
    from systems.trajectory import PlanTrajectory, plan_scenario

    plan = copy.deepcopy(full)
    k = next(i for i, ph in enumerate(plan["phases"])
             if ph["kind"] == "body" and "ramp" in ph["steps"][0])
    steps = plan["phases"][k]["steps"]
    a = next(i for i, s in enumerate(steps) if "ramp" not in s)
    move = np.subtract(steps[a + 1]["pose"], steps[a]["pose"])
    steps[a]["pose"] = (np.asarray(steps[a]["pose"]) + 9e-10 * np.sign(move)).tolist()
    assert check_plan(plan) == []
    path = dict(plan_paths(Plan.from_dict(plan)))[k]
    assert len(path.knots) == len(steps) and path.first_step == 0
    assert path.knots[0] == steps[0]["t"], "the ramps' intervals are left out of the sampling"
    q, v = path.pose.vector_values(path.knots).T, path.velocity.vector_values(path.knots).T
    bound = smooth_departure(path.knots, q, v)[a - 1]
    t = np.linspace(steps[a - 1]["t"], steps[a]["t"], 2001)
    dev = path.pose.vector_values(t).T - np.asarray(steps[a - 1]["pose"])
    measured = float(np.hypot(dev[:, 0], dev[:, 1]).max()) / TRANSLATION
    assert measured > 1e-4, "the perturbation no longer makes the interval move"
    assert bound >= measured, (bound, measured)
    traj = PlanTrajectory(plan, plan_scenario(Plan.from_dict(plan)))
    assert traj.departure >= bound
