"""The steps of a trajectory phase in a plan file, from the planned poses and tensions.

Both the plan builder (`planning.plan.build_motion_plan`) and the easing of its phases
(`planning.easing.ease_phase`) write phase steps this way; it lives here so that neither of
those two modules has to import the other.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario
from rb_drake.statics import statics_problem


def steps_with_tensions(scn: Scenario, stance_ids: tuple[str | None, ...], poses: np.ndarray,
                        tensions: np.ndarray, tips: np.ndarray | None, t0: float,
                        dt: float) -> list[dict[str, Any]]:
    """Configurations with given tensions, one every dt from t0; probabilities as `rbp check`
    recomputes them (one vectorised statics evaluation for the whole phase)."""
    stance = scn.stance(stance_ids)
    prob = statics_problem(scn.robot, scn.gravity_vector, poses, stance, tips)
    att = stance.attached
    f = np.where(att, tensions, 0.0)
    lp = stance.log_prob(f, np.nan_to_num(prob.pull_angles))
    steps = []
    for k in range(len(poses)):
        step: dict[str, Any] = {
            "t": round(float(t0 + k * dt), 6),
            "pose": [float(v) for v in poses[k]],
            "tension": [float(f[k, i]) if att[i] else None for i in range(NUM_BOOMS)],
            "p_grasp": [float(np.exp(lp[k, i])) if att[i] else None for i in range(NUM_BOOMS)],
            "p_success": float(np.exp(lp[k, att].sum())),
        }
        if tips is not None:
            step["free_tip"] = [float(v) for v in tips[k]]
            step["shoulder_torque"] = float(prob.shoulder_torque[k])
        steps.append(step)
    return steps
