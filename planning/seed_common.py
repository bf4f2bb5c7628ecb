"""What the seeds of both phase kinds share (`planning.seeds`): their configuration
(`SeedConfig`), their result (`Seed`), the subdivision of waypoints into configurations at most a
step apart (`subdivide`), and how configurations are checked and a failure described.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from rb_drake.errors import RbpInputError
from rb_drake.feasibility import REASON_TEXT, PoseCheck, Reason, World, check_poses
from rb_drake.stance import Stance

MAX_OMPL_CHECKS = 1_000_000  # RRTConnect's budget at most: minutes, not hours, per seed


@dataclasses.dataclass(frozen=True)
class SeedConfig:
    step: float = 0.02          # m between successive poses (and free tip positions)
    turn_step: float = 0.03     # rad between successive poses
    # local sampling: body detours (body phase) or body offsets (reach phase)
    local_rounds: int = 4       # rounds (spreads), the spread doubling each round
    local_samples: int = 24     # candidates per round
    local_spread: float = 0.05  # m, first round's std (a detour's first mode); phi's: x turn/step
    local_modes: int = 3        # half-sine modes of a body detour
    ompl_checks: int = 1000     # RRTConnect's budget: poses given the full check (about 0.5 s)
    ompl_time: float | None = None  # s, a wall-clock cap besides (None: none; a run stopped by
    # it depends on the machine's speed and load, so the same seed may give another plan)
    ompl_range: float = 0.3     # RRTConnect's extension length (SE(2) distance)
    ompl_margin: float = 0.5    # m, the SE(2) bounds: start and goal's box grown by this
    arc_heights: tuple[float, ...] = (0.1, 0.2, 0.35, 0.5)  # tip arc heights / chord, tried
    arc_min_height: float = 0.05  # m

    def __post_init__(self) -> None:
        if isinstance(self.ompl_checks, bool) or not isinstance(self.ompl_checks, int) or \
                not 1 <= self.ompl_checks <= MAX_OMPL_CHECKS:
            raise RbpInputError(f"must be a whole number from 1 to {MAX_OMPL_CHECKS:,} (about "
                                f"a millisecond each), got {self.ompl_checks!r}",
                                field="seed.ompl_checks")
        if self.ompl_time is not None and not 0.0 < self.ompl_time < math.inf:
            raise RbpInputError(f"must be a positive number of seconds (or null: none), got "
                                f"{self.ompl_time!r}", field="seed.ompl_time")


class Seed(NamedTuple):
    success: bool
    method: str               # body: "straight" | "local" | "ompl"; reach: "hold" | "local"
    poses: np.ndarray         # (N, 3); in a reach phase the pose at each tip position
    tips: np.ndarray | None   # (N, 2) free tip positions (reach phases), else None
    log_probs: np.ndarray     # (N,) robustness r = log P of each configuration
    reason: str               # why not, when failed


def failed_seed(reason: str, reach: bool = False) -> Seed:
    """A seed that failed for `reason` (empty arrays; a reach phase's with its tips)."""
    return Seed(False, "", np.zeros((0, 3)), np.zeros((0, 2)) if reach else None, np.zeros(0),
                reason)


def pieces(waypoints: np.ndarray, step: float, turn_step: float) -> np.ndarray:
    """How many equal parts each straight piece between waypoints needs (see `subdivide`)."""
    d = np.diff(waypoints, axis=0)
    ratio = np.maximum(np.linalg.norm(d[:, :2], axis=1) / step, np.abs(d[:, 2]) / turn_step)
    if waypoints.shape[1] > 3:
        ratio = np.maximum(ratio, np.linalg.norm(d[:, 3:5], axis=1) / step)
    return np.maximum(1, np.ceil(ratio)).astype(int)


def subdivide(waypoints: np.ndarray, step: float, turn_step: float) -> np.ndarray:
    """Waypoints (W, 3) or (W, 5) (pose, then free tip) joined by straight pieces, each cut into
    equal parts that move the position and the tip at most `step` and phi at most `turn_step`.
    The waypoints themselves are kept exactly."""
    w = np.asarray(waypoints, dtype=float)
    parts = pieces(w, step, turn_step)
    seg = np.repeat(np.arange(len(parts)), parts)
    first = np.concatenate([[0], np.cumsum(parts)[:-1]])
    t = (np.arange(len(seg)) - first[seg]) / parts[seg]
    return np.vstack([w[seg] + t[:, None] * np.diff(w, axis=0)[seg], w[-1:]])


def check_configurations(world: World, stance: Stance,
                         configs: np.ndarray) -> PoseCheck:
    """check_poses on configurations (N, 3) or (N, 5) (pose, free tip); a reach phase's in
    its `reach_world`."""
    tips = configs[:, 3:5] if configs.shape[1] > 3 else None
    return check_poses(world, stance, configs[:, :3], tips)


def describe_infeasible(check: PoseCheck, configs: np.ndarray, what: str,
                        k: int | None = None) -> str:
    """Configuration k (default: the first infeasible one) and check_poses' reason for it."""
    where = ""
    if k is None:
        k = int(np.argmin(check.feasible))
        where = f" at configuration {k} of {len(configs)}"
    x, y, phi = configs[k, :3]
    code = Reason(int(check.reason[k]))
    boom = int(check.boom[k])
    tip = f", tip ({configs[k, 3]:.3f}, {configs[k, 4]:.3f})" if configs.shape[1] > 3 else ""
    on = f" (boom {boom})" if boom >= 0 else ""
    return (f"{what} infeasible{where}: pose ({x:.3f}, {y:.3f}, {phi:.3f}){tip}: "
            f"{REASON_TEXT[code]}{on}")


def found_seed(method: str, configs: np.ndarray, log_probs: np.ndarray) -> Seed:
    """A found seed from its checked configurations (N, 3) or (N, 5) and their log P."""
    tips = configs[:, 3:5].copy() if configs.shape[1] > 3 else None
    return Seed(True, method, configs[:, :3].copy(), tips, np.array(log_probs, dtype=float), "")
