"""Meshcat view of a simulated climb (systems.meshcat_view): loopback only, the scene's
content, and a self-contained HTML replay that renders in headless Chromium.

The climb is the hand-made one-regrasp plan of test_simulation.py (body, reach and body
phases on a short generated shaft; no planner, 1 s to simulate). One
session Meshcat serves every test (Python systems and Meshcat servers live until the process
ends in pydrake 1.51); `meshcat.Delete()` clears it between tests.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import subprocess
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

import numpy as np
import pytest
from test_simulation import hand_plan

from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario
from systems.diagram import ClimbSimulator, PlanTrajectory, SimulationRecord, plan_scenario
from systems.meshcat_view import ROOT, extrude, show_climb, start_meshcat, triangulate

CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="session")
def meshcat():
    return start_meshcat()


@pytest.fixture(autouse=True)
def clean_meshcat(meshcat):
    yield
    meshcat.Delete()
    meshcat.DeleteRecording()


@pytest.fixture(scope="module")
def plan() -> dict[str, Any]:
    return hand_plan(line_holds=True)


@pytest.fixture(scope="module")
def record(plan: dict[str, Any]) -> SimulationRecord:
    scn = plan_scenario(plan)
    return ClimbSimulator(scn).run(PlanTrajectory(plan, scn))


def test_meshcat_listens_on_loopback_only(meshcat) -> None:
    url = urlparse(meshcat.web_url())
    assert url.hostname in ("localhost", "127.0.0.1"), meshcat.web_url()
    assert url.port == meshcat.port() > 0
    if shutil.which("ss") is None:
        pytest.skip("ss is not installed: the socket itself is not checked")
    lines = [ln for ln in subprocess.run(["ss", "-ltnH"], capture_output=True, text=True,
                                         check=True).stdout.splitlines()
             if ln.split()[3].endswith(f":{meshcat.port()}")]
    assert lines, f"nothing listens on port {meshcat.port()}"
    for ln in lines:
        local = ln.split()[3]
        assert local in (f"127.0.0.1:{meshcat.port()}", f"[::1]:{meshcat.port()}"), ln


@pytest.mark.parametrize("seed", [0, 1])
def test_triangulation_covers_each_rock_polygon(shaft: Scenario, seed: int) -> None:
    walls = [*shaft.walls, *generate_cave("crevasse", seed, CaveConfig()).walls]
    for wall in walls:
        pts = np.asarray(wall)
        tri = triangulate(pts)
        assert tri.shape == (len(pts) - 2, 3)
        a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
        areas = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
        x, y = pts[:, 0], pts[:, 1]
        polygon = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
        assert np.all(areas > 0), "every triangle must keep the polygon's orientation"
        assert areas.sum() == pytest.approx(polygon, rel=1e-9), "triangles must tile it"
    vertices, faces = extrude(walls[0], 0.2)
    assert vertices.shape == (3, 2 * len(walls[0])) and faces.max() < vertices.shape[1]


def test_scene_holds_cave_and_animated_robot(meshcat, record: SimulationRecord) -> None:
    shaft = record.plan.scenario
    frames = show_climb(meshcat, record)
    for k in range(len(shaft.walls)):
        assert meshcat.HasPath(f"/drake/{ROOT}/cave/rock{k}")
    for anchor in shaft.anchors:
        assert meshcat.HasPath(f"/drake/{ROOT}/cave/anchors/{anchor.id}")
    for part in ("body", "boom0", "boom3", "gripper2"):
        assert meshcat.HasPath(f"/drake/{ROOT}/robot/{part}")
    assert frames >= 10, f"{frames} frames for a {record.times[-1]:.1f} s climb"
    meshcat.Delete()
    assert not meshcat.HasPath(f"/drake/{ROOT}/robot/body"), "Delete() must clear the scene"


def test_html_replay_renders_in_chromium(meshcat, plan: dict[str, Any], tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """`rbp simulate --html` writes a self-contained replay; headless Chromium draws it."""
    import systems.meshcat_view
    from systems.sim_cli import add_simulate_command, cmd_simulate

    monkeypatch.setattr(systems.meshcat_view, "start_meshcat", lambda: meshcat)
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps(plan))
    html = tmp_path / "out" / "climb.html"
    parser = argparse.ArgumentParser()
    add_simulate_command(parser.add_subparsers())
    args = parser.parse_args(["simulate", str(plan_file), "--trials", "0", "--html", str(html)])
    assert cmd_simulate(args) == 0
    text = html.read_text()
    assert text.lstrip().lower().startswith("<!doctype html") or "<html" in text[:200]
    assert 'src="http' not in text, "the replay must not load scripts from the network"
    assert "set_animation" in text, "the replay must carry the climb's animation"
    assert [p.name for p in html.parent.iterdir()] == ["climb.html"], "temporary files left"
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is not installed: the replay is not rendered")
    shot = tmp_path / "shot.png"
    log = tmp_path / "chromium.log"
    # Output to a file, not pipes: Chromium's helper processes keep inherited pipes open after
    # the browser exits. Its own session, ended afterwards, takes those helpers with it.
    with log.open("w") as out:
        proc = subprocess.Popen(
            [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", "--host-resolver-rules=MAP * ~NOTFOUND",
             f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
             "--window-size=800,600", "--virtual-time-budget=5000", html.as_uri()],
            stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            proc.wait(timeout=120)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
    assert shot.exists(), f"no screenshot (exit {proc.returncode}):\n{log.read_text()[-2000:]}"
    import matplotlib.image

    pixels = matplotlib.image.imread(shot)[..., :3]
    colours = {tuple(c) for c in np.round(pixels.reshape(-1, 3) * 20).astype(int)}
    assert pixels.std() > 0.05, f"the screenshot is blank (pixel std {pixels.std():.4f})"
    assert len(colours) >= 8, f"only {len(colours)} distinct colours: the scene is not drawn"
    rockish = np.all(np.abs(pixels - [0.62, 0.54, 0.46]) < 0.25, axis=-1).mean()
    assert rockish > 0.05, f"rock covers {rockish:.1%} of the picture"
