"""The stochastic half-ellipse limit surface: hand values, tails and derivatives."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import log_ndtr, ndtr

from rb_drake import grasp

# The shaft's anchors: F_n = 40 N, F_t = 20 N, sigma_n = 3 N, sigma_t = 5 N.
FN, FT, SN, ST = 40.0, 20.0, 3.0, 5.0
PHI_1 = 0.8413447460685429     # Phi(1), from tables
PHI_M2 = 0.022750131948179195  # Phi(-2)


def test_mean_limit_hand_values():
    cases = {
        0.0: FN,                      # pulled along the normal: F_n
        math.pi / 2: FT,              # pulled sideways: F_t
        -math.pi / 2: FT,
        # psi = pi/4: 40*20 / sqrt((20 cos 45)^2 + (40 sin 45)^2) = 800 / sqrt(200 + 800)
        #           = 800 / sqrt(1000) = 8 sqrt(10) = 25.298221281347036
        math.pi / 4: 25.298221281347036,
        -math.pi / 4: 25.298221281347036,
        # psi = pi/3: 800 / sqrt(400 * 0.25 + 1600 * 0.75) = 800 / sqrt(1300) = 22.188007849...
        math.pi / 3: 22.188007849009164,
    }
    for psi, want in cases.items():
        got = float(grasp.mean_limit(psi, FN, FT))
        assert got == pytest.approx(want, abs=1e-12), f"mu({psi:.4f}) = {got}, hand value {want}"


def test_mean_limit_vectorised_broadcast():
    psi = np.linspace(-1.5, 1.5, 7)
    fn = np.array([[40.0], [10.0]])
    got = grasp.mean_limit(psi, fn, FT)
    assert got.shape == (2, 7), f"broadcast shape {got.shape}, expected (2, 7)"
    for row, f_n in enumerate((40.0, 10.0)):
        for k, p in enumerate(psi):
            want = f_n * FT / math.sqrt((FT * math.cos(p)) ** 2 + (f_n * math.sin(p)) ** 2)
            assert got[row, k] == pytest.approx(want, rel=1e-13), (
                f"mu(psi={p:.3f}, F_n={f_n}) = {got[row, k]}, scalar formula gives {want}")


def test_sigma_linear_in_abs_psi():
    cases = {
        0.0: 3.0,                            # sigma_n
        math.pi / 2: 5.0,                    # sigma_t
        -math.pi / 2: 5.0,
        math.pi / 4: 4.0,                    # 3 + (1/2)(5 - 3)
        -math.pi / 4: 4.0,
        math.pi / 6: 3.0 + (1.0 / 3.0) * 2.0,  # 3.666...
        -math.pi / 3: 3.0 + (2.0 / 3.0) * 2.0,  # 4.333...
    }
    for psi, want in cases.items():
        got = float(grasp.sigma_limit(psi, SN, ST))
        assert got == pytest.approx(want, abs=1e-12), f"sigma({psi:.4f}) = {got}, hand {want}"


@pytest.mark.parametrize("psi", [0.0, math.pi / 4, -math.pi / 6, 1.2])
def test_probability_hand_phi_values(psi):
    mu = float(grasp.mean_limit(psi, FN, FT))
    sigma = float(grasp.sigma_limit(psi, SN, ST))
    cases = [(mu, 0.5), (mu - sigma, PHI_1), (mu + 2.0 * sigma, PHI_M2)]
    for force, want in cases:
        p = float(grasp.prob(force, psi, FN, FT, SN, ST))
        assert p == pytest.approx(want, abs=1e-12), (
            f"P(f={force:.4f}, psi={psi:.3f}) = {p}, expected Phi = {want}")
        lp = float(grasp.log_prob(force, psi, FN, FT, SN, ST))
        assert lp == pytest.approx(math.log(want), abs=1e-12), (
            f"log P(f={force:.4f}, psi={psi:.3f}) = {lp}, expected {math.log(want)}")
    z = float(grasp.margin(mu - sigma, psi, FN, FT, SN, ST))
    assert z == pytest.approx(1.0, abs=1e-12), f"margin at f = mu - sigma is {z}, expected 1"


def test_probability_decreases_with_force():
    force = np.linspace(0.0, 80.0, 201)
    p = grasp.prob(force, 0.3, FN, FT, SN, ST)
    assert np.all(np.diff(p) <= 1e-15), "P must not increase with the pulling force"
    assert p[0] == pytest.approx(1.0, abs=1e-12), f"P(f=0) = {p[0]}, expected ~1"
    assert p[-1] == pytest.approx(0.0, abs=1e-12), f"P(f=80) = {p[-1]}, expected ~0"


@pytest.mark.parametrize("psi", [math.pi / 2, -math.pi / 2, 2.0, -3.0, math.pi])
def test_pull_into_rock_is_impossible(psi):
    lp = grasp.log_prob(1.0, psi, FN, FT, SN, ST)
    p = grasp.prob(1.0, psi, FN, FT, SN, ST)
    assert np.isneginf(lp), f"|psi| = {abs(psi):.4f} >= pi/2 must give log P = -inf, got {lp}"
    assert p == 0.0, f"|psi| >= pi/2 must give P = 0, got {p}"


def test_just_inside_half_plane_is_finite():
    psi = math.pi / 2 - 1e-9
    lp = float(grasp.log_prob(1.0, psi, FN, FT, SN, ST))
    assert math.isfinite(lp), f"psi just below pi/2 must give a finite log P, got {lp}"
    want = float(log_ndtr((FT - 1.0) / ST))  # mu -> F_t = 20, sigma -> sigma_t = 5: z = 3.8
    assert lp == pytest.approx(want, abs=1e-9), f"log P just inside pi/2 = {lp}, expected {want}"


def test_log_prob_deep_tail():
    # z = (mu - f) / sigma = -40 at psi = 0: f = 40 + 40 * 3 = 160 N.
    z = -40.0
    force = FN - z * SN
    lp = float(grasp.log_prob(force, 0.0, FN, FT, SN, ST))
    with np.errstate(divide="ignore"):
        naive = float(np.log(ndtr(z)))
    assert naive == -math.inf, f"log(ndtr(-40)) should underflow to -inf, got {naive}"
    leading = -0.5 * z * z - math.log(-z) - 0.5 * math.log(2.0 * math.pi)  # -804.6084...
    assert math.isfinite(lp), f"log P at z = -40 must be finite, got {lp}"
    # The asymptotic series' next term is log(1 - 1/z^2) ~ -1/1600 = -6.25e-4.
    assert lp == pytest.approx(leading, abs=1e-3), (
        f"log P(z=-40) = {lp}, leading asymptotic value {leading}")
    series = leading + math.log(1.0 - 1.0 / z**2 + 3.0 / z**4 - 15.0 / z**6)
    assert lp == pytest.approx(series, abs=1e-9), (
        f"log P(z=-40) = {lp}, asymptotic series to O(z^-6) gives {series}")


def test_log_prob_vectorised_over_forces(rng):
    force = rng.uniform(0.0, 300.0, size=50)
    psi = rng.uniform(-1.5, 1.5, size=50)
    lp = grasp.log_prob(force, psi, FN, FT, SN, ST)
    z = grasp.margin(force, psi, FN, FT, SN, ST)
    assert np.all(np.isfinite(lp)), "every |psi| < pi/2 must give a finite log P"
    np.testing.assert_allclose(lp, log_ndtr(z), rtol=1e-14, atol=0,
                               err_msg="log_prob must equal log_ndtr(margin)")


def _central(fun, x, h):
    return (fun(x + h) - fun(x - h)) / (2.0 * h)


@pytest.mark.parametrize(("f_n", "f_t"), [(40.0, 20.0), (10.0, 25.0), (15.0, 15.0)])
def test_mean_limit_derivative_finite_difference(f_n, f_t):
    psi = np.linspace(-1.55, 1.55, 63)
    h = 1e-6
    fd = _central(lambda p: grasp.mean_limit(p, f_n, f_t), psi, h)
    got = grasp.mean_limit_derivative(psi, f_n, f_t)
    np.testing.assert_allclose(got, fd, rtol=1e-6, atol=1e-6,
                               err_msg=f"d mu/d psi vs central difference (F_n={f_n}, F_t={f_t})")
    if f_n == f_t:
        np.testing.assert_allclose(got, 0.0, atol=1e-12,
                                   err_msg="a circular limit surface has d mu/d psi = 0")


def test_sigma_limit_derivative_finite_difference():
    psi = np.concatenate([np.linspace(-1.5, -0.05, 30), np.linspace(0.05, 1.5, 30)])
    h = 1e-6
    fd = _central(lambda p: grasp.sigma_limit(p, SN, ST), psi, h)
    got = grasp.sigma_limit_derivative(psi, SN, ST)
    np.testing.assert_allclose(got, fd, rtol=1e-7, atol=1e-8,
                               err_msg="d sigma/d psi vs central difference away from psi = 0")
    slope = (ST - SN) / (math.pi / 2)  # 4/pi = 1.2732...
    np.testing.assert_allclose(np.abs(got), slope, rtol=1e-14,
                               err_msg="|d sigma/d psi| must be (sigma_t - sigma_n)/(pi/2)")
    at_zero = float(grasp.sigma_limit_derivative(0.0, SN, ST))
    assert at_zero == 0.0, f"the documented value at psi = 0 is 0, got {at_zero}"


def test_mills_ratio_is_derivative_of_log_ndtr():
    z = np.linspace(-35.0, 7.0, 85)
    h = 1e-5
    fd = _central(log_ndtr, z, h)
    got = grasp.mills_ratio(z)
    np.testing.assert_allclose(got, fd, rtol=1e-6, atol=1e-14,
                               err_msg="mills_ratio vs central difference of log_ndtr")
    lam0 = float(grasp.mills_ratio(0.0))
    want0 = 2.0 / math.sqrt(2.0 * math.pi)  # phi(0)/Phi(0) = 0.3989.../0.5 = 0.7978845608...
    assert lam0 == pytest.approx(want0, abs=1e-14), f"lambda(0) = {lam0}, hand value {want0}"
    deep = float(grasp.mills_ratio(-60.0))
    assert math.isfinite(deep) and deep == pytest.approx(60.0, rel=1e-3), (
        f"lambda(z) ~ -z deep in the left tail (no 0/0): lambda(-60) = {deep}")


def test_log_ndtr_second_derivative_finite_difference():
    z = np.linspace(-35.0, 7.0, 85)
    h = 1e-5
    value, first, second = grasp.log_ndtr_derivatives(z)
    np.testing.assert_allclose(value, log_ndtr(z), rtol=1e-15, atol=0,
                               err_msg="log_ndtr_derivatives' value must be log_ndtr")
    np.testing.assert_allclose(first, grasp.mills_ratio(z), rtol=1e-15, atol=0,
                               err_msg="the first derivative must be the Mills ratio")
    fd = _central(grasp.mills_ratio, z, h)
    np.testing.assert_allclose(second, fd, rtol=1e-6, atol=1e-12,
                               err_msg="second derivative vs central difference of mills_ratio")
    assert np.all(second < 0.0), "log Phi is strictly concave: the second derivative must be < 0"
