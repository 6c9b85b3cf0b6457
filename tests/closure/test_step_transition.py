"""A bias step in low-passed data is a ramp: its size is not taken for its shape.

The data are drawn here with numpy (white noise, a step through seven 10 s boxcars,
the CRN-like filter of the independent generator in ``tests/indep``), not with
``accal simulate``.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.edgekernel import END_CLEAR
from accal.closure.transition import SHIFTS, WIDTHS, transition_columns

from .conftest import WHITE_T0, close_white, white_noise_day


def _boxcar_ramp(t: np.ndarray, centre: float, length: int, order: int) -> np.ndarray:
    """A unit step at ``centre`` through ``order`` cascaded boxcars of ``length`` samples
    (1 Hz), sampled at ``t``: the cumulative sum of the cascade's impulse response."""
    k = np.array([1.0])
    for _ in range(order):
        k = np.convolve(k, np.ones(length) / length)
    x = np.arange(k.size) - (k.size - 1) / 2
    cdf = np.cumsum(k)
    return np.interp(t - centre, x, cdf, left=0.0, right=1.0)


def test_the_columns_are_local_and_follow_the_sampling():
    t = np.arange(-500.0, 500.0)
    parts = transition_columns(t, 0.0, 1.0)
    assert [k for k, _ in parts] == [f"transition_w{w:g}" for w in WIDTHS] + [
        f"transition_shift{w:g}" for w in SHIFTS
    ]
    for _, col in parts:
        assert col.shape == (t.size, 1)
        assert np.all(col[np.abs(t) > 150] == 0.0)  # zero far from the epoch
        assert np.any(col[np.abs(t) < 5] != 0.0)
    # at a 10 s sampling the narrow ramps are the edge itself: left out
    coarse = transition_columns(np.arange(-500.0, 500.0, 10.0), 0.0, 10.0)
    assert [k for k, _ in coarse] == ["transition_w7", "transition_w11", "transition_shift6"]


@pytest.mark.parametrize("length", [3, 5, 10])
@pytest.mark.parametrize("shift", [-3.0, 0.0, 2.0])
def test_the_span_holds_boxcar_ramps(length, shift):
    """The part of a ramp's misfit to the edge that the columns cannot fit has a small
    one-sided area (what biases the size), against the edge alone."""
    t = np.arange(-80.0, 80.0)
    edge = (t >= 0).astype(float)
    misfit = _boxcar_ramp(t, shift - 0.5, length, 7) - edge
    cols = np.column_stack([c for _, c in transition_columns(t, 0.0, 1.0)])
    rest = misfit - cols @ np.linalg.lstsq(cols, misfit, rcond=None)[0]
    before = abs(misfit[t < 0].sum())
    after = abs(rest[t < 0].sum())
    assert after < 0.3  # seconds times the size: the bias the edge alone takes
    if before > 0.5:  # a short ramp shifted by 2 s is nearly the edge: 0.32 s
        assert after < 0.25 * before


def _ramp_day(seed: int, size: float):
    t, y = white_noise_day(seed, 43200)
    rng = np.random.default_rng([seed, 5])
    epoch = WHITE_T0 + float(rng.uniform(0.2, 0.8)) * 43200
    y = y + size * _boxcar_ramp(t, epoch, 10, 7)
    return t, y, epoch


def _close(t, y, transition: bool):
    from accal.closure import close_loop

    return close_loop(t, y, orbit_period=5600.0, candidates=("bias_step",),
                      options={"orbit_period_fixed": True, "step_transition": transition})  # fmt: skip


def test_a_filtered_step_is_measured_without_the_ramps_bias():
    """With the orbit template in the null model a step's information is local, and an
    edge fitted to a 70 s ramp came out small by many σ; with the transition columns
    the size is within its σ."""
    z_edge, z_ramp = [], []
    for seed in (11, 12, 13):
        t, y, epoch = _ramp_day(seed, 1e-8)
        for transition, out in ((False, z_edge), (True, z_ramp)):
            res = _close(t, y, transition)
            steps = [e for e in res.effects if e.name == "bias_step"]
            assert len(steps) == 1 and abs(steps[0].epoch - epoch) < 10
            e = steps[0]
            out.append((e.coefficient - 1e-8) / e.sigma)
            if transition:
                assert e.details["n_columns"] == 1 + len(WIDTHS) + len(SHIFTS)
    assert np.all(np.abs(z_ramp) < 3), z_ramp
    assert np.mean(np.abs(z_edge)) > 2 * np.mean(np.abs(z_ramp)), (z_edge, z_ramp)


def test_without_the_option_the_step_is_an_edge():
    t, y, _ = _ramp_day(14, 1e-8)
    res = close_white(t, y, ["bias_step"])
    (e,) = [e for e in res.effects if e.name == "bias_step"]
    assert e.details["n_columns"] == 1


@pytest.mark.parametrize("length", [30, 300])
@pytest.mark.parametrize("at_end", [False, True])
def test_an_offset_of_the_record_s_first_samples_is_not_a_step(at_end, length):
    """A level change close to the record's end is no level: a step at a
    ``tests/indep`` day's 10th sample (4.2e-9 ± 8e-10 m/s², the record's first samples
    off) was removed and moved the bias by 3.7σ; on a QA thruster day "steps" 82 s and
    133 s into the record, between screened firings, moved the z bias 9σ and 5σ.  A
    least-squares step of low-passed data needs ``END_CLEAR`` (600 s) on either side;
    an offset of the first (or last) 30 or 300 samples, 6σ each (under the outlier
    screen's 10σ), is left alone."""
    t, y = white_noise_day(21, 43200)
    if at_end:
        y[-length:] += 6e-10
    else:
        y[:length] += 6e-10
    res = _close(t, y, True)
    ends = (t[0] + END_CLEAR, t[-1] - END_CLEAR)
    near = [e for e in res.effects if e.name == "bias_step" and not ends[0] <= e.epoch <= ends[1]]
    assert not near, near


def _linear_ramp_day(seed: int, size: float, duration: float):
    """A white-noise day with a bias change of ``size`` spread linearly over ``duration``
    seconds, then through seven 10 s boxcars (the Level-1B filter's stand-in)."""
    t, y = white_noise_day(seed, 43200)
    rng = np.random.default_rng([seed, 7])
    epoch = WHITE_T0 + float(rng.uniform(0.3, 0.7)) * 43200
    lin = np.clip((t - epoch) / duration + 0.5, 0.0, 1.0)
    k = np.array([1.0])
    for _ in range(7):
        k = np.convolve(k, np.ones(10) / 10)
    ramp = np.convolve(np.r_[np.zeros(k.size), lin, np.ones(k.size)], k, "same")[k.size : -k.size]
    return t, y + size * ramp, epoch


@pytest.mark.parametrize("duration", [300.0, 600.0])
def test_a_bias_change_over_minutes_is_fitted_as_a_ramp(duration):
    """A bias change over 5 or 10 min (QA of 2026-11-29: 5e-9 m/s² over 5 min came out
    3.83e-9 ± 3.2e-10, z −3.6): the data ask for a ramp (``closure.softstep``) of about
    its duration, and the size is within 3σ; a filtered sharp step of the same size
    stays an edge."""
    for seed in (31, 32):
        t, y, epoch = _linear_ramp_day(seed, 2e-9, duration)
        (e,) = [e for e in _close(t, y, True).effects if e.name == "bias_step"]
        assert abs(e.epoch - epoch) < 0.5 * duration
        assert 0.5 * duration <= e.details["ramp_duration"] <= 2.0 * duration
        assert abs(e.coefficient - 2e-9) < 3.0 * e.sigma, (e.coefficient, e.sigma)
        t, y, epoch = _ramp_day(seed, 2e-9)
        (e,) = [e for e in _close(t, y, True).effects if e.name == "bias_step"]
        assert "ramp_duration" not in e.details
