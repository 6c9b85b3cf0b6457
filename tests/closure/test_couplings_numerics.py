"""The coupling search's numerical kernels against scipy.signal (exact cases).

The closure avoids importing ``scipy.signal`` at run time (its import costs ~0.6 s);
these tests hold its replacements to the library's results.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import correlate, lfilter

from accal.closure.couplings import first_order
from accal.closure.lagscan import correlate_valid


@pytest.mark.parametrize("tau", [0.5, 3.0, 300.0, 3000.0, 1e6])
def test_first_order_is_lfilter(tau):
    rng = np.random.default_rng(3)
    x = 293.0 + np.cumsum(rng.standard_normal(20_000)) * 0.01
    a = np.exp(-1.0 / tau)
    want = lfilter([1 - a], [1, -a], x - x[0]) + x[0]
    got = first_order(x, 1.0, tau)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(x)))


def test_first_order_step_response_is_exponential():
    # a unit step at k = 0 after a settled zero: y[k] = 1 − a^(k+1), the ZOH solution
    x = np.r_[0.0, np.ones(1000)]
    y = first_order(x, 2.0, 50.0)
    a = np.exp(-2.0 / 50.0)
    np.testing.assert_allclose(y[1:], 1.0 - a ** np.arange(1, 1001), rtol=0, atol=1e-14)
    assert np.array_equal(first_order(x, 1.0, 0.0), x)  # τ = 0: no filter


@settings(max_examples=60, deadline=None)
@given(
    n_r=st.integers(1, 300),
    extra=st.integers(0, 200),
    seed=st.integers(0, 2**31 - 1),
)
def test_correlate_valid_is_scipy(n_r, extra, seed):
    rng = np.random.default_rng(seed)
    h = rng.standard_normal(n_r + extra)
    r = rng.standard_normal(n_r)
    want = correlate(h, r, mode="valid", method="direct")
    got = correlate_valid(h, r)
    assert got.shape == want.shape
    scale = np.sqrt(np.sum(h**2) * np.sum(r**2))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)
