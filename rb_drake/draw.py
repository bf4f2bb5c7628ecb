"""Pictures of caves and of the robot in them (matplotlib).

Rock is brown; each anchor is a dot with a short black line along its normal (psi = 0) and a
pale half-ellipse glyph: the mean limit mu(psi) drawn in every pull direction, so a big glyph is
a strong grasp and a flat one is weak sideways. Booms are coloured by their grasp's probability
of holding, on a 'nines' scale (0.9, 0.99, 0.999, ...): green holds, red is at risk.
"""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from rb_drake import geometry, grasp
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

ROCK = "#8c6d4f"
GLYPH_SCALE = 0.006  # m of glyph per N of mean limit
NINES = Normalize(vmin=1.0, vmax=5.0)  # colour scale in -log10(1 - P)
CMAP = matplotlib.colormaps["RdYlGn"]


def new_figure(**kwargs) -> Figure:
    """A figure drawn by Agg, outside pyplot: pyplot's import (0.1 s) and its registry of open
    figures are not needed to save a picture, and nothing has to close it. Jupyter still shows
    it (IPython's inline backend formats any Figure)."""
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def nines(p: npt.ArrayLike) -> np.ndarray:
    """-log10(1 - P): 1 for 0.9, 2 for 0.99, ..."""
    return -np.log10(np.clip(1.0 - np.asarray(p, dtype=float), 1e-12, 1.0))


def format_prob(p: float) -> str:
    """0.9731 as is; 0.99999963 as '1 - 3.7e-07', so that near-certain grasps stay distinct."""
    return f"{p:.4f}" if p < 0.9999 else f"1 - {1.0 - p:.1e}"


def prob_colour(p: float):
    return CMAP(NINES(nines(p)))


def draw_cave(ax, scn: Scenario, highlight: tuple[str | None, ...] = (),
              glyphs: bool = True) -> None:
    """Walls, anchors with normals and limit-surface glyphs, and the goal region.

    One collection per kind of thing (walls, glyphs, normals, anchor dots), not one artist per
    anchor: a snapshot figure draws the cave a dozen times."""
    ax.add_collection(PolyCollection(list(scn.walls), closed=True, facecolors=ROCK,
                                     edgecolors="#5a4330", linewidths=0.8, zorder=1))
    held = set(a for a in highlight if a is not None)
    if scn.anchors:
        p, n = scn.anchor_positions, scn.anchor_normals
        is_held = np.array([a.id in held for a in scn.anchors])
        if glyphs:
            psi = np.linspace(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3, 41)
            polys = []
            for a, pos, normal in zip(scn.anchors, p, n, strict=True):
                base = math.atan2(normal[1], normal[0])
                mu = grasp.mean_limit(psi, a.f_normal, a.f_lateral) * GLYPH_SCALE
                pts = pos + mu[:, None] * np.stack([np.cos(base + psi), np.sin(base + psi)],
                                                   axis=1)
                polys.append(np.vstack([pos, pts]))
            ax.add_collection(PolyCollection(polys, closed=True, facecolors="#9ecae1",
                                             edgecolors="#4292c6", linewidths=0.5, alpha=0.55,
                                             zorder=2))
        segments = np.stack([p, p + 0.25 * n], axis=1)
        # LineCollection takes an (n, 2, 2) array, where matplotlib's stub says a Sequence
        ax.add_collection(LineCollection(segments,  # type: ignore[arg-type]
                                         colors=np.where(is_held, "red", "black"),
                                         linewidths=np.where(is_held, 1.6, 0.9), zorder=3))
        for mask, colour in ((~is_held, "black"), (is_held, "red")):
            if mask.any():
                ax.plot(p[mask, 0], p[mask, 1], "o", ls="none", color=colour, ms=3, zorder=4)
    gx, gy = scn.goal_position
    ax.add_patch(Circle((gx, gy), scn.goal_tolerance, facecolor="none", edgecolor="#2171b5",
                        ls="--", lw=1.2, zorder=2))
    ax.plot(gx, gy, "*", color="#2171b5", ms=12, zorder=5, label="goal")


def draw_robot(ax, robot: RobotParams, pose: np.ndarray, stance: Stance,
               probabilities: np.ndarray | None = None, free_tip: np.ndarray | None = None,
               alpha: float = 1.0, label_booms: bool = True) -> None:
    """The body and its booms; attached booms coloured by grasp probability (if given)."""
    pose = np.asarray(pose, dtype=float)
    corners = geometry.body_corners(robot, pose)[0]
    ax.add_patch(Polygon(corners, closed=True, facecolor="#525252", edgecolor="black",
                         alpha=alpha, zorder=6))
    sh = geometry.shoulder_positions(robot, pose)[0]
    booms, tips, colours, styles = [], [], [], []
    for i in range(NUM_BOOMS):
        if stance.attached[i]:
            tip = stance.positions[i]
            colour = prob_colour(probabilities[i]) if probabilities is not None else "#3182bd"
            ls = "-"
        elif free_tip is not None:
            tip, colour, ls = np.asarray(free_tip), "#636363", ":"
        else:
            continue
        booms.append(i)
        tips.append(tip)
        colours.append(colour)
        styles.append(ls)
    if not booms:
        return
    tips_arr = np.array(tips, dtype=float)
    segments = np.stack([sh[booms], tips_arr], axis=1)
    ax.add_collection(LineCollection(segments,  # type: ignore[arg-type]  # as in draw_cave
                                     colors=colours, linewidths=2.6, linestyles=styles,
                                     alpha=alpha, zorder=7, capstyle="round"))
    ax.scatter(tips_arr[:, 0], tips_arr[:, 1], marker="s", s=16, c=colours, alpha=alpha,
               zorder=8, linewidths=0)
    if label_booms:
        for i, tip in zip(booms, tips_arr, strict=True):
            mid = 0.5 * (sh[i] + tip)
            text = f"{i}"
            if probabilities is not None and stance.attached[i]:
                text += f": P = {format_prob(probabilities[i])}"
            ax.annotate(text, mid, fontsize=7, zorder=9, ha="center", va="center",
                        bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))


def add_probability_colourbar(fig, ax) -> None:
    sm = ScalarMappable(norm=NINES, cmap=CMAP)
    bar = fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02)
    ticks = np.arange(1, 6)
    bar.set_ticks(ticks)
    bar.set_ticklabels([f"{1 - 10.0**-k:.{k}f}" for k in ticks])
    bar.set_label("grasp probability of holding")


def frame_axes(ax, scn: Scenario, margin: float = 0.3) -> None:
    """Limit the view to the free space of the cave (rock beyond it is cropped)."""
    pts = np.vstack([scn.anchor_positions, [scn.start_pose[:2]], [scn.goal_position]])
    lo, hi = pts.min(axis=0) - margin - 0.5, pts.max(axis=0) + margin + 0.5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def scenario_figure(scn: Scenario):
    """The cave with the robot in its start stance, booms coloured by grasp probability."""
    from rb_drake.feasibility import check_poses, diagnose_pose

    stance = scn.stance(scn.start_stance)
    pose = np.array(scn.start_pose)
    check = check_poses(scn, stance, pose)
    probs = np.exp(check.allocation.log_probs[0])
    extent = np.ptp(np.vstack([scn.anchor_positions, [scn.goal_position]]), axis=0) + 1.6
    height = 8.0
    width = float(np.clip(height * extent[0] / extent[1], 5.0, 16.0)) + 1.5
    fig = new_figure(figsize=(width, height))
    ax = fig.subplots()
    draw_cave(ax, scn, highlight=stance.ids)
    draw_robot(ax, scn.robot, pose, stance, probs)
    frame_axes(ax, scn)
    add_probability_colourbar(fig, ax)
    if check.feasible[0]:
        status = (f"start stance P = {format_prob(check.probability[0])}"
                  f"  (r = log P = {check.allocation.robustness[0]:.2e})")
    else:
        status = "start pose infeasible: " + "; ".join(diagnose_pose(scn, stance, pose))
    ax.set_title(f"{scn.name}: {len(scn.anchors)} anchors, gravity "
                 f"{np.linalg.norm(scn.gravity_vector):.2f} m/s²\n{status}", fontsize=10)
    fig.tight_layout()
    return fig
