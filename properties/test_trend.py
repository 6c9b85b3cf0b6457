"""Hypothesis properties of the trend estimators: exactness and equivariance."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.estimators.trend import fit_trend

methods = st.sampled_from(["wavelet", "lsq"])


@st.composite
def sample_times(draw):
    """Uneven sampling with gaps, odd/even lengths, arbitrary epoch and step."""
    n = draw(st.integers(min_value=4, max_value=3000))
    step = draw(st.floats(min_value=1e-3, max_value=100.0))
    epoch = draw(st.floats(min_value=-1e9, max_value=1e9))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    steps = step * (1 + draw(st.floats(0, 0.9)) * rng.uniform(-1, 1, n - 1))
    n_gaps = draw(st.integers(0, 3))
    for _ in range(n_gaps):
        steps[rng.integers(0, n - 1)] *= rng.uniform(2, 500)
    return epoch + np.concatenate([[0.0], np.cumsum(steps)])


@settings(max_examples=150, deadline=None)
@given(
    t=sample_times(),
    b=st.floats(-1e-3, 1e-3),
    d=st.floats(-1e-6, 1e-6),
    method=methods,
)
def test_pure_linear_trend_is_exact(t, b, d, method):
    """A pure b + d·(t − t0) comes back to machine precision for any layout."""
    x = t - t[0]
    a = b + d * x
    fit = fit_trend(t, a, method=method)
    scale = abs(b) + abs(d) * x[-1] + 1e-300
    assert abs(fit.bias - b) <= 1e-12 * scale
    assert abs(fit.drift - d) * x[-1] <= 1e-12 * scale


@settings(max_examples=80, deadline=None)
@given(
    t=sample_times(),
    c=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
    method=methods,
)
def test_pure_quadratic_trend_is_exact_with_order2(t, c, method):
    x = (t - t[0]) / (t[-1] - t[0])  # coefficients in natural units of the span
    span = t[-1] - t[0]
    a = c[0] + c[1] * x + c[2] * x * x
    fit = fit_trend(t, a, method=method, order=2)
    scale = sum(abs(v) for v in c) + 1e-300
    # "exact" means to rounding times the conditioning of the layout: e.g. 4 samples in two
    # tight clusters at the ends of a long gap barely determine a quadratic (cond ~ 1e7)
    cond = float(np.linalg.cond(np.vander(x, 3, increasing=True)))
    tol = max(1.0, 1e-6 * cond)
    assert abs(fit.bias - c[0]) <= 1e-10 * tol * scale
    assert abs(fit.drift * span - c[1]) <= 1e-9 * tol * scale
    assert abs(fit.quadratic * span**2 - c[2]) <= 1e-9 * tol * scale


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(10, 2000),
    shift=st.floats(-1e-4, 1e-4),
    slope=st.floats(-1e-8, 1e-8),
    method=methods,
)
def test_adding_a_trend_moves_the_estimate_by_exactly_that_trend(seed, n, shift, slope, method):
    """Linearity: fit(a + b' + d'(t − t0)) = fit(a) + (b', d'); sigmas unchanged."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    a = 1e-6 * rng.standard_normal(n)
    f1 = fit_trend(t, a, method=method)
    f2 = fit_trend(t, a + shift + slope * (t - t[0]), method=method)
    assert abs((f2.bias - f1.bias) - shift) <= 1e-12 * (abs(shift) + 1e-6)
    assert abs((f2.drift - f1.drift) - slope) * (t[-1] - t[0]) <= 1e-12 * (
        abs(shift) + 1e-6
    ) + 1e-12 * abs(slope) * (t[-1] - t[0])
    np.testing.assert_allclose(f2.sigma, f1.sigma, rtol=1e-6)
