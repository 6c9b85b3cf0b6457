"""Bias-step sizes under strongly red noise, on days drawn here (numpy and scipy only).

A black-box QA pass (2026-11-29, its own generator: AR(1) noise with τ of 10-60 min, a
random walk, boxcar or Butterworth low-pass) found step sizes larger than the truth on
13 of 16 days (z RMS 1.53, median +5 %).  The days below reproduce it: 3e-9 m/s² steps
come out at 3.05-3.65e-9 ± ~4e-10 (mean z ≈ +0.9 over 20 days), while the same steps
in white + 1/f noise (``tests/closure/test_jumps.py``, ``make closure-detection``) are
unbiased.  Not understood yet (issue 19): the size is additive to the day, not
proportional to the step, and does not come from where the epoch is placed (1-3 s).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from accal.closure import close_loop

N = 86400


def _red_day(seed: int, size: float):
    """A cross-track axis: solar pressure switched off in eclipse (40 s ramps), AR(1)
    noise of 7e-10 m/s² with τ 25-60 min, a random walk reaching ~1e-8 m/s² over the
    day, white noise, a step of ``size`` at 20-80 % of the day; three passes of a 10 s
    boxcar over everything (the data's low-pass)."""
    rng = np.random.default_rng(seed)
    t = np.arange(float(N))
    period = rng.uniform(5550.0, 5700.0)
    u = 2 * np.pi * t / period + rng.uniform(0, 2 * np.pi)
    beta = np.deg2rad(rng.uniform(-60, 60))
    shadow = 1.0 - np.convolve(
        (np.cos(beta) * np.cos(u) < -0.375).astype(float), np.ones(40) / 40, mode="same"
    )
    signal = 4e-8 * np.cos(beta) * np.sin(u) * shadow + 2e-9 * np.cos(u + 1.0)
    a = np.exp(-1.0 / rng.uniform(1500.0, 3500.0))
    noise = lfilter([np.sqrt(1 - a * a) * 7e-10], [1.0, -a], rng.standard_normal(N))
    noise += np.cumsum(rng.standard_normal(N)) * 1e-8 / np.sqrt(N)
    noise += 7.5e-11 * rng.standard_normal(N)
    epoch = float(rng.integers(int(0.2 * N), int(0.8 * N)))
    y = -2.85e-5 + signal + noise + size * (t >= epoch)
    for _ in range(3):
        y = np.convolve(np.pad(y, 10, mode="edge"), np.ones(10) / 10, mode="same")[10:-10]
    return t, y, period, epoch


@pytest.mark.xfail(
    reason="step sizes under AR(1) + random-walk noise come out ~0.9σ too large on "
    "average (QA 2026-11-29; module notes); open",
    strict=False,
)
def test_step_sizes_under_red_noise_are_unbiased():
    z = []
    for seed in range(6):
        t, y, period, epoch = _red_day(seed, 3e-9)
        res = close_loop(t, y, orbit_period=period, options={"step_transition": True})
        steps = [e for e in res.effects if e.name == "bias_step" and abs(e.epoch - epoch) < 60]
        z += [(e.coefficient - 3e-9) / e.sigma for e in steps]
    assert len(z) >= 4
    assert abs(np.mean(z)) < 0.5, z
