"""Probe 24: what a command leaves behind when it writes (a full disk half-way through its
outputs, hard links, symlinks, `-o /dev/stdout` appended to a file), partial climbs flown by
`rbp simulate` as by `rbp rig-run`, and memory that grew with the input (the replan cache, an
`--html` replay). Each test shows the input, what rbp does with it now, and that valid uses
still work."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from cli_helpers import ROOT, one_error_line, run_rbp

GOLDEN = ROOT / "tests" / "data" / "golden"


def _env() -> dict[str, str]:
    """The environment of an `rbp` child: this tree first, no empty PYTHONPATH entry."""
    return {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
            "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                       os.environ.get("PYTHONPATH", "")]))}


def _in_shell(script: str, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """`sh -c SCRIPT sh ARGS`, where "$@" after the script's own arguments is `python -m rbp`."""
    return subprocess.run(["sh", "-c", script, "sh", *args, sys.executable, "-m", "rbp"],
                          cwd=cwd, env=_env(), capture_output=True, text=True, timeout=300,
                          check=False)


# --- a full disk half-way through a command's outputs ---

def _no_space_for_pictures(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every picture fails as on a full disk, inside the writer (as matplotlib's savefig
    does when the disk fills), after the plan file is written."""
    from rb_drake import files

    def full(fig: Any, path: str | Path, **kwargs: Any) -> Path:
        def write(f: Any) -> None:
            f.write(b"\x89PNG half")
            raise OSError(errno.ENOSPC, "No space left on device")

        return files.atomic_write(path, write)

    monkeypatch.setattr(files, "atomic_save_figure", full)


@pytest.mark.parametrize("before", [None, b'{"an": "older plan"}\n'])
def test_a_full_disk_at_the_picture_leaves_no_plan_written(
        before: bytes | None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp plan` on a disk that filled while plan.png was written ended with exit 2 and
    `error: plan.png: -o's picture: cannot write: No space left on device`, yet plan.json was
    written: a plan without its picture, from a command that said it failed. A command's
    outputs are now written together or not at all: no plan.json (or the older one kept)."""
    from rbp import cli

    plan = tmp_path / "plan.json"
    if before is not None:
        plan.write_bytes(before)
    _no_space_for_pictures(monkeypatch)
    status = cli.main(["plan", "demo-shaft", "--footsteps-only", "-q", "-o", str(plan)])
    out, err = capsys.readouterr()
    assert status == 2, (status, err)
    assert err.strip().splitlines() == [
        f"error: {tmp_path / 'plan.png'}: -o's picture: cannot write: No space left on device"
    ], err
    assert "wrote" not in out, f"it said it wrote what it did not keep: {out!r}"
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ([] if before is None else ["plan.json"]), f"left behind: {names}"
    if before is not None:
        assert plan.read_bytes() == before, "the older plan was replaced"


def _namespaces_work() -> bool:
    if os.geteuid() != 0 or not shutil.which("unshare"):
        return False
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True, check=False)
    return probe.returncode == 0


@pytest.mark.skipif(not _namespaces_work(), reason="needs root and a mount namespace")
def test_a_real_full_disk_leaves_the_older_plan(tmp_path: Path) -> None:
    """The same on a 64 kB filesystem (the plan, 44 kB, fits; its picture does not): the
    older plan.json stays, byte for byte, and nothing else is left."""
    disk = tmp_path / "disk"
    disk.mkdir()
    script = ('mount -t tmpfs -o size=64k tmpfs "$1" && cd "$1" && echo older > plan.json && '
              'shift && "$@" plan demo-shaft --footsteps-only -q -o plan.json; '
              'echo "status $?"; ls -A; cat plan.json')
    result = subprocess.run(["unshare", "-m", "sh", "-c", script, "sh", str(disk),
                             sys.executable, "-m", "rbp"], cwd=tmp_path, env=_env(),
                            capture_output=True, text=True, timeout=300, check=False)
    assert "No space left on device" in result.stderr, result.stderr[-600:]
    assert "Traceback" not in result.stderr, result.stderr[-600:]
    assert result.stdout.split() == ["status", "2", "plan.json", "older"], result.stdout


def test_demo_writes_its_cave_picture_and_report_together(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp demo` wrote cave.png and start.json one after the other (and later plan.json
    and its pictures): a full disk between them left some. Each group is written whole."""
    from rbp import cli

    _no_space_for_pictures(monkeypatch)
    out = tmp_path / "demo"
    assert cli.main(["demo", "--out", str(out)]) == 2
    assert "cave.png: --out: cannot write: No space left on device" in capsys.readouterr().err
    assert not out.exists() or list(out.iterdir()) == [], list(out.iterdir())


def test_simulate_writes_its_json_and_html_together(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp simulate --json sim.json --html climb.html` whose page cannot be written kept
    sim.json; now neither is written."""
    from test_simulation import _short_plan

    from rb_drake import files
    from rbp import cli
    from systems import meshcat_view

    path = tmp_path / "plan.json"
    path.write_text(json.dumps(_short_plan(json.loads(
        (GOLDEN / "demo-shaft-current.json").read_text()))))

    def full(meshcat: Any, out: str | Path) -> Path:
        def write(f: Any) -> None:
            raise OSError(errno.ENOSPC, "No space left on device")

        return files.atomic_write(out, write)

    monkeypatch.setattr(meshcat_view, "save_html", full)
    status = cli.main(["simulate", str(path), "--trials", "0", "--no-verify", "--json",
                       str(tmp_path / "sim.json"), "--html", str(tmp_path / "climb.html")])
    err = capsys.readouterr().err
    assert status == 2 and "climb.html: --html: cannot write: No space left" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]


# --- hard links, symlinks, and the descriptors /dev/stdout names ---

def test_an_output_with_a_hard_link_is_written_in_place(tmp_path: Path) -> None:
    """`rbp scenario generate -o b.yaml`, b.yaml a hard link of a.yaml: the rename gave b.yaml
    a new file and left a.yaml with the old content (the link broken). The file is now
    written in place, as `cp` does: both names read the new cave, one inode."""
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text("old " * 10_000)  # longer than the cave: the rest must go
    os.link(a, b)
    inode = a.stat().st_ino
    result = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "b.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert b.stat().st_ino == inode and a.stat().st_nlink == 2, "the hard link was broken"
    assert a.read_text() == b.read_text() and "format: reachbot-scenario/1" in a.read_text()
    assert "old old" not in a.read_text(), "the old content's tail was left"
    checked = run_rbp("scenario", "check", "a.yaml", cwd=tmp_path)
    assert checked.returncode == 0, checked.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml"]


def test_an_output_through_a_symlink_is_written_into_its_target(tmp_path: Path) -> None:
    """Through a symlink the target's content changes and the target stays the same file
    (its other names, its owner); the link stays a link."""
    target = tmp_path / "caves" / "cave.yaml"
    target.parent.mkdir()
    target.write_text("old\n")
    target.chmod(0o640)
    os.link(target, tmp_path / "caves" / "also.yaml")
    (tmp_path / "link.yaml").symlink_to(target)
    inode = target.stat().st_ino
    result = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "link.yaml",
                     cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "link.yaml").is_symlink()
    assert target.stat().st_ino == inode and oct(target.stat().st_mode & 0o777) == "0o640"
    assert (tmp_path / "caves" / "also.yaml").read_text() == target.read_text()
    assert "name: shaft-0" in target.read_text()


@pytest.mark.skipif(not _namespaces_work(), reason="needs root and a mount namespace")
def test_a_full_disk_leaves_a_hard_linked_output_as_it_was(tmp_path: Path) -> None:
    """Written in place, a file is not replaced whole: on a 20 kB filesystem (room for the
    cave's temporary file, not for a second copy) the space is asked for before the file is
    touched, so both names keep the old content and the error names the output."""
    disk = tmp_path / "disk"
    disk.mkdir()
    script = ('mount -t tmpfs -o size=20k tmpfs "$1" && cd "$1" && echo old > a.yaml && '
              'ln a.yaml b.yaml && shift && "$@" scenario generate --kind shaft -o b.yaml; '
              'echo "status $?"; ls -A; cat a.yaml b.yaml')
    result = subprocess.run(["unshare", "-m", "sh", "-c", script, "sh", str(disk),
                             sys.executable, "-m", "rbp"], cwd=tmp_path, env=_env(),
                            capture_output=True, text=True, timeout=300, check=False)
    assert result.stderr.strip() == ("error: b.yaml: -o: cannot write: No space left on "
                                     "device"), result.stderr[-600:]
    assert result.stdout.split() == ["status", "2", "a.yaml", "b.yaml", "old", "old"], \
        result.stdout


@pytest.mark.skipif(os.geteuid() != 0, reason="root makes a file another user owns")
def test_a_file_of_another_user_keeps_its_owner(tmp_path: Path) -> None:
    """Root replacing a user's plan by the rename made it root's (the user could no longer
    write it); it is written in place now, as `cp` does."""
    cave = tmp_path / "cave.yaml"
    cave.write_text("old\n")
    os.chown(cave, 12345, 12345)
    assert run_rbp("scenario", "generate", "--kind", "shaft", "-o", "cave.yaml",
                   cwd=tmp_path).returncode == 0
    assert (cave.stat().st_uid, cave.stat().st_gid) == (12345, 12345)
    assert "name: shaft-0" in cave.read_text()


_HANGUP_IN_PLACE = r"""
import os, signal, sys
from rb_drake import files
from rbp.commands.common import Terminated, clean_interrupts

copy = files._copy_in_place

def hung_up_midway(tmp, target):
    os.kill(os.getpid(), signal.SIGHUP)  # the terminal hangs up as the copy starts
    copy(tmp, target)

files._copy_in_place = hung_up_midway
try:
    with clean_interrupts():
        files.atomic_write(sys.argv[1], lambda f: f.write(b"new content " * 100_000))
    print("written")
except Terminated:
    print("terminated")
"""


def test_a_hangup_during_a_copy_in_place_waits_for_its_end(tmp_path: Path) -> None:
    """A copy in place cannot be undone half-way (the rename could: the old file stayed
    whole): a hang-up as it starts is held until it ends, then unwinds as before (status
    3), the file whole and no temporary file left."""
    target = tmp_path / "plan.json"
    target.write_bytes(b"old")
    os.link(target, tmp_path / "also.json")
    env = {**_env(), "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    done = subprocess.run([sys.executable, "-c", _HANGUP_IN_PLACE, str(target)], env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.stdout.strip() == "terminated", (done.returncode, done.stderr[-300:])
    assert target.read_bytes() == b"new content " * 100_000, "the copy was cut short"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["also.json", "plan.json"]


def _writer_at_a_held_lock(tmp_path: Path) -> subprocess.Popen:
    """`rbp scenario generate -o b.yaml`, b.yaml a hard link of a.yaml, started while the test
    holds the lock on a.yaml; returned once its output has begun."""
    import time

    writer = subprocess.Popen([sys.executable, "-m", "rbp", "scenario", "generate",
                               "--kind", "shaft", "-o", "b.yaml"], cwd=tmp_path,
                              env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".b.yaml.*.tmp")) and writer.poll() is None:
        assert time.monotonic() < deadline, "the command never began its output"
        time.sleep(0.05)
    return writer


def test_two_writers_of_one_file_in_place_take_turns(tmp_path: Path) -> None:
    """Two commands writing one hard-linked file at once interleaved their copies in place
    (the rename needed no turn-taking); a copy in place now holds an exclusive lock (flock)
    on the file. Here the test holds it: the command waits, the file unchanged, until it is
    released."""
    import fcntl
    import time

    a = tmp_path / "a.yaml"
    a.write_text("old\n")
    os.link(a, tmp_path / "b.yaml")
    with a.open("rb+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        writer = _writer_at_a_held_lock(tmp_path)
        time.sleep(2.0)  # long enough for an unlocked copy of 11 kB to be done
        assert a.read_text() == "old\n", "the file was written while another held it"
        fcntl.flock(held, fcntl.LOCK_UN)
    _, err = writer.communicate(timeout=120)
    assert writer.returncode == 0, err
    assert "name: shaft-0" in a.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml"]


def test_a_writer_waiting_for_its_turn_can_be_interrupted(tmp_path: Path) -> None:
    """The wait for another writer's lock comes before interrupts are held: SIGTERM ends
    the waiting command as usual (`interrupted`, status 3), the file as it was, no temporary
    file left (held, it would have waited without end)."""
    import fcntl
    import signal
    import time

    a = tmp_path / "a.yaml"
    a.write_text("old\n")
    os.link(a, tmp_path / "b.yaml")
    with a.open("rb+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        writer = _writer_at_a_held_lock(tmp_path)
        time.sleep(1.0)  # at the lock by now
        writer.send_signal(signal.SIGTERM)
        _, err = writer.communicate(timeout=60)
    assert writer.returncode == 3 and err.strip() == "interrupted", (writer.returncode, err)
    assert a.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml"]


def test_a_single_name_is_still_replaced_atomically(tmp_path: Path) -> None:
    """An output with one name is written as before: a new file renamed over it (a reader
    never sees it half-written)."""
    cave = tmp_path / "cave.yaml"
    cave.write_text("old\n")
    inode = cave.stat().st_ino
    assert run_rbp("scenario", "generate", "--kind", "shaft", "-o", "cave.yaml",
                   cwd=tmp_path).returncode == 0
    assert cave.stat().st_ino != inode and "name: shaft-0" in cave.read_text()


@pytest.mark.parametrize("redirect", [">>", ">"])
def test_dev_stdout_redirected_to_a_file_is_written_through_it(redirect: str,
                                                              tmp_path: Path) -> None:
    """`rbp scenario generate -o /dev/stdout >> log.txt` replaced log.txt (its earlier
    lines lost), and the "wrote" line went into the replaced file. The output now goes
    through the descriptor (`>>` appends, `>` writes from its start) and the command's
    messages to stderr."""
    log = tmp_path / "log.txt"
    log.write_text("an earlier line\n")
    result = _in_shell(f'"$@" scenario generate --kind shaft -o /dev/stdout {redirect} log.txt',
                       cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = log.read_text()
    if redirect == ">>":
        assert text.startswith("an earlier line\n# rbp scenario generate"), text[:200]
        text = text.removeprefix("an earlier line\n")
    assert text.startswith("# rbp scenario generate") and "wrote" not in text, text[-300:]
    assert "wrote /dev/stdout: shaft-0" in result.stderr, result.stderr
    (tmp_path / "cave.yaml").write_text(text)
    assert run_rbp("scenario", "check", "cave.yaml", cwd=tmp_path).returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cave.yaml", "log.txt"]


def test_proc_self_fd_of_an_open_file_is_written_through_it(tmp_path: Path) -> None:
    """`-o /proc/self/fd/3` with descriptor 3 open for appending: as /dev/stdout."""
    log = tmp_path / "log.txt"
    log.write_text("first\n")
    result = _in_shell('"$@" scenario generate --kind shaft -o /proc/self/fd/3 3>> log.txt',
                       cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = log.read_text()
    assert text.startswith("first\n# rbp scenario generate") and "name: shaft-0" in text
    assert "wrote /proc/self/fd/3" in result.stdout, "its messages stay on stdout"


def test_dev_stdin_is_refused_as_an_output(tmp_path: Path) -> None:
    """`rbp scenario generate -o /dev/stdin < cave.yaml` replaced cave.yaml (the name resolves
    to the file standard input reads) with a generated cave. A descriptor open for reading
    only is refused as an output, before the work."""
    cave = tmp_path / "cave.yaml"
    shutil.copy(ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml", cave)
    before = cave.read_bytes()
    for name in ("/dev/stdin", "/dev/fd/0", "/proc/self/fd/0"):
        result = _in_shell(f'"$@" scenario generate --kind shaft -o {name} < cave.yaml',
                           cwd=tmp_path)
        one_error_line(result, f"{name}: -o: names standard input, open for reading only")
        assert cave.read_bytes() == before, f"-o {name} replaced the input"


# --- partial climbs: rbp simulate flies them, as rbp rig-run does ---

@pytest.fixture(scope="module")
def partial_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """blocked-shaft's partial climb (no route; 3 regrasps to the stance nearest the goal),
    without SCP (10 s)."""
    import rbp
    from rb_drake.scenario import bundled_caves, load_scenario

    made = rbp.plan(load_scenario(bundled_caves()["blocked-shaft"]),
                    rbp.PipelineConfig(optimise=False), partial=True)
    assert made.partial is not None and not made.success
    path = tmp_path_factory.mktemp("partial") / "partial.json"
    rbp.write_plan(made, path)
    return path


def test_simulate_flies_a_partial_climb_as_rig_run_does(
        partial_plan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp simulate` refused a partial plan ("the plan found no route; nothing to simulate",
    exit 1) that `rbp check` verifies and `rbp rig-run` flies. Both fly it now, to its end."""
    import rbp
    from rbp import cli

    sim = tmp_path / "sim.json"
    assert cli.main(["simulate", str(partial_plan), "--trials", "20", "--json",
                     str(sim)]) == 0
    out = capsys.readouterr().out
    assert "a partial climb: it ends 2.31 m from the goal" in out, out
    assert json.loads(sim.read_text())["trials"] == 20
    assert cli.main(["rig-run", str(partial_plan), "--phase", "0", "--sim-rig", "--log",
                     str(tmp_path / "rig.lcm")]) == 0
    result = rbp.simulate(json.loads(partial_plan.read_text()), plant="body")
    assert result.success, "the API refused it too"


def test_a_plan_of_no_route_is_still_nothing_to_simulate(
        partial_plan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rbp import cli

    plan = json.loads(partial_plan.read_text())
    del plan["partial"]
    path = tmp_path / "noroute.json"
    path.write_text(json.dumps(plan))
    assert cli.main(["simulate", str(path), "--trials", "0"]) == 1
    assert "success: the plan found no route" in capsys.readouterr().err


def test_simulate_refuses_a_footstep_plan_whose_straight_lines_cross_rock(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp rig-run` refuses demo-shaft's footstep plan (its straight lines between steps put
    a boom through rock: rule `between`), yet `rbp simulate`, which follows the same lines,
    flew it, exit 0. Both refuse it now, through the same verifier; --no-verify flies it."""
    import rbp
    from rbp import cli
    from systems.plan_check import executed_motion_problems

    plan = rbp.plan("demo-shaft", footsteps_only=True)
    assert executed_motion_problems(plan.to_dict()), "its straight lines no longer cross rock"
    path = tmp_path / "fs.json"
    rbp.write_plan(plan, path)
    assert cli.main(["simulate", str(path), "--trials", "0"]) == 1
    err = capsys.readouterr().err
    assert ": between: " in err and "which rig-run commands and simulate follows" in err, err
    assert cli.main(["rig-run", str(path), "--phase", "0", "--sim-rig", "--log",
                     str(tmp_path / "rig.lcm")]) == 1
    assert "which rig-run commands and simulate follows" in capsys.readouterr().err
    assert cli.main(["simulate", str(path), "--trials", "0", "--no-verify"]) == 0


# --- memory that grew with the input ---

def test_the_replan_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """`rbp simulate --replan` kept every replanned climb it simulated, one per distinct
    failure state (a whole demo climb: 3.5 MB; thousands of failures: gigabytes). At most
    `replan_cache_mb` are kept now; one dropped is made again when asked for, and the
    results are those of the unbounded cache."""
    import numpy as np
    from test_simulation import _short_plan

    from planning import bounded_cache
    from planning.plan_file import plan_from
    from systems import montecarlo
    from systems.diagram import ClimbSimulator
    from systems.trajectory import PlanTrajectory, plan_scenario

    model = plan_from(_short_plan(json.loads((GOLDEN / "demo-shaft-current.json").read_text())))
    scn = plan_scenario(model)
    sim = ClimbSimulator(scn, plant="body")
    record = sim.run(PlanTrajectory(model, scn))
    # grasps weakened along the phase: failures at many distinct samples
    weak = record._replace(probability=record.probability
                           * np.linspace(1.0, 0.9, len(record.times))[:, None])
    made: list[Any] = []

    class Kept(montecarlo._Replanning):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(montecarlo, "_Replanning", Kept)
    monkeypatch.setattr(bounded_cache, "PROTECTED", 2)  # few entries suffice to show it
    whole = montecarlo.monte_carlo(weak, 300, 0, montecarlo.retry_replanner, "retry", sim,
                                   replan_cache_mb=1e6)
    cap_mb = 0.3
    bounded = montecarlo.monte_carlo(weak, 300, 0, montecarlo.retry_replanner, "retry", sim,
                                     replan_cache_mb=cap_mb)
    assert whole.replanning is not None and whole.replanning.replans > 8, whole.replanning
    assert bounded.replanning == whole.replanning, "bounding changed the results"
    full, capped = made[0].cache.stats(), made[1].cache.stats()
    entry = full["peak_bytes"] / full["live"]
    assert full["peak_bytes"] > 3 * cap_mb * 2**20, f"not enough to bound: {full}"
    assert capped["peak_bytes"] <= cap_mb * 2**20 + 3 * entry, capped
    assert capped["drops"] > 0, capped


def test_a_long_climbs_replay_is_bounded(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """`rbp simulate --html` wrote a frame every 0.2 s of climb (4.4 kB each: the demo's
    182 s, 4.0 MB), without end: a 10-hour climb's page would be 800 MB. A replay now has at
    most MAX_REPLAY_FRAMES frames, spread over the climb, and says so (the limit lowered here
    to 20 so that the 7 s plan reaches it)."""
    from test_simulation import _short_plan

    from rbp import cli
    from systems import meshcat_view

    path = tmp_path / "plan.json"
    path.write_text(json.dumps(_short_plan(json.loads(
        (GOLDEN / "demo-shaft-current.json").read_text()))))
    monkeypatch.setattr(meshcat_view, "MAX_REPLAY_FRAMES", 20)
    page = tmp_path / "climb.html"
    assert cli.main(["simulate", str(path), "--trials", "0", "--no-verify", "--html",
                     str(page)]) == 0
    out = capsys.readouterr().out
    assert "replay: 20 frames spread over the 7 s climb, at most 20" in out, out
    assert "would be 36" in out, out
    assert page.stat().st_size > 0
    assert meshcat_view.replay_frames(36_000.0) == 20, "a 10-hour climb"
    monkeypatch.setattr(meshcat_view, "MAX_REPLAY_FRAMES", 10_000)
    assert meshcat_view.replay_frames(182.0) == 911, "the demo's replay is as before"


# --- file names that break a line ---

def test_a_newline_in_a_file_name_forges_no_line(tmp_path: Path) -> None:
    """`rbp plan -o $'a\\nerror: b.json'` printed "wrote a" and then a line "error: b.json" on
    stdout, and `rbp check` of such a file "c" and "error: d.json: ok: ...": a script reading
    the output saw an error the command never had. File names are printed escaped, as error
    lines print them."""
    made = run_rbp("plan", "demo-shaft", "--footsteps-only", "-q", "-o", "a\nerror: b.json",
                   cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    lines = made.stdout.splitlines()
    assert lines[:2] == ["wrote a\\nerror: b.json", "wrote a\\nerror: b.png"], lines
    checked = run_rbp("check", "-q", "a\nerror: b.json", cwd=tmp_path)
    assert checked.returncode == 0, checked.stderr
    assert not any(line.startswith("error") for line in checked.stdout.splitlines()), \
        checked.stdout
    assert checked.stdout.startswith("a\\nerror: b.json: ok: "), checked.stdout[:80]


# --- names with '.' and '..' that pathlib reads otherwise than the system ---

@pytest.mark.parametrize("output,why", [
    ("cave.yaml/.", "ends with '/.', a folder's name"),
    ("cave.yaml/..", "ends with '/..', a folder's name"),
    ("x/../cave.yaml", "goes up out of x ('..'), which is not a folder")])
def test_an_output_name_pathlib_reads_otherwise_is_refused(output: str, why: str,
                                                           tmp_path: Path) -> None:
    """`-o cave.yaml/.` wrote cave.yaml (pathlib drops a last '/.'; the system says "Not a
    directory"), and `-o x/../cave.yaml`, x missing, made the folder x to climb out of it
    and left it behind, empty (the system says "No such file or directory"). Refused before
    the work now, as `-o cave.yaml/` was."""
    one_error_line(run_rbp("scenario", "generate", "--kind", "shaft", "-o", output,
                           cwd=tmp_path), f"{output}: -o: {why}")
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())
    (tmp_path / "x").mkdir()
    done = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "x/../cave.yaml",
                   cwd=tmp_path)
    assert done.returncode == 0 and (tmp_path / "cave.yaml").is_file(), done.stderr


@pytest.mark.parametrize("command", [["check"], ["simulate", "--trials", "0"],
                                     ["check", "p.json", "--scenario"]])
@pytest.mark.parametrize("tail", ["/.", "/..", "/x"])
def test_an_input_name_going_on_after_a_file_is_refused(command: list[str], tail: str,
                                                        tmp_path: Path) -> None:
    """`rbp check plan.json/.` read plan.json (pathlib drops '/.'), where the system says
    "Not a directory"; `--scenario cave.yaml/` and `/.` were read as cave.yaml (the check of
    a trailing '/' had not been given to --scenario)."""
    shutil.copy(GOLDEN / "demo-shaft-current.json", tmp_path / "p.json")
    shutil.copy(ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml", tmp_path / "c.yaml")
    name = ("c.yaml" if command[-1] == "--scenario" else "p.json") + tail
    result = run_rbp(*command, name, cwd=tmp_path)
    one_error_line(result, f"'{name}' goes on after '{name[:-len(tail)]}', which is a file, "
                   "not a directory")


def test_the_api_reads_a_name_as_the_system_does(tmp_path: Path) -> None:
    """`rbp.load_scenario("cave.yaml/.")` and `("cave.yaml/")` read cave.yaml (made a Path
    first), where `rbp.read_plan` and the commands refuse such names."""
    import rbp
    from rb_drake.scenario import ScenarioError

    cave = tmp_path / "cave.yaml"
    shutil.copy(ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml", cave)
    for tail in ("/.", "/"):
        with pytest.raises(ScenarioError, match="cannot read: Not a directory"):
            rbp.load_scenario(f"{cave}{tail}")
    assert rbp.load_scenario(str(cave)).name == "demo-shaft"
