"""Reference calibration: bias bases, AR prewhitening, scales and scale matrix (issue 22).

The data are drawn here (a small generator of this file, not ``accal simulate``):
a drag-like along-track signal with orbit-periodic and random slow parts, small
cross-track and radial signals, a bias on the basis under test, raw = S⁻¹ a_ref + b,
and a reference with coloured noise (AR(1) plus a differenced white part: red and
blue, as a POD-derived reference is).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import linalg, signal

from accal.errors import ValidationError
from accal.estimators.arnoise import ArModel, fit_ar, levinson, segment_positions
from accal.estimators.refbasis import parse_bias_basis
from accal.estimators.reference import fit_reference

T0 = 1.6e8


def _smooth(rng, n, tau, amp):
    b, a = signal.butter(2, 1 / tau, fs=1.0)
    x = signal.lfilter(b, a, rng.normal(size=n + int(20 * tau)))[int(20 * tau) :]
    return amp * x / x.std()


def _arc(rng, n, period=5600.0):
    t = T0 + np.arange(n, dtype=float)
    ph = 2 * np.pi * t / period
    drag = 2e-7 * (1 + 0.3 * np.sin(ph + 0.4) + _smooth(rng, n, 3000, 0.2))
    true = np.column_stack(
        [
            -drag,
            1e-8 * np.cos(ph) + 0.02 * drag * _smooth(rng, n, 2000, 1),
            3e-8 * np.sin(ph + 1) + 0.03 * drag + _smooth(rng, n, 1500, 5e-9),
        ]
    )
    return t, true


def _ref_noise(rng, n, red=1e-9, blue=2e-8):
    e = signal.lfilter([1], [1, -0.9], rng.normal(size=(n, 3)) * red, axis=0)
    return e + signal.lfilter([1, -1], [1], rng.normal(size=(n, 3)) * blue, axis=0)


def _case(rng, n, spec, s_mat, noise=True):
    t, true = _arc(rng, n)
    basis = parse_bias_basis(spec, t[0], t[-1])
    coef = rng.normal(size=(3, basis.size)) * 1e-7 + np.array([[-1e-6], [2.8e-5], [-5e-7]])
    cols, first = basis.design(t)
    assert first == 0 and cols.shape[1] == basis.size
    raw = true @ np.linalg.inv(s_mat).T + cols @ coef.T
    ref = true.copy()
    if noise:
        raw = raw + rng.normal(size=(n, 3)) * 1e-10
        ref = ref + _ref_noise(rng, n)
    return t, raw, ref, basis, coef


S_DIAG = np.diag([0.96, 0.98, 0.95])
S_FULL = S_DIAG + np.array([[0, 1e-3, 0], [0, 0, -5e-4], [-2e-3, 0, 0]])


# ----------------------------------------------------------------------------- exact cases


@pytest.mark.parametrize(
    ("spec", "mode", "s_mat", "n"),
    [
        ("poly1", "fit", S_DIAG, 20_000),
        ("poly2", "fit-matrix", S_FULL, 20_000),
        ("spline:3h", "fit-matrix", S_FULL, 40_000),
    ],
)
def test_noise_free_data_give_the_truth(spec, mode, s_mat, n):
    rng = np.random.default_rng(3)
    t, raw, ref, basis, coef = _case(rng, n, spec, s_mat, noise=False)
    fit = fit_reference(t, raw, ref, np.ones(n, bool), basis, scale=mode)
    assert fit.modes == (mode,) * 3 and not fit.notes
    np.testing.assert_allclose(fit.scale, s_mat, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fit.bias_coef, coef, rtol=0, atol=1e-10 * np.abs(coef).max())
    np.testing.assert_allclose(fit.calibrate(t, raw), ref, rtol=0, atol=1e-15)


def test_fixed_scale_is_the_given_one_and_the_bias_exact():
    rng = np.random.default_rng(4)
    t, raw, ref, basis, coef = _case(rng, 20_000, "spline:2h", S_DIAG, noise=False)
    fit = fit_reference(
        t, raw, ref, np.ones(t.size, bool), basis, scale="fixed", apriori=tuple(np.diag(S_DIAG))
    )
    assert fit.modes == ("fixed",) * 3
    np.testing.assert_array_equal(fit.scale, S_DIAG)
    assert np.all(fit.scale_sigma == 0)
    np.testing.assert_allclose(fit.bias_coef, coef, rtol=0, atol=1e-12 * np.abs(coef).max())


# ----------------------------------------------------------------------------- noise model


def test_levinson_whitening_is_the_inverse_cholesky_factor():
    """With p = L − 1 the partial predictors whiten any stationary covariance exactly."""
    lag = np.arange(12)
    gamma = 0.8**lag * np.cos(0.3 * lag) + 0.1 * (lag == 0)
    phi, v = levinson(gamma)
    model = ArModel(tuple(phi), v)
    cov = linalg.toeplitz(gamma)
    w = model.whiten(np.eye(12), np.arange(12))
    np.testing.assert_allclose(w @ cov @ w.T, np.eye(12), atol=1e-12)
    # and the last predictor is the Yule-Walker solution
    np.testing.assert_allclose(phi[-1], linalg.solve_toeplitz(gamma[:-1], gamma[1:]), rtol=1e-10)


def test_segments_restart_after_gaps_and_breaks():
    t = np.array([0, 1, 2, 5, 6, 7, 8, 9, 10.0])
    brk = np.zeros(t.size, bool)
    brk[6] = True
    np.testing.assert_array_equal(segment_positions(t, brk), [0, 1, 2, 0, 1, 2, 0, 1, 2])


def test_ar_fit_recovers_an_ar2_process_and_its_psd():
    rng = np.random.default_rng(5)
    x = signal.lfilter([1], [1, -1.2, 0.5], rng.normal(size=200_000))
    model = fit_ar(x, np.arange(x.size, dtype=float), max_order=10)
    assert model.order == 2
    np.testing.assert_allclose(model.phi[2], [1.2, -0.5], atol=0.01)
    assert model.v[2] == pytest.approx(1.0, rel=0.01)
    f = np.array([0.01, 0.2])
    a = np.abs(1 - 1.2 * np.exp(-2j * np.pi * f) + 0.5 * np.exp(-4j * np.pi * f)) ** 2
    np.testing.assert_allclose(model.psd(f, 1.0), 2 / a, rtol=0.05)


# ----------------------------------------------------------------------------- σ by Monte-Carlo


@pytest.mark.parametrize(("spec", "mode", "s_mat"), [("poly1", "fit", S_DIAG)])
def test_sigmas_match_the_scatter(spec, mode, s_mat):
    """z-scores of scales and bias coefficients over drawn arcs: std within 0.75–1.3."""
    zs, zb = [], []
    for rep in range(24):
        rng = np.random.default_rng(1000 + rep)
        t, raw, ref, basis, coef = _case(rng, 20_000, spec, s_mat)
        fit = fit_reference(t, raw, ref, np.ones(t.size, bool), basis, scale=mode)
        sig = fit.scale_sigma
        zs.append((fit.scale - s_mat)[sig > 0] / sig[sig > 0])
        zb.append((fit.bias_coef - coef).ravel() / np.sqrt(np.diag(fit.bias_cov)))
    zs, zb = np.array(zs), np.array(zb)
    assert 0.75 < zs.std() < 1.3, zs.std(0)
    assert 0.75 < zb.std() < 1.3, zb.std(0)
    assert np.abs(zs.mean(0)).max() < 3 / np.sqrt(len(zs)) * 1.5


def test_whitening_beats_ordinary_least_squares_under_blue_noise():
    """GLS scales scatter less than OLS ones under blue noise (the point of weighting)."""
    err_gls, err_ols = [], []
    for rep in range(8):
        rng = np.random.default_rng(50 + rep)
        t, raw, ref, basis, _ = _case(rng, 10_000, "poly1", S_DIAG, noise=False)
        # blue noise (a differentiated position, as a POD-derived reference) over white
        ref = ref + signal.lfilter([1, -1], [1], rng.normal(size=(t.size, 3)) * 3e-7, axis=0)
        ref = ref + rng.normal(size=(t.size, 3)) * 3e-10
        valid = np.ones(t.size, bool)
        kw = {"scale": "fit", "max_scale_sigma": np.inf}  # no fall-back: compare the numbers
        gls = fit_reference(t, raw, ref, valid, basis, **kw)
        ols = fit_reference(t, raw, ref, valid, basis, iterations=-1, **kw)
        assert all(m.order == 0 for m in ols.noise) and all(m.order > 0 for m in gls.noise)
        assert gls.modes[0] == ols.modes[0] == "fit"  # x: the drag, the most signal
        err_gls.append(gls.scale[0, 0] - S_DIAG[0, 0])
        err_ols.append(ols.scale[0, 0] - S_DIAG[0, 0])
    assert np.sqrt(np.mean(np.square(err_gls))) < 0.7 * np.sqrt(np.mean(np.square(err_ols)))


# ----------------------------------------------------------------------------- decisions


def test_a_constant_reference_leaves_the_scale_fixed_and_says_why():
    rng = np.random.default_rng(6)
    n = 20_000
    t = T0 + np.arange(n, dtype=float)
    const = np.tile([-2e-7, 1e-9, 3e-9], (n, 1))
    raw = const / 0.97 + 1e-6 + rng.normal(size=(n, 3)) * 1e-12
    ref = const + rng.normal(size=(n, 3)) * 1e-8
    basis = parse_bias_basis("poly1", t[0], t[-1])
    fit = fit_reference(t, raw, ref, np.ones(n, bool), basis, scale="fit", apriori=(0.97,) * 3)
    assert fit.modes == ("fixed",) * 3
    assert all("not identifiable" in note for note in fit.notes) and len(fit.notes) == 3
    np.testing.assert_array_equal(np.diag(fit.scale), [0.97] * 3)
    b, sb = fit.bias(t[:1])
    assert np.all(np.abs(b - 1e-6) < 4 * sb)


def test_crosstalk_test_flags_a_real_cross_term_only():
    s_x = S_DIAG.copy()
    s_x[2, 0] = 0.005
    p = {}
    for name, s_mat in (("clean", S_DIAG), ("cross", s_x)):
        t, raw, ref, basis, _ = _case(np.random.default_rng(7), 40_000, "poly1", s_mat)
        fit = fit_reference(t, raw, ref, np.ones(t.size, bool), basis, scale="fit-matrix")
        assert fit.crosstalk_test["dof"] == 6
        p[name] = fit.crosstalk_test["p"]
    assert p["cross"] < 1e-4 < 1e-3 < p["clean"]
    assert fit.modes[2] == "fit-matrix"
    assert abs(fit.scale[2, 0] - 0.005) < 3 * fit.scale_sigma[2, 0]


def test_flagged_samples_do_not_enter_the_fit():
    rng = np.random.default_rng(8)
    t, raw, ref, basis, coef = _case(rng, 20_000, "poly1", S_DIAG, noise=False)
    valid = np.ones(t.size, bool)
    valid[5000:5100] = False
    raw[5000:5100] += 1e-3  # a thruster-like spike, excluded
    fit = fit_reference(t, raw, ref, valid, basis, scale="fit")
    np.testing.assert_allclose(fit.bias_coef, coef, rtol=0, atol=1e-10 * np.abs(coef).max())
    assert fit.n_used == t.size - 100


def test_too_few_samples_and_bad_options_are_clear_errors():
    t = T0 + np.arange(20.0)
    basis = parse_bias_basis("spline:1s", t[0], t[-1])
    with pytest.raises(ValidationError, match="usable samples"):
        fit_reference(t, np.zeros((20, 3)), np.zeros((20, 3)), np.ones(20, bool), basis)
    with pytest.raises(ValidationError, match="scale"):
        fit_reference(t, np.zeros((20, 3)), np.zeros((20, 3)), np.ones(20, bool), basis, scale="x")
    for bad in ("spline", "spline:0h", "poly9", "cubic"):
        with pytest.raises(ValidationError, match="bias-basis"):
            parse_bias_basis(bad, 0.0, 1.0)


# ----------------------------------------------------------------------------- bases


@pytest.mark.parametrize("spec", ["spline:6h", "spline:90min", "spline:5000"])
def test_spline_basis_partition_of_unity_and_derivative(spec):
    t = T0 + np.linspace(0, 2 * 86400, 4001)
    basis = parse_bias_basis(spec, t[0], t[-1])
    cols, first = basis.design(t)
    np.testing.assert_allclose(cols.sum(1), 1.0, atol=1e-13)
    coef = np.random.default_rng(0).normal(size=basis.size)
    val = cols @ coef[first : first + cols.shape[1]]
    d1, f1 = basis.design(t, deriv=1)
    der = d1 @ coef[f1 : f1 + d1.shape[1]]
    fd = np.gradient(val, t)
    np.testing.assert_allclose(der[5:-5], fd[5:-5], atol=1e-3 * np.abs(der).max())
    # a block of the arc sees only its own few coefficients
    part, lo = basis.design(t[1000:1100])
    assert part.shape[1] <= 4 + int(np.ceil(100 * (t[1] - t[0]) / basis.node_step)) + 1
    np.testing.assert_allclose(part @ coef[lo : lo + part.shape[1]], val[1000:1100], rtol=1e-12)


def test_poly_basis_derivative():
    t = T0 + np.linspace(0, 86400, 1001)
    basis = parse_bias_basis("poly2", t[0], t[-1])
    cols, _ = basis.design(t)
    d1, _ = basis.design(t, deriv=1)
    coef = np.array([1e-6, 2e-7, -3e-8])
    np.testing.assert_allclose(
        (d1 @ coef)[1:-1], np.gradient(cols @ coef, t)[1:-1], rtol=1e-4, atol=1e-18
    )


@settings(max_examples=25, deadline=None)
@given(
    c=st.floats(0.5, 2.0),
    shift=st.floats(-1e-5, 1e-5),
    seed=st.integers(0, 2**16),
)
def test_scale_and_shift_equivariance(c, shift, seed):
    """Reference × c ⇒ S × c, bias unchanged; raw + shift ⇒ bias + shift, S unchanged."""
    rng = np.random.default_rng(seed)
    t, raw, ref, basis, _ = _case(rng, 6_000, "poly1", S_DIAG)
    valid = np.ones(t.size, bool)
    base = fit_reference(t, raw, ref, valid, basis, scale="fit", max_order=4)
    scaled = fit_reference(t, raw, ref * c, valid, basis, scale="fit", max_order=4)
    shifted = fit_reference(t, raw + shift, ref, valid, basis, scale="fit", max_order=4)
    assert scaled.modes == base.modes == shifted.modes  # the decisions are equivariant too
    fixed = np.array([m == "fixed" for m in base.modes])
    expect = base.scale * np.where(fixed, 1.0, c)[:, None]
    np.testing.assert_allclose(scaled.scale, expect, rtol=1e-9)
    np.testing.assert_allclose(
        scaled.bias_coef[~fixed], base.bias_coef[~fixed], rtol=1e-7, atol=1e-16
    )
    np.testing.assert_allclose(shifted.scale, base.scale, rtol=1e-9, atol=1e-12)
    b0, _ = base.bias(t[:1])
    b1, _ = shifted.bias(t[:1])
    np.testing.assert_allclose(b1 - b0, shift, rtol=1e-7, atol=1e-14)


def test_a_gap_longer_than_the_node_step_leaves_its_coefficients_unestimated():
    rng = np.random.default_rng(9)
    t, raw, ref, basis, coef = _case(rng, 70_000, "spline:2h", S_DIAG, noise=False)
    valid = np.ones(t.size, bool)
    valid[15_000:51_000] = False  # 10 h without data: B-splines (8 h wide) inside it
    fit = fit_reference(t, raw, ref, valid, basis, scale="fit")
    assert fit.unsupported.any() and "not estimated" in fit.notes[0]
    assert np.isnan(fit.bias_coef[:, fit.unsupported]).all()
    ok = ~fit.unsupported
    np.testing.assert_allclose(fit.bias_coef[:, ok], coef[:, ok], atol=1e-10 * np.abs(coef).max())
    b, sb = fit.bias(t)
    assert np.isnan(b[30_000]).all() and np.isfinite(b[fit.used]).all()
    assert not fit.used[valid & np.isnan(b).any(1)].any()
    np.testing.assert_allclose(fit.calibrate(t[fit.used], raw[fit.used]), ref[fit.used], atol=1e-15)


def test_a_smooth_reference_and_noisy_raw_data_do_not_shrink_the_scale():
    """Errors in variables: the weights favour frequencies where the raw data hold only
    noise (the reference is smooth there); without the correction the scale came out
    10 % low at 28σ (a 10× sparser reference, interpolated)."""
    z = []
    for rep in range(8):
        rng = np.random.default_rng(200 + rep)
        t, true = _arc(rng, 40_000)
        basis = parse_bias_basis("poly1", t[0], t[-1])
        raw = true @ np.linalg.inv(S_DIAG).T + 1e-6 + 1e-9 * rng.normal(size=(t.size, 3))
        fit = fit_reference(
            t, raw, true, np.ones(t.size, bool), basis, scale="fit", max_scale_sigma=np.inf
        )
        z.append((fit.scale[0, 0] - S_DIAG[0, 0]) / fit.scale_sigma[0, 0])
    assert abs(np.mean(z)) < 1.5 and 0.5 < np.std(z) < 1.6, z
