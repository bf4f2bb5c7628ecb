"""A scan to a climb, in one picture: the shipped lava-tube mesh cut by the import's plane, the
cave `rbp scenario import` makes of the section (rock, anchors, the start stance, the goal),
and the footstep route `rbp plan --footsteps-only` finds up it.

    python -m experiments.terrain_import                  # docs/figures/terrain-import.png
    python -m experiments.terrain_import --scan rb_drake/data/terrain/lava_tube_cloud.ply \
        --seed 1 --out cloud.png

The same as, from the command line:

    rbp scenario import rb_drake/data/terrain/lava_tube.ply -o lava_tube.yaml
    rbp plan lava_tube.yaml -o climb.json --footsteps-only
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from experiments.arguments import OneLineParser, path_argument, seed_number

ROOT = Path(__file__).resolve().parents[1]
DOCS_FIGURE = ROOT / "docs" / "figures" / "terrain-import.png"
MESH = ROOT / "rb_drake" / "data" / "terrain" / "lava_tube.ply"
PATH_COLOUR = "#2171b5"


def climb_figure(scan: Path, scn: Any, plan: Any, out: Path) -> Path:
    """Three panels into `out`: the scan with the plane and the section's outline in 3D, the
    imported cave with the robot in its start stance, and the planned route (the body's path,
    its outline where each stance's move ends, the anchors held on the way, the robot at the
    end)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Polygon as MplPolygon
    from shapely.geometry import Polygon

    from planning.plan_model import plan_dict
    from rb_drake import draw, geometry
    from rb_drake.files import atomic_save_figure
    from rb_drake.terrain.mesh_figure import draw_scan

    data = plan_dict(plan)
    fig = draw.new_figure(figsize=(12.5, 7.2), layout="constrained")
    grid = fig.add_gridspec(1, 3, width_ratios=(1.5, 1.0, 1.0))
    rock = [Polygon(w) for w in scn.walls]
    draw_scan(fig.add_subplot(grid[0], projection="3d"), scan, rock, max_items=1500)

    start = scn.stance(scn.start_stance)
    ax = fig.add_subplot(grid[1])
    draw.draw_cave(ax, scn, highlight=tuple(scn.start_stance), glyphs=False)
    first = data["phases"][0]["steps"][0] if data["phases"] else None
    probs = None if first is None else np.array(
        [np.nan if p is None else p for p in first["p_grasp"]])
    draw.draw_robot(ax, scn.robot, np.array(scn.start_pose), start, probs, label_booms=False)
    draw.frame_axes(ax, scn)
    ax.set_title(f"the imported cave: {len(scn.walls)} rock polygons,\n{len(scn.anchors)} "
                 "anchors, the start stance, the goal", fontsize=9)

    ax = fig.add_subplot(grid[2])
    body = [p for p in data["phases"] if p["kind"] == "body"]
    held = tuple(sorted({a for p in body for a in p["stance"] if a is not None}))
    draw.draw_cave(ax, scn, highlight=held, glyphs=False)
    if data["success"]:
        path = np.array([s["pose"][:2] for p in data["phases"] for s in p["steps"]])
        ax.plot(path[:, 0], path[:, 1], "-", color=PATH_COLOUR, lw=1.2, zorder=5)
        for p in body:  # the body where each stance's move ends (the next boom lets go)
            corners = geometry.body_corners(scn.robot, np.array(p["steps"][-1]["pose"]))[0]
            ax.add_patch(MplPolygon(corners, closed=True, facecolor="none", lw=0.8,
                                    edgecolor=PATH_COLOUR, zorder=5))
        last = body[-1]
        pose = np.array(last["steps"][-1]["pose"])
        draw.draw_robot(ax, scn.robot, pose, scn.stance(tuple(last["stance"])),
                        np.array([np.nan if q is None else q
                                  for q in last["steps"][-1]["p_grasp"]]), label_booms=False)
        title = (f"the planned climb: {data['regrasps']} regrasps,\n"
                 f"p_path {data['p_path']:.3f}, p_min {data['p_min']:.3f}")
    else:
        title = f"no route: {data['reason']}"
    draw.frame_axes(ax, scn)
    ax.set_title(title, fontsize=9)
    handles = draw.cave_legend_handles(scn, glyphs=False)
    handles += [Line2D([], [], color=PATH_COLOUR, lw=1.2, label="the body's route"),
                MplPolygon([(0, 0)], closed=True, facecolor="none", edgecolor=PATH_COLOUR,
                           label="the body where each stance's move ends")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    return atomic_save_figure(fig, out, dpi=110)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scan", type=Path, default=MESH,
                        help="a mesh or point cloud (.stl, .obj, .ply; default the lava tube)")
    parser.add_argument("--seed", type=seed_number, default=0, help="the anchors' seed (default 0)")
    parser.add_argument("--out", type=path_argument, default=DOCS_FIGURE,
                        help="the picture to write")
    args = parser.parse_args(argv)

    # rbp.import_scenario and rbp.plan(footsteps_only=True), from below the command line's
    # layer (tests/test_layers.py)
    from planning.footsteps import plan_footsteps
    from planning.plan import build_plan
    from rb_drake.terrain.import_cave import ImportOptions, import_cave

    scn = import_cave(args.scan, ImportOptions(seed=args.seed))
    fp = plan_footsteps(scn)
    plan = build_plan(scn, fp, "rbp", {"footstep": fp.seconds, "total": fp.seconds})
    print(f"{scn.name}: {len(scn.anchors)} anchors, start {list(scn.start_pose)}, goal "
          f"{list(scn.goal_position)}; route: {plan.success}, {plan.regrasps} regrasps, "
          f"footsteps {plan.timing['footstep']:.2f} s")
    print(f"wrote {climb_figure(args.scan, scn, plan, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
