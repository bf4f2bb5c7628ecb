"""Output paths are checked before any work, and an output never destroys another file.

`rbp plan -o clash.png` used to write the plan and then its picture to the same path (the plan
lost); a directory, a symlink loop or an unwritable folder was refused only after the plan was
computed; a symlink was replaced by a plain file. Each case here is refused before the planner,
the generator or the drawing is called (exit 2, one line naming the user's path), or, for a
symlink, written through.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from rb_drake.files import atomic_write_text, output_problem
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


def _refused(result, words: str, *more: str) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr[-2000:]
    for w in (words, *more):
        assert w in lines[0], (w, lines[0])
    assert ".tmp" not in lines[0], lines[0]  # the user's path, never the temporary file
    return lines[0]


@pytest.fixture
def fifo_link(tmp_path: Path) -> Path:
    """out.json, a symlink to a FIFO: stands for a link to a device such as /dev/zero, which
    the atomic writer replaced with a regular file when run as root."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    link = tmp_path / "out.json"
    link.symlink_to(fifo)
    return link


def test_atomic_write_never_replaces_a_non_regular_target(fifo_link, tmp_path):
    with pytest.raises(OSError, match="not a regular file") as e:
        atomic_write_text(fifo_link, "{}")
    assert e.value.filename == str(fifo_link)
    assert (tmp_path / "fifo").is_fifo() and fifo_link.is_symlink()
    assert output_problem(fifo_link) is not None
    (tmp_path / "d").mkdir()
    with pytest.raises(OSError, match="is a directory"):
        atomic_write_text(tmp_path / "d", "{}")
    assert not list(tmp_path.glob(".*.tmp"))


def test_symlinked_output_to_a_pipe_refused_before_work(fifo_link, tmp_path):
    result = run_rbp("scenario", "generate", "-o", str(fifo_link), cwd=tmp_path)
    _refused(result, str(fifo_link), "-o: is not a regular file")
    assert (tmp_path / "fifo").is_fifo()


def test_outputs_checked_before_the_work_naming_the_option(tmp_path):
    (tmp_path / "DIR").mkdir()
    (tmp_path / "plan.json").write_text("{}")  # refused before the plan is read
    result = run_rbp("simulate", "--trials", "1", "--html", "DIR", "plan.json", cwd=tmp_path)
    _refused(result, "DIR: --html: is a directory")
    (tmp_path / "pdir" / "p.png").mkdir(parents=True)
    result = run_rbp("plan", "demo-shaft", "-o", "pdir/p.json", "--footsteps-only",
                     cwd=tmp_path)
    _refused(result, "pdir/p.png: -o's picture: is a directory")
    assert not (tmp_path / "pdir" / "p.json").exists(), "the plan was made before refusing"
    (tmp_path / "afile").write_text("x")
    result = run_rbp("experiment", "timing_table", "--trials", "1", "--workers", "1", "--out",
                     "afile", cwd=tmp_path)
    _refused(result, "afile: --out: is not a folder")


def test_trial_record_that_is_not_a_file_refused_before_the_trial(tmp_path, fifo_link):
    trials = tmp_path / "ex" / "trials"
    trials.mkdir(parents=True)
    (trials / "000-shaft-s1.json").mkdir()
    result = run_rbp("experiment", "timing_table", "--trials", "1", "--workers", "1", "--out",
                     "ex", cwd=tmp_path)
    _refused(result, "000-shaft-s1.json: --out: is a directory")
    shutil.rmtree(trials / "000-shaft-s1.json")
    (trials / "000-shaft-s1.json").symlink_to(tmp_path / "fifo")
    result = run_rbp("experiment", "timing_table", "--trials", "1", "--workers", "1", "--out",
                     "ex", cwd=tmp_path)
    _refused(result, "000-shaft-s1.json: --out: is not a regular file")
    assert (tmp_path / "fifo").is_fifo()


@pytest.mark.parametrize(("args", "words"), [
    (("simulate", "--trials", "1", "--json", "P.json", "P.json"), "--json: is the plan's file"),
    (("rig-run", "--sim-rig", "--log", "P.json", "P.json"), "--log: is the plan's file"),
    (("scenario", "import", "P.json", "-o", "P.json"), "-o: is the imported file"),
    (("scenario", "show", "P.json", "-o", "link.png"), "-o: is the scenario's file"),
    (("plan", "P.json", "-o", "o.json", "--animate", "link.png"), "--animate: is the scenario"),
])
def test_output_that_is_an_input_refused(tmp_path, args, words):
    """`--json P.json P.json` replaced the plan with the results, `rig-run --log` with a binary
    log; through a symlink (or a hard link) it is the same file."""
    plan = tmp_path / "P.json"
    plan.write_text('{"not": "touched"}')
    (tmp_path / "link.png").symlink_to(plan)
    _refused(run_rbp(*args, cwd=tmp_path), "P.json" if "link.png" not in args else "link.png",
             words, "the output would overwrite it")
    assert plan.read_text() == '{"not": "touched"}'
