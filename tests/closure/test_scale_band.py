"""A scale error against a reference that is not filtered like the data (closure.scaleband).

Data drawn here (numpy only, not ``accal simulate`` nor ``tests.indep``): along-track
drag with a once-per-revolution modulation, solar pressure switched off in eclipses
with 40 s ramps (sharp in the reference, as a modelled one is), the measured series
through a Level-1B-like low-pass (four centred 11-sample moving averages), white noise and a
bias; the reference has its own noise.  Above the filter's passband ``raw − reference`` holds ``LP(a) − a``, which a
regressor of the whole reference takes for a scale error (QA, 2026-11-29: −3.2 % on y
at 7σ on a clean day, the bias moved 7.4σ).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop
from accal.closure.scaleband import band_limited

P = 5650.0  # orbit period [s]


def _moving_average(x: np.ndarray, width: int = 11, passes: int = 4) -> np.ndarray:
    for _ in range(passes):
        pad = np.r_[np.full(width, x[0]), x, np.full(width, x[-1])]
        x = np.convolve(pad, np.ones(width) / width, "same")[width:-width]
    return x


def reference_day(seed: int, axis: int, scale_error: float = 0.0):
    """``(t, y, ref)``: 1 Hz, one day, ``y = raw − ref`` on ``axis`` (0 along-track, 1
    cross-track: solar pressure dominates), raw = (1 + scale_error)·LP(a) + b + noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(86400.0)
    u = 2 * np.pi * t / P + rng.uniform(0, 2 * np.pi)
    drag = -rng.uniform(1e-7, 5e-7) * (1 + rng.uniform(0.1, 0.4) * np.cos(u - 0.5))
    # eclipse: 35 % of each orbit, 40 s linear ramps (penumbra)
    phase = np.mod(u, 2 * np.pi) / (2 * np.pi) * P
    start, stop = 0.4 * P, 0.75 * P
    illum = np.clip(np.maximum(start - phase, phase - stop) / 40.0 + 0.5, 0.0, 1.0)
    srp = rng.uniform(3e-8, 6e-8) * illum
    a = [drag + 0.2 * srp * np.sin(u), 0.02 * drag - srp, 0.01 * drag + 0.3 * srp * np.cos(u)][axis]
    raw = (1 + scale_error) * _moving_average(a) + 2e-6 + 1e-10 * rng.standard_normal(t.size)
    # a modelled reference's own error: white 1e-9 m/s² per sample averaged over 45 s
    ref = a + np.convolve(1e-9 * rng.standard_normal(t.size), np.ones(45) / 45, "same")
    return t, raw - ref, ref


def _scale(res):
    return [e for e in res.effects if e.name == "scale"]


@pytest.mark.parametrize("seed, axis", [(4, 2), (6, 2), (1, 1), (3, 0)])
def test_a_sharper_reference_is_no_scale_error(seed, axis):
    """Clean days: no scale error removed (before the band limit: −2.7e-3 ± 8.6e-4 and
    −2.1e-3 ± 6.6e-4 on the radial axis of the first two)."""
    t, y, ref = reference_day(seed, axis)
    res = close_loop(t, y, base="poly1", reference=ref, candidates=("scale",), alpha=0.01)
    assert not _scale(res), _scale(res)


@pytest.mark.parametrize("seed, axis, error", [(5, 0, 0.01), (6, 1, 0.02), (7, 0, -0.003)])
def test_a_scale_error_is_found_in_the_band(seed, axis, error):
    """A real scale error, same data and reference: found, within 3σ of ``error``."""
    t, y, ref = reference_day(seed, axis, error)
    res = close_loop(t, y, base="poly1", reference=ref, candidates=("scale",), alpha=0.01)
    (e,) = _scale(res)
    assert abs(e.coefficient - error) < 3 * e.sigma, (e.coefficient, e.sigma)


def test_band_limited_passes_the_band_and_bridges_gaps():
    """Sinusoids below the cut-off pass unchanged (away from the ends' reflection),
    those above are removed; with a gap the output has the input's samples, finite."""
    t = np.arange(40000.0)
    low = np.sin(2 * np.pi * 2e-4 * t) + 0.3 * t / t[-1]
    high = np.sin(2 * np.pi * 5e-3 * t)
    out = band_limited(t, low + high, 1.0)
    inner = slice(10000, -10000)
    assert np.max(np.abs(out[inner] - low[inner])) < 0.02
    keep = np.ones(t.size, bool)
    keep[18000:19000] = False
    out = band_limited(t[keep], (low + high)[keep], 1.0)
    assert out.shape == (int(keep.sum()),) and np.all(np.isfinite(out))
