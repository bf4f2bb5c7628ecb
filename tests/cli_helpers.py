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
