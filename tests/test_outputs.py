"""Output paths are checked before any work, and an output never destroys another file.

`rbp plan -o clash.png` used to write the plan and then its picture to the same path (the plan
lost); a directory, a symlink loop or an unwritable folder was refused only after the plan was
computed; a symlink was replaced by a plain file. Each case here is refused before the planner,
the generator or the drawing is called (exit 2, one line naming the user's path), or, for a
symlink, written through.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.cli_helpers import run_rbp


class _WorkStartedError(Exception):
    """Raised by the work a refused command must never start."""


def _refusal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
             capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """The one line `rbp ARGS` (run in `tmp_path`) refuses with, exit 2, no traceback, before
    it starts the work: planning, generating a cave or drawing raise _WorkStartedError here."""
    import rb_drake.generate
    import rbp.api
    import rbp.commands.plan
    from rbp.cli import main

    def work(*_a: object, **_k: object) -> None:
        raise _WorkStartedError(f"{args}: the work started before the refusal")

    for module, name in ((rbp.commands.plan, "run_planner"), (rb_drake.generate, "generate_cave"),
                         (rbp.api, "draw")):
        monkeypatch.setattr(module, name, work)
    monkeypatch.chdir(tmp_path)
    code = main(list(args))
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, (args, code, err)
    assert len(lines) == 1 and "Traceback" not in err, (args, err)
    return lines[0]


def test_plan_refuses_a_picture_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    line = _refusal(tmp_path, monkeypatch, capsys, "plan", "demo-shaft", "-o", "clash.png")
    assert "clash.png: -o: is a picture's name" in line, line
    assert not (tmp_path / "clash.png").exists(), "a refused plan wrote its output"


def test_plan_refuses_a_directory_and_a_symlink_loop(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "out").mkdir()
    line = _refusal(tmp_path, monkeypatch, capsys, "plan", "demo-shaft", "-o", "out")
    assert "out: -o: is a directory" in line, line
    (tmp_path / "loop.json").symlink_to(tmp_path / "loop.json")
    line = _refusal(tmp_path, monkeypatch, capsys, "plan", "demo-shaft", "-o", "loop.json")
    assert "symlink loop" in line, line


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any folder")
def test_plan_refuses_a_read_only_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        line = _refusal(tmp_path, monkeypatch, capsys, "plan", "demo-shaft", "-o",
                        "locked/p.json")
        assert "not writable" in line, line
    finally:
        folder.chmod(0o755)


def test_other_outputs_are_checked_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "d").mkdir()
    line = _refusal(tmp_path, monkeypatch, capsys, "scenario", "generate", "--kind", "shaft",
                    "--seed", "1", "-o", "d")
    assert "d: -o: is a directory" in line, line
    line = _refusal(tmp_path, monkeypatch, capsys, "scenario", "show", "demo-shaft", "-o", "d")
    assert "d: -o: is a directory" in line, line


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
