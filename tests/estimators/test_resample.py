"""Resampling onto a uniform grid with gaps left as gaps (accal.estimators.resample)."""

import numpy as np
import pytest

from accal.errors import ValidationError
from accal.estimators.resample import UniformResampler, nominal_step, resample_uniform


def test_by_hand():
    """Jittered samples and a 4 s hole: grid points in the hole are marked, not filled."""
    t = np.array([0.0, 1.1, 1.9, 3.0, 4.0, 8.0, 9.0])
    y = 10 * t
    g, v, ok, rep = resample_uniform(t, {"y": y}, 1.0)
    np.testing.assert_array_equal(g, np.arange(10.0))
    assert ok.tolist() == [True] * 5 + [False] * 3 + [True] * 2
    np.testing.assert_allclose(v["y"][ok], 10 * g[ok])
    assert np.isnan(v["y"][~ok]).all()
    assert (rep.n_grid, rep.n_exact, rep.n_interpolated, rep.n_gap) == (10, 5, 2, 3)
    assert rep.n_gaps == 1 and rep.largest_gap == 4.0 and rep.n_input == 7
    # a lost sample makes a 2.1 s step: a gap at 2 steps, interpolated at 3
    t2, y2 = np.delete(t, 3), np.delete(y, 3)
    _, _, ok2, rep2 = resample_uniform(t2, {"y": y2}, 1.0)
    assert ok2.tolist() == [True, True, False, False, True, False, False, False, True, True]
    _, v3, ok3, rep3 = resample_uniform(t2, {"y": y2}, 1.0, gap_factor=3.0)
    assert ok3[:5].all() and not ok3[5:8].any() and rep3.n_gaps == 1
    np.testing.assert_allclose(v3["y"][2:4], [20.0, 30.0])


@pytest.mark.parametrize("sizes", [[1], [3, 5], [1000]])
def test_chunking_does_not_matter(sizes):
    rng = np.random.default_rng(0)
    t = np.arange(500) + rng.uniform(-0.05, 0.05, 500)
    t = np.delete(t, np.r_[100:104, 300])
    cols = {"a": np.sin(t / 30), "b": t**2}
    step = nominal_step(t, 600.0)
    g, v, ok, rep = resample_uniform(t, cols, step)
    r = UniformResampler(step)
    parts, i, k = [], 0, 0
    while i < t.size:
        sl = slice(i, i + sizes[k % len(sizes)])
        i, k = sl.stop, k + 1
        parts.append(r.push(t[sl], {n: c[sl] for n, c in cols.items()}))
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts]), g)
    for n in cols:
        np.testing.assert_array_equal(np.concatenate([p[1][n] for p in parts]), v[n])
    np.testing.assert_array_equal(np.concatenate([p[2] for p in parts]), ok)
    assert r.report == rep and rep.n_gap == 4 and rep.n_gaps == 1


def test_nominal_step_snaps_to_whole_samples_per_period():
    rng = np.random.default_rng(1)
    t = 0.1 * np.arange(20000) + rng.normal(0, 2e-3, 20000)  # 10 Hz with 2 ms jitter
    assert abs(float(np.median(np.diff(t))) - 0.1) > 1e-9
    assert nominal_step(t, 600.0) == 600.0 / 6000
    # 600.5 s at 1 Hz is not a whole number of samples: no snapping (demod says so)
    assert nominal_step(np.arange(100.0), 600.5) == 1.0
    with pytest.raises(ValidationError, match="at least 2 samples"):
        nominal_step([1.0])
