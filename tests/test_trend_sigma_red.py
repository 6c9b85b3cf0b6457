"""σ of bias/drift under red noise (issue 20): the low-frequency noise model.

Noise is drawn here, by generators of this file (numpy only), not by accal.simulate.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.estimators.lowfreq import ALPHAS, LowFreqSpectrum
from accal.estimators.trend import (
    _CovarianceKernel,
    fit_trend,
    linear_estimator_covariance,
    lsq_weights,
    wavelet_weights,
)

DAY = 86400


def random_walk(rng: np.random.Generator, n: int, q: float, white: float) -> np.ndarray:
    """Random walk of increment variance ``q`` from 0 at the first sample, plus white noise."""
    return np.cumsum(np.sqrt(q) * rng.standard_normal(n)) + white * rng.standard_normal(n)


def power_law(
    rng: np.random.Generator, n: int, white: float, amp: float, alpha: float
) -> np.ndarray:
    """Stationary noise of two-sided PSD ``white² + amp·f^-alpha`` (f in cycles/sample).

    Spectral synthesis on 4n points (flat below 1/(8n)), a window of n samples.
    """
    m = 4 * n
    f = np.fft.rfftfreq(m)
    s = white**2 + amp * np.maximum(f, 0.5 / m) ** -alpha
    z = np.sqrt(s * m / 2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    z[0] = z[0].real * np.sqrt(2)
    return np.fft.irfft(z, m)[n : 2 * n]


def kernel(n: int, method: str = "lsq") -> tuple[np.ndarray, np.ndarray, _CovarianceKernel]:
    t = np.arange(n, dtype=float)
    g = (lsq_weights if method == "lsq" else wavelet_weights)(t, 1)
    return t, g, _CovarianceKernel(t, g, 1)


# --------------------------------------------------------------------------------------
# exact cases
# --------------------------------------------------------------------------------------


def test_whittle_fit_recovers_the_model_from_its_own_expectation():
    """Fed the expected ordinates of W + A·f^-1.5 (no noise), the fit returns W, A
    (to 1e-3) and α = 1.5 (to 0.01, the parabola between grid nodes) and prefers that shape over every other one."""
    _, _, kern = kernel(DAY)
    sp = kern.spectrum
    j = int(np.flatnonzero(np.isclose(sp.params, 1.5) & (sp.kinds == 0))[0])
    w_true, a_true = 2.0e-20, 5.0e-19
    expected = w_true * sp.white + a_true * sp.b[j]
    fitted = sp.fit(expected[None, :], iters=60)
    assert int(np.argmax(fitted["loglik"][0])) == j
    assert fitted["W"][0, j] == pytest.approx(w_true, rel=1e-3)
    assert fitted["A"][0, j] == pytest.approx(a_true, rel=1e-3)
    model = sp.model(fitted, 0, expected)
    assert model.kind == "power"
    assert model.alpha == pytest.approx(1.5, abs=0.01)  # parabola through a 0.1 grid


def test_quadrature_is_parseval_for_white_and_exact_for_a_random_walk():
    """Q of the α = 0 shape is Σ g gᵀ (white noise, Parseval); Q of α = 2, pinned at
    t0, is the exact random-walk covariance q Σ_s H_i(s) H_j(s) (H: reverse cumulative
    sums of the weights) to 0.5 % (the discrete walk's PSD q/(4 sin²πf) is q/(2πf)²
    only at low f)."""
    for method in ("lsq", "wavelet"):
        t, g, kern = kernel(DAY, method)
        sp = kern.spectrum
        a0 = int(np.flatnonzero(np.isclose(sp.params, 0.0) & (sp.kinds == 0))[0])
        np.testing.assert_allclose(kern.q[a0], g @ g.T, rtol=1e-6)
        a2 = int(np.flatnonzero(np.isclose(sp.params, 2.0) & (sp.kinds == 0))[0])
        assert kern.pinned[a2]
        h = np.cumsum(g[:, ::-1], axis=1)[:, ::-1]
        exact = h @ h.T  # q = 1
        got = kern.q[a2] / (2.0 * np.pi * sp.f_ref) ** 2
        np.testing.assert_allclose(np.diag(got), np.diag(exact), rtol=5e-3)


def test_white_noise_sigma_equals_the_analytic_least_squares_sigma():
    """σ² (VᵀV)⁻¹ for white noise: the model is white (no coloured term is kept) and
    the mean σ over 6 days is within 3 % of the analytic value."""
    rng = np.random.default_rng(20)
    t = np.arange(DAY, dtype=float)
    v = np.vander(t, 2, increasing=True)
    analytic = np.sqrt(np.diag(np.linalg.inv(v.T @ v))) * 3e-10
    sig = []
    for _ in range(6):
        fit = fit_trend(t, 3e-10 * rng.standard_normal(DAY), method="lsq")
        assert fit.noise is not None and fit.noise.kind == "white"
        assert fit.notes == ()
        sig.append(fit.sigma)
    np.testing.assert_allclose(np.mean(sig, axis=0), analytic, rtol=0.03)


def test_gaps_keep_white_sigma_analytic():
    """With 40 gaps (8 % of the day) the white term's expectation is exact for the mask:
    the mean σ of 8 days is within 6 % of the analytic one (one day scatters by ~7 %)."""
    rng = np.random.default_rng(21)
    keep = np.ones(DAY, bool)
    for a in rng.choice(np.arange(100, DAY - 2000), 40, replace=False):
        keep[a : a + rng.integers(10, 350)] = False
    t = np.arange(DAY, dtype=float)[keep]
    v = np.vander(t, 2, increasing=True)
    analytic = np.sqrt(np.diag(np.linalg.inv(v.T @ v)))
    sig = [fit_trend(t, rng.standard_normal(t.size), method="lsq").sigma for _ in range(8)]
    np.testing.assert_allclose(np.mean(sig, axis=0), analytic, rtol=0.06)


def test_fitted_model_recovers_a_synthetic_power_law():
    """Noise of PSD W + A f^-1.5: median α̂ over 8 days within 0.15 of 1.5, W within 15 %."""
    rng = np.random.default_rng(22)
    t = np.arange(DAY, dtype=float)
    alphas, whites = [], []
    for _ in range(8):
        e = power_law(rng, DAY, 1e-10, 4e-24, 1.5)  # equals the white level near bin 400
        model = fit_trend(t, e).noise
        assert model is not None and model.kind == "power"
        alphas.append(model.alpha)
        whites.append(model.white)
    assert np.median(alphas) == pytest.approx(1.5, abs=0.15)
    assert np.median(whites) == pytest.approx(1e-20, rel=0.15)


def test_short_record_falls_back_to_white_noise_with_a_note():
    t = np.arange(30, dtype=float)
    fit = fit_trend(t, np.random.default_rng(1).standard_normal(30))
    assert np.isfinite(fit.sigma).all()
    assert any("too few" in n for n in fit.notes)
    assert fit.noise is None


# --------------------------------------------------------------------------------------
# the misfit flag
# --------------------------------------------------------------------------------------


def test_a_line_in_the_residual_is_flagged_and_white_noise_is_not():
    rng = np.random.default_rng(23)
    t = np.arange(DAY, dtype=float)
    white = 1e-10 * rng.standard_normal(DAY)
    assert fit_trend(t, white).notes == ()
    line = 3e-10 * np.sin(2 * np.pi * t / 5600.0 + 0.3)
    notes = fit_trend(t, white + line).notes
    assert any(n.startswith("noise spectrum misfit") for n in notes), notes


# --------------------------------------------------------------------------------------
# Monte Carlo under a random walk
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
def test_monte_carlo_sigma_is_honest_under_a_random_walk(method):
    """2e-12 m/s²/√s random walk (from 0 at t0) + 1e-10 white, 1 Hz day: scatter / RMS σ
    in [0.7, 1.4] for bias and drift over 120 days (before issue 20: 2.0–3.2)."""
    rng = np.random.default_rng(24 + (method == "lsq"))
    t = np.arange(DAY, dtype=float)
    est, sig = [], []
    for _ in range(120):
        fit = fit_trend(t, random_walk(rng, DAY, 4e-24, 1e-10), method=method)
        est.append(fit.coef)
        sig.append(fit.sigma)
    ratio = np.std(est, axis=0) / np.sqrt(np.mean(np.square(sig), axis=0))
    assert np.all((ratio >= 0.7) & (ratio <= 1.4)), ratio


def test_linear_estimator_covariance_matches_the_kernel():
    rng = np.random.default_rng(25)
    t, g, kern = kernel(5000)
    e = random_walk(rng, 5000, 1.0, 3.0)
    r = e - np.polynomial.polynomial.polyval(t, g @ e)
    np.testing.assert_allclose(linear_estimator_covariance(t, r, g), kern.covariances(r[None])[0])


# --------------------------------------------------------------------------------------
# properties
# --------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(600, 4000),
    scale=st.floats(1e-3, 1e3),
    offset=st.floats(-1e3, 1e3),
    slope=st.floats(-1.0, 1.0),
    method=st.sampled_from(["wavelet", "lsq"]),
)
def test_sigma_scales_with_the_noise_and_ignores_the_trend(seed, n, scale, offset, slope, method):
    """σ(c·e + b + d·t) = |c|·σ(e): the Whittle fit is scale-equivariant and the
    residual does not depend on the trend."""
    rng = np.random.default_rng(seed)
    t = 2.0 * np.arange(n)
    e = random_walk(rng, n, 0.01, 1.0)
    base = fit_trend(t, e, method=method)
    moved = fit_trend(t, scale * e + offset + slope * t, method=method)
    np.testing.assert_allclose(moved.sigma, scale * base.sigma, rtol=1e-5)
    assert moved.notes == base.notes


def test_alpha_grid_is_what_the_docs_say():
    assert ALPHAS[0] == 0.0 and ALPHAS[-1] == 2.5
    assert LowFreqSpectrum(np.ones(30, bool), 1.0).ok is False  # 14 bins: too few
