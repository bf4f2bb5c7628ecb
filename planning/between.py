"""The motion between a plan's steps. A plan is verified at its steps, one every time step,
but executed everywhere between them, along the segments that join them. Where the booms'
lines nearly meet in one point the tensions that hold the body swing within one interval: in
simulation a grasp at P 0.998 at both ends of an interval fell to 0.84 between them
(crevasse-8m-s2), and the statics left the tension bounds between steps inside them
(shaft-1), losses that p_path, a product over the steps, cannot see. `between_steps` tests
configurations inside every interval; SCP accepts only iterates that pass it, and easing
slows a phase (its interpolated configurations become steps, counted by p_path) until it does.
Besides its three points per interval it checks the samples `rbp check` verifies (rule
`between`, planning.verify_between, on `step_motion`, the motion `rbp rig-run` executes).
"""

from __future__ import annotations

import numpy as np

from planning.smooth_motion import smooth_problem
from planning.verify_between import (
    MAX_PARTS,
    first_failure,
    samples,
    subdivisions,
    verification_world,
)
from rb_drake.feasibility import Reason, World
from rb_drake.kernel.scoring import score_poses
from rb_drake.stance import Stance
from rb_drake.statics import null_vector, statics_problem

BETWEEN = (0.25, 0.5, 0.75)  # where between two steps `between_steps` tests the motion
BETWEEN_DIP = 1e-3  # log P a grasp may lose between two steps, below the less of its ends


def between(values: np.ndarray) -> np.ndarray:
    """values (N, n) at the fractions BETWEEN of each interval, linearly: (N - 1) * 3 rows."""
    a, b = values[:-1, None, :], values[1:, None, :]
    w = np.asarray(BETWEEN)[None, :, None]
    return ((1.0 - w) * a + w * b).reshape(-1, values.shape[1])


def between_steps(world: World, stance: Stance, poses: np.ndarray, log_probs: np.ndarray,
                  tips: np.ndarray | None = None, times: np.ndarray | None = None,
                  dwell: bool = True, smooth: bool = True) -> str:
    """Why the motion between successive steps fails ('' when it does not): at BETWEEN of
    each interval (poses and free tip linear, `tips` (N, 2) at the steps in a 3-stance; the
    most robust tensions), a configuration must be feasible and each grasp hold with log P at
    least the less of its two ends' less BETWEEN_DIP (`log_probs`: (N, 4) at the steps); and
    the null vector of the booms' wrench matrix (its signed minors; in a 3-stance the
    determinant) must keep its direction from each of these configurations to the next. A
    direction that turns back means the segment passes where the booms' lines meet in one
    point, which can lie between the samples (crevasse-s6: conditioning 0.016 at 0.9 of an
    interval whose samples held 0.12 and more). Then the samples `rbp check` verifies on the
    straight motion (`dense_problem`) and on the smooth path `rbp simulate` follows through
    the steps (`smooth_motion.smooth_problem`, the steps at `times`, default one per unit, and
    with the final dwell added when `dwell`; not when `smooth` is False): a path that rounds a
    corner where a limit is active crosses it (a shoulder by up to 0.96 deg on the bundled
    plans)."""
    N = len(poses)
    if N < 2:
        return ""
    n_between = len(BETWEEN)
    mid = between(poses)
    mid_tips = None if tips is None else between(tips)
    check = score_poses(world, stance, mid, mid_tips)  # compiled: check_poses' decisions
    if not check.feasible.all():
        k = int(np.argmin(check.feasible))
        return (f"between steps {k // n_between} and {k // n_between + 1}: "
                f"{Reason(int(check.reason[k])).name}")
    dense = (dense_problem(world, stance, poses, tips)
             or (smooth_problem(world, stance, poses, tips, times, dwell) if smooth else ""))
    if dense:
        return dense
    att = stance.attached
    ends = np.minimum(log_probs[:-1], log_probs[1:])[:, att]
    floor = np.repeat(ends, n_between, axis=0) - BETWEEN_DIP
    low = check.log_probs[:, att] < floor
    if low.any():
        k = int(np.flatnonzero(low.any(axis=1))[0])
        return f"a grasp weaker between steps {k // n_between} and {k // n_between + 1}"
    seq = np.concatenate([poses[:-1, None], mid.reshape(N - 1, n_between, 3), poses[1:, None]],
                         axis=1).reshape(-1, 3)
    seq_tips = None
    if tips is not None:
        assert mid_tips is not None  # between(tips) above
        seq_tips = np.concatenate([tips[:-1, None], mid_tips.reshape(N - 1, n_between, 2),
                                   tips[1:, None]], axis=1).reshape(-1, 2)
    A = statics_problem(world.robot, world.gravity_vector, seq, stance, seq_tips).A
    n = null_vector(A).reshape(N - 1, n_between + 2, 4)
    turned = (np.sum(n[:, 1:] * n[:, :-1], axis=-1) <= 0.0).any(axis=1)
    if turned.any():
        k = int(np.flatnonzero(turned)[0])
        return f"between steps {k} and {k + 1}: the booms' lines meet in one point (SINGULAR)"
    return ""


def dense_problem(world: World, stance: Stance, poses: np.ndarray,
                  tips: np.ndarray | None) -> str:
    """Why a configuration fails at `rbp check`'s resolution between the steps ('' when none
    does): the samples rule `between` checks (planning.verify_between.samples, on the straight
    motion), feasible as the rule has it (its tension slack included). Three points per
    interval miss a limit crossed between them (a shoulder past its range on
    4 of the 69 benchmark plans)."""
    if np.any(subdivisions(world.robot, poses, tips) > MAX_PARTS):
        return "between steps: an interval too long to sample"
    s = samples(world.robot, np.arange(len(poses), dtype=float), poses, tips)
    return first_failure(verification_world(world), stance, s, "dense")
