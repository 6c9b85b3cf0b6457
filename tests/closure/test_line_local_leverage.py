"""A spectral line is tested against the noise the model left, not the noise it took.

A line's test compares it with the residual periodogram around its frequency.  With
the orbit template in the null model (no reference) about a fifth of the noise is
fitted away, most of it near the orbit harmonics; the mean periodogram there
under-counted the noise, and lines of 1-3e-12 m/s² (2.5-4.4 times their σ) on white
noise were significant on 1 of 40 days (and 6 of 72 axes of a QA helper's CLI runs).
The local level is now the ratio estimator with the model's leverage.

The days are drawn here with numpy: one day at 1 Hz of a bias, a 1e-12 m/s²/s drift and
white noise of 1e-10 m/s² per sample.
"""

from __future__ import annotations

import numpy as np


def test_white_noise_day_has_no_line(white_day, close_white_day):
    """Seed 21: a 1.3e-12 m/s² line at 0.54 cycles per orbit (2.6 times its σ) had
    corrected p 0.006; nothing now."""
    res = close_white_day(*white_day(21), ("periodic",))
    assert res.effects == ()


def test_a_real_line_is_still_found(white_day, close_white_day):
    """A 5e-12 m/s² line (~10 times its σ) at 300 s on another white-noise day: found
    at its frequency, its amplitude within 3σ."""
    t, y = white_day(22)
    y = y + 5e-12 * np.sin(2 * np.pi * (t - t[0]) / 300.0 + 0.3)
    res = close_white_day(t, y, ("periodic",))
    lines = [e for e in res.effects if e.name == "periodic"]
    assert len(lines) == 1
    e = lines[0]
    assert abs(e.frequency * 300.0 - 1.0) < 1e-3
    assert abs(e.coefficient - 5e-12) < 3 * e.sigma
