"""Pictures of plans: footstep snapshots (the paper's Fig. 5)."""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from planning.search_outcome import Stop
from rb_drake import draw
from rb_drake.errors import RbpInputError
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


def snapshots_figure(scn: Scenario, plan: dict[str, Any], max_panels: int = 12):
    """The robot at successive stances (one panel per body phase, drawn at the phase's last
    pose, where the next boom lets go), grasped anchors' normals in red, the body's path so
    far dotted blue, booms coloured by grasp probability. A panel's title gives P (all grasps
    hold) at its body move's first pose (for the first stance, the start pose: `rbp scenario
    show`'s P) and at the pose drawn; a legend below explains the marks."""
    body = [p for p in plan["phases"] if p["kind"] == "body"]
    picks: np.ndarray | list[int] = np.unique(
        np.linspace(0, len(body) - 1, min(max_panels, len(body))).round().astype(int)
    ) if body else []
    n = max(1, len(picks))
    cols = min(4, n)
    rows = math.ceil(n / cols)
    handles = draw.cave_legend_handles(scn, glyphs=not body)
    if not body:
        fig = draw.new_figure(figsize=(7.0, 6.0), layout="constrained")
        ax = fig.subplots()
        draw.draw_cave(ax, scn, highlight=tuple(scn.start_stance))
        draw.frame_axes(ax, scn)
        title = f"{draw.title_name(scn.name)} — {plan['planner']}: no plan ({plan['reason']})"
        ax.set_title("\n".join(textwrap.wrap(title, 70)), fontsize=8, parse_math=False)
        handles[1].set_label("anchor of the start stance (its normal in red)")
        fig.legend(handles=handles, loc="outside lower center", fontsize=7, frameon=False)
        return fig
    # Fixed margins in inches (a solved layout, constrained or tight, measures every tick
    # label of every panel: it would double the figure's time): the suptitle's lines above,
    # two-line panel titles, tick labels and the legend's rows below, the colour scale right.
    if plan["p_path"] is None:
        summary = f"no plan: {plan['reason']}"
    else:
        summary = (f"p_path = {plan['p_path']:.4f}, p_min = {plan['p_min']:.4f} (the lowest "
                   "P over every pose of the plan)")
    part = plan.get("partial")
    if part is not None:  # rbp plan --partial: no route reached the goal
        summary = (f"PARTIAL climb (no route reaches the goal): ends "
                   f"{part['goal_distance_m']:.2f} m from the goal (the start is "
                   f"{part['start_distance_m']:.2f} m), {summary}")
    width = max(4.0 * cols, 6.0) + 0.5 + 1.45
    name = draw.title_name(scn.name)
    lines = [f"{name} — {plan['planner']}: {plan['regrasps']} regrasps, {summary}",
             "each panel: the robot at the last pose of its stance's body move (where the next "
             "boom lets go); P (all grasps hold) at the move's first pose → at that pose"]
    heading = [w for line in lines for w in textwrap.wrap(line, int(width * 11.5))]
    ncol = min(cols, 3)
    top = 0.2 + 0.19 * len(heading) + 0.45
    bottom = 0.35 + 0.2 * math.ceil((len(handles) + 2) / ncol) + 0.1
    height = top + 4.4 * rows + bottom
    fig = draw.new_figure(figsize=(width, height))
    fig.subplots_adjust(left=0.5 / width, right=1.0 - 1.45 / width, bottom=bottom / height,
                        top=1.0 - top / height, wspace=0.45 / 3.6, hspace=0.75 / 3.9)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[n:]:
        ax.axis("off")
    path = np.array([s["pose"][:2] for p in plan["phases"] for s in p["steps"]])
    for ax, k in zip(axes.flat, picks, strict=False):
        phase = body[k]
        index = plan["phases"].index(phase)
        step = phase["steps"][-1]
        stance = scn.stance(tuple(phase["stance"]))
        pose = np.array(step["pose"])
        draw.draw_cave(ax, scn, highlight=stance.ids, glyphs=False)
        upto = sum(len(p["steps"]) for p in plan["phases"][:index + 1])
        ax.plot(path[:upto, 0], path[:upto, 1], ":", color="#2171b5", lw=1.5, zorder=5)
        probs = np.array([np.nan if p is None else p for p in step["p_grasp"]])
        draw.draw_robot(ax, scn.robot, pose, stance, probs, label_booms=False)
        ax.set_xlim(pose[0] - 2.6, pose[0] + 2.6)
        ax.set_ylim(pose[1] - 2.6, pose[1] + 2.6)
        ax.set_aspect("equal")
        first = draw.format_prob(phase["steps"][0]["p_success"])
        ax.set_title(f"stance {k + 1} of {len(body)} (phase {index})\n"
                     f"P {first} → {draw.format_prob(step['p_success'])}", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.locator_params(nbins=5)  # fewer ticks: their labels are most of the drawing time
    fig.suptitle("\n".join(heading), fontsize=10, y=1.0 - 0.15 / height, va="top",
                 parse_math=False)
    bar = draw.add_probability_colourbar(
        fig, axes, cax=fig.add_axes((1.0 - 1.3 / width, bottom / height, 0.15 / width,
                                     1.0 - (top + bottom) / height)))
    bar.ax.tick_params(labelsize=8)
    bar.set_label(bar.ax.get_ylabel(), fontsize=9)
    handles.append(Line2D([], [], ls=":", color="#2171b5", lw=1.5,
                          label="the body's path so far"))
    handles.append(Line2D([], [], color=draw.prob_colour(0.9999), lw=2.6,
                          label="boom, coloured by its grasp's P (scale on the right)"))
    fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.05 / height),
               fontsize=8, frameon=False, ncol=ncol)
    return fig


BOOM_COLOURS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a")


def phase_figure(plan: dict[str, Any], k: int):
    """The paper's Fig. 6 for phase k: tensions per boom over time (seed dotted, optimised
    solid) and the configuration's probability of failure 1 - P over time (seed and optimised,
    log scale: lower is better)."""
    phase = plan["phases"][k]
    motion = phase.get("motion")
    if motion is None:
        raise RbpInputError("holds no trajectory (plan it without --no-motion)",
                            field=f"phases[{k}].motion")
    t = np.array([s["t"] for s in phase["steps"]])
    t = t - t[0]
    tension = np.array([[np.nan if v is None else v for v in s["tension"]]
                        for s in phase["steps"]])
    seed_tension = np.array([[np.nan if v is None else v for v in f]
                             for f in motion["seed_tension"]])
    p = np.array([s["p_success"] for s in phase["steps"]])
    p_seed = np.array(motion["seed_p_success"])
    fig = draw.new_figure(figsize=(8.0, 5.8), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for i in range(NUM_BOOMS):
        if np.all(np.isnan(tension[:, i])):
            continue
        c = BOOM_COLOURS[i]
        top.plot(t, seed_tension[:, i], ":", color=c, lw=1.6)
        top.plot(t, tension[:, i], "-", color=c, lw=1.8, label=f"boom {i}")
    top.plot([], [], "k:", label="seed")
    top.plot([], [], "k-", label="optimised")
    top.set_ylabel("tension [N]")
    outside = dict(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    top.legend(**outside)
    # Failure probability on a log axis: configurations hold with P between 0.99 and
    # 0.999999, where a linear axis of P shows seed and optimum as one line.
    floor = 1e-12
    bottom.semilogy(t, np.maximum(1.0 - p_seed, floor), ":", color="black", lw=1.6,
                    label="seed")
    bottom.semilogy(t, np.maximum(1.0 - p, floor), "-", color="#2171b5", lw=1.8,
                    label="optimised")
    bottom.axhline(1.0 - plan["robot"]["p_min"], color="#cb181d", lw=1, ls="--",
                   label=f"1 - the robot's p_min\n(least P allowed: {plan['robot']['p_min']:g})")
    bottom.set_ylabel("1 - P (P: all grasps hold)")
    bottom.set_xlabel("time in phase [s]")
    bottom.legend(**outside)
    what = "body movement" if phase["kind"] == "body" else (
        f"boom {phase['free_boom']} {phase['from_anchor']} -> {phase['to_anchor']}")
    title = (f"phase {k} ({what}): seed {motion['seed_method']}; SCP "
             f"{motion['scp_status']}")
    top.set_title("\n".join(textwrap.wrap(title, 90)), fontsize=8, parse_math=False)
    return fig


def animation_figure(scn: Scenario, plan: dict[str, Any], max_frames: int = 400):
    """The animation's figure, a function drawing frame n into it, and the frame count. Fixed
    margins (in inches: a title line above, tick labels and an axis label below and left)
    hold the axes still from frame to frame without solving a layout for each."""
    frames = [(phase, step) for phase in plan["phases"] for step in phase["steps"]]
    if not frames:
        raise RbpInputError("the plan has no configurations to animate", field="phases")
    frames = [frames[i] for i in np.unique(np.linspace(0, len(frames) - 1,
                                                       min(max_frames, len(frames))).astype(int))]
    size = 6.4
    fig = draw.new_figure(figsize=(size, size))
    fig.subplots_adjust(left=0.75 / size, right=1.0 - 0.15 / size, bottom=0.6 / size,
                        top=1.0 - 0.4 / size)
    ax = fig.subplots()

    def draw_frame(n: int):
        ax.clear()
        phase, step = frames[n]
        stance = scn.stance(tuple(phase["stance"]))
        draw.draw_cave(ax, scn, highlight=stance.ids, glyphs=False)
        probs = np.array([np.nan if v is None else v for v in step["p_grasp"]])
        tip = np.array(step["free_tip"]) if "free_tip" in step else None
        draw.draw_robot(ax, scn.robot, np.array(step["pose"]), stance, probs, free_tip=tip,
                        label_booms=False)
        draw.frame_axes(ax, scn)
        name = draw.title_name(scn.name)
        ax.set_title(f"{name}: t = {step['t']:.1f} s, P (all grasps hold) = "
                     f"{draw.format_prob(step['p_success'])}", fontsize=9, parse_math=False)
        return []

    draw_frame(0)
    return fig, draw_frame, len(frames)


def animate_plan(scn: Scenario, plan: dict[str, Any], path: str, fps: int = 10,
                 max_frames: int = 400) -> None:
    """An animation of the whole climb (GIF through Pillow, or MP4 through ffmpeg, by the
    file's suffix), written atomically."""
    from matplotlib.animation import FuncAnimation

    from rb_drake.files import atomic_write

    fig, draw_frame, count = animation_figure(scn, plan, max_frames)
    anim = FuncAnimation(fig, draw_frame, frames=count, blit=False)
    suffix = str(path).rsplit(".", 1)[-1].lower()
    writer = "pillow" if suffix == "gif" else "ffmpeg"

    def write(f) -> None:
        import os
        import tempfile

        from rb_drake.files import output_target

        # matplotlib writers need a file name: render in a temporary folder, then copy; with
        # no usable one (TMPDIR), beside the target, whose folder was checked writable
        try:
            scratch = tempfile.TemporaryDirectory()
        except OSError:
            scratch = tempfile.TemporaryDirectory(prefix=f".{output_target(path).name}.",
                                                  suffix=".tmp", dir=output_target(path).parent)
        with scratch as tmp:
            name = os.path.join(tmp, f"anim.{suffix}")
            anim.save(name, writer=writer, fps=fps)
            with open(name, "rb") as src:
                f.write(src.read())

    atomic_write(path, write)


STOP_REASONS: dict[str, str] = {
    Stop.BUDGET: "stopped on its budget (max_expansions or time_limit reached): no claim",
    Stop.EXHAUSTED: "exhausted: every stance it could reach was expanded (not a proof)",
    Stop.NOROUTE: "proved no route through the lattice's points",
    Stop.NOSTART: "the start pose joins no lattice pose of its stance",
}


def _lattice_of(fp):
    """The lattice the complete search used (its memo's, else the default)."""
    from planning.lattice import LatticeConfig

    return getattr(getattr(getattr(fp, "memo", None), "lattice", None), "config", None) or (
        LatticeConfig())


def search_figure(scn: Scenario, fp):
    """Where a failed footstep search went: the body pose of each expanded stance coloured by
    expansion order, the frontier (reached, never expanded), the nearest stance reached (the
    robot drawn in it; the distance of its anchors' centroid from the goal, the measure the
    plan's reason gives) and the goal; the legend, below the cave, says why the search
    stopped."""
    from planning.search_cost import centroid_distance

    explored = list(fp.explored or [])
    frontier = list(fp.frontier or [])
    pts = np.vstack([scn.anchor_positions, [scn.start_pose[:2]], [scn.goal_position]])
    extent = np.ptp(pts, axis=0) + 1.6
    height = 7.0
    width = float(np.clip(height * extent[0] / extent[1], 3.5, 14.0)) + 1.6
    fig = draw.new_figure(figsize=(max(width, 6.0), height + 2.0), layout="constrained")
    ax = fig.subplots()
    draw.draw_cave(ax, scn, glyphs=False)
    if explored:
        poses = np.array([e.pose[:2] for e in explored])
        order = np.array([e.order for e in explored], dtype=float)
        dots = ax.scatter(poses[:, 0], poses[:, 1], c=order, cmap="viridis", s=14, zorder=6,
                          vmin=0.0, vmax=max(1.0, float(order.max())),
                          label=f"expanded stances ({len(explored)}): the body's centre")
        bar = fig.colorbar(dots, ax=ax, fraction=0.04, pad=0.02)
        bar.locator = MaxNLocator(integer=True)
        bar.update_ticks()
        bar.set_label("expansion order (0: the start)")
    if frontier:
        poses = np.array([e.pose[:2] for e in frontier])
        ax.scatter(poses[:, 0], poses[:, 1], facecolors="none", edgecolors="#636363", s=18,
                   lw=0.8, zorder=5, label=f"frontier ({len(frontier)}): reached, never expanded")
    reached = explored or frontier  # the plan's reason measures the expanded stances
    if reached:
        near = min(reached, key=lambda e: centroid_distance(scn, tuple(e.stance)))
        stance = scn.stance(tuple(near.stance))
        start = centroid_distance(scn, tuple(scn.start_stance))
        draw.draw_robot(ax, scn.robot, near.pose, stance, alpha=0.8, label_booms=False)
        ax.plot(*near.pose[:2], "X", color="#cb181d", ms=11, zorder=9, ls="none",
                label=f"nearest stance reached: {centroid_distance(scn, tuple(near.stance)):.2f}"
                      f" m from the goal (the start is {start:.2f} m; distance from the "
                      "stance's anchor centroid to the goal's centre)")
    else:
        ax.plot(*scn.start_pose[:2], "X", color="#cb181d", ms=11, zorder=9, ls="none",
                label="start (the search recorded no stances)")
    route = getattr(fp, "partial", None)
    if route is not None:  # rbp plan --partial climbs it: start, transition poses, end
        line = np.array([np.asarray(route.start_pose)[:2]]
                        + [np.asarray(s.pose)[:2] for s in route.steps]
                        + [np.asarray(route.goal_pose)[:2]])
        n = len(route.steps)
        ax.plot(line[:, 0], line[:, 1], "-", color="#cb181d", lw=1.4, zorder=8,
                label=f"partial route (rbp plan --partial): {n} regrasp{'' if n == 1 else 's'} "
                      "to the nearest stance, through its transition poses")
    why = STOP_REASONS.get(getattr(fp, "stop", "") or "", "stopped")
    refined = getattr(fp, "refined", ())
    if getattr(fp, "stop", "") == Stop.NOROUTE:
        lattice = _lattice_of(fp)
        why += f" ({lattice.position_step * 100:g} cm / {lattice.angle_step_deg:g} deg"
        why += ", nor the coarser before it)" if refined else ")"
    elif refined:  # the coarse lattice had no route; the finer one stopped
        why += (f" (on the refined lattice {refined[-1].position_step * 100:g} cm / "
                f"{refined[-1].angle_step_deg:g} deg; no route on the coarser)")
    ax.plot([], [], ls="none", label=f"search {why}")
    draw.frame_axes(ax, scn)
    handles, labels = ax.get_legend_handles_labels()
    marks = draw.cave_legend_handles(scn, glyphs=False, held=False)  # the goal's among them
    keep = [k for k, text in enumerate(labels) if text != "goal"]
    handles = marks + [handles[k] for k in keep]
    labels = [h.get_label() for h in marks] + [labels[k] for k in keep]
    wrap = max(40, int(7.0 * 72 / 4.2 * (max(width, 6.0) - 0.6) / 7.0))  # chars a line holds
    labels = ["\n".join(textwrap.wrap(text, wrap)) for text in labels]
    fig.legend(handles, labels, loc="outside lower center", fontsize=7, frameon=False)
    name = draw.title_name(scn.name)
    title = (f"{name}: footstep search failed after {fp.expansions} expansions, "
             f"{fp.transitions_tested} transitions tested")
    # over the figure, not the axes: a tall cave's axes are narrow, and a title centred on them
    # ran past the figure's edge (a 30 m shaft's was cut off)
    chars = max(40, int((max(width, 6.0) - 0.4) * 13))  # at fontsize 9
    fig.suptitle("\n".join(textwrap.wrap(title, chars)), fontsize=9, parse_math=False)
    return fig
