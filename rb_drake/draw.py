"""Pictures of caves and of the robot in them (matplotlib).

Rock is brown; each anchor is a dot with a short black line along its normal (psi = 0) and a
pale half-ellipse glyph: the mean limit mu(psi) drawn in every pull direction, so a big glyph is
a strong grasp and a flat one is weak sideways. Booms are coloured by their grasp's probability
of holding, on a 'nines' scale (0.9, 0.99, 0.999, ...): green holds, red is at risk.
"""

from __future__ import annotations

import math
import unicodedata
import warnings

import matplotlib
import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon

from rb_drake import geometry, grasp
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance

ROCK = "#8c6d4f"
TITLE_NAME = 80  # characters of a scenario's name in a picture's title


# A name in a script the font lacks (洞窟, an emoji) is drawn as boxes; matplotlib's warning
# about each missing glyph was printed on stderr of an accepted run.
warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from font", category=UserWarning)


def title_name(name: str) -> str:
    """`name` for a title: its first TITLE_NAME characters, with an ellipsis if cut, control
    characters (tab, CR, newline) as spaces. Titles holding user text are drawn with
    `parse_math=False`: `$x^{$` in a name ended every picture in mathtext's traceback."""
    name = "".join(" " if unicodedata.category(c)[0] == "C" else c for c in name)
    return name if len(name) <= TITLE_NAME else name[:TITLE_NAME - 1] + "…"


def plain_label(text: str) -> str:
    """User text (an anchor id) for a legend label, which cannot turn mathtext off: `$` escaped,
    control characters as spaces."""
    return title_name(text).replace("$", r"\$")

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


def format_prob(p: float, log_p: float | None = None) -> str:
    """0.9731 as is; 0.99999963 as '1 - 3.7e-07', so that near-certain grasps stay distinct.
    Given log P (`log_p`), 1 - P comes from it (-expm1), exact where 1 - P itself rounds to
    0; a P that is 1 to double precision reads '1 - <1e-16', never '1 - 0.0e+00'."""
    if not p >= 0.9999:  # nan too
        return f"{p:.4f}"
    failure = -math.expm1(log_p) if log_p is not None else 1.0 - p
    return f"1 - {failure:.1e}" if failure > 0.0 else "1 - <1e-16"


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


def cave_legend_handles(scn: Scenario, glyphs: bool = True, held: bool = True) -> list:
    """Legend entries for what draw_cave draws: anchors and their normals (red: held by the
    stance drawn), the limit glyphs, the goal and its tolerance."""
    from matplotlib.patches import Patch

    handles: list = [
        Line2D([], [], color="black", marker="o", ms=3, lw=0.9,
               label="anchor; its line: the wall's normal (0.25 m)"),
    ]
    if held:
        handles.append(Line2D([], [], color="red", marker="o", ms=3, lw=1.6,
                              label="anchor held by a boom (its normal in red)"))
    if glyphs:
        handles.append(Patch(facecolor="#9ecae1", edgecolor="#4292c6", alpha=0.55,
                             label=f"grasp limit glyph: mean limit per pull direction "
                                   f"({GLYPH_SCALE * 1000:g} mm per N)"))
    handles.append(Line2D([], [], color="#2171b5", marker="*", ms=10, ls="--", lw=1.2,
                          label=f"goal, within {scn.goal_tolerance:g} m (dashed)"))
    return handles


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
                text += f": P = {format_prob(float(probabilities[i]))}"
            ax.annotate(text, mid, fontsize=7, zorder=9, ha="center", va="center",
                        bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))


def add_probability_colourbar(fig, ax, cax=None):
    """The grasp probability's colour scale beside `ax` (or in `cax`, if given)."""
    sm = ScalarMappable(norm=NINES, cmap=CMAP)
    bar = (fig.colorbar(sm, cax=cax) if cax is not None
           else fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02))
    ticks = np.arange(1, 6)
    bar.set_ticks(ticks)
    bar.set_ticklabels([f"{1 - 10.0**-k:.{k}f}" for k in ticks])
    bar.set_label("grasp probability of holding")
    return bar


def frame_axes(ax, scn: Scenario, margin: float = 0.3) -> None:
    """Limit the view to the free space of the cave (rock beyond it is cropped)."""
    pts = np.vstack([scn.anchor_positions, [scn.start_pose[:2]], [scn.goal_position]])
    lo, hi = pts.min(axis=0) - margin - 0.5, pts.max(axis=0) + margin + 0.5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    _even_ticks(ax, hi - lo)


def _nice_step(span: float, below: bool = False) -> float:
    """The least of 1, 2, 5 x 10^k at or above `span` (`below`: the most at or below it)."""
    base = 10.0 ** math.floor(math.log10(span))
    if below:
        return max(f * base for f in (1.0, 2.0, 5.0) if f * base <= span * (1 + 1e-9))
    return next(f * base for f in (1.0, 2.0, 5.0, 10.0) if f * base >= span * (1 - 1e-9))


def _even_ticks(ax, extent: np.ndarray) -> None:
    """Ticks at most about eight along the longer axis and as far apart on paper along the
    shorter (the aspect is equal): matplotlib's own spaced a tall cave's few metres of width as
    finely as its height, and the labels ran into one another ("-10 1" for -1, 0, 1)."""
    from matplotlib.ticker import MultipleLocator

    long, short = float(max(extent)), float(min(extent))
    if not (math.isfinite(long) and long > 0):
        return
    step = _nice_step(long / 8.0)
    # the shorter axis: closer ticks where it is narrow, but not closer than 0.4 of the longer
    # axis's on paper, where labels of a few characters would touch
    short_step = step if short >= 2.5 * step else max(_nice_step(short / 2.5, below=True),
                                                       _nice_step(0.4 * step))
    x_step, y_step = (step, short_step) if extent[0] >= extent[1] else (short_step, step)
    ax.xaxis.set_major_locator(MultipleLocator(x_step))
    ax.yaxis.set_major_locator(MultipleLocator(y_step))


def scenario_figure(scn: Scenario):
    """The cave with the robot in its start stance, booms coloured by grasp probability, and a
    legend (below the cave) for the anchors, their normals, glyphs and the goal."""
    from rb_drake.feasibility import check_poses, diagnose_pose

    stance = scn.stance(scn.start_stance)
    pose = np.array(scn.start_pose)
    check = check_poses(scn, stance, pose)
    log_probs = check.allocation.log_probs[0]
    probs = np.exp(log_probs)
    extent = np.ptp(np.vstack([scn.anchor_positions, [scn.goal_position]]), axis=0) + 1.6
    height = 8.0
    width = float(np.clip(height * extent[0] / extent[1], 5.0, 16.0)) + 1.5
    fig = new_figure(figsize=(width, height + 1.2), layout="constrained")
    ax = fig.subplots()
    draw_cave(ax, scn, highlight=stance.ids)
    draw_robot(ax, scn.robot, pose, stance, probs)
    frame_axes(ax, scn)
    add_probability_colourbar(fig, ax)
    if check.feasible[0]:
        r = float(check.allocation.robustness[0])
        status = (f"start pose: P(all grasps hold) = {format_prob(float(np.exp(r)), r)}"
                  f"  (r = log P = {r:.2e})")
    else:
        status = "start pose infeasible: " + "; ".join(diagnose_pose(scn, stance, pose))
    ax.set_title(f"{title_name(scn.name)}: {len(scn.anchors)} anchors, gravity "
                 f"{np.linalg.norm(scn.gravity_vector):.2f} m/s²\n{status}", fontsize=10,
                 parse_math=False)
    handles = cave_legend_handles(scn)
    handles.append(Line2D(
        [], [], color=prob_colour(0.9999), lw=2.6,
        label="boom, coloured by its grasp's P (scale on the right); label: boom: P"))
    fig.legend(handles=handles, loc="outside lower center", fontsize=8,
               ncol=2 if width >= 10 else 1, frameon=False)
    return fig
