"""Hypothesis properties of the demodulation (eqs. 14, 16, 17, 19).

Noise-free data built from eq. 4 with an affine signal and an affine bias per
record: the per-period means (and slopes, affine model) must come back to
machine precision, and adding a constant bias must change nothing.
"""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from accal.estimators.demod import demodulate
from accal.estimators.design import design_pattern, tile

PATTERN = design_pattern(600, 200, 1.0)
N_PER = 4
T, THETA = tile(PATTERN, N_PER)
Q = PATTERN.q

acc = st.floats(-1e-6, 1e-6, allow_nan=False)
rate = st.floats(-1e-9, 1e-9, allow_nan=False)  # [m s⁻³]
bias = st.floats(-1e-5, 1e-5, allow_nan=False)


def _measure(a0y, a1y, a0z, a1z, b0y, b1y, b0z, b1z):
    ay = a0y + a1y * T
    az = a0z + a1z * T
    c, s = np.cos(THETA), np.sin(THETA)
    my = c * ay + s * az + b0y + b1y * T
    mz = -s * ay + c * az + b0z + b1z * T
    return my, mz, ay, az


@settings(max_examples=30, deadline=None)
@given(acc, rate, acc, rate, bias, rate, bias, rate, st.sampled_from(["mean", "affine"]))
@example(0.0, 0.0, 0.0, 9.030577619568519e-10, 0.0, 0.0, 0.0, 0.0, "mean")
def test_exact_recovery_affine_signal_affine_bias(a0y, a1y, a0z, a1z, b0y, b1y, b0z, b1z, model):
    """To 1e-13 of the largest of the biases and the signal (a CI-like run found a
    signal of 1.9e-6 m/s² recovered to 8.8e-15 relative, against a tolerance set by the
    zero biases alone)."""
    my, mz, ay, az = _measure(a0y, a1y, a0z, a1z, b0y, b1y, b0z, b1z)
    r = demodulate(T, my, mz, THETA, tau=600, mask=200, signal_model=model)
    scale = max(abs(b0y), abs(b0z), abs(b1y * T[-1]), abs(b1z * T[-1]), 1e-7)
    scale = max(scale, float(np.abs(ay).max()), float(np.abs(az).max()))
    tol = 1e-13 * scale
    np.testing.assert_allclose(r.a_Y, ay.reshape(N_PER, Q).mean(axis=1), rtol=0, atol=tol)
    np.testing.assert_allclose(r.a_Z, az.reshape(N_PER, Q).mean(axis=1), rtol=0, atol=tol)
    if model == "affine":
        np.testing.assert_allclose(r.slope_Y, a1y, rtol=0, atol=tol / 60)
        np.testing.assert_allclose(r.slope_Z, a1z, rtol=0, atol=tol / 60)


@settings(max_examples=30, deadline=None)
@given(acc, acc, bias, st.sampled_from(["ls", "gls"]), st.sampled_from(["mean", "affine"]))
def test_constant_bias_changes_nothing(a0y, a0z, extra, method, model):
    rng = np.random.default_rng(0)
    my, mz, _, _ = _measure(a0y, 0.0, a0z, 0.0, 1e-6, 1e-11, -2e-6, 0.0)
    my = my + 5e-12 * rng.standard_normal(my.size)
    mz = mz + 5e-12 * rng.standard_normal(mz.size)
    kw = dict(tau=600, mask=200, method=method, signal_model=model)
    r0 = demodulate(T, my, mz, THETA, **kw)
    r1 = demodulate(T, my + extra, mz - extra, THETA, **kw)
    tol = 1e-15 * (abs(extra) + 1e-5) * 100
    np.testing.assert_allclose(r1.a_Y, r0.a_Y, rtol=0, atol=tol)
    np.testing.assert_allclose(r1.a_Z, r0.a_Z, rtol=0, atol=tol)
    np.testing.assert_allclose(r1.bias_y[:, 0] - r0.bias_y[:, 0], extra, rtol=0, atol=tol)
    np.testing.assert_array_equal(r1.sigma_Y, r0.sigma_Y)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.integers(1, 1500), min_size=1, max_size=6),
    st.sampled_from(["ls", "gls"]),
    st.sampled_from(["mean", "affine"]),
)
def test_chunking_changes_nothing(sizes, method, model):
    """demodulate_stream over chunks of any sizes equals demodulate on the whole record."""
    from accal.estimators.demod import DemodChunk, demodulate_stream

    rng = np.random.default_rng(1)
    my, mz, _, _ = _measure(2e-7, 1e-12, -1e-7, 0.0, 1e-6, 1e-11, -2e-6, 0.0)
    my = my + 5e-12 * rng.standard_normal(my.size)
    mz = mz + 5e-12 * rng.standard_normal(mz.size)
    kw = dict(tau=600, mask=200, method=method, signal_model=model)
    whole = demodulate(T, my, mz, THETA, **kw)

    def source():
        i = k = 0
        while i < T.size:
            sl = slice(i, i + sizes[k % len(sizes)])
            i, k = sl.stop, k + 1
            yield DemodChunk(T[sl], my[sl], mz[sl], THETA[sl])

    res = demodulate_stream(source, **kw)
    assert res.solver == whole.solver
    for f in ("a_Y", "a_Z", "sigma_Y", "Rd", "bias_y"):
        x, y = np.asarray(getattr(whole, f)), np.asarray(getattr(res, f))
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-12 * np.max(np.abs(x)), err_msg=f)
