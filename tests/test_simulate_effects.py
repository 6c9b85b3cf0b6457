"""Injected instrument effects of ``accal simulate grace`` (accal.simulate.effects).

Every effect is checked the same way: the day simulated with the effect minus the
same day without it (same seed) is the effect's term, recomputed here from the
numbers of its specification with code of its own, to rounding; the other axes are
untouched, and the truth carries the exact parameters.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from accal.crn import crn_smooth
from accal.errors import ValidationError
from accal.simulate.effects import CHANNEL_PREROLL, lowpass, parse_effect
from accal.simulate.grace import simulate_grace_day

DURATION = 20000.0  # [s]
KW = {"date": "2005-01-01", "satellite": "A", "seed": 7, "duration": DURATION, "n_gaps": 2}


@pytest.fixture(scope="module")
def clean():
    return simulate_grace_day(**KW)


def _injected(clean, spec):
    day = simulate_grace_day(**KW, effects=[spec])
    assert np.array_equal(day.time, clean.time) and np.array_equal(day.true, clean.true)
    return day, day.raw - clean.raw, day.time - clean.truth["t0"]


def _band(term_full, tau):
    """A term given on the gap-free 1 s grid as the file holds it: through the Level-1B
    CRN-like filter (:func:`crn_smooth`; the simulator filters before cutting the gaps),
    then on the samples kept (times ``tau``)."""
    keep = np.isin(np.arange(round(DURATION)) * 1.0, tau)
    return crn_smooth(term_full, 1.0)[keep]


def _check_axis_only(diff, axis, expected, scale):
    """The difference is the expected term on ``axis`` (to the rounding of the raw
    values, |raw| <= 3e-5 m/s²: eps·3e-5 ≈ 7e-21) and exactly 0 on the others."""
    k = "xyz".index(axis)
    assert np.abs(diff[:, k] - expected).max() <= 4e-21 + 1e-12 * scale
    others = [i for i in range(3) if i != k]
    assert not diff[:, others].any()


@pytest.mark.parametrize(
    ("spec", "term"),
    [
        ("step:axis=x,epoch=7000,size=3e-9", lambda tau: 3e-9 * (tau >= 7000.0)),
        ("step:axis=z,epoch=0,size=-2e-9", lambda tau: -2e-9 + 0 * tau),
        ("quadratic:axis=z,coef=2e-18", lambda tau: 2e-18 * tau * tau),
        (
            "sawtooth:axis=y,period=3000,amp=1e-9,phase=0.25",
            lambda tau: 1e-9 * (2 * ((tau / 3000 + 0.25) % 1.0) - 1),
        ),
        (
            "growing:axis=y,period=2000,amp0=1e-9,amp1=4e-9",
            lambda tau: (1e-9 + 3e-9 * tau / DURATION) * np.sin(2 * np.pi * tau / 2000),
        ),
        (
            "growing:axis=x,period=1234.5,amp0=2e-9,amp1=0,phase=1.5",
            lambda tau: 2e-9 * (1 - tau / DURATION) * np.sin(2 * np.pi * tau / 1234.5 + 1.5),
        ),
        ("exponential:axis=x,amp=3e-9,tau=3000", lambda tau: 3e-9 * np.exp(-tau / 3000.0)),
    ],
)
def test_additive_effect_is_exactly_its_term(clean, spec, term):
    day, diff, tau = _injected(clean, spec)
    axis = spec.split("axis=")[1][0]
    _check_axis_only(diff, axis, _band(term(np.arange(round(DURATION)) * 1.0), tau), 4e-9)
    (truth,) = day.truth["effects"]
    assert truth["name"] == spec.split(":")[0] and truth["spec"] == spec
    for item in spec.split(":")[1].split(","):
        key, value = item.split("=")
        assert truth[key] == (value if key == "axis" else float(value))
    json.dumps(day.truth)  # JSON-ready
    # the truth's effects_trend is the LS line of the injected term over the valid samples
    v = day.valid
    k = "xyz".index(axis)
    drift, bias = np.polyfit(tau[v], day.instrument[v, k], 1)
    assert day.truth["effects_trend"]["bias"][k] == pytest.approx(bias, rel=1e-6, abs=1e-22)
    assert day.truth["effects_trend"]["drift"][k] == pytest.approx(drift, rel=1e-6, abs=1e-27)


def test_step_truth_has_its_gps_epoch(clean):
    day, _, _ = _injected(clean, "step:axis=y,epoch=43.5,size=1e-9")
    assert day.truth["effects"][0]["epoch_gps"] == clean.truth["t0"] + 43.5


def test_scale_error_multiplies_the_true_signal(clean):
    """raw = s·factor·a_true + ...: the difference is s·(factor − 1)·a_true."""
    day, diff, _ = _injected(clean, "scale:axis=x,factor=1.02")
    s = clean.truth["scale_s"][0]
    _check_axis_only(diff, "x", 0.02 * s * clean.true[:, 0], 1e-8)
    assert day.truth["effects"][0]["scale_s_true"] == pytest.approx(s * 1.02, rel=1e-15)
    assert day.truth["scale_s"] == clean.truth["scale_s"]  # the nominal scale stays


def _exact_lowpass_loop(x, h, tau):
    """τ y' + y = x for x linear between samples, solved sample by sample (the test's own)."""
    if tau == 0:
        return x
    y = np.empty_like(x)
    y[0] = x[0]
    e = math.exp(-h / tau)
    for k in range(1, x.size):
        slope = (x[k] - x[k - 1]) / h
        # y(t) = x(t) − τ·slope + C e^{−t/τ}: the particular solution of a ramp, plus decay
        y[k] = x[k] - tau * slope + (y[k - 1] - (x[k - 1] - tau * slope)) * e
    return y


@pytest.mark.parametrize(
    "extra",
    ["", ",lag=600", ",lag=450,tau=300", ",tau=120,tau2=40", ",lag=3600,tau=1000,tau2=1000"],
)
def test_coupling_is_the_lagged_low_passed_channel(clean, extra):
    spec = f"coupling:axis=y,channel=temperature,coef=3e-9{extra}"
    day, diff, tau = _injected(clean, spec)
    e = parse_effect(spec)
    tc = day.channel_time - day.truth["t0"]
    x = day.channels["temperature"]
    assert tc[0] == -CHANNEL_PREROLL and np.allclose(np.diff(tc), 1.0)
    y = _exact_lowpass_loop(_exact_lowpass_loop(x, 1.0, e.params["tau"]), 1.0, e.params["tau2"])
    lag = e.params["lag"]
    tau_full = np.arange(round(DURATION)) * 1.0
    expected = _band(3e-9 * y[np.searchsorted(tc, tau_full - lag)], tau)  # lag: a shift
    _check_axis_only(diff, "y", expected, 3e-9 * 300)
    # realistic temperature: ~293-300 K, an orbital cycle of 0.1-0.5 K, no wild jumps
    assert 290 < x.mean() < 302 and 0.1 < np.ptp(x) < 3.0
    assert np.abs(np.diff(x)).max() < 0.01
    prm = day.truth["channels"]["temperature"]
    assert 0.1 <= prm["orbital_amplitude"] <= 0.5 and prm["unit"] == "K"
    assert prm["orbit_period"] == day.truth["orbit_period"]


def test_lowpass_solves_the_first_order_equation():
    """Against RK4 with 20 substeps per sample on a random piecewise-linear channel."""
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=400))
    h, tau = 2.0, 37.0
    y = lowpass(x, h, tau)
    out, v = [x[0]], x[0]
    for k in range(x.size - 1):
        m, dt = 20, h / 20

        def f(s, yy, k=k):
            return (x[k] + (x[k + 1] - x[k]) * s / h - yy) / tau

        for j in range(m):
            s0 = j * dt
            k1 = f(s0, v)
            k2 = f(s0 + dt / 2, v + dt / 2 * k1)
            k3 = f(s0 + dt / 2, v + dt / 2 * k2)
            k4 = f(s0 + dt, v + dt * k3)
            v = v + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(v)
    assert np.abs(np.array(out) - y).max() < 1e-9 * np.abs(x).max()


def test_effects_add_up_and_change_nothing_else(clean):
    specs = [
        "step:axis=x,epoch=5000,size=2e-9",
        "exponential:axis=x,amp=1e-9,tau=2000",
        "coupling:axis=z,channel=temperature_icu,coef=-1e-9,lag=100",
        "coupling:axis=y,channel=temperature,coef=2e-9",
    ]
    day = simulate_grace_day(**KW, effects=specs)
    assert np.abs(day.raw - clean.raw - day.instrument).max() < 1e-20
    assert sorted(day.channels) == ["temperature", "temperature_icu"]
    # two channels are drawn independently, and a channel does not depend on the others
    assert not np.allclose(day.channels["temperature"], day.channels["temperature_icu"])
    one = simulate_grace_day(**KW, effects=specs[3:])
    assert np.array_equal(one.channels["temperature"], day.channels["temperature"])
    for k in ("bias", "drift", "scale_s", "signal_trend", "orbit_period", "eclipses"):
        assert day.truth[k] == clean.truth[k]
    for k in ("ang_accl_x", "acl_z_res"):
        assert np.array_equal(day.aux[k], clean.aux[k])


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("drift:axis=x,rate=1", "unknown effect 'drift'"),
        ("step", "step needs key=value pairs"),
        ("step:", "step needs key=value pairs"),
        ("step:axis=x,size=1e-9", "step needs epoch"),
        ("step:axis=x,epoch=10,size=1e-9,size=2e-9", "size given twice"),
        ("step:axis=x,epoch=10,size=1e-9,when=3", "step has no key 'when'"),
        ("step:axis=q,epoch=10,size=1e-9", "axis must be x, y or z, got 'q'"),
        ("step:axis=x,epoch=ten,size=1e-9", "epoch must be a number, got 'ten'"),
        ("step:axis=x,epoch=10,size=nan", "size must be finite"),
        ("step:axis=x,epoch=-1,size=1e-9", "epoch must be in [0, 86400)"),
        ("step:axis=x,epoch=10,size", "expected key=value, got 'size'"),
        ("coupling:axis=x,coef=1e-9", "coupling needs channel"),
        ("coupling:axis=x,channel=volts,coef=1e-9", "channel must be 'temperature'"),
        ("coupling:axis=x,channel=temperature,coef=1e-9,lag=-5", "lag must be in [0, 3600]"),
        ("coupling:axis=x,channel=temperature,coef=1e-9,tau2=5000", "tau2 must be in [0, 1000]"),
        ("scale:axis=x,factor=0", "factor must be > 0"),
        ("sawtooth:axis=x,period=0,amp=1e-9", "period must be > 0"),
        ("exponential:axis=x,amp=1e-9,tau=-3", "tau must be > 0"),
    ],
)
def test_bad_specifications_name_the_bad_part(spec, says):
    with pytest.raises(ValidationError) as info:
        parse_effect(spec)
    assert says in str(info.value) and "\n" not in str(info.value)
