"""The cave and a simulated climb in Drake's Meshcat, and a self-contained HTML replay.

The scene lies in the x-y plane (the world frame of the model), seen from +z by an orthographic
camera, so x points right and y up as in the matplotlib figures; what is drawn in front has the
larger z: rock polygons as extruded triangle meshes with their outlines on top, anchors as small
spheres with a line along their outward normal, the goal as a disc, and the robot as its body
box, four booms (thin boxes stretched from shoulder to gripper) and gripper spheres. A run
(`SimulationRecord`) is replayed as a Meshcat animation: transforms and the booms' "scale"
property per frame, an attached boom green, a free one orange, a failed one red from its failure
on; the robot also stands at the first frame's pose outside the animation, so it is drawn before
the replay starts.

Meshcat must listen on the loopback interface only: `start_meshcat` binds 127.0.0.1 on a free
port (Drake's default listens on every interface). The replay is saved with
`meshcat.StaticHtml()`, written atomically, with a few lines of script that fit the camera's
box into the browser window (see `save_html`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydrake.geometry import Box, Cylinder, Meshcat, MeshcatParams, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix

from rb_drake.files import atomic_write_text
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario
from systems.diagram import SimulationRecord

ROOT = "rbp"  # relative: under Meshcat's /drake, so meshcat.Delete() clears it
ROCK_DEPTH = 0.2      # m, the rock's extrusion below and above the plane
BOOM_WIDTH = 0.025    # m
ANCHOR_RADIUS = 0.025
GRIPPER_RADIUS = 0.035
NORMAL_LENGTH = 0.15  # m, the line drawn along an anchor's outward normal
FRONT = ROCK_DEPTH + 0.06  # z of the robot and the anchors, between the camera and the rock
CAMERA_HEIGHT = 10.0  # m above the plane (orthographic: only the order in depth matters)
MARGIN = 0.05  # of the cave's larger extent (at least MIN_MARGIN) around the framed scene
MIN_MARGIN = 0.2  # m
ROCK = Rgba(0.62, 0.54, 0.46, 1.0)
ROCK_EDGE = Rgba(0.25, 0.2, 0.15, 1.0)
ANCHOR = Rgba(0.15, 0.35, 0.85, 1.0)
GOAL = Rgba(0.75, 0.92, 0.75, 0.5)
BODY = Rgba(0.2, 0.2, 0.25, 1.0)
ATTACHED = [0.2, 0.65, 0.25]
FREE = [0.95, 0.6, 0.1]
FAILED = [0.9, 0.1, 0.1]
AMBIENT = 2.6  # the only light; measured: the rock then shows its own colour (tone mapping)
# The slowest replay: Drake keys an animation by an int frame (time x frames per second), which
# silently wraps past 2^31 (a frame at 1e12 s became -2^31); the longest plan (t <= 1e7 s) at
# 20 frames a second stays below it at 0.1x (2e9).
MIN_SPEEDUP = 0.1
# A replay's frames at most: `--html` holds about 4.4 kB a frame (the demo's 182 s climb at 4x:
# 911 frames, 4.0 MB), and its page grew without end with the climb (a 10-hour climb: 800 MB)
MAX_REPLAY_FRAMES = 10_000


def start_meshcat() -> Meshcat:
    """A Meshcat server on 127.0.0.1 and a free port (never all interfaces)."""
    return Meshcat(MeshcatParams(host="localhost", port=0))


def triangulate(polygon: np.ndarray) -> np.ndarray:
    """Ear-clipping triangulation of a simple counter-clockwise polygon: (n - 2, 3) indices."""
    pts = np.asarray(polygon, dtype=float)
    left = list(range(len(pts)))
    triangles = []

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    def inside(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
        return cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0

    guard = 0
    while len(left) > 3 and guard < 10 * len(pts) ** 2:
        guard += 1
        for k in range(len(left)):
            i, j, m = left[k - 1], left[k], left[(k + 1) % len(left)]
            a, b, c = pts[i], pts[j], pts[m]
            if cross(a, b, c) <= 1e-15:
                continue  # reflex or degenerate corner: not an ear
            if any(inside(pts[q], a, b, c) for q in left if q not in (i, j, m)):
                continue
            triangles.append((i, j, m))
            left.pop(k)
            break
        else:
            break  # no ear found (not simple): fan the rest
    for k in range(1, len(left) - 1):
        triangles.append((left[0], left[k], left[k + 1]))
    return np.array(triangles, dtype=np.int32)


def extrude(polygon: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (3, 2n) and faces (3, m) of a polygon extruded between z = -depth and +depth."""
    pts = np.asarray(polygon, dtype=float)
    n = len(pts)
    top = triangulate(pts)
    vertices = np.vstack([np.column_stack([pts, np.full(n, depth)]),
                          np.column_stack([pts, np.full(n, -depth)])])
    faces = [top, top[:, ::-1] + n]
    ring = np.arange(n)
    nxt = (ring + 1) % n
    faces.append(np.column_stack([ring, ring + n, nxt + n]))
    faces.append(np.column_stack([ring, nxt + n, nxt]))
    return vertices.T.copy(), np.vstack(faces).T.astype(np.int32).copy()


def draw_scenario(meshcat: Meshcat, scn: Scenario) -> None:
    """Rock, anchors (with normals) and the goal, under /drake/rbp/cave."""
    for k, wall in enumerate(scn.walls):
        vertices, faces = extrude(wall, ROCK_DEPTH)
        meshcat.SetTriangleMesh(f"{ROOT}/cave/rock{k}", vertices, faces, ROCK)
        outline = np.column_stack([np.vstack([wall, wall[:1]]),
                                   np.full(len(wall) + 1, ROCK_DEPTH + 0.01)])
        meshcat.SetLine(f"{ROOT}/cave/edge{k}", outline.T.copy(), 2.0, ROCK_EDGE)
    for anchor in scn.anchors:
        path = f"{ROOT}/cave/anchors/{anchor.id}"
        p = np.array([*anchor.position, FRONT])
        meshcat.SetObject(path, Sphere(ANCHOR_RADIUS), ANCHOR)
        meshcat.SetTransform(path, RigidTransform(p))
        tip = p + NORMAL_LENGTH * np.array([*anchor.normal, 0.0])
        meshcat.SetLine(f"{path}-normal", np.column_stack([p, tip]), 2.0, ANCHOR)
    goal = f"{ROOT}/cave/goal"
    meshcat.SetObject(goal, Cylinder(scn.goal_tolerance, 0.005), GOAL)
    # a disc over the rock, under the robot
    meshcat.SetTransform(goal, RigidTransform([*scn.goal_position, ROCK_DEPTH + 0.03]))


def _robot_objects(meshcat: Meshcat, scn: Scenario) -> None:
    w, h = scn.robot.body_size
    meshcat.SetObject(f"{ROOT}/robot/body", Box(w, h, 0.08), BODY)
    for i in range(NUM_BOOMS):
        # a unit-length box along x, stretched to the boom's length by its "scale" property
        meshcat.SetObject(f"{ROOT}/robot/boom{i}", Box(1.0, BOOM_WIDTH, BOOM_WIDTH),
                          Rgba(*ATTACHED, 1.0))
        meshcat.SetObject(f"{ROOT}/robot/gripper{i}", Sphere(GRIPPER_RADIUS), Rgba(*ATTACHED, 1.0))


def robot_frame(scn: Scenario, pose: np.ndarray, tips: np.ndarray
                ) -> tuple[RigidTransform, list[tuple[RigidTransform, float]], np.ndarray]:
    """Body transform, per boom (transform of its midpoint, length), shoulder positions."""
    x, y, phi = (float(v) for v in pose)
    c, s = math.cos(phi), math.sin(phi)
    shoulders = np.array([[x + c * sx - s * sy, y + s * sx + c * sy]
                          for sx, sy in scn.robot.shoulders])
    z = FRONT
    body = RigidTransform(RotationMatrix.MakeZRotation(phi), [x, y, z])
    booms = []
    for p, t in zip(shoulders, tips, strict=True):
        d = t - p
        length = float(np.hypot(*d))
        mid = 0.5 * (p + t)
        booms.append((RigidTransform(RotationMatrix.MakeZRotation(math.atan2(d[1], d[0])),
                                     [mid[0], mid[1], z]), max(length, 1e-3)))
    return body, booms, shoulders


def gripper_positions(record: SimulationRecord, sample: int) -> tuple[np.ndarray, np.ndarray]:
    """Each gripper's position at a sample and whether its boom is attached."""
    plan = record.plan
    k = int(record.phase[sample])
    phase = plan.phases[k]
    t = float(record.times[sample])
    tips = np.where(phase.stance.attached[:, None], phase.stance.positions, 0.0)
    j = phase.stance.free_boom
    if j is not None and phase.free_tip is not None:
        tips[j] = phase.free_tip.value(t).ravel()
    return tips, phase.stance.attached.copy()


def srgb_to_linear(rgb: list[float] | np.ndarray) -> np.ndarray:
    """sRGB components (as `Rgba` takes them) in the viewer's linear working colour space, which
    the "color" property and animated material colours are given in."""
    c = np.asarray(rgb, dtype=float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _set_robot(meshcat: Meshcat, record: SimulationRecord, sample: int,
               time: float | None) -> None:
    """The robot at a sample of the run: in the animation at `time`, or now if it is None."""
    scn = record.plan.scenario
    at = () if time is None else (time,)
    tips, attached = gripper_positions(record, sample)
    body, booms, _ = robot_frame(scn, record.state[sample, :3], tips)
    failure = record.failure
    meshcat.SetTransform(f"{ROOT}/robot/body", body, *at)
    for i, (X, length) in enumerate(booms):
        colour = ATTACHED if attached[i] else FREE
        if failure is not None and i == failure.boom and record.times[sample] >= failure.time:
            colour = FAILED
        meshcat.SetTransform(f"{ROOT}/robot/boom{i}", X, *at)
        meshcat.SetProperty(f"{ROOT}/robot/boom{i}/<object>", "scale", [length, 1.0, 1.0], *at)
        linear = [float(c) for c in srgb_to_linear(colour)]
        for part in (f"boom{i}", f"gripper{i}"):
            if time is None:
                meshcat.SetProperty(f"{ROOT}/robot/{part}/<object>", "color", [*linear, 1.0])
            else:  # the "color" property has no animation track; the material's colour has
                meshcat.SetProperty(f"{ROOT}/robot/{part}/<object>", "material.color", linear,
                                    time)
        meshcat.SetTransform(f"{ROOT}/robot/gripper{i}", RigidTransform([*tips[i], FRONT]), *at)


def replay_frames(duration: float, speedup: float = 4.0,
                  frames_per_second: float = 20.0) -> int:
    """The frames of a replay of a climb of `duration` s: one every `speedup /
    frames_per_second` s of the climb, at most MAX_REPLAY_FRAMES (a long climb's frames are
    spread evenly over it: its replay plays as long, less smoothly)."""
    return min(natural_frames(duration, speedup, frames_per_second), MAX_REPLAY_FRAMES)


def natural_frames(duration: float, speedup: float = 4.0,
                   frames_per_second: float = 20.0) -> int:
    """A replay's frames without MAX_REPLAY_FRAMES (one every `speedup / frames_per_second` s
    of the climb)."""
    return math.floor(duration * frames_per_second / speedup + 1e-9) + 1


def animate(meshcat: Meshcat, record: SimulationRecord, frames_per_second: float = 20.0,
            speedup: float = 4.0) -> int:
    """Replay `record` as a Meshcat animation (played `speedup` times faster than simulated
    time, MIN_SPEEDUP at least) of at most MAX_REPLAY_FRAMES frames (`replay_frames`);
    returns the number of frames. Call `draw_scenario` first for the cave."""
    if not MIN_SPEEDUP <= speedup < math.inf:
        raise ValueError(f"speedup must be {MIN_SPEEDUP:g} or more and finite, got {speedup:g}")
    _robot_objects(meshcat, record.plan.scenario)
    # The animation only moves the robot once it plays: stand it at its start meanwhile.
    _set_robot(meshcat, record, 0, None)
    meshcat.StartRecording(frames_per_second, False)
    period = speedup / frames_per_second  # simulated seconds per frame
    frames = replay_frames(float(record.times[-1]), speedup, frames_per_second)
    if frames >= len(record.times):  # a frame for every sample: no grid of frame times (at
        samples = np.arange(len(record.times))  # speedup 1e-300 it asked 1e304 of them)
    else:
        grid = np.arange(frames) * period
        if frames < natural_frames(float(record.times[-1]), speedup, frames_per_second):
            # a long climb: sparser frames, evenly over it
            grid = np.linspace(0.0, float(record.times[-1]), frames)
        samples = np.unique(np.searchsorted(record.times, grid))
        samples = samples[samples < len(record.times)]
    for s in samples:  # at its own time: samples may be sparser than frames
        _set_robot(meshcat, record, int(s), float(record.times[s]) / speedup)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    return len(samples)


def view_bounds(scn: Scenario) -> tuple[float, float, float, float]:
    """xmin, xmax, ymin, ymax of the cave (rock, anchors and goal) with a small margin."""
    goal = np.asarray(scn.goal_position, dtype=float)
    pts = np.vstack([*scn.walls, scn.anchor_positions, goal - scn.goal_tolerance,
                     goal + scn.goal_tolerance])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = max(MIN_MARGIN, MARGIN * float(np.max(hi - lo)))
    return float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad)


def view_from_front(meshcat: Meshcat, bounds: tuple[float, float, float, float]) -> None:
    """An orthographic camera on +z looking down at the x-y plane (x right, y up) that frames
    `bounds` = (xmin, xmax, ymin, ymax).

    The viewer's orbit controls turn the camera towards their target, the world origin, on
    every render, whatever orientation it was given (with y up): a camera below the plane (on
    -z) shows the scene mirrored (x to the left) and one off the z axis tilts it. So the camera
    sits on the +z axis, and the bounds, which are in its frame (x right, y up, centred on the
    axis), move the view over the cave.
    """
    # Set2dRenderMode's camera frame C: it looks along +Cy with +Cz up, here Cx = x, Cy = -z,
    # Cz = y.
    R_WC = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]))
    meshcat.Set2dRenderMode(RigidTransform(R_WC, [0.0, 0.0, CAMERA_HEIGHT]), *bounds)


def show_scenario(meshcat: Meshcat, scn: Scenario) -> None:
    """The cave alone (what was shown before cleared), seen as in the 2-D figures (x right,
    y up)."""
    meshcat.Delete(ROOT)
    meshcat.DeleteRecording()
    draw_scenario(meshcat, scn)
    view_from_front(meshcat, view_bounds(scn))
    # Flat colours, as in the 2-D figures: only the ambient light (it does not depend on the
    # faces' directions).
    for light in ("SpotLight", "PointLightNegativeX", "PointLightPositiveX", "FillLight"):
        meshcat.SetProperty(f"/Lights/{light}/<object>", "intensity", 0.0)
    meshcat.SetProperty("/Lights/AmbientLight/<object>", "intensity", AMBIENT)


def show_climb(meshcat: Meshcat, record: SimulationRecord, speedup: float = 4.0) -> int:
    """The cave, the robot and the animated climb, seen as in the 2-D figures (x right, y up)."""
    show_scenario(meshcat, record.plan.scenario)
    return animate(meshcat, record, speedup=speedup)


# Drake's viewer keeps an orthographic camera's left, bottom and top edges when the window is
# sized and moves only its right edge with the window's aspect ratio, which crops a scene wider
# than the window or pads it on the right. This fits the box the camera was given, centred,
# into the window instead (and again on every resize).
_FIT_ORTHOGRAPHIC_CAMERA = """
    viewer.set_3d_pane_size = function (width, height) {  // rbp: fit the orthographic box
      if (width === undefined) width = this.dom_element.offsetWidth;
      if (height === undefined) height = this.dom_element.offsetHeight;
      const camera = this.camera;
      if (camera.isOrthographicCamera) {
        const box = camera.userData.rbp_box || (camera.userData.rbp_box = {
          left: camera.left, right: camera.right, bottom: camera.bottom, top: camera.top});
        const cx = 0.5 * (box.left + box.right), cy = 0.5 * (box.bottom + box.top);
        const aspect = width / Math.max(height, 1);
        let hw = 0.5 * (box.right - box.left), hh = 0.5 * (box.top - box.bottom);
        if (hw < hh * aspect) { hw = hh * aspect; } else { hh = hw / aspect; }
        camera.left = cx - hw; camera.right = cx + hw;
        camera.bottom = cy - hh; camera.top = cy + hh;
      } else {
        camera.aspect = width / height;
      }
      camera.updateProjectionMatrix();
      this.renderer.setSize(width, height);
      this.set_dirty();
    };
"""
_VIEWER_CREATED = 'var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));'
FIT_MARKER = "rbp: fit the orthographic box"


def fit_camera_script(html: str) -> str:
    """`html` (from `Meshcat.StaticHtml`) with the camera fitted to the window (see above);
    unchanged if the page does not create its viewer as expected."""
    at = html.find(_VIEWER_CREATED)
    if at < 0:
        return html
    at += len(_VIEWER_CREATED)
    return html[:at] + _FIT_ORTHOGRAPHIC_CAMERA + html[at:]


def save_html(meshcat: Meshcat, path: str | Path) -> Path:
    """The scene and its animation as one self-contained HTML file, written atomically; the
    page fits the scene into the browser window (`fit_camera_script`)."""
    return atomic_write_text(path, fit_camera_script(meshcat.StaticHtml()))
