"""The base coefficients' spread over a coupling's alias lags (closure/aliasspread.py),
and the periods a lagged coupling's left-out start thins (closure/demod.py).

The data are drawn here (numpy only): a per-block affine base, a channel that repeats
with the block length plus a random walk, white noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.closure.aliasspread import base_shift
from accal.closure.demod import _shifted_periods, close_loop_demod
from accal.estimators.design import rest_mask

from .conftest import AY, block_context


def _context(seed: int, n_blocks: int = 12, q: int = 300):
    rng = np.random.default_rng(seed)
    n = n_blocks * q
    t = np.arange(n, dtype=float)
    block = np.arange(n) // q
    u = (t % q) / q - 0.5
    cols = np.column_stack([np.ones(n), u])
    kick = np.exp(-(t % q) / 60.0)  # repeats with the block
    x = kick + 0.05 * np.cumsum(rng.standard_normal(n)) / np.sqrt(q) + 1e-3 * t / q
    y = 2.0 + 0.1 * block + 0.3 * np.interp(t - 450.0, t, x) + 0.01 * rng.standard_normal(n)
    use = t >= 600.0  # the channel's history known at every used sample for lags ≤ 600 s
    ctx = block_context(t, y, use, block, cols, n_blocks, {"x": x})
    return ctx, t, y, x, block, cols, use


@pytest.mark.parametrize("lag", [150.0, 450.0, 449.3])
def test_base_shift_is_the_full_refit_to_machine_precision(lag):
    """β_R(y) − Σ β_R(z) γ (Frisch-Waugh-Lovell) equals the least squares of y on the
    block base and the coupling's column at that lag, block by block."""
    ctx, t, y, x, block, cols, use = _context(1)
    z = np.interp(t - lag, t, x)  # the candidate's own column: linear interpolation, τ = 0
    nb, p = 12, 2
    design = np.zeros((t.size, nb * p + 1))
    for b in range(nb):
        design[block == b, b * p : (b + 1) * p] = cols[block == b]
    design[:, -1] = z
    coef, *_ = np.linalg.lstsq(design[use], y[use], rcond=None)
    direct = coef[:-1].reshape(nb, p)
    shift, _ = base_shift(ctx, "x", x, 0.0, lag)
    beta_r = ctx.basis.fit(y[use]).beta.reshape(nb, p)
    got = beta_r - shift
    ok = np.isfinite(got).all(axis=1)  # the blocks before t = 600 s have no used sample
    assert ok.sum() == 10
    np.testing.assert_allclose(got[ok], direct[ok], rtol=1e-9, atol=1e-12)


def _with_signal_slope(d, slope):
    """The platform run with ``a_Y(t) = AY + slope·t`` (eq. 4: on m_y by cos θ, on m_z
    by −sin θ) and the per-period truth: the mean over each period's rest samples."""
    t, th = d["t"], d["theta"]
    g = slope * t
    m = d["m"] + np.column_stack([np.cos(th) * g, -np.sin(th) * g])
    rest = rest_mask(th)
    k = (t // 600).astype(int)
    truth = AY + np.bincount(k[rest], g[rest]) / np.bincount(k[rest])
    return m, truth


def test_a_period_the_lagged_coupling_thins_is_left_out(platform):
    """QA (a platform day, a 3e-8 m/s²/K coupling at 1543 s found at its alias 343 s):
    the first 343 s are left out as the lagged channel is unknown there, and the first
    period's a_Y, a mean over the rest of its samples only, was 52σ from the period's
    mean of a drifting signal, before and after closure alike.  A period so thinned is
    now left out of the table, with a note."""
    d = platform(3, temp_coupling=2e-8, temp_lag=343.0)
    m, truth = _with_signal_slope(d, 3e-13)  # 1.8e-10 m/s² per period, ~40σ
    res, per = close_loop_demod(d["t"], m, d["theta"], tau=600.0, aux={"temp": d["temp"]})
    e = res.effects[0]
    assert e.name == "auxiliary"
    # the kicks repeat with τ: the lag or an alias; measured 343.0 s scanned at every
    # sample lag (with the 31-lag grid 943.0 s, the alias 343 s listed)
    assert (e.lag - 343.0) % 600.0 == pytest.approx(0.0, abs=10.0)
    aliases = e.details.get("base_sigma_aliases") or []
    assert all(abs(a - 343.0) % 600.0 < 10.0 for a in aliases)
    thinned = int(e.lag // 600.0)  # its start left out; the ones before: all of it
    assert thinned not in per.period_index and per.period_index.size == 36 - thinned - 1
    note = [n for n in res.notes if "left out of the table" in n["note"]]
    assert len(note) == 1 and note[0]["details"]["periods"] == [thinned]
    z = (per.a_Y_after - truth[per.period_index]) / per.sigma_Y_after
    # measured: max |z| 1.15 (the thinned period, had it been kept: ~50σ); std z 0.41:
    # a_Y's RMS error 3.8e-12 (1.9e-11 before closure; 2.3e-11 at the 31-lag grid's
    # alias lag) under a σ of 9.3e-12 that counts the signal's slope, 40σ a period and
    # left in the residual by the "mean" model, as noise (σ before: 2.7× the error)
    assert float(np.max(np.abs(z))) < 4.5 and float(np.std(z)) < 1.5


@settings(max_examples=60, deadline=None)
@given(
    n_per=st.integers(2, 8),
    q=st.integers(4, 40),
    seed=st.integers(0, 2**32 - 1),
)
def test_shifted_periods_match_a_per_period_loop(n_per, q, seed):
    """``_shifted_periods`` against a plain loop over the periods; nothing thinned,
    nothing flagged; a period's start cut moves its mean time (flagged when by over a
    step)."""
    rng = np.random.default_rng(seed)
    n = n_per * q
    t = np.arange(n, dtype=float)
    period = np.arange(n) // q
    use_t = rng.random(n) < 0.8
    after = use_t & (rng.random(n) < 0.9)
    cut = int(rng.integers(0, n_per))
    after &= ~((period == cut) & (t < cut * q + q // 2))
    got = _shifted_periods(after, use_t, t, period, n_per, 1.0)
    for k in range(n_per):
        a, b = use_t & (period == k), after & use_t & (period == k)
        want = a.any() and b.any() and abs(t[b].mean() - t[a].mean()) > 1.0
        assert got[k] == want
    assert not _shifted_periods(use_t, use_t, t, period, n_per, 1.0).any()
