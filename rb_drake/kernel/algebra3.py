"""Small dense linear algebra for compiled code: 3x3 determinants and solves and the smallest
singular value of a 3 x k matrix, where the numpy reference calls LAPACK (a call per pose would
cost more than the arithmetic). Cofactor determinants, Gaussian elimination with partial
pivoting, Cramer's rule and a one-sided Jacobi SVD: each accurate to rounding where the kernel's
decisions need it (see `solve_without`, `singular_value_above`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def det3(M: np.ndarray) -> float:
    return (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
            - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
            + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))


@njit(cache=True, error_model="numpy")
def solve3(M: np.ndarray, rhs: np.ndarray, out: np.ndarray) -> None:
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


@njit(cache=True, error_model="numpy", inline="always")  # inlined: see allocation.release_r
def solve_without(A: np.ndarray, j: int, rhs: np.ndarray, out: np.ndarray) -> float:
    """out = the tensions of the three columns of A other than j (in order) that balance
    `rhs`, by Cramer's rule; returns the determinant of those columns. A 3-stance's statics:
    the kernel's 3-stance rows and its release 3-stances (`allocation.release_r`) both solve through
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
def smallest_singular_value(B: np.ndarray, k: int) -> float:
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
def singular_value_above(B: np.ndarray, k: int, tau: float) -> int:
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

