"""Procedural example scans: a small lava-tube-like vertical shaft, as a mesh and as a point
cloud sampled from its surface, for the mesh importer's tests, docs and figure.

`python -m rb_drake.terrain.examples` rewrites rb_drake/data/terrain/lava_tube.ply (the mesh)
and lava_tube_cloud.ply (the points); the same seed gives the same bytes.

The shaft (`TubeDesign`) is a closed tube, floor and ceiling capped so that a section is a
closed outline, of elliptic cross-section: `width` along world y, `depth` along world x. Its
axis stays at x = 0 and sways along y by `sway`; its width bulges by `bulge` (a fraction) with
height; the wall is displaced along the ellipse's radius by smooth noise of at most `noise`
plus per-vertex jitter of at most `jitter`. Cut by the default plane (normal world +x through
the centre), it looks like a generated shaft (rb_drake.generate): two rough walls about 1.7 m
apart, here also with a floor and a ceiling.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from rb_drake.files import atomic_write

DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "terrain"
MESH_FILE = DATA_DIR / "lava_tube.ply"
CLOUD_FILE = DATA_DIR / "lava_tube_cloud.ply"
SEED = 29


@dataclass(frozen=True)
class TubeDesign:
    width: float = 1.7      # m, along world y (what the default section shows)
    depth: float = 1.2      # m, along world x
    height: float = 5.0     # m, floor at z = 0
    sway: float = 0.2       # m, the axis's sideways (y) excursion
    bulge: float = 0.06     # the width's relative variation with height
    noise: float = 0.05     # m, most the smooth wall noise moves a wall
    jitter: float = 0.015   # m, most the per-vertex jitter moves a wall
    around: int = 48        # vertices around a ring
    rings: int = 51         # rings from floor to ceiling
    cloud_points: int = 12_000

    def axis_y(self, z: float | np.ndarray) -> Any:
        """World y of the tube's axis at height z (its x is 0)."""
        return self.sway * np.sin(2.0 * math.pi * np.asarray(z) / (1.6 * self.height) + 0.3)

    def width_at(self, z: float | np.ndarray) -> Any:
        """The designed width (along world y, through the axis) at height z, noise left out:
        the walls are within noise + jitter of it on each side."""
        return self.width * (1.0 + self.bulge * np.sin(2.0 * math.pi * np.asarray(z) / 2.5))

    def depth_at(self, z: float | np.ndarray) -> Any:
        """The designed depth (along world x) at height z, scaled as the width."""
        return self.depth / self.width * self.width_at(z)


def lava_tube_mesh(seed: int = SEED, design: TubeDesign = TubeDesign()) -> Any:
    """The shaft as a watertight trimesh.Trimesh; the same seed, the same mesh."""
    import trimesh

    rng = np.random.default_rng(seed)
    theta = np.linspace(0.0, 2.0 * math.pi, design.around, endpoint=False)
    z = np.linspace(0.0, design.height, design.rings)
    T, Z = np.meshgrid(theta, z)  # (rings, around)
    # Smooth noise: a few random harmonics around and along the tube, scaled to at most `noise`.
    terms = 10
    m = rng.integers(2, 9, terms)
    wavelength = rng.uniform(0.3, 2.0, terms)
    phase = rng.uniform(0.0, 2.0 * math.pi, (2, terms))
    coeff = rng.uniform(0.3, 1.0, terms)
    smooth = sum(coeff[k] * np.cos(m[k] * T + phase[0, k])
                 * np.cos(2.0 * math.pi * Z / wavelength[k] + phase[1, k]) for k in range(terms))
    offset = design.noise * smooth / coeff.sum()
    offset = offset + rng.uniform(-design.jitter, design.jitter, T.shape)
    half_w = design.width_at(Z) / 2.0 + offset
    half_d = design.depth_at(Z) / 2.0 + offset
    ring_vertices = np.stack([half_d * np.cos(T), design.axis_y(Z) + half_w * np.sin(T), Z],
                             axis=-1).reshape(-1, 3)
    bottom = np.array([[0.0, float(design.axis_y(0.0)), 0.0]])
    top = np.array([[0.0, float(design.axis_y(design.height)), design.height]])
    vertices = np.vstack([ring_vertices, bottom, top])
    a = design.around
    i = np.arange(design.rings - 1)[:, None] * a
    j = np.arange(a)[None, :]
    v00, v01 = i + j, i + (j + 1) % a
    v10, v11 = v00 + a, v01 + a
    sides = np.concatenate([np.stack([v00, v01, v11], -1).reshape(-1, 3),
                            np.stack([v00, v11, v10], -1).reshape(-1, 3)])
    b, t = len(vertices) - 2, len(vertices) - 1
    last = (design.rings - 1) * a
    floor = np.stack([np.full(a, b), (np.arange(a) + 1) % a, np.arange(a)], -1)
    ceiling = np.stack([np.full(a, t), last + np.arange(a), last + (np.arange(a) + 1) % a], -1)
    faces = np.concatenate([sides, floor, ceiling])
    mesh = trimesh.Trimesh(vertices=vertices.astype(np.float32).astype(float), faces=faces,
                           process=False)
    trimesh.repair.fix_normals(mesh)  # outward from the free space: into the rock
    return mesh


def lava_tube_cloud(mesh: Any, seed: int = SEED,
                    count: int = TubeDesign.cloud_points) -> np.ndarray:
    """`count` points uniform on the surface of `mesh` ((count, 3) float32); seeded."""
    rng = np.random.default_rng(seed + 1)
    tris = np.asarray(mesh.triangles, dtype=float)
    area = np.asarray(mesh.area_faces, dtype=float)
    face = rng.choice(len(tris), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tris[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    return points.astype(np.float32)


def example_bytes(seed: int = SEED, design: TubeDesign = TubeDesign()) -> tuple[bytes, bytes]:
    """The binary PLY files of the shaft's mesh and of its point cloud."""
    import trimesh

    mesh = lava_tube_mesh(seed, design)
    cloud = trimesh.PointCloud(lava_tube_cloud(mesh, seed, design.cloud_points))
    return mesh.export(file_type="ply"), cloud.export(file_type="ply")


def _writer(data: bytes) -> Callable[[IO[bytes]], object]:
    return lambda f: f.write(data)


def write_examples(mesh_path: Path = MESH_FILE, cloud_path: Path = CLOUD_FILE,
                   seed: int = SEED) -> tuple[Path, Path]:
    """Write the example mesh and point cloud (atomically); returns their paths."""
    mesh_bytes, cloud_bytes = example_bytes(seed)
    for path, data in ((mesh_path, mesh_bytes), (cloud_path, cloud_bytes)):
        atomic_write(path, _writer(data))
    return Path(mesh_path), Path(cloud_path)


if __name__ == "__main__":
    for written in write_examples():
        print(f"wrote {written} ({written.stat().st_size / 1024:.0f} kB)")
