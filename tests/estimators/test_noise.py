"""Tests of the noise model (eq. 1) and the covariance helpers of accal.estimators.noise."""

import numpy as np
import pytest

from accal.errors import ValidationError
from accal.estimators.noise import (
    MicroStarPSD,
    TabulatedPSD,
    as_psd,
    cov_linear,
    cov_linear_freq,
    precision_linear_freq,
    structure_function,
    toeplitz_matmul,
)


def test_eq1_values():
    """Eq. 1: sqrt(S) = K sqrt(1 + (f/4.2 mHz)^-1 + (f/0.27 Hz)^4), two-sided, even in f."""
    psd = MicroStarPSD()
    K = 5.7e-11
    assert psd(4.2e-3) == pytest.approx(K**2 * (2 + (4.2e-3 / 0.27) ** 4))
    assert psd(-0.27) == pytest.approx(K**2 * (1 + 4.2e-3 / 0.27 + 1))
    assert np.isinf(psd(0.0))


def test_white_structure_function():
    """White two-sided PSD K² over [-fs/2, fs/2]: R[0] = K² fs, so D[k>0] = K² fs."""
    fs = 2.0
    psd = TabulatedPSD(np.array([1e-6, 10.0]), np.array([4.0, 4.0]))
    d = structure_function(psd, 50, fs)
    assert d[0] == 0
    np.testing.assert_allclose(d[1:], 4.0 * fs, rtol=1e-6)


def test_difference_and_frequency_forms_agree():
    """Σw = 0: -w'T_D w (Toeplitz) equals ∫ S |W|² df (eq. 21) despite the 1/f term."""
    psd = MicroStarPSD()
    rng = np.random.default_rng(3)
    w = rng.standard_normal(300)
    w -= w.mean()
    v = rng.standard_normal(300)
    v -= v.mean()
    d = structure_function(psd, 300)
    a = cov_linear(w, v, d)
    b = cov_linear_freq(w, v, psd, oversample=64)
    assert a == pytest.approx(b, rel=2e-3)


def test_toeplitz_matmul_matches_dense():
    from scipy.linalg import toeplitz

    rng = np.random.default_rng(0)
    col = rng.standard_normal(37)
    x = rng.standard_normal((37, 3))
    np.testing.assert_allclose(toeplitz_matmul(col, x), toeplitz(col) @ x, atol=1e-12)


def test_precision_inverse_of_covariance_for_white_noise():
    """Eq. 25 with a flat PSD: v'Ω⁻¹w = v'w / (K² fs)."""
    psd = TabulatedPSD(np.array([1e-6, 10.0]), np.array([2.0, 2.0]))
    rng = np.random.default_rng(1)
    v = rng.standard_normal((64, 2))
    np.testing.assert_allclose(precision_linear_freq(v, psd), v.T @ v / 2.0, rtol=1e-9)


def test_tabulated_psd_interpolates_loglog_and_validates():
    psd = as_psd((np.array([1e-3, 1e-1]), np.array([1e-18, 1e-22])))
    assert psd(1e-2) == pytest.approx(1e-20)
    assert psd(1e-4) == pytest.approx(1e-16)  # power-law extension
    with pytest.raises(ValidationError, match="strictly increasing"):
        TabulatedPSD(np.array([1.0, 0.5]), np.array([1.0, 1.0]))
    with pytest.raises(ValidationError, match="psd must be"):
        as_psd("flat")


# --- the shared coloured-noise generator (accal.simulate.noise) ---------------


def test_shared_coloured_noise_variance_and_grace_wrapper():
    """White two-sided PSD K² → variance K² fs, for both ways of drawing the white noise;
    the GRACE simulator's one-sided ASD form is the same generator."""
    from accal.simulate.grace import coloured_noise as grace_noise
    from accal.simulate.noise import coloured_noise

    fs, k2 = 2.0, 4.0
    white = TabulatedPSD(np.array([1e-6, 10.0]), np.array([k2, k2]))
    for how, pad in (("frequency", True), ("time", False)):
        x = coloured_noise(20000, white, fs, np.random.default_rng(1), size=4, pad=pad, white=how)
        assert x.shape == (4, 20000)
        assert np.var(x) == pytest.approx(k2 * fs, rel=0.03)
    level, corner, dt = 1e-10, 1e-3, 0.5
    a = grace_noise(1000, dt, level, corner, np.random.default_rng(7))

    def psd(f):
        with np.errstate(divide="ignore"):
            return 0.5 * level**2 * (1 + corner / np.abs(f))

    b = coloured_noise(1000, psd, 1 / dt, np.random.default_rng(7), pad=False, white="time")[0]
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValidationError, match="'white' parameter"):
        coloured_noise(10, white, fs, np.random.default_rng(0), white="pink")


def test_simulate_gap_chunks_continue_the_record():
    """Noise-free: the blocks of simulate_gap_chunks concatenate to simulate_gap's record
    (bias drift, signal phase and the temperature filter run on across blocks)."""
    from accal.simulate.gap import simulate_gap, simulate_gap_chunks

    kw = dict(days=0.5, seed=1, temperature_coupling=2e-9, noise=False, signal_amplitude=1e-9)
    data, truth = simulate_gap(**kw)
    blocks = list(simulate_gap_chunks(**kw, chunk_days=0.1))
    assert len(blocks) == 6 and blocks[1][0]["time"][0] == 14 * 600.0
    for col in data:
        np.testing.assert_array_equal(np.concatenate([b[0][col] for b in blocks]), data[col])
    for col in truth:
        np.testing.assert_array_equal(np.concatenate([b[1][col] for b in blocks]), truth[col])
    # with noise, one block is the whole record: same draws as simulate_gap
    d1, _ = simulate_gap(days=0.1, seed=3)
    ((d2, _),) = simulate_gap_chunks(days=0.1, seed=3, chunk_days=1.0)
    np.testing.assert_array_equal(d1["m_y"], d2["m_y"])
