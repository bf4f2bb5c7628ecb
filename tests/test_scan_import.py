"""`rbp scenario import` of the shipped scans end to end: the lava-tube mesh and its point
cloud become scenarios that `rbp scenario check` accepts, climbing most of the tube; a plane
that misses the scan is refused in one line; the mesh's cave is planned from Python."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("trimesh", reason="the optional extra 'import' (trimesh) is missing")
shapely = pytest.importorskip("shapely",
                              reason="the optional extra 'import' (shapely) is missing")

from rb_drake.scenario import load_scenario  # noqa: E402
from rb_drake.terrain.cave_from_rock import GOAL_HEADROOM, GOAL_TOLERANCE, START_RISE  # noqa: E402
from rb_drake.terrain.examples import CLOUD_FILE, MESH_FILE, TubeDesign  # noqa: E402
from tests.cli_helpers import run_rbp  # noqa: E402

SCANS = {"mesh": MESH_FILE, "cloud": CLOUD_FILE}
DESIGN = TubeDesign()
# The start is looked for START_RISE above the lowest anchor (the floor's) and the goal is the
# highest place whose upper booms reach anchors GOAL_HEADROOM above it (the ceiling's): a climb
# of the tube's height less 2 m, less a grid step or two (2.8 m today); a goal tolerance more
# is allowed. A section that lost part of the cave (the cloud's outline leaking through its
# walls) leaves less or nothing.
MIN_CLIMB = DESIGN.height - START_RISE - GOAL_HEADROOM - GOAL_TOLERANCE  # m


@pytest.mark.parametrize("kind", SCANS)
def test_shipped_scan_imports_to_a_checked_scenario(kind: str, tmp_path: Path) -> None:
    out = tmp_path / f"{kind}.yaml"
    result = run_rbp("scenario", "import", str(SCANS[kind]), "-o", str(out), cwd=tmp_path)
    assert result.returncode == 0, f"{kind}: exit {result.returncode}: {result.stderr}"
    assert result.stderr == "", f"{kind}: stderr {result.stderr!r}"
    check = run_rbp("scenario", "check", str(out), cwd=tmp_path)
    assert check.returncode == 0, f"{kind}: scenario check exit {check.returncode}: " \
                                  f"{check.stderr}"
    assert f"{out}: ok: " in check.stdout, check.stdout
    scn = load_scenario(out)
    frame = shapely.union_all([shapely.Polygon(w) for w in scn.walls]).exterior
    on_frame = [a.id for a in scn.anchors if frame.distance(shapely.Point(a.position)) < 0.1]
    assert not on_frame, f"{kind}: anchors on the section's frame, no rock surface: {on_frame}"
    climb = scn.goal_position[1] - scn.start_pose[1]
    assert climb >= MIN_CLIMB, \
        f"{kind}: the goal is {climb:.2f} m above the start, at least {MIN_CLIMB} m expected"


def test_plane_that_misses_the_mesh_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "cave.yaml"
    result = run_rbp("scenario", "import", str(MESH_FILE), "-o", str(out),
                     "--plane-origin", "100", "0", "0", cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, f"exit {result.returncode}: {result.stderr!r}"
    assert len(lines) == 1, f"{len(lines)} lines on stderr: {result.stderr!r}"
    assert lines[0].startswith(f"error: {MESH_FILE}: plane: "), lines[0]
    assert "does not cut the mesh" in lines[0], lines[0]
    assert not out.exists(), "a scenario was written"


def test_mesh_import_is_planned_from_python(tmp_path: Path) -> None:
    """rbp.import_scenario then rbp.plan (footsteps only, about 6 s): a route to the goal that
    the verifier accepts, drawn as the README's figure draws it."""
    import rbp
    from experiments.terrain_import import climb_figure

    scn = rbp.import_scenario(MESH_FILE)
    plan = rbp.plan(scn, footsteps_only=True)
    assert plan.success, f"no route up the imported mesh: {plan.reason}"
    assert plan.regrasps > 0, "a climb of metres takes regrasps"
    assert rbp.check(plan, scn) == [], rbp.check(plan, scn)
    out = climb_figure(MESH_FILE, scn, plan, tmp_path / "climb.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", "no PNG written"
    assert not list(tmp_path.glob(".*.tmp")), "a temporary file was left behind"
