"""A reference sampled more sparsely than the data: the cubic spline of
``accal.gracejob.reading.interpolate_reference`` (and ``subtract_reference``).

QA (2026-11-29): a 10 s reference interpolated linearly onto 1 Hz data biased the
fitted z scale by −3.5e-4.  Data drawn here (numpy only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.gracejob.reading import interpolate_reference, subtract_reference
from accal.series import AccSeries

P = 5600.0  # orbit period [s]


def _reference(tr: np.ndarray, acc: np.ndarray, valid=None) -> AccSeries:
    return AccSeries(time=tr, acc=acc, valid=np.ones(tr.size, bool) if valid is None else valid)


def _drag_day(t: np.ndarray) -> np.ndarray:
    """Drag with 1/rev and 2/rev terms, a ~300 s wave, a radial term with eclipses."""
    rng = np.random.default_rng(3)
    ph = 2 * np.pi * t / P
    wave = sum(
        rng.normal() * np.cos(2 * np.pi * t / p + rng.uniform(0, 6)) for p in (250, 330, 410)
    )
    drag = -2e-7 * (1 + 0.3 * np.cos(ph) + 0.08 * np.cos(2 * ph)) * (1 + 0.02 * wave)
    sun = 1 / (1 + np.exp(-(np.cos(ph - 0.3) + 0.6) / (2 * np.pi / P * 10)))  # 40 s penumbra
    return np.column_stack([drag, 1e-8 * np.cos(ph + 1), 3e-8 * np.sin(ph + 0.3) + 1e-8 * sun])


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.floats(4.0, 9.9), min_size=4, max_size=60),  # no step a hole
    coef=st.lists(st.floats(-1e-6, 1e-6), min_size=4, max_size=4),
)
def test_a_cubic_is_reproduced_at_every_epoch_between_any_samples(steps, coef):
    """A not-a-knot cubic spline reproduces a cubic polynomial exactly, whatever the spacing
    (irregular, no step over 2.5 times the median: longer ones are holes)."""
    tr = np.cumsum(np.r_[0.0, steps])
    u = (tr - tr.mean()) / np.ptp(tr)
    poly = np.polynomial.Polynomial(coef)
    ref = _reference(tr, np.column_stack([poly(u), -poly(u), 2 * poly(u)]))
    t = np.linspace(tr[0], tr[-1], 301)
    got = interpolate_reference(ref, ("x", "y", "z"), t)
    want = poly((t - tr.mean()) / np.ptp(tr))
    scale = max(np.abs(coef).max(), 1e-300)
    np.testing.assert_allclose(got[:, 0], want, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(got[:, 2], 2 * want, rtol=0, atol=2e-10 * scale)


def test_a_10_s_reference_of_a_drag_day_is_interpolated_50_times_closer_than_linearly():
    t = np.arange(0.0, 43_201.0)
    truth = _drag_day(t)
    tr = t[::10]
    got = interpolate_reference(_reference(tr, truth[::10]), ("x", "y", "z"), t)
    err = got - truth
    lin = np.column_stack([np.interp(t, tr, truth[::10, i]) for i in range(3)]) - truth
    rms, rms_lin = np.sqrt((err**2).mean(0)), np.sqrt((lin**2).mean(0))
    assert np.all(rms[:2] < rms_lin[:2] / 20), (rms, rms_lin)  # smooth axes
    assert rms[2] < rms_lin[2] / 2, (rms, rms_lin)  # the eclipse edges limit z
    # what a scale fit sees: the error's regression on the signal, per axis
    for i in range(3):
        s = truth[:, i] - truth[:, i].mean()
        assert abs(s @ err[:, i] / (s @ s)) < 2e-6 < abs(s @ lin[:, i] / (s @ s)), i
    # at the reference's own epochs the data get the reference itself
    np.testing.assert_allclose(got[::10], truth[::10], rtol=1e-15, atol=0)


def test_invalid_and_non_finite_reference_samples_are_not_interpolated_through():
    t = np.arange(0.0, 2_001.0)
    tr = t[::5].copy()
    acc = _drag_day(tr)
    valid = np.ones(tr.size, bool)
    valid[100] = False  # flagged (its value is garbage)
    acc[100] = 1e3
    acc[200, 1] = np.nan  # a non-finite value of a valid sample
    ref = _reference(tr, acc, valid)
    got = interpolate_reference(ref, ("x", "y", "z"), t)
    assert np.isfinite(got).all() and np.abs(got).max() < 1e-6
    series = AccSeries(time=t, acc=np.zeros((t.size, 3)) + 1e-7)
    out = subtract_reference(series, ref, Path("ref.parquet"))
    # the data next to the flagged sample are left out (no bridge through it), the rest kept
    assert not out.valid[(t > tr[99]) & (t < tr[101])].any()
    assert np.isfinite(out.acc[out.valid]).all() and out.valid.sum() > 0.98 * t.size


def test_a_hole_is_not_bridged_by_the_spline_and_its_edges_stay_exact():
    """A 10 s reference with a 10-minute hole: a spline per stretch (a cubic over the
    hole would ring into its edges); inside the hole NaN."""
    t = np.arange(0.0, 20_001.0)
    truth = _drag_day(t)
    tr = t[::10]
    keep = (tr < 8_000.0) | (tr > 8_600.0)
    got = interpolate_reference(_reference(tr[keep], truth[::10][keep]), ("x", "y", "z"), t)
    hole = (t > 7_990.0) & (t < 8_610.0)
    assert np.isnan(got[hole]).all() and np.isfinite(got[~hole]).all()
    near = ((t > 7_900.0) & (t <= 7_990.0)) | ((t >= 8_610.0) & (t < 8_700.0))
    lin = np.column_stack([np.interp(t, tr, truth[::10, i]) for i in range(3)])
    err, err_lin = np.abs(got[near] - truth[near]), np.abs(lin[near] - truth[near])
    assert np.all(err.max(0)[:2] < err_lin.max(0)[:2])  # better than linear up to the hole
