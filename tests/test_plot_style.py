"""accal.plot_style: the acceleration units and the binned envelope every plot uses."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.plot_style import accel_scale, envelope


def test_envelope_is_the_mean_min_max_of_each_interval():
    x = np.arange(10_000, dtype=float)
    y = np.sin(x / 50.0) + 1e-3 * x
    c, mean, lo, hi = envelope(x, y, bins=100)
    edges = np.linspace(0.0, 9999.0, 101)
    for k in (0, 37, 99):
        sel = (x >= edges[k]) & ((x < edges[k + 1]) if k < 99 else (x <= edges[k + 1]))
        assert mean[k] == np.mean(y[sel]) or abs(mean[k] - np.mean(y[sel])) < 1e-14
        assert lo[k] == y[sel].min() and hi[k] == y[sel].max()
        assert c[k] == 0.5 * (edges[k] + edges[k + 1])


def test_envelope_breaks_at_gaps_and_keeps_short_series():
    x = np.r_[np.arange(3000.0), np.arange(7000.0, 10_000.0)]
    c, mean, lo, hi = envelope(x, np.ones_like(x), bins=100)
    gap = (c > 3000.0) & (c < 7000.0)
    assert gap.any() and np.all(np.isnan(mean[gap])) and np.all(np.isnan(hi[gap]))
    assert np.all(mean[~np.isnan(mean)] == 1.0)
    short = np.arange(150.0)
    out = envelope(short, short * 2.0, bins=100)
    assert all(
        np.array_equal(a, b)
        for a, b in zip(out, (short, short * 2, short * 2, short * 2), strict=True)
    )


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(300, 5000),
    bins=st.integers(2, 140),
    seed=st.integers(0, 2**32 - 1),
)
def test_envelope_keeps_every_extreme(n, bins, seed):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(0.1, 2.0, n))
    y = rng.standard_normal(n) * 1e-9
    c, mean, lo, hi = envelope(x, y, bins=bins)
    ok = ~np.isnan(mean)
    assert np.all(lo[ok] <= mean[ok] + 1e-24) and np.all(mean[ok] <= hi[ok] + 1e-24)
    assert np.nanmax(hi) == y.max() and np.nanmin(lo) == y.min()
    assert np.all(np.diff(c) > 0)


def test_accel_scale_picks_the_prefix_that_fits():
    assert accel_scale(np.array([3e-13, np.nan])) == (1e12, "pm/s²")
    assert accel_scale(np.array([-4.2e-9, 1e-10])) == (1e9, "nm/s²")
    assert accel_scale(np.array([1.5e-6])) == (1e6, "µm/s²")
    assert accel_scale(np.array([1.5e-7])) == (1e9, "nm/s²")  # 150 nm/s², not 0.15 µm/s²
    assert accel_scale(np.array([2.0])) == (1.0, "m/s²")
    assert accel_scale(np.array([np.nan])) == (1e12, "pm/s²")
