"""A coupling's (lag, τ) polished to the least-squares optimum (closure/couplings.py
``_polish``); the platform run it was measured on is in test_indep_acceptance.py.

The data are drawn here (numpy only, not ``accal simulate`` nor ``tests.indep``): a
block base, a channel kicked at every block (a first-order decay after each kick, as a
platform's temperature after each rotation) plus a random walk, white noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.closure.couplings import _polish
from accal.closure.couplingscan import power_at

from .conftest import block_context

Q = 300  # block length [samples, s]


def _kicked(n: int, rng, decay: float = 60.0) -> np.ndarray:
    t = np.arange(n, dtype=float)
    return np.exp(-(t % Q) / decay) + 0.05 * np.cumsum(rng.standard_normal(n)) / np.sqrt(Q)


def _context(seed: int, lag: float, tau: float = 0.0, n_blocks: int = 12):
    """Block base (offset + slope per block), a coupling 0.3·(h_τ * x)(t − lag)."""
    rng = np.random.default_rng(seed)
    n = n_blocks * Q
    t = np.arange(n, dtype=float)
    block = np.arange(n) // Q
    u = (t % Q) / Q - 0.5
    x = _kicked(n, rng)
    xr = x.copy()
    if tau > 0:  # first-order low-pass, exact for a held sample (zero-order hold)
        a = np.exp(-1.0 / tau)
        for k in range(1, n):
            xr[k] = a * xr[k - 1] + (1 - a) * x[k]
    y = 2.0 + 0.1 * block + 0.3 * np.interp(t - lag, t, xr) + 0.002 * rng.standard_normal(n)
    use = t >= 600.0  # the channel's history known at every used sample
    cols = np.column_stack([np.ones(n), u])
    return block_context(t, y, use, block, cols, n_blocks, {"x": x}), x


def test_a_lag_found_as_a_low_pass_returns_to_no_low_pass():
    """The refinement's point on the lag/low-pass ridge (QA platform seed: lag 0 s with
    τ 26 s for a 23.3 s lag without one) goes to the ridge's end."""
    ctx, x = _context(1, lag=123.4)
    lag, tc = _polish(ctx, "x", x, 100.0, 26.0, 600.0)
    assert tc == 0.0
    assert lag == pytest.approx(123.4, abs=0.3)  # measured 123.4


def test_a_real_low_pass_is_refined_not_dropped():
    """A coupling through a 40 s low-pass, started off the optimum: the Gauss-Newton
    steps reach it (the power at the start is below the optimum's)."""
    ctx, x = _context(2, lag=200.0, tau=40.0)
    p_start = power_at(ctx, "x", x, 20.0, 215.0)
    lag, tc = _polish(ctx, "x", x, 215.0, 20.0, 600.0)
    assert tc == pytest.approx(40.0, rel=0.1)  # measured 40.0 s
    assert lag == pytest.approx(200.0, abs=2.0)  # measured 200.0 s
    assert power_at(ctx, "x", x, tc, lag) > p_start


@settings(max_examples=25, deadline=None)
@given(
    lag0=st.floats(0.0, 590.0),
    tc0=st.floats(6.0, 400.0),
    seed=st.integers(0, 3),
)
def test_polish_never_explains_less(lag0, tc0, seed):
    """Whatever the start, the polished (lag, τ) explains at least the start's power."""
    ctx, x = _context(seed, lag=150.0, tau=30.0, n_blocks=8)
    p0 = power_at(ctx, "x", x, tc0, lag0)
    lag, tc = _polish(ctx, "x", x, lag0, tc0, 590.0)
    assert 0.0 <= lag <= 590.0 and tc >= 0.0
    assert power_at(ctx, "x", x, tc, lag) >= p0 * (1 - 1e-12)
