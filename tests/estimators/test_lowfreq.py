"""accal.estimators.lowfreq: exact expectations, pooled-σ calibration, misfits.

The noise of the Monte-Carlo tests is drawn here (white, random walk), not by accal.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import toeplitz

from accal.estimators.lowfreq import (
    BETAS,
    K_BAND,
    TAUS_PER_N,
    NoiseSpectrum,
    noise_spectra,
    noise_spectrum,
    pooled_covariance,
)
from accal.estimators.trend import fit_trend, lsq_weights, wavelet_weights


def _gappy_times(n: int = 480) -> np.ndarray:
    keep = np.ones(n, bool)
    keep[120:160] = False
    keep[330:333] = False
    return np.arange(n, dtype=float)[keep] * 2.0


@pytest.mark.parametrize("weights", [wavelet_weights, lsq_weights])
def test_expectations_equal_the_dense_quadratic_forms(weights):
    """E|R_k|² = c_kᴴ C c_k and G C Gᵀ for white noise and the AR(1) shapes, computed
    with dense matrices on a gapped record: equal to rounding."""
    t = _gappy_times()
    g = weights(t, 1)
    spec = noise_spectrum(t, np.zeros(t.size), g, order=1)
    m = np.rint((t - t[0]) / 2.0).astype(int)
    n_grid = int(m[-1]) + 1
    k = np.arange(1, spec.white.size + 1)
    taper = np.sin(np.pi * (m + 0.5) / n_grid)
    vand = np.vander(t - t[0], 2, increasing=True)
    proj = np.eye(t.size) - vand @ g  # r = (I − V G) e
    ck = proj.T @ (np.exp(2j * np.pi * np.outer(m, k) / n_grid) * taper[:, None])
    np.testing.assert_allclose(spec.white, np.sum(np.abs(ck) ** 2, axis=0), rtol=1e-9)
    np.testing.assert_allclose(spec.white_cov, g @ g.T, rtol=1e-9)
    ar = [j for j, name in enumerate(spec.names) if name.startswith("AR(1)")]
    assert len(ar) == 16
    assert ar[0] == BETAS.size
    for j in ar[::5]:
        tau = TAUS_PER_N[j - BETAS.size] * n_grid
        cov = toeplitz(np.exp(-np.arange(n_grid) / tau))[np.ix_(m, m)]
        want = np.real(np.einsum("tk,ts,sk->k", ck.conj(), cov, ck))
        np.testing.assert_allclose(spec.shapes[j], want, rtol=1e-7)
        np.testing.assert_allclose(spec.covs[j], g @ cov @ g.T, rtol=1e-7)


def test_spectrum_arrays_round_trip_and_shared_layout():
    rng = np.random.default_rng(1)
    t = np.arange(2000.0)
    g = wavelet_weights(t, 1)
    a, b = noise_spectra(t, rng.standard_normal((2, t.size)), g, order=1, method="wavelet")
    assert a.shapes is b.shapes  # one layout, computed once
    assert a.periodogram.size == min(K_BAND, (t.size - 1) // 2)
    back = NoiseSpectrum.from_arrays(a.to_arrays("x."), "x.")
    np.testing.assert_array_equal(back.periodogram, a.periodogram)
    np.testing.assert_allclose(back.shapes, a.shapes, rtol=1e-6)  # stored as float32
    assert back.names == a.names
    assert noise_spectrum(t[:300], np.zeros(300), g[:, :300], order=1) is None  # too short


def _days(rng, n_days, n, walk, white=1.0):
    """Independent days of white + random-walk noise.

    The walk starts at 0 on the first sample: its level at t0 is the instrument's bias
    (the "pinned" convention of accal.estimators.lowfreq), so the true bias is 0."""
    e = white * rng.standard_normal((n_days, n))
    if walk:
        e += walk * np.cumsum(rng.standard_normal((n_days, n)), axis=1)
    return e


@pytest.mark.parametrize("walk", [0.0, 0.05])
def test_pooled_sigma_is_calibrated(walk):
    """96 days in pools of 8: scatter of the estimates over the mean σ in 0.8–1.25 for
    bias and drift, white and white + random walk.

    Measured (seed 5): white 0.96/1.00 (bias/drift), σ scatter 0.9 %; random walk
    0.88/0.87.  The day's own binned periodogram gives 1.67/2.76 under the random
    walk (checked below).
    """
    rng = np.random.default_rng(5)
    n, pool, n_days = 3000, 8, 96
    t = np.arange(n, dtype=float) * 10.0
    g = wavelet_weights(t, 1)
    est, sig, own = [], [], []
    for _ in range(n_days // pool):
        e = _days(rng, pool, n, walk)
        fits = [fit_trend(t, x) for x in e]
        specs = noise_spectra(
            t, np.array([x - f.evaluate(t) for x, f in zip(e, fits, strict=True)]), g,
            method="wavelet",
        )  # fmt: skip
        for i in range(pool):
            cov, info = pooled_covariance(specs[i], specs[:i] + specs[i + 1 :])
            assert cov is not None and info["days"] == pool
            est.append(fits[i].coef)
            sig.append(np.sqrt(np.diag(cov)))
            own.append(fits[i].sigma)
    est, sig, own = np.array(est), np.array(sig), np.array(own)
    ratio = est.std(axis=0) / np.sqrt(np.mean(sig**2, axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    if walk:
        own_ratio = est.std(axis=0) / np.sqrt(np.mean(own**2, axis=0))
        assert np.all(own_ratio > 1.4), own_ratio
    else:  # stationary noise: σ stable from day to day
        assert np.all(sig.std(axis=0) / sig.mean(axis=0) < 0.1)


def test_a_line_is_a_misfit_and_keeps_the_days_estimate():
    rng = np.random.default_rng(2)
    t = np.arange(3000.0) * 10.0
    g = wavelet_weights(t, 1)
    e = rng.standard_normal((4, t.size)) + 3.0 * np.sin(2 * np.pi * t / 3000.0)
    specs = noise_spectra(t, e - e.mean(axis=1, keepdims=True), g, method="wavelet")
    cov, info = pooled_covariance(specs[0], specs[1:])
    assert cov is None and info["misfit"] and info["lines"] > 0


@settings(max_examples=25, deadline=None)
@given(
    scale=st.floats(1e-12, 1e3),
    seed=st.integers(0, 2**32 - 1),
    walk=st.sampled_from([0.0, 0.03]),
)
def test_pooled_covariance_is_scale_equivariant_symmetric_and_order_free(scale, seed, walk):
    """cov(c·e) = c²·cov(e), symmetric with a positive diagonal, the same for any order
    of the other days (the Whittle fit's estimating equations are scale-equivariant)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1200.0)
    g = lsq_weights(t, 1)
    e = _days(rng, 4, t.size, walk)
    e -= (np.vander(t, 2, increasing=True) @ (g @ e.T)).T  # the residuals of the fit
    specs = noise_spectra(t, e, g, method="lsq")
    scaled = noise_spectra(t, scale * e, g, method="lsq")
    cov, info = pooled_covariance(specs[0], specs[1:])
    cov_s, info_s = pooled_covariance(scaled[0], scaled[:0:-1])
    assert info["model"] == info_s["model"]
    if cov is None:
        assert cov_s is None
        return
    np.testing.assert_allclose(cov_s, scale**2 * cov, rtol=1e-6)
    np.testing.assert_allclose(cov, cov.T, rtol=0, atol=0)
    assert np.all(np.diag(cov) > 0)


def test_a_spectrum_rising_above_the_low_band_is_fitted_on_a_narrower_band():
    """White noise plus differenced white noise (PSD 4 sin²(πf), rising above the bins
    that carry the estimators' weight): the full band is a misfit, a narrower one fits
    and the σ are those of the white level there (QA: the tests' realistic L1B noise)."""
    rng = np.random.default_rng(8)
    t = np.arange(3000.0) * 10.0
    g = wavelet_weights(t, 1)
    x = rng.standard_normal((9, t.size + 1))
    e = rng.standard_normal((8, t.size)) + 3.0 * np.diff(x[:8], axis=1)
    specs = noise_spectra(t, e - e.mean(axis=1, keepdims=True), g, method="wavelet")
    cov, info = pooled_covariance(specs[0], specs[1:])
    assert cov is not None and info["bins"] < specs[0].periodogram.size
    # the low band's level: white (1) + 9·4 sin²(πf) ≈ 1 there; σ within 25 % of white's
    white = np.sqrt(np.diag(g @ g.T))
    assert np.all(np.abs(np.sqrt(np.diag(cov)) / white - 1) < 0.25)
