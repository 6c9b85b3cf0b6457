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
