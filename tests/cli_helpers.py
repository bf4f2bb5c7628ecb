"""Running the `rbp` command line from tests, as a user would (a subprocess, no network)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_rbp(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "rbp", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def one_error_line(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    """The one `error: ` line a refused command (exit 2) wrote on stderr, each of `needles` in
    it; asserts all of that."""
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, f"exit {result.returncode}, stderr {result.stderr[-400:]!r}"
    assert len(lines) == 1 and lines[0].startswith("error: "), f"not one line: {lines!r}"
    for needle in needles:
        assert needle in lines[0], f"{needle!r} not in {lines[0]!r}"
    return lines[0]
