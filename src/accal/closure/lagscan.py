"""The coupling lag scan at every sample lag, exact, for a base of many blocks.

A coupling ``c · h(t − l)`` to a channel ``h`` (already low-passed) is ranked by its
OLS explained power summed over the data channels ``c`` (the platform's y and z
axes), with the current design ``Q`` projected out::

    P(l) = Σ_c (z_clᵀ r)² / (‖z_cl‖² − ‖Qᵀ z_cl‖²),   z_cl[i] = h[k_i − l]·1[chan_i = c]

(``k_i`` the grid index of used sample ``i``, ``r`` the residual, orthogonal to the
design; the same statistic as :func:`accal.closure.candidates.channel_power`).  Every
term is a cross-correlation over the lag, so all lags ``0 .. L`` come from FFTs
(Oppenheim & Schafer, *Discrete-Time Signal Processing*, 3rd ed., sec. 8.7):

* ``z_clᵀ r`` and ``‖z_cl‖²``: the channel (its square) correlated with the
  residual (the channel's used-sample indicator) placed on the grid;
* the block part of ``‖Qᵀ z_cl‖²``, ``Σ_b Σ_j (Q_bjᵀ z_cl)²``: each block's columns
  are non-zero on the block only, so ``Q_bjᵀ z_cl`` is the correlation of the
  block's window of ``h`` with the block's column, one short FFT per block and
  column, and the sum of squares is taken over the blocks at every lag;
* the extra (dense) columns' part: one correlation per column and channel.

The block part depends on the channel only and is computed once per channel and
time constant; a selection step costs the residual's and the extra columns'
correlations.  The same power as evaluating each lag's column directly, to
rounding, at ~100× more lags for less time (a 31-lag grid, 120 s apart on a day,
fell between the peaks of a platform temperature whose identifying part, with the
per-period base projected out, decorrelates within tens of seconds).

The lag multiplicity of such a scan is counted on the same projected columns
(:func:`projected_width`): the correlation of the projected column at the middle
lag with the projected column at every other lag, from the same correlations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import fft

__all__ = [
    "PERIODIC_ACF",
    "BlockSpectra",
    "ChannelScan",
    "block_scan",
    "block_spectra",
    "channel_period",
    "correlate_valid",
    "projected_width",
    "scan_power",
]

#: Rows (the residual, the extra columns) correlated together by the scan.
DENSE_BATCH = 4
#: Blocks per FFT batch (bounds the memory of long records: a batch of 128 blocks of a
#: 600 s period with a 3,600 s lag range is ~30 MB per column).
BLOCK_BATCH = 128


def correlate_valid(h: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """``c[k] = Σ_j h[j + k]·r[j]`` for ``k = 0 .. len(h) − len(r)`` (``"valid"`` mode).

    ``r`` may be (…, len_r): the correlation of ``h`` with each of its rows.  By FFT:
    the circular correlation of ``h`` with ``r`` zero-padded to a length ``N ≥
    len(h)`` equals the linear one wherever ``j + k < len(h)`` (no wrap), which
    holds for every ``k`` kept (Oppenheim & Schafer, *Discrete-Time Signal
    Processing*, 3rd ed., sec. 8.7).
    """
    n = fft.next_fast_len(h.size, real=True)
    c = fft.irfft(fft.rfft(h, n) * np.conj(fft.rfft(r, n, axis=-1)), n, axis=-1)
    return c[..., : h.size - r.shape[-1] + 1]


@dataclass(frozen=True)
class ChannelScan:
    """What the scan of one (channel, time constant) keeps between selection steps.

    Lags are indexed by ``d = L − l`` (``l`` the lag in samples, ``L`` the longest).

    Attributes
    ----------
    h : ndarray, shape (N + L,)
        The channel's response on the grid from ``L`` steps early, mean removed.
    norm2 : ndarray, shape (C, L + 1)
        ``‖z_cl‖²`` per data channel.
    block2 : ndarray, shape (C, L + 1)
        ``Σ_b Σ_j (Q_bjᵀ z_cl)²``, the block base's captured power.
    cross : ndarray, shape (C, L + 1)
        ``z_cmᵀ z_cl − Σ_bj (Q_bjᵀ z_cm)(Q_bjᵀ z_cl)`` with ``m`` the middle lag (the
        projected columns' cross products with the middle one, block base only).
    """

    h: NDArray[np.float64]
    norm2: NDArray[np.float64]
    block2: NDArray[np.float64]
    cross: NDArray[np.float64]


def _placed(idx, chan, n_chan: int, size: int, values: NDArray[np.float64]):
    """``values`` (k, n) of the used samples on the grid per channel -> (k, C, size)."""
    out = np.zeros((values.shape[0], n_chan, size))
    out[:, chan, idx] = values
    return out


@dataclass(frozen=True)
class BlockSpectra:
    """The block base's columns on each block's window of the grid, Fourier transformed.

    They depend on the design's blocks and the used samples only (not on the channel):
    computed once and shared by every channel and time constant of a selection.

    Attributes
    ----------
    k_lo : ndarray of int, shape (B,)
        First grid point of each active block.
    lmax : int
        Longest block window [grid points].
    big : int
        Longest lag [samples].
    nfft : int
        FFT length (``≥ lmax + big``).
    spectra : list of list of ndarray
        Per batch of :data:`BLOCK_BATCH` blocks, per column ``j``: ``conj(rfft(Q_bj))``
        of shape (g, C, nfft/2 + 1), the column placed on the block's window per data
        channel.
    """

    k_lo: NDArray[np.int64]
    lmax: int
    big: int
    nfft: int
    spectra: list


def block_spectra(grid, basis, big: int) -> BlockSpectra:
    """:class:`BlockSpectra` of ``basis``'s blocks for lags ``0 .. big``."""
    idx, chan, n_chan = grid.idx, grid.channel, grid.n_chan
    segs = np.flatnonzero((basis.seg_block >= 0) & (basis.rank > 0))
    if not segs.size:
        return BlockSpectra(np.zeros(0, np.int64), 0, big, 0, [])
    k_lo = np.minimum.reduceat(idx, basis.seg_start)[segs]
    k_hi = np.maximum.reduceat(idx, basis.seg_start)[segs]
    lmax = int(np.max(k_hi - k_lo)) + 1
    nfft = fft.next_fast_len(lmax + big, real=True)
    out = []
    for a in range(0, segs.size, BLOCK_BATCH):
        part = segs[a : a + BLOCK_BATCH]
        lo = k_lo[a : a + BLOCK_BATCH]
        rows = np.concatenate([np.arange(basis.seg_start[s], basis.seg_stop[s]) for s in part])
        which = np.repeat(np.arange(part.size), basis.seg_stop[part] - basis.seg_start[part])
        pos = idx[rows] - lo[which]
        cols = []
        for j in range(int(basis.rank[part].max())):
            g = np.zeros((part.size, n_chan, lmax))
            g[which, chan[rows], pos] = basis.q[rows, j]
            cols.append(np.conj(fft.rfft(g, nfft, axis=-1)))
        out.append(cols)
    return BlockSpectra(k_lo, lmax, big, nfft, out)


def block_scan(
    grid, basis, h: NDArray[np.float64], big: int, spectra: BlockSpectra | None = None
) -> ChannelScan:
    """The channel-only parts of the scan (:class:`ChannelScan`) for lags ``0 .. big``.

    Parameters
    ----------
    grid : Grid
        The used samples on their grid (:class:`accal.closure.noise_psd.Grid`).
    basis : Basis
        The design; its block part is used (:class:`accal.closure.basis.Basis`).
    h : ndarray, shape (grid.size + big,)
        The channel's response at grid points ``−big .. N−1``.
    big : int
        Longest lag [samples].
    spectra : BlockSpectra, optional
        :func:`block_spectra` of ``grid``, ``basis`` and ``big`` (computed if not given).
    """
    if spectra is None:
        spectra = block_spectra(grid, basis, big)
    h = np.asarray(h, dtype=np.float64)
    h = h - float(np.mean(h))
    idx, chan, n_chan = grid.idx, grid.channel, grid.n_chan
    mid = big // 2
    ind = _placed(idx, chan, n_chan, grid.size, np.ones((1, idx.size)))[0]
    norm2 = correlate_valid(h * h, ind)
    # z_cmᵀ z_cl: h correlated with the middle lag's column placed on the grid
    at_mid = _placed(idx, chan, n_chan, grid.size, h[idx + mid][None, :])[0]
    cross = correlate_valid(h, at_mid)
    block2 = np.zeros_like(norm2)
    bx = np.zeros_like(norm2)
    sp = spectra
    hpad = np.concatenate([h, np.zeros(sp.lmax)])
    ahead = np.arange(sp.lmax + big)[None, :]
    for b, cols in enumerate(sp.spectra):
        lo = sp.k_lo[b * BLOCK_BATCH : (b + 1) * BLOCK_BATCH]
        fw = fft.rfft(hpad[lo[:, None] + ahead], sp.nfft, axis=-1)[:, None, :]  # (g, 1, nf)
        for fg in cols:
            c = fft.irfft(fw * fg, sp.nfft, axis=-1)[..., : big + 1]  # (g, C, big + 1)
            block2 += np.einsum("gcd,gcd->cd", c, c)
            bx += np.einsum("gc,gcd->cd", c[..., mid], c)
    return ChannelScan(h, norm2, block2, cross - bx)


def _dense_correlations(ctx_grid, basis, residual, h, big):
    """``z_clᵀ r`` (C, L+1) and ``Q_eᵀ z_cl`` (k, C, L+1) for the extra columns, in
    batches of :data:`DENSE_BATCH` rows (each row's correlation is a grid-long
    transform per data channel, ~3 MB on a day)."""
    g = ctx_grid
    rows = np.vstack([residual[None, :], basis.qe.T])
    out = np.empty((rows.shape[0], g.n_chan, big + 1))
    for a in range(0, rows.shape[0], DENSE_BATCH):
        part = _placed(g.idx, g.channel, g.n_chan, g.size, rows[a : a + DENSE_BATCH])
        out[a : a + DENSE_BATCH] = correlate_valid(h, part)
    return out[0], out[1:]


def scan_power(grid, basis, residual, scan: ChannelScan, big: int) -> NDArray[np.float64]:
    """Explained power (summed over the data channels) at every lag ``0 .. big`` [samples].

    Index ``l`` of the result is the lag ``l`` (not ``d``); zero where a column has
    nothing outside the design (its projected norm under 1e-9 of its norm, as
    :func:`accal.closure.candidates.row_fit`).
    """
    num, ext = _dense_correlations(grid, basis, residual, scan.h, big)
    den = scan.norm2 - scan.block2 - np.sum(ext**2, axis=0)
    ok = den > 1e-9 * np.maximum(scan.norm2, 1e-300)
    pw = np.where(ok, num**2 / np.where(ok, den, 1.0), 0.0).sum(axis=0)
    return pw[::-1]


def projected_width(grid, basis, scan: ChannelScan, big: int) -> float:
    """Decorrelation width [samples] of the projected columns over the lag.

    The correlation of the projected column at the middle lag ``m`` with the one at
    lag ``l`` (block base and extra columns projected out; averaged over the data
    channels); the width is the mean distance from ``m`` at which it first falls
    below 1/2 on either side (the rule of
    :func:`accal.closure.couplings.lag_multiplicity`, on the columns the scan ranks).
    """
    if big < 2:
        return 1.0
    mid = big // 2
    _, ext = _dense_correlations(grid, basis, np.zeros(grid.idx.size), scan.h, big)
    den = scan.norm2 - scan.block2 - np.sum(ext**2, axis=0)
    cross = scan.cross - np.einsum("kc,kcd->cd", ext[..., mid], ext)
    ok = np.all(den > 1e-9 * np.maximum(scan.norm2, 1e-300), axis=0)
    if not ok[mid]:
        return float(big)
    rho = np.mean(cross / np.sqrt(np.maximum(den * den[:, mid : mid + 1], 1e-300)), axis=0)
    low = ~(rho >= 0.5) | ~ok
    right = np.flatnonzero(low[mid:])
    left = np.flatnonzero(low[: mid + 1][::-1])
    w_r = right[0] if right.size else big - mid + 1
    w_l = left[0] if left.size else mid + 1
    return float(max(0.5 * (w_r + w_l), 1.0))


#: Autocorrelation a channel must reach again, past its first zero, to repeat with a
#: period (:func:`channel_period`).
PERIODIC_ACF = 0.6


def channel_period(values: NDArray[np.float64], step: float) -> float:
    """The period [s] with which a channel on a uniform grid repeats, or 0.

    The lag of the first local maximum of the autocorrelation past its first zero
    crossing that reaches :data:`PERIODIC_ACF` (the channel less its least-squares
    line; Wiener-Khinchin by FFT, zero-padded; lags up to a third of the record).  A
    heater cycling every 1,500-2,700 s repeats; a random walk, a drift or noise does
    not.  Used to pick the shortest of couplings' lags a period apart
    (:func:`accal.closure.couplings._shortest_lag`).
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    n = v.size
    if n < 16:
        return 0.0
    u = np.arange(n, dtype=np.float64)
    v = v - np.polyval(np.polyfit(u, v, 1), u)
    f = fft.rfft(v, 2 * n)
    acf = fft.irfft(f.real**2 + f.imag**2, 2 * n)[: n // 3]
    if not acf[0] > 0:
        return 0.0
    acf = acf / acf[0]
    below = np.flatnonzero(acf < 0)
    if below.size == 0:
        return 0.0
    # the first local maximum that high (not the highest: its multiples are as high)
    a = acf[below[0] :]
    peak = np.flatnonzero((a[1:-1] >= PERIODIC_ACF) & (a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:]))
    return float((below[0] + 1 + peak[0]) * step) if peak.size else 0.0
