"""Bias jumps and noise with memory whose innovations are heavy-tailed (closure.jumps).

Data drawn here (numpy/scipy only, not ``accal simulate`` nor ``tests.indep``): an
orbit-periodic signal whose amplitude grows, white noise, and an AR(1) process of
20 min correlation time whose innovations are either Gaussian or Student-t with 2.2
degrees of freedom (the QA helper's "kicks" of 2026-11-29: each a jump that decays
over ~20 min), all through the Level-1B low-pass (seven 11-sample moving averages).

The spectrum-weighted step test weighs a step under such a spectrum mostly by the
innovation at its epoch: with Gaussian innovations its σ holds and clean days lose
nothing; with heavy-tailed ones a day's largest kicks pass as bias steps (6 of 12
days here, 4 of 5 QA days).  Measured in the eleventh and twelfth stops
(docs/closure.md, "Heavy-tailed kicks"): the level an hour after such a kick cannot
be told from the jump's once the orbit template and the smooth curve are in the
null model (σ of the size with ±600-3,600 s left out 6e-10 to 7e-9 m/s² against
the jump's 1e-10), so nothing here tells a kick from a step yet.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from accal.closure import close_loop

P = 5600.0  # orbit period [s]


def kick_day(seed: int, heavy: bool, n_orbits: int = 6):
    """``(t, y)``: 1 Hz, ``n_orbits`` orbits; AR(1) of 20 min and 3e-10 m/s² (its
    stationary σ) driven by Student-t (ν = 2.2, unit variance) or Gaussian innovations,
    1e-10 m/s² white noise, the Level-1B low-pass."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(n_orbits * P), dtype=np.float64)
    w = 2 * np.pi / P
    y = (1 + 0.1 * t / t[-1]) * (2e-7 * np.cos(w * t) + 5e-8 * np.cos(2 * w * t + 1.0)) - 3e-7
    phi = np.exp(-1.0 / 1200.0)
    if heavy:
        innov = rng.standard_t(2.2, t.size) / np.sqrt(2.2 / 0.2)
    else:
        innov = rng.standard_normal(t.size)
    y += lfilter([1.0], [1.0, -phi], innov * 3e-10 * np.sqrt(1 - phi * phi))
    y += rng.normal(0.0, 1e-10, t.size)
    for _ in range(7):  # centred 11-sample moving average, ends held
        y = np.convolve(np.r_[np.full(5, y[0]), y, np.full(5, y[-1])], np.ones(11) / 11, "valid")
    return t, y


def _instrument(t, y):
    res = close_loop(t, y, base="poly1", orbit_period=P, candidates=("bias_step",), alpha=0.01)
    return [e for e in res.effects if e.instrument]


def test_gaussian_kicks_leave_clean_days_alone():
    """The same process with Gaussian innovations: nothing removed on 5 days."""
    found = {seed: _instrument(*kick_day(seed, heavy=False)) for seed in range(5)}
    assert not any(found.values()), found


@pytest.mark.xfail(
    strict=True,
    reason="heavy-tailed innovations of noise with memory: a day's largest kicks pass the "
    "spectrum-weighted step test (6 of these 12 days), and their decay cannot be told "
    "from a step's level given the orbit template and smooth curve (docs/closure.md)",
)
def test_heavy_tailed_kicks_are_not_bias_steps():
    found = {seed: _instrument(*kick_day(seed, heavy=True)) for seed in range(12)}
    assert not any(found.values()), {k: v for k, v in found.items() if v}
