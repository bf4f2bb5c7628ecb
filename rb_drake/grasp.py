"""The stochastic half-ellipse limit surface of a microspine grasp, and its probabilities.

A grasp pulled with force f at pull angle psi (signed angle from the anchor's outward normal to
the pull direction) holds with probability

    P = Phi((mu(psi) - f) / sigma(psi)),
    mu(psi)    = F_n F_t / sqrt((F_t cos psi)^2 + (F_n sin psi)^2)     (a half-ellipse),
    sigma(psi) = sigma_n + |psi| / (pi/2) (sigma_t - sigma_n)           (linear in |psi|).

|psi| >= pi/2 pulls into or along the rock: probability 0 (log-probability -inf).
Every function is vectorised over numpy broadcasting. Log-probabilities use `log_ndtr`, which
stays accurate far into both tails where `log(ndtr(z))` underflows.
"""

from __future__ import annotations

import functools
import math
from types import ModuleType

import numpy as np

HALF_PI = 0.5 * math.pi
SQRT_2_OVER_PI = math.sqrt(2.0 / math.pi)
INV_SQRT2 = 1.0 / math.sqrt(2.0)


@functools.cache
def _special() -> ModuleType:
    """scipy.special, imported on first use: it takes 0.3 s, and every command reads a
    scenario through this module, also to refuse one in a line."""
    import scipy.special

    return scipy.special


def mean_limit(psi: np.ndarray, f_normal: np.ndarray | float,
               f_lateral: np.ndarray | float) -> np.ndarray:
    """mu(psi): the expected force the grasp sustains when pulled at angle psi (one anchor's
    F_n and F_t, or a stance's)."""
    c, s = np.cos(psi), np.sin(psi)
    return f_normal * f_lateral / np.sqrt((f_lateral * c) ** 2 + (f_normal * s) ** 2)


def mean_limit_derivative(psi: np.ndarray, f_normal: np.ndarray,
                          f_lateral: np.ndarray) -> np.ndarray:
    """d mu / d psi."""
    c, s = np.cos(psi), np.sin(psi)
    q = (f_lateral * c) ** 2 + (f_normal * s) ** 2
    dq = 2.0 * s * c * (f_normal**2 - f_lateral**2)
    return -0.5 * f_normal * f_lateral * dq / q**1.5


def sigma_limit(psi: np.ndarray, sigma_normal: np.ndarray,
                sigma_lateral: np.ndarray) -> np.ndarray:
    """sigma(psi): the standard deviation of the limit, linear in |psi|."""
    return sigma_normal + (np.abs(psi) / HALF_PI) * (sigma_lateral - sigma_normal)


def sigma_limit_derivative(psi: np.ndarray, sigma_normal: np.ndarray,
                           sigma_lateral: np.ndarray) -> np.ndarray:
    """d sigma / d psi (the one-sided slope sign(psi); 0 taken at psi = 0)."""
    return np.sign(psi) * (sigma_lateral - sigma_normal) / HALF_PI


def margin(force: np.ndarray, psi: np.ndarray, f_normal: np.ndarray, f_lateral: np.ndarray,
           sigma_normal: np.ndarray, sigma_lateral: np.ndarray) -> np.ndarray:
    """z = (mu - f) / sigma, the grasp's safety margin in standard deviations."""
    return (mean_limit(psi, f_normal, f_lateral) - force) / sigma_limit(
        psi, sigma_normal, sigma_lateral)


def log_prob(force: np.ndarray, psi: np.ndarray, f_normal: np.ndarray, f_lateral: np.ndarray,
             sigma_normal: np.ndarray, sigma_lateral: np.ndarray) -> np.ndarray:
    """log P of one grasp: log Phi(z), and -inf where |psi| >= pi/2."""
    psi = np.asarray(psi, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = margin(force, psi, f_normal, f_lateral, sigma_normal, sigma_lateral)
        out = _special().log_ndtr(z)
    return np.where(np.abs(psi) < HALF_PI, out, -np.inf)


def prob(force: np.ndarray, psi: np.ndarray, f_normal: np.ndarray, f_lateral: np.ndarray,
         sigma_normal: np.ndarray, sigma_lateral: np.ndarray) -> np.ndarray:
    """P of one grasp (see `log_prob`)."""
    return np.exp(log_prob(force, psi, f_normal, f_lateral, sigma_normal, sigma_lateral))


def mills_ratio(z: np.ndarray) -> np.ndarray:
    """lambda(z) = phi(z) / Phi(z) = d log Phi / dz, computed in log space (no underflow)."""
    # phi/Phi = sqrt(2/pi) / erfcx(-z/sqrt 2): stable in both tails and cheaper than log_ndtr.
    return SQRT_2_OVER_PI / _special().erfcx(-np.asarray(z, dtype=float) * INV_SQRT2)


def log_ndtr_derivatives(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """log Phi(z) and its first and second derivatives; the second is -lambda (z + lambda) < 0."""
    z = np.asarray(z, dtype=float)
    lam = mills_ratio(z)
    return _special().log_ndtr(z), lam, -lam * (z + lam)
