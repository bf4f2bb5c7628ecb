"""A picture of a scan cut into a cave: the mesh (a subsample of its triangles) or the point
cloud in 3D with the cutting plane, beside the section's rock polygons in the plane's 2D frame.

`python -m rb_drake.terrain.mesh_figure` draws docs/figures/terrain-section.png from the bundled
lava tube (rb_drake/terrain/examples.py): the mesh's section, the point cloud's outline over it
(its resolution from its density). `experiments/terrain_import.py` draws the scan beside the
cave imported from it and a planned climb (docs/figures/terrain-import.png).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rb_drake.draw import ROCK, new_figure, title_name
from rb_drake.files import atomic_save_figure
from rb_drake.terrain.mesh_section import (
    DEFAULT_NORMAL,
    load_scan,
    plane_frame,
    section_polygons,
)

DOCS_FIGURE = Path(__file__).resolve().parents[2] / "docs" / "figures" / "terrain-section.png"


def section_figure(path: Path, out: Path, origin: tuple[float, float, float] | None = None,
                   normal: tuple[float, float, float] | None = None,
                   resolution: float | None = None,
                   tolerance: float = 0.02, compare: Path | None = None,
                   max_items: int = 2000, seed: int = 0) -> Path:
    """Draw the scan in `path` cut by the plane (section_polygons' arguments) into `out`
    (atomically; the format from its suffix). `compare`, another scan of the same cave, has
    its section's rock outlined (dashed) over the first's. At most `max_items` triangles or
    points are drawn in 3D (a seeded subsample). Returns `out`."""
    path = Path(path)
    rock = section_polygons(path, origin, normal, resolution, tolerance)
    fig = new_figure(figsize=(9.0, 6.0))
    draw_scan(fig.add_subplot(1, 2, 1, projection="3d"), path, rock, origin, normal,
              max_items, seed)

    ax = fig.add_subplot(1, 2, 2)
    for poly in rock:
        q = np.asarray(poly.exterior.coords)
        ax.fill(q[:, 0], q[:, 1], color=ROCK, alpha=0.9, linewidth=0.0)
    if compare is not None:
        for k, poly in enumerate(section_polygons(Path(compare), origin, normal, resolution,
                                                  tolerance)):
            q = np.asarray(poly.exterior.coords)
            ax.plot(q[:, 0], q[:, 1], "--", color="#1f5fa8", linewidth=1.0,
                    label=f"{Path(compare).name}" if k == 0 else None)
        ax.legend(loc="upper center", fontsize=8, framealpha=0.9)
    ax.set_aspect("equal")
    ax.set_xlabel("section x (m)")
    ax.set_ylabel("section y (m): up")
    ax.set_title(f"rock of the section ({len(rock)} polygons)", fontsize=9)
    fig.tight_layout()
    return atomic_save_figure(fig, out, dpi=110)


def draw_scan(ax3: Any, path: Path, rock: list[Any],
              origin: tuple[float, float, float] | None = None,
              normal: tuple[float, float, float] | None = None, max_items: int = 2000,
              seed: int = 0) -> None:
    """On the 3D axes `ax3`: the scan in `path` (at most `max_items` of its triangles or
    points, a seeded subsample), the plane (origin and normal as section_polygons takes them)
    over the extent of `rock` (the section's rock polygons, in the plane's 2D frame), and the
    free space's outline back in 3D."""
    import shapely
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    kind, scan = load_scan(Path(path))
    vertices = np.asarray(scan.vertices if kind == "mesh" else scan, dtype=float)
    o = (vertices.min(axis=0) + vertices.max(axis=0)) / 2.0 if origin is None else np.asarray(
        origin, dtype=float)
    x2, y2, _ = plane_frame(DEFAULT_NORMAL if normal is None else normal)
    rng = np.random.default_rng(seed)
    if kind == "mesh":
        tris = np.asarray(scan.triangles, dtype=float)
        pick = rng.choice(len(tris), size=min(max_items, len(tris)), replace=False)
        ax3.add_collection3d(Poly3DCollection(tris[pick], facecolor="#c8b49a",
                                              edgecolor="#8c6d4f", linewidth=0.2, alpha=0.35))
    else:
        pick = rng.choice(len(vertices), size=min(max_items, len(vertices)), replace=False)
        p = vertices[pick]
        ax3.scatter(p[:, 0], p[:, 1], p[:, 2], s=1.0, color=ROCK, alpha=0.6)
    minx, miny, maxx, maxy = _bounds(rock)
    corners = [o + a * x2 + b * y2 for a, b in ((minx, miny), (maxx, miny), (maxx, maxy),
                                                (minx, maxy))]
    ax3.add_collection3d(Poly3DCollection([corners], facecolor="#4a90d9", alpha=0.25,
                                          edgecolor="#1f5fa8"))
    for ring in shapely.union_all(rock).interiors:  # the free space's outline, back in 3D
        q = np.asarray(ring.coords)
        w = o + q[:, :1] * x2 + q[:, 1:] * y2
        ax3.plot(w[:, 0], w[:, 1], w[:, 2], color="#b22222", linewidth=0.8)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    span = np.maximum(hi - lo, 1e-3)
    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(lo[2], hi[2])
    ax3.set_box_aspect(tuple(span.tolist()))
    for axis in (ax3.xaxis, ax3.yaxis, ax3.zaxis):
        axis.set_major_locator(MaxNLocator(3))
    ax3.tick_params(labelsize=7)
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.set_title(f"{title_name(Path(path).name)}: "
                  f"{'mesh' if kind == 'mesh' else 'point cloud'} and the plane", fontsize=9,
                  parse_math=False)


def _bounds(polygons: list[Any]) -> tuple[float, float, float, float]:
    b = np.array([p.bounds for p in polygons])
    return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())


if __name__ == "__main__":
    from rb_drake.terrain.examples import CLOUD_FILE, MESH_FILE

    print(f"wrote {section_figure(MESH_FILE, DOCS_FIGURE, compare=CLOUD_FILE)}")
