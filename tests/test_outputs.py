"""Output paths are checked before any work, and an output never destroys another file.

`rbp plan -o clash.png` used to write the plan and then its picture to the same path (the plan
lost); a directory, a symlink loop or an unwritable folder was refused only after the plan was
computed; a symlink was replaced by a plain file. Each case here is refused before planning
(within seconds, exit 2, one line naming the user's path), or, for a symlink, written through.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from tests.cli_helpers import run_rbp


def _refused(tmp_path: Path, *args: str, words: str) -> None:
    start = time.perf_counter()
    result = run_rbp(*args, cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (args, result.returncode, result.stderr)
    assert len(lines) == 1 and words in lines[0], (args, result.stderr)
    assert "Traceback" not in result.stderr
    assert time.perf_counter() - start < 60, f"{args}: refused only after the work"


def test_plan_refuses_a_picture_name(tmp_path: Path) -> None:
    _refused(tmp_path, "plan", "demo-shaft", "-o", "clash.png", words="clash.png: -o: is a "
             "picture's name")
    assert not (tmp_path / "clash.png").exists(), "a refused plan wrote its output"


def test_plan_refuses_a_directory_and_a_symlink_loop(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    _refused(tmp_path, "plan", "demo-shaft", "-o", "out", words="out: -o: is a directory")
    (tmp_path / "loop.json").symlink_to(tmp_path / "loop.json")
    _refused(tmp_path, "plan", "demo-shaft", "-o", "loop.json", words="symlink loop")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any folder")
def test_plan_refuses_a_read_only_folder(tmp_path: Path) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        _refused(tmp_path, "plan", "demo-shaft", "-o", "locked/p.json", words="not writable")
    finally:
        folder.chmod(0o755)


def test_other_outputs_are_checked_first(tmp_path: Path) -> None:
    (tmp_path / "d").mkdir()
    _refused(tmp_path, "scenario", "generate", "--kind", "shaft", "--seed", "1", "-o", "d",
             words="d: -o: is a directory")
    _refused(tmp_path, "scenario", "show", "demo-shaft", "-o", "d", words="d: -o: is a "
             "directory")


def test_a_symlinked_output_is_written_through(tmp_path: Path) -> None:
    target = tmp_path / "real.yaml"
    link = tmp_path / "cave.yaml"
    link.symlink_to(target)
    result = run_rbp("scenario", "generate", "--kind", "shaft", "--seed", "1", "-o", "cave.yaml",
                     cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert link.is_symlink(), "the symlink was replaced by a plain file"
    assert target.is_file() and "reachbot-scenario/1" in target.read_text()


def test_demo_out_that_is_a_file_is_refused_in_one_line(tmp_path: Path) -> None:
    """`rbp demo --out FILE` said only 'FILE: File exists'."""
    (tmp_path / "afile").write_text("keep me\n")
    result = run_rbp("demo", "--out", "afile", "--no-plan", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-1500:]
    assert result.stderr.strip() == ("error: afile: --out: is a file; give a folder (its "
                                     "outputs are written into it)"), result.stderr
    assert (tmp_path / "afile").read_text() == "keep me\n"
