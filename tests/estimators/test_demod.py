"""Unit tests of accal.estimators.demod: validation, solvers, leakage, options, speed."""

import numpy as np
import pytest

from accal.errors import ValidationError
from accal.estimators.demod import demodulate, demodulate_table, fit_sinusoid, sigma_mean
from accal.simulate.gap import simulate_gap


@pytest.fixture(scope="module")
def day():
    data, truth = simulate_gap(days=1, seed=5)
    return data, truth


@pytest.fixture(scope="module")
def small():
    return simulate_gap(days=0.1, seed=1)


def _args(d):
    return d.time.to_numpy(), d.m_y.to_numpy(), d.m_z.to_numpy(), d.theta.to_numpy()


def test_section_4_2_masking_measured_vs_nominal(small):
    data, _ = small
    r = demodulate(*_args(data), tau=600, mask=200)
    assert np.all(r.n_used == 392)
    np.testing.assert_allclose(r.masked_time, 208.0)
    assert r.nominal_masked_time == 200.0
    assert r.masked_fraction == pytest.approx(208 / 600)
    r2 = demodulate(*_args(data), tau=600, mask=200, settle=3.0)
    assert np.all(r2.n_used == 392 - 4 * 2 * 3)


def test_eq14_equals_joint_ls_when_eq16_holds(small):
    data, _ = small
    a = demodulate(*_args(data), tau=600, mask=200, solver="eq14")
    b = demodulate(*_args(data), tau=600, mask=200, solver="joint")
    assert a.solver == "eq14" and b.solver == "joint"
    np.testing.assert_allclose(a.a_Y, b.a_Y, rtol=0, atol=1e-20)
    np.testing.assert_allclose(a.sigma_Z, b.sigma_Z, rtol=1e-9)
    assert a.max_leakage < 1e-12


def test_affine_model_reports_leakage_and_uses_joint(small):
    data, _ = small
    r = demodulate(*_args(data), tau=600, mask=200, signal_model="affine")
    assert r.solver == "joint"
    assert r.max_leakage == pytest.approx(5.8e-3, rel=0.01)  # Σct² residual of the pattern
    assert np.all(np.isfinite(r.slope_Y)) and np.all(r.sigma_slope_Y > 0)
    assert r.cov.shape == (r.a_Y.size, 4, 4)


def test_temperature_bias_needs_auxiliary_channel():
    """Eq. 18 with temperature: coupled bias leaks unless the channel is in V̂b."""
    data, truth = simulate_gap(days=0.5, seed=3, temperature_coupling=2e-9, noise=False)
    args = _args(data)
    plain = demodulate(*args, tau=600, mask=200)
    withT = demodulate(*args, tau=600, mask=200, bias_aux={"T": data.temperature.to_numpy()})
    err_plain = np.abs(plain.a_Y - truth.a_Y.to_numpy()[plain.period_index]).max()
    err_T = np.abs(withT.a_Y - truth.a_Y.to_numpy()[withT.period_index]).max()
    assert withT.solver == "joint" and withT.bias_names == ("bias", "drift", "T")
    assert err_T < 1e-6 * err_plain + 1e-18
    np.testing.assert_allclose(withT.bias_y[:, 2], 2e-9, rtol=1e-6)


def test_quadratic_factor_is_rejected():
    """Section 4.1: measuring only at 0 and π turns k2·a² into a constant bias."""
    data, truth = simulate_gap(days=0.2, seed=3, quadratic=1e2, noise=False)
    r = demodulate(*_args(data), tau=600, mask=200)
    np.testing.assert_allclose(r.a_Y, truth.a_Y.to_numpy(), rtol=1e-9)


def test_gls_with_tabulated_psd(small):
    data, _ = small
    f = np.logspace(-5, np.log10(0.5), 50)
    r = demodulate(*_args(data), tau=600, mask=200, method="gls", psd=(f, 1e-21 * np.ones(50)))
    # white noise: GLS = LS and σ² = K² fs / n_used
    assert r.sigma_Y[0] == pytest.approx(np.sqrt(1e-21 / 392), rel=1e-3)


def test_dropped_periods(small):
    data, _ = small
    args = list(_args(data))
    th = args[3].copy()
    th[600:1200] = 0.0  # second period never leaves θ = 0
    r = demodulate(args[0], args[1], args[2], th, tau=600, mask=200)
    assert r.dropped == 1 and 1 not in r.period_index


def test_sigma_mean_and_sinusoid_ols():
    assert sigma_mean([4.0], 4) == pytest.approx(1.0)
    t = np.arange(1, 61) * 600.0
    f = 1 / (144 * 600.0)
    y = 3e-12 * np.cos(2 * np.pi * f * t) - 1e-12 * np.sin(2 * np.pi * f * t)
    fit = fit_sinusoid(t, y, f, rd=[1e-24, 1e-26])
    assert fit.alpha == pytest.approx(3e-12) and fit.beta == pytest.approx(-1e-12)


# --- validation: one clear line each ------------------------------------------


def _base():
    data, _ = simulate_gap(days=0.05, seed=0, noise=False)
    return {k: data[k].to_numpy().copy() for k in ("time", "m_y", "m_z", "theta")}


def test_missing_columns():
    tab = _base()
    del tab["theta"]
    with pytest.raises(ValidationError, match="missing column.*theta"):
        demodulate_table(tab, tau=600, mask=200)


def test_theta_in_degrees():
    tab = _base()
    tab["theta"] = np.degrees(tab["theta"])
    with pytest.raises(ValidationError, match="looks like degrees"):
        demodulate_table(tab, tau=600, mask=200)


def test_nans():
    tab = _base()
    tab["m_z"][7] = np.nan
    with pytest.raises(ValidationError, match="m_z contains 1 NaN.*index 7"):
        demodulate_table(tab, tau=600, mask=200)


def test_irregular_sampling():
    tab = _base()
    tab["time"][100:] += 0.5
    with pytest.raises(ValidationError, match="sampling is irregular"):
        demodulate_table(tab, tau=600, mask=200)


def test_tau_not_integer_number_of_samples():
    tab = _base()
    with pytest.raises(ValidationError, match=r"tau·fs = 600.5 .*use tau = 600 s or 601 s"):
        demodulate_table(tab, tau=600.5, mask=200)


def test_mask_not_shorter_than_tau():
    tab = _base()
    with pytest.raises(ValidationError, match="mask .* must be in"):
        demodulate_table(tab, tau=600, mask=600)


def test_no_usable_period():
    tab = _base()
    with pytest.raises(ValidationError, match="no period has enough unmasked samples"):
        demodulate_table(tab, tau=600, mask=200, min_fraction=1.5)


def test_theta_never_reaches_pi():
    tab = _base()
    tab["theta"] = np.minimum(tab["theta"], 1.0)
    with pytest.raises(ValidationError, match="never reaches π"):
        demodulate_table(tab, tau=600, mask=200)


def test_bad_option():
    tab = _base()
    with pytest.raises(ValidationError, match="'method' parameter"):
        demodulate_table(tab, tau=600, mask=200, method="wls")


# --- streaming: chunks of any size give the whole-record result ---------------


def _chunked(t, my, mz, th, aux, sizes, valid=None):
    from accal.estimators.demod import DemodChunk

    def source():
        i = k = 0
        while i < t.size:
            sl = slice(i, i + sizes[k % len(sizes)])
            i, k = sl.stop, k + 1
            yield DemodChunk(
                t[sl],
                my[sl],
                mz[sl],
                th[sl],
                {n: v[sl] for n, v in aux.items()},
                None if valid is None else valid[sl],
            )

    return source


def _same(a, b, rtol=1e-12):
    assert a.solver == b.solver and a.dropped == b.dropped and a.n_periods == b.n_periods
    np.testing.assert_array_equal(a.period_index, b.period_index)
    np.testing.assert_array_equal(a.n_used, b.n_used)
    for f in ("a_Y", "a_Z", "sigma_Y", "sigma_Z", "bias_y", "bias_z", "cov", "Rd", "t_mid"):
        x, y = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        np.testing.assert_allclose(y, x, rtol=0, atol=rtol * np.max(np.abs(x)), err_msg=f)
    assert b.masked_fraction == pytest.approx(a.masked_fraction, rel=1e-12)


@pytest.mark.parametrize(
    "kw",
    [{}, {"method": "gls", "aux": True}, {"signal_model": "affine", "settle": 2.0}],
    ids=["ls-auto", "gls-aux", "affine-settle"],
)
def test_stream_equals_whole_record(kw):
    """Chunks of 7 samples (the rest mask and Rd[k] cross every chunk border) or of odd
    sizes give the whole-record result to rounding; a period dropped mid-record stays
    dropped."""
    from accal.estimators.demod import demodulate_stream

    data, _ = simulate_gap(days=0.1, seed=5, temperature_coupling=2e-9)
    t, my, mz, th, temp = (
        data[c].to_numpy() for c in ("time", "m_y", "m_z", "theta", "temperature")
    )
    th = th.copy()
    th[1800:2400] = 0.0  # period 3 never at π: dropped
    kw = dict(kw)
    aux = {"T": temp} if kw.pop("aux", False) else {}
    whole = demodulate(t, my, mz, th, tau=600, mask=200, bias_aux=aux or None, **kw)
    assert whole.dropped == 1
    for sizes in ([7], [599, 1, 1234]):
        res = demodulate_stream(
            _chunked(t, my, mz, th, aux, sizes), tau=600, mask=200, bias_aux=tuple(aux), **kw
        )
        _same(whole, res)


def test_stream_checks_each_chunk():
    from accal.estimators.demod import demodulate_stream

    tab = _base()
    t, my, mz, th = (tab[k] for k in ("time", "m_y", "m_z", "theta"))
    t2 = t.copy()
    t2[1000:] += 0.5
    with pytest.raises(ValidationError, match="sampling is irregular: step 1.5 s at index 999"):
        demodulate_stream(_chunked(t2, my, mz, th, {}, [300]), tau=600, mask=200)
    with pytest.raises(ValidationError, match="never reaches π"):
        demodulate_stream(_chunked(t, my, mz, np.minimum(th, 1), {}, [300]), tau=600, mask=200)
    with pytest.raises(ValidationError, match="looks like degrees"):
        demodulate_stream(_chunked(t, my, mz, np.degrees(th), {}, [300]), tau=600, mask=200)


def test_invalid_samples_are_masked_like_rotations():
    """Missing samples (valid False, NaN values and θ) are masked with their two
    neighbours (θ̇, θ̈ undefined there); noise-free data are still recovered exactly."""
    data, truth = simulate_gap(days=0.05, seed=0, noise=False, bias=3e-6)
    t, my, mz, th = (data[c].to_numpy().copy() for c in ("time", "m_y", "m_z", "theta"))
    ok = np.ones(t.size, bool)
    ok[700:710] = False  # 10 samples inside the -100 s rest (at π) of period 1
    my[~ok] = mz[~ok] = th[~ok] = np.nan
    r = demodulate(t, my, mz, th, tau=600, mask=200, valid=ok, solver="joint")
    assert r.n_used.tolist() == [392, 392 - 12, 392, 392, 392, 392, 392]
    np.testing.assert_allclose(r.a_Y, truth.a_Y.to_numpy(), rtol=1e-9)
    np.testing.assert_allclose(r.a_Z, truth.a_Z.to_numpy(), rtol=1e-9)
    with pytest.raises(ValidationError, match="m_y contains 10 NaN"):
        demodulate(t, my, mz, th, tau=600, mask=200)


# --- eq. 24 with a constant term ---------------------------------------------


def test_sinusoid_constant_term_absorbs_the_mean():
    """Eq. 24 has no constant: over 0.4 of a period, a mean of 4.6e-7 m s⁻² leaks into α, β.
    With ``constant=True`` the same points give α, β and c back exactly."""
    tau, f = 600.0, 1.0 / 86400.0
    t = np.arange(1, 58) * tau  # 9.5 h of a 1-day sinusoid
    y = 4.6e-7 + 3e-12 * np.cos(2 * np.pi * f * t) - 1e-12 * np.sin(2 * np.pi * f * t)
    rd = [1.84e-23, 8.8e-26, 3e-29]
    plain = fit_sinusoid(t, y, f, rd=rd)
    assert not plain.constant and np.isnan(plain.offset) and plain.cov.shape == (2, 2)
    assert abs(plain.alpha - 3e-12) > 1e-8  # the mean leaks by orders of magnitude
    fit = fit_sinusoid(t, y, f, rd=rd, constant=True)
    assert fit.constant and fit.cov.shape == (3, 3)
    assert fit.alpha == pytest.approx(3e-12, abs=1e-20)
    assert fit.beta == pytest.approx(-1e-12, abs=1e-20)
    assert fit.offset == pytest.approx(4.6e-7, rel=1e-12)
    # the constant costs precision on α and β (it is nearly degenerate with them here)
    assert fit.sigma_alpha > plain.sigma_alpha and fit.sigma_offset > 0


def test_sinusoid_banded_covariance_with_missing_periods():
    """``rd`` + ``index`` (a banded solve) equals the dense covariance with the same lags."""
    rng = np.random.default_rng(2)
    idx = np.delete(np.arange(80), [5, 6, 40])
    t = (idx + 1) * 600.0
    y = rng.normal(size=idx.size) * 4e-12
    rd = np.array([1.84e-23, 8.8e-26, -2e-27, 1e-28])
    lag = np.abs(idx[:, None] - idx[None, :])
    dense = np.where(lag < rd.size, rd[np.minimum(lag, rd.size - 1)], 0.0)
    for c in (False, True):
        a = fit_sinusoid(t, y, 1 / 43200.0, rd=rd, index=idx, constant=c)
        b = fit_sinusoid(t, y, 1 / 43200.0, cov=dense, constant=c)
        np.testing.assert_allclose([a.alpha, a.beta], [b.alpha, b.beta], rtol=1e-10)
        np.testing.assert_allclose(a.cov, b.cov, rtol=1e-10)
