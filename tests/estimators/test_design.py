"""Tests of the calibration-pattern designer (section 4.1, Figs. 1-2)."""

import numpy as np
import pytest

from accal.errors import ValidationError
from accal.estimators.design import condition_residuals, design_pattern, rest_mask


def test_fig2_pattern_for_tau600_tm200():
    """Search gives +34 | 50 | -100 | 50 | +132 | 50 | -100 | 50 | +34 s (τ = 600, TM = 200)."""
    p = design_pattern(600, 200, 1.0)
    assert [n for n, _ in p.segments] == [34, 50, 100, 50, 132, 50, 100, 50, 34]
    assert p.mask_nominal.sum() == 400
    assert p.mask.sum() == 392  # θ̈ drops one more sample at each end of each rotation
    # eq. 16 for a mean signal and an affine bias: exact on the sample grid
    assert p.residuals["sum_c"] == 0 and p.residuals["sum_ct"] == 0
    assert p.residuals_nominal["sum_c"] == 0 and p.residuals_nominal["sum_ct"] == 0
    # affine signal: Σct² is the smallest over integer layouts, not zero
    assert abs(p.residuals["sum_ct2"]) < 0.01
    for a in (20, 33, 35, 50):
        other = design_pattern(600, 200, 1.0, a=a)
        assert abs(other.residuals["sum_ct2"]) >= abs(p.residuals["sum_ct2"])


def test_pattern_properties():
    p = design_pattern(600, 200)
    th = p.theta
    assert th.min() >= 0 and th.max() <= 2 * np.pi
    rest = np.isclose(th, 0) | np.isclose(th, np.pi)
    assert np.all(rest[p.mask_nominal])
    # smooth rotations: discrete velocity and acceleration small at the ends
    d1 = np.diff(th)
    moving = np.flatnonzero(np.abs(d1) > 0)
    starts = moving[np.r_[True, np.diff(moving) > 1]]
    assert len(starts) == 4
    assert np.all(np.abs(d1[starts]) < 1e-3)  # θ̇ ≈ 0 when a rotation starts
    assert np.max(np.abs(np.diff(d1))) < 1e-2


def test_fig1_pattern_rejects_constant_and_drift():
    p = design_pattern(600, 200, kind="fig1")
    assert [n for n, _ in p.segments] == [100, 100, 200, 100, 100]
    assert p.residuals["sum_c"] == 0 and p.residuals["sum_ct"] == 0


def test_rest_mask_settle_and_tolerance():
    th = np.r_[np.zeros(10), np.linspace(0, np.pi, 6)[1:-1], np.full(10, np.pi)]
    base = rest_mask(th)
    assert base.sum() == len(th) - 4 - 2
    assert rest_mask(th, settle=2).sum() == base.sum() - 4
    noisy = th + 1e-7 * np.random.default_rng(0).standard_normal(th.size)
    assert rest_mask(noisy).sum() < base.sum()
    assert rest_mask(noisy, tol=1e-6).sum() == base.sum()


def test_condition_residuals_detects_bad_layout():
    th = np.r_[np.zeros(300), np.full(300, np.pi)]
    r = condition_residuals(th, np.ones(600, bool))
    assert r["sum_c"] == 0 and abs(r["sum_ct"]) == pytest.approx(1.0)


def test_design_errors():
    with pytest.raises(ValidationError, match="not an integer"):
        design_pattern(600.5, 200)
    with pytest.raises(ValidationError, match="divisible"):
        design_pattern(602, 200)
    with pytest.raises(ValidationError, match="tm must be in"):
        design_pattern(600, 600)
    with pytest.raises(ValueError, match="Allowed values"):
        design_pattern(600, 200, kind="fig3")
