"""What the null model does with signal it cannot resolve: pulses and steep orbit edges.  The data are drawn here, not with
``accal simulate`` or ``tests.indep``.

Found in closure-detection (issue 19): on GRACE-FO storm + thruster days 5 of 12 days
had false bias steps removed, among them thruster pulses not screened (their ghosts in
the orbit template put > 2 % of the samples over the outlier threshold, so none was
left out) and penumbra ramps whose sub-sample phase the one-sample bins cannot follow.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from accal.closure import close_loop
from accal.closure.nuisance import OrbitTemplate
from accal.closure.outliers import spikes

PERIOD = 997.3  # [s] not a whole number of samples: the bins' phase jitters
N_ORBITS = 16


def _smooth_noise(n, level, rng, width=8):
    """Low-passed (CRN-like: smooth from sample to sample) Gaussian noise of RMS ``level``."""
    x = uniform_filter1d(uniform_filter1d(rng.standard_normal(n + 64), width), width)[32:-32]
    return level * x / np.std(x)


def _ramp_profile(phase, width=0.04):
    """An eclipse-like illumination: 1, a linear ramp down over ``width`` of the orbit,
    0 in shadow, a ramp back up (fractions of the orbit)."""
    a, b = 0.30, 0.65
    up = np.clip((phase - a) / width, 0, 1)
    down = np.clip((phase - b) / width, 0, 1)
    return 1.0 - up + down


def test_spikes_flags_pulses_on_smooth_data_and_nothing_else():
    rng = np.random.default_rng(1)
    n = 20000
    t = np.arange(n, dtype=float)
    x = 3e-8 * np.sin(2 * np.pi * t / PERIOD) + 2e-8 * _ramp_profile((t / PERIOD) % 1.0)
    x += 1e-12 * t + np.where(t >= 12345, 4e-9, 0.0)  # a drift and a bias step
    x += _smooth_noise(n, 1e-10, rng)
    pulses = np.zeros(n, bool)
    for start in rng.choice(np.arange(100, n - 100), 40, replace=False):
        width = int(rng.integers(1, 6))
        # ≥ 3e-9: 45 σ of the noise's wiggles, beyond the one-sided medians' lag on the
        # sine's slope (up to 1.3e-9 over their 7-sample half-window)
        x[start : start + width] += rng.choice([-1, 1]) * 10 ** rng.uniform(-8.5, -7)
        pulses[start : start + width] = True
    hit = spikes(x, None, t)
    assert hit[pulses].all()
    # the step is not a pulse: in this very smooth noise a few samples at its edge may be
    # left out (test_a_real_step_among_pulses_is_found: the step is then still found)
    assert hit[12330:12360].sum() <= 10
    # besides the pulses and their padding, next to nothing
    near = np.convolve(pulses, np.ones(7), mode="same") > 0
    assert int((hit & ~near).sum()) <= 0.005 * n  # a few ramp corners


def test_spikes_leaves_white_noise_alone():
    rng = np.random.default_rng(2)
    x = rng.standard_normal(30000)
    assert spikes(x, None, np.arange(x.size, dtype=float)).sum() == 0


def test_unresolved_flags_steep_edges_only():
    rng = np.random.default_rng(3)
    n = int(N_ORBITS * PERIOD)
    t = np.arange(n, dtype=float)
    tm = OrbitTemplate(t, PERIOD, 2, 1)
    smooth = 2e-8 * np.cos(2 * np.pi * t / PERIOD) + 1e-10 * rng.standard_normal(n)
    assert not tm.unresolved(smooth, 1e-10).any()
    edges = 5e-8 * _ramp_profile((t / PERIOD) % 1.0, width=0.02)  # 20 s ramps
    hit = tm.unresolved(edges + 1e-10 * rng.standard_normal(n), 1e-10)
    ph = (t / PERIOD) % 1.0
    on_ramp = ((ph > 0.30) & (ph < 0.32)) | ((ph > 0.65) & (ph < 0.67))
    assert hit[on_ramp].mean() > 0.9
    assert hit[~on_ramp].mean() < 0.01


def _pulsed_day(seed, n_pulses=25, step=0.0):
    """A GRACE-FO-like axis without angular accelerations to flag its thruster firings:
    an orbit signal with eclipse ramps, smooth (CRN-like) noise, box pulses of 1-5 s
    (25 in 4.4 h: GRACE fires 2-6 an hour)."""
    rng = np.random.default_rng(seed)
    n = int(N_ORBITS * PERIOD)
    t = np.arange(n, dtype=float)
    ph = (t / PERIOD) % 1.0
    y = 2e-8 * np.cos(2 * np.pi * ph) + 3e-8 * _ramp_profile(ph) + 1e-9 + 1e-13 * t
    y += _smooth_noise(n, 1e-10, rng) + np.where(t >= 0.6 * n, step, 0.0)
    for start in rng.choice(np.arange(n - 10), n_pulses, replace=False):
        y[start : start + int(rng.integers(1, 6))] += rng.choice([-1, 1]) * 10 ** rng.uniform(
            -8, -7
        )
    return t, y


@pytest.mark.parametrize("seed", [21, 22])
def test_pulses_and_edges_are_not_taken_for_steps(seed):
    t, y = _pulsed_day(seed)
    res = close_loop(t, y, orbit_period=PERIOD, candidates=("bias_step",))
    assert not res.effects, [(e.name, e.epoch, e.coefficient) for e in res.effects]
    notes = {n["name"] for n in res.notes}
    assert "outliers" in notes


def test_a_real_step_among_pulses_is_found():
    t, y = _pulsed_day(23, step=1e-9)
    res = close_loop(t, y, orbit_period=PERIOD, candidates=("bias_step",))
    steps = [e for e in res.effects if e.name == "bias_step"]
    assert len(steps) == 1
    assert abs(steps[0].epoch - 0.6 * t.size) <= 2.0
    assert abs(steps[0].coefficient - 1e-9) < 3 * steps[0].sigma


def test_spikes_keeps_a_step_edge_on_a_steep_slope():
    """On the signal's slope (here 2e-10 m/s² per sample, a 4e-7 m/s² orbit term) the
    sample after an upward 3e-9 step is above both one-sided medians, like a pulse (it
    was left out with its neighbours, 1995-2003); lines fitted either side tell it is an
    edge between two levels, and a pulse on the same signal is still flagged."""
    rng = np.random.default_rng(3)
    n = 6000
    t = np.arange(n, dtype=float)
    x = 4e-7 * np.sin(2 * np.pi * t / 5600.0 + 2.0) + 3e-9 * (t >= 2000)
    x += _smooth_noise(n, 1e-10, rng)
    x[3000:3003] += 2e-8  # a 3-sample pulse
    hit = spikes(x, None, t)
    assert not hit[1980:2020].any(), np.flatnonzero(hit[1980:2020]) + 1980
    assert hit[3000:3003].all()


def test_a_level_shift_flagged_in_two_runs_is_kept():
    """The screen's runs a padding apart are judged as one: a step whose approach and
    ramp were flagged as two runs 2 samples apart was left out (each run had the other
    for a side); a burst split the same way is still left out."""
    from accal.closure.outliers import OUTLIER_PAD, _bursts_only

    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 1e-11, 2000)
    x[1000:] += 1e-8  # the step
    x[880:1000] += np.linspace(0.0, 3e-9, 120)  # the slope before it
    hit = np.zeros(x.size, bool)
    hit[880:990] = True
    hit[990 + 2 * OUTLIER_PAD - 2 : 1010] = True  # a gap of 2 samples
    assert hit.sum() < 130 and not hit[990]
    assert not _bursts_only(hit, x).any()
    y = rng.normal(0.0, 1e-11, 2000)
    y[900:1000] += 5e-9  # a burst: back to the level before
    burst = np.zeros(y.size, bool)
    burst[900:948] = True
    burst[950:1000] = True
    assert np.array_equal(_bursts_only(burst, y), burst)
