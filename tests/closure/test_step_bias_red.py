"""Bias steps under strongly red noise, on days drawn here (numpy and scipy only).

A black-box QA pass (2026-11-29, its own generator: AR(1) noise with τ of 10-60 min, a
random walk, boxcar or Butterworth low-pass) found step sizes larger than the truth on
13 of 16 days (z RMS 1.53, median +5 %) and 3e-8 m/s² steps missed.  The days below
reproduce both (docs/closure.md): a step's size was the kernel's at the scan's epoch
(the largest of the kernels that hold the ramp) whenever its midpoint fell outside the
set of kernel epochs within 1σ of that one, and a step's own spectrum in the PSD estimate
levelled its z off below the threshold (a 3e-9 m/s² step found, 1e-8 at the same epoch
not).
"""

from __future__ import annotations

import numpy as np
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


def _found(seed: int, size: float):
    t, y, period, epoch = _red_day(seed, size)
    res = close_loop(t, y, orbit_period=period, options={"step_transition": True})
    steps = [e for e in res.effects if e.name == "bias_step" and abs(e.epoch - epoch) < 60]
    others = [e for e in res.effects if e.instrument and e not in steps]
    return steps, others


def test_a_large_step_is_not_hidden_by_its_own_spectrum():
    """Seed 11: before the scan tested its strongest edge with the PSD of the residual
    less that edge, nothing was significant with a 1e-8 m/s² step, and a 3e-9 step at
    the same epoch was found.  (A 3e-8 step there is found or not depending on the
    period estimate's last 1e-3 s: with its spectrum in, the PSD makes the kernel
    1,854 s wide, over jumps.HALF_MAX, and the day is not scanned; open.)"""
    steps, others = _found(11, 1e-8)
    assert len(steps) == 1 and not others, (steps, others)
    assert abs(steps[0].coefficient - 1e-8) < 3 * steps[0].sigma


def test_step_sizes_under_red_noise_are_calibrated():
    """±1e-8 m/s² steps (~25σ, found on every day): z RMS 0.57, mean +0.26 over these
    eight days (seed 7 was −1.63 with the size at the scan's epoch)."""
    z = []
    for seed in range(8):
        size = 1e-8 if seed % 2 == 0 else -1e-8
        steps, others = _found(seed, size)
        assert len(steps) == 1 and not others, (seed, steps, others)
        z.append((steps[0].coefficient - size) / steps[0].sigma)
    assert np.sqrt(np.mean(np.square(z))) < 1.2 and abs(np.mean(z)) < 0.6, z
