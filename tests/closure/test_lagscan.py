"""The block-wise FFT lag scan (closure/lagscan.py) against the direct evaluation.

The data are drawn here (numpy only): two data channels interleaved in time as the
platform's y and z axes, a per-block base of a few columns per channel, gaps inside
and between blocks, blocks of unequal length, and extra dense columns in the design.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.closure.candidates import Context, channel_power
from accal.closure.lagscan import block_scan, projected_width, scan_power

from .conftest import block_context


def _two_channel_context(seed: int, n: int, block_len: int, n_extra: int, holes: int):
    rng = np.random.default_rng(seed)
    tt = np.arange(n, dtype=float)
    t = np.repeat(tt, 2)
    chan = np.tile([0, 1], n)
    # blocks of block_len/2 .. block_len samples
    edges = np.cumsum(rng.integers(max(block_len // 2, 1), block_len + 1, n))
    blk_t = np.searchsorted(edges, tt, side="right")
    block = np.repeat(blk_t, 2)
    use = np.ones(2 * n, bool)
    for _ in range(holes):
        a = int(rng.integers(0, 2 * n - 40))
        use[a : a + int(rng.integers(1, 40))] = False
    use[: 2 * int(rng.integers(0, 20))] = False
    th = 2 * np.pi * tt / block_len
    u = (tt % block_len) / block_len - 0.5
    zero = np.zeros(n)
    cy = [np.cos(th), np.sin(th), np.ones(n), u, zero, zero]
    cz = [-np.sin(th), np.cos(th), zero, zero, np.ones(n), u]
    cols = np.empty((2 * n, 6))
    cols[0::2] = np.column_stack(cy)
    cols[1::2] = np.column_stack(cz)
    extra = rng.standard_normal((2 * n, n_extra)).cumsum(axis=0) if n_extra else None
    n_blocks = int(blk_t.max()) + 1
    y = rng.standard_normal(2 * n)
    ctx = block_context(
        t, y, use, block, cols, n_blocks, {}, extra=extra, chan=chan, names=("y", "z")
    )
    return ctx, rng


def _channel(rng, size: int, block_len: int) -> np.ndarray:
    """A kicked channel (a decay after every block start) plus a random walk, on
    ``size`` grid points (from ``big`` samples before the first one)."""
    k = np.arange(size, dtype=float)
    return 290.0 + np.exp(-(k % block_len) / 17.0) + 0.1 * np.cumsum(rng.standard_normal(size))


def _direct(ctx: Context, h: np.ndarray, big: int) -> np.ndarray:
    """The power at every lag as couplingscan.scan_direct forms it: row by row."""
    h = h - h.mean()
    z = np.stack([h[ctx.grid.idx + big - lag] for lag in range(big + 1)])
    return channel_power(ctx, z)


@pytest.mark.parametrize("n_extra", [0, 3])
def test_block_scan_is_the_direct_power_at_every_lag(n_extra):
    ctx, rng = _two_channel_context(3, n=3000, block_len=300, n_extra=n_extra, holes=6)
    big = 400
    h = _channel(rng, ctx.grid.size + big, 300)
    scan = block_scan(ctx.grid, ctx.basis, h, big)
    got = scan_power(ctx.grid, ctx.basis, ctx.residual, scan, big)
    want = _direct(ctx, h, big)
    assert got.shape == (big + 1,)
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9 * want.max())


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    block_len=st.integers(20, 120),
    n_blocks=st.integers(2, 9),
    big=st.integers(0, 150),
    n_extra=st.integers(0, 2),
    holes=st.integers(0, 5),
)
def test_block_scan_property(seed, block_len, n_blocks, big, n_extra, holes):
    """Any block length, lag range (also longer than a block), gaps and extras."""
    ctx, rng = _two_channel_context(seed, block_len * n_blocks, block_len, n_extra, holes)
    h = _channel(rng, ctx.grid.size + big, block_len)
    scan = block_scan(ctx.grid, ctx.basis, h, big)
    got = scan_power(ctx.grid, ctx.basis, ctx.residual, scan, big)
    want = _direct(ctx, h, big)
    scale = max(float(want.max()), 1e-300)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-8 * scale)


def test_projected_width_is_the_projected_columns_correlation():
    """The width from the scan's correlations equals the one from the columns formed
    and projected explicitly; the projection makes it narrower than the channel's own
    (a random walk decorrelates slowly, its part outside the block base quickly)."""
    ctx, rng = _two_channel_context(5, n=3000, block_len=300, n_extra=2, holes=3)
    big = 300
    h = _channel(rng, ctx.grid.size + big, 300)
    scan = block_scan(ctx.grid, ctx.basis, h, big)
    got = projected_width(ctx.grid, ctx.basis, scan, big)
    hc = h - h.mean()
    mid = big // 2
    masks = ctx.channel_masks()
    rho = np.zeros(big + 1)
    zm = hc[ctx.grid.idx + mid]
    for m in masks:
        a = (zm * m) - ctx.basis.project(zm * m)
        for d in range(big + 1):
            z = hc[ctx.grid.idx + d] * m
            b = z - ctx.basis.project(z)
            rho[d] += a @ b / np.sqrt((a @ a) * (b @ b)) / len(masks)
    low = rho < 0.5
    w_r = np.flatnonzero(low[mid:])[0]
    w_l = np.flatnonzero(low[: mid + 1][::-1])[0]
    assert got == pytest.approx(0.5 * (w_r + w_l))
    assert got < 60  # the kicks' 17 s decay, not the random walk's hours


def test_a_sharp_coupling_between_grid_lags_is_found_at_its_lag():
    """A coupling at 150 s to a channel kicked at every block: every sample lag is
    scanned, so the peak is at the true lag; a 31-lag grid over the same range (20 s
    apart here) falls on the peak's sides, with under half its power."""
    ctx, rng = _two_channel_context(11, n=6000, block_len=300, n_extra=0, holes=4)
    big, lag = 600, 150
    h = _channel(rng, ctx.grid.size + big, 300)
    hc = h - h.mean()
    col = hc[ctx.grid.idx + big - lag]
    y = 0.02 * col * np.where(ctx.grid.channel == 0, 1.0, 0.5)
    y += 0.05 * rng.standard_normal(y.size)
    resid = y - ctx.basis.project(y)
    scan = block_scan(ctx.grid, ctx.basis, h, big)
    pw = scan_power(ctx.grid, ctx.basis, resid, scan, big)
    assert int(np.argmax(pw)) == lag
    grid = np.rint(np.linspace(0, big, 31)).astype(int)
    assert pw[grid].max() < 0.6 * pw[lag]  # measured 0.48, at 160 s
