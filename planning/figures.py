"""Pictures of plans: footstep snapshots (the paper's Fig. 5)."""

from __future__ import annotations

import math
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from rb_drake import draw
from rb_drake.scenario import Scenario


def snapshots_figure(scn: Scenario, plan: dict[str, Any], max_panels: int = 12):
    """The robot at successive stances (one panel per body phase's end), grasped anchors' normals
    in red, the body's path so far dotted blue, booms coloured by grasp probability."""
    body = [p for p in plan["phases"] if p["kind"] == "body"]
    picks = np.unique(np.linspace(0, len(body) - 1, min(max_panels, len(body))).round().astype(int)
                      ) if body else []
    n = max(1, len(picks))
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols, 4.4 * rows), squeeze=False)
    path = np.array([s["pose"][:2] for p in plan["phases"] for s in p["steps"]]) if body else None
    for ax in axes.flat[n:]:
        ax.axis("off")
    if not body:
        ax = axes.flat[0]
        draw.draw_cave(ax, scn, highlight=tuple(scn.start_stance))
        draw.frame_axes(ax, scn)
        ax.set_title(f"{plan['planner']}: no plan ({plan['reason']})", fontsize=9)
        return fig
    for ax, k in zip(axes.flat, picks, strict=False):
        phase = body[k]
        step = phase["steps"][-1]
        stance = scn.stance(tuple(phase["stance"]))
        pose = np.array(step["pose"])
        draw.draw_cave(ax, scn, highlight=stance.ids, glyphs=False)
        upto = sum(len(p["steps"]) for p in plan["phases"][:plan["phases"].index(phase) + 1])
        ax.plot(path[:upto, 0], path[:upto, 1], ":", color="#2171b5", lw=1.5, zorder=5)
        probs = np.array([np.nan if p is None else p for p in step["p_grasp"]])
        draw.draw_robot(ax, scn.robot, pose, stance, probs, label_booms=False)
        ax.set_xlim(pose[0] - 2.6, pose[0] + 2.6)
        ax.set_ylim(pose[1] - 2.6, pose[1] + 2.6)
        ax.set_aspect("equal")
        ax.set_title(f"stance {k} of {len(body) - 1}: P = {draw.format_prob(step['p_success'])}",
                     fontsize=9)
        ax.tick_params(labelsize=7)
    p_path = plan["p_path"]
    fig.suptitle(f"{scn.name} — {plan['planner']}: {plan['regrasps']} regrasps, "
                 f"p_path = {p_path:.4f}, p_min = {plan['p_min']:.4f}", fontsize=11)
    fig.tight_layout()
    return fig
