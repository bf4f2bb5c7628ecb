"""The pose lattice: every body pose on a grid, and the feasible ones of a stance.

The complete footstep search (`planning.complete`) decides transitions on a lattice of body
poses, x = i dx, y = k dx, phi = m dphi (default dx = 2 cm, dphi = 2.5 deg), fixed in the world
so that every stance sees the same poses. For a 4-stance it enumerates exactly the lattice poses
at which all four booms reach their anchors (boom length and shoulder range; for one
orientation this region is the intersection of four 90-degree circular sectors, a convex set,
so each lattice column holds an interval of it), scores them all with the compiled
feasibility kernel, and keeps the feasible ones with:
- their robustness in the stance,
- which booms may let go there (the 3-stance with that gripper still at its anchor is
  feasible too: the two release configurations of a transition),
- the connected component each belongs to (26-neighbours on the lattice): the body can move
  between two poses of one component through feasible poses, one lattice step at a time.
Nothing here samples: a lattice pose is in the set exactly when the kernel finds it feasible.

The search itself grows only the components it enters (`planning.components`, by flood fill);
the tests hold those components equal to a reference that scores the whole reachable lattice
(`stance_lattice` in tests/lattice_reference.py).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from planning.config_ranges import angle_count, angle_step_problem
from planning.lattice_kernels import reach_violation
from rb_drake.errors import RbpInputError
from rb_drake.params import RobotParams

if TYPE_CHECKING:
    from rb_drake.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class LatticeConfig:
    """The resolution at which the complete search is complete."""

    position_step: float = 0.02      # m
    angle_step_deg: float = 2.5      # deg; 360 / angle_step_deg must be an even integer

    def __post_init__(self) -> None:
        # Outside these, a lattice is either meaningless (a step of 0 or below, which searched
        # as if no pose held) or so fine that one stance's poses alone exhaust the memory
        # (1e-9 m took 16 GB before a MemoryError).
        for name, value, (lo, hi), unit in (
                ("position_step", self.position_step, POSITION_STEP_RANGE, "m"),
                ("angle_step_deg", self.angle_step_deg, ANGLE_STEP_RANGE, "deg")):
            if not (isinstance(value, int | float) and lo <= value <= hi):
                raise RbpInputError(f"must be between {lo:g} and {hi:g} {unit}, got {value!r}",
                                    field=name)
        self.angle_count  # noqa: B018 (raises unless the step divides 180 deg)

    @property
    def angle_step(self) -> float:
        return math.radians(self.angle_step_deg)

    @functools.cached_property  # asked for at every move of a search
    def angle_count(self) -> int:
        """Orientation indices -n/2 .. n/2 - 1 cover the whole circle."""
        n = angle_count(self.angle_step_deg)
        if n is None:
            raise RbpInputError(angle_step_problem(self.angle_step_deg), field="angle_step_deg")
        return n


POSITION_STEP_RANGE = (0.005, 0.5)  # m: 5 mm is 16 times the default's positions
ANGLE_STEP_RANGE = (0.5, 45.0)       # deg: 0.5 deg is 5 times the default's orientations


# Lattice indices are packed into one int64 key, so that sets of poses intersect by sorting.
SPAN = 1 << 21  # |i|, |k| < 2^20 cells: 20 km at 2 cm


def span_problem(scn: Scenario, cfg: LatticeConfig) -> str:
    """Why the lattice of `cfg` cannot index every body pose of `scn` ("" if it can): an index
    beyond SPAN / 2 cells from the origin wraps in `pack` onto another pose (a cave 10 km out
    at 5 mm steps answered a wrong "start joined to no feasible pose"). The body reaches at
    most a boom and a shoulder offset beyond an anchor."""
    reach = float(scn.robot.boom_length[1]) + float(np.abs(scn.robot.shoulder_array).max())
    points = [scn.anchor_positions, np.array([scn.start_pose[:2], scn.goal_position])]
    extent = float(max(np.abs(p).max() for p in points if p.size)) + reach
    cells = extent / cfg.position_step
    if cells < SPAN // 2 - 2:
        return ""
    return (f"the cave reaches {extent:.0f} m from the origin, {cells:,.0f} lattice steps of "
            f"{cfg.position_step:g} m: the lattice indexes at most {SPAN // 2 - 2:,}; use a step "
            f"of at least {extent / (SPAN // 2 - 2):.4f} m (or move the cave to the origin)")


def pack(idx: np.ndarray, angle_count: int) -> np.ndarray:
    """One sortable int64 per lattice index (i, k, m)."""
    idx = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
    return ((idx[:, 0] + SPAN // 2) * SPAN + (idx[:, 1] + SPAN // 2)) * angle_count + (
        idx[:, 2] + angle_count // 2)


def unpack(keys: np.ndarray, angle_count: int) -> np.ndarray:
    """Lattice indices (i, k, m) of packed keys: `pack`'s inverse."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1)
    rest = keys // angle_count
    return np.column_stack([rest // SPAN - SPAN // 2, rest % SPAN - SPAN // 2,
                            keys % angle_count - angle_count // 2])


def poses_of(idx: np.ndarray, cfg: LatticeConfig) -> np.ndarray:
    idx = np.asarray(idx).reshape(-1, 3)
    return np.column_stack([idx[:, 0] * cfg.position_step, idx[:, 1] * cfg.position_step,
                            idx[:, 2] * cfg.angle_step])


def reachable_lattice(robot: RobotParams, anchors: np.ndarray, booms: np.ndarray,
                      cfg: LatticeConfig) -> np.ndarray:
    """Every lattice index (i, k, m) at which boom booms[n] reaches anchors[n] for every n (boom
    length within bounds, shoulder angle within range), (P, 3) int64.

    Per orientation, boom n's shoulder must lie within L_max of its anchor inside the 90-degree
    cone about the boom's direction: the body centre lies in a circular sector, and each lattice
    column holds an interval of the sectors' intersection (with a margin for rounding); every
    index of those intervals is then tested exactly, as `reach_violation` tests it."""
    if robot.shoulder_range >= math.pi / 2:
        raise ValueError("the lattice enumeration needs a shoulder range below 90 deg")
    anchors = np.ascontiguousarray(anchors, dtype=float).reshape(-1, 2)
    booms = np.ascontiguousarray(booms, dtype=np.int64).reshape(-1)
    idx = _reachable_kernel(anchors, np.ascontiguousarray(robot.shoulder_array[booms]),
                            np.ascontiguousarray(robot.shoulder_directions[booms]),
                            float(robot.boom_length[0]), float(robot.boom_length[1]),
                            float(robot.shoulder_range), float(cfg.position_step),
                            float(cfg.angle_step), int(cfg.angle_count))
    if not len(idx):
        return idx
    # The exact test, exactly as the feasibility kernel's (its own rounding).
    v = reach_violation(robot, poses_of(idx, cfg), anchors, booms).sum(axis=1)
    return idx[v == 0.0]


@njit(cache=True)
def _reachable_kernel(anchors, shoulders, directions, lo, hi, half, dx, dphi,
                      n_phi):  # pragma: no cover - compiled
    B = anchors.shape[0]
    cap = 1024
    out = np.empty((cap, 3), dtype=np.int64)
    n = 0
    ax = np.empty(B)
    ay = np.empty(B)
    margin = 1e-7  # m: rounding of the bounds; the exact test follows
    for m in range(-n_phi // 2, n_phi // 2):
        phi = m * dphi
        c, s = math.cos(phi), math.sin(phi)
        x_lo, x_hi, y_lo0, y_hi0 = -math.inf, math.inf, -math.inf, math.inf
        for b in range(B):
            ax[b] = anchors[b, 0] - (c * shoulders[b, 0] - s * shoulders[b, 1])
            ay[b] = anchors[b, 1] - (s * shoulders[b, 0] + c * shoulders[b, 1])
            x_lo = max(x_lo, ax[b] - hi)
            x_hi = min(x_hi, ax[b] + hi)
            y_lo0 = max(y_lo0, ay[b] - hi)
            y_hi0 = min(y_hi0, ay[b] + hi)
        if x_lo > x_hi or y_lo0 > y_hi0:
            continue
        for i in range(math.ceil(x_lo / dx - 1e-6), math.floor(x_hi / dx + 1e-6) + 1):
            x = i * dx
            y_lo, y_hi = y_lo0, y_hi0
            for b in range(B):
                px = x - ax[b]
                disc = hi * hi - px * px
                if disc < -1e-12:
                    y_lo, y_hi = math.inf, -math.inf
                    break
                root = math.sqrt(max(disc, 0.0))
                y_lo = max(y_lo, ay[b] - root)
                y_hi = min(y_hi, ay[b] + root)
                # The centre lies in the cone of directions phi + d + pi +- half from the apex:
                # sign * (r_x (y - a_y) - r_y p_x) >= 0 for its two boundary rays.
                axis = phi + directions[b] + math.pi
                for side in range(2):
                    ang = axis - half if side == 0 else axis + half
                    sign = 1.0 if side == 0 else -1.0
                    a = sign * math.cos(ang)
                    off = -sign * math.sin(ang) * px
                    if abs(a) < 1e-12:
                        if off < -1e-9:
                            y_lo, y_hi = math.inf, -math.inf
                        continue
                    bound = ay[b] - off / a
                    if a > 0:
                        y_lo = max(y_lo, bound)
                    else:
                        y_hi = min(y_hi, bound)
            if not y_lo <= y_hi + 2 * margin:
                continue
            for k in range(math.ceil((y_lo - margin) / dx - 1e-9),
                           math.floor((y_hi + margin) / dx + 1e-9) + 1):
                if n == cap:
                    grown = np.empty((2 * cap, 3), dtype=np.int64)
                    grown[:cap] = out
                    out = grown
                    cap *= 2
                out[n, 0] = i
                out[n, 1] = k
                out[n, 2] = m
                n += 1
    return out[:n].copy()
