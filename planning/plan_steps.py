"""The steps of a plan file: one configuration each (`plan_model.Step`), written here only.

Both the plan builder (`planning.plan.build_motion_plan`) and the easing of its phases
(`planning.easing.ease_phase`) write phase steps from planned poses and tensions
(`steps_with_tensions`); the footstep-stage plan, the rig's plan and the replanners write
single configurations with the robust allocation (`allocation_step`). Every step is made as a
`Step`, so the five producers make one form (written by `Step.to_dict` at the file).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from planning.plan_model import Step
from rb_drake.scenario import Scenario
from rb_drake.stance import Stance
from rb_drake.statics import statics_problem


def _maybe(values: Iterable[float], attached: Iterable[bool]) -> tuple[float | None, ...]:
    return tuple(float(v) if a else None for v, a in zip(values, attached, strict=True))


def allocation_step(stance: Stance, alloc: Any, row: int, t: float, pose: np.ndarray,
                    free_tip: np.ndarray | None = None) -> Step:
    """The step at `pose` with row `row` of a robust allocation (`check_poses(full=True)`):
    a free boom's (or a non-finite) tension and a free boom's grasp probability are null."""
    att = stance.attached
    tension = alloc.tensions[row]
    step = Step(
        t=float(t), pose=tuple(float(v) for v in pose),
        tension=_maybe(tension, [a and np.isfinite(f) for a, f in zip(att, tension, strict=True)]),
        p_grasp=_maybe(np.exp(alloc.log_probs[row]), att),
        p_success=float(np.exp(alloc.robustness[row])),
        free_tip=None if free_tip is None else tuple(float(v) for v in free_tip),
        shoulder_torque=None if free_tip is None else float(alloc.shoulder_torque[row]))
    return step


def steps_with_tensions(scn: Scenario, stance_ids: tuple[str | None, ...], poses: np.ndarray,
                        tensions: np.ndarray, tips: np.ndarray | None, t0: float,
                        dt: float) -> list[Step]:
    """Configurations with given tensions, one every dt from t0; probabilities as `rbp check`
    recomputes them (one vectorised statics evaluation for the whole phase)."""
    stance = scn.stance(stance_ids)
    prob = statics_problem(scn.robot, scn.gravity_vector, poses, stance, tips)
    att = stance.attached
    f = np.where(att, tensions, 0.0)
    lp = stance.log_prob(f, np.nan_to_num(prob.pull_angles))
    steps = []
    for k in range(len(poses)):
        step = Step(
            t=round(float(t0 + k * dt), 6),
            pose=tuple(float(v) for v in poses[k]),
            tension=_maybe(f[k], att),
            p_grasp=_maybe(np.exp(lp[k]), att),
            p_success=float(np.exp(lp[k, att].sum())),
            free_tip=None if tips is None else tuple(float(v) for v in tips[k]),
            shoulder_torque=None if tips is None else float(prob.shoulder_torque[k]))
        steps.append(step)
    return steps
