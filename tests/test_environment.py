"""The environment rbp runs in: the libraries' variables (numba, OpenMP, matplotlib) are
checked or set by the command line before those libraries are imported."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rbp.cli import main
from tests.cli_helpers import ROOT


@pytest.mark.parametrize("variable,value", [
    ("NUMBA_NUM_THREADS", "0"), ("NUMBA_NUM_THREADS", "abc"),
    ("NUMBA_THREADING_LAYER", "nosuch"), ("OMP_NUM_THREADS", "abc"),
    ("OMP_NUM_THREADS", "2,0")])
def test_a_malformed_library_variable_is_refused_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        variable: str, value: str) -> None:
    """numba's traceback (NUMBA_NUM_THREADS=0, an unknown threading layer), its warning
    (NUMBA_NUM_THREADS=abc) and libgomp's complaints became one line naming the variable."""
    monkeypatch.setenv(variable, value)
    out = tmp_path / "p.json"
    assert main(["plan", "demo-shaft", "--no-pictures", "-o", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {variable} (environment): "), lines
    assert repr(value) in lines[0] and not out.exists()


def test_good_library_variables_are_accepted(monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    for variable, value in (("NUMBA_NUM_THREADS", "2"), ("OMP_NUM_THREADS", "4,2"),
                            ("NUMBA_THREADING_LAYER", "workqueue")):
        monkeypatch.setenv(variable, value)
    assert main(["scenario", "check", "demo-shaft"]) == 0, capsys.readouterr().err
    assert capsys.readouterr().err == "", "well-formed variables must pass without a word"


def test_matplotlib_backend_and_an_unusable_home_are_quiet(tmp_path: Path) -> None:
    """rbp draws to files with Agg whatever MPLBACKEND says (nosuch was a traceback), and a
    HOME that is a file (matplotlib's two warning lines) gets a temporary config folder."""
    home = tmp_path / "afile"
    home.write_text("not a folder")
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "nosuch",
           "HOME": str(home), "PYTHONPATH": str(ROOT)}
    for name in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME"):
        env.pop(name, None)
    result = subprocess.run([sys.executable, "-m", "rbp", "scenario", "show", "demo-shaft",
                             "-o", "x.png"], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=300, check=False)
    assert result.returncode == 0 and result.stderr == "", result.stderr[-1500:]
    assert (tmp_path / "x.png").exists()
