"""close_loop_demod on simulated rotating-platform data (a quarter day at 1 Hz, τ = 600 s).

One test per undeclared effect the demodulation model lacks: the right effect is
found, its coefficient is within 3σ of the truth, and the true error of the
per-period a_Y / a_Z drops (the measured drop is stated in each test).  The
per-period σ of a_Y is ~4e-12 m/s² (MicroSTAR eq. 1 noise).
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.indep.rotating import calibration_pattern

from accal.closure import EFFECT_NAMES
from accal.closure.demod import close_loop_demod
from accal.closure.validation import SIGNAL_STEP_REASON
from accal.estimators.demod import demodulate

from .conftest import AY, AZ


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _errors(per):
    return {
        "Y": (_rms(per.a_Y_before - AY), _rms(per.a_Y_after - AY)),
        "Z": (_rms(per.a_Z_before - AZ), _rms(per.a_Z_after - AZ)),
    }


def _run(d, **kw):
    return close_loop_demod(d["t"], d["m"], d["theta"], tau=600.0, aux={"temp": d["temp"]}, **kw)


def test_clean_run_matches_demodulate_and_reports_nothing(platform):
    d = platform(1)
    res, per = _run(d)
    assert res.effects == () and res.unexplained == ()
    # the block base reproduces accal.estimators.demod (eq. 14 = eq. 17 when eq. 16 holds)
    dm = demodulate(d["t"], d["m"][:, 0], d["m"][:, 1], d["theta"], tau=600.0, mask=200.0)
    np.testing.assert_allclose(per.a_Y_before, dm.a_Y, rtol=0, atol=1e-18)
    np.testing.assert_allclose(per.a_Z_before, dm.a_Z, rtol=0, atol=1e-18)
    np.testing.assert_array_equal(per.period_index, dm.period_index)
    assert per.sigma_Y_before == pytest.approx(dm.sigma_Y, rel=0.3)  # residual PSD vs eq. 1
    assert np.array_equal(per.a_Y_after, per.a_Y_before)
    # an angle offset is not identifiable with rests at 0 and π: said, not proposed
    notes = {(n["name"], n["channel"]) for n in res.notes}
    assert notes == {("angle_offset", "common"), ("angle_offset", "rest@3.142")}
    tab = per.to_table()
    assert {"period", "t_mid", "a_Y", "sigma_Y", "a_Z_before", "change_Z"} <= set(tab)
    assert len(tab["a_Y"]) == 36


def test_temperature_coupling_with_lag(platform):
    d = platform(2, temp_coupling=2e-8, temp_lag=120.0)
    res, per = _run(d)
    assert res.effects[0].name == "auxiliary"
    # lags are searched to 1080 s on this quarter day (the channel repeats with τ: the
    # shortest lag is taken); beside the coupling only a borderline line may come up
    # (measured on this seed: 1.3e-11 m/s² at 0.45 Hz, corrected p 0.006; 1 of 16
    # seed/lag cases, the same seed at both lags)
    assert all(e.name == "periodic" and e.significance > 1e-3 for e in res.effects[1:])
    # the re-search leaves out the lag at the start, not the 1080 s cap (with the cap
    # the first two periods had no extended values); the first period, thinned, is left
    # out of the table (its mean would refer to the end of the period only)
    assert per.period_index.size == 35 and 0 not in per.period_index
    assert np.isfinite(per.a_Y_after).all()
    e = res.effects[0]
    assert e.channel == "temp" and e.lag == pytest.approx(120.0, abs=10.0)
    ax = e.details["axes"]
    assert abs(ax["y"]["coefficient"] - 2e-8) < 3 * ax["y"]["sigma"]
    assert abs(ax["z"]["coefficient"] - 1e-8) < 3 * ax["z"]["sigma"]
    err = _errors(per)
    # measured: a_Y error RMS 3.9e-11 -> 4.1e-12, a_Z 2.2e-11 -> 5.2e-12 (noise level)
    assert err["Y"][1] < 0.2 * err["Y"][0] and err["Z"][1] < 0.35 * err["Z"][0]


@pytest.mark.parametrize("ref", ["min", "mid"])
def test_quadratic_temperature_coupling(platform, ref):
    """``c1·(T − T0) + c2·(T − T0)²`` on m_y, T the platform temperature.

    QA: with T0 at the bottom of the range the closure reported the linear coupling
    plus three steps, a line and a shape (a_Y std z 12 -> 37); with T0 in the middle
    (linear part small) a settling shape first (std z 31).  Now both terms are found
    (the square is offered once the coupling is in the model, or tested with it when
    it explains more than the coupling alone) and a_Y drops to the noise.
    """
    d = platform(9)
    temp = d["temp"]
    x = temp - (temp.min() if ref == "min" else 0.5 * (temp.min() + temp.max()))
    d["m"] = d["m"].copy()
    d["m"][:, 0] += 2e-9 * x + 4e-8 * x**2
    res, per = _run(d)
    chans = {e.channel: e for e in res.effects if e.name == "auxiliary"}
    assert set(chans) == {"temp", "temp^2"}, [(e.name, e.channel) for e in res.effects]
    sq = chans["temp^2"].details["axes"]["y"]
    assert abs(sq["coefficient"] - 4e-8) < 3 * sq["sigma"] + 0.01 * 4e-8
    err = _errors(per)
    # measured: a_Y error RMS 3.7e-11 -> 4.4e-12 (min), 2.4e-11 -> 4.4e-12 (mid)
    assert err["Y"][1] < 0.5 * err["Y"][0] and err["Y"][1] < 6e-12


def test_bias_step_inside_a_period(platform):
    """A step 250 s into period 7 (a step at a period boundary is absorbed by the bias)."""
    epoch = 7 * 600 + 250.0
    d = platform(3, step=(epoch, 1e-9))
    res, per = _run(d)
    assert [e.name for e in res.effects] == ["bias_step"]
    e = res.effects[0]
    assert e.axis == "y" and abs(e.epoch - epoch) <= 5.0
    assert abs(e.coefficient - 1e-9) < 3 * e.sigma
    z = e.details["axes"]["z"]
    assert abs(z["coefficient"]) < 3 * z["sigma"]
    k = int(np.flatnonzero(per.period_index == 7)[0])
    before, after = abs(per.a_Y_before[k] - AY), abs(per.a_Y_after[k] - AY)
    # measured: period 7's a_Y error 1.27e-10 -> 1.1e-11; RMS over the run 2.2e-11 -> 4.0e-12
    assert after < 0.15 * before
    assert _errors(per)["Y"][1] < 0.3 * _errors(per)["Y"][0]


@pytest.mark.parametrize("into_period", [50.0, 500.0])
def test_a_step_of_the_signal_is_not_a_bias_step(platform, into_period):
    """QA: a 1e-9 m/s² step of a_Y in a period's last rest came out as a bias step and
    its period's a_Y went from 0.35σ to 5.3σ off.  While θ rests a signal step is a
    bias step; the rests at other angles after it within its period tell them apart
    (at 50 s: three of them, and the signal step is what they show; at 500 s: none,
    the rotation after the last rest being masked).  Either way nothing is removed."""
    d = platform(3, pattern="four")
    epoch = 7 * 600 + into_period
    after = d["t"] >= epoch
    c, s = np.cos(d["theta"]), np.sin(d["theta"])
    d["m"] = d["m"] + 1e-9 * np.column_stack([c * after, -s * after])  # Δa_Y, eq. 4
    res, per = _run(d)
    assert not [e for e in res.effects if e.name == "bias_step"], res.effects
    np.testing.assert_array_equal(per.a_Y_after, per.a_Y_before)
    why = [e.details["reason"] for e in res.rejected if e.name == "bias_step"]
    assert why and why[0].startswith(SIGNAL_STEP_REASON), why


def test_a_step_of_the_signal_within_a_rest_is_not_a_bias_step(platform):
    """QA (2026-11-29): a +1e-10 m/s² step of a_Z 98 s into a rest at θ = 0 came out as
    a bias step of −1.48e-10 on z at the rest's start (the signal's step tried only at
    the bias step's own epoch), and its period's a_Z went from 3.6σ to 25.4σ off.  The
    signal's step is now tried within ±200 s of it."""
    d = platform(3)
    t, th = d["t"], d["theta"]
    k = 7
    inp = (t >= k * 600 + t[0]) & (t < (k + 1) * 600 + t[0])
    rest = inp & (np.abs(np.cos(th) - 1.0) < 1e-9)  # θ = 0 in period 7
    idx = np.flatnonzero(rest)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    longest = max(runs, key=len)
    assert len(longest) >= 60
    epoch = float(t[longest[len(longest) * 2 // 3]])
    after = t >= epoch
    c, s = np.cos(th), np.sin(th)
    d["m"] = d["m"] + 1e-9 * np.column_stack([s * after, c * after])  # Δa_Z, eq. 4
    res, per = _run(d)
    assert not [e for e in res.effects if e.name == "bias_step"], res.effects


@pytest.mark.parametrize("from_end", [False, True])
def test_bias_step_seconds_from_the_run_ends(platform, from_end):
    """QA: a step 10-60 s from either end of a run was outside the epochs scanned (0.5 %
    of the record from its ends) and came out as steps of the wrong sign (a_Y max |z|
    5.6 -> 14.6) or an exponential plus steps.  A block base scans each period on its
    own, so only the record's last 10 samples are left out.

    Such a step is found, but it is not a bias step the data can tell from a change of
    the signal: before it (60 s in) or after it (10 s from the end) its period rests at
    one angle only, and a bias step there is exactly a change of a_Y at its epoch plus
    the period's own bias and a_Y.  So it is not removed, and the σ of the period's
    a_Y holds the two readings (accal.closure.aliasspread.add_signal_step_spread):
    before that, 7.8σ (start) and 4.2σ (end) off."""
    d = platform(3)
    n = d["t"].size
    epoch = d["t"][n - 10] if from_end else d["t"][0] + 60.0
    d["m"] = d["m"] + np.column_stack([1e-9 * (d["t"] >= epoch), np.zeros(n)])
    res, per = _run(d)
    assert not [e for e in res.effects if e.name == "bias_step"], res.effects
    steps = [e for e in res.rejected if e.name == "bias_step" and abs(e.epoch - epoch) <= 30.0]
    # at a rest start when the step falls during a rotation (masked samples)
    assert steps and steps[0].details["reason"].startswith(SIGNAL_STEP_REASON), res.rejected
    assert abs(steps[0].coefficient - 1e-9) < 0.3e-9
    k = -1 if from_end else 0
    assert abs(per.a_Y_before[k] - AY) > 4 * per.sigma_Y_before[k]
    assert abs(per.a_Y_after[k] - AY) < 3 * per.sigma_Y_after[k]
    assert any("is in the σ of the base coefficients" in n["note"] for n in res.notes)


def test_settling_transient_after_each_rotation(platform):
    """A transient with the sign of the rotation leaks into a_Y/a_Z; a common one barely."""
    d = platform(4, settle=(2e-10, -1e-10, 20.0, "direction"))
    res, per = _run(d)
    assert [e.name for e in res.effects] == ["intra_period_shape"]
    e = res.effects[0]
    assert e.channel == "direction" and abs(e.tau - 20.0) < 3 * e.details["tau_sigma"]
    ax = e.details["axes"]
    assert abs(ax["y"]["coefficient"] - 2e-10) < 3 * ax["y"]["sigma"]
    assert abs(ax["z"]["coefficient"] + 1e-10) < 3 * ax["z"]["sigma"]
    err = _errors(per)
    # measured: a_Y error RMS 4.2e-11 -> 4.1e-12, a_Z 2.1e-11 -> 3.7e-12
    assert err["Y"][1] < 0.15 * err["Y"][0] and err["Z"][1] < 0.3 * err["Z"][0]


def test_angle_offset_found_where_identifiable(platform):
    """Rests at 0, π/2, π, 3π/2; the π/2 rest is really at π/2 + 2e-4 rad."""
    d = platform(5, pattern="four", angle_error=(np.pi / 2, 2e-4))
    res, per = close_loop_demod(d["t"], d["m"], d["theta"], tau=600.0)
    # first and by far the most significant (p 2e-42); a borderline periodic line at
    # 0.29 Hz (5e-12 m/s², corrected p 0.009) also passes on this run: the line
    # search's nominal 1 % false-alarm rate (none in 60 clean runs)
    names = [e.name for e in res.effects]
    assert names[0] == "angle_offset" and "angle_offset" not in names[1:] and len(names) <= 2
    e = res.effects[0]
    assert e.channel == "rest@1.571" and e.significance < 1e-20
    assert abs(e.coefficient - 2e-4) < 3 * e.sigma  # measured 2.04e-4 ± 5e-6 rad
    # the common offset stays not identifiable (a rotation of (a_Y, a_Z))
    notes = [(n["name"], n["channel"]) for n in res.notes]
    assert ("angle_offset", "common") in notes and all(
        n[0] != "angle_offset" or n[1] == "common" for n in notes
    )
    err = _errors(per)
    # measured: a_Z error RMS 3.2e-11 -> 5.3e-12, a_Y 9.7e-12 -> 5.9e-12
    assert err["Z"][1] < 0.3 * err["Z"][0] and err["Y"][1] < err["Y"][0]


def test_common_angle_offset_is_reported_not_identifiable(platform):
    """A common encoder offset rotates (a_Y, a_Z) by δ: not estimable, and not faked."""
    d = platform(7)
    res, per = close_loop_demod(d["t"], d["m"], d["theta"] + 1e-4, tau=600.0)
    assert not any(e.name == "angle_offset" for e in res.effects)
    assert any(
        n["name"] == "angle_offset" and n["note"].startswith("not identifiable") for n in res.notes
    )
    for e in res.effects + res.unexplained:
        assert e.name in EFFECT_NAMES
    # the log reads θ + δ, so the estimates are (a_Y, a_Z) rotated by −δ:
    # â_Y − a_Y ≈ −δ a_Z, â_Z − a_Z ≈ +δ a_Y (the closure cannot tell: see the note)
    assert np.mean(per.a_Z_after) - AZ == pytest.approx(1e-4 * AY, rel=0.2)
    assert np.mean(per.a_Y_after) - AY == pytest.approx(-1e-4 * AZ, rel=0.3)


def _clean_count(platform, seeds) -> int:
    found = 0
    for seed in seeds:
        res, _ = _run(platform(seed))
        found += res.found
    return found


def test_clean_runs_false_alarms_fast(platform):
    """5 clean quarter days: nothing reported (the 20-run version is marked slow)."""
    assert _clean_count(platform, range(1000, 1005)) == 0


@pytest.mark.slow
def test_clean_runs_false_alarms(platform):
    """At least 19 of 20 clean quarter days report nothing (measured: 20/20)."""
    assert _clean_count(platform, range(1000, 1020)) <= 1


def test_lag_beyond_half_a_period_on_a_channel_that_does_not_repeat(platform):
    """QA: lags were searched in [0, τ/2] only; a coupling to a slow channel (not
    repeating with τ) with a 1000 s lag was missed ("no effect", a_Y std z 31) or
    fitted with the wrong sign at 450 s.  Lags now go to min(span/20, 1 h)."""
    d = platform(5, days=1.0)
    t = d["t"]
    # an orbital cycle and a random walk (two smooth sinusoids alone are the lag/τ ridge:
    # 165 s + a 954 s low-pass fits them as well as a 1000 s delay)
    walk = np.cumsum(np.random.default_rng(5).standard_normal(t.size))
    slow = 0.3 * np.sin(2 * np.pi * t / 5400.0) + 0.002 * walk
    d["m"] = d["m"] + np.column_stack([2e-8 * np.interp(t - 1000.0, t, slow), np.zeros(t.size)])
    res, per = close_loop_demod(d["t"], d["m"], d["theta"], tau=600.0, aux={"slow": slow})
    assert [e.name for e in res.effects] == ["auxiliary"]
    e = res.effects[0]
    assert e.lag == pytest.approx(1000.0, abs=5.0)
    # measured 1.967e-8 ± 3.6e-11 at lag 1001 s: 1.7 % (9σ) low; the σ of a pure lag's
    # coupling leaves the lag's own uncertainty out (docs/closure.md, known limitations)
    ay = e.details["axes"]["y"]
    assert abs(ay["coefficient"] - 2e-8) < 3 * ay["sigma"] + 0.025 * 2e-8
    z = (per.a_Y_after - AY) / per.sigma_Y_after
    assert float(np.std(z)) < 1.5


@pytest.mark.parametrize("period", [1000.0, 5400.0])
def test_periodic_bias_term_found_at_its_own_period(platform, period):
    """A sinusoidal bias term on m_y, faster and slower than the modulation period.

    The per-period bias takes most of a 5400 s term out of the residual and leaves
    its curvature, whose periodogram peaks at the sidebands 1/600 ∓ 1/5400 (675 and
    540 s): those lines were proposed and kept (QA: a_Y std z 1.12 -> 9.9 on a day).
    The frequency is now the alias whose projected sinusoid explains most
    (``candidates._unalias``), refined on that same projected power.
    """
    d = platform(9, days=0.5, line=(1e-8, period))
    res, per = _run(d)
    lines = [e for e in res.effects if e.name == "periodic"]
    assert len(lines) == 1, [(e.name, e.frequency) for e in res.effects]
    e = lines[0]
    # measured: 1000 s -> 1000.002 s (999.857 s with the plain refinement), 5400 s ->
    # 5400.2 s (before: lines at 674.9 and 539.9 s and a bias step)
    assert abs(e.frequency * period - 1) < (2e-5 if period < 600 * 2 else 2e-3)
    assert e.axis == "y" and abs(e.coefficient - 1e-8) < 3 * e.sigma
    before, after = _errors(per)["Y"]
    # measured (5400 s): a_Y RMS error 4.79e-12 before (the per-period affine bias holds
    # most of it), 4.83e-12 after (4.35e-11 before the fix); 1000 s: 2.76e-10 -> 4.84e-12
    assert after < 1.2 * min(before, 5e-12)


def test_lagged_coupling_after_a_resampled_gap(platform):
    """A 1000 s gap on the resampled grid (NaN data and channel, invalid), lag 500 s.

    The search bridged the channel across the gap, so after it the lagged regressor
    was a straight line: QA (a day, ``--resample``) found the coupling and 4 false
    steps, a_Y z +152 in the period after the gap.  The lagged re-search now leaves
    out ``lead`` after every hole of a coupled channel, as after the run's start.
    """
    d = platform(4, days=0.5, temp_coupling=2e-8, temp_lag=500.0)
    t = d["t"]
    gap = (t >= 20000.0) & (t < 21000.0)
    m, temp = d["m"].copy(), d["temp"].copy()
    m[gap] = np.nan
    temp[gap] = np.nan
    res, per = close_loop_demod(t, m, d["theta"], tau=600.0, valid=~gap, aux={"temp": temp})
    assert [e.name for e in res.effects if e.name != "periodic"] == ["auxiliary"]
    e = res.effects[0]
    assert e.lag == pytest.approx(500.0, abs=5.0)
    assert abs(e.details["axes"]["y"]["coefficient"] - 2e-8) < 3 * e.details["axes"]["y"]["sigma"]
    z = (per.a_Y_after - AY) / per.sigma_Y_after
    # measured: std z 1.53, max |z| 3.3 (the same seed without the gap: std z 1.51);
    # before the fix 4 false steps of 0.5-1.1e-9 m/s² at 21134-21567 s, max |z| 6.4
    assert np.isfinite(z).all()
    assert float(np.std(z)) < 1.8 and float(np.max(np.abs(z))) < 4.5


@pytest.mark.parametrize("s", [1e-3, 1e-4])
def test_angle_scale_error_on_a_four_rest_pattern(platform, s):
    """The platform turns by (1 + s) times the logged angle (an encoder gain).

    QA (a day, s = 1e-3): only the π/2 rest's offset was found (-1.09e-3 rad, the
    wrong sign), plus settling shapes and lines at 1/τ and 2/τ; a_Y error RMS
    8.2e-11 -> 3.7e-10.  Now one ``angle_offset`` of channel ``scale``.
    """
    d = platform(6, pattern="four")
    theta_true = d["theta"] * (1 + s)
    c, sn = np.cos(theta_true), np.sin(theta_true)
    c0, s0 = np.cos(d["theta"]), np.sin(d["theta"])
    # re-synthesise the signal at the true angle (noise and bias unchanged)
    dy = (c - c0) * AY + (sn - s0) * AZ
    dz = -(sn - s0) * AY + (c - c0) * AZ
    m = d["m"] + np.column_stack([dy, dz])
    res, per = close_loop_demod(d["t"], m, d["theta"], tau=600.0)
    ang = [e for e in res.effects if e.name == "angle_offset"]
    assert [e.channel for e in ang] == ["scale"], [(e.name, e.channel) for e in res.effects]
    assert abs(ang[0].coefficient - s) < 3 * ang[0].sigma
    assert all(e.name == "periodic" and e.significance > 1e-3 for e in res.effects[1:])
    err = _errors(per)
    # measured: s = 1e-3 -> 1.0012e-3 ± 2.4e-6, a_Y error RMS 8.6e-11 -> 5.9e-12, a_Z
    # 1.3e-9 -> 5.2e-12 (the previous code: two rest offsets, two lines and a settling
    # shape, a_Z 5.2e-10 after); s = 1e-4 -> 1.009e-4 ± 2.4e-6
    assert err["Y"][1] < 8e-12 and err["Z"][1] < 8e-12


@pytest.mark.parametrize(
    ("tau_s", "kind"), [(60.0, "direction"), (140.0, "direction"), (60.0, "common")]
)
def test_settling_time_constant_between_the_grid_values(platform, tau_s, kind):
    """τ_s is refined between the grid's values (5 ... 200 s), with its σ (Jacobian).

    On the grid alone a 60 s transient of 2e-9 m/s² came out at 50 s plus two lines,
    a step and a second shape, and a_Y's error stayed at 1.4e-10 m/s²; 140 s: at 200 s
    plus a step, lines and a quadratic, a_Y error 5.1e-10 (noise ~4e-12).
    """
    d = platform(8, settle=(2e-9, -1e-9, tau_s, kind))
    res, per = _run(d)
    assert [e.name for e in res.effects] == ["intra_period_shape"]
    e = res.effects[0]
    assert e.channel == kind and abs(e.tau - tau_s) < 3 * e.details["tau_sigma"]
    ax = e.details["axes"]
    assert abs(ax["y"]["coefficient"] - 2e-9) < 3 * ax["y"]["sigma"]
    z = (per.a_Y_after - AY) / per.sigma_Y_after
    # measured: τ_s 60.67 ± 0.32 / 142.4 ± 1.4 / 59.64 ± 0.32 s; a_Y error RMS 1.0e-11 /
    # 2.2e-11 / 4.1e-12 m/s², mostly a common offset from τ_s's error, which σ carries
    # (mean z 1.4 / 1.6 / -0.05)
    assert abs(float(np.mean(z))) < 3 and float(np.max(np.abs(z))) < 4.5


def test_no_effect_kept_only_for_a_held_time_constant(platform):
    """Four rests, an angle scale error of 3e-4 and a direction-dependent transient.

    The search holds each τ at its searched value; an effect that only took up the
    misfit of a held τ is no longer determined once the final fit frees it (its
    Jacobian).  Such effects are now dropped: on this run a common shape of
    -2.8e-12 ± 1.1e-11 m/s² had been kept (p 9e-5), a_Z error 1.9e-11 m/s².
    """
    s = 3e-4
    d = platform(4, pattern="four", settle=(1e-9, 0.0, 75.0, "direction"))
    tt = d["theta"] * (1 + s)
    c, sn = np.cos(tt), np.sin(tt)
    c0, s0 = np.cos(d["theta"]), np.sin(d["theta"])
    dy = (c - c0) * AY + (sn - s0) * AZ
    dz = -(sn - s0) * AY + (c - c0) * AZ
    res, per = close_loop_demod(d["t"], d["m"] + np.column_stack([dy, dz]), d["theta"], tau=600.0)
    got = sorted((e.name, e.channel) for e in res.effects)
    assert got == [("angle_offset", "scale"), ("intra_period_shape", "direction")]
    scale = next(e for e in res.effects if e.name == "angle_offset")
    assert abs(scale.coefficient - s) < 3 * scale.sigma
    # measured: a_Y / a_Z error RMS 5.5e-12 / 6.2e-12 m/s² (noise level)
    err = _errors(per)
    assert err["Y"][1] < 8e-12 and err["Z"][1] < 8e-12


def _midrotation_run(seed: int, offset: int = 60, n_per: int = 144):
    """A clean day drawn here: the Fig. 2 pattern (``tests.indep.rotating``) started
    ``offset`` s into its period, a_Y/a_Z with daily terms of 1e-9 m/s², bias and drift,
    white noise of 1e-11 m/s² per sample."""
    th1 = calibration_pattern(600.0, 200.0).theta
    th = np.tile(th1, n_per + 1)[offset : offset + n_per * th1.size]
    t = np.arange(th.size, dtype=float)
    rng = np.random.default_rng(seed)
    ay = 4.6e-7 + 1e-9 * np.sin(2 * np.pi * t / 86400 + 0.3)
    az = -2.3e-7 + 1e-9 * np.cos(2 * np.pi * t / 86400 + 1.1)
    c, s = np.cos(th), np.sin(th)
    my = c * ay + s * az + 2e-6 + 1e-13 * t + rng.normal(0, 1e-11, t.size)
    mz = -s * ay + c * az - 1e-6 - 5e-14 * t + rng.normal(0, 1e-11, t.size)
    return t, np.column_stack([my, mz]), th


def test_a_clean_run_started_mid_pattern_gets_no_drift():
    """QA (2026-11-29): runs starting 60 s into the pattern with a daily 1e-9 m/s²
    signal had an exponential drift of ~9e-8 m/s² (τ 8,400 s) removed, every period's
    σ ×2.5 (here: −2.2e-7 on 3 of 3 seeds).  A drift's curvature within a period fits
    the "mean" model's leak of the signal's slope; it must now stay significant with
    that slope in the model, as a coupling must."""
    res, per = close_loop_demod(*_midrotation_run(0), tau=600.0)
    assert res.effects == (), [(e.name, e.coefficient) for e in res.effects]
    np.testing.assert_array_equal(per.a_Y_after, per.a_Y_before)
