"""`rbp scenario import` of the shipped scans end to end: the lava-tube mesh and its point
cloud become scenarios that `rbp scenario check` accepts, climbing most of the tube; a plane
that misses the scan is refused in one line; the mesh's cave is planned from Python."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("trimesh", reason="the optional extra 'import' (trimesh) is missing")
pytest.importorskip("shapely", reason="the optional extra 'import' (shapely) is missing")

from rb_drake.scenario import load_scenario
from rb_drake.terrain.examples import CLOUD_FILE, MESH_FILE, TubeDesign
from tests.cli_helpers import run_rbp

SCANS = {"mesh": MESH_FILE, "cloud": CLOUD_FILE}
DESIGN = TubeDesign()
# The start is looked for 1.5 m above the lowest anchor (the floor) and the goal is the highest
# place with 0.5 m of rock above the upper booms' anchors: a climb of the tube's height less
# about 2 m. A section that lost part of the cave (the cloud's outline leaking through its
# walls) leaves less or nothing.
MIN_CLIMB = DESIGN.height - 2.0  # m


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


def test_mesh_import_is_planned_from_python() -> None:
    """rbp.import_scenario then rbp.plan (footsteps only, about 6 s): a route to the goal that
    the verifier accepts."""
    import rbp

    scn = rbp.import_scenario(MESH_FILE)
    plan = rbp.plan(scn, footsteps_only=True)
    assert plan.success, f"no route up the imported mesh: {plan.reason}"
    assert plan.regrasps > 0, "a climb of metres takes regrasps"
    assert rbp.check(plan, scn) == [], rbp.check(plan, scn)
