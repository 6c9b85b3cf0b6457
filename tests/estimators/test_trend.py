"""Tests of the bias/drift estimators (accal.estimators.trend)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from accal.errors import ValidationError
from accal.estimators.trend import (
    fit_trend,
    linear_estimator_covariance,
    lsq_weights,
    wavelet_weights,
)


@pytest.fixture
def table1_series():
    """Paper eq. (12): sin(2πt) + 0.01 t − 15.5 at 50 samples/s for 10 s.

    Source: grace_wavelet_calibration.txt, section 3 and Table 1 (the paper's
    wavelet estimate: bias −15.4999998007976, drift 0.009999960159522, i.e. errors
    of 2.0e-7 and 4.0e-8).
    """
    t = np.arange(500) / 50.0
    return t, np.sin(2 * np.pi * t) + 0.01 * t - 15.5


def test_wavelet_reproduces_table1_better_than_paper(table1_series):
    """Table 1: our discrete scheme is exact on whole periods (≤ 1e-9, paper: 2e-7)."""
    t, a = table1_series
    fit = fit_trend(t, a, method="wavelet")
    assert abs(fit.bias - (-15.5)) <= 1e-9
    assert abs(fit.drift - 0.01) <= 1e-9
    # the paper's own errors, for the record: ours must beat them
    assert abs(fit.bias + 15.5) < abs(-15.4999998007976 + 15.5)
    assert abs(fit.drift - 0.01) < abs(0.009999960159522 - 0.01)
    assert fit.t0 == 0.0
    assert fit.n_used == 500


@pytest.mark.parametrize("n", [500, 501])
def test_table1_odd_and_even_length(n):
    t = np.arange(n) / 50.0
    fit = fit_trend(t, np.sin(2 * np.pi * t) + 0.01 * t - 15.5)
    assert fit.bias == pytest.approx(-15.5, abs=1e-9)
    assert fit.drift == pytest.approx(0.01, abs=1e-9)


def test_table1_reference_least_squares_is_degraded_by_differentiation(table1_series):
    """Table 1's comparison, qualitatively: LS against a reference obtained by
    differentiating a noisy f(t) (eq. 13) is far worse than the wavelet scheme,
    which needs no reference (the paper: LS bias error 0.09 vs wavelet 2e-7)."""
    t, a = table1_series
    rng = np.random.default_rng(13)
    f = -np.cos(2 * np.pi * t) / (2 * np.pi) + 1e-3 * rng.standard_normal(t.size)
    reference = np.gradient(f, t)  # noise amplified by ~1/dt
    ls = fit_trend(t, a - reference, method="lsq")
    wav = fit_trend(t, a, method="wavelet")
    err_ls = abs(ls.bias + 15.5) + abs(ls.drift - 0.01) * 10
    err_wav = abs(wav.bias + 15.5) + abs(wav.drift - 0.01) * 10
    assert err_ls > 1e-4
    assert err_ls > 1e4 * err_wav
    # and the LS fit's own sigma sees the amplified noise
    assert ls.sigma[0] > 1e-4


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
@pytest.mark.parametrize("order", [1, 2])
def test_pure_polynomial_machine_precision_real_epochs(method, order):
    """GPS epochs (~1e8 s), gaps and jitter: the trend comes back to machine precision."""
    rng = np.random.default_rng(4)
    t = 116769600.0 + np.arange(86400.0)
    t = t[(t - t[0] < 20000) | (t - t[0] > 23000)] + rng.uniform(-0.2, 0.2, size=None)
    b, d, c = 2.85e-5, 3.0e-13, 2e-18 if order == 2 else 0.0
    x = t - t[0]
    a = b + d * x + c * x * x
    fit = fit_trend(t, a, method=method, order=order)
    span = x[-1]
    assert abs(fit.bias - b) <= 1e-15 * abs(b) * 100
    assert abs(fit.drift - d) * span <= 1e-13 * abs(b)
    if order == 2:
        assert abs(fit.quadratic - c) * span**2 <= 1e-13 * abs(b)
    np.testing.assert_allclose(fit.evaluate(t), a, rtol=1e-14, atol=0)
    assert fit.rms <= 1e-14 * abs(b)


def test_wavelet_order1_equals_paper_continuous_formula():
    """On a fine uniform grid, eq. (4)/(6): d = (2/L)² ∫₀^{L/2} [a(s+L/2) − a(s)] ds and
    eq. (8): b = mean − d·L/2, evaluated with the rectangle rule."""
    rng = np.random.default_rng(0)
    n = 2000
    dt = 0.5
    t = dt * np.arange(n)
    a = rng.standard_normal(n) + 0.3 * t
    L = n * dt
    half = n // 2
    d_paper = (2 / L) ** 2 * np.sum(a[half:] - a[:half]) * dt
    b_paper = a.mean() - 0.5 * d_paper * (L - dt)  # centroid offset of the samples
    fit = fit_trend(t, a, method="wavelet")
    assert fit.drift == pytest.approx(d_paper, rel=1e-12)
    assert fit.bias == pytest.approx(b_paper, rel=1e-12)


def test_weights_sum_rules():
    """Linear-estimator identities: Σg_bias = 1, Σg_bias·(t−t0) = 0, Σg_drift = 0,
    Σg_drift·(t−t0) = 1, for both methods and uneven sampling."""
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0, 1000, 777))
    for g in (wavelet_weights(t, 1), lsq_weights(t, 1)):
        x = t - t[0]
        np.testing.assert_allclose(g @ np.ones_like(t), [1, 0], atol=1e-12)
        np.testing.assert_allclose(g @ x, [0, 1], atol=1e-10)


def test_valid_mask_and_nan_are_excluded():
    t = np.arange(1000.0)
    a = 1.0 + 1e-3 * t
    a[100:200] = 1e6
    valid = np.ones(t.size, bool)
    valid[100:200] = False
    a[500] = np.nan
    fit = fit_trend(t, a, valid=valid)
    assert fit.n_used == 899
    assert fit.bias == pytest.approx(1.0, abs=1e-12)
    assert fit.drift == pytest.approx(1e-3, abs=1e-15)


def test_bad_arguments_are_rejected_with_clear_messages():
    t = np.arange(10.0)
    with pytest.raises(ValidationError, match="'method' parameter.*'wavelet', 'lsq'.*'spline'"):
        fit_trend(t, t, method="spline")
    with pytest.raises(ValidationError, match="'order' parameter"):
        fit_trend(t, t, order=3)
    with pytest.raises(ValidationError, match="equal length"):
        fit_trend(t, t[:-1])
    with pytest.raises(ValidationError, match="only 2 usable samples"):
        fit_trend(t[:2], t[:2])
    with pytest.raises(ValidationError, match="strictly increasing"):
        fit_trend(t[::-1], t)


def test_covariance_expectation_matches_exact_quadratic_form():
    """For AR(1) noise the exact Var(g'e) = g' C g (dense matrix, small n) must match
    the mean of the residual-based estimates over realisations (within 15 %)."""
    n = 1500
    t = np.arange(n, dtype=float)
    phi = 0.9
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    cmat = phi**lags / (1 - phi**2)
    rng = np.random.default_rng(2)
    for method in ("wavelet", "lsq"):
        g = (wavelet_weights if method == "wavelet" else lsq_weights)(t, 1)
        exact = g @ cmat @ g.T
        est = []
        for _ in range(100):
            e = scipy.signal.lfilter([1], [1, -phi], rng.standard_normal(n + 500))[500:]
            fit = fit_trend(t, e, method=method)
            est.append(linear_estimator_covariance(t, e - fit.evaluate(t), g))
        mean = np.mean(est, axis=0)
        assert mean[0, 0] == pytest.approx(exact[0, 0], rel=0.15)
        assert mean[1, 1] == pytest.approx(exact[1, 1], rel=0.15)
        assert mean[0, 1] == pytest.approx(exact[0, 1], rel=0.25)


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
@pytest.mark.parametrize("phi", [0.0, 0.95, 0.99])
def test_monte_carlo_sigma_is_honest_for_coloured_noise(method, phi):
    """Empirical scatter / reported sigma in [0.7, 1.4] for white and AR(1) noise
    (correlation times 0, 20 and 100 samples in a 4,320-sample record) plus white.

    See docs/grace_bias.md for the ratios measured.
    """
    rng = np.random.default_rng(int(phi * 100) + (method == "lsq"))
    n = 4320
    t = 10.0 * np.arange(n)
    eb, ed, sb, sd = [], [], [], []
    for _ in range(200):
        w = rng.standard_normal(n + 3000)
        e = scipy.signal.lfilter([1], [1, -phi], w)[3000:] + rng.standard_normal(n)
        fit = fit_trend(t, 3.0 + 2e-4 * t + e, method=method)
        eb.append(fit.bias - 3.0)
        ed.append(fit.drift - 2e-4)
        sb.append(fit.sigma[0])
        sd.append(fit.sigma[1])
    rb = np.std(eb) / np.sqrt(np.mean(np.square(sb)))
    rd = np.std(ed) / np.sqrt(np.mean(np.square(sd)))
    assert 0.7 <= rb <= 1.4, rb
    assert 0.7 <= rd <= 1.4, rd


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
def test_monte_carlo_sigma_is_honest_for_one_over_f_noise(method):
    """SuperSTAR-like noise over a 1 Hz day: white 1e-10 m/s²/√Hz with a 1/f rise below
    1 mHz (the simulator's noise).  The low-frequency power that the trend fit
    absorbs is restored by the projection correction; scatter/sigma in [0.7, 1.4]."""
    from accal.simulate.grace import coloured_noise

    rng = np.random.default_rng(11 + (method == "lsq"))
    n = 86400
    t = np.arange(n, dtype=float)
    eb, ed, sb, sd = [], [], [], []
    for _ in range(60):
        e = coloured_noise(n, 1.0, 1e-10, 1e-3, rng)
        fit = fit_trend(t, e, method=method)
        eb.append(fit.bias)
        ed.append(fit.drift)
        sb.append(fit.sigma[0])
        sd.append(fit.sigma[1])
    rb = np.std(eb) / np.sqrt(np.mean(np.square(sb)))
    rd = np.std(ed) / np.sqrt(np.mean(np.square(sd)))
    assert 0.7 <= rb <= 1.4, rb
    assert 0.7 <= rd <= 1.4, rd


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
@pytest.mark.parametrize("order", [1, 2])
def test_fit_trends_matches_fit_trend_per_column(method, order):
    """The shared-work multi-axis fit gives each column's fit_trend result."""
    from accal.estimators.trend import fit_trend, fit_trends

    rng = np.random.default_rng(order)
    n = 5000
    t = 1.2e8 + np.cumsum(rng.uniform(0.9, 1.1, n))
    valid = rng.random(n) > 0.05
    a = 1e-6 * np.array([1.0, -28.0, 0.5]) + 1e-12 * np.outer(t - t[0], [1, 2, 3])
    a = a + 1e-9 * rng.standard_normal((n, 3))
    multi = fit_trends(t, a, method=method, order=order, valid=valid)
    for j in range(3):
        one = fit_trend(t, a[:, j], method=method, order=order, valid=valid)
        np.testing.assert_allclose(multi[j].coef, one.coef, rtol=1e-9, atol=1e-22)
        np.testing.assert_allclose(multi[j].cov, one.cov, rtol=1e-9, atol=0)
        assert multi[j].n_used == one.n_used and multi[j].t0 == one.t0
        assert multi[j].rms == pytest.approx(one.rms, rel=1e-12)


def test_fit_trends_exact_on_pure_linear_trends_and_falls_back_on_nan():
    from accal.estimators.trend import fit_trends

    t = 2.0e8 + np.arange(3001.0)
    b = np.array([1.2e-6, -2.9e-5, 5e-7])
    d = np.array([3e-13, -1e-12, 2e-14])
    a = b + np.outer(t - t[0], d)
    for method in ("wavelet", "lsq"):
        fits = fit_trends(t, a, method=method)
        for j, f in enumerate(fits):
            assert abs(f.bias - b[j]) <= 4 * np.finfo(float).eps * abs(b[j])
            assert abs(f.drift - d[j]) <= 1e-10 * abs(d[j])
    a[10, 1] = np.nan  # one column with a NaN: per-column masks
    fits = fit_trends(t, a)
    assert fits[1].n_used == t.size - 1 and fits[0].n_used == t.size


def _wavelet_weights_by_definition(t, order):
    """Slow reference: per-sample segment membership and moment sums in loops."""
    t = np.asarray(t, float)
    n, p = t.size, order + 1
    centre, half = 0.5 * (t[0] + t[-1]), 0.5 * (t[-1] - t[0])
    u = (t - centre) / half
    d = np.diff(t)
    w = np.append(np.minimum(d, 1.5 * np.median(d)), np.median(d))
    edges = np.linspace(-1, 1, p + 1)
    seg = np.array([min(max(np.sum(edges <= x) - 1, 0), p - 1) for x in u])
    if any(np.sum(seg == k) == 0 for k in range(p)):
        seg = np.array([min(i * p // n, p - 1) for i in range(n)])
    m = np.array([[np.sum(w[seg == k] * u[seg == k] ** j) for j in range(p)] for k in range(p)])
    wsum = np.array([np.sum(w[seg == k]) for k in range(p)])
    minv = np.linalg.inv(m / wsum[:, None])
    g_u = np.array([[minv[j, seg[i]] * w[i] / wsum[seg[i]] for i in range(n)] for j in range(p)])
    # powers of u -> powers of (t - t0): a = sum_j c_j u^j evaluated with u = (t-t0)/half + s
    s = (t[0] - centre) / half
    from math import comb

    tm = np.array(
        [
            [comb(j, k) * s ** (j - k) / half**k if j >= k else 0.0 for j in range(p)]
            for k in range(p)
        ]
    )
    return tm @ g_u


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize(
    "layout",
    ["uniform", "odd", "gaps", "jitter", "huge_gap_empties_a_segment", "last_step_large"],
)
def test_wavelet_weights_equal_the_segment_definition(order, layout):
    """The vectorised weights (slices of sorted segments) equal a per-sample loop."""
    rng = np.random.default_rng(11)
    t = 1.2e8 + np.arange(400.0)
    if layout == "odd":
        t = t[:399]
    elif layout == "gaps":
        t = np.delete(t, np.r_[50:80, 200:210, 333])
    elif layout == "jitter":
        t = t + rng.uniform(-0.2, 0.2, t.size)
    elif layout == "huge_gap_empties_a_segment":
        t = np.concatenate([t[:100], t[:100] + 1e6])
    elif layout == "last_step_large":
        t = np.append(t, t[-1] + 50.0)
    g = wavelet_weights(t, order)
    ref = _wavelet_weights_by_definition(t, order)
    scale = np.abs(ref).max(axis=1, keepdims=True)
    assert np.max(np.abs(g - ref) / scale) < 1e-10


def test_grid_placement_and_orthonormal_basis():
    """Samples go to their grid index (runs copied or scattered alike); uniform
    grids skip the copy; the polynomial basis is orthonormal and spans the same space."""
    from accal.estimators.trend import _grid_index, _on_grid, _orthonormal_columns

    rng = np.random.default_rng(5)
    t = np.arange(2000.0)
    assert _grid_index(t)[0] is None and _grid_index(t)[1] == 2000
    for n_gaps in (1, 5, 200):  # runs path (<= 64 breaks) and scatter path
        keep = np.ones(t.size, bool)
        for a in rng.choice(np.arange(1, 1990), n_gaps, replace=False):
            keep[a : a + rng.integers(1, 5)] = False
        idx, ngrid = _grid_index(t[keep])
        assert np.array_equal(idx, np.flatnonzero(keep)) and ngrid == 2000
        rows = rng.standard_normal((3, keep.sum()))
        naive = np.zeros((3, ngrid))
        naive[:, idx] = rows
        assert np.array_equal(_on_grid(rows, idx, ngrid), naive)
    u = np.linspace(-1, 1, 1001)
    for p in (1, 2, 3):
        x = np.vander(u, p, increasing=True)
        q = _orthonormal_columns(x)
        assert np.allclose(q.T @ q, np.eye(p), atol=1e-14)
        assert np.allclose(q @ (q.T @ x), x, atol=1e-13)


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
def test_uniform_layouts_share_a_design_that_matches_the_direct_one(method):
    """Complete days use cached weights/kernel from the canonical grid: same result as the
    direct computation on the day's own epochs, for any t0, and the cache is read-only."""
    from accal.estimators.trend import _CovarianceKernel, _fit_columns, _uniform_design

    rng = np.random.default_rng(3)
    n = 5000
    a = 1e-7 + 1e-12 * np.arange(n)[:, None] + 1e-9 * rng.standard_normal((n, 2))
    fits = []
    for t0 in (116769600.0, 7.3e8 + 0.5, 0.0):
        t = t0 + 2.0 * np.arange(n)
        fits.append(fit_trend(t, a[:, 0], method=method))
        g_direct = (wavelet_weights if method == "wavelet" else lsq_weights)(t, 1)
        g_cached, kernel = _uniform_design(n, 2.0, method, 1)
        np.testing.assert_allclose(g_cached, g_direct, rtol=1e-9, atol=1e-12 * abs(g_direct).max())
        resid = np.ascontiguousarray((a - a.mean(axis=0)).T)
        np.testing.assert_allclose(
            kernel.covariances(resid), _CovarianceKernel(t, g_direct, 1).covariances(resid),
            rtol=1e-8,
        )  # fmt: skip
        assert not g_cached.flags.writeable
        uncached = _fit_columns(t, a, np.ones(n, bool) & (np.arange(n) != 17), method, 1)
        assert np.isfinite(uncached[0].cov).all()
    for f in fits[1:]:
        np.testing.assert_allclose(f.coef, fits[0].coef, rtol=1e-12)
        np.testing.assert_allclose(f.cov, fits[0].cov, rtol=1e-12)


def test_noise_grid_is_bounded_when_stretches_are_far_apart():
    """Two stretches months apart: the grid stays <= 4 n points (it was 35 M points and
    9 GB for one record 400 days late), order and short gaps are kept."""
    from accal.estimators.trend import MAX_GRID_FACTOR, _grid_index

    t = np.concatenate([np.arange(1000.0), np.arange(1000.0, 1500.0, 2.0), [400 * 86400.0]])
    idx, ngrid = _grid_index(t)
    assert ngrid <= MAX_GRID_FACTOR * t.size and ngrid == idx[-1] + 1
    assert np.all(np.diff(idx) >= 1)
    assert np.array_equal(np.diff(idx)[:1249], np.rint(np.diff(t)[:1249]))  # short gaps kept
    fit = fit_trend(t, 1e-7 + 1e-12 * t)
    assert np.isfinite(fit.sigma).all()
    np.testing.assert_allclose(fit.coef, [1e-7, 1e-12], rtol=1e-9)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("layout", ["uniform", "gaps", "odd"])
def test_binned_covariance_equals_the_per_frequency_quadratic_form(order, layout):
    """The kernel sums Re(G_i conj(G_j)) over each PSD bin once; the covariance must
    equal Re(G diag(w) G^H)/M with G the weights' DFT zero-padded to M = 2 N points
    (the frequency integral of the DTFT, on a grid twice finer than the Fourier
    frequencies) and the PSD estimate w spread over every frequency, each taking the
    bin of the Fourier frequency at or below it (the lowest bin's value below f_1),
    to rounding."""
    from accal.estimators.trend import _OVERSAMPLE, _CovarianceKernel, _on_grid

    rng = np.random.default_rng(11)
    n = {"uniform": 4000, "gaps": 4000, "odd": 3001}[layout]
    t = np.arange(n, dtype=float)
    if layout == "gaps":
        keep = np.ones(n, bool)
        for a in rng.choice(np.arange(10, n - 10), 40, replace=False):
            keep[a : a + rng.integers(1, 30)] = False
        t = t[keep]
    g = wavelet_weights(t, order)
    resid = np.cumsum(rng.standard_normal((3, t.size)), axis=1)
    kern = _CovarianceKernel(t, g, order)
    got = kern.covariances(resid)

    # reference: the explicit per-frequency weights
    spec_r = np.fft.rfft(_on_grid(resid, kern.idx, kern.ngrid), axis=1)
    nf = spec_r.shape[1]
    m = _OVERSAMPLE * kern.ngrid
    spec_g = np.fft.rfft(_on_grid(g, kern.idx, kern.ngrid), n=m, axis=1)
    nfm = spec_g.shape[1]
    pgram = np.abs(spec_r) ** 2 * (kern.inv_suppress / kern.n)
    sbin = np.add.reduceat(pgram[:, 1:], kern.starts, axis=1) / kern.counts
    s_fourier = np.repeat(sbin, kern.counts, axis=1)  # at f_1 .. f_nf-1
    below = np.clip(np.arange(nfm) // _OVERSAMPLE, 1, nf - 1)
    w = s_fourier[:, below - 1] * 2.0
    w[:, 0] /= 2.0
    if m % 2 == 0:
        w[:, nfm - 1] /= 2.0
    want = np.einsum("if,kf,jf->kij", spec_g, w, spec_g.conj()).real / m

    assert got.shape == (3, order + 1, order + 1)
    scale = np.sqrt(np.einsum("kii,kjj->kij", want, want))
    assert np.max(np.abs(got - want) / scale) < 1e-12


@pytest.mark.parametrize("method", ["wavelet", "lsq"])
def test_covariance_under_a_band_near_one_per_rev_is_the_dtft_integral(method):
    """Var(g'e) = ∫|G(f)|² S(f) df (DTFT), checked against the exact time-domain
    g'Cg for a band-limited process (damped cosine autocovariance at 1/5600 Hz) on a
    day: the kernel's quadrature of the integral with the bin means of the true PSD
    (Σ_b S_b · pair_bins[b] / M) must give g'Cg within 15 %, at least 10 points
    closer than the sum over the Fourier frequencies alone (the circular
    approximation used before: 26-49 % too large here, σ 1.5x under mc_sigma's band)."""
    from scipy.linalg import toeplitz

    from accal.estimators.trend import _CovarianceKernel, lsq_weights

    n = 8640  # a day at 0.1 Hz
    dt = 10.0
    t = np.arange(n) * dt
    g = (wavelet_weights if method == "wavelet" else lsq_weights)(t, 1)
    lags = np.arange(n) * dt
    f0, decay = 1.0 / 5600.0, 20000.0  # a band ~1 Fourier bin wide at ~15 cycles per day
    acov = np.exp(-lags / decay) * np.cos(2 * np.pi * f0 * lags)
    exact = g @ toeplitz(acov) @ g.T
    # the true PSD at the Fourier frequencies k/n: S_k = Σ_h acov_h e^(-2πikh/n)
    psd = 2.0 * np.fft.rfft(acov).real - acov[0]
    kern = _CovarianceKernel(t, g, 1)
    sbin = np.add.reduceat(psd[1:], kern.starts) / kern.counts
    p = kern.p
    got = (sbin @ kern.pair_bins.reshape(p * p, kern.nbins).T).reshape(p, p) / kern.scale
    # the circular approximation: the same bin values at the Fourier frequencies only
    gk = np.fft.rfft(g, axis=1)
    two_sided = np.full(gk.shape[1], 2.0)
    two_sided[0] = two_sided[-1] = 1.0
    s_k = np.concatenate([sbin[:1], np.repeat(sbin, kern.counts)])
    circular = (np.abs(gk) ** 2 * two_sided * s_k).sum(axis=1) / n
    err_new = np.abs(np.diag(got) / np.diag(exact) - 1.0)
    err_old = np.abs(circular / np.diag(exact) - 1.0)
    # the rest is the PSD estimate's resolution (bins 3-5 Fourier bins wide there):
    # with the true PSD on the twice finer grid the integral is exact (circulant
    # embedding of the n x n Toeplitz form in 2n points)
    assert np.all(err_new < 0.15), (np.diag(got), np.diag(exact))
    assert np.all(err_old > err_new + 0.1), (err_old, err_new)
