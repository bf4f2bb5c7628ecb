"""Special functions for compiled code: scipy.special's algorithms (xsf's log_ndtr, Faddeeva's
erfcx), scalar and njit-compiled, because numba cannot call scipy.special.

`mills_ratio` is the compiled twin of `grasp.mills_ratio` (the numpy reference, on scipy's
erfcx), with the same formula and constants; it cannot be that one, which takes arrays and
calls scipy.
"""

from __future__ import annotations

import math

from numba import njit

from rb_drake.grasp import INV_SQRT2, SQRT_2_OVER_PI

_SQRT1_2 = 0.707106781186547524400844362104849039  # M_SQRT1_2, in scipy's log_ndtr
_INV_SQRT_PI = 0.56418958354775628694807945156     # Faddeeva's ispi
_CEPHES_MAXLOG = 7.09782712893383996843e2
_SPLIT = 134217729.0                               # 2^27 + 1, Dekker's splitter


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
    return SQRT_2_OVER_PI / erfcx(-z * INV_SQRT2)

