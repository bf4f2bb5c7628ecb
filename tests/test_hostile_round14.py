"""Probe 14 (session 29): `rbp plan`'s options and planner configuration. An output name
ending in '/' (pathlib dropped the slash and wrote the file), options that contradict each
other refused before the planner's imports (or silently ignored: --search sampled with
--thorough, --partial with the sampled search, the naive planner's search options,
--max-expansions with --thorough), --dt's refusal showing the digits that put it out of range,
and a configuration object whose field no copy can take named by rbp.plan."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import rbp
from rb_drake.errors import RbpInputError

ROOT = Path(__file__).resolve().parents[1]


def env() -> dict[str, str]:
    return dict(os.environ, LCM_DEFAULT_URL="memq://", RBP_THREADS="1")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rbp", *args], capture_output=True, text=True,
                          env=env(), cwd=ROOT, timeout=120)


def one_error_line(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, f"exit {result.returncode}, stderr {result.stderr[-400:]!r}"
    assert len(lines) == 1 and lines[0].startswith("error: "), f"not one line: {lines!r}"
    for needle in needles:
        assert needle in lines[0], f"{needle!r} not in {lines[0]!r}"
    return lines[0]


@pytest.mark.parametrize("command", [
    ["plan", "demo-shaft", "--footsteps-only", "-o"],
    ["plan", "demo-shaft", "--footsteps-only", "--no-pictures", "-o"],
    ["scenario", "generate", "--kind", "shaft", "-o"],
])
def test_an_output_name_ending_in_a_slash_is_refused(tmp_path, command):
    """`-o plan.json/` names a folder: pathlib dropped the slash and the plan was written to
    the file plan.json (and its picture beside it)."""
    name = "out.json" if command[0] == "plan" else "cave.yaml"
    given = f"{tmp_path / name}/"
    line = one_error_line(run(*command, given), "-o", "ends with '/'")
    assert line.startswith(f"error: {given}: -o: "), f"not named as given: {line}"
    assert list(tmp_path.iterdir()) == [], f"a refused command wrote {list(tmp_path.iterdir())}"


def test_an_existing_folder_with_its_slash_is_still_called_a_folder(tmp_path):
    one_error_line(run("plan", "demo-shaft", "--footsteps-only", "-o", f"{tmp_path}/"),
                   "-o", "is a directory")


def test_the_api_refuses_an_output_name_ending_in_a_slash(tmp_path):
    cave = rbp.load_scenario("demo-shaft")
    with pytest.raises(RbpInputError, match="ends with '/'"):
        rbp.draw(cave, f"{tmp_path / 'cave.png'}/")
    assert list(tmp_path.iterdir()) == [], "rbp.draw wrote through a trailing slash"
