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
