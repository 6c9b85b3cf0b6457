"""Fast paths of :class:`accal.closure.basis.Basis` against the straightforward ones.

The tiled layout (every block of one length, every sample in a block: the rotating
platform's periods) builds the per-block SVD and the padded products from reshapes
instead of a gather and a scatter; the block columns' leverage is computed once per
grid and shared by the extended bases.  Both must give what the general path and a
fresh computation give, bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.basis import Basis
from accal.closure.residual import make_grid


def _tiled(seed: int, n_blocks: int = 7, length: int = 40, p: int = 4):
    """Interleaved two-channel samples, blocks of one length tiling them."""
    rng = np.random.default_rng(seed)
    n = n_blocks * length
    block = np.repeat(np.arange(n_blocks), length)
    cols = rng.standard_normal((n, p))
    cols[: length // 2, 3] = 0.0  # a column without support in part of a block
    cols[length : 2 * length, 2] = cols[length : 2 * length, 1]  # rank-deficient block
    t = np.repeat(np.arange(n // 2, dtype=float), 2)
    chan = np.tile([0, 1], n // 2)
    return block, cols, t, chan, rng


def _general(block, cols, n_blocks):
    """The same design through the general (gather/scatter) path: one trailing sample
    outside every block makes the layout non-tiled."""
    b2 = np.r_[block, -1]
    c2 = np.vstack([cols, np.zeros((1, cols.shape[1]))])
    return Basis(b2, c2, n_blocks=n_blocks)


def test_tiled_blocks_equal_the_general_path():
    block, cols, _, _, rng = _tiled(3)
    fast = Basis(block, cols)
    slow = _general(block, cols, fast.n_blocks)
    assert fast._tiled and not slow._tiled
    n = block.size
    np.testing.assert_array_equal(fast.q, slow.q[:n])
    np.testing.assert_array_equal(fast.rinv, slow.rinv[: fast.seg_start.size])
    np.testing.assert_array_equal(fast.ident, slow.ident[: fast.seg_start.size])
    np.testing.assert_array_equal(fast.rank, slow.rank[: fast.seg_start.size])
    assert fast.rank[1] == cols.shape[1] - 1  # the dependent column is dropped
    z = rng.standard_normal((n, 3))
    np.testing.assert_array_equal(
        fast.block_coef(z), slow.block_coef(np.vstack([z, 0 * z[:1]]))[:-1]
    )
    y = rng.standard_normal(n)
    ff, fs = fast.fit(y), slow.fit(np.r_[y, 0.0])
    np.testing.assert_array_equal(ff.beta, fs.beta)
    np.testing.assert_array_equal(ff.resid, fs.resid[:n])


def test_padded_layout_is_a_view_of_q_when_tiled():
    block, cols, _, _, _ = _tiled(4)
    b = Basis(block, cols)
    assert np.shares_memory(b._qp, b.q)
    np.testing.assert_array_equal(b._qp.reshape(b.n, b.p), b.q)


def _dense_leverage(basis: Basis, grid) -> np.ndarray:
    """``Σ_j |rfft(Q_j)|²`` per channel from the dense orthonormal basis."""
    q = basis.dense_q()
    return np.sum(np.abs(grid.fft(q)) ** 2, axis=0)


def test_leverage_is_computed_once_and_equals_a_fresh_computation():
    block, cols, t, chan, rng = _tiled(5)
    grid = make_grid(t, chan)
    b0 = Basis(block, cols)
    lev0 = b0.leverage(grid)
    ext = b0.extend(rng.standard_normal((block.size, 2)))
    lev1 = ext.leverage(grid)
    assert ext._q_lev is b0._q_lev and ext._q_lev["grid"] is grid  # shared, not recomputed
    fresh0 = Basis(block, cols).leverage(grid)
    fresh1 = Basis(block, cols).extend(ext.extra).leverage(grid)
    np.testing.assert_array_equal(lev0, fresh0)
    np.testing.assert_array_equal(lev1, fresh1)
    np.testing.assert_allclose(lev1, _dense_leverage(ext, grid), rtol=1e-10, atol=1e-10)
    # a caller changing the returned array does not change the kept one
    lev0[:] = -1.0
    np.testing.assert_array_equal(b0.leverage(grid), fresh0)
    # another grid: recomputed for that grid
    grid2 = make_grid(t * 1.0, chan)
    np.testing.assert_array_equal(b0.leverage(grid2), fresh0)
    assert b0._q_lev["grid"] is grid2


def test_blocks_are_built_on_first_use_and_equal_an_eager_build():
    block, cols, t, chan, rng = _tiled(6)
    lazy = Basis(block, cols)
    assert lazy.__dict__["_blocks_pending"] and "q" not in lazy.__dict__
    z = rng.standard_normal((block.size, 2))
    ext = lazy.extend(z)  # builds the blocks once, for both
    assert not lazy._blocks_pending and ext.q is lazy.q
    eager = Basis(block, cols)
    eager._build_blocks()
    for name in ("q", "rinv", "ident", "rank", "seg_start", "sample_seg"):
        np.testing.assert_array_equal(getattr(lazy, name), getattr(eager, name))
    y = rng.standard_normal(block.size)
    np.testing.assert_array_equal(ext.fit(y).resid, eager.extend(z).fit(y).resid)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = Basis(block, cols).nothing
    assert Basis(block, cols).rank_total == eager.rank_total


def test_block_cov_from_kept_spectra_equals_a_fresh_computation():
    block, cols, t, chan, rng = _tiled(7)
    grid = make_grid(t, chan)
    b = Basis(block, cols)
    b.leverage(grid)  # keeps the local spectra of Q
    psd = 1.0 + rng.random(grid.size // 2 + 1)
    kept = b.block_cov(grid, psd)
    fresh = b.block_cov(grid, psd, vals=b.q.copy())  # the same weights, computed afresh
    np.testing.assert_array_equal(kept, fresh)
    other = b.extend(rng.standard_normal((block.size, 1)))
    np.testing.assert_array_equal(
        other.block_cov(grid, 2 * psd), b.block_cov(grid, 2 * psd, vals=b.q)
    )


def test_step_norms_equal_the_dense_projection_of_each_step():
    block, cols, _, _, rng = _tiled(8, n_blocks=4, length=10)
    b = Basis(block, cols).extend(rng.standard_normal((block.size, 1)))
    mask = (rng.random(block.size) > 0.3).astype(float)
    q = b.dense_q()
    n = block.size
    steps = (np.arange(n)[:, None] >= np.arange(n)[None, :]) * mask[:, None]  # column i: v_i
    np.testing.assert_allclose(b.step_norms(mask), np.sum((q.T @ steps) ** 2, axis=0), rtol=1e-10)


def test_a_failed_block_build_raises_again_on_the_next_use(monkeypatch):
    block, cols, _, _, _ = _tiled(9)
    b = Basis(block, cols)
    calls = []

    def broken_svd(*args, **kwargs):
        calls.append(1)
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(np.linalg, "svd", broken_svd)
    for _ in range(2):
        with pytest.raises(np.linalg.LinAlgError, match="did not converge"):
            _ = b.q
    assert len(calls) == 2
    monkeypatch.undo()
    np.testing.assert_array_equal(b.q, Basis(block, cols).q)


def test_appended_columns_equal_a_full_qr_and_a_dependent_one_falls_back():
    """``extend`` updates the QR of the extra columns (CholeskyQR2 of the new block);
    a basis built with all of them at once (Householder QR) spans the same space."""
    block, cols, _, _, rng = _tiled(10)
    n = block.size
    z1, z2 = rng.standard_normal((n, 3)), rng.standard_normal((n, 2))
    inc = Basis(block, cols).extend(z1).extend(z2)
    full = Basis(block, cols, extra=np.column_stack([z1, z2]))
    y = rng.standard_normal(n)
    fi, ff = inc.fit(y), full.fit(y)
    np.testing.assert_allclose(fi.resid, ff.resid, rtol=0, atol=1e-12 * np.abs(y).max())
    np.testing.assert_allclose(fi.gamma, ff.gamma, rtol=1e-9)
    np.testing.assert_allclose(inc.qe.T @ inc.qe, np.eye(5), atol=1e-12)
    # a column in the span of the others: the pivoted QR drops it (coefficient NaN)
    dep = inc.extend(z1[:, :1] + 2.0 * z2[:, 1:])
    assert dep.keep.size == 5 and np.isnan(dep.fit(y).gamma).sum() == 1
    np.testing.assert_allclose(dep.fit(y).resid, fi.resid, atol=1e-12 * np.abs(y).max())
