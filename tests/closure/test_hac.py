"""The Newey-West Wald test of :mod:`accal.closure.hac`.

Data drawn here with numpy: white noise, and "firings" that put bumps into a regressor
and into the residual at the same samples with independent sizes (the linear and the
angular accelerations of a thruster firing), through a 5 × 7-sample boxcar cascade.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.distributions import chi2_sf
from accal.closure.hac import hac_wald


def _direct(z, r, lags):
    """The same statistic by its definition (loops over the lags)."""
    a = z.T @ z
    g = np.linalg.solve(a, z.T @ r)
    u = z * (r - z @ g)[:, None]
    omega = u.T @ u
    for lag in range(1, lags + 1):
        w = 1.0 - lag / (lags + 1.0)
        gam = u[:-lag].T @ u[lag:]
        omega += w * (gam + gam.T)
    a_inv = np.linalg.inv(a)
    v = a_inv @ omega @ a_inv
    return float(g @ np.linalg.solve(v, g))


@pytest.mark.parametrize("lags", [0, 1, 7, 60])
def test_the_statistic_is_its_definition(lags):
    rng = np.random.default_rng(lags)
    z = rng.normal(size=(500, 2))
    r = rng.normal(size=500) * (1 + np.abs(z[:, 0])) + 0.1 * z[:, 1]
    stat, p = hac_wald(z, r, lags)
    assert stat == pytest.approx(_direct(z, r, lags), rel=1e-10)
    assert p == pytest.approx(chi2_sf(stat, 2), rel=1e-12)


def test_no_regressor_and_a_singular_one():
    r = np.ones(10)
    assert hac_wald(np.zeros((10, 0)), r) == (0.0, 1.0)
    assert hac_wald(np.zeros((10, 1)), r) == (0.0, 1.0)


def _cascade(x):
    for _ in range(5):
        x = np.convolve(x, np.ones(7) / 7, "same")
    return x


def _firings(rng, n):
    """``(z, r)``: bumps at the same ~60 samples with independent sizes, plus noise."""
    at = rng.choice(n - 40, 60, replace=False) + 20
    zf, rf = np.zeros(n), np.zeros(n)
    zf[at], rf[at] = rng.normal(0, 30.0, at.size), rng.normal(0, 30.0, at.size)
    z = _cascade(zf + rng.normal(0, 1.0, n))
    r = _cascade(rf + rng.normal(0, 1.0, n))
    return z - z.mean(), r - r.mean()


def test_coincident_bumps_are_not_a_coupling():
    """300 draws under the null: the test holds its level where a stationary σ does not
    (the same draws referred to the residual's own autocovariance, taken as
    stationary, reject several times as often)."""
    rng = np.random.default_rng(11)
    n = 8000
    hac, stationary = 0, 0
    for _ in range(300):
        z, r = _firings(rng, n)
        _, p = hac_wald(z[:, None], r)
        hac += p < 0.01
        # stationary: var(Σ z r) = Σ_l acf_z(l) acf_r(l), both sample autocovariances
        lags = 60
        acf_z = np.array([z[: n - k] @ z[k:] for k in range(lags)])
        acf_r = np.array([r[: n - k] @ r[k:] for k in range(lags)]) / n
        var = acf_z[0] * acf_r[0] + 2 * np.sum(acf_z[1:] * acf_r[1:])
        stationary += chi2_sf((z @ r) ** 2 / var, 1) < 0.01
    assert hac <= 9  # 1 %: 3 expected; 7 drawn (Newey-West is a little liberal with few bumps)
    assert stationary >= 3 * max(hac, 5)


def test_a_real_coupling_stays_significant():
    """A coupling of 1 on every sample, the bumps' independent parts as big: t > 5."""
    rng = np.random.default_rng(12)
    z, r = _firings(rng, 8000)
    _, p = hac_wald(z[:, None], r + z)
    assert p < 1e-6
