"""The rig's LCM message types: the committed package is what lcm-gen makes of the .lcm file,
and every message survives an encode/decode round trip."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from systems.reachbot_lcm import rig_command_t, rig_setup_t, rig_status_t

ROOT = Path(__file__).resolve().parents[1]
LCM_FILE = ROOT / "lcmtypes" / "reachbot.lcm"
COMMITTED = ROOT / "systems" / "reachbot_lcm"


def lcm_gen() -> str:
    """lcm-gen from the lcm wheel, beside this Python, else on PATH."""
    beside = Path(sys.executable).parent / "lcm-gen"
    found = str(beside) if beside.exists() else shutil.which("lcm-gen")
    assert found, "lcm-gen not found: it ships in the lcm wheel's bin/ (pip install lcm)"
    return found


def test_committed_types_are_current(tmp_path: Path) -> None:
    subprocess.run([lcm_gen(), "-p", "--ppath", str(tmp_path), str(LCM_FILE)], check=True,
                   capture_output=True, timeout=60)
    fresh = {p.name: p.read_text() for p in (tmp_path / "reachbot_lcm").glob("*.py")}
    committed = {p.name: p.read_text() for p in COMMITTED.glob("*.py")}
    assert sorted(fresh) == sorted(committed), (
        f"generated files {sorted(fresh)} != committed {sorted(committed)}: regenerate with "
        "lcm-gen -p --ppath systems lcmtypes/reachbot.lcm")
    stale = [name for name in fresh if fresh[name] != committed[name]]
    assert not stale, (f"{stale} differ from what lcm-gen makes of {LCM_FILE.name}: regenerate "
                       "with lcm-gen -p --ppath systems lcmtypes/reachbot.lcm")


def random_command(rng: np.random.Generator) -> rig_command_t:
    msg = rig_command_t()
    msg.utime = int(rng.integers(0, 2**62))
    msg.boom_length = rng.uniform(0.01, 2.0, 4)
    msg.tension_setpoint = rng.uniform(0.0, 50.0, 4)
    return msg


def random_status(rng: np.random.Generator) -> rig_status_t:
    msg = rig_status_t()
    msg.utime = int(rng.integers(0, 2**62))
    msg.winch_length = rng.uniform(0.01, 2.0, 4)
    msg.load_cell_force = rng.normal(5.0, 3.0, 4)
    msg.hinge_angle = rng.uniform(-np.pi, np.pi, 4)
    return msg


@pytest.mark.parametrize("trial", range(5))
def test_round_trip(trial: int) -> None:
    rng = np.random.default_rng(100 + trial)
    for msg in (random_command(rng), random_status(rng)):
        back = type(msg).decode(msg.encode())
        for field in msg.__slots__:
            sent, got = np.asarray(getattr(msg, field)), np.asarray(getattr(back, field))
            np.testing.assert_array_equal(got, sent, err_msg=f"{type(msg).__name__}.{field}")
    setup = rig_setup_t()
    setup.utime = int(rng.integers(0, 2**62))
    setup.scenario_json = '{"name": "rig", "\\u00e9": [1.5, -2]}'
    setup.stance = ["upper-right", "upper-left", "lower-left", "lower-right"]
    setup.plan_source = f"plan-{trial}.json phase 0"
    back = rig_setup_t.decode(setup.encode())
    assert (back.utime, back.scenario_json, list(back.stance), back.plan_source) == (
        setup.utime, setup.scenario_json, setup.stance, setup.plan_source), "rig_setup_t"


def test_decoding_the_wrong_type_is_refused() -> None:
    data = random_command(np.random.default_rng(1)).encode()
    with pytest.raises(ValueError, match="Decode error"):
        rig_status_t.decode(data)
