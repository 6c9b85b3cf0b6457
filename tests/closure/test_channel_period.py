"""``accal.closure.lagscan.channel_period``: the cycle a housekeeping channel repeats with.

QA (2026-11-30): on days whose temperature was heater square waves (1,500 s) a coupling
at 300 s was reported at 1,798 s, one cycle long.  Channels drawn here (numpy only).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.lagscan import channel_period


@pytest.mark.parametrize("period", [700.0, 1500.0, 2335.0])
def test_a_heater_square_wave_with_an_orbit_term_and_noise_repeats_with_its_cycle(period):
    rng = np.random.default_rng(int(period))
    t = np.arange(86_400.0)
    heater = 0.3 * np.sign(np.sin(2 * np.pi * t / period + 0.4))
    x = 293.0 + heater + 0.05 * np.sin(2 * np.pi * t / 5600.0) + 0.01 * rng.standard_normal(t.size)
    assert channel_period(x, 1.0) == pytest.approx(period, abs=3.0)
    # every 10 s, as an AHK table may be
    assert channel_period(x[::10], 10.0) == pytest.approx(period, abs=15.0)


@pytest.mark.parametrize("seed", range(3))
def test_a_random_walk_or_a_drift_does_not_repeat(seed):
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.standard_normal(86_400)) * 1e-3
    assert channel_period(walk, 1.0) == 0.0
    assert channel_period(293.0 + 1e-5 * np.arange(86_400.0), 1.0) == 0.0
    assert channel_period(rng.standard_normal(5000), 1.0) == 0.0
