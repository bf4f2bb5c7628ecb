"""Compiled pose feasibility: `check_poses(..., full=True)` and `violation` in one numba loop.

The transition search scores thousands of small batches of poses; in numpy each batch costs a
few milliseconds of per-call overhead (dozens of small array operations), whatever its size.
`score_poses` runs the same tests in the same order, with the same constants and algorithms,
one pose at a time in compiled code, and returns what the search needs: feasibility, the first
failing `Reason`, the allocation's robustness, log-probabilities and tensions, and the
violation. `score_rows` does the same for rows that each pair a pose with one of several
stances (a transition's four configurations in one call). `rb_drake.feasibility` stays the
reference, and is used everywhere else.

Where the numpy path calls LAPACK (determinants, 3x3 solves, the SVD of the conditioning) this
module uses cofactor determinants, Gaussian elimination with partial pivoting and a one-sided
Jacobi SVD; it has its own `log_ndtr` and `erfcx` (numba has no scipy.special), and its
allocation stops the safeguarded Newton steps once they move by less than NEWTON_EXIT, where
`statics.allocate`'s remaining steps move by rounding errors. Results differ in the last bits
only: on 310,000 poses of tests/test_feasibility_kernel.py's cases no feasibility or reason
differed, and every value agreed to 4e-11 relative (tensions 2e-11, robustness 2e-12), so a
decision can flip only for a pose within about that of a threshold.

Constants that decide (limits, MIN_CONDITIONING, REGULARISATION, ...) reach the kernels as data
(`_robot_params`), so that numba's on-disk cache, which only notices changes to this file, can
never hold stale ones; the Reason codes below are checked against `feasibility.Reason`.
"""

from __future__ import annotations

import math
import os
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from statistics import NormalDist
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from rb_drake.collision import ANCHOR_CLEARANCE, Rock
from rb_drake.feasibility import MIN_CONDITIONING, World
from rb_drake.grasp import HALF_PI
from rb_drake.params import RobotParams
from rb_drake.stance import Stance
from rb_drake.statics import REGULARISATION, STATICS_TOL

NEWTON_STEPS = 12  # statics.allocate's default
NEWTON_EXIT = 1e-12  # stop once a Newton step is this small (relative to 1 + |t|)

# The special functions' constants, written as grasp.py and scipy's xsf write them.
_SQRT1_2 = 0.707106781186547524400844362104849039  # M_SQRT1_2, in scipy's log_ndtr
_INV_SQRT2 = 1.0 / math.sqrt(2.0)                  # grasp.mills_ratio's
_SQRT_2_OVER_PI = math.sqrt(2.0 / math.pi)
_INV_SQRT_PI = 0.56418958354775628694807945156     # Faddeeva's ispi
_CEPHES_MAXLOG = 7.09782712893383996843e2
_SPLIT = 134217729.0                               # 2^27 + 1, Dekker's splitter
_TWO_PI = 2.0 * math.pi

# Layout of the packed robot parameters (`_robot_params`).
_SHOULDER = 0       # 8 values: x0, y0, ..., x3, y3 (body frame)
_DIRECTION = 8      # 4 values: equilibrium directions (rad)
_RANGE = 12
_L_LO, _L_HI = 13, 14
_F_LO, _F_HI = 15, 16
_TORQUE_MAX = 17
_GRIPPER_MASS = 18
_DENSITY = 19
_BODY_MASS = 20
_WIDTH, _HEIGHT = 21, 22
_LOG_P_MIN = 23
_GRAVITY = 24       # 2 values
_MOMENT_SCALE = 26  # 1 / largest shoulder distance, as in wrench_conditioning
_MIN_CONDITIONING = 27
_REGULARISATION = 28
_STATICS_TOL = 29
_CLEARANCE = 30
_Z_FLOOR = 31       # Phi^-1(p_min), less a margin: no grasp of a feasible pose has a lower z
_MAX_PULL = 32      # robot.max_pull_angle (rad): the PULL_ANGLE test's limit
_N_PARAMS = 33

ALL_SEGMENTS = 0b11111  # `score_rows(collide=)`: bit i boom i's segment, bit 4 the body

# Reason codes (feasibility.Reason), as plain ints for the compiled code.
_BOOM_LENGTH, _SHOULDER_ANGLE, _BODY_COLLISION, _BOOM_COLLISION = 1, 2, 3, 4
_PULL_ANGLE, _SHOULDER_TORQUE, _SINGULAR, _STATICS, _PROBABILITY = 5, 6, 7, 8, 9


class KernelCheck(NamedTuple):
    """`check_poses(..., full=True)` and `violation` at P poses, in one."""

    feasible: np.ndarray    # (P,) bool
    reason: np.ndarray      # (P,) Reason codes (first failing test)
    robustness: np.ndarray  # (P,) allocated r; -inf where statics fail
    log_probs: np.ndarray   # (P, 4) log P_i (0 for a free boom)
    tensions: np.ndarray    # (P, 4) allocated; NaN for a free boom and where none exist
    violation: np.ndarray   # (P,) feasibility.violation: 0 where feasible
    # score_rows(release=True) only: per 4-stance row feasible, r of releasing each boom (the
    # 3-stance with that gripper at its anchor, the gripper counted unloaded), NaN elsewhere
    release_r: np.ndarray | None = None


class PackedStances(NamedTuple):
    """Stances as the kernel reads them, one per row: S rows (a free boom's entries NaN)."""

    positions: np.ndarray      # (S, 4, 2)
    normals: np.ndarray        # (S, 4, 2)
    f_normal: np.ndarray       # (S, 4)
    f_lateral: np.ndarray      # (S, 4)
    sigma_normal: np.ndarray   # (S, 4)
    sigma_lateral: np.ndarray  # (S, 4)
    attached: np.ndarray       # (S, 4) bool


def pack_stances(*stances: Stance) -> PackedStances:
    """Plain (not per-row) stances, one row each, for `score_rows`."""
    for stance in stances:
        _anchor_count(stance)
    return PackedStances(*(np.stack([getattr(s, name) for s in stances]).astype(
        bool if name == "attached" else float) for name in PackedStances._fields))


def score_poses(world: World, stance: Stance, poses: np.ndarray,
                free_tip: np.ndarray | None = None, ignore_grasps: bool = False) -> KernelCheck:
    """`check_poses(world, stance, poses, free_tip, full=True, ignore_grasps)` followed by
    `violation(...)` on the same poses, compiled.

    `stance` may be per-row (`Stance.mix`); a 3-stance needs `free_tip`, (2,) or (P, 2)."""
    poses = np.ascontiguousarray(poses, dtype=float).reshape(-1, 3)
    P = poses.shape[0]
    if _anchor_count(stance) == 3:
        if free_tip is None:
            raise ValueError(f"a 3-stance (boom {stance.free_boom} free) needs the free "
                             "gripper's position")
        tips = _floats(free_tip, (-1, 2))
        if tips.shape[0] not in (1, P):
            raise ValueError(f"free_tip holds {tips.shape[0]} points for {P} poses")
    else:
        tips = _NO_TIP
    S = P if stance.positions.ndim == 3 else 1
    attached = np.tile(np.asarray(stance.attached, dtype=bool), (S, 1))
    packed = PackedStances(_floats(stance.positions, (S, 4, 2)), _floats(stance.normals, (S, 4, 2)),
                           _floats(stance.f_normal, (S, 4)), _floats(stance.f_lateral, (S, 4)),
                           _floats(stance.sigma_normal, (S, 4)),
                           _floats(stance.sigma_lateral, (S, 4)), attached)
    rows = np.arange(P)
    return score_rows(world, packed, tips, poses, rows, rows if S > 1 else np.zeros(P, np.int64),
                      rows if tips.shape[0] > 1 else np.zeros(P, np.int64), ignore_grasps)


def score_rows(world: World, stances: PackedStances, tips: np.ndarray, poses: np.ndarray,
               pose_row: np.ndarray, stance_row: np.ndarray, tip_row: np.ndarray,
               ignore_grasps: bool = False, decide_only: bool = False,
               collide: int = ALL_SEGMENTS, release: bool = False) -> KernelCheck:
    """`score_poses` for R rows at once, each its own configuration: row r is pose
    poses[pose_row[r]] in stance stances[stance_row[r]], with the free gripper of a 3-stance
    at tips[tip_row[r]] (tips: (T, 2); ignored in a 4-stance). Lets one call score several
    stances, as a transition's four configurations. With `decide_only` (the lattice search,
    which asks only which rows are feasible) each row stops at a failing test: the violation
    is NaN and an infeasible row's reason is one failing test, not always the first.
    `collide` (decide_only only) tests only the segments of its bits for collision: those of
    the others must be known clear, e.g. decided in another configuration at the same pose.
    `release` (decide_only only): also each feasible 4-stance row's release r (KernelCheck),
    as the flood fill decides it."""
    if collide != ALL_SEGMENTS and not decide_only:
        raise ValueError("collide leaves out collision tests: only with decide_only")
    if release and not decide_only:
        raise ValueError("release sets are decided with decide_only only")
    R = len(pose_row)
    reason = np.empty(R, dtype=np.int64)
    robustness = np.empty(R)
    log_probs = np.empty((R, 4))
    tensions = np.empty((R, 4))
    violation = np.empty(R)
    release_r = np.full((R if release else 0, 4), np.nan)
    if R:
        edges, owner, vertices = _packed_rock(world.rock)
        _score_kernel(_floats(poses, (-1, 3)), _robot_params(world.robot, world.gravity_vector),
                      *stances, _floats(tips, (-1, 2)), _indices(pose_row), _indices(stance_row),
                      _indices(tip_row), edges, owner, vertices, bool(ignore_grasps),
                      bool(decide_only), int(collide), reason, robustness, log_probs, tensions,
                      violation, release_r, np.empty(0, dtype=np.int8), 15, 0, 1)
    return KernelCheck(reason == 0, reason, robustness, log_probs, tensions, violation,
                       release_r if release else None)


_NO_TIP = np.full((1, 2), np.nan)


def _anchor_count(stance: Stance) -> int:
    n = int(np.count_nonzero(stance.attached))
    if n not in (3, 4):
        raise ValueError(f"a stance holds 3 or 4 anchors, this one holds {n}")
    return n


# The kernel is compiled for C-contiguous, writable float64 / int64 / bool arrays: anything
# else (a read-only view, say) would trigger a second compilation of it.
def _floats(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float).reshape(shape)
    return a if a.flags.writeable else a.copy()


def _indices(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.int64)
    return a if a.flags.writeable else a.copy()


def _robot_params(robot: RobotParams, gravity: np.ndarray) -> np.ndarray:
    """The robot, gravity and the feasibility constants as one float array (layout above);
    the last few are kept by the robot's identity, as a planner asks for the same robot
    thousands of times, with its gravity (scoring) and without (the lattice's reach tests)."""
    g_x, g_y = float(gravity[0]), float(gravity[1])
    key = (id(robot), g_x, g_y)
    hit = _LAST_PARAMS.get(key)
    if hit is not None and hit[0] is robot:
        return hit[1]
    params = _pack_robot(robot, g_x, g_y)
    if len(_LAST_PARAMS) >= 8:
        _LAST_PARAMS.clear()
    _LAST_PARAMS[key] = (robot, params)
    return params


_LAST_PARAMS: dict[tuple[int, float, float], tuple[RobotParams, np.ndarray]] = {}


@lru_cache(maxsize=16)
def _pack_robot(robot: RobotParams, g_x: float, g_y: float) -> np.ndarray:
    p = np.empty(_N_PARAMS)
    p[_SHOULDER:_SHOULDER + 8] = robot.shoulder_array.ravel()
    p[_DIRECTION:_DIRECTION + 4] = robot.shoulder_directions
    p[_RANGE] = robot.shoulder_range
    p[_L_LO], p[_L_HI] = robot.boom_length
    p[_F_LO], p[_F_HI] = robot.boom_tension
    p[_TORQUE_MAX] = robot.shoulder_torque_max
    p[_GRIPPER_MASS] = robot.gripper_mass
    p[_DENSITY] = robot.boom_linear_density
    p[_BODY_MASS] = robot.body_mass
    p[_WIDTH], p[_HEIGHT] = robot.body_size
    p[_LOG_P_MIN] = robot.log_p_min
    p[_GRAVITY], p[_GRAVITY + 1] = g_x, g_y
    p[_MOMENT_SCALE] = 1.0 / float(np.linalg.norm(robot.shoulder_array, axis=1).max())
    p[_MIN_CONDITIONING] = MIN_CONDITIONING
    p[_REGULARISATION] = REGULARISATION
    p[_STATICS_TOL] = STATICS_TOL
    p[_CLEARANCE] = ANCHOR_CLEARANCE
    # A feasible pose has r = sum_i log P_i >= log p_min with every term <= 0, so each grasp's
    # z is at least Phi^-1(p_min); the margin keeps the bound from deciding a rounding tie.
    p_min = math.exp(robot.log_p_min)
    p[_Z_FLOOR] = NormalDist().inv_cdf(p_min) - 1e-6 if 0.0 < p_min < 1.0 else -math.inf
    p[_MAX_PULL] = robot.max_pull_angle
    return p


_ROCK_CACHE: weakref.WeakKeyDictionary[Rock, tuple[np.ndarray, np.ndarray, np.ndarray]] = (
    weakref.WeakKeyDictionary())


def _packed_rock(rock: Rock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges (E, 4: x0, y0, x1, y1), the polygon of each edge (E,) and one vertex per polygon
    (W, 2), packed once per Rock."""
    packed = _ROCK_CACHE.get(rock)
    if packed is None:
        if rock.polygons:
            edges = np.hstack([rock.edge_start, rock.edge_end])
            owner = np.repeat(np.arange(len(rock.polygons)), [len(p) for p in rock.polygons])
            vertices = np.array(rock.vertex, dtype=float)
        else:
            edges, owner, vertices = np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros((0, 2))
        packed = (np.ascontiguousarray(edges, dtype=float), owner.astype(np.int64),
                  np.ascontiguousarray(vertices))
        _ROCK_CACHE[rock] = packed
    return packed


# ---------------------------------------------------------------------------------------------
# Special functions (scipy.special's algorithms: xsf log_ndtr, Faddeeva erfcx)


@njit(cache=True, error_model="numpy")
def _erfcx_nonnegative(x: float) -> float:
    if x < 26.0:
        # erfc(x) exp(x^2), with the rounding error of x^2 restored (Dekker's exact product):
        # exp would otherwise turn it into a relative error of up to 7e-14.
        xx = x * x
        t = _SPLIT * x
        hi = t - (t - x)
        lo = x - hi
        err = ((hi * hi - xx) + 2.0 * hi * lo) + lo * lo
        return math.erfc(x) * math.exp(xx) * (1.0 + err)
    if x < 50.0:  # asymptotic series; its 9th term is below 1e-20 here
        inv2 = 0.5 / (x * x)
        term, total = 1.0, 1.0
        for n in range(1, 10):
            term *= -(2 * n - 1) * inv2
            total += term
        return _INV_SQRT_PI / x * total
    if x < 5e7:  # Faddeeva's continued fraction, as scipy
        return _INV_SQRT_PI * ((x * x) * (x * x + 4.5) + 2) / (x * ((x * x) * (x * x + 5) + 3.75))
    return _INV_SQRT_PI / x


@njit(cache=True, error_model="numpy")
def erfcx(x: float) -> float:
    """The scaled complementary error function exp(x^2) erfc(x) (scipy.special.erfcx)."""
    if x < 0.0:
        if x < -26.7:
            return math.inf
        if x < -6.1:
            return 2.0 * math.exp(x * x)
        return 2.0 * math.exp(x * x) - _erfcx_nonnegative(-x)
    return _erfcx_nonnegative(x)


@njit(cache=True, error_model="numpy")
def log_ndtr(x: float) -> float:
    """log Phi(x), as scipy.special.log_ndtr computes it."""
    t = x * _SQRT1_2
    if x < -1.0:
        return math.log(erfcx(-t) / 2) - t * t
    # scipy's erfc (cephes) is exp(-t^2) times a rational function from t = 1 on; computing it
    # the same way keeps the far tail (log Phi ~ -1e-100) within rounding of scipy's.
    if t < 1.0:
        upper = math.erfc(t)
    elif -t * t < -_CEPHES_MAXLOG:  # cephes returns 0 where exp(-t^2) would be subnormal
        upper = 0.0
    else:
        upper = math.exp(-t * t) * _erfcx_nonnegative(t)
    return math.log1p(-upper / 2)


@njit(cache=True, error_model="numpy")
def mills_ratio(z: float) -> float:
    """phi(z) / Phi(z), as grasp.mills_ratio computes it."""
    return _SQRT_2_OVER_PI / erfcx(-z * _INV_SQRT2)


# ---------------------------------------------------------------------------------------------
# Small dense linear algebra


@njit(cache=True, error_model="numpy")
def _det3(M: np.ndarray) -> float:
    return (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
            - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
            + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))


@njit(cache=True, error_model="numpy")
def _solve3(M: np.ndarray, rhs: np.ndarray, out: np.ndarray) -> None:
    """out = M^-1 rhs by Gaussian elimination with partial pivoting (M, rhs overwritten)."""
    for k in range(3):
        p = k
        for i in range(k + 1, 3):
            if abs(M[i, k]) > abs(M[p, k]):
                p = i
        if p != k:
            for j in range(3):
                M[k, j], M[p, j] = M[p, j], M[k, j]
            rhs[k], rhs[p] = rhs[p], rhs[k]
        for i in range(k + 1, 3):
            m = M[i, k] / M[k, k]
            for j in range(k + 1, 3):
                M[i, j] -= m * M[k, j]
            rhs[i] -= m * rhs[k]
    for k in range(2, -1, -1):
        s = rhs[k]
        for j in range(k + 1, 3):
            s -= M[k, j] * out[j]
        out[k] = s / M[k, k]


@njit(cache=True, error_model="numpy", inline="always")  # inlined: see _release_r
def _solve_without(A: np.ndarray, j: int, rhs: np.ndarray, out: np.ndarray) -> float:
    """out = the tensions of the three columns of A other than j (in order) that balance
    `rhs`, by Cramer's rule; returns the determinant of those columns. A 3-stance's statics:
    the kernel's 3-stance rows and its release 3-stances (`_release_r`) both solve through
    it, so that they decide alike, bit for bit; a third of the cost of elimination, and
    accurate wherever the conditioning test (MIN_CONDITIONING) can pass."""
    p = 0 if j != 0 else 1
    q = p + 1 if p + 1 != j else p + 2
    t = q + 1 if q + 1 != j else q + 2
    # cross products of the column pairs: each numerator is rhs . (one x other)
    qt0 = A[1, q] * A[2, t] - A[2, q] * A[1, t]
    qt1 = A[2, q] * A[0, t] - A[0, q] * A[2, t]
    qt2 = A[0, q] * A[1, t] - A[1, q] * A[0, t]
    tp0 = A[1, t] * A[2, p] - A[2, t] * A[1, p]
    tp1 = A[2, t] * A[0, p] - A[0, t] * A[2, p]
    tp2 = A[0, t] * A[1, p] - A[1, t] * A[0, p]
    pq0 = A[1, p] * A[2, q] - A[2, p] * A[1, q]
    pq1 = A[2, p] * A[0, q] - A[0, p] * A[2, q]
    pq2 = A[0, p] * A[1, q] - A[1, p] * A[0, q]
    det = A[0, p] * qt0 + A[1, p] * qt1 + A[2, p] * qt2
    out[0] = (rhs[0] * qt0 + rhs[1] * qt1 + rhs[2] * qt2) / det
    out[1] = (rhs[0] * tp0 + rhs[1] * tp1 + rhs[2] * tp2) / det
    out[2] = (rhs[0] * pq0 + rhs[1] * pq1 + rhs[2] * pq2) / det
    return det


@njit(cache=True, error_model="numpy")
def _smallest_singular_value(B: np.ndarray, k: int) -> float:
    """The smallest singular value of the 3 x k matrix B[:, :k] (k >= 3; B overwritten), by
    one-sided Jacobi on its rows: accurate to about eps times the largest one."""
    for _ in range(40):
        rotated = False
        for p in range(2):
            for q in range(p + 1, 3):
                alpha = beta = gamma = 0.0
                for j in range(k):
                    alpha += B[p, j] * B[p, j]
                    beta += B[q, j] * B[q, j]
                    gamma += B[p, j] * B[q, j]
                if abs(gamma) <= 1e-15 * math.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = c * t
                for j in range(k):
                    bp, bq = B[p, j], B[q, j]
                    B[p, j] = c * bp - s * bq
                    B[q, j] = s * bp + c * bq
        if not rotated:
            break
    smallest = math.inf
    for p in range(3):
        norm2 = 0.0
        for j in range(k):
            norm2 += B[p, j] * B[p, j]
        smallest = min(smallest, math.sqrt(norm2))
    return smallest


@njit(cache=True, error_model="numpy")
def _singular_value_above(B: np.ndarray, k: int, tau: float) -> int:
    """Whether the smallest singular value of the 3 x k matrix B[:, :k] is at least tau: 1 or 0
    where Sylvester's criterion on B B^T - tau^2 I decides it by a wide margin (1e-9 relative,
    far above rounding), -1 where it is too close to call (then ask the SVD)."""
    g00 = g01 = g02 = g11 = g12 = g22 = 0.0
    for j in range(k):
        g00 += B[0, j] * B[0, j]
        g01 += B[0, j] * B[1, j]
        g02 += B[0, j] * B[2, j]
        g11 += B[1, j] * B[1, j]
        g12 += B[1, j] * B[2, j]
        g22 += B[2, j] * B[2, j]
    scale = g00 + g11 + g22  # >= the largest eigenvalue of B B^T
    t2 = tau * tau
    a00, a11, a22 = g00 - t2, g11 - t2, g22 - t2
    d1 = a00
    d2 = a00 * a11 - g01 * g01
    d3 = (a00 * (a11 * a22 - g12 * g12) - g01 * (g01 * a22 - g12 * g02)
          + g02 * (g01 * g12 - a11 * g02))
    eps = 1e-9
    if d1 > eps * scale and d2 > eps * scale * scale and d3 > eps * scale * scale * scale:
        return 1  # B B^T - tau^2 I positive definite: every singular value above tau
    if d1 < -eps * scale or d2 < -eps * scale * scale or d3 < -eps * scale * scale * scale:
        return 0  # a negative leading minor: not positive semi-definite
    return -1


# ---------------------------------------------------------------------------------------------
# Collision (collision.Rock.segments_hit / contains, feasibility.rock_inside_body)


@njit(cache=True, error_model="numpy")
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, error_model="numpy")
def _segment_hits(ax, ay, bx, by, edges, near) -> bool:
    """Whether segment a-b crosses or touches one of the edges `near` (collision's test)."""
    lo_x, hi_x = min(ax, bx), max(ax, bx)
    lo_y, hi_y = min(ay, by), max(ay, by)
    for e in near:
        cx, cy, dx, dy = edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3]
        if (max(cx, dx) < lo_x or min(cx, dx) > hi_x or max(cy, dy) < lo_y
                or min(cy, dy) > hi_y):
            continue  # apart (collision.Rock culls the same way, per batch)
        o1 = _orient(ax, ay, bx, by, cx, cy)
        o2 = _orient(ax, ay, bx, by, dx, dy)
        o3 = _orient(cx, cy, dx, dy, ax, ay)
        o4 = _orient(cx, cy, dx, dy, bx, by)
        if o1 * o2 <= 0 and o3 * o4 <= 0 and not (o1 == 0 and o2 == 0):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _inside_rock(x, y, edges, owner, near, parity) -> bool:
    """Whether point (x, y) lies inside some polygon (even-odd rule per polygon)."""
    parity[:] = 0
    for e in near:
        x0, y0, x1, y1 = edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            parity[owner[e]] ^= 1
    return parity.any()


@njit(cache=True, error_model="numpy")
def _near_edges(poses, edges, reach) -> tuple[np.ndarray, np.ndarray]:
    """Edges that a body or boom at one of the poses can touch (within `reach` of a centre), and
    those a ray towards +x from a body corner can cross. Like collision.Rock's culling per
    batch, this only drops edges that cannot change a result."""
    x_lo, x_hi = poses[:, 0].min() - reach, poses[:, 0].max() + reach
    y_lo, y_hi = poses[:, 1].min() - reach, poses[:, 1].max() + reach
    hit = np.empty(edges.shape[0], dtype=np.int64)
    ray = np.empty(edges.shape[0], dtype=np.int64)
    n_hit = n_ray = 0
    for e in range(edges.shape[0]):
        ex_lo, ex_hi = min(edges[e, 0], edges[e, 2]), max(edges[e, 0], edges[e, 2])
        ey_lo, ey_hi = min(edges[e, 1], edges[e, 3]), max(edges[e, 1], edges[e, 3])
        if ey_hi >= y_lo and ey_lo <= y_hi and ex_hi >= x_lo:
            ray[n_ray] = e
            n_ray += 1
            if ex_lo <= x_hi:
                hit[n_hit] = e
                n_hit += 1
    return hit[:n_hit], ray[:n_ray]


# ---------------------------------------------------------------------------------------------
# The kernel


@njit(cache=True, error_model="numpy")
def _wrap(a: float) -> float:
    w = (a + math.pi) % _TWO_PI - math.pi
    return w - _TWO_PI if w >= math.pi else w


@njit(cache=True, error_model="numpy")
def _slope(t, fp, n, mu, sigma, dz, reg, curvature) -> tuple[float, float]:
    """d/dt (and d2/dt2) of the allocation objective along the tension family fp + t n."""
    d1 = 0.0
    reg1 = 0.0
    d2 = 0.0
    reg2 = 0.0
    for i in range(4):
        f = fp[i] + t * n[i]
        z = (mu[i] - f) / sigma[i]
        lam = mills_ratio(z)
        d1 += lam * dz[i]
        reg1 += f * n[i]
        if curvature:
            d2 += -lam * (z + lam) * dz[i] * dz[i]
            reg2 += n[i] * n[i]
    return d1 - reg * reg1, d2 - reg * reg2


@njit(cache=True, error_model="numpy")
def _without_column(A: np.ndarray, c: int, work: np.ndarray) -> None:
    """work = A with column c left out (the other three, in order): a 3-stance's matrix."""
    m = 0
    for j in range(4):
        if j != c:
            for r in range(3):
                work[r, m] = A[r, j]
            m += 1


@njit(cache=True, error_model="numpy")
def _limb_load(x, y, L, sh, tg, j, prm, b):
    """geometry.limb_load: the cantilevered free limb j (its boom from the shoulder sh[j] to the
    gripper at tg[j]) added to the body's load b (in place); returns its shoulder torque."""
    gx, gy = prm[_GRAVITY], prm[_GRAVITY + 1]
    m_boom = prm[_DENSITY] * L[j]
    m_grip = prm[_GRIPPER_MASS]
    tx, ty = tg[j, 0], tg[j, 1]
    px, py = sh[j, 0], sh[j, 1]
    mx, my = 0.5 * (px + tx), 0.5 * (py + ty)
    b[0] -= (m_boom + m_grip) * gx
    b[1] -= (m_boom + m_grip) * gy
    b[2] -= (m_boom * ((mx - x) * gy - (my - y) * gx)
             + m_grip * ((tx - x) * gy - (ty - y) * gx))
    return (m_boom * ((mx - px) * gy - (my - py) * gx)
            + m_grip * ((tx - px) * gy - (ty - py) * gx))


@njit(cache=True, error_model="numpy")
def _allocate4(A, b, psi, fn, ft, sn, st, f_lo, f_hi, reg, f, fp, minors, vec, work, rhs,
               w, z_floor) -> tuple[bool, bool, bool]:
    """statics.allocate for four attached booms: the most robust member of the family
    fp + t n within the tension bounds, into f (NaN where there is none). Leaves fp and the
    unnormalised null vector (minors) for the violation; returns (ok, A A^T regular, short):
    `short` when no member within the bounds gives every grasp z >= z_floor, so that none
    can be robust enough (then f is not computed; z_floor = -inf never stops it)."""
    for c in range(4):  # null vector by signed 3x3 minors
        _without_column(A, c, work)
        minors[c] = _det3(work) * (1.0 if c % 2 == 0 else -1.0)
    n_norm = math.sqrt(minors[0] * minors[0] + minors[1] * minors[1] + minors[2] * minors[2]
                       + minors[3] * minors[3])
    n, mu, sigma, dz = vec[0], vec[1], vec[2], vec[3]
    for i in range(4):
        n[i] = minors[i] / max(n_norm, 1e-300)
    for r in range(3):  # particular (minimum-norm) solution A^T (A A^T)^-1 b
        for c in range(3):
            s = 0.0
            for j in range(4):
                s += A[r, j] * A[c, j]
            work[r, c] = s
        rhs[r] = b[r]
    regular = abs(_det3(work)) > 1e-14
    if not regular:
        for r in range(3):
            for c in range(3):
                work[r, c] = 1.0 if r == c else 0.0
    _solve3(work, rhs, w)
    for i in range(4):
        fp[i] = A[0, i] * w[0] + A[1, i] * w[1] + A[2, i] * w[2]
    t_lo, t_hi = -math.inf, math.inf
    for i in range(4):
        if abs(n[i]) < 1e-12:
            inside = fp[i] >= f_lo - 1e-9 and fp[i] <= f_hi + 1e-9
            lo_i, hi_i = (-math.inf, math.inf) if inside else (math.inf, -math.inf)
        else:
            t1 = (f_lo - fp[i]) / n[i]
            t2 = (f_hi - fp[i]) / n[i]
            lo_i, hi_i = min(t1, t2), max(t1, t2)
        t_lo, t_hi = max(t_lo, lo_i), min(t_hi, hi_i)
    ok = regular and t_lo <= t_hi and n_norm > 1e-12
    if not ok:
        t_lo = t_hi = 0.0
    for i in range(4):
        if abs(psi[i]) < HALF_PI:
            sigma[i] = sn[i] + (abs(psi[i]) / HALF_PI) * (st[i] - sn[i])
            mu[i] = _mean_limit(psi[i], fn[i], ft[i])
            dz[i] = -n[i] / sigma[i]
        else:
            sigma[i], mu[i], dz[i] = 1.0, 1e6, 0.0
    if ok and z_floor > -math.inf:  # each grasp's z >= z_floor: f_i <= mu_i - z_floor sigma_i
        c_lo, c_hi = t_lo, t_hi
        for i in range(4):
            if abs(psi[i]) < HALF_PI and abs(n[i]) >= 1e-12:
                bound = (mu[i] - z_floor * sigma[i] - fp[i]) / n[i]
                if n[i] > 0.0:
                    c_hi = min(c_hi, bound)
                else:
                    c_lo = max(c_lo, bound)
            elif abs(psi[i]) < HALF_PI and fp[i] > mu[i] - z_floor * sigma[i]:
                c_lo, c_hi = math.inf, -math.inf
        if not c_lo <= c_hi:
            return ok, regular, True
    # The concave objective's slope has one root in [t_lo, t_hi]: safeguarded Newton steps
    # inside a shrinking bracket, as statics.allocate (same start, steps and order). allocate
    # always takes NEWTON_STEPS steps; here they stop once a Newton step moves t by less than
    # NEWTON_EXIT (relative), where allocate's remaining steps move it by rounding errors only.
    if not ok:
        t = math.nan
    elif _slope(t_lo, fp, n, mu, sigma, dz, reg, False)[0] <= 0.0:
        t = t_lo
    elif _slope(t_hi, fp, n, mu, sigma, dz, reg, False)[0] >= 0.0:
        t = t_hi
    else:
        lo, hi = t_lo, t_hi
        t = 0.5 * (lo + hi)
        for _ in range(NEWTON_STEPS):
            d1, d2 = _slope(t, fp, n, mu, sigma, dz, reg, True)
            if d1 > 0.0:
                lo = t
            else:
                hi = t
            step = t - d1 / d2
            inside = math.isfinite(step) and lo <= step <= hi
            if inside and abs(step - t) <= NEWTON_EXIT * (1.0 + abs(t)):
                t = step
                break
            t = step if inside else 0.5 * (lo + hi)
    for i in range(4):
        f[i] = fp[i] + t * n[i]
    return ok, regular, False


@njit(cache=True, error_model="numpy")
def _mean_limit(psi, fn, ft):
    c, s = math.cos(psi), math.sin(psi)
    return fn * ft / math.sqrt((ft * c) ** 2 + (fn * s) ** 2)


@njit(cache=True, error_model="numpy")
def _collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh, clearance, edges, owner,
                    near_hit, near_ray, parity, vertices, collide) -> int:
    """_BODY_COLLISION, _BOOM_COLLISION or 0 for the pose (x, y, phi = atan2(s, c)) whose booms
    run from the shoulders sh to the targets tg along u (collision.Rock's tests), testing the
    segments of `collide`'s bits only (ALL_SEGMENTS)."""
    if collide & 16:
        code = _body_collision(x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit,
                               near_ray, parity, vertices)
        if code:
            return code
    for i in range(4):
        if not collide & (1 << i):
            continue
        ux = u[i, 0] if math.isfinite(u[i, 0]) else 0.0
        uy = u[i, 1] if math.isfinite(u[i, 1]) else 0.0
        ex = tg[i, 0] - clearance * ux
        ey = tg[i, 1] - clearance * uy
        if _segment_hits(sh[i, 0], sh[i, 1], ex, ey, edges, near_hit):
            return _BOOM_COLLISION
    return 0


@njit(cache=True, error_model="numpy")
def _body_collision(x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit, near_ray,
                    parity, vertices) -> int:
    for q in range(4):
        cx[q] = x + (c * corner_x[q] - s * corner_y[q])
        cy[q] = y + (s * corner_x[q] + c * corner_y[q])
    for q in range(4):
        r = (q + 1) % 4
        if (_segment_hits(cx[q], cy[q], cx[r], cy[r], edges, near_hit)
                or _inside_rock(cx[q], cy[q], edges, owner, near_ray, parity)):
            return _BODY_COLLISION
    for v in range(vertices.shape[0]):  # a whole rock polygon inside the body square
        inside = True
        for q in range(4):
            r = (q + 1) % 4
            side = ((cx[r] - cx[q]) * (vertices[v, 1] - cy[q])
                    - (cy[r] - cy[q]) * (vertices[v, 0] - cx[q]))
            if not side > 0:
                inside = False
                break
        if inside:
            return _BODY_COLLISION
    return 0


@njit(cache=True, error_model="numpy")
def _reject(row, code, reason_out, r_out, lp_out, f_out, v_out) -> None:
    """decide_only: row `row` is infeasible for `code`; nothing else of it is computed."""
    reason_out[row] = code
    r_out[row] = -math.inf
    for i in range(4):
        lp_out[row, i] = math.nan
        f_out[row, i] = math.nan
    v_out[row] = math.nan


# inline="always": numba, not LLVM, inlines it; a call passing its many arrays costs as much
# as its arithmetic (the flood fill scores a feasible pose 20 % faster)
@njit(cache=True, error_model="numpy", inline="always")
def _release_r(j, x, y, L, sh, tg, u, psi, A, prm, mu, sigma, f_lo, f_hi, ignore_grasps, rhs,
               w, f, lp, B, b3) -> float:
    """r of the 3-stance with boom j's gripper at its anchor, at a pose feasible in the
    4-stance whose geometry (L, sh, tg, u, psi, A) is given; NaN where it is infeasible
    (r itself may be -inf with ignore_grasps).
    The same operations, in the same order, as `_score_kernel` on that 3-stance's row with
    decide_only and collide=0 (its boom lengths, shoulder angles, pull angles and segments
    are the 4-stance's, all passed), so the decision and r are bitwise the same, but for one
    term: the freed grasp j counts with its P at zero tension (log_ndtr(mu_j / sigma_j)), as
    at the end of the release ramp (planning.ramps), where it is unloaded but still attached
    and `rbp check` counts it; the 3-stance alone does not. `mu`
    and `sigma` are the 4-stance's allocation's (`_allocate4`): each grasp's mean limit and
    spread."""
    b3[0] = -prm[_BODY_MASS] * prm[_GRAVITY]
    b3[1] = -prm[_BODY_MASS] * prm[_GRAVITY + 1]
    b3[2] = 0.0
    torque = _limb_load(x, y, L, sh, tg, j, prm, b3)
    if abs(torque) > prm[_TORQUE_MAX]:  # the cheap tests first
        return math.nan
    rhs[0], rhs[1], rhs[2] = b3[0], b3[1], b3[2]
    ok = abs(_solve_without(A, j, rhs, w)) > 1e-12
    m = 0
    for i in range(4):
        if i != j:
            f[i] = w[m] if ok else math.nan
            m += 1
        else:
            f[i] = math.nan
    for i in range(4):  # tensions out of bounds fail statics whatever follows
        if i != j and not (math.isfinite(f[i]) and f_lo - 1e-9 <= f[i] <= f_hi + 1e-9):
            return math.nan
    if not ignore_grasps:  # every grasp's z >= Phi^-1(p_min), else r < log p_min (exact)
        for i in range(4):
            if i != j and abs(psi[i]) < HALF_PI and (mu[i] - f[i]) / sigma[i] < prm[_Z_FLOOR]:
                return math.nan
        if mu[j] / sigma[j] < prm[_Z_FLOOR]:  # the freed grasp, unloaded (below)
            return math.nan
    residual = 0.0
    for r in range(3):
        acc = 0.0
        for i in range(4):
            acc += (A[r, i] if i != j else 0.0) * (f[i] if math.isfinite(f[i]) else 0.0)
        residual = max(residual, abs(acc - b3[r]))
    statics_ok = residual < prm[_STATICS_TOL]
    r_sum = 0.0
    for i in range(4):
        if i != j:
            fi = f[i] if math.isfinite(f[i]) else 0.0
            statics_ok = statics_ok and math.isfinite(f[i]) and (
                f_lo - 1e-9 <= f[i] <= f_hi + 1e-9)
            if abs(psi[i]) < HALF_PI:
                lp[i] = log_ndtr((mu[i] - fi) / sigma[i])
            else:
                lp[i] = -math.inf
        else:  # the freed grasp at zero tension: still attached at the release ramp's end
            lp[i] = log_ndtr(mu[i] / sigma[i]) if not ignore_grasps else 0.0
        r_sum += lp[i]
    robustness = r_sum if statics_ok else -math.inf
    if not ignore_grasps:
        for i in range(4):
            if i != j and not abs(psi[i]) < prm[_MAX_PULL]:  # feasibility.pull_within
                return math.nan
    if abs(torque) > prm[_TORQUE_MAX]:
        return math.nan
    if not statics_ok:
        return math.nan
    if not ignore_grasps and robustness < prm[_LOG_P_MIN]:
        return math.nan
    m = 0
    for i in range(4):
        if i != j:
            B[0, m] = A[0, i]
            B[1, m] = A[1, i]
            B[2, m] = A[2, i] * prm[_MOMENT_SCALE]
            m += 1
    above = _singular_value_above(B, m, prm[_MIN_CONDITIONING])
    if above < 0:
        above = int(_smallest_singular_value(B, m) >= prm[_MIN_CONDITIONING])
    if not above:
        return math.nan
    return robustness


@njit(cache=True, error_model="numpy")
def _score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                  sigma_lateral, attached, tips, pose_row, stance_row, tip_row, edges, owner,
                  vertices, ignore_grasps, decide_only, collide, reason_out, r_out, lp_out, f_out,
                  v_out, release_out, body_known, release_booms, first, stride) -> None:
    """check_poses(full=True) and violation for each row (see score_rows), into the outputs.

    `release_out` (R, 4) or (0, 4): with decide_only, for each feasible 4-stance row, the r of
    the 3-stance with boom j's gripper still at its anchor, for the booms j of the bits of
    `release_booms` (NaN where infeasible, and for the other booms): what
    score_rows gives for that row with collide=0, from this row's geometry (`_release_r`).
    `body_known` (R,) int8 or (0,): with decide_only, whether each row's body is known clear
    of rock (1), known in it (2) or not known (0, then tested where needed and filled in): the
    body's test depends on the pose alone, so the flood fill shares it across stances.
    Rows of chunks `first`, `first + stride`, ... of ROW_CHUNK rows are scored (0 and 1: all;
    `_score_interleaved` gives each thread its share), the others' outputs left as they are.

    With `decide_only` a row stops at its first failing test (kinematics, collisions, then the
    allocation's tests, the conditioning last) and its violation is NaN: feasibility, and the
    robustness, log-probabilities and tensions of feasible rows, are as without it; the
    reason of an infeasible row is one failing test, not always the first."""
    L_lo, L_hi, rng = prm[_L_LO], prm[_L_HI], prm[_RANGE]
    f_lo, f_hi = prm[_F_LO], prm[_F_HI]
    gx, gy = prm[_GRAVITY], prm[_GRAVITY + 1]
    reg = prm[_REGULARISATION]
    log_p_min = prm[_LOG_P_MIN]
    half_w, half_h = prm[_WIDTH] / 2, prm[_HEIGHT] / 2
    corner_x = np.array([half_w, -half_w, -half_w, half_w])
    corner_y = np.array([half_h, half_h, -half_h, -half_h])
    has_rock = edges.shape[0] > 0
    shoulder_reach = 0.0
    for i in range(4):
        sx, sy = prm[_SHOULDER + 2 * i], prm[_SHOULDER + 2 * i + 1]
        shoulder_reach = max(shoulder_reach, math.sqrt(sx * sx + sy * sy))
    # Every segment tested for collision lies within this distance of its pose's centre (a
    # boom is tested only once its length is within bounds).
    reach = max(shoulder_reach + L_hi, math.sqrt(half_w * half_w + half_h * half_h)) + 1.0
    dir_cos = np.empty(4)
    dir_sin = np.empty(4)
    for i in range(4):
        dir_cos[i], dir_sin[i] = math.cos(prm[_DIRECTION + i]), math.sin(prm[_DIRECTION + i])
    # the shoulder test's limit as a cosine (-2: every direction is within a range of pi)
    cos_range = math.cos(rng + 1e-12) if rng + 1e-12 < math.pi else -2.0
    near_hit, near_ray = _near_edges(poses, edges, reach)
    parity = np.zeros(vertices.shape[0], dtype=np.int64)
    # Per-pose scratch.
    L = np.empty(4)
    theta = np.empty(4)
    sh = np.empty((4, 2))     # shoulders in the world
    off = np.empty((4, 2))    # R(phi) s_i
    tg = np.empty((4, 2))     # targets
    u = np.empty((4, 2))
    psi = np.empty(4)
    A = np.empty((3, 4))
    b = np.empty(3)
    b3 = np.empty(3)  # a release 3-stance's load (_release_r)
    f = np.empty(4)
    fp = np.empty(4)
    minors = np.empty(4)
    vec = np.empty((4, 4))
    lp = np.empty(4)
    work = np.empty((3, 3))
    rhs = np.empty(3)
    w = np.empty(3)
    B = np.empty((3, 4))
    cx = np.empty(4)
    cy = np.empty(4)
    for row in range(pose_row.shape[0]):
        if (row // ROW_CHUNK) % stride != first:  # another thread's (_score_interleaved)
            continue
        if release_out.shape[0]:
            for j in range(4):
                release_out[row, j] = math.nan
        k, sk, tk = pose_row[row], stance_row[row], tip_row[row]
        att = attached[sk]
        free = -1
        for i in range(4):
            if not att[i]:
                free = i
        if free >= 0 and not (math.isfinite(tips[tk, 0]) and math.isfinite(tips[tk, 1])):
            raise ValueError("a 3-stance row needs a finite free-gripper position")
        x, y, phi = poses[k, 0], poses[k, 1], poses[k, 2]
        c, s = math.cos(phi), math.sin(phi)
        fn, ft = f_normal[sk], f_lateral[sk]
        sn, st = sigma_normal[sk], sigma_lateral[sk]
        # -- geometry (geometry.boom_geometry, statics.statics_problem)
        reach_code = 0
        for i in range(4):
            sx, sy = prm[_SHOULDER + 2 * i], prm[_SHOULDER + 2 * i + 1]
            off[i, 0], off[i, 1] = c * sx - s * sy, s * sx + c * sy
            sh[i, 0], sh[i, 1] = x + off[i, 0], y + off[i, 1]
            if att[i]:
                tg[i, 0], tg[i, 1] = positions[sk, i, 0], positions[sk, i, 1]
            else:
                tg[i, 0], tg[i, 1] = tips[tk, 0], tips[tk, 1]
            dx, dy = tg[i, 0] - sh[i, 0], tg[i, 1] - sh[i, 1]
            L[i] = math.sqrt(dx * dx + dy * dy)
            u[i, 0], u[i, 1] = dx / L[i], dy / L[i]
            if decide_only:  # a boom out of reach decides the row: the rest is not needed
                if L[i] < L_lo or L[i] > L_hi:
                    reach_code = _BOOM_LENGTH
                    break
                # The shoulder angle's cosine, clear of the limit's by 1e-9 (far beyond its
                # rounding), decides without atan2; near the limit, atan2 as below.
                cos_w = (dx * (c * dir_cos[i] - s * dir_sin[i])
                         + dy * (s * dir_cos[i] + c * dir_sin[i])) / L[i]
                if cos_w > cos_range + 1e-9:
                    theta[i] = 0.0  # within range: its value is not needed with decide_only
                elif cos_w < cos_range - 1e-9:
                    reach_code = _SHOULDER_ANGLE
                    break
                else:
                    theta[i] = _wrap(math.atan2(dy, dx) - phi - prm[_DIRECTION + i])
                    if abs(theta[i]) > rng + 1e-12:
                        reach_code = _SHOULDER_ANGLE
                        break
            else:
                theta[i] = _wrap(math.atan2(dy, dx) - phi - prm[_DIRECTION + i])
            if att[i]:
                nx, ny = normals[sk, i, 0], normals[sk, i, 1]
                vx, vy = -u[i, 0], -u[i, 1]
                psi[i] = math.atan2(nx * vy - ny * vx, nx * vx + ny * vy)
                A[0, i], A[1, i] = u[i, 0], u[i, 1]
                A[2, i] = off[i, 0] * u[i, 1] - off[i, 1] * u[i, 0]
            else:
                psi[i] = math.nan
                A[0, i] = A[1, i] = A[2, i] = 0.0
        if reach_code:
            _reject(row, reach_code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        b[0] = -prm[_BODY_MASS] * gx
        b[1] = -prm[_BODY_MASS] * gy
        b[2] = 0.0
        torque = 0.0
        if free >= 0:  # the cantilevered free limb
            torque = _limb_load(x, y, L, sh, tg, free, prm, b)
        # -- kinematic limits
        code = 0
        for i in range(4):
            if L[i] < L_lo or L[i] > L_hi:
                code = _BOOM_LENGTH
                break
        if code == 0:
            for i in range(4):
                if abs(theta[i]) > rng + 1e-12:
                    code = _SHOULDER_ANGLE
                    break
        if decide_only and code == 0:  # the grasp tests that need no tensions, first
            if not ignore_grasps:
                for i in range(4):
                    if att[i] and not abs(psi[i]) < prm[_MAX_PULL]:  # as below
                        code = _PULL_ANGLE
                        break
            if code == 0 and free >= 0 and abs(torque) > prm[_TORQUE_MAX]:
                code = _SHOULDER_TORQUE
        # -- collisions (only where they decide the reason; with decide_only after the
        # allocation's tests, which reject more poses for less)
        if code == 0 and has_rock and not decide_only:
            code = _collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh,
                                   prm[_CLEARANCE], edges, owner, near_hit, near_ray, parity,
                                   vertices, ALL_SEGMENTS)
        if decide_only and code != 0:
            _reject(row, code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        # -- force allocation (statics.allocate, statics._finish)
        if free >= 0:
            for r in range(3):
                rhs[r] = b[r]
            det = _solve_without(A, free, rhs, w)
            ok = abs(det) > 1e-12
            m = 0
            for i in range(4):
                if att[i]:
                    f[i] = w[m] if ok else math.nan
                    m += 1
                else:
                    f[i] = math.nan
            ten = 0.0  # violation: the unique tensions' excess over the bounds
            if abs(det) > 1e-9:
                for i in range(4):
                    if att[i]:
                        ten += max(0.0, f_lo - f[i]) + max(0.0, f[i] - f_hi)
            else:
                ten = 100.0
        else:
            z_floor = prm[_Z_FLOOR] if decide_only and not ignore_grasps else -math.inf
            ok, regular, short = _allocate4(A, b, psi, fn, ft, sn, st, f_lo, f_hi, reg, f, fp,
                                            minors, vec, work, rhs, w, z_floor)
            ten = 100.0
            if regular and not decide_only:  # violation: the least violating member
                ten = math.inf
                for bound in (f_lo, f_hi):
                    for q in range(4):
                        tq = (bound - fp[q]) / minors[q]
                        if not math.isfinite(tq):
                            tq = 0.0
                        total = 0.0
                        for i in range(4):
                            fi = fp[i] + tq * minors[i]
                            total += max(0.0, f_lo - fi) + max(0.0, fi - f_hi)
                        ten = min(ten, total)
            if short:  # decide_only: no member of the family is robust enough
                code = _PROBABILITY
        if decide_only and code == 0:  # tensions out of bounds fail statics whatever follows
            for i in range(4):
                if att[i] and not (math.isfinite(f[i]) and f_lo - 1e-9 <= f[i] <= f_hi + 1e-9):
                    code = _STATICS
                    break
        if decide_only and code != 0:
            _reject(row, code, reason_out, r_out, lp_out, f_out, v_out)
            continue
        residual = 0.0
        for r in range(3):
            acc = 0.0
            for i in range(4):
                acc += A[r, i] * (f[i] if math.isfinite(f[i]) else 0.0)
            residual = max(residual, abs(acc - b[r]))
        statics_ok = residual < prm[_STATICS_TOL]
        r_sum = 0.0
        for i in range(4):
            if att[i]:
                fi = f[i] if math.isfinite(f[i]) else 0.0
                statics_ok = statics_ok and math.isfinite(f[i]) and (
                    f_lo - 1e-9 <= f[i] <= f_hi + 1e-9)
                if abs(psi[i]) < HALF_PI and free < 0:  # _allocate4's mu and sigma: the same
                    lp[i] = log_ndtr((vec[1, i] - fi) / vec[2, i])
                elif abs(psi[i]) < HALF_PI:
                    sig = sn[i] + (abs(psi[i]) / HALF_PI) * (st[i] - sn[i])
                    lp[i] = log_ndtr((_mean_limit(psi[i], fn[i], ft[i]) - fi) / sig)
                else:
                    lp[i] = -math.inf
            else:
                lp[i] = 0.0
            r_sum += lp[i]
            lp_out[row, i] = lp[i]
            f_out[row, i] = f[i]
        robustness = r_sum if statics_ok else -math.inf
        r_out[row] = robustness
        # -- the grasp and statics tests (feasibility.check_poses' order)
        if code == 0 and not ignore_grasps:
            for i in range(4):
                if att[i] and not abs(psi[i]) < prm[_MAX_PULL]:  # feasibility.pull_within
                    code = _PULL_ANGLE
                    break
        if code == 0 and free >= 0 and abs(torque) > prm[_TORQUE_MAX]:
            code = _SHOULDER_TORQUE
        if decide_only:  # the cheap tests first, the conditioning only where they all pass
            if code == 0 and not statics_ok:
                code = _STATICS
            if code == 0 and not ignore_grasps and robustness < log_p_min:
                code = _PROBABILITY
            if code == 0 and has_rock:
                segments = collide
                if body_known.shape[0] and collide & 16:  # the body's test, shared by stances
                    if body_known[row] == 0:
                        body_known[row] = 2 if _body_collision(
                            x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit,
                            near_ray, parity, vertices) else 1
                    if body_known[row] == 2:
                        code = _BODY_COLLISION
                    segments = collide & ~16
                if code == 0:
                    code = _collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh,
                                           prm[_CLEARANCE], edges, owner, near_hit, near_ray,
                                           parity, vertices, segments)
            if code != 0:
                reason_out[row] = code
                v_out[row] = math.nan
                continue
        m = 0
        for i in range(4):
            if att[i]:
                B[0, m] = A[0, i]
                B[1, m] = A[1, i]
                B[2, m] = A[2, i] * prm[_MOMENT_SCALE]
                m += 1
        if decide_only:  # only kappa < MIN_CONDITIONING matters: decided cheaply if clear-cut
            above = _singular_value_above(B, m, prm[_MIN_CONDITIONING])
            if above < 0:
                above = int(_smallest_singular_value(B, m) >= prm[_MIN_CONDITIONING])
            kappa = math.inf if above else 0.0
        else:
            kappa = _smallest_singular_value(B, m)
        if code == 0 and kappa < prm[_MIN_CONDITIONING]:
            code = _SINGULAR
        if code == 0 and not statics_ok:
            code = _STATICS
        if code == 0 and not ignore_grasps and robustness < log_p_min:
            code = _PROBABILITY
        reason_out[row] = code
        if decide_only:
            v_out[row] = math.nan
            if release_out.shape[0] and code == 0 and free < 0:
                for j in range(4):
                    if not release_booms & (1 << j):
                        continue
                    release_out[row, j] = _release_r(
                        j, x, y, L, sh, tg, u, psi, A, prm, vec[1], vec[2], f_lo, f_hi,
                        ignore_grasps, rhs, w, f, lp, B, b3)
            continue
        # -- feasibility.violation
        v = 0.0
        for i in range(4):
            v += (max(0.0, L[i] - L_hi) + max(0.0, L_lo - L[i])
                  + max(0.0, abs(theta[i]) - rng))
        if code in (_BODY_COLLISION, _BOOM_COLLISION):
            v += 1.0
        v += ten / 10.0
        if free >= 0:
            v += max(0.0, abs(torque) - prm[_TORQUE_MAX]) / max(prm[_TORQUE_MAX], 1e-9)
        v += max(0.0, prm[_MIN_CONDITIONING] - kappa) / prm[_MIN_CONDITIONING]
        if not ignore_grasps:
            pull = 0.0
            for i in range(4):
                if att[i]:
                    pull += max(0.0, abs(psi[i]) - (prm[_MAX_PULL] - 1e-3))
            v += pull
            r = robustness if math.isfinite(robustness) else log_p_min - 1.0
            if statics_ok:
                v += max(0.0, log_p_min - r)
        v_out[row] = 0.0 if code == 0 else max(v, 1e-6)


# ---------------------------------------------------------------------------------------------
# Rows scored on several threads (the complete search's flood fills and moves)

# Threads take rows in chunks this long: interleaved row by row, two threads wrote to the same
# cache lines of every output (a flood fill ran 6 % slower on two threads).
ROW_CHUNK = 16
MIN_ROWS_PER_THREAD = 12  # fewer: one thread scores them (a launch and join cost a few us)


def kernel_threads() -> int:
    """Threads the complete search's compiled flood fills and moves use: RBP_THREADS if set,
    else numba's count (this machine's cores unless NUMBA_NUM_THREADS says fewer); a worker
    pool gives each worker its share of the cores (`experiments.sweep`). Results are the
    same, row for row, on any number of threads. Inside `held_kernel_threads`, the count read
    as the block began."""
    if _HELD_THREADS:
        return _HELD_THREADS[-1]
    value = os.environ.get("RBP_THREADS", "").strip()
    threads = int(value) if value else numba.config.NUMBA_NUM_THREADS
    return max(1, min(threads, numba.config.NUMBA_NUM_THREADS))


_HELD_THREADS: list[int] = []


@contextmanager
def held_kernel_threads() -> Iterator[int]:
    """`kernel_threads()` read once and held for a block: a search asks for it thousands of
    times, and reading the environment each time cost 1 % of a proof."""
    _HELD_THREADS.append(kernel_threads())
    try:
        yield _HELD_THREADS[-1]
    finally:
        _HELD_THREADS.pop()


@njit(cache=True, parallel=True, error_model="numpy")
def _score_interleaved(threads, poses, prm, positions, normals, f_normal, f_lateral,
                       sigma_normal, sigma_lateral, attached, tips, pose_row, stance_row,
                       tip_row, edges, owner, vertices, ignore_grasps, decide_only, collide,
                       reason_out, r_out, lp_out, f_out, v_out, release_out, body_known,
                       release_booms) -> None:  # pragma: no cover - compiled
    """`_score_kernel` with thread t scoring chunks t, t + threads, t + 2 threads, ... of
    ROW_CHUNK rows: the same outputs, row for row (each row is scored on its own and writes its
    own entries), and feasible and infeasible rows, which differ fivefold in cost, shared
    evenly."""
    for t in prange(threads):
        _score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                      sigma_lateral, attached, tips, pose_row, stance_row, tip_row, edges,
                      owner, vertices, ignore_grasps, decide_only, collide, reason_out, r_out,
                      lp_out, f_out, v_out, release_out, body_known, release_booms, np.int64(t),
                      threads)


@njit(cache=True, error_model="numpy")
def _score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                   sigma_lateral, attached, tips, pose_row, stance_row, tip_row, edges, owner,
                   vertices, ignore_grasps, decide_only, collide, reason_out, r_out, lp_out,
                   f_out, v_out, release_out, body_known,
                   release_booms) -> None:  # pragma: no cover - compiled
    """`_score_kernel`, on up to `threads` threads where the rows are many enough."""
    use = min(threads, pose_row.shape[0] // MIN_ROWS_PER_THREAD)
    if use > 1:
        _score_interleaved(use, poses, prm, positions, normals, f_normal, f_lateral,
                           sigma_normal, sigma_lateral, attached, tips, pose_row, stance_row,
                           tip_row, edges, owner, vertices, ignore_grasps, decide_only, collide,
                           reason_out, r_out, lp_out, f_out, v_out, release_out, body_known,
                           release_booms)
    else:
        _score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                      sigma_lateral, attached, tips, pose_row, stance_row, tip_row, edges,
                      owner, vertices, ignore_grasps, decide_only, collide, reason_out, r_out,
                      lp_out, f_out, v_out, release_out, body_known, release_booms, np.int64(0),
                      np.int64(1))


# ---------------------------------------------------------------------------------------------
# The flood fill of the complete search's components (planning.flood)


@njit(cache=True, error_model="numpy")
def flood_kernel(seed, box, dx, dphi, n_phi, prm, positions, normals, f_normal, f_lateral,
                  sigma_normal, sigma_lateral, attached, tips, edges, owner, vertices,
                  ignore_grasps, decide_only, collide, body, body_origin,
                  threads):  # pragma: no cover - compiled
    """The lattice poses 26-connected to `seed` that are feasible in stance row 0, inside
    `box` (planning.flood.grow_component): (indices, robustness, release r (F, 4; NaN where
    boom j may not let go), indices scored infeasible). Waves of poses, each scored in one
    `_score_kernel` call (decide_only), which also scores the four release 3-stances of each
    feasible pose (`_release_r`). `decide_only` (True) and `collide` (ALL_SEGMENTS) come in as
    arguments, not literals, so that `_score_kernel` is called with the types Python calls it
    with: one compilation serves both. `body` (I, K, n_phi) int8, lattice index (i, k, m) at
    [i - body_origin[0], k - body_origin[1], m + n_phi // 2]: the body's collision test of
    each pose (0 unknown, 1 clear, 2 in rock), read and filled in (`_score_kernel`'s
    body_known); poses outside it are tested each time."""
    i0, k0, m0 = box[0, 0], box[0, 1], -(n_phi // 2)
    ni, nk = box[1, 0] - i0 + 1, box[1, 1] - k0 + 1
    state = np.zeros((ni, nk, n_phi), dtype=np.int8)  # 0 unseen, 1 queued
    wave = np.empty((64, 3), dtype=np.int64)
    wave[0] = seed
    n_wave = 1
    state[seed[0] - i0, seed[1] - k0, seed[2] - m0] = 1
    out = np.empty((256, 3), dtype=np.int64)
    out_r = np.empty(256)
    out_rel = np.empty((256, 4))
    n_out = 0
    bad = np.empty((256, 3), dtype=np.int64)
    n_bad = 0
    nxt = np.empty((256, 3), dtype=np.int64)
    while n_wave:
        poses = np.empty((n_wave, 3))
        for w in range(n_wave):
            poses[w, 0] = wave[w, 0] * dx
            poses[w, 1] = wave[w, 1] * dx
            poses[w, 2] = wave[w, 2] * dphi
        rows = np.arange(n_wave)
        zeros = np.zeros(n_wave, dtype=np.int64)
        reason = np.empty(n_wave, dtype=np.int64)
        r = np.empty(n_wave)
        rel = np.empty((n_wave, 4))
        known = np.zeros(n_wave, dtype=np.int8)
        for w in range(n_wave):
            a = wave[w, 0] - body_origin[0]
            b = wave[w, 1] - body_origin[1]
            if 0 <= a < body.shape[0] and 0 <= b < body.shape[1]:
                known[w] = body[a, b, wave[w, 2] - m0]
        _score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral,
                       sigma_normal, sigma_lateral, attached, tips, rows, zeros, zeros, edges,
                       owner, vertices, ignore_grasps, decide_only, collide, reason, r,
                       np.empty((n_wave, 4)), np.empty((n_wave, 4)), np.empty(n_wave), rel,
                       known, np.int64(15))
        for w in range(n_wave):
            a = wave[w, 0] - body_origin[0]
            b = wave[w, 1] - body_origin[1]
            if known[w] and 0 <= a < body.shape[0] and 0 <= b < body.shape[1]:
                body[a, b, wave[w, 2] - m0] = known[w]
        n_next = 0
        for w in range(n_wave):
            if reason[w] != 0:
                if n_bad == bad.shape[0]:
                    bad = _grown(bad)
                bad[n_bad] = wave[w]
                n_bad += 1
                continue
            if n_out == out.shape[0]:
                out = _grown(out)
                out_rel = _grown(out_rel)
                grown_r = np.empty(2 * out_r.shape[0])
                grown_r[:n_out] = out_r
                out_r = grown_r
            out[n_out] = wave[w]
            out_r[n_out] = r[w]
            out_rel[n_out] = rel[w]
            n_out += 1
            for di in range(-1, 2):
                a = wave[w, 0] + di - i0
                if a < 0 or a >= ni:
                    continue
                for dk in range(-1, 2):
                    b = wave[w, 1] + dk - k0
                    if b < 0 or b >= nk:
                        continue
                    for dm in range(-1, 2):
                        c = wave[w, 2] + dm - m0
                        if c < 0 or c >= n_phi or state[a, b, c]:
                            continue
                        state[a, b, c] = 1
                        if n_next == nxt.shape[0]:
                            nxt = _grown(nxt)
                        nxt[n_next, 0] = a + i0
                        nxt[n_next, 1] = b + k0
                        nxt[n_next, 2] = c + m0
                        n_next += 1
        wave, nxt = nxt, wave
        n_wave = n_next
    return out[:n_out].copy(), out_r[:n_out].copy(), out_rel[:n_out].copy(), bad[:n_bad].copy()


@njit(cache=True)
def component_arrays(idx, r, release_r, bad, span, n_phi):  # pragma: no cover - compiled
    """A flood fill's output as planning.components keeps it: the component's lattice keys
    (planning.lattice.pack) ascending, with its r, whether each boom may let go and that
    3-stance's r (-inf where it may not) in the same order; the rows at which boom j may let
    go, ascending, concatenated (boom j's from starts[j] to starts[j + 1]); the smallest and
    largest lattice (i, k); and the keys of the infeasible poses scored."""
    F = idx.shape[0]
    keys = np.empty(F, dtype=np.int64)
    for q in range(F):
        keys[q] = _pack(idx[q, 0], idx[q, 1], idx[q, 2], span, n_phi)
    order = np.argsort(keys)  # keys are distinct: one order, whatever the sort
    keys = keys[order]
    r_out = np.empty(F)
    release = np.empty((F, 4), dtype=np.bool_)
    rel_out = np.empty((F, 4))
    counts = np.zeros(4, dtype=np.int64)
    box = np.empty((2, 2), dtype=np.int64)
    box[0, 0] = box[0, 1] = np.iinfo(np.int64).max
    box[1, 0] = box[1, 1] = np.iinfo(np.int64).min
    for q in range(F):
        o = order[q]
        r_out[q] = r[o]
        for j in range(4):
            ok = not math.isnan(release_r[o, j])
            release[q, j] = ok
            rel_out[q, j] = release_r[o, j] if ok else -math.inf
            counts[j] += ok
        for d in range(2):
            box[0, d] = min(box[0, d], idx[o, d])
            box[1, d] = max(box[1, d], idx[o, d])
    starts = np.zeros(5, dtype=np.int64)
    for j in range(4):
        starts[j + 1] = starts[j] + counts[j]
    rows = np.empty(starts[4], dtype=np.int64)
    fill = starts[:4].copy()
    for j in range(4):
        for q in range(F):
            if release[q, j]:
                rows[fill[j]] = q
                fill[j] += 1
    bad_keys = np.empty(bad.shape[0], dtype=np.int64)
    for q in range(bad.shape[0]):
        bad_keys[q] = _pack(bad[q, 0], bad[q, 1], bad[q, 2], span, n_phi)
    return keys, r_out, release, rel_out, rows, starts, box, bad_keys


@njit(cache=True)
def _pack(i, k, m, span, n_phi):  # pragma: no cover - compiled
    """planning.lattice.pack of one index."""
    return ((i + span // 2) * span + (k + span // 2)) * n_phi + (m + n_phi // 2)


@njit(cache=True, error_model="numpy")
def _grown(a):  # pragma: no cover - compiled
    b = np.empty((2 * a.shape[0], a.shape[1]), dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


def reach_violation(robot: RobotParams, poses: np.ndarray, targets: np.ndarray,
                    booms: np.ndarray) -> np.ndarray:
    """`geometry.reach(robot, poses, targets, booms).violation`, compiled: per pose and k, how
    far boom booms[k] is from reaching targets[k] (m + rad; 0 where it reaches), (P, K).
    The transition search ranks thousands of random poses by it per stance."""
    poses = np.ascontiguousarray(poses, dtype=float).reshape(-1, 3)
    targets = np.ascontiguousarray(targets, dtype=float).reshape(-1, 2)
    booms = np.ascontiguousarray(booms, dtype=np.int64).reshape(-1)
    if len(booms) != len(targets):
        raise ValueError(f"{len(booms)} booms for {len(targets)} targets")
    return _reach_kernel(poses, targets, booms, _robot_params(robot, np.zeros(2)))


@njit(cache=True)
def _reach_kernel(poses, targets, booms, params):  # pragma: no cover - compiled
    P, K = poses.shape[0], targets.shape[0]
    out = np.empty((P, K))
    lo, hi, rng = params[_L_LO], params[_L_HI], params[_RANGE]
    for p in range(P):
        x, y, phi = poses[p, 0], poses[p, 1], poses[p, 2]
        c, s = math.cos(phi), math.sin(phi)
        for k in range(K):
            i = booms[k]
            sx, sy = params[_SHOULDER + 2 * i], params[_SHOULDER + 2 * i + 1]
            dx = targets[k, 0] - (x + (c * sx - s * sy))
            dy = targets[k, 1] - (y + (s * sx + c * sy))
            length = math.sqrt(dx * dx + dy * dy)
            w = (math.atan2(dy, dx) - phi - params[_DIRECTION + i] + math.pi) % _TWO_PI - math.pi
            if w >= math.pi:
                w -= _TWO_PI
            out[p, k] = (max(0.0, length - hi) + max(0.0, lo - length)
                         + max(0.0, abs(w) - rng))
    return out


# ---------------------------------------------------------------------------------------------
# The moves of a lattice component (planning.complete): which anchors a boom reaches from the
# component's release poses, and from which poses. Poses come as packed lattice keys
# (planning.lattice.pack), decoded here as lattice.poses_of(unpack(...)) does; the reach test is
# _reach_kernel's, to the bit.


@njit(cache=True)
def _decode(key, span, dx, dphi, n_phi):  # pragma: no cover - compiled
    rest = key // n_phi
    return ((rest // span - span // 2) * dx, (rest % span - span // 2) * dx,
            (key % n_phi - n_phi // 2) * dphi)


@njit(cache=True)
def _reaches(x, y, c, s, phi, tx, ty, i, params):  # pragma: no cover - compiled
    """Whether _reach_kernel's violation of boom i to (tx, ty) at pose (x, y, phi) is 0."""
    sx, sy = params[_SHOULDER + 2 * i], params[_SHOULDER + 2 * i + 1]
    dx = tx - (x + (c * sx - s * sy))
    dy = ty - (y + (s * sx + c * sy))
    length = math.sqrt(dx * dx + dy * dy)
    # The violation, a sum of non-negative terms, is 0 exactly when each term is: the length's
    # first, so that a boom out of reach costs no atan2.
    if length > params[_L_HI] or length < params[_L_LO]:
        return False
    w = (math.atan2(dy, dx) - phi - params[_DIRECTION + i] + math.pi) % _TWO_PI - math.pi
    if w >= math.pi:
        w -= _TWO_PI
    return abs(w) <= params[_RANGE]


@njit(cache=True)
def _keep_clear(rows, shoulders, tx, ty, edges, clearance, out, n_out):  # pragma: no cover
    """Append to out[n_out:] those of `rows` whose boom, from its shoulder (`shoulders`, one
    (x, y) per row) to (tx, ty), is clear of the rock's `edges` (`_score_kernel`'s test of
    that segment, to the bit); returns the new n_out. Edges apart from the box of every
    shoulder and the target are left out first (collision.Rock culls the same way): they
    cannot change a result."""
    lo_x = hi_x = tx
    lo_y = hi_y = ty
    for q in range(rows.shape[0]):
        lo_x, hi_x = min(lo_x, shoulders[q, 0]), max(hi_x, shoulders[q, 0])
        lo_y, hi_y = min(lo_y, shoulders[q, 1]), max(hi_y, shoulders[q, 1])
    near = np.empty(edges.shape[0], dtype=np.int64)
    m = 0
    for e in range(edges.shape[0]):
        if (max(edges[e, 0], edges[e, 2]) >= lo_x and min(edges[e, 0], edges[e, 2]) <= hi_x
                and max(edges[e, 1], edges[e, 3]) >= lo_y
                and min(edges[e, 1], edges[e, 3]) <= hi_y):
            near[m] = e
            m += 1
    near = near[:m]
    for q in range(rows.shape[0]):
        px, py = shoulders[q, 0], shoulders[q, 1]
        ddx, ddy = tx - px, ty - py
        length = math.sqrt(ddx * ddx + ddy * ddy)
        ux, uy = ddx / length, ddy / length
        ux = ux if math.isfinite(ux) else 0.0
        uy = uy if math.isfinite(uy) else 0.0
        if not _segment_hits(px, py, tx - clearance * ux, ty - clearance * uy, edges, near):
            out[n_out] = rows[q]
            n_out += 1
    return n_out


@njit(cache=True)
def lattice_reach_rows(keys, rows, tx, ty, boom, params, span, dx, dphi, n_phi,
                       edges):  # pragma: no cover - compiled
    """Those of `rows` (rows of `keys`, ascending) whose pose boom `boom` reaches (tx, ty)
    from, its segment to there clear of the rock's `edges` (`_score_kernel`'s test of that
    segment, to the bit: half of a move's poses fail it, and no other test is cheaper),
    ascending."""
    out = np.empty(rows.shape[0], dtype=np.int64)
    shoulders = np.empty((rows.shape[0], 2))
    n = 0
    sx, sy = params[_SHOULDER + 2 * boom], params[_SHOULDER + 2 * boom + 1]
    for q in range(rows.shape[0]):
        r = rows[q]
        x, y, phi = _decode(keys[r], span, dx, dphi, n_phi)
        c, s = math.cos(phi), math.sin(phi)
        if _reaches(x, y, c, s, phi, tx, ty, boom, params):
            out[n] = r
            shoulders[n, 0], shoulders[n, 1] = x + (c * sx - s * sy), y + (s * sx + c * sy)
            n += 1
    kept = _keep_clear(out[:n].copy(), shoulders[:n], tx, ty, edges, params[_CLEARANCE], out,
                       0)
    return out[:kept].copy()


@njit(cache=True)
def lattice_reached_anchors(keys, release_rows, starts, targets, params, span, dx, dphi,
                            n_phi):  # pragma: no cover - compiled
    """(4, K) bool: whether boom j reaches targets[k] from some row of `keys` at which it may
    let go: release_rows[starts[j]:starts[j + 1]] (boom j's release rows, concatenated)."""
    K = targets.shape[0]
    found = np.zeros((4, K), dtype=np.bool_)
    for j in range(4):
        left = K
        for q in range(starts[j], starts[j + 1]):
            if left == 0:
                break
            x, y, phi = _decode(keys[release_rows[q]], span, dx, dphi, n_phi)
            c, s = math.cos(phi), math.sin(phi)
            for k in range(K):
                if not found[j, k] and _reaches(x, y, c, s, phi, targets[k, 0], targets[k, 1],
                                                j, params):
                    found[j, k] = True
                    left -= 1
    return found


@njit(cache=True)
def lattice_move_table(keys, release_rows, starts, targets, params, span, dx, dphi, n_phi,
                       edges):  # pragma: no cover - compiled
    """Every move of a component in one pass: for boom j and target k, the rows of boom j's
    release rows (release_rows[starts[j]:starts[j + 1]], ascending) from which it reaches
    targets[k] with its segment there clear of `edges`: `lattice_reach_rows` of each (j, k),
    row for row and to the bit (the same tests, in the same arithmetic). Returns (rows,
    offsets): the rows of (j, k) are rows[offsets[j * K + k]:offsets[j * K + k + 1]]. Each
    pose is decoded once for all targets, where one call per move decoded it per target."""
    K = targets.shape[0]
    offsets = np.zeros(4 * K + 1, dtype=np.int64)
    out = np.empty(0, dtype=np.int64)
    n_out = 0
    clearance = params[_CLEARANCE]
    L_lo, L_hi, rng = params[_L_LO], params[_L_HI], params[_RANGE]
    # Clear-cut cases decided without the square root or atan2, by margins (1e-9) far beyond
    # their rounding; the rest by _reaches' own arithmetic, so the answer is its.
    far2 = (L_hi * (1.0 + 1e-9)) ** 2
    near2 = (L_lo * (1.0 - 1e-9)) ** 2
    cos_rng = math.cos(rng) if rng < math.pi else -2.0
    for j in range(4):
        sx, sy = params[_SHOULDER + 2 * j], params[_SHOULDER + 2 * j + 1]
        direction = params[_DIRECTION + j]
        first, last = starts[j], starts[j + 1]
        # (target, row, shoulder) of every reaching pair, rows ascending within a target
        cap = 64
        pair_k = np.empty(cap, dtype=np.int64)
        pair_r = np.empty(cap, dtype=np.int64)
        pair_p = np.empty((cap, 2))
        n_pair = 0
        count = np.zeros(K, dtype=np.int64)
        for q in range(first, last):
            r = release_rows[q]
            x, y, phi = _decode(keys[r], span, dx, dphi, n_phi)
            c, s = math.cos(phi), math.sin(phi)
            px, py = x + (c * sx - s * sy), y + (s * sx + c * sy)
            cu, su = math.cos(phi + direction), math.sin(phi + direction)
            for k in range(K):
                # _reaches' test, the shoulder computed once per pose
                ddx, ddy = targets[k, 0] - px, targets[k, 1] - py
                d2 = ddx * ddx + ddy * ddy
                if d2 > far2 or d2 < near2:
                    continue
                length = math.sqrt(d2)
                if length > L_hi or length < L_lo:
                    continue
                cos_w = (ddx * cu + ddy * su) / length
                if cos_w < cos_rng - 1e-9:
                    continue
                if cos_w <= cos_rng + 1e-9:  # near the shoulder's limit: atan2 decides
                    w = (math.atan2(ddy, ddx) - phi - direction + math.pi) % _TWO_PI - math.pi
                    if w >= math.pi:
                        w -= _TWO_PI
                    inside = abs(w) <= rng
                else:
                    inside = True
                if inside:
                    if n_pair == cap:
                        cap *= 2
                        grown_k = np.empty(cap, dtype=np.int64)
                        grown_r = np.empty(cap, dtype=np.int64)
                        grown_p = np.empty((cap, 2))
                        grown_k[:n_pair] = pair_k[:n_pair]
                        grown_r[:n_pair] = pair_r[:n_pair]
                        grown_p[:n_pair] = pair_p[:n_pair]
                        pair_k, pair_r, pair_p = grown_k, grown_r, grown_p
                    pair_k[n_pair] = k
                    pair_r[n_pair] = r
                    pair_p[n_pair, 0] = px
                    pair_p[n_pair, 1] = py
                    n_pair += 1
                    count[k] += 1
        # grouped by target, rows ascending (a stable counting sort)
        at = np.zeros(K + 1, dtype=np.int64)
        for k in range(K):
            at[k + 1] = at[k] + count[k]
        order = np.empty(n_pair, dtype=np.int64)
        fill = at[:K].copy()
        for p in range(n_pair):
            order[fill[pair_k[p]]] = p
            fill[pair_k[p]] += 1
        if out.shape[0] < n_out + n_pair:
            grown = np.empty(max(2 * out.shape[0], n_out + n_pair), dtype=np.int64)
            grown[:n_out] = out[:n_out]
            out = grown
        for k in range(K):
            offsets[j * K + k] = n_out
            if count[k] == 0:
                continue
            group = order[at[k]:at[k + 1]]
            n_out = _keep_clear(pair_r[group], pair_p[group], targets[k, 0], targets[k, 1],
                                edges, clearance, out, n_out)
    offsets[4 * K] = n_out
    return out[:n_out].copy(), offsets


@njit(cache=True, error_model="numpy")
def _gathered(rows, tips, table_positions, table_normals, table_f_normal, table_f_lateral,
              table_sigma_normal, table_sigma_lateral):  # pragma: no cover - compiled
    """Kernel stances (PackedStances' arrays) of `rows` (S, 4) anchor-table indices (the
    table's last row leaves a boom free) and tip points of `tips` (T,) table indices:
    `planning.transition.pack_rows`, compiled."""
    free = table_positions.shape[0] - 1
    S = rows.shape[0]
    positions = np.empty((S, 4, 2))
    normals = np.empty((S, 4, 2))
    f_normal = np.empty((S, 4))
    f_lateral = np.empty((S, 4))
    sigma_normal = np.empty((S, 4))
    sigma_lateral = np.empty((S, 4))
    attached = np.empty((S, 4), dtype=np.bool_)
    for q in range(S):
        for i in range(4):
            a = rows[q, i]
            positions[q, i, 0], positions[q, i, 1] = table_positions[a, 0], table_positions[a, 1]
            normals[q, i, 0], normals[q, i, 1] = table_normals[a, 0], table_normals[a, 1]
            f_normal[q, i], f_lateral[q, i] = table_f_normal[a], table_f_lateral[a]
            sigma_normal[q, i], sigma_lateral[q, i] = table_sigma_normal[a], table_sigma_lateral[a]
            attached[q, i] = a != free
    tip_points = np.empty((tips.shape[0], 2))
    for q in range(tips.shape[0]):
        tip_points[q, 0] = table_positions[tips[q], 0]
        tip_points[q, 1] = table_positions[tips[q], 1]
    return (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
            tip_points)


@njit(cache=True, error_model="numpy")
def transition_boom_costs(pose, prm, table_positions, table_normals, table_f_normal,
                          table_f_lateral, table_sigma_normal, table_sigma_lateral, rows, tips,
                          edges, owner, vertices, ignore_grasps, decide_only,
                          collide):  # pragma: no cover - compiled
    """Per boom, the worst -log P_i over a transition's four configurations at `pose` (3,):
    `rows` (3, 4) anchor-table indices of the old 4-stance, the 3-stance and the new 4-stance
    (the table's last row leaves a boom free), `tips` (2,) the free gripper's table rows (at
    the old anchor, at the new). `planning.footsteps.boom_costs`, the stances gathered from
    the table here and scored by `_score_kernel` as `score_rows` scores them (full mode):
    the same numbers, without a dozen numpy calls around one compiled one. `ignore_grasps`
    and `decide_only` (False) and `collide` (ALL_SEGMENTS) come in as arguments, not
    literals, so that `_score_kernel` is called with the types Python calls it with."""
    (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
     tip_points) = _gathered(rows, tips, table_positions, table_normals, table_f_normal,
                             table_f_lateral, table_sigma_normal, table_sigma_lateral)
    poses = np.empty((1, 3))
    poses[0, 0], poses[0, 1], poses[0, 2] = pose[0], pose[1], pose[2]
    stance_row = np.array([0, 1, 1, 2])
    tip_row = np.array([0, 0, 1, 0])
    lp = np.empty((4, 4))
    _score_kernel(poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                  sigma_lateral, attached, tip_points, np.zeros(4, dtype=np.int64), stance_row,
                  tip_row, edges, owner, vertices, ignore_grasps, decide_only, collide,
                  np.empty(4, dtype=np.int64), np.empty(4), lp, np.empty((4, 4)), np.empty(4),
                  np.empty((0, 4)), np.empty(0, dtype=np.int8), np.int64(15), np.int64(0),
                  np.int64(1))
    costs = np.empty(4)
    for i in range(4):  # nan_to_num's values: a free boom's NaN as 0, -inf as the largest
        worst = math.inf
        for q in range(4):
            v = lp[q, i]
            if math.isnan(v):
                v = 0.0
            elif v == -math.inf:
                v = -_LARGEST_FLOAT
            worst = min(worst, v)
        costs[i] = max(0.0, -worst)
    return costs


_LARGEST_FLOAT = np.finfo(np.float64).max


@njit(cache=True, error_model="numpy")
def lattice_move_kernel(keys, rows, boom, span, dx, dphi, n_phi, prm, table_positions,
                        table_normals, table_f_normal, table_f_lateral, table_sigma_normal,
                        table_sigma_lateral, stance_rows, tip_rows, edges, owner, vertices,
                        ignore_grasps, decide_only, collide,
                        threads):  # pragma: no cover - compiled
    """A move's two new configurations at rows `rows` of a component (keys: its lattice keys),
    in one call (planning.complete's scored transitions): stance row 0 is the 3-stance with
    the freed boom's gripper at the new anchor tips[0], tested for the segments of `collide`
    (the freed boom's: the others are the old 4-stance's, clear); where it holds, stance row 1,
    the new 4-stance, with its release r of `boom` (`_release_r`). Returns the rows where both hold,
    the new 4-stance's release r of `boom` there (the attach ramp's start) and its r: what
    `score_rows` gives for the same rows (decide_only), in two calls. The two stances come as
    anchor-table rows (`stance_rows` (2, 4), `tip_rows` (2,): `_gathered`)."""
    (positions, normals, f_normal, f_lateral, sigma_normal, sigma_lateral, attached,
     tips) = _gathered(stance_rows, tip_rows, table_positions, table_normals, table_f_normal,
                       table_f_lateral, table_sigma_normal, table_sigma_lateral)
    n = rows.shape[0]
    poses = np.empty((n, 3))
    for q in range(n):
        x, y, phi = _decode(keys[rows[q]], span, dx, dphi, n_phi)
        poses[q, 0] = x
        poses[q, 1] = y
        poses[q, 2] = phi
    zeros = np.zeros(n, dtype=np.int64)
    reason = np.empty(n, dtype=np.int64)
    _score_threads(threads, poses, prm, positions, normals, f_normal, f_lateral, sigma_normal,
                   sigma_lateral, attached, tips, np.arange(n), zeros, zeros, edges, owner,
                   vertices, ignore_grasps, decide_only, collide, reason, np.empty(n),
                  np.empty((n, 4)), np.empty((n, 4)), np.empty(n), np.empty((0, 4)),
                  np.empty(0, dtype=np.int8), np.int64(0))
    m = 0
    for q in range(n):
        if reason[q] == 0:
            m += 1
    ok = np.empty(m, dtype=np.int64)
    second = np.empty((m, 3))
    m = 0
    for q in range(n):
        if reason[q] == 0:
            ok[m] = q
            second[m] = poses[q]
            m += 1
    if m == 0:
        return np.empty(0, dtype=np.int64), np.empty(0), np.empty(0)
    ones = np.ones(m, dtype=np.int64)
    reason2 = np.empty(m, dtype=np.int64)
    r2 = np.empty(m)
    rel = np.empty((m, 4))
    _score_threads(threads, second, prm, positions, normals, f_normal, f_lateral,
                   sigma_normal, sigma_lateral, attached, tips, np.arange(m), ones, ones, edges,
                   owner, vertices, ignore_grasps, decide_only, np.int64(0), reason2, r2,
                  np.empty((m, 4)), np.empty((m, 4)), np.empty(m), rel,
                  np.empty(0, dtype=np.int8), np.int64(1) << boom)
    k = 0
    for q in range(m):
        if reason2[q] == 0 and not math.isnan(rel[q, boom]):
            k += 1
    kept = np.empty(k, dtype=np.int64)
    arrive = np.empty(k)
    r_new = np.empty(k)
    k = 0
    for q in range(m):
        if reason2[q] == 0 and not math.isnan(rel[q, boom]):
            kept[k] = rows[ok[q]]
            arrive[k] = rel[q, boom]
            r_new[k] = r2[q]
            k += 1
    return kept, arrive, r_new
