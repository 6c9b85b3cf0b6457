"""Orthonormal bases of the designs of :func:`accal.closure.close_loop`.

A base is *block-diagonal over contiguous sample blocks*: block ``b`` owns a run of
consecutive samples and ``p`` columns that are zero outside it
(:class:`accal.closure.blockbase.BlockBase`).  A polynomial or any dense design is the
special case of one block; one platform day at 1 Hz is ~144 periods × 4-8 columns,
and the dense design (86,400 × ~800) is never formed.

:class:`Basis` is the orthonormal basis of ``[base | extra dense columns]`` on the
used samples: one SVD per block (``Q_b``), and a QR of the extra columns (the
effects found) after projecting the blocks out.  Everything the selection needs is
computed block by block:

* projections ``Qᵀz`` and ``QQᵀz`` (``np.add.reduceat`` over the blocks);
* the squared norms ``‖Qᵀ 1[t ≥ t_i]‖²`` of every step indicator (cumulative sums);
* the *leverage spectrum* ``Σ_j |Q_j(f)|²`` (the white-noise power the fit removes
  at each frequency, used to correct the residual periodogram): the autocorrelations
  of the block columns, computed on each block's own short grid and folded onto the
  record's frequency grid;
* covariances ``Gᵀ C G`` of block-local linear estimators under a stationary noise
  with autocovariance ``C`` (local FFTs), and of the few dense ones (full FFTs).

With one block all of this reduces to the dense computation, so the dense and the
block path give the same numbers (tested).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.nuisance import tail_sum_norms
from accal.errors import ValidationError

if TYPE_CHECKING:
    from accal.closure.residual import Grid

__all__ = ["Basis", "FitResult"]

_RANK_TOL = 1e-9

#: Attributes of :class:`Basis` set by its ``_build_blocks``.
_BLOCK_ATTRS = frozenset(
    ("seg_start", "seg_stop", "seg_block", "sample_seg", "q", "rinv", "ident", "rank")
    + ("_q_lev", "_pad", "_gather", "_qp", "_qpt", "_tiled")
)


# --------------------------------------------------------------------------------------


def _next_pow2(n: int) -> int:
    return 1 << max(int(np.ceil(np.log2(max(n, 1)))), 0)


def _two_sided(size: int, nf: int) -> NDArray[np.float64]:
    w = np.full(nf, 2.0)
    w[0] = 1.0
    if size % 2 == 0:
        w[-1] = 1.0
    return w


@dataclass
class FitResult:
    """Least-squares fit of ``y`` on ``[base | extra]`` (used samples).

    Attributes
    ----------
    beta : ndarray, shape (n_blocks·p,)
        Base coefficients (NaN where not identifiable: block without used samples,
        or a column in the span of the block's other columns).
    gamma : ndarray, shape (k,)
        Coefficients of the extra columns (NaN for columns left out as dependent).
    resid : ndarray, shape (n,)
        Residual on the used samples.
    a_mat : ndarray, shape (n_seg, p, k_kept)
        ``L E`` per block (``beta_b = L_b y − a_mat_b gamma``).
    qe, re : ndarray, shapes (n, k_kept) and (k_kept, k_kept)
        The extra columns' orthonormal part and its triangle (``E_⊥ = qe re``), from
        which :attr:`w_gamma` is formed when asked for.
    """

    beta: NDArray[np.float64]
    gamma: NDArray[np.float64]
    resid: NDArray[np.float64]
    a_mat: NDArray[np.float64]
    qe: NDArray[np.float64] = field(repr=False)
    re: NDArray[np.float64] = field(repr=False)

    @property
    def k_kept(self) -> int:
        """Number of kept extra columns."""
        return int(self.re.shape[0])

    @property
    def w_gamma(self) -> NDArray[np.float64]:
        """Weights of the kept ``gamma``, shape (k_kept, n): ``gamma[keep] = w_gamma @ y``.

        Formed on demand (only the final fit's covariances need it): an (n, k) array per
        cached model state cost 47 MB each on a 1 Hz day with the orbit template.
        """
        if not self.k_kept:
            return np.zeros((0, self.qe.shape[0]))
        return np.linalg.solve(self.re, self.qe.T)


class Basis:
    """Orthonormal basis of ``[block base | extra dense columns]`` on the used samples.

    Parameters
    ----------
    block : ndarray of int, shape (n,)
        Block of each used sample (``-1``: none), consecutive per block.
    columns : ndarray, shape (n, p)
        Per-sample base column values.
    extra : ndarray, shape (n, k), optional
        Extra dense columns (raw, not orthonormal).
    n_blocks : int, optional
        Number of blocks of the base (default ``block.max() + 1``).
    nuisance : OrbitTemplate, optional
        A projection that is part of the model but never formed as columns (the
        orbit-phase signal template, :class:`accal.closure.nuisance.OrbitTemplate`):
        every other column is taken with it projected out (Frisch-Waugh-Lovell), and
        projections, norms and leverage include it.  Only with a base of one block.
    """

    def __init__(
        self,
        block: NDArray[np.int64],
        columns: NDArray[np.float64],
        extra: NDArray[np.float64] | None = None,
        n_blocks: int | None = None,
        nuisance: Any = None,
    ) -> None:
        self.block = np.asarray(block, dtype=np.int64)
        self.nuisance = nuisance
        self.columns = np.asarray(columns, dtype=np.float64)
        if nuisance is not None:
            if np.unique(self.block[self.block >= 0]).size > 1:
                raise ValidationError("a nuisance projection needs a base of one block")
            self.columns = nuisance.residualize(self.columns)
        n, p = self.columns.shape
        self.n = n
        self.p = p
        self.n_blocks = int(self.block.max()) + 1 if n_blocks is None else int(n_blocks)
        # the per-block SVDs are made when a block attribute is first needed
        # (:meth:`__getattr__`): some bases of a run are built for a check that the
        # run may not reach (e.g. the bias-only and the extended-signal bases)
        self._blocks_pending = True
        self.extra = np.zeros((n, 0)) if extra is None else np.asarray(extra, dtype=np.float64)
        self._build_extra()

    def __getattr__(self, name: str) -> Any:
        # only called when ``name`` is not set: the block attributes before the blocks
        # are built
        if name in _BLOCK_ATTRS and self.__dict__.get("_blocks_pending"):
            self._ensure_blocks()
            if name in self.__dict__:
                return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def _ensure_blocks(self) -> None:
        """Build the blocks if not yet built (a failed build is tried again next time)."""
        if self.__dict__.get("_blocks_pending"):
            try:
                self._build_blocks()
            except BaseException:
                self._blocks_pending = True
                raise

    # ----------------------------------------------------------------- construction
    def _build_blocks(self) -> None:
        self._blocks_pending = False
        n, p = self.n, self.p
        starts = (
            np.flatnonzero(np.r_[True, self.block[1:] != self.block[:-1]])
            if n
            else np.zeros(0, int)
        )
        stops = np.r_[starts[1:], n].astype(np.int64)
        self.seg_start = starts.astype(np.int64)
        self.seg_stop = stops
        self.seg_block = self.block[starts] if n else np.zeros(0, np.int64)
        ns = starts.size
        self.sample_seg = np.repeat(np.arange(ns), stops - starts)
        q = np.zeros((n, p))
        rinv = np.zeros((ns, p, p))
        ident = np.zeros((ns, p), dtype=bool)
        rank = np.zeros(ns, dtype=np.int64)
        lengths = stops - starts
        active = self.seg_block >= 0
        # every segment active and of one length: the samples tile them, and the
        # per-segment views are reshapes (no gather, no scatter)
        tiled = bool(ns > 0 and active.all() and np.all(lengths == lengths[0]))
        for length in np.unique(lengths[active]):
            segs = np.flatnonzero(active & (lengths == length))
            if tiled:
                rows = None
                x = self.columns.reshape(ns, int(length), p)
            else:
                rows = self.seg_start[segs][:, None] + np.arange(length)[None, :]
                x = self.columns[rows]  # (g, L, p)
            nrm = np.sqrt(np.sum(x**2, axis=1))  # (g, p)
            d = np.where(nrm > 0, nrm, 1.0)
            u, s, vt = np.linalg.svd(x / d[:, None, :], full_matrices=False)
            r = min(int(length), p)
            smax = s[:, :1] if s.shape[1] else np.zeros((len(segs), 1))
            keep = (s > _RANK_TOL * np.maximum(smax, 1e-300)) & (smax > 0)
            rk = keep.sum(axis=1)
            uk = u * keep[:, None, :]
            sinv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
            # beta = D^-1 V S^-1 U' y   -> rinv (p, r): columns follow U's columns
            ri = (np.transpose(vt, (0, 2, 1)) * sinv[:, None, :]) / d[:, :, None]
            if rows is None:
                q.reshape(ns, int(length), p)[:, :, :r] = uk
            else:
                q[rows.ravel(), :r] = uk.reshape(-1, uk.shape[2])
            rinv[segs, :, :r] = ri
            vk = vt * keep[:, :, None]
            ident[segs] = (np.sum(vk**2, axis=1) > 1 - 1e-6) & (nrm > 0)
            rank[segs] = rk
        self.q = q
        # the block columns' spectra on a grid (:meth:`_q_spectra`); shared by the
        # bases :meth:`extend` makes, which keep these blocks
        self._q_lev: dict[str, Any] = {}
        self.rinv = rinv
        self.ident = ident
        self.rank = rank
        # padded layout (n_seg, L_max) for batched products, when it is not wasteful
        lmax = int(lengths.max()) if lengths.size else 0
        self._pad = None
        if ns > 1 and ns * lmax <= 1.5 * n:
            pos = np.arange(n) - self.seg_start[self.sample_seg]
            # one flat index into the padded rows: a scatter/gather by one index array
            # is ~30 % faster than by two (a platform day's 301 single-column calls)
            flat = self.sample_seg * lmax + pos
            self._pad = (flat, lmax)
            # the same layout as a gather: padded row -> sample (n: a zero row), ~2x
            # faster than the scatter for two columns
            self._gather = np.full(ns * lmax, n, dtype=np.int64)
            self._gather[flat] = np.arange(n)
            if ns * lmax == n:  # tiled: a view of q
                qp = q.reshape(ns, lmax, p)
            else:
                qp = np.zeros((ns, lmax, p))
                qp[self.sample_seg, pos] = q
            self._qp = qp
            self._qpt = np.ascontiguousarray(np.transpose(qp, (0, 2, 1)))
            # segments of one length tiling the samples (every platform period fully
            # sampled): the padded layout is a reshape, no scatter or gather
            self._tiled = ns * lmax == n

    def _build_extra(self) -> None:
        """QR of the extra columns after projecting the blocks out.

        Columns (numerically) dependent on the blocks or on earlier extra columns
        are left out (``self.keep`` lists the kept ones; their coefficient is NaN).
        """
        e = self.extra
        k = e.shape[1]
        self.keep = np.arange(k)
        if k == 0:
            self.qe = np.zeros((self.n, 0))
            self.re = np.zeros((0, 0))
            return
        ez = e if self.nuisance is None else self.nuisance.residualize(e)
        et = ez - self.block_project(ez)
        norms = np.linalg.norm(e, axis=0)
        qe, re = np.linalg.qr(et)
        d = np.abs(np.diag(re))
        ok = d > _RANK_TOL * np.maximum(norms, 1e-300)
        if not ok.all():
            from scipy.linalg import qr

            _, r2, piv = qr(et, mode="economic", pivoting=True)
            d2 = np.abs(np.diag(r2))
            rank = int(np.sum(d2 > 1e-8 * max(float(norms.max()), 1e-300)))
            self.keep = np.sort(piv[:rank])
            qe, re = np.linalg.qr(et[:, self.keep])
        self.qe = qe
        self.re = re

    def extend(self, z: NDArray[np.float64]) -> Basis:
        """A new basis with the raw columns ``z`` (n, q) appended to the extra ones."""
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        self._ensure_blocks()  # built once, shared by both
        new = Basis.__new__(Basis)
        new.__dict__.update(self.__dict__)
        new.extra = np.column_stack([self.extra, z])
        if not (self.keep.size == self.n_extra and new._append_extra(z)):
            new._build_extra()
        return new

    def _append_extra(self, z: NDArray[np.float64]) -> bool:
        """Update the QR of the extra columns for the appended ``z`` (False: not possible).

        With the current columns all kept, ``[E z] = [Q_e q] [[R_e, c], [0, r]]`` with
        ``c = Q_eᵀ z̃`` and ``q r`` the QR of ``z̃ − Q_e c`` (``z̃`` the columns with the
        blocks and the nuisance projected out; Gram-Schmidt twice, Giraud et al. 2005,
        *Numer. Math.* 101, 87): ``O(n k q)`` instead of the ``O(n (k+q)²)`` of a new
        QR each time the search adds an effect to a basis with ``k`` extra columns.
        The QR of the new block is CholeskyQR2 (Fukaya et al. 2014, *ScalA*, 31),
        matrix products only.  A new column whose part outside the others is under
        1e-6 of its norm returns False (the caller's pivoted QR decides what to keep).
        """
        ez = z if self.nuisance is None else self.nuisance.residualize(z)
        et = ez - self.block_project(ez)
        c = self.qe.T @ et
        et = et - self.qe @ c
        c2 = self.qe.T @ et
        et = et - self.qe @ c2
        try:
            r1 = np.linalg.cholesky(et.T @ et).T
            q = et @ np.linalg.inv(r1)
            r2 = np.linalg.cholesky(q.T @ q).T
            q = q @ np.linalg.inv(r2)
        except np.linalg.LinAlgError:
            return False
        r = r2 @ r1
        norms = np.linalg.norm(z, axis=0)
        d = np.abs(np.diag(r))
        if not (np.all(np.isfinite(q)) and np.all(d > 1e-6 * np.maximum(norms, 1e-300))):
            return False
        k, m = self.re.shape[0], r.shape[0]
        re = np.zeros((k + m, k + m))
        re[:k, :k] = self.re
        re[:k, k:] = c + c2
        re[k:, k:] = r
        self.qe = np.column_stack([self.qe, q])
        self.re = re
        self.keep = np.arange(k + m)
        return True

    # ----------------------------------------------------------------- projections
    @property
    def n_extra(self) -> int:
        """Number of extra (dense) columns."""
        return int(self.extra.shape[1])

    @property
    def rank_total(self) -> int:
        """Dimension of the spanned space."""
        extra = 0 if self.nuisance is None else int(self.nuisance.rank)
        return int(self.rank.sum()) + int(self.keep.size) + extra

    def block_coef(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """``Q_bᵀ z`` for every block: shape (n_seg, p, m)."""
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        if self.seg_start.size == 1:
            return (self.q.T @ z)[None]
        if self._pad is not None:
            flat, lmax = self._pad
            ns = self.seg_start.size
            if self._tiled:
                zp = z.reshape(ns, lmax, z.shape[1])
            else:
                ze = np.concatenate([z, np.zeros((1, z.shape[1]))])
                zp = np.take(ze, self._gather, axis=0).reshape(ns, lmax, z.shape[1])
            return np.matmul(self._qpt, zp)
        out = np.empty((self.seg_start.size, self.p, z.shape[1]))
        for j in range(self.p):
            out[:, j, :] = np.add.reduceat(self.q[:, j : j + 1] * z, self.seg_start, axis=0)
        return out

    def block_expand(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """``Σ_j Q_bj c_bj`` on every sample: (n_seg, p, m) -> (n, m)."""
        if self.seg_start.size == 1:
            return self.q @ c[0]
        if self._pad is not None:
            flat, lmax = self._pad
            prod = np.matmul(self._qp, c)
            if self._tiled:
                return prod.reshape(self.n, -1)
            return prod.reshape(self.seg_start.size * lmax, -1)[flat]
        out = np.zeros((self.n, c.shape[2]))
        for j in range(self.p):
            out += self.q[:, j : j + 1] * c[self.sample_seg, j, :]
        return out

    def block_project(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Projection of ``z`` onto the block part."""
        z = np.asarray(z, dtype=np.float64)
        one = z.ndim == 1
        out = self.block_expand(self.block_coef(z))
        return out[:, 0] if one else out

    def project(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Projection of ``z`` (n,) or (n, m) onto the whole design."""
        z = np.asarray(z, dtype=np.float64)
        one = z.ndim == 1
        z2 = z[:, None] if one else z
        out = self.block_expand(self.block_coef(z2))
        if self.qe.shape[1]:
            out += self.qe @ (self.qe.T @ z2)
        if self.nuisance is not None:
            out += self.nuisance.project(z2)
        return out[:, 0] if one else out

    def captured(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """``‖Qᵀz‖²`` of each column of ``z`` (n, m): the power the design captures."""
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        out = np.sum(self.block_coef(z) ** 2, axis=(0, 1))
        if self.qe.shape[1]:
            out = out + np.sum((self.qe.T @ z) ** 2, axis=0)
        if self.nuisance is not None:
            out = out + self.nuisance.captured(z)
        return out

    def complement(self, z: NDArray[np.float64], tol: float = 1e-8) -> NDArray[np.float64]:
        """Orthonormal basis of the part of the columns ``z`` orthogonal to the design.

        Columns (numerically) in the span of the design or of each other are dropped.
        """
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        # the column norms as np.linalg.norm computes them (same sums), without its copy
        norms0 = np.sqrt(np.add.reduce(z * z, axis=0))
        if z.shape[1] == 0 or not np.any(norms0 > 0):
            return np.zeros((z.shape[0], 0))
        zt = self.project(z)
        np.subtract(z, zt, out=zt)  # z − P z, in the projection's array
        scale = max(float(norms0.max()), 1e-300)
        if z.shape[1] <= 8:
            qz, rz = np.linalg.qr(zt)  # tall-skinny: QR, then the SVD of the small R
            ur, s, _ = np.linalg.svd(rz)
            keep = s > tol * scale
            return qz @ ur[:, keep]
        # many columns (the catch-all basis): Gram matrix + eigh, twice (CholeskyQR2-like);
        # rank decided at 1e-6 of the largest norm (the Gram route cannot resolve 1e-8)
        lam, v = np.linalg.eigh(zt.T @ zt)
        keep = lam > (max(tol, 1e-6) * scale) ** 2
        u = zt @ (v[:, keep] / np.sqrt(lam[keep]))
        lam2, v2 = np.linalg.eigh(u.T @ u)
        return u @ (v2 / np.sqrt(np.maximum(lam2, 1e-300)))

    def dense_q(self) -> NDArray[np.float64]:
        """The orthonormal basis as a dense (n, rank) matrix (small designs only)."""
        cols = []
        for s in range(self.seg_start.size):
            a, b = self.seg_start[s], self.seg_stop[s]
            for j in range(int(self.rank[s])):
                c = np.zeros(self.n)
                c[a:b] = self.q[a:b, j]
                cols.append(c)
        cols.extend(self.qe.T)
        return np.column_stack(cols) if cols else np.zeros((self.n, 0))

    def step_norms(self, mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """``‖Qᵀ v_i‖²`` for every step indicator ``v_i = 1[k ≥ i] · mask`` (n,)."""
        m = np.ones(self.n) if mask is None else np.asarray(mask, dtype=np.float64)
        qm = self.q * m[:, None]
        rc = np.zeros((self.n + 1, self.p))
        np.cumsum(qm[::-1], axis=0, out=rc[-2::-1])  # rc[k] = Σ_{j ≥ k} qm[j]
        ssum = rc[self.seg_start] - rc[self.seg_stop]  # (n_seg, p)
        tot = np.sum(ssum**2, axis=1)
        tail = np.zeros(tot.size + 1)
        tail[:-1] = np.cumsum(tot[::-1])[::-1]
        seg = self.sample_seg
        partial = rc[:-1] - rc[self.seg_stop[seg]]
        out = np.sum(np.square(partial, out=partial), axis=1) + tail[seg + 1]
        out += tail_sum_norms(self.qe, m)
        if self.nuisance is not None:
            out = out + self.nuisance.step_norms(mask)
        return out

    # ----------------------------------------------------------------- spectra
    def _local_groups(self, grid: Grid, vals: NDArray[np.float64]):
        """Per-block values on each block's own zero-padded grid, grouped by FFT length.

        Yields ``(segments, M, F)`` with ``F`` of shape (g, C, m, M//2+1): the rfft of
        the block values (``vals`` (n, m)) per channel, on a grid of length ``M`` ≥ twice
        the block's grid span (so products of two such spectra are linear, not
        circular, correlations).
        """
        seg = np.flatnonzero(self.rank > 0)
        if seg.size == 0:
            return
        gpos = grid.idx
        g0 = gpos[self.seg_start[seg]]
        span = gpos[self.seg_stop[seg] - 1] - g0 + 1
        mlen = np.array([_next_pow2(2 * int(s)) for s in span])
        chan = grid.channel
        for m_len in np.unique(mlen):
            segs = seg[mlen == m_len]
            gi = np.repeat(np.arange(segs.size), self.seg_stop[segs] - self.seg_start[segs])
            rows = np.concatenate([np.arange(self.seg_start[s], self.seg_stop[s]) for s in segs])
            arr = np.zeros((segs.size, grid.n_chan, vals.shape[1], int(m_len)))
            arr[gi, chan[rows], :, gpos[rows] - gpos[self.seg_start[segs]][gi]] = vals[rows]
            f = np.fft.rfft(arr, axis=-1)
            del arr  # not kept while the caller works on f
            yield segs, int(m_len), f

    def _q_spectra(self, grid: Grid) -> dict[str, Any]:
        """The block columns' local spectra and their part of :meth:`leverage`, once per grid.

        One run asks for them several times with the same blocks and grid (the null
        model's leverage, every extended model's leverage, both covariances of the
        final fit): they are computed on the first call and kept (the bases
        :meth:`extend` makes share them, as they share the blocks).  Returns
        ``{"grid", "lev": (C, nf), "groups": [(segments, M, F)]}`` as
        :meth:`_local_groups` yields them for ``Q``.
        """
        cache = self._q_lev
        if cache.get("grid") is not grid:
            nn = grid.size
            circ = np.zeros((grid.n_chan, nn))
            groups = list(self._local_groups(grid, self.q))
            for _, m_len, f in groups:
                acf = np.fft.irfft(np.sum(np.abs(f) ** 2, axis=(0, 2)), m_len, axis=-1)  # (C, M)
                half = m_len // 2
                lags = np.r_[np.arange(half), np.arange(half - m_len, 0)]
                keep = np.abs(lags) < nn
                np.add.at(circ, (slice(None), lags[keep] % nn), acf[:, keep])
            cache.clear()
            cache.update(grid=grid, lev=np.fft.rfft(circ, axis=-1).real, groups=groups)
        return cache

    def leverage(self, grid: Grid) -> NDArray[np.float64]:
        """``Σ_j |Q_j(f)|²`` per channel on the grid's frequencies: shape (C, nf).

        The share of white-noise power the fit removes at ``f`` is this over the
        channel's sample count.  Block columns: their summed linear autocorrelation
        (local FFTs), folded onto the record's circle of length ``N`` and transformed
        (identical to ``|rfft(Q_j)|²`` summed, without N-point FFTs per column;
        computed once per grid, :meth:`_q_spectra`).
        """
        lev = self._q_spectra(grid)["lev"].copy()
        if self.qe.shape[1]:
            lev = lev + np.sum(np.abs(grid.fft(self.qe)) ** 2, axis=0)
        if self.nuisance is not None:
            lev = lev + self.nuisance.leverage(grid.size, grid.step, grid.counts)
        return lev

    def block_cov(
        self, grid: Grid, psd: NDArray[np.float64], vals: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """``V_bᵀ C V_b`` for every block: shape (n_seg, m, m).

        ``vals`` (n, m) are per-sample block-local weights (default the orthonormal
        columns ``Q_b``, whose local spectra :meth:`_q_spectra` keeps); ``C`` is the
        circulant noise covariance of the one-sided PSD level ``psd`` (nf,) on the
        grid (channels independent).
        """
        v = self.q if vals is None else vals
        nn = grid.size
        acov = np.fft.irfft(psd, nn)  # circulant autocovariance on the grid
        out = np.zeros((self.seg_start.size, v.shape[1], v.shape[1]))
        groups = self._q_spectra(grid)["groups"] if vals is None else self._local_groups(grid, v)
        for segs, m_len, f in groups:
            half = m_len // 2
            lags = np.abs(np.r_[np.arange(half), np.arange(half - m_len, 0)])
            kern = np.where(lags < nn, acov[np.minimum(lags, nn - 1)], 0.0)
            kf = np.fft.rfft(kern).real * _two_sided(m_len, f.shape[-1])
            c = np.einsum("gcif,gcjf,f->gij", f, np.conj(f), kf).real / m_len
            out[segs] = 0.5 * (c + np.transpose(c, (0, 2, 1)))
        return out

    # ----------------------------------------------------------------- fitting
    def fit(self, y: NDArray[np.float64]) -> FitResult:
        """Least squares of ``y`` on the design (minimum norm within rank-deficient blocks)."""
        k = self.n_extra
        kept = self.extra[:, self.keep]
        gamma = np.full(k, np.nan)
        if self.keep.size:
            gamma[self.keep] = np.linalg.solve(self.re, self.qe.T @ y)
            a_mat = np.einsum("spr,srk->spk", self.rinv, self.block_coef(kept))
            yb = y - kept @ gamma[self.keep]
        else:
            a_mat = np.zeros((self.seg_start.size, self.p, 0))
            yb = y
        cb = self.block_coef(yb)[:, :, 0]  # (n_seg, p)
        beta_seg = np.einsum("spr,sr->sp", self.rinv, cb)
        beta = np.full((self.n_blocks, self.p), np.nan)
        act = self.seg_block >= 0
        b_ids = self.seg_block[act]
        beta[b_ids] = np.where(self.ident[act], beta_seg[act], np.nan)
        resid = y - self.project(y)
        return FitResult(beta.ravel(), gamma, resid, a_mat, self.qe, self.re)

    def seg_of_block(self) -> NDArray[np.int64]:
        """Segment index of every block (``-1`` when the block has no used sample)."""
        out = np.full(self.n_blocks, -1, dtype=np.int64)
        act = self.seg_block >= 0
        out[self.seg_block[act]] = np.flatnonzero(act)
        return out
