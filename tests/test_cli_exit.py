"""Exit statuses of `rbp plan` (and the entry point): 0 plan found, 1 no route, 2 bad input,
3 interrupted; each with one line on stderr and never a half-written file."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from cli_helpers import ROOT, run_rbp
from conftest import SHAFT

from planning.plan_model import FORMAT
from rbp import cli
from rbp.commands import plan as plan_cli


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


@pytest.fixture
def stuck_shaft(tmp_path: Path) -> Path:
    """The test shaft: four anchors only, so no boom can move and the goal is out of reach."""
    path = tmp_path / "stuck.yaml"
    path.write_text(yaml.safe_dump(SHAFT, sort_keys=False))
    return path


def test_plan_found_exits_0(tmp_path: Path) -> None:
    proc = run_rbp("plan", "demo-crevasse", "-o", "p.json", "--footsteps-only", cwd=tmp_path)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    plan = json.loads((tmp_path / "p.json").read_text())
    assert plan["success"] is True, plan["reason"]


def test_no_route_exits_1_and_still_writes_the_plan(tmp_path: Path, stuck_shaft: Path) -> None:
    proc = run_rbp("plan", str(stuck_shaft), "-o", "p.json", "--max-expansions", "20",
                   cwd=tmp_path)
    assert proc.returncode == 1, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    plan = json.loads((tmp_path / "p.json").read_text())
    assert plan["success"] is False and plan["reason"], f"success {plan['success']}"
    assert proc.stdout.strip().splitlines()[-1].startswith("success: false"), proc.stdout
    assert leftovers(tmp_path) == [], leftovers(tmp_path)
    # the failed search is pictured beside the plan
    for name in ("p.png", "p-search.png"):
        picture = tmp_path / name
        assert picture.is_file() and picture.stat().st_size > 1000, f"{name} missing or tiny"
        assert f"wrote {name}" in proc.stdout, proc.stdout


@pytest.mark.parametrize("change, field", [
    ({"goal": {"position": [0.0, 7.0], "tolerance": -1}}, "goal.tolerance"),
    ({"start": {"pose": [0.0, 1.0, 0.0], "stance": ["a0", "a1", "a2", "a9"]}},
     "start.stance[3]"),
    ({"goal": {"position": [1.6, 4.0], "tolerance": 0.5}}, "goal.position"),  # in rock
])
def test_bad_scenario_exits_2_with_one_line(tmp_path: Path, change: dict, field: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({**SHAFT, **change}, sort_keys=False))
    proc = run_rbp("plan", str(path), "-o", "p.json", cwd=tmp_path)
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: {field}:"), proc.stderr
    assert not (tmp_path / "p.json").exists(), "a plan file was written for bad input"


def test_unwritable_output_exits_2(tmp_path: Path, stuck_shaft: Path) -> None:
    (tmp_path / "file").write_text("not a folder")
    proc = run_rbp("plan", str(stuck_shaft), "-o", "file/p.json", "--max-expansions", "5",
                   cwd=tmp_path)
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr


def test_interrupt_while_planning_exits_3(tmp_path: Path, stuck_shaft: Path, monkeypatch,
                                          capsys) -> None:
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(plan_cli, "run_planner", interrupted)
    out = tmp_path / "p.json"
    assert cli.main(["plan", str(stuck_shaft), "-o", str(out)]) == cli.EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["interrupted"], err
    assert not out.exists(), "a plan file was written by an interrupted run"


def test_interrupt_while_writing_leaves_no_file(tmp_path: Path, stuck_shaft: Path, monkeypatch,
                                                capsys) -> None:
    """Ctrl-C in the middle of writing the plan: neither the plan nor a temporary file stays."""
    real_dumps = json.dumps

    def dumps(obj, *args, **kwargs):
        if isinstance(obj, dict) and obj.get("format") == FORMAT:
            raise KeyboardInterrupt
        return real_dumps(obj, *args, **kwargs)

    monkeypatch.setattr(json, "dumps", dumps)
    out = tmp_path / "p.json"
    status = cli.main(["plan", str(stuck_shaft), "-o", str(out), "--max-expansions", "5"])
    assert status == cli.EXIT_INTERRUPTED, status
    assert capsys.readouterr().err.strip().splitlines()[-1] == "interrupted"
    assert not out.exists() and leftovers(tmp_path) == [], sorted(os.listdir(tmp_path))


def test_sigint_exits_3_without_traceback(tmp_path: Path) -> None:
    """A real Ctrl-C (SIGINT) during a long search: one line, status 3, no plan file."""
    env = {**os.environ, "MPLBACKEND": "Agg", "LCM_DEFAULT_URL": "memq://",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    # A shell that started this run in the background ignores SIGINT, and children inherit
    # that: give the child the default disposition, so Python installs its handler.
    # A 20 m shaft: its search runs for minutes (a bundled cave plans in seconds now).
    made = run_rbp("scenario", "generate", "--kind", "shaft", "--seed", "1002", "--length",
                   "20", "20", "-o", "long.yaml", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    proc = subprocess.Popen([sys.executable, "-m", "rbp", "plan", "long.yaml", "-o", "p.json",
                             "--max-expansions", "100000", "--footsteps-only"], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(3.0)  # past start-up (about a second), inside the search (minutes)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, f"exit {proc.returncode}\n{out}\n{err}"
    assert err.strip().splitlines()[-1] == "interrupted" and "Traceback" not in err, err
    assert not (tmp_path / "p.json").exists()
    assert leftovers(tmp_path) == [], sorted(os.listdir(tmp_path))


def test_help_documents_the_exit_statuses(tmp_path: Path) -> None:
    for args in (("--help",), ("plan", "--help")):
        proc = run_rbp(*args, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        text = " ".join(proc.stdout.split())
        for line in ("exit status:", "0 done", "1 ran but failed", "2 bad input",
                     "3 interrupted"):
            assert line in text, f"{line!r} missing from rbp {' '.join(args)}:\n{proc.stdout}"


def test_plan_without_pictures_loads_no_matplotlib(tmp_path: Path, stuck_shaft: Path) -> None:
    """matplotlib is imported only when a picture is drawn (it costs about 0.3 s)."""
    out = tmp_path / "p.json"
    code = ("import sys; from rbp.cli import main; "
            f"status = main(['plan', {str(stuck_shaft)!r}, '-o', {str(out)!r}, '--no-pictures', "
            "'--max-expansions', '5']); "
            "print(status, 'matplotlib' in sys.modules)")
    env = {**os.environ, "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, check=False)
    assert proc.stdout.strip().splitlines()[-1] == "1 False", proc.stdout + proc.stderr
    assert out.is_file() and not (tmp_path / "p.png").exists()


def _env() -> dict[str, str]:
    return {**os.environ, "MPLBACKEND": "Agg", "LCM_DEFAULT_URL": "memq://",
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def test_a_closed_output_pipe_stops_quietly_with_status_3(tmp_path: Path) -> None:
    """`rbp ... | head` closes the pipe early: status 3 and no traceback or bogus 'error:'
    (unbuffered, so that the first print meets the closed pipe)."""
    proc = subprocess.Popen([sys.executable, "-u", "-m", "rbp", "scenario", "list"],
                            cwd=tmp_path, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader goes away before the first line
    status = proc.wait(timeout=120)
    stderr = proc.stderr.read().decode()
    proc.stderr.close()
    assert status == cli.EXIT_INTERRUPTED, f"exit {status}, want 3\n{stderr}"
    assert "Traceback" not in stderr and "error" not in stderr, stderr


def test_check_does_not_load_the_footstep_planner(tmp_path: Path) -> None:
    """Reading and verifying a plan needs neither the search (numba, networkx) nor jsonschema
    (a valid plan passes the compiled schema); importing them cost rbp check 0.4 s."""
    out = tmp_path / "p.json"
    proc = run_rbp("plan", "demo-crevasse", "-o", str(out), "--footsteps-only", "--no-pictures",
                   cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    code = ("import sys; from rbp.cli import main; "
            f"status = main(['check', {str(out)!r}]); "
            "print(status, *(m in sys.modules for m in ('numba', 'networkx', 'jsonschema')))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, check=False)
    assert proc.stdout.strip().splitlines()[-1] == "0 False False False", (
        "rbp check loaded the footstep planner or jsonschema (status, numba, networkx, "
        f"jsonschema):\n{proc.stdout}{proc.stderr}")


_SWALLOWED = r"""
import os, signal, sys, tempfile, time
import rbp.commands.common as common
from rb_drake.files import LIVE_TEMPORARY
common.SWALLOWED_INTERRUPT_S = 1
fd, tmp = tempfile.mkstemp(dir=sys.argv[1], suffix=".tmp")
LIVE_TEMPORARY.add(tmp)
with common.clean_interrupts():
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    except KeyboardInterrupt:
        pass  # swallowed, as a callback's exception is
    if sys.argv[2] == "long":
        time.sleep(30)
print("finished")
"""


@pytest.mark.parametrize("work", ["long", "short"])
def test_a_swallowed_sigterm_still_ends_the_command(tmp_path: Path, work: str) -> None:
    """SIGTERM raised inside code that swallows it (matplotlib's callbacks did, while an
    animation was written): the command still ends, exit 3, its temporary files removed; if
    it ends by itself first, it still reports the interrupt."""
    done = subprocess.run([sys.executable, "-c", _SWALLOWED, str(tmp_path), work],
                          capture_output=True, text=True, timeout=120)
    assert "finished" not in done.stdout, f"the command went on to its end: {done.stdout!r}"
    assert list(tmp_path.iterdir()) == [] or work == "short", \
        f"a temporary file was left: {list(tmp_path.iterdir())}"
    if work == "long":
        assert done.returncode == 3, (done.returncode, done.stderr)
        assert done.stderr.strip() == "interrupted", done.stderr
    else:
        assert done.returncode != 0 and "Terminated" in done.stderr, \
            "a swallowed interrupt must still end the command as interrupted at its end"


_DURING_IMPORT = r"""
import os, signal, sys, time
sys.path.insert(0, sys.argv[1])
from rbp.commands.common import clean_interrupts
try:
    with clean_interrupts():
        try:
            import slow_library  # interrupts itself halfway through its import
        except ImportError:
            print("swallowed by an optional import")
        time.sleep(3)
        print("not interrupted")
except KeyboardInterrupt:
    print("interrupted once imported:", sys.modules["slow_library"].DONE)
"""

_SLOW_LIBRARY = """
import os, signal, time
os.kill(os.getpid(), signal.{signal})
start = time.monotonic()
while time.monotonic() - start < 0.3:  # work in Python, where the interrupt would land
    pass
DONE = True
"""


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_an_interrupt_during_an_import_lands_after_it(tmp_path: Path, name: str) -> None:
    """Ctrl-C inside an import left pydrake "initialization failed", numba's extension an
    ImportError, once a segfault, and an optional import's `except ImportError` swallowed it:
    the interrupt is held until the import is done, then raised."""
    (tmp_path / "slow_library.py").write_text(_SLOW_LIBRARY.format(signal=name))
    # SIGINT restored in the child: a shell that started this run in the background ignores
    # it, children inherit that, and clean_interrupts rightly leaves an ignored SIGINT ignored
    done = subprocess.run([sys.executable, "-c", _DURING_IMPORT, str(tmp_path)], cwd=ROOT,
                          env=_env(), capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines = done.stdout.strip().splitlines()
    assert lines == ["interrupted once imported: True"], (lines, done.stderr[-2000:])


def test_a_plan_of_no_route_is_a_failed_outcome_for_simulate_and_rig_run(tmp_path: Path) -> None:
    """`rbp plan` writes a valid plan when it finds no route; `rbp simulate` and `rbp rig-run`
    have nothing to fly: one line naming `success`, exit status 1 (a failed outcome), not 2
    (bad input), and rig-run no longer says 'phases[0]: no such phase'."""
    planned = run_rbp("plan", "blocked-shaft", "-o", "p.json", "--footsteps-only",
                      "--no-pictures", cwd=tmp_path)
    assert planned.returncode == 1 and (tmp_path / "p.json").exists(), planned.stderr
    for args in (("simulate", "p.json", "--trials", "1"),
                 ("rig-run", "--sim-rig", "p.json", "--log", "r.lcm")):
        done = run_rbp(*args, cwd=tmp_path)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 1 and len(lines) == 1, (args, done.returncode, done.stderr)
        assert "p.json: success: the plan found no route" in lines[0], lines[0]
    assert not (tmp_path / "r.lcm").exists(), "rig-run wrote a log of nothing"
