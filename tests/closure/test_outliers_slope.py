"""The outlier screen on a sloped residual (``accal.closure.outliers.outliers``).

QA (2026-11-30): the null model's partial fit of a 1e-8 m/s² step on a quiet GRACE-A
axis left a residual sloping on both sides of the step (±4.2e-9 m/s² decaying over
~10 min, up to ~7e-12 m/s² per second); one-sided running medians lag such a slope, the 114
samples after the step were flagged with the step's edge, and the step was not found.
The residual is drawn here (numpy only) in that shape.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.outliers import outliers


def _sawtooth(seed: int, burst: bool):
    rng = np.random.default_rng(seed)
    n, e = 20_000, 12_000
    t = np.arange(n, dtype=np.float64)
    # the misfit the null model leaves around the step: ±4.2e-9 decaying over ~10 min
    r = np.sign(t - e + 0.5) * 4.2e-9 * np.exp(-np.abs(t - e + 0.5) / 600.0)
    r += rng.normal(0.0, 5e-10, n)
    for _ in range(7):  # the Level-1B low-pass: the step a ±35 s ramp
        r = np.convolve(np.r_[np.full(5, r[0]), r, np.full(5, r[-1])], np.ones(11) / 11, "valid")
    if burst:
        r[5_000:5_012] += 5e-9  # a 12-sample burst (a thruster firing's size)
    return t, r, e


@pytest.mark.parametrize("seed", range(6))
def test_the_slope_after_a_large_step_is_no_outlier_and_a_burst_still_is(seed):
    t, r, e = _sawtooth(seed, burst=True)
    bad = outliers(r, None, t)
    assert not bad[e + 10 : e + 400].any(), np.flatnonzero(bad[e : e + 400])[:5] + e
    assert bad[5_000:5_012].all()
    assert bad.sum() < 100  # the burst, the step's few ramp samples, nothing else
