"""Probe 22: the filesystem and the process environment around every command (file names that
are not UTF-8, full disks, signals, standard streams, folders that go away). Each test shows
the command refusing in one line, or doing its work, where it once ended in a traceback or
wrote an output its own readers refuse."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_helpers import ROOT, one_error_line, run_rbp

from rb_drake.errors import utf8_text

DEMO = ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml"
GEOJSON = ROOT / "rb_drake" / "data" / "terrain" / "lava-tube-shaft.geojson"
NOT_UTF8 = os.fsdecode(b"cave\xff\xfe")  # a file name's bytes as argv gives them to Python


def test_utf8_text_escapes_only_what_utf8_cannot_hold() -> None:
    assert utf8_text("shaft é洞") == "shaft é洞", "UTF-8 text must stay as it is"
    assert utf8_text(NOT_UTF8) == "cave\\udcff\\udcfe", utf8_text(NOT_UTF8)
    utf8_text(NOT_UTF8).encode("utf-8")  # never raises


def test_a_plan_of_a_file_named_in_bytes_reads_back(tmp_path: Path) -> None:
    """The plan's provenance held the name's lone surrogates: `rbp check` refused the plan
    `rbp plan` had just written (`provenance.command: a lone surrogate`), and so did
    `--from-plan`."""
    shutil.copy(DEMO, tmp_path / f"{NOT_UTF8}.yaml")
    made = run_rbp("plan", f"{NOT_UTF8}.yaml", "--footsteps-only", "--no-pictures", "--quiet",
                   "-o", f"{NOT_UTF8}.json", cwd=tmp_path)
    assert made.returncode == 0, made.stderr[-600:]
    plan = json.loads((tmp_path / f"{NOT_UTF8}.json").read_bytes())
    recorded = plan["provenance"]
    assert "cave\\udcff\\udcfe.yaml" in recorded["command"], recorded["command"]
    assert recorded["scenario_source"] == "cave\\udcff\\udcfe.yaml", recorded
    checked = run_rbp("check", "-q", f"{NOT_UTF8}.json", cwd=tmp_path)
    assert checked.returncode == 0, f"rbp check refused rbp plan's plan: {checked.stderr!r}"


def test_simulate_json_names_a_plan_named_in_bytes_as_utf8(tmp_path: Path) -> None:
    """`rbp simulate --json` wrote the plan's name with its lone surrogates (\\udcff in JSON, no
    UTF-8 text)."""
    plan = tmp_path / f"{NOT_UTF8}.json"
    shutil.copy(ROOT / "tests" / "data" / "golden" / "demo-shaft-current.json", plan)
    sim = run_rbp("simulate", plan.name, "--trials", "0", "--json", "sim.json", cwd=tmp_path)
    assert sim.returncode == 0, sim.stderr[-600:]
    raw = (tmp_path / "sim.json").read_text(encoding="utf-8")
    assert json.loads(raw)["plan"] == "cave\\udcff\\udcfe.json", raw[:200]


def test_import_of_a_file_named_in_bytes_writes_a_cave_that_reads_back(tmp_path: Path) -> None:
    """`rbp scenario import` of a file whose name is not UTF-8 ended in a UnicodeEncodeError's
    traceback (its command line, in the cave's first line, and its default name)."""
    pytest.importorskip("shapely")
    shutil.copy(GEOJSON, tmp_path / f"{NOT_UTF8}.geojson")
    made = run_rbp("scenario", "import", f"{NOT_UTF8}.geojson", "-o", "cave.yaml", cwd=tmp_path)
    assert made.returncode == 0 and "Traceback" not in made.stderr, made.stderr[-800:]
    text = (tmp_path / "cave.yaml").read_text(encoding="utf-8")
    assert "name: cave\\udcff\\udcfe" in text, text[:300]
    checked = run_rbp("scenario", "check", "cave.yaml", cwd=tmp_path)
    assert checked.returncode == 0, checked.stderr


def test_import_refuses_a_name_in_bytes(tmp_path: Path) -> None:
    """`--name` of bytes that are not UTF-8 was the same traceback; a name is text."""
    pytest.importorskip("shapely")
    result = run_rbp("scenario", "import", str(GEOJSON), "--name", NOT_UTF8, "-o", "cave.yaml",
                     cwd=tmp_path)
    one_error_line(result, "--name", "not UTF-8 text", "cave\\udcff\\udcfe")
    assert not (tmp_path / "cave.yaml").exists(), "a refused import wrote its cave"


# --- no usable temporary folder (TMPDIR, /tmp, /var/tmp and the current folder read-only) ---

GOLDEN = ROOT / "tests" / "data" / "golden"


def _namespaces_work() -> bool:
    if os.geteuid() != 0 or not (shutil.which("unshare") and shutil.which("setpriv")):
        return False
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True, check=False)
    return probe.returncode == 0


needs_root = pytest.mark.skipif(not _namespaces_work() or not os.access("/dev/shm", os.W_OK),
                                reason="needs root, a mount namespace (unshare -m) and /dev/shm")


def _hidden_by_empty_tmp() -> bool:
    """Whether this Python or this tree lives under /tmp or /var/tmp, which
    `without_temporary_folders` hides (a CI checkout under /tmp: its interpreter vanished)."""
    here = (Path(sys.executable).resolve(), Path(sys.prefix).resolve(), ROOT.resolve())
    return any(p.is_relative_to(top) for p in here for top in ("/tmp", "/var/tmp"))


needs_root_outside_tmp = pytest.mark.skipif(
    not _namespaces_work() or not os.access("/dev/shm", os.W_OK) or _hidden_by_empty_tmp(),
    reason="needs root, a mount namespace, /dev/shm, and Python and rbp outside /tmp")


@pytest.fixture
def shm_path() -> Iterator[Path]:
    """A folder outside /tmp, which the namespace hides (pytest's tmp_path is under it)."""
    folder = Path(tempfile.mkdtemp(prefix="rbp-round22-", dir="/dev/shm"))
    yield folder
    for sub in folder.rglob("*"):
        if sub.is_dir():
            sub.chmod(0o755)
    shutil.rmtree(folder, ignore_errors=True)


def without_temporary_folders(folder: Path, *args: str, home: str = "/tmp/home"
                              ) -> subprocess.CompletedProcess[str]:
    """`rbp ARGS` run from the read-only folder FOLDER/ro, in a private mount namespace whose
    /tmp and /var/tmp are empty read-only filesystems, without root's right to write where
    modes forbid it: no temporary folder is usable (tempfile's last resort, the current
    folder, is read-only too). The mounts end with the namespace's one process."""
    ro = folder / "ro"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    script = ("mount -t tmpfs -o ro tmpfs /tmp && mount -t tmpfs -o ro tmpfs /var/tmp && "
              'exec setpriv --inh-caps=-all --ambient-caps=-all --bounding-set=-all "$@"')
    env = {k: v for k, v in os.environ.items()
           if k not in ("TMPDIR", "TEMP", "TMP", "MPLCONFIGDIR", "XDG_CONFIG_HOME",
                        "XDG_CACHE_HOME")}
    env |= {"HOME": home, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(["unshare", "-m", "sh", "-c", script, "sh", sys.executable, "-m",
                           "rbp", *args], cwd=ro, env=env, capture_output=True, text=True,
                          timeout=600, check=False)


@needs_root_outside_tmp
def test_commands_that_draw_nothing_run_without_a_temporary_folder(shm_path: Path) -> None:
    """With HOME read-only and no temporary folder, every command (even `rbp check`) ended in
    a traceback at start-up (making matplotlib's folder), and `rbp rig-run` in `error: (file):
    No usable temporary directory found` (its LCM check's and its log's scratch files)."""
    shutil.copy(GOLDEN / "demo-shaft-current.json", shm_path / "plan.json")
    shutil.copy(GOLDEN / "rig.json", shm_path / "rig.json")
    checked = without_temporary_folders(shm_path, "check", "-q", "../plan.json")
    assert checked.returncode == 0, checked.stderr[-800:]
    assert "Traceback" not in checked.stderr, checked.stderr[-800:]
    run = without_temporary_folders(shm_path, "rig-run", "../rig.json", "--phase", "0",
                                    "--sim-rig", "--log", "../run.lcm")
    assert run.returncode == 0, run.stderr[-800:]
    assert (shm_path / "run.lcm").stat().st_size > 0, "rig-run wrote no log"
    assert sorted(p.name for p in shm_path.iterdir()) == ["plan.json", "rig.json", "ro",
                                                          "run.lcm"], "scratch files left"


@needs_root_outside_tmp
def test_a_picture_that_matplotlib_cannot_draw_is_refused_in_one_line(shm_path: Path) -> None:
    """matplotlib needs a writable folder (HOME's, MPLCONFIGDIR, or a temporary one): with
    none, `rbp scenario show` ended in a traceback; now its -o is refused, naming what to set."""
    result = without_temporary_folders(shm_path, "scenario", "show", "demo-shaft", "-o",
                                       "../cave.png")
    one_error_line(result, "../cave.png: -o: no picture can be drawn here", "MPLCONFIGDIR",
                   "TMPDIR")
    assert not (shm_path / "cave.png").exists()


@needs_root_outside_tmp
def test_an_animation_is_written_without_a_temporary_folder(shm_path: Path) -> None:
    """The animation was rendered in a temporary folder only: with none usable it failed after
    the planning; it is rendered beside its output then."""
    home = shm_path / "home"
    home.mkdir()
    result = without_temporary_folders(shm_path, "plan", "demo-shaft", "--footsteps-only",
                                       "--quiet", "-o", "../plan.json", "--animate",
                                       "../climb.gif", home=str(home))
    assert result.returncode == 0, result.stderr[-800:]
    assert (shm_path / "climb.gif").read_bytes()[:3] == b"GIF", "no animation written"
    assert not [p for p in shm_path.iterdir() if p.name.startswith(".")], "scratch left"


# --- standard streams named as files ---

def test_dash_is_refused_as_an_output_and_explained_as_an_input(tmp_path: Path) -> None:
    """`-o -` wrote a file named '-' (to many tools '-' is standard output), and `rbp check -`
    said only "no such file"."""
    result = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "-", cwd=tmp_path)
    one_error_line(result, "-: -o: '-' is not standard output", "./-")
    assert not (tmp_path / "-").exists(), "a file named '-' was written"
    one_error_line(run_rbp("check", "-", cwd=tmp_path), "-: (file): no such file",
                   "not standard input")
    named = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "./-", cwd=tmp_path)
    assert named.returncode == 0 and (tmp_path / "-").is_file(), named.stderr


def test_dev_stdout_on_a_pipe_is_called_a_pipe(tmp_path: Path) -> None:
    """`-o /dev/stdout` piped (`| cat`) said "cannot write a file there (No such file or
    directory)": the name resolved through /proc/self/fd/1 to 'pipe:[N]', which is no file."""
    result = run_rbp("scenario", "generate", "--kind", "shaft", "-o", "/dev/stdout",
                     cwd=tmp_path)  # run_rbp's standard output is a pipe
    one_error_line(result, "/dev/stdout: -o: is not a regular file", "pipe")


# --- numba's on-disk cache ---

TINY_KERNEL = """
import rb_drake.kernel  # installs rbp's cache handling, as every command's kernels do
from numba import njit

@njit(cache=True)
def plus_one(x):
    return x + 1

print(plus_one(41))
"""


@pytest.mark.parametrize("pattern", ["*.nbc", "*.nbi"])
def test_a_truncated_cache_file_is_compiled_again(tmp_path: Path, pattern: str) -> None:
    """A cache file cut short (a disk that filled, a copy interrupted) ended every command that
    plans in pickle's traceback ("pickle data was truncated") until the cache was deleted; it
    is now a cache miss, compiled again and saved over."""
    (tmp_path / "tiny.py").write_text(TINY_KERNEL)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}

    def run() -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-c", "import tiny"], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300, check=False)

    first = run()
    assert first.returncode == 0 and first.stdout.strip() == "42", first.stderr[-600:]
    files = list((tmp_path / "cache").rglob(pattern))
    assert files, f"numba saved no {pattern} file"
    for f in files:
        f.write_bytes(f.read_bytes()[:20])
    again = run()
    assert again.returncode == 0 and again.stdout.strip() == "42", again.stderr[-600:]
    healed = run()  # and the entry was saved again, whole
    assert healed.returncode == 0 and all(f.stat().st_size > 20 for f in files), \
        [f.stat().st_size for f in files]


def test_simulate_meshcat_with_standard_input_closed(tmp_path: Path) -> None:
    """`rbp simulate --meshcat <&-` (a daemon's or a cron job's closed standard input) ended in
    an AttributeError's traceback after the whole simulation (sys.stdin is None)."""
    shutil.copy(GOLDEN / "demo-shaft-current.json", tmp_path / "plan.json")
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run(["sh", "-c", 'exec "$@" <&-', "sh", sys.executable, "-m", "rbp",
                             "simulate", "plan.json", "--trials", "0", "--meshcat"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
                            check=False)
    assert result.returncode == 0, result.stderr[-800:]
    assert "Meshcat: http" in result.stdout, result.stdout[-400:]


def test_outputs_in_a_current_folder_deeper_than_path_max(tmp_path: Path) -> None:
    """From a current folder nested past PATH_MAX (4096 bytes, reached by relative `cd`s) every
    relative output was refused, "cannot write a file there (File name too long)", while the
    shell and rbp's readers worked there: tempfile made the temporary file's path absolute."""
    deep = "d" * 200
    # down by relative steps (a shell's `cd` takes its logical path, which fails), then rbp
    script = ("import os, sys\nfor _ in range(25):\n    os.mkdir(sys.argv[1])\n"
              "    os.chdir(sys.argv[1])\n"
              "os.execv(sys.executable, [sys.executable, *sys.argv[2:]])")
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://", "MPLBACKEND": "Agg",
           # no empty entry: Python makes one absolute from the current folder, which fails
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                      os.environ.get("PYTHONPATH", "")]))}
    result = subprocess.run([sys.executable, "-c", script, deep, "-m", "rbp", "scenario",
                             "generate", "--kind", "shaft", "-o", "sub/cave.yaml"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
                            check=False)
    assert result.returncode == 0, result.stderr[-400:]
    where = tmp_path.joinpath(*[deep] * 25)  # os.walk's file descriptors reach it; open can't
    fd = os.open(tmp_path, os.O_RDONLY)
    try:
        for _ in range(25):
            sub = os.open(deep, os.O_RDONLY, dir_fd=fd)
            os.close(fd)
            fd = sub
        sub = os.open("sub", os.O_RDONLY, dir_fd=fd)
        os.close(fd)
        fd = sub
        names = sorted(os.listdir(fd))
    finally:
        os.close(fd)
    assert names == ["cave.yaml"], f"{names} in {str(where)[:60]}..."


# --- file names beginning with '-' ---

def test_a_file_name_beginning_with_a_dash_is_explained(tmp_path: Path) -> None:
    """`rbp check -plan.json` said only "unrecognized arguments: -plan.json", and `-o
    -cave.yaml` "expected one argument": argparse reads the name as an option."""
    shutil.copy(GOLDEN / "demo-shaft-current.json", tmp_path / "-plan.json")
    one_error_line(run_rbp("check", "-plan.json", cwd=tmp_path), "unrecognized arguments",
                   "write ./-plan.json")
    one_error_line(run_rbp("scenario", "generate", "--kind", "shaft", "-o", "-cave.yaml",
                           cwd=tmp_path), "-o/--output: expected one argument",
                   "write ./-cave.yaml")
    plain = run_rbp("plan", "demo-shaft", "--seed", "-1.5", "-o", "x.json", cwd=tmp_path)
    assert "write ./" not in one_error_line(plain, "--seed"), "a number is no file name"
    assert run_rbp("check", "-q", "./-plan.json", cwd=tmp_path).returncode == 0


# --- the locale ---

def test_an_ascii_text_encoding_is_refused_in_one_line(tmp_path: Path) -> None:
    """The C locale with Python's UTF-8 mode off (PYTHONUTF8=0): pydrake's import read its own
    files as ASCII and `rbp plan` ended in 80 lines of traceback ("initialization failed")."""
    env = {**os.environ, "LC_ALL": "C", "PYTHONUTF8": "0", "LCM_DEFAULT_URL": "memq://",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-m", "rbp", "plan", "demo-shaft",
                             "--footsteps-only", "--no-pictures", "-o", "plan.json"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
                            check=False)
    one_error_line(result, "PYTHONUTF8 (environment)", "ASCII", "C.UTF-8")
    env["LC_ALL"] = "C.UTF-8"  # a UTF-8 locale, UTF-8 mode off: as before
    result = subprocess.run([sys.executable, "-m", "rbp", "scenario", "check", "demo-shaft"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
                            check=False)
    assert result.returncode == 0, result.stderr[-400:]


def test_an_output_folder_that_is_a_dangling_symlink_is_refused_before_the_work(
        tmp_path: Path) -> None:
    """`-o link/plan.json` with `link` a symlink to a folder that does not exist passed the
    check of outputs and failed after the planning, "error: link: File exists" (no option)."""
    (tmp_path / "link").symlink_to(tmp_path / "gone")
    result = run_rbp("plan", "demo-shaft", "--footsteps-only", "-o", "link/plan.json",
                     cwd=tmp_path)
    one_error_line(result, "link/plan.json: -o: its folder link is a symlink to",
                   "which does not exist")
    assert "wrote" not in result.stdout, "the planning ran before the refusal"


# --- signals ---

_HANGUP = r"""
import os, signal, sys
from rb_drake.files import atomic_write
from rbp.commands.common import Terminated, clean_interrupts
if sys.argv[2] == "nohup":
    signal.signal(signal.SIGHUP, signal.SIG_IGN)

def write(f):
    f.write(b"half")
    os.kill(os.getpid(), signal.SIGHUP)  # the terminal hangs up mid-write
    f.write(b" and the rest")

try:
    with clean_interrupts():
        atomic_write(os.path.join(sys.argv[1], "out.json"), write)
    print("written")
except Terminated:
    print("terminated")
"""


@pytest.mark.parametrize("caller", ["terminal", "nohup"])
def test_a_hangup_unwinds_as_sigterm_does(tmp_path: Path, caller: str) -> None:
    """SIGHUP (the terminal closed, an ssh session dropped) killed rbp at once: a picture or
    animation being written left its `.NAME.XXXXXXXX.tmp` behind, exit status 129. It now
    unwinds as SIGTERM does; under nohup (SIGHUP ignored) it stays ignored."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    done = subprocess.run([sys.executable, "-c", _HANGUP, str(tmp_path), caller], env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    left = sorted(p.name for p in tmp_path.iterdir())
    if caller == "nohup":
        assert done.stdout.strip() == "written" and left == ["out.json"], (done, left)
        assert (tmp_path / "out.json").read_bytes() == b"half and the rest"
    else:
        assert done.stdout.strip() == "terminated", (done.returncode, done.stderr[-300:])
        assert left == [], f"left behind: {left}"


# --- replacing an existing output ---

def test_a_replaced_output_keeps_its_permissions(tmp_path: Path) -> None:
    """Writing an output again reset its mode to 0644: a plan its owner had made private
    (0600) became readable by everyone."""
    cave = tmp_path / "cave.yaml"
    assert run_rbp("scenario", "generate", "--kind", "shaft", "-o", "cave.yaml",
                   cwd=tmp_path).returncode == 0
    cave.chmod(0o600)
    again = run_rbp("scenario", "generate", "--kind", "shaft", "--seed", "2", "-o", "cave.yaml",
                    cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert "shaft-2" in cave.read_text(), "not written again"
    assert oct(cave.stat().st_mode & 0o777) == oct(0o600), oct(cave.stat().st_mode)


def test_a_read_only_output_is_refused_before_the_work(tmp_path: Path) -> None:
    """A file its owner made read-only (0444) was replaced all the same (the rename needs only
    the folder's permission; `cp` refuses): `rbp check --stamp` rewrote a 0444 plan as 0644."""
    if os.geteuid() == 0 and not shutil.which("setpriv"):
        pytest.skip("root writes any file; setpriv is needed to drop that right")
    plan = tmp_path / "plan.json"
    shutil.copy(GOLDEN / "demo-shaft-current.json", plan)
    plan.chmod(0o444)
    before = plan.read_bytes()
    prefix = (["setpriv", "--inh-caps=-all", "--ambient-caps=-all", "--bounding-set=-all"]
              if os.geteuid() == 0 else [])
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([*prefix, sys.executable, "-m", "rbp", "check", "--stamp",
                             "plan.json"], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=300, check=False)
    one_error_line(result, "plan.json: --stamp: is read-only (mode 0444)", "chmod u+w")
    assert plan.read_bytes() == before and oct(plan.stat().st_mode & 0o777) == oct(0o444)


def test_a_bundled_cave_from_a_current_folder_that_cannot_be_searched(tmp_path: Path) -> None:
    """From a current folder its user may not search (`sudo -u someone rbp ...` run from a
    private home), `rbp scenario check demo-shaft` said "demo-shaft: (file): cannot read:
    Permission denied": looking for a file of that name failed, and the bundled cave was
    never tried."""
    if os.geteuid() == 0 and not shutil.which("setpriv"):
        pytest.skip("root searches any folder; setpriv is needed to drop that right")
    prefix = (["setpriv", "--inh-caps=-all", "--ambient-caps=-all", "--bounding-set=-all"]
              if os.geteuid() == 0 else [])
    closed = tmp_path / "closed"
    closed.mkdir()
    script = "import os, sys\nos.chmod('.', 0)\nos.execvp(sys.argv[1], sys.argv[1:])"
    env = {**os.environ, "LCM_DEFAULT_URL": "memq://",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    try:
        result = subprocess.run([sys.executable, "-c", script, *prefix, sys.executable, "-m",
                                 "rbp", "scenario", "check", "demo-shaft"], cwd=closed,
                                env=env, capture_output=True, text=True, timeout=300,
                                check=False)
        missing = subprocess.run([sys.executable, "-c", script, *prefix, sys.executable, "-m",
                                  "rbp", "scenario", "check", "nosuch.yaml"], cwd=closed,
                                 env=env, capture_output=True, text=True, timeout=300,
                                 check=False)
    finally:
        closed.chmod(0o755)
    assert result.returncode == 0 and "ok: demo-shaft" in result.stdout, result.stderr
    one_error_line(missing, "nosuch.yaml: (file): cannot read: Permission denied")


@needs_root
def test_a_full_disk_under_the_cache_leaves_the_kernel_unsaved(tmp_path: Path) -> None:
    """A full disk where numba saves its cache ended every planning command in "error: (file):
    No space left on device" (numba's save raised after compiling); the kernel now runs,
    unsaved."""
    (tmp_path / "tiny.py").write_text(TINY_KERNEL)
    cache = tmp_path / "cache"
    cache.mkdir()
    script = ('mount -t tmpfs -o size=8k tmpfs "$1" && (cat /dev/zero > "$1/fill") 2>/dev/null;'
              ' shift; exec "$@"')
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    result = subprocess.run(["unshare", "-m", "sh", "-c", script, "sh", str(cache),
                             sys.executable, "-c", "import tiny"], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0 and result.stdout.strip() == "42", result.stderr[-600:]
    assert list(cache.iterdir()) == [], "the namespace's mount was seen outside it"


def test_a_finished_trial_record_made_read_only_is_kept(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The read-only refusal is for files rbp would replace: a sweep's finished trial records,
    kept as they are, may be read-only (results protected with chmod a-w, then resumed)."""
    from rb_drake import files
    from rb_drake.files import output_problem

    record = tmp_path / "trial.json"
    record.write_text("{}\n")
    record.chmod(0o444)
    access = os.access  # root may write anything: the record alone is denied to it here
    monkeypatch.setattr(files.os, "access",
                        lambda p, mode: Path(p) != record and access(p, mode))
    assert output_problem(record, may_keep=True) is None
    assert "is read-only (mode 0444)" in str(output_problem(record))


# --- a file that changes while it is used ---

def test_stamp_never_replaces_a_plan_written_during_its_check(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """`rbp check --stamp plan.json` while `rbp plan -o plan.json` wrote a new plan: the stamp
    replaced the new plan with the old one, marked as verified."""
    import systems.plan_check as plan_check
    from rbp import cli

    plan = tmp_path / "plan.json"
    shutil.copy(GOLDEN / "demo-shaft-current.json", plan)
    newer = b'{"format": "reachbot-plan/2", "written": "meanwhile"}\n'
    verify = plan_check.plan_problems

    def meanwhile(*args, **kwargs):  # type: ignore[no-untyped-def]
        found = verify(*args, **kwargs)
        plan.write_bytes(newer)  # another command writes the plan during the check
        return found

    monkeypatch.setattr(plan_check, "plan_problems", meanwhile)
    status = cli.main(["check", "--stamp", "-q", str(plan)])
    err = capsys.readouterr().err
    assert status == 2, (status, err)
    assert "--stamp: the file changed while it was being checked" in err, err
    assert plan.read_bytes() == newer, "the stamp replaced the plan written meanwhile"
