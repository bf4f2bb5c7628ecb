"""The `rbp` command line, run as a subprocess: generate, check, show, list, demo, --help."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from cli_helpers import run_rbp

from rb_drake.params import RobotParams
from rb_drake.scenario import bundled_caves, load_scenario


def assert_ok(proc: subprocess.CompletedProcess[str]) -> None:
    assert proc.returncode == 0, (
        f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
    assert "Traceback" not in proc.stderr, proc.stderr


def leftovers(folder: Path) -> list[str]:
    """Temporary files of atomic writes (.NAME.XXXX.tmp) left in `folder`."""
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def assert_picture(path: Path) -> None:
    """A PNG with real content: not one flat colour."""
    assert path.is_file() and path.stat().st_size > 1000, f"{path} missing or tiny"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[2] in (3, 4), f"image shape {img.shape}"
    assert img.shape[0] >= 200 and img.shape[1] >= 200, f"image only {img.shape[:2]} pixels"
    rgb = np.asarray(img[..., :3], dtype=float)
    std = float(rgb.std())
    assert std > 0.1, f"pixel standard deviation {std:.4f}: the picture is nearly blank"
    colours = np.unique(np.round(rgb * 255).astype(int).reshape(-1, 3), axis=0)
    assert len(colours) >= 50, f"only {len(colours)} distinct colours"


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    folder = tmp_path_factory.mktemp("cli")
    proc = run_rbp("scenario", "generate", "--kind", "crevasse", "--seed", "3", "-o", "X.yaml",
                   cwd=folder)
    return folder, proc


def test_generate_writes_a_scenario(generated):
    folder, proc = generated
    assert_ok(proc)
    path = folder / "X.yaml"
    assert path.is_file(), f"no X.yaml; stdout:\n{proc.stdout}"
    assert "X.yaml" in proc.stdout and "crevasse-3" in proc.stdout, proc.stdout
    scn = load_scenario(path, check_start=True)
    assert scn.name == "crevasse-3", f"name {scn.name!r}"
    assert len(scn.anchors) >= 4 and len(scn.walls) == 3
    assert leftovers(folder) == [], f"temporary files left: {leftovers(folder)}"


def test_generate_length_sets_the_shaft_height(tmp_path: Path) -> None:
    proc = run_rbp("scenario", "generate", "--kind", "shaft", "--seed", "4", "--length", "4.5",
                   "5", "-o", "S.yaml", cwd=tmp_path)
    assert_ok(proc)
    text = (tmp_path / "S.yaml").read_text()
    assert text.startswith("# rbp scenario generate --kind shaft --seed 4 --length 4.5 5"), (
        f"the file should say how it was made: {text[:120]!r}")
    scn = load_scenario(tmp_path / "S.yaml")
    top = max(p[1] for wall in scn.walls for p in wall)
    # The generator's walls reach 0.5 m past the shaft's height H, drawn in [4.5, 5].
    assert 5.0 - 1e-6 <= top <= 5.5 + 1e-6, f"walls reach y = {top}, not H + 0.5 for H in [4.5, 5]"


@pytest.mark.parametrize("flags, field", [
    (("--length", "5", "4"), "--length"),
    (("--length", "1", "2"), "--length"),
    (("--anchor-density", "0"), "--anchor-density"),
])
def test_generate_refuses_bad_flags(tmp_path: Path, flags, field: str) -> None:
    proc = run_rbp("scenario", "generate", *flags, "-o", "B.yaml", cwd=tmp_path)
    assert proc.returncode == 2, f"exit {proc.returncode}: {proc.stderr}"
    assert proc.stderr.startswith(f"error: {field}:"), proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "B.yaml").exists()


def test_check_generated(generated):
    folder, gen = generated
    assert_ok(gen)
    proc = run_rbp("scenario", "check", "X.yaml", cwd=folder)
    assert_ok(proc)
    first = proc.stdout.splitlines()[0]
    assert "X.yaml" in first and "ok" in first, f"first line {first!r}"
    assert proc.stderr.strip() == "", proc.stderr
    for i in range(4):
        assert f"boom {i} ->" in proc.stdout, f"boom {i} missing from:\n{proc.stdout}"


def test_show_generated(generated):
    folder, gen = generated
    assert_ok(gen)
    proc = run_rbp("scenario", "show", "X.yaml", "-o", "X.png", cwd=folder)
    assert_ok(proc)
    assert_picture(folder / "X.png")
    assert leftovers(folder) == [], f"temporary files left: {leftovers(folder)}"


def test_demo(tmp_path):
    out = tmp_path / "demo"
    proc = run_rbp("demo", "--out", str(out), cwd=tmp_path)
    assert_ok(proc)
    assert_picture(out / "cave.png")
    report = json.loads((out / "start.json").read_text())
    start = report["start"]
    p = start["p_success"]
    assert isinstance(p, float) and math.isfinite(p), f"p_success {p!r}"
    assert 0.95 <= p <= 1.0 + 1e-12, f"p_success {p} below 0.95"
    robot = RobotParams()
    assert report["scenario"]["robot"]["boom_tension"] == list(robot.boom_tension)
    lo, hi = robot.boom_tension
    tension = start["tension"]
    assert len(tension) == 4, f"tensions {tension}"
    for i, t in enumerate(tension):
        assert lo - 1e-6 <= t <= hi + 1e-6, f"boom {i}: tension {t} N outside [{lo}, {hi}] N"
    p_grasp = start["p_grasp"]
    assert len(p_grasp) == 4 and all(0.0 <= q <= 1.0 + 1e-12 for q in p_grasp), p_grasp
    assert p <= min(p_grasp) + 1e-9, f"p_success {p} above a single grasp's {min(p_grasp)}"
    assert all(abs(a) < 90.0 for a in start["pull_angle_deg"]), start["pull_angle_deg"]
    demo = load_scenario(bundled_caves()["demo-shaft"])
    assert start["stance"] == list(demo.start_stance), f"stance {start['stance']}"
    assert start["pose"] == list(demo.start_pose), f"pose {start['pose']}"
    names = sorted(p.name for p in out.iterdir())
    fig6 = [n for n in names if n.startswith("plan-phase")]
    assert names == sorted(["cave.png", "plan.json", "plan.png", "start.json", *fig6]), names
    assert len(fig6) == 1, f"expected one Fig. 6 picture, got {fig6}"
    # The demo plans the climb: the plan must follow the schema and verify from scratch.
    from planning.check import check_plan
    from planning.plan import validate

    plan = json.loads((out / "plan.json").read_text())
    validate(plan)
    assert plan["success"], f"demo plan failed: {plan['reason']}"
    assert check_plan(plan) == [], "the demo plan does not verify"
    assert proc.stdout.strip().splitlines()[-1].startswith("success: true"), proc.stdout
    assert_picture(out / "plan.png")
    assert_picture(out / fig6[0])
    # Full trajectories, not just transition poses: every phase has a seed and SCP record.
    assert all("motion" in phase for phase in plan["phases"]), "a phase without trajectory"
    assert sum(len(phase["steps"]) for phase in plan["phases"]) > 3 * len(plan["phases"])


def test_list(tmp_path):
    proc = run_rbp("scenario", "list", cwd=tmp_path)
    assert_ok(proc)
    names = [line.split()[0] for line in proc.stdout.splitlines() if line.strip()]
    assert "demo-shaft" in names, f"demo-shaft not listed:\n{proc.stdout}"
    assert set(names) == {*bundled_caves(), "rig"}, f"listed {names}"  # the caves and the rig


def test_help(tmp_path):
    proc = run_rbp("--help", cwd=tmp_path)
    assert_ok(proc)
    assert "usage:" in proc.stdout, proc.stdout
    for command in ("demo", "scenario"):
        assert command in proc.stdout, f"{command!r} missing from --help"


def test_help_loads_no_heavy_module() -> None:
    """`rbp --help` builds the whole parser without numpy, Drake or the benchmarks."""
    import subprocess
    import sys

    code = ("import sys; from rbp.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('numpy', 'pydrake', 'experiments.bench', 'scipy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", f"heavy modules loaded by the parser: {out.stdout}"


def test_simulate_no_verify_on_another_caves_plan_ends_in_one_line(tmp_path: Path) -> None:
    """`rbp simulate --no-verify` on a plan of another cave (demo-crevasse's phases in
    shaft-1): the plant's solver diverges; one line names the phase and the time (issue 32:
    it was a Drake traceback), exit status 1 (a failed execution)."""
    golden = Path(__file__).parent / "data" / "golden"
    plan = json.loads((golden / "demo-crevasse.json").read_text())
    plan["scenario"] = json.loads((golden / "shaft-1.json").read_text())["scenario"]
    plan.pop("verified", None)
    (tmp_path / "crossed.json").write_text(json.dumps(plan))
    proc = run_rbp("simulate", "crossed.json", "--no-verify", "--trials", "0", cwd=tmp_path)
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("WARNING:"), proc.stderr
    assert lines[1].startswith("error: crossed.json: the simulation failed in phase "), lines
    assert " at t = " in lines[1] and "rbp check crossed.json" in lines[1], lines[1]


def test_counts_read_right_in_the_singular(tmp_path: Path) -> None:
    """'1 phase', '1 problem', '1 configuration' (issue 32: 'motion: 1 phases')."""
    from rbp.commands.common import plural

    assert [plural(n, "phase") for n in (0, 1, 2)] == ["0 phases", "1 phase", "2 phases"]
    golden = Path(__file__).parent / "data" / "golden" / "rig.json"
    proc = run_rbp("check", str(golden), cwd=tmp_path)
    assert_ok(proc)
    n = len(json.loads(golden.read_text())["phases"])
    assert f"ok: {plural(n, 'phase')}, " in proc.stdout, proc.stdout
