"""The motion between a plan's steps. A plan is verified at its steps, one every time step,
but executed everywhere between them, along the segments that join them. Where the booms'
lines nearly meet in one point the tensions that hold the body swing within one interval: in
simulation a grasp at P 0.998 at both ends of an interval fell to 0.84 between them
(crevasse-8m-s2), and the statics left the tension bounds between steps inside them
(shaft-1), losses that p_path, a product over the steps, cannot see. `between_steps` tests
configurations inside every interval; SCP accepts only iterates that pass it, and easing
slows a phase (its interpolated configurations become steps, counted by p_path) until it does.
"""

from __future__ import annotations

import numpy as np

from rb_drake.feasibility import Reason, World, check_poses
from rb_drake.stance import Stance

BETWEEN = (0.25, 0.5, 0.75)  # where between two steps `between_steps` tests the motion
BETWEEN_DIP = 1e-3  # log P a grasp may lose between two steps, below the less of its ends


def between(values: np.ndarray) -> np.ndarray:
    """values (N, n) at the fractions BETWEEN of each interval, linearly: (N - 1) * 3 rows."""
    a, b = values[:-1, None, :], values[1:, None, :]
    w = np.asarray(BETWEEN)[None, :, None]
    return ((1.0 - w) * a + w * b).reshape(-1, values.shape[1])


def between_steps(world: World, stance: Stance, poses: np.ndarray, log_probs: np.ndarray,
                  between_tips: np.ndarray | None = None) -> str:
    """Why the motion between successive steps fails ('' when it does not): at BETWEEN of
    each interval (poses and free tip linear, the most robust tensions), a configuration
    must be feasible and each grasp hold with log P at least the less of its two ends' less
    BETWEEN_DIP (`log_probs`: (N, 4) at the steps)."""
    if len(poses) < 2:
        return ""
    mid = between(poses)
    check = check_poses(world, stance, mid, between_tips)
    if not check.feasible.all():
        k = int(np.argmin(check.feasible))
        return (f"between steps {k // len(BETWEEN)} and {k // len(BETWEEN) + 1}: "
                f"{Reason(int(check.reason[k])).name}")
    att = stance.attached
    ends = np.minimum(log_probs[:-1], log_probs[1:])[:, att]
    floor = np.repeat(ends, len(BETWEEN), axis=0) - BETWEEN_DIP
    low = check.allocation.log_probs[:, att] < floor
    if low.any():
        k = int(np.flatnonzero(low.any(axis=1))[0])
        return f"a grasp weaker between steps {k // len(BETWEEN)} and {k // len(BETWEEN) + 1}"
    return ""
