"""close_loop on simulated days: one test per effect kind, two at once, clean data, a chirp.

Noise: accal.simulate.grace.coloured_noise, 1e-10 m/s²/√Hz white with a 1/f rise
below 1 mHz (GRACE SuperSTAR-like), one day at 2 s (43,200 samples) to keep the
suite fast; two gaps unless stated.  The days hold no non-gravitational signal: they
stand for raw − reference, so the closure runs without a signal model.  "3σ" checks use the coloured-noise sigma the
result reports.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from accal.closure import EFFECT_NAMES, close_loop
from accal.errors import ValidationError

ORBIT = 5600.0
DAY = {"n": 43200, "dt": 2.0, "n_gaps": 2}
#: The candidates without the scale (a reference given here is exact).
CANDS = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
)


def _run(d, **kw):
    # the days are noise plus effects, like raw − reference: no signal model
    kw.setdefault("aux", {"temp": d["temp"]})
    kw.setdefault("orbit_period", ORBIT)
    kw.setdefault("signal_model", "none")
    return close_loop(d["t"], d["y"], valid=d["valid"], **kw)


def _names(res):
    return [e.name for e in res.effects]


def _err(res, d):
    return res.true_error(d["truth"])


def _with_decay(sim, seed, amp, tau):
    """A simulated day with ``amp·exp(−(t − t0)/tau)`` added from its first sample."""
    d = sim(seed, **DAY)
    d["y"] = d["y"] + amp * np.exp(-(d["t"] - d["t"][0]) / tau)
    return d


def test_quadratic_drift_found_and_bias_error_drops(sim):
    d = sim(1, quadratic=2e-19, **DAY)  # 1.5e-9 m/s² over the day
    res = _run(d)
    assert _names(res)[0] == "quadratic_drift"
    e = res.effects[0]
    assert abs(e.coefficient - 2e-19) < 3 * e.sigma
    err = _err(res, d)
    # measured: bias error 2.4e-10 -> 2.5e-12, drift 1.7e-14 -> 2.1e-16 (≥ 10x)
    assert abs(err["bias"]["after"]) < 0.1 * abs(err["bias"]["before"])
    assert abs(err["drift"]["after"]) < 0.1 * abs(err["drift"]["before"])
    assert res.base_coefficient("bias").change_significant


def test_cubic_drift_found(sim):
    d = sim(2, cubic=4e-24, **DAY)  # 2.6e-9 m/s² over the day
    res = _run(d)
    names = _names(res)
    assert "cubic_drift" in names
    e = res.effects[names.index("cubic_drift")]
    assert abs(e.coefficient - 4e-24) < 3 * e.sigma
    err = _err(res, d)
    assert abs(err["drift"]["after"]) < 0.1 * abs(err["drift"]["before"])


@pytest.mark.parametrize(("amp", "tau"), [(3e-9, 3600.0), (1e-9, 900.0), (-2e-9, 15000.0)])
def test_exponential_drift_found_with_its_time_constant(sim, amp, tau):
    """A decaying bias from the start: named, not taken for a step or a polynomial."""
    d = _with_decay(sim, 8, amp, tau)
    res = _run(d)
    assert _names(res) == ["exponential_drift"]
    e = res.effects[0]
    assert abs(e.coefficient - amp) < 3 * e.sigma
    # measured: T within 0.2-3 % (the noise, not the search grid, sets it)
    assert e.tau == pytest.approx(tau, rel=0.05)
    err = _err(res, d)
    assert abs(err["bias"]["after"]) < 0.2 * abs(err["bias"]["before"])


@pytest.mark.parametrize(("seed", "amp", "tau"), [(8, 3e-9, 30000.0), (10, -5e-9, 60000.0)])
def test_slow_exponential_is_not_removed_as_polynomial_terms(sim, seed, amp, tau):
    """A decay slower than span/4 (the forward search's cap) takes the polynomials' place.

    Before, quadratic + cubic were removed instead and the bias kept the decay's
    amplitude: errors of 2.2e-9 / -4.5e-9 m/s² at σ ~1e-11 (z ~ 100-400).  Measured
    now: bias errors 4e-11 / 1.2e-10 at z 0.3 / 0.3, T within 0.4 % / 0.1 %.
    """
    d = _with_decay(sim, seed, amp, tau)
    res = _run(d)
    assert _names(res) == ["exponential_drift"]
    e = res.effects[0]
    assert abs(e.coefficient - amp) < 3 * e.sigma
    assert {r.name for r in res.eliminated} >= {"quadratic_drift"}
    # T's uncertainty is propagated (Jacobian column): T and the bias within 3σ
    assert abs(e.tau - tau) < 3 * e.details["tau_sigma"]
    bias = res.base_coefficient("bias")
    assert abs(_err(res, d)["bias"]["after"]) < 3 * bias.sigma_after


def test_time_constant_uncertainty_reaches_the_bias_sigma(sim):
    """σ(T) from the Gauss-Newton Jacobian; the bias σ includes what T's search costs.

    Without the Jacobian column a 60,000 s decay's bias σ was 4.1e-11 for an error of
    8.8e-10 (seed 9, z = 21); with it σ = 4.9e-10 (z = 1.8).
    """
    d = _with_decay(sim, 9, -5e-9, 60000.0)
    res = _run(d)
    e = res.effects[0]
    assert e.name == "exponential_drift" and e.details["tau_sigma"] > 0
    assert abs(e.tau - 60000.0) < 3 * e.details["tau_sigma"]
    bias = res.base_coefficient("bias")
    assert bias.sigma_after > 5 * bias.sigma_plain
    assert abs(_err(res, d)["bias"]["after"]) < 3 * bias.sigma_after


@pytest.mark.parametrize(("amp", "tau", "rel"), [(5e-9, 7200.0, 1e-9), (3e-9, 50000.0, 1e-8)])
def test_exponential_drift_noise_free_is_exact(amp, tau, rel):
    """Also beyond span/4 (50,000 s over a day: the polynomial swap's range).

    Exact to the conditioning, not to one rounding: a 50,000 s decay over one day is
    a line plus a little curvature, nearly collinear with the bias and drift of the
    base, so T and A carry the rounding errors amplified (2.5e-9 and 3.2e-9 relative on
    the 2026-11-27 machine with numpy 2.4.6/OpenBLAS; within 1e-9 on an earlier one).
    """
    t = np.arange(0.0, 86400.0, 2.0)
    y = 1e-7 + 1e-12 * t + amp * np.exp(-t / tau)
    res = close_loop(t, y, resolution=np.finfo(float).eps * 1e-7)
    assert _names(res) == ["exponential_drift"] and res.unexplained == ()
    e = res.effects[0]
    assert e.coefficient == pytest.approx(amp, rel=rel)
    assert e.tau == pytest.approx(tau, rel=rel)
    assert res.base_coefficient("bias").after == pytest.approx(1e-7, rel=1e-12)


def test_bias_step_found_at_right_epoch(sim):
    d = sim(3, step=(0.4, 2e-9), **DAY)
    res = _run(d)
    assert _names(res)[0] == "bias_step"
    e = res.effects[0]
    true_epoch = d["t"][0] + 0.4 * (d["t"][-1] - d["t"][0])
    assert abs(e.epoch - true_epoch) <= 120.0  # within 1 % of a day even with red noise
    assert abs(e.coefficient - 2e-9) < 3 * e.sigma
    err = _err(res, d)
    # measured: bias 2.7e-10 -> 5.7e-13, drift 3.4e-14 -> 3.2e-17
    assert abs(err["bias"]["after"]) < 0.1 * abs(err["bias"]["before"])
    assert abs(err["drift"]["after"]) < 0.1 * abs(err["drift"]["before"])


def test_orbit_periodic_found_with_estimated_frequency(sim):
    d = sim(4, orbit=(3e-9, 1e-9), **DAY)
    res = _run(d)
    assert _names(res)[0] == "periodic"
    e = res.effects[0]
    assert e.channel == "orbit"
    assert e.frequency == pytest.approx(1 / ORBIT, rel=0.005)
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma + 0.01 * 3e-9  # frequency grid: 0.15 %
    assert e.details["amplitudes"][1] == pytest.approx(1e-9, rel=0.1)
    assert res.rms_after < res.rms_before


def test_constant_amplitude_line_is_not_modulated(sim):
    """A line of constant amplitude stays a plain sinusoid (no amplitude rate)."""
    d = sim(22, **DAY)
    tau = d["t"] - d["t"][0]
    d["y"] = d["y"] + 3e-9 * np.sin(2 * np.pi * tau / 3000.0 + 0.2)
    res = _run(d)
    per = [e for e in res.effects if e.name == "periodic"]
    assert len(per) == 1 and "amplitude_rate" not in per[0].details
    assert abs(per[0].coefficient - 3e-9) < 3 * per[0].sigma + 0.01 * 3e-9


@pytest.mark.parametrize("c2", [1e-9, 2e-9])
def test_quadratic_temperature_coupling(sim, c2):
    """``c1·T + c2·(T − 20 K)²`` on a 20 ± 1.5 K channel: the coupling and the
    channel's square (about its mean) are both found.  With c2 = 1e-9 the linear
    coupling comes first and the square is offered once it is in the model; with
    2e-9 (QA: nothing found, smooth structure "unexplained") the linear coupling
    alone is not significant and the two are tested together."""
    d = sim(23, **DAY)
    temp = d["temp"]
    d["y"] = d["y"] + 3e-9 * temp + c2 * (temp - 20.0) ** 2
    res = _run(d)
    chans = {e.channel: e for e in res.effects if e.name == "auxiliary"}
    assert set(chans) == {"temp", "temp^2"}, [(e.name, e.channel) for e in res.effects]
    assert len(res.effects) == 2
    assert abs(chans["temp^2"].coefficient - c2) < 3 * chans["temp^2"].sigma + 0.01 * c2
    # the linear coefficient is the slope at the channel's mean: c1 + 2·c2·(mean − 20 K)
    slope = 3e-9 + 2 * c2 * (float(np.mean(temp)) - 20.0)  # the mean of all samples
    assert abs(chans["temp"].coefficient - slope) < 3 * chans["temp"].sigma + 0.02 * 3e-9
    err = _err(res, d)
    # measured (1e-9): drift error 1.6e-14 -> 5e-17
    assert abs(err["drift"]["after"]) < 0.05 * abs(err["drift"]["before"])


def test_temperature_coupling_with_lag(sim):
    d = sim(5, temp_coupling=3e-9, temp_lag=600.0, **DAY)
    res = _run(d)
    assert _names(res)[0] == "auxiliary"
    e = res.effects[0]
    assert e.channel == "temp"
    assert abs(e.lag - 600.0) <= 240.0  # lag grid step 90 s; day-scale temperature is smooth
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma + 0.02 * 3e-9
    err = _err(res, d)
    # measured: drift error 9.1e-15 -> 8.6e-17; bias 5.9e-8 (the coupling × the 20 K
    # mean temperature) -> 2.9e-11 (z 0.6): the regressor is not de-meaned, the bias
    # is the one at channel value 0, as the injected model b + c·T says
    assert abs(err["drift"]["after"]) < 0.05 * abs(err["drift"]["before"])
    bias = res.base_coefficient("bias")
    assert abs(err["bias"]["after"]) < 3 * bias.sigma_after
    assert abs(err["bias"]["after"]) < 1e-3 * abs(err["bias"]["before"])


def test_two_effects_temperature_and_step(sim):
    d = sim(6, temp_coupling=1e-8, step=(0.7, 3e-9), **DAY)
    res = _run(d, orbit_period=None)
    assert set(_names(res)) >= {"auxiliary", "bias_step"}
    step = res.effects[_names(res).index("bias_step")]
    assert abs(step.coefficient - 3e-9) < 3 * step.sigma
    # measured: drift error 2.8e-13 -> 1.5e-16
    err = _err(res, d)
    assert abs(err["drift"]["after"]) < 0.05 * abs(err["drift"]["before"])


def test_clean_days_report_nothing(sim):
    """False alarms: at least 19 of 20 clean days report no effect and nothing unexplained."""
    found = []
    for seed in range(100, 120):
        d = sim(seed, **DAY)
        res = _run(d)
        found.append(res.found)
        if not res.found:
            assert res.to_dict()["effects"] == []
            assert res.rms_after == res.rms_before
    assert sum(found) <= 1, f"false alarms on {sum(found)} of 20 clean days"


def test_slow_chirp_is_unexplained(sim):
    d = sim(7, chirp=3e-9, **DAY)
    res = _run(d)
    assert res.effects == ()  # no wrong confident effect
    assert res.unexplained
    u = res.unexplained[-1]
    assert u.name == "unexplained"
    # the chirp sweeps 1/8 h .. 1/1.5 h
    assert 1 / 28800 * 0.5 <= u.frequency <= 1 / 5400 * 1.5


def test_to_dict_is_json_and_uses_allowed_names(sim):
    d = sim(3, step=(0.4, 2e-9), **DAY)
    res = _run(d)
    out = json.loads(json.dumps(res.to_dict(truth=d["truth"])))
    assert {"effects", "rms_before", "rms_after", "base", "true_error"} <= set(out)
    for e in out["effects"] + out["unexplained"]:
        assert e["name"] in EFFECT_NAMES
        assert {"channel", "coefficient", "sigma", "significance", "epoch", "frequency"} <= set(e)
    assert out["effects"][0]["epoch"] is not None


def test_custom_base_design_and_builder(sim):
    """A caller's own design matrix (the demod case) and its own candidate builder."""
    d = sim(8, step=(0.5, 3e-9), **DAY)
    tau = d["t"] - d["t"][0]
    base = np.column_stack([np.ones_like(tau), tau / tau[-1]])
    res = close_loop(d["t"], d["y"], base=base, valid=d["valid"], candidates=("bias_step",))
    assert _names(res) == ["bias_step"]
    assert [b.name for b in res.base] == ["b0", "b1"]

    from accal.closure import Proposal

    def my_effect(ctx):
        col = (ctx.t_all >= d["t"][0] + 0.5 * tau[-1]).astype(float)[:, None]
        return [Proposal("angle_offset", "theta", col, ("theta",), 1.0, {})]

    res = close_loop(d["t"], d["y"], valid=d["valid"], candidates=(my_effect,))
    assert _names(res) == ["angle_offset"]


def test_bad_input_messages():
    t = np.arange(100.0)
    with pytest.raises(ValidationError, match="equal length"):
        close_loop(t, np.zeros(99))
    with pytest.raises(ValidationError, match="Invalid value for the 'candidates'"):
        close_loop(t, np.zeros(100), candidates=("nope",))
    with pytest.raises(ValidationError, match="at least 50 usable"):
        close_loop(t, np.zeros(100), valid=t < 10)
    with pytest.raises(ValidationError, match="auxiliary channel 'T'"):
        close_loop(t, np.zeros(100), aux={"T": np.zeros(3)})
    with pytest.raises(ValidationError, match="platform angle"):
        close_loop(t, np.random.default_rng(0).standard_normal(100), candidates=("angle_offset",))


def test_two_effects_with_orbit_candidate(sim):
    """A lagged temperature coupling and a step, with the orbit candidate on.

    Each masks the other (alone, the coupling's test has p = 0.013 after the
    multiplicity correction and the step's 0.9), and the coupling's once-per-orbit
    part is significant as ``periodic``.  The pair search (coupling + its best
    partner tested jointly) and the lag refinement find both, with the true lag.
    """
    d = sim(6, temp_coupling=3e-9, step=(0.7, 1.5e-9), **DAY)
    res = _run(d)
    assert sorted(_names(res)) == ["auxiliary", "bias_step"]
    aux = res.effects[_names(res).index("auxiliary")]
    step = res.effects[_names(res).index("bias_step")]
    assert abs(aux.coefficient - 3e-9) < 3 * aux.sigma  # measured 2.998e-9 ± 2.1e-12
    # a smooth channel: lag and low-pass trade along a ridge (measured 439 s + 162 s);
    # the delay they give at low frequency, lag + τ, is the true 600 s
    assert aux.lag + aux.tau == pytest.approx(600.0, rel=0.02)
    assert abs(step.coefficient - 1.5e-9) < 3 * step.sigma  # measured 1.507e-9 ± 6.5e-12
    parts = res.effect_models()
    assert [e.name for e, _ in parts] == _names(res)
    np.testing.assert_allclose(sum(m for _, m in parts), res.effects_model(), rtol=1e-12, atol=0)
    err = _err(res, d)
    # measured: drift error 7.6e-14 -> 1.5e-16, bias 6.4e-8 -> 1.1e-10 (z 2.4)
    assert abs(err["drift"]["after"]) < 0.05 * abs(err["drift"]["before"])
    assert abs(err["bias"]["after"]) < 0.01 * abs(err["bias"]["before"])


def test_lines_off_the_orbit_found_beside_its_harmonics():
    """Two 5e-9 m/s² lines (1000 s, 4000 s) on a simulated half day's raw z axis.

    The simulated signal carries the orbit's harmonics (solar pressure switched off in
    eclipse), several of them larger than 1e-9 m/s²: without a reference they are in the
    null model (the orbit-phase template), and the lines off them are found, reported
    (not removed: periodic terms may be real signal).
    """
    from accal.simulate.grace import simulate_grace_day

    sim = simulate_grace_day(date="2005-03-01", satellite="A", seed=3, duration=43200.0)
    t = sim.time
    tau = t - t[0]
    lines = {1 / 1000: (5e-9, 0.3), 1 / 4000: (5e-9, 2.0)}  # frequency: (amplitude, phase)
    z = sim.raw[:, 2] + sum(a * np.sin(2 * np.pi * f * tau + p) for f, (a, p) in lines.items())
    res = close_loop(t, z, valid=sim.valid, orbit_period=ORBIT)
    assert res.signal_model["kind"] == "orbit_template"
    per = [e for e in res.effects if e.name == "periodic"]
    assert all(not e.instrument for e in per)
    for f, (amp, _) in lines.items():
        hit = [e for e in per if e.channel == "line" and abs(e.frequency - f) < 0.5 / 43200]
        assert len(hit) == 1, [(e.channel, e.frequency) for e in per]
        assert abs(hit[0].coefficient - amp) < 3 * hit[0].sigma + 0.01 * amp


@pytest.mark.parametrize("lag", [600.0, 1500.0])
def test_lagged_coupling_start_is_not_an_exponential_or_a_step(sim, lag):
    """QA: the lagged channel is unknown for the first `lag` seconds (the regressor held
    its first value); that flat start was taken for an exponential settling and a step,
    removed, and the bias came out -6e-10 for +7e-10.  The search is redone on the
    samples the lagged channel covers."""
    d = sim(21, **DAY)
    el = d["t"] - d["t"][0]

    def temp(x):  # known before the record starts, as a real temperature is
        return 0.8 * np.sin(2 * np.pi * x / ORBIT + 0.3) + 0.5 * np.sin(2 * np.pi * x / 20000.0)

    d["y"] = d["y"] + 3e-9 * temp(el - lag)
    res = _run(d, aux={"temp": temp(el)})
    names = _names(res)
    assert "auxiliary" in names
    assert "exponential_drift" not in names and "bias_step" not in names
    e = res.effects[names.index("auxiliary")]
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma
    # the lag (plus 5 τ of a low-pass the first search may split the delay into) was left
    # out at the start and the search redone
    left = [re.search(r"the first (\d+) s", n["note"]) for n in res.notes]
    assert any(m and lag - 5 <= int(m[1]) <= 2 * lag for m in left)


@pytest.mark.parametrize("tc", [500.0, 1600.0, 3000.0, 4500.0])
def test_filtered_coupling_between_grid_time_constants(sim, tc):
    """QA: the coupling's low-pass was searched on a grid (0, 300, 1000, 3000 s) only: a
    500 s low-pass came out as 300 s + a 160 s lag with the coefficient 7 % low, and to a
    channel near 293 (kelvin) the bias at channel value 0 was 13σ off (1600 s: 22 %
    low, 9σ).  Lag and time constant are now refined together between grid values, and
    their Jacobian is in the final fit, so the bias σ includes what they cost."""
    from scipy.signal import lfilter

    d = sim(23, **DAY)
    el = d["t"] - d["t"][0]
    pre = np.arange(-4000.0, 0.0, 2.0)

    def temp(x):
        return 293 + 1.5 * np.sin(2 * np.pi * x / ORBIT + 0.4) + 0.8 * np.sin(2 * np.pi * x / 5e4)

    x = temp(np.concatenate([pre, el]))
    a = np.exp(-2.0 / tc)
    d["y"] = d["y"] + 2e-9 * (lfilter([1 - a], [1, -a], x - x[0]) + x[0])[pre.size :]
    res = _run(d, aux={"temp": temp(el)})
    names = _names(res)
    assert names.count("auxiliary") == 1 and "exponential_drift" not in names
    e = res.effects[names.index("auxiliary")]
    assert abs(e.coefficient - 2e-9) < 3 * e.sigma
    assert abs(e.tau - tc) < 3 * e.details["tau_sigma"]
    assert e.lag < 3 * e.details["lag_sigma"] + 1.0
    bias = res.base_coefficient("bias")
    assert abs(_err(res, d)["bias"]["after"]) < 3 * bias.sigma_after


def test_lag_and_low_pass_on_half_a_day_with_gaps_keep_the_coupling(sim):
    """QA: lag 2000 s + 1500 s low-pass to a 293 K channel, half a day with gaps.  The
    re-search without the start (lag cap + 5 τ, and as much after each gap) recomputed
    the lag cap from the shorter span (below 2000 s), lost the coupling, and its
    c × 293 K went into the bias (z = 1053).  The re-search keeps the first search's
    lag cap, and if the coupling is still not found the first search's result stands."""
    from scipy.signal import lfilter

    d = sim(5, n=21600, dt=2.0, n_gaps=3)
    el = d["t"] - d["t"][0]
    pre = np.arange(-12000.0, 0.0, 2.0)

    def temp(x):
        return 293 + 1.5 * np.sin(2 * np.pi * x / ORBIT + 0.4) + 0.8 * np.sin(2 * np.pi * x / 3e4)

    x = temp(np.concatenate([pre, el]))
    a = np.exp(-2.0 / 1500.0)
    filt = lfilter([1 - a], [1, -a], x - x[0]) + x[0]
    full_t = np.concatenate([pre, el])
    d["y"] = d["y"] + 3e-9 * np.interp(el - 2000.0, full_t, filt)
    res = _run(d, aux={"temp": temp(el)})
    # was: c 3.6e-9 beside a step, a quadratic, lines.  Since flagged stretches (the
    # channel is known there) are no longer left out like gaps, the re-search has more
    # samples, and the coupling's small misfit at the orbit frequency (lag 1979 s and
    # τ 1526 s for 2000/1500) is reported as an orbit term of 4.8e-11 ± 3.9e-11 m/s²,
    # which is reported only, not removed
    assert _names(res)[0] == "auxiliary" and set(_names(res)[1:]) <= {"periodic"}
    e = res.effects[0]
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma
    # the lag is right to 1 %, but its reported σ is too small on this kind of case
    # (seeds 5-12: lag z 0.4-5.3, RMS ~2.9; docs/closure.md, Known limitations): not a
    # 3σ check.  Seed 5 gave 2001.6 ± 1.8 s, and 2006.1 ± 2.0 s once the step scan's
    # template changed which start the re-search leaves out (8,322 s instead of 16,605 s)
    # the lag/low-pass ridge (a smooth channel): within 2.5 %; its σ is too small here
    # (docs/closure.md, known limitations)
    assert abs(e.lag - 2000.0) < 50.0
    # so is the time constant's (1452 ± 6 s once the periodic kinds are tried last)
    assert abs(e.tau - 1500.0) < 0.05 * 1500.0
    bias = res.base_coefficient("bias")
    assert abs(_err(res, d)["bias"]["after"]) < 3 * bias.sigma_after


@pytest.mark.parametrize("tc", [300.0, 1000.0])
def test_filtered_coupling_start_is_not_an_exponential(sim, tc):
    """QA: a coupling through a first-order low-pass whose state at the record start
    differs from the regressor's (which starts settled on the first value) left that
    difference, a decay of time constant tc, as an exponential_drift of T = tc
    (1.04e-9 m/s², T = 298 s beside a 2e-9 m/s²/K coupling).  The search is redone
    without the first 5 tc."""
    from scipy.signal import lfilter

    d = sim(22, **DAY)
    el = d["t"] - d["t"][0]
    pre = np.arange(-4000.0, 0.0, 2.0)  # the channel runs before the record starts

    def temp(x):
        return 20 + 0.8 * np.sin(2 * np.pi * x / ORBIT + 0.3) + 0.5 * np.sin(2 * np.pi * x / 2e4)

    x = temp(np.concatenate([pre, el]))
    a = np.exp(-2.0 / tc)
    filt = lfilter([1 - a], [1, -a], x - x[0]) + x[0]
    d["y"] = d["y"] + 2e-9 * filt[pre.size :]
    res = _run(d, aux={"temp": temp(el)})
    names = _names(res)
    assert "auxiliary" in names and "exponential_drift" not in names
    e = res.effects[names.index("auxiliary")]
    assert abs(e.coefficient - 2e-9) < 3 * e.sigma
    # lag and time constant are refined off the search grid, with their σ
    assert abs(e.tau - tc) < 3 * e.details["tau_sigma"] and e.details["tau_sigma"] < 0.03 * tc
    assert e.lag < 3 * e.details["lag_sigma"]
    # the first ~5 tc (the unknown filter state) were left out and searched again
    left = [re.search(r"the first (\d+) s", n["note"]) for n in res.notes]
    assert any(m and abs(float(m[1]) - 5 * tc) < 0.1 * 5 * tc for m in left)
    from accal.closure.report import to_markdown

    line = next(x for x in to_markdown(res).splitlines() if x.startswith("| auxiliary"))
    assert re.search(r"lag \S+ ± \S+, τ \S+ ± \S+ s \|$", line), line  # both in the report
    # measured: bias error 4.0e-8 (the coupling at the channel's 20 K mean) -> 3e-11 and
    # 1.4e-10 (z 0.8 and 3.9: c's 0.1 % error times the 20 K mean is the larger part)
    err = _err(res, d)["bias"]
    assert abs(err["after"]) < 0.01 * abs(err["before"])


@pytest.mark.parametrize(("first", "second"), [(1e-9, -1e-9), (1e-9, 1e-9)])
def test_two_steps_that_mask_each_other_are_both_found(sim, first, second):
    """QA: a +1e-9/-1e-9 box gave only `unexplained` (each step alone had p 1.0: the
    other one inflated the low-frequency noise estimate); found as a pair now."""
    d = sim(31, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + first * (el >= 25000.0) + second * (el >= 60000.0)
    res = _run(d)
    assert _names(res) == ["bias_step", "bias_step"] and res.unexplained == ()
    got = sorted((e.epoch - d["t"][0], e.coefficient, e.sigma) for e in res.effects)
    truth = [(25000.0, first), (60000.0, second)]
    for (epoch, c, s), (e_true, c_true) in zip(got, truth, strict=True):
        assert epoch == e_true and abs(c - c_true) < 3 * s


@pytest.mark.parametrize(("start", "length"), [(20000, 50), (20000, 100), (0, 80), (-80, 80)])
def test_outlier_burst_is_left_out_not_fitted_as_steps(sim, start, length):
    """QA: 50 samples of 5e-8 m/s² (kurtosis 856); with pairs of steps allowed it came
    out as two bias steps of ±2.9e-9 m/s²; 100 samples, or 80 at either end of the
    record, still became steps or an exponential + step with a centred running
    median.  Outliers are left out of the analysis."""
    d = sim(41, **DAY)
    d["y"] = d["y"].copy()
    i = start % d["y"].size
    d["y"][i : i + length] += 5e-8
    res = _run(d)
    assert res.effects == () and res.unexplained == ()
    note = next(n for n in res.notes if n["name"] == "outliers")
    assert note["details"]["n"] >= length
    assert note["details"]["first"] <= d["t"][i]


def test_fast_decay_at_the_start_is_not_screened_as_outliers(sim):
    """1e-8 m/s² with T = 120 s: its first samples deviate like a burst at the start;
    the closure finds the decay and analyses them with it."""
    d = sim(41, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 1e-8 * np.exp(-el / 120.0)
    res = _run(d)
    assert _names(res) == ["exponential_drift"]
    assert res.effects[0].coefficient == pytest.approx(1e-8, rel=0.01)
    assert not any(n["name"] == "outliers" for n in res.notes)


def test_clean_day_has_no_outliers(sim):
    res = _run(sim(42, **DAY))
    assert not any(n["name"] == "outliers" for n in res.notes)


def test_lagged_coupling_after_a_data_gap_makes_no_steps(sim):
    """QA: the channel is only known at the data's times, so across a gap the lagged
    regressor was bridged and steps of ±2.5e-10 m/s² appeared right after the gap."""
    d = sim(22, n=43200, dt=2.0)
    keep = np.ones(d["t"].size, bool)
    keep[20000:21500] = False  # a 3000 s gap: no samples at all
    t, y = d["t"][keep], d["y"][keep]
    el = t - t[0]

    def temp(x):
        return 0.8 * np.sin(2 * np.pi * x / ORBIT + 0.3) + 0.5 * np.sin(2 * np.pi * x / 20000.0)

    y = 1e-7 + 1e-12 * el + 3e-9 * temp(el - 600.0)  # noise-free, as raw - reference can be
    res = close_loop(
        t, y, aux={"temp": temp(el)}, orbit_period=ORBIT, resolution=3e-23, signal_model="none"
    )
    names = _names(res)
    assert "auxiliary" in names and "bias_step" not in names
    e = res.effects[names.index("auxiliary")]
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma and e.lag == pytest.approx(600.0, abs=2.0)


@pytest.mark.parametrize(("a", "b"), [(1000.0, 85000.0), (30000.0, 31000.0)])
def test_steps_near_the_ends_and_close_together(sim, a, b):
    """QA: a step 1000 s from the start was outside the scanned epochs (2 % of the day
    from either end) and came out as an exponential, table bias error 2e-9 at z = 179;
    steps 1000 s apart were not resolved.  Epochs are scanned to 0.5 % of the span."""
    d = sim(42, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 2e-9 * (el >= a) - 1e-9 * (el >= b)
    res = _run(d)
    assert _names(res) == ["bias_step", "bias_step"]
    got = sorted((e.epoch - d["t"][0], e.coefficient, e.sigma) for e in res.effects)
    for (epoch, c, s), (e_true, c_true) in zip(got, [(a, 2e-9), (b, -1e-9)], strict=True):
        assert epoch == e_true and abs(c - c_true) < 3 * s


@pytest.mark.parametrize("epoch", [40.0, 60.0, 150.0, 86400.0 - 60.0, 86400.0 - 300.0])
def test_step_at_the_edge_of_the_record(sim, epoch):
    """QA: a 3e-9 m/s² step 150 s into the record (inside the 0.5 % the epoch scan left
    out) came out as an exponential of T = 180 s plus two steps; 60 s in it was left
    out as 60 outliers and the bias kept it; 300 s before the end it was found, but the
    60 samples after it were also screened as a burst (the running-median window the
    record's end truncates).  The scan now reaches 0.1 % of the span, a constant run of
    flagged samples at either end is tried as a step, and flagged samples a found
    step explains are not outliers."""
    d = sim(43, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 3e-9 * (el >= epoch)
    res = _run(d)
    assert _names(res) == ["bias_step"] and res.unexplained == ()
    e = res.effects[0]
    assert e.epoch - d["t"][0] == epoch and abs(e.coefficient - 3e-9) < 3 * e.sigma
    assert not any(n["name"] == "outliers" for n in res.notes)
    err = _err(res, d)["bias"]["after"]
    assert abs(err) < 3 * res.base_coefficient("bias").sigma_after


def test_burst_near_a_step_stays_outliers(sim):
    """Flagged samples near a found step are analysed with it only when that gives the
    same effects: a burst 200 s after a step is still left out, not fitted as steps."""
    d = sim(43, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 3e-9 * (el >= 40000.0)
    i = int(np.searchsorted(el, 40200.0))
    d["y"][i : i + 50] += 5e-8
    res = _run(d)
    assert _names(res) == ["bias_step"] and res.effects[0].epoch - d["t"][0] == 40000.0
    assert next(n for n in res.notes if n["name"] == "outliers")["details"]["n"] >= 50


@pytest.mark.parametrize(
    ("sat", "date", "seed", "gaps", "axis", "period"),
    [("A", "2008-03-01", 31, 0, 1, 2200.0), ("B", "2010-06-01", 23, 4, 0, 2500.0)],
)
def test_line_between_the_orbit_harmonics_on_raw_minus_reference(
    sat, date, seed, gaps, axis, period
):
    """QA: a 3e-9 m/s² line (40x the noise) at 2200 s or 2500 s on raw − reference, half
    a day.  At 2200 s the line was fitted 0.036 DFT bins off (the 1/10-bin grid); the
    misfit stayed in its PSD bin and the line was not significant (p 0.1).  At 2500 s
    the orbit trial's f was pulled 2.9 % high by the line, its harmonics kept the line
    out of the search, and only "unexplained" was reported.  Where lines were found,
    their σ was 20-90x too large.  The frequency is now refined continuously, and only
    an orbit effect in the model keeps lines off its harmonics."""
    from accal.simulate.grace import simulate_grace_day

    day = simulate_grace_day(
        date=date, satellite=sat, seed=seed, duration=43200.0, n_gaps=gaps, noise=1e-10
    )
    tau = day.time - day.truth["t0"]
    ref = day.truth["scale_s"][axis] * day.true[:, axis]
    y = day.raw[:, axis] - ref + 3e-9 * np.sin(2 * np.pi * tau / period)
    res = close_loop(
        day.time, y, valid=day.valid, orbit_period=ORBIT, reference=ref, candidates=CANDS
    )
    assert [(e.name, e.channel) for e in res.effects] == [("periodic", "line")]
    assert res.unexplained == ()
    e = res.effects[0]
    assert abs(e.frequency - 1 / period) < 0.02 / 43200.0
    # measured: 3.00e-9 ± 1.1e-12 and ± 2.2e-12 (white noise alone: ~5e-13)
    assert abs(e.coefficient - 3e-9) < 3 * e.sigma and e.sigma < 5e-12


def test_burst_at_the_start_beside_a_step_stays_outliers(sim):
    """QA: with a 2e-9 m/s² step mid-day the residual's MAD made a 5e-8 m/s² burst at the
    start look ~100σ, under the 200σ an edge run may be a step: it was removed as a
    5e-8 step and the bias was 5e-8 off.  The run's offset is now measured against
    the σ of first differences."""
    d = sim(44, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 2e-9 * (el >= 40000.0)
    d["y"][:30] += 5e-8
    res = _run(d)
    assert _names(res) == ["bias_step"] and res.effects[0].epoch - d["t"][0] == 40000.0
    assert next(n for n in res.notes if n["name"] == "outliers")["details"]["n"] >= 30


def test_steps_near_both_ends(sim):
    """QA: a step 20 s from the start and one 30 s from the end: both runs of flagged
    samples were left out as outliers and neither step was found (bias z 324)."""
    d = sim(45, **DAY)
    el = d["t"] - d["t"][0]
    d["y"] = d["y"] + 3e-9 * (el >= 40.0) - 2e-9 * (el >= 86400.0 - 60.0)
    res = _run(d)
    assert _names(res) == ["bias_step", "bias_step"]
    assert sorted(e.epoch - d["t"][0] for e in res.effects) == [40.0, 86340.0]
    assert not any(n["name"] == "outliers" for n in res.notes)
    err = _err(res, d)["bias"]["after"]
    assert abs(err) < 3 * res.base_coefficient("bias").sigma_after
