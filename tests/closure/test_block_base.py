"""Block-diagonal base designs: the block path equals the dense path; validation; channels."""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import BlockBase, close_loop
from accal.closure.basis import Basis
from accal.closure.residual import make_grid
from accal.errors import ValidationError
from accal.simulate.grace import coloured_noise

Q = 600  # samples per block


def _blocky_day(seed: int, n_blocks: int = 12, gaps: bool = True):
    """Per-block affine bias + coloured noise + a step inside block 7 + a lagged coupling."""
    rng = np.random.default_rng(seed)
    n = n_blocks * Q
    t = 1000.0 + np.arange(n, dtype=float)
    blk = np.arange(n) // Q
    u = (np.arange(n) % Q - (Q - 1) / 2) / Q
    y = 1e-7 * rng.standard_normal(n_blocks)[blk] + 3e-9 * rng.standard_normal(n_blocks)[blk] * u
    y += coloured_noise(n, 1.0, 1e-10, 1e-3, rng)
    y += 2e-9 * (t >= t[0] + 7.5 * Q)
    temp = np.sin(2 * np.pi * (t - t[0]) / 2500.0) + 0.2 * rng.standard_normal(n).cumsum() / 50
    y += 4e-9 * np.interp(t - 60.0, t, temp)
    valid = np.ones(n, bool)
    if gaps:
        valid[1500:1540] = False  # inside a block
        valid[3 * Q : 4 * Q] = False  # a whole block without data
    cols = np.column_stack([np.ones(n), u])
    return t, y, valid, blk, cols, temp


def test_block_and_dense_paths_give_the_same_result():
    t, y, valid, blk, cols, temp = _blocky_day(1)
    bb = BlockBase(blk, cols, ("bias", "drift"), scale=np.array([1.0, 1.0 / Q]))
    dense = bb.dense()
    assert dense.shape == (t.size, 24)
    kw = dict(valid=valid, aux={"temp": temp}, candidates=("bias_step", "auxiliary"))
    # a base of several blocks has its coupling lags scanned at every sample
    # (closure/lagscan.py); the dense base (one block) at 31 lags: the same here
    rb = close_loop(t, y, base=bb, options={"lag_scan": "grid"}, **kw)
    rd = close_loop(t, y, base=dense, **kw)
    names = [e.name for e in rb.effects]
    assert names == [e.name for e in rd.effects]
    assert sorted(names) == ["auxiliary", "bias_step"]
    for eb, ed in zip(rb.effects, rd.effects, strict=True):
        assert eb.coefficient == pytest.approx(ed.coefficient, rel=1e-7)
        assert eb.sigma == pytest.approx(ed.sigma, rel=1e-6)
        # the block path knows a step is scanned block by block (a larger
        # multiplicity, see scan_multiplicity); the dense path sees one scan
        per_test_b = eb.significance / eb.details["multiplicity"]
        per_test_d = ed.significance / ed.details["multiplicity"]
        assert per_test_b == pytest.approx(per_test_d, rel=1e-4, abs=1e-300)
        if eb.name == "bias_step":
            assert eb.details["multiplicity"] > ed.details["multiplicity"] == 200
        else:
            assert eb.details["multiplicity"] == ed.details["multiplicity"]
        assert eb.epoch == ed.epoch  # the lag is refined continuously: equal to rounding
        assert (eb.lag is None and ed.lag is None) or eb.lag == pytest.approx(ed.lag, rel=1e-6)
    # the block without data has no coefficients (NaN on both paths)
    bsc = np.tile([1.0, 1.0 / Q], 12)
    for j, (cb, cd) in enumerate(zip(rb.base, rd.base, strict=True)):
        if j // 2 == 3:
            assert np.isnan(cb.before) and np.isnan(cb.sigma_after) and np.isnan(cd.after)
            continue
        for attr in ("before", "after", "change"):
            assert getattr(cb, attr) == pytest.approx(
                getattr(cd, attr) * bsc[j], rel=1e-6, abs=1e-20
            )
        for attr in ("sigma_before", "sigma_after", "sigma_change"):
            assert getattr(cb, attr) == pytest.approx(getattr(cd, attr) * bsc[j], rel=1e-5)
    assert rb.rms_after == pytest.approx(rd.rms_after, rel=1e-9)
    m = rb.use
    np.testing.assert_allclose(rb.residual_after[m], rd.residual_after[m], rtol=0, atol=1e-18)
    np.testing.assert_allclose(rb.effects_model(), rd.effects_model(), rtol=1e-7, atol=1e-20)
    # the step inside block 7 is found where it is (a step between blocks would be
    # absorbed by the per-block bias)
    assert abs(rb.effects[names.index("bias_step")].epoch - (t[0] + 7.5 * Q)) <= 30
    # every sample lag scanned: the same coupling, at the true 60 s (measured 60.0 s,
    # 4.0340e-9 ± 1.9e-11; the grid's refinement 59.95 s)
    (ef,) = [e for e in close_loop(t, y, base=bb, **kw).effects if e.name == "auxiliary"]
    (eg,) = [e for e in rb.effects if e.name == "auxiliary"]
    assert abs(ef.lag - 60.0) < 3 * ef.details["lag_sigma"]
    assert abs(ef.coefficient - eg.coefficient) < 0.1 * eg.sigma


def test_block_base_is_never_formed_densely(monkeypatch):
    t, y, valid, blk, cols, temp = _blocky_day(2)
    bb = BlockBase(blk, cols, ("bias", "drift"))

    def boom(self):
        raise AssertionError("dense design formed")

    monkeypatch.setattr(BlockBase, "dense", boom)
    res = close_loop(t, y, base=bb, valid=valid, aux={"temp": temp})
    assert res.effects
    assert res.model().shape == t.shape
    assert res.cov.shape == (24 + res.effects_cov.shape[0],) * 2
    assert np.isnan(res.cov[0, 2])  # covariances across blocks are not computed
    assert res.base_coefficient("bias[5]").sigma_after > 0


def test_leverage_and_block_covariance_match_dense_fft():
    """Σ_j |Q_j(f)|² and Qᵀ C Q block by block equal the full-length FFT computation."""
    rng = np.random.default_rng(3)
    n = 1800
    t = np.arange(n, dtype=float)
    keep = rng.random(n) > 0.1
    blk = (np.arange(n) // 300)[keep]
    cols = np.column_stack([np.ones(n), np.cos(t / 40.0), t % 300])[keep]
    grid = make_grid(t[keep])
    b = Basis(blk, cols)
    q = b.dense_q()
    lev_dense = np.sum(np.abs(grid.fft(q)) ** 2, axis=0)
    np.testing.assert_allclose(b.leverage(grid), lev_dense, rtol=1e-9, atol=1e-9)
    psd = 1.0 + 50.0 / np.maximum(grid.freqs * 100.0, 0.01)
    acov = np.fft.irfft(psd, grid.size)
    c = acov[np.abs(grid.idx[:, None] - grid.idx[None, :])]
    g = b.block_cov(grid, psd)
    for s in range(b.seg_start.size):
        sl = slice(b.seg_start[s], b.seg_stop[s])
        qs = b.q[sl, : b.rank[s]]
        np.testing.assert_allclose(g[s][: b.rank[s], : b.rank[s]], qs.T @ c[sl, sl] @ qs, rtol=1e-9)


def test_block_base_validation_messages():
    with pytest.raises(ValidationError, match="block 0 are not consecutive"):
        BlockBase(np.array([0, 0, 1, 0]), np.ones((4, 1)), ("b",))
    with pytest.raises(ValidationError, match="names must have 2 entries"):
        BlockBase(np.zeros(4, int), np.ones((4, 2)), ("b",))
    with pytest.raises(ValidationError, match="slices must be increasing"):
        BlockBase.from_slices(10, [(slice(5, 8), np.ones(3)), (slice(0, 3), np.ones(3))], ("b",))
    with pytest.raises(ValidationError, match="base must cover 100 samples"):
        close_loop(np.arange(100.0), np.zeros(100), base=BlockBase.from_dense(np.ones(99)))


def test_two_channels_step_in_one_channel():
    """Two channels on one grid (interleaved): a step in channel z only is found there."""
    rng = np.random.default_rng(4)
    n = 20000
    tt = np.arange(n, dtype=float)
    t = np.repeat(tt, 2)
    ch = np.tile([0, 1], n)
    y = np.empty(2 * n)
    y[0::2] = 1e-7 + coloured_noise(n, 1.0, 1e-10, 1e-3, rng)
    y[1::2] = -2e-7 + 1e-14 * tt + coloured_noise(n, 1.0, 1e-10, 1e-3, rng)
    y[1::2] += 1e-9 * (tt >= 12000)
    res = close_loop(t, y, channel=ch, channel_names=("y", "z"), candidates=("bias_step",))
    assert [e.name for e in res.effects] == ["bias_step"]
    e = res.effects[0]
    assert e.axis == "z" and abs(e.epoch - 12000) <= 60
    assert abs(e.coefficient - 1e-9) < 3 * e.sigma
    assert abs(e.details["axes"]["y"]["coefficient"]) < 3 * e.details["axes"]["y"]["sigma"]
    assert {b.name for b in res.base} == {"bias:y", "drift:y", "bias:z", "drift:z"}
    with pytest.raises(ValidationError, match="channel 0 must be strictly increasing"):
        close_loop(np.zeros(100), np.zeros(100), channel=np.r_[np.zeros(99, int), 1])


@pytest.mark.parametrize("drop", [False, True])
def test_block_products_equal_dense_on_tiled_and_ragged_layouts(drop):
    """``Q_bᵀ z`` and ``Σ Q_b c_b`` per block: the reshape path (blocks of one length
    tiling the samples) and the padded path (a shorter block) equal the dense basis."""
    rng = np.random.default_rng(4)
    n = 8 * 250
    keep = np.ones(n, bool)
    if drop:
        keep[1010:1060] = False  # block 4 is shorter: not tiled
    blk = (np.arange(n) // 250)[keep]
    u = (np.arange(n) % 250 / 250.0)[keep]
    cols = np.column_stack([np.ones(u.size), u, np.cos(7 * u)])
    b = Basis(blk, cols)
    assert b._tiled is not drop
    z = rng.standard_normal((u.size, 5))
    q = b.dense_q()
    np.testing.assert_allclose(b.block_project(z), q @ (q.T @ z), rtol=0, atol=1e-12)
    coef = b.block_coef(z)
    for s in range(b.seg_start.size):
        sl = slice(b.seg_start[s], b.seg_stop[s])
        np.testing.assert_allclose(coef[s], b.q[sl].T @ z[sl], rtol=0, atol=1e-12)
