"""Hostile scans for `rbp scenario import` (rb_drake/terrain/scan_bytes.py, mesh_section.py):
what trimesh's readers let through or choke on is refused in one line naming the line or
element, with exit 2 and no warning before it."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh", reason="the optional extra 'import' (trimesh) is missing")
pytest.importorskip("shapely", reason="the optional extra 'import' (shapely) is missing")

from rb_drake.terrain.examples import CLOUD_FILE, MESH_FILE  # noqa: E402
from rb_drake.terrain.scan_bytes import ScanBytesError, check_scan  # noqa: E402
from rbp.cli import main  # noqa: E402

PLY_XYZ = b"property float x\nproperty float y\nproperty float z\n"


def refused(path: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> str:
    """The one `error:` line of importing `path`, which must exit 2."""
    assert main(["scenario", "import", str(path), "-o", str(path.with_suffix(".yaml")),
                 *extra]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: "), lines
    return lines[0]


def tube() -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=1.0, height=5.0, sections=24)


@pytest.mark.parametrize("text, line", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 2\n", "line 5: 'v 1 2'"),  # was a traceback
    ("v 0 0\nv 1 0\nv 0 1\n", "line 1: 'v 0 0'"),                          # all 2D
    ("# a cloud\r\nv 1", "line 2: 'v 1'"),                                  # 1D
])
def test_obj_vertex_of_fewer_than_3_coordinates(tmp_path, capsys, text, line):
    path = tmp_path / "cloud.obj"
    path.write_bytes(text.encode())
    assert f"mesh: {line} has fewer than 3 coordinates" in refused(path, capsys)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_binary_stl_non_finite_vertex(tmp_path, capsys, bad):
    """trimesh dropped the NaN triangle and the import succeeded; inf was 'an open curve'."""
    data = bytearray(tube().export(file_type="stl"))
    data[-14:-10] = np.float32(bad).tobytes()  # the last triangle's last x
    path = tmp_path / "tube.stl"
    path.write_bytes(bytes(data))
    message = refused(path, capsys)
    assert "mesh: triangle 96 has a non-finite vertex coordinate" in message, message


@pytest.mark.parametrize("suffix, line", [("stl", "vertex nan 0 0"), ("obj", "v 0 inf 0")])
def test_text_non_finite_vertex_is_named(tmp_path, capsys, suffix, line):
    text = tube().export(file_type="stl_ascii" if suffix == "stl" else "obj")
    lines = text.splitlines()
    at = max(i for i, s in enumerate(lines) if s.strip().split()[:1] == [line.split()[0]])
    lines[at] = line
    path = tmp_path / f"tube.{suffix}"
    path.write_text("\n".join(lines) + "\n")
    assert f"mesh: line {at + 1}: '{line}' has a non-finite coordinate" in refused(path, capsys)


def binary_ply(vertices: np.ndarray, faces: np.ndarray, counts: np.ndarray) -> bytes:
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(vertices) + PLY_XYZ
            + b"element face %d\nproperty list uchar int vertex_indices\nend_header\n"
            % len(faces))
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rows["n"], rows["i"] = counts, faces
    return head + vertices.astype("<f4").tobytes() + rows.tobytes()


@pytest.mark.parametrize("count, index, reason", [
    (255, 0, "face 96 has a list count of 255, not 3"),
    (0, 0, "face 96 has a list count of 0, not 3"),
    (3, -7, "face 96 has vertex indices"),
    (3, 10**6, "face 96 has vertex indices"),
])
def test_binary_ply_corrupt_faces(tmp_path, capsys, count, index, reason):
    """trimesh read every list as 3 indices and wrapped a negative one: accepted silently."""
    mesh = tube()
    counts = np.full(len(mesh.faces), 3)
    counts[-1] = count
    faces = mesh.faces.copy()
    faces[-1, 2] = index if index else faces[-1, 2]
    path = tmp_path / "tube.ply"
    path.write_bytes(binary_ply(mesh.vertices, faces, counts))
    assert f"mesh: {reason}" in refused(path, capsys)
    path.write_bytes(binary_ply(mesh.vertices, mesh.faces, np.full(len(mesh.faces), 3)))
    assert check_scan(path.read_bytes(), ".ply") is None  # the same mesh, intact: trimesh's


def ascii_cloud(n: int, last: bytes) -> bytes:
    points = np.random.default_rng(0).uniform(-1.0, 1.0, (n - 1, 3))
    body = "".join(f"{x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in points).encode()
    return (b"ply\nformat ascii 1.0\nelement vertex %d\n" % n + PLY_XYZ + b"end_header\n"
            + body + last)


def problem(data: bytes) -> str:
    with pytest.raises(ScanBytesError) as info:
        check_scan(data, ".ply")
    return str(info.value)


@pytest.mark.parametrize("last", [b"1.0 2.0\n", b"1.0 2.0 3.0 4.0"])
def test_ascii_ply_cloud_bad_line_named_in_bounded_memory(last: bytes) -> None:
    """A short last line took numpy's wording, 4.8 s and 926 MB for 22 MB; now numpy's
    C parser, the line named, in memory a small multiple of the file's."""
    data = ascii_cloud(100_000, last)
    tracemalloc.start()
    try:
        message = problem(data)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    words = len(last.split())
    assert message == (f"line 100,007: {last.strip().decode()!r} (vertex 100,000) holds {words} "
                       "value(s), not 3"), message
    assert peak < 4 * len(data), f"{peak / 1e6:.1f} MB for a {len(data) / 1e6:.1f} MB cloud"
    assert "(vertex 10) has a non-finite coordinate" in problem(ascii_cloud(10, b"nan 0 0\n"))
    assert "line 17: '0 zero 0' holds a value that is not a number" in problem(
        ascii_cloud(10, b"0 zero 0\n"))
    assert "line 18: 'the end' holds a value" in problem(ascii_cloud(10, b"0 0 0\nthe end"))
    assert "holds 9 element lines, not the header's 10" in problem(ascii_cloud(10, b""))


def test_ascii_ply_cloud_reads_as_trimesh_does(tmp_path: Path) -> None:
    """The points read without trimesh are trimesh's, bit for bit (float32 properties: each
    number parsed as float64, then cast), so imports are unchanged."""
    data = ascii_cloud(1_000, b"0.1 0.2 0.3\n4 5\n")  # numbers after the vertices: ignored
    path = tmp_path / "cloud.ply"
    path.write_bytes(data)
    read = check_scan(data, ".ply")
    assert read is not None and read[1] is None and read[0].dtype == np.float64
    assert np.array_equal(read[0], trimesh.load(path).vertices)


def test_ascii_ply_mesh_reads_as_trimesh_does(tmp_path: Path, capsys) -> None:
    """An ASCII PLY mesh (18 MB of memory a MB in trimesh's reader) read in C makes trimesh's
    mesh; a face that is not 3 indices of existing vertices is named."""
    path = tmp_path / "tube.ply"
    path.write_bytes(tube().export(file_type="ply", encoding="ascii"))
    read = check_scan(path.read_bytes(), ".ply")
    assert read is not None and read[1] is not None
    mine, theirs = trimesh.Trimesh(vertices=read[0], faces=read[1]), trimesh.load(path)
    assert np.array_equal(mine.vertices, theirs.vertices)
    assert np.array_equal(mine.faces, theirs.faces)
    text = path.read_text().splitlines()
    for line, reason in (("4 0 1 2 3", "(face 96) holds 5 value(s), not 4"),
                         ("3 0 1 99", "(face 96) is not 3 indices of the 50 vertices")):
        path.write_text("\n".join([*text[:-1], line]) + "\n")
        assert f"line {len(text)}: '{line}' {reason}" in refused(path, capsys)


def test_the_bundled_scans_pass_the_byte_checks() -> None:
    for path in (MESH_FILE, CLOUD_FILE):
        assert check_scan(Path(path).read_bytes(), ".ply") is None  # binary: trimesh reads


@pytest.mark.parametrize("flags", [["--scale", "1e300"], ["--scale", "1e150"],
                                   ["--unit", "ft", "--scale", "1e5"]])
def test_scan_coordinates_checked_after_scaling(tmp_path, capsys, flags):
    """As a drawing's: before any geometry (shapely warned of overflows at 1e300)."""
    path = tmp_path / "tube.ply"
    path.write_bytes(Path(MESH_FILE).read_bytes())
    message = refused(path, capsys, *flags)
    assert message.endswith("mesh: a coordinate beyond 10000 m once scaled; check --unit and "
                            "--scale"), message


def test_stl_refused_before_trimesh_builds_arrays(tmp_path, capsys) -> None:
    """A far coordinate in a binary STL (300 MB for 16 MB in trimesh's arrays) and an
    ASCII STL without a `vertex` (32 MB of zeros: 202 MB) are refused from the bytes."""
    data = bytearray(tube().export(file_type="stl"))
    data[-14:-10] = np.float32(1e8).tobytes()
    path = tmp_path / "far.stl"
    path.write_bytes(bytes(data))
    assert "mesh: has a coordinate beyond 1e+07 (in the file's unit)" in refused(path, capsys)
    path.write_bytes(bytes(1000))
    assert "mesh: holds no triangles or points" in refused(path, capsys)
