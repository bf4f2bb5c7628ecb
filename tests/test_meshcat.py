"""Meshcat view of a simulated climb (systems.meshcat_view): loopback only, the scene's
content, and a self-contained HTML replay that headless Chromium draws framed like the 2-D
figures (x right, y up, the whole cave with a small margin, the robot and the anchors shown).

Two climbs: the hand-made one-regrasp plan of test_simulation.py (body, reach and body phases
on a short generated shaft; no planner, 1 s to simulate) and one short body phase in the
bundled demo-crevasse passage, whose ceiling spans the picture's whole width. The screenshots
are checked against where the camera's framing (`view_bounds`, fitted centred into the
window) puts the cave: rock across the picture, each anchor at its pixel, the body on its path.
One session Meshcat serves every test (Python systems and Meshcat servers live until the
process ends in pydrake 1.51); `meshcat.Delete()` clears it between tests.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
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
from pydrake.geometry import Rgba
from test_simulation import hand_plan

from planning.plan import BODY_SPEED, FORMAT, plan_configurations, validate
from planning.plan_model import plan_of
from planning.probability import path_probability
from rb_drake.generate import CaveConfig, generate_cave
from rb_drake.scenario import Scenario, bundled_caves, load_scenario
from systems.diagram import ClimbSimulator, SimulationRecord
from systems.meshcat_view import (
    ANCHOR,
    ANCHOR_RADIUS,
    ATTACHED,
    BODY,
    BOOM_WIDTH,
    FIT_MARKER,
    ROCK,
    ROOT,
    extrude,
    robot_frame,
    save_html,
    show_climb,
    start_meshcat,
    triangulate,
    view_bounds,
)
from systems.montecarlo import configuration
from systems.trajectory import PlanTrajectory, plan_scenario

CHROMIUM = Path("/usr/bin/chromium")
WINDOW = (800, 600)  # px, the screenshots' width and height
WAIT_MS = 4000  # real time to the screenshot at the latest (Chromium's --timeout)
PASSAGE_MOVE = np.array([0.2, 0.0, 0.0])  # the passage climb's body move from its start pose
PASSAGE_SPEEDUP = 0.1  # its replay's: the body moves less than 0.04 m in WAIT_MS


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


@pytest.fixture(scope="module")
def passage_record() -> SimulationRecord:
    """One body phase of demo-crevasse, PASSAGE_MOVE from the start pose in the start stance
    (feasible all along: checked here), as planning.plan writes plans."""
    scn = load_scenario(bundled_caves()["demo-crevasse"])
    stance, start = tuple(scn.start_stance), np.array(scn.start_pose)
    end = start + PASSAGE_MOVE
    duration = float(np.linalg.norm(PASSAGE_MOVE[:2])) / BODY_SPEED
    steps = []
    for s in np.linspace(0.0, 1.0, 5):
        step, ok = configuration(scn, stance, start + s * (end - start), None, s * duration)
        assert ok, f"the passage climb's pose {step.pose} is infeasible"
        steps.append(step.to_dict())
    plan = {"format": FORMAT, "planner": "rbp", "success": True, "reason": "", "p_min": None,
            "p_path": None, "regrasps": 0,
            "timing": dict.fromkeys(("footstep", "seed_body", "scp_body", "seed_reach",
                                     "scp_reach", "total"), 0.0),
            "scenario": scn.to_dict(resolved=True), "robot": scn.robot.to_dict(),
            "phases": [{"kind": "body", "stance": list(stance), "free_boom": None,
                        "steps": steps}]}
    prob = path_probability(plan_configurations(plan_of(plan)), scn.robot.attach_failure)
    plan["p_path"], plan["p_min"] = prob.p_path, prob.p_min
    validate(plan)
    scn = plan_scenario(plan)
    return ClimbSimulator(scn).run(PlanTrajectory(plan, scn))


def screenshot(html: Path, out: Path) -> np.ndarray:
    """Headless Chromium's WINDOW-sized picture of `html`, taken once the page has loaded (in
    about a second) or after WAIT_MS at the latest: (height, width, 3) RGB in [0, 1]. Skips
    the test when Chromium is not installed.

    Real time (--timeout), not --virtual-time-budget: with a virtual time budget this Chromium
    (156) hangs without a screenshot in about one run of five on these pages.
    """
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is not installed: the replay is not rendered")
    shot, log = out / "shot.png", out / "chromium.log"
    # Output to a file, not pipes: Chromium's helper processes keep inherited pipes open after
    # the browser exits. Its own session, ended afterwards, takes those helpers with it.
    with log.open("w") as stream:
        proc = subprocess.Popen(
            [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", "--host-resolver-rules=MAP * ~NOTFOUND",
             f"--user-data-dir={out / 'profile'}", f"--screenshot={shot}",
             f"--window-size={WINDOW[0]},{WINDOW[1]}", f"--timeout={WAIT_MS}",
             html.as_uri()],
            stdout=stream, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            proc.wait(timeout=60)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
    assert shot.exists(), f"no screenshot (exit {proc.returncode}):\n{log.read_text()[-2000:]}"
    import matplotlib.image

    pixels = matplotlib.image.imread(shot)[..., :3]
    assert pixels.shape[:2] == (WINDOW[1], WINDOW[0]), f"screenshot of {pixels.shape}"
    return pixels


class Framing:
    """World <-> pixel of the replay: the camera's box (`view_bounds`) fitted, centred, into
    the window (the page's script), x right and y up."""

    def __init__(self, scn: Scenario):
        xmin, xmax, ymin, ymax = view_bounds(scn)
        width, height = WINDOW
        self.scale = min(width / (xmax - xmin), height / (ymax - ymin))  # px per m
        self.centre = np.array([0.5 * (xmin + xmax), 0.5 * (ymin + ymax)])

    def pixel(self, xy: np.ndarray) -> np.ndarray:
        """(column, row) of world points (n, 2)."""
        d = (np.asarray(xy, dtype=float) - self.centre) * self.scale
        return np.column_stack([0.5 * WINDOW[0] + d[:, 0], 0.5 * WINDOW[1] - d[:, 1]])

    def world(self, column_row: np.ndarray) -> np.ndarray:
        c = np.asarray(column_row, dtype=float)
        return self.centre + np.column_stack([c[:, 0] - 0.5 * WINDOW[0],
                                              0.5 * WINDOW[1] - c[:, 1]]) / self.scale


def near(pixels: np.ndarray, colour, tolerance: float) -> np.ndarray:
    """Mask of the pixels within `tolerance` of an Rgba's colour in every channel."""
    return np.all(np.abs(pixels - [colour.r(), colour.g(), colour.b()]) < tolerance, axis=-1)


def body_mask(pixels: np.ndarray) -> np.ndarray:
    """Pixels of the robot's body: the viewer's tone mapping darkens its grey (to about 0.11,
    0.11, 0.16), and its blue tint sets it apart from the dark-brown outlines of the rock."""
    return near(pixels, BODY, 0.15) & (pixels[..., 2] > pixels[..., 0] + 0.02)


def assert_body_on_path(pixels: np.ndarray, record: SimulationRecord, framing: Framing,
                        path: np.ndarray) -> None:
    """The body's colour covers about its area, centred within 0.1 m of a pose of `path`."""
    w, h = record.plan.scenario.robot.body_size
    area = w * h * framing.scale**2
    mask = body_mask(pixels)
    assert 0.5 * area < mask.sum() < 2.0 * area, \
        f"{mask.sum()} pixels of the body's colour, its area is {area:.0f} px"
    rows, columns = np.nonzero(mask)
    centre = framing.world(np.array([[columns.mean() + 0.5, rows.mean() + 0.5]]))[0]
    miss = float(np.min(np.linalg.norm(path[:, :2] - centre, axis=1)))
    assert miss < 0.1, f"the body is drawn at {centre}, {miss:.2f} m from its path"


def assert_rock_framed(pixels: np.ndarray, scn: Scenario, framing: Framing) -> None:
    """The rock's colour reaches the walls' extremes where the framing puts them (within 1 %
    of the window, plus the outlines), and the walls fill at least 80 % of the window's width
    or height (the margin is small)."""
    rock = near(pixels, ROCK, 0.08)
    assert rock.mean() > 0.05, f"rock covers {rock.mean():.1%} of the picture"
    walls = np.vstack(scn.walls)
    (left, top), (right, bottom) = framing.pixel([[walls[:, 0].min(), walls[:, 1].max()],
                                                  [walls[:, 0].max(), walls[:, 1].min()]])
    rows, columns = np.nonzero(rock)
    tolerance = 3 + 0.01 * WINDOW[0]
    for name, drawn, expected in (("left", columns.min(), left), ("right", columns.max(), right),
                                  ("top", rows.min(), top), ("bottom", rows.max(), bottom)):
        assert abs(drawn - expected) < tolerance, \
            f"the rock's {name} edge is drawn at {drawn} px, the framing puts it at {expected:.0f}"
    fill = max((right - left) / WINDOW[0], (bottom - top) / WINDOW[1])
    assert fill > 0.8, f"the cave fills {fill:.0%} of the window: the margin is too wide"


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


def test_html_replay_renders_in_chromium(meshcat, plan: dict[str, Any], record: SimulationRecord,
                                         tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                         ) -> None:
    """`rbp simulate --html` writes a self-contained replay; headless Chromium draws the shaft
    filling the window's height and the robot on its path."""
    import systems.meshcat_view
    from rbp.commands.simulate import add_simulate_command, cmd_simulate

    monkeypatch.setattr(systems.meshcat_view, "start_meshcat", lambda: meshcat)
    plan_file = tmp_path / "plan.json"
    valid = copy.deepcopy(plan)  # simulate verifies the plan: its goal is where it ends
    valid["scenario"]["goal"]["position"] = valid["phases"][-1]["steps"][-1]["pose"][:2]
    plan_file.write_text(json.dumps(valid))
    html = tmp_path / "out" / "climb.html"
    parser = argparse.ArgumentParser()
    add_simulate_command(parser.add_subparsers())
    # a hand-made footstep plan: its reach's straight line puts a boom through rock (rule
    # between, which simulate verifies as rig-run does); the page is what is tested here
    args = parser.parse_args(["simulate", str(plan_file), "--trials", "0", "--no-verify",
                              "--html", str(html)])
    assert cmd_simulate(args) == 0
    text = html.read_text()
    assert text.lstrip().lower().startswith("<!doctype html") or "<html" in text[:200]
    assert 'src="http' not in text, "the replay must not load scripts from the network"
    assert "set_animation" in text, "the replay must carry the climb's animation"
    assert FIT_MARKER in text, "the page must fit the camera's box into the window"
    assert [p.name for p in html.parent.iterdir()] == ["climb.html"], "temporary files left"
    pixels = screenshot(html, tmp_path)
    colours = {tuple(c) for c in np.round(pixels.reshape(-1, 3) * 20).astype(int)}
    assert pixels.std() > 0.05, f"the screenshot is blank (pixel std {pixels.std():.4f})"
    assert len(colours) >= 8, f"only {len(colours)} distinct colours: the scene is not drawn"
    framing = Framing(record.plan.scenario)
    assert_rock_framed(pixels, record.plan.scenario, framing)
    assert_body_on_path(pixels, record, framing, record.state)


def test_passage_replay_frames_the_whole_cave(meshcat, passage_record: SimulationRecord,
                                              tmp_path: Path) -> None:
    """A passage's replay (slowed: it has barely started): the rock across the whole picture
    (the ceiling spans the cave's width) and framed, every anchor drawn where the framing puts
    it, the booms drawn, and the robot's body at its start pose."""
    scn = passage_record.plan.scenario
    show_climb(meshcat, passage_record, speedup=PASSAGE_SPEEDUP)
    html = save_html(meshcat, tmp_path / "passage.html")
    pixels = screenshot(html, tmp_path)
    framing = Framing(scn)
    rock = near(pixels, ROCK, 0.08)
    thirds = [rock[:, k * WINDOW[0] // 3:(k + 1) * WINDOW[0] // 3].mean() for k in range(3)]
    assert min(thirds) > 0.1, f"rock covers {np.round(thirds, 3)} of the left, middle and " \
                              "right thirds of the picture: the cave is cut or off-centre"
    assert_rock_framed(pixels, scn, framing)
    # Each anchor's sphere at its pixel (the viewer's tone mapping shifts its blue by up to
    # 0.15); the four grippers of the stance cover theirs.
    blue = near(pixels, ANCHOR, 0.2)
    radius = max(2, round(0.8 * framing.scale * ANCHOR_RADIUS))
    missing = []
    for (column, row), anchor in zip(framing.pixel(scn.anchor_positions), scn.anchors,
                                     strict=True):
        c, r = int(column), int(row)
        window = blue[max(r - radius, 0):r + radius + 1, max(c - radius, 0):c + radius + 1]
        if window.sum() < radius * radius:
            missing.append(anchor.id)
    assert len(missing) <= 4, f"anchors {missing} are not drawn where the framing puts them"
    # The booms (attached: green) from the shoulders to their anchors, over rock and air.
    tips = np.array([scn.anchors[scn.anchor_index[a]].position for a in scn.start_stance])
    _, booms, _ = robot_frame(scn, passage_record.state[0, :3], tips)
    boom_area = sum(length for _, length in booms) * BOOM_WIDTH * framing.scale**2
    green = near(pixels, Rgba(*ATTACHED, 1.0), 0.08).sum()
    assert green > 0.5 * boom_area, \
        f"{green} pixels of the attached booms' colour, their area is {boom_area:.0f} px"
    start = passage_record.state[:1]
    assert_body_on_path(pixels, passage_record, framing, start)
