"""The residual on its nominal grid and its coloured-noise PSD estimate.

:func:`make_grid` places the used samples on their nominal uniform grid
(:class:`Grid`, several channels sharing one time grid); :func:`estimate_psd` is
the binned PSD ``S(f)`` of a residual from its periodogram, corrected for the
power the fitted design removed (:func:`leverage_of`, and under strongly coloured
noise :func:`projection_bias`), resolved down to ``min_bin/T``: the noise model of
the sandwich Wald test of :mod:`accal.closure.wald`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import fft
from scipy.optimize import nnls


@dataclass(frozen=True)
class Grid:
    """The used samples placed on their nominal uniform sampling grid.

    Several channels (e.g. the y and z axes of the rotating platform) share one time
    grid; their noises are taken as independent with a common PSD.

    Attributes
    ----------
    idx : ndarray of int, shape (n,)
        Grid index of each used sample (within its channel).
    size : int
        Number of grid points ``N`` per channel (gaps included).
    step : float
        Nominal sampling interval [s].
    chan : ndarray of int, shape (n,), optional
        Channel of each used sample (default: all 0).
    n_chan : int
        Number of channels ``C``.
    """

    idx: NDArray[np.int64]
    size: int
    step: float
    chan: NDArray[np.int64] | None = None
    n_chan: int = 1

    @property
    def channel(self) -> NDArray[np.int64]:
        """Channel of each used sample (zeros for a single channel)."""
        return np.zeros(self.idx.size, dtype=np.int64) if self.chan is None else self.chan

    @property
    def counts(self) -> NDArray[np.float64]:
        """Used samples per channel, shape (C,)."""
        return np.bincount(self.channel, minlength=self.n_chan).astype(np.float64)

    def place(self, cols: NDArray[np.float64]) -> NDArray[np.float64]:
        """Put columns (n, k) or a vector (n,) on the grid, zeros in gaps -> (k, C, N)."""
        cols = np.asarray(cols, dtype=np.float64)
        if cols.ndim == 1:
            cols = cols[:, None]
        out = np.zeros((cols.shape[1], self.n_chan, self.size))
        out[:, self.channel, self.idx] = cols.T
        return out

    def fft(self, cols: NDArray[np.float64]) -> NDArray[np.complex128]:
        """rfft of :meth:`place` per channel -> (k, C, nf)."""
        return np.fft.rfft(self.place(cols), axis=-1)

    @property
    def freqs(self) -> NDArray[np.float64]:
        """Frequencies of the one-sided DFT of the grid [Hz]."""
        return np.fft.rfftfreq(self.size, self.step)


def _fast_size(n: int) -> int:
    """The grid's length: ``n`` points, or a few more, empty, up to the next length whose
    FFT is fast (:func:`scipy.fft.next_fast_len`; 2, 3, 5 and 7 as factors).

    A length with a large prime factor goes to Bluestein's algorithm, ~7 times slower
    (a day without its first 630 s: 85,770 = 2·3²·5·953 points, 5.7 ms per transform
    against 0.76 ms for 86,400); closure's tests, PSD estimates and lag scans are
    FFTs of the grid.  The added points are a gap at the end, which every estimate
    already allows for (86,400 needs none).
    """
    return int(fft.next_fast_len(int(n), real=True))


def make_grid(t: NDArray[np.float64], chan: NDArray[np.int64] | None = None) -> Grid:
    """Nominal-grid indices of sample times ``t`` [s], increasing within each channel,
    on a grid of a fast FFT length (:func:`_fast_size`).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, non-decreasing (strictly increasing within a channel) [s].
    chan : ndarray of int, shape (n,), optional
        Channel index ``0 .. C-1`` of each sample.
    """
    t = np.asarray(t, dtype=np.float64)
    if chan is None or t.size == 0:
        if t.size < 2:
            return Grid(np.zeros(t.size, dtype=np.int64), max(t.size, 1), 1.0)
        step = float(np.median(np.diff(t)))
        idx = np.rint((t - t[0]) / step).astype(np.int64)
        idx = np.maximum.accumulate(np.maximum(idx, np.arange(idx.size)))
        return Grid(idx, _fast_size(int(idx[-1]) + 1), step)
    chan = np.asarray(chan, dtype=np.int64)
    n_chan = int(chan.max()) + 1
    diffs = [np.diff(t[chan == c]) for c in range(n_chan)]
    d = np.concatenate(diffs) if diffs else np.zeros(0)
    step = float(np.median(d)) if d.size else 1.0
    idx = np.zeros(t.size, dtype=np.int64)
    for c in range(n_chan):
        m = chan == c
        ic = np.rint((t[m] - t[0]) / step).astype(np.int64)
        ic = np.maximum.accumulate(np.maximum(ic, np.arange(ic.size) + (ic[0] if ic.size else 0)))
        idx[m] = ic
    return Grid(idx, _fast_size(int(idx.max()) + 1), step, chan, n_chan)


@dataclass(frozen=True)
class NoisePSD:
    """Binned, projection-corrected two-sided PSD estimate of a residual.

    Attributes
    ----------
    level : ndarray, shape (nbins,)
        PSD value of each bin (two-sided, per grid sample: ``E|R(f)|²/n``) [(m/s²)²].
    which : ndarray of int, shape (nf,)
        Bin of each DFT frequency (frequency 0 belongs to bin 0).
    counts : ndarray, shape (nbins,)
        Effective number of periodogram ordinates in each bin (ordinates weighted by
        the share of their power the fitted design left in the residual), summed
        over the channels.
    pgram : ndarray, shape (nf,)
        The corrected periodogram itself (mean over the channels).
    shape : ndarray, shape (nf,), optional
        Within-bin shape of the PSD (``level`` is the level of ``PSD/shape``).
    """

    level: NDArray[np.float64]
    which: NDArray[np.int64]
    counts: NDArray[np.float64]
    pgram: NDArray[np.float64]
    shape: NDArray[np.float64] | None = None

    @property
    def psd(self) -> NDArray[np.float64]:
        """The PSD at every DFT frequency: bin level times the within-bin shape."""
        out = self.level[self.which]
        return out if self.shape is None else out * self.shape

    @property
    def binned(self) -> NDArray[np.float64]:
        """Mean PSD of each bin (DC excluded)."""
        p = self.psd
        nb = self.level.size
        return np.bincount(self.which[1:], weights=p[1:], minlength=nb) / np.maximum(
            np.bincount(self.which[1:], minlength=nb), 1
        )


def two_sided_weights(size: int, nf: int) -> NDArray[np.float64]:
    w = np.full(nf, 2.0)
    w[0] = 1.0
    if size % 2 == 0:
        w[-1] = 1.0
    return w


def as_leverage(basis: NDArray, n_chan: int) -> NDArray[np.float64]:
    """Leverage spectrum (C, nf) from either itself or a complex basis rfft (k, [C,] nf)."""
    b = np.asarray(basis)
    if np.iscomplexobj(b):
        lev = np.sum(np.abs(b) ** 2, axis=0)
        return lev[None, :] if lev.ndim == 1 else lev
    return b[None, :] if b.ndim == 1 else b


def estimate_psd(
    grid: Grid,
    residual: NDArray[np.float64],
    basis_leverage: NDArray,
    *,
    min_bin: int = 3,
    growth: float = 0.25,
    tilt: bool = True,
    first_bin: int = 10,
) -> NoisePSD:
    """PSD of ``residual`` from its periodogram, corrected for the fitted model.

    Parameters
    ----------
    grid : Grid
        Sample placement.
    residual : ndarray, shape (n,)
        Residual of a least-squares fit [m/s²].
    basis_leverage : ndarray, shape (C, nf)
        Leverage spectrum ``Σ_j |Q_j(f)|²`` of an orthonormal basis ``Q`` of the
        fitted design, per channel (:meth:`accal.closure.basis.Basis.leverage`); a
        complex array ``rfft(Q)`` of shape (k, nf) is accepted too.  Removing the
        design removed the share ``Σ_j |Q_j(f)|²/n_c`` of the white-noise power at
        ``f``.  Each bin's level is then ``Σ P_f / Σ (1 − share_f)`` (unbiased for
        noise that is white within the bin), and bins are widened until they hold
        ``min_bin/2`` effective ordinates.
    min_bin, growth : int, float
        Bins of ``min_bin`` ordinates at the low end, each growing by ``growth``.
    first_bin : int
        Ordinates of the lowest bin.  The slowest regressors (steps, quadratics,
        day-scale couplings) put most of their variance there; with ``min_bin``
        ordinates their test would rest on ~5 degrees of freedom (heavy F tails:
        on simulated 1/f noise a 1e-10 m/s² step is then found 2/10 times instead
        of 10/10).  Ten ordinates with the within-bin shape keep the calibration
        (docs/closure.md).
    tilt : bool
        Shape the PSD within each bin by a smooth non-negative combination of
        ``1, 1/f, 1/f², f², f⁴`` fitted across the bins (each bin keeps its
        estimated total): under red noise the first ordinates of a low bin carry
        more than the bin mean, and the slowest regressors put most of their power
        there (a flat bin makes their test anti-conservative: 15 % instead of 5 %
        for a quadratic under 1/f noise); likewise the top of a wide bin under a
        steep high-frequency rise, where a sharp step has its variance.

    Returns
    -------
    NoisePSD
    """
    nc = np.maximum(grid.counts, 1.0)[:, None]
    spec = grid.fft(residual)[0]  # (C, nf)
    nf = spec.shape[-1]
    raw = np.abs(spec) ** 2 / nc
    lev = as_leverage(basis_leverage, grid.n_chan)
    supp_c = np.clip(1.0 - lev / nc, 0.0, 1.0) if lev.size else np.ones((grid.n_chan, nf))
    supp = np.mean(supp_c, axis=0)  # bin layout from the mean suppression
    # bins: at least `min_bin` ordinates and `min_bin/2` effective (unsuppressed) ones
    csum = np.concatenate([[0.0], np.cumsum(supp)])
    edges = [1]
    while edges[-1] < nf:
        a = edges[-1]
        width = max(min_bin, int(growth * a), first_bin if a == 1 else 0)
        b = a + width
        need = csum[a] + 0.5 * width
        if b < nf and csum[b] < need:
            b = max(b, int(np.searchsorted(csum, need)))
        edges.append(min(b, nf))
    if len(edges) > 2 and csum[edges[-1]] - csum[edges[-2]] < 0.5 * min_bin:
        edges.pop(-2)  # merge a starved last bin into its neighbour
    edges_arr = np.asarray(edges)
    which = np.zeros(nf, dtype=np.int64)
    which[1:] = np.searchsorted(edges_arr, np.arange(1, nf), side="right") - 1
    nb = max(edges_arr.size - 1, 1)
    # ratio estimator: E[Σ raw] = S · Σ supp within a bin (white within the bin)
    rsum = raw[:, 1:].sum(axis=0)
    ssum = supp_c[:, 1:].sum(axis=0)
    sums = np.bincount(which[1:], weights=rsum, minlength=nb)
    effective = np.bincount(which[1:], weights=ssum, minlength=nb)
    level = sums / np.maximum(effective, 1e-12)
    counts = np.maximum(effective, 0.5)
    pgram = np.mean(raw / np.maximum(supp_c, 0.2), axis=0)
    shape = None
    if tilt and nb >= 4:
        # the PSD is not flat within the lowest bins (a 1/f rise puts 1.6x the bin
        # mean on the first of three ordinates, where the slowest regressors live),
        # nor within the wide top bins under a steep rise: tilt each bin by a smooth
        # shape fitted across the bins, keeping the ratio estimator:
        # E[Σ raw] = level · Σ supp·shape
        f = np.fft.rfftfreq(grid.size, grid.step)
        fc = np.bincount(which[1:], weights=f[1:], minlength=nb) / np.maximum(
            np.bincount(which[1:], minlength=nb), 1
        )
        sh = _smooth_shape(f, fc, level, counts)
        if sh is not None:
            wsum = np.bincount(which[1:], weights=ssum * sh[1:], minlength=nb)
            level = sums / np.maximum(wsum, 1e-300)
            shape = sh
    return NoisePSD(level, which, counts, pgram, shape)


_SHAPE_POWERS = (0.0, -1.0, -2.0, 2.0, 4.0)


def _smooth_shape(f, fc, level, counts) -> NDArray[np.float64] | None:
    """``Σ c_k f^k``, k in (0, −1, −2, 2, 4), c_k ≥ 0, fitted in relative error to bin levels.

    Red terms for 1/f and random-walk noise at the low end, rising terms for a
    high-frequency rise (MicroSTAR's f⁴, eq. 1 of Lenoir et al. 2013) at the top.
    """
    ok = (level > 0) & (fc > 0)
    if ok.sum() < 6:
        return None
    x = np.column_stack([fc[ok] ** k for k in _SHAPE_POWERS])
    scale = x.max(axis=0)
    ref = level[ok]
    coef = None
    for _ in range(3):  # weights from the fit, not the noisy levels
        wgt = np.sqrt(counts[ok]) / np.maximum(ref, 1e-300)
        c, _ = nnls(x / scale * wgt[:, None], level[ok] * wgt)
        coef = c / scale
        if not np.any(coef > 0):
            return None
        ref = np.maximum(x @ coef, 1e-3 * level[ok])
    out = np.empty_like(f)
    out[1:] = sum(c * f[1:] ** k for c, k in zip(coef, _SHAPE_POWERS, strict=True))
    out[0] = out[1]
    return out / np.mean(out[1:])


def leverage_of(grid: Grid, basis) -> NDArray[np.float64]:
    """Leverage spectrum (C, nf) of a basis object, a dense orthonormal basis, or itself."""
    if hasattr(basis, "leverage"):
        return basis.leverage(grid)
    b = np.asarray(basis)
    if not np.iscomplexobj(b) and b.ndim == 2 and b.shape[0] == grid.idx.size:
        return np.sum(np.abs(grid.fft(b)) ** 2, axis=0)
    return as_leverage(b, grid.n_chan)


def projection_bias(
    grid: Grid,
    basis,
    residual: NDArray[np.float64],
    basis_leverage: NDArray[np.float64],
    *,
    n_sim: int = 8,
    iterations: int = 2,
    seed: int = 0,
) -> NDArray[np.float64]:
    """Actual over white-noise suppression of the residual periodogram, per frequency.

    :func:`estimate_psd` assumes that removing the design removes the share
    ``Σ_j |Q_j(f)|²/n`` of the power at ``f`` (exact for noise white within a bin).
    Under strongly coloured noise and a rich design (the per-period demodulation
    base removes most of the 1/f power below ~1/τ, and rotation gaps mix
    frequencies) the residual holds much less (a third at 1/τ on a MicroSTAR day),
    the PSD estimate is low there and the tests of regressors living there are
    anti-conservative.  This measures the factor with a small parametric bootstrap:
    ``n_sim`` circulant Gaussian series with the estimated PSD are projected on the
    design; per PSD bin, ``β = Σ simulated periodogram / Σ PSD × white share``.
    Bins where ``β`` is not significantly different from 1 (3 Monte-Carlo σ) keep
    1; the estimate and the simulation are iterated ``iterations`` times.  The
    random draws use a fixed seed (results are reproducible).

    Parameters
    ----------
    grid : Grid
    basis : Basis
        Orthonormal basis of the design (``project``).
    residual : ndarray, shape (n,)
        Residual of the design's fit [m/s²].
    basis_leverage : ndarray, shape (C, nf)
        White-noise leverage spectrum of the design.
    n_sim, iterations, seed : int
        Monte-Carlo settings.

    Returns
    -------
    ndarray, shape (C, nf)
        The factor ``β`` per channel and frequency (multiply the white share
        ``1 − leverage/n`` by it).
    """
    rng = np.random.default_rng(seed)
    nc = np.maximum(grid.counts, 1.0)[:, None]
    supp_w = np.clip(1.0 - basis_leverage / nc, 0.0, 1.0)
    beta = np.ones_like(supp_w)
    nn = grid.size
    nf = nn // 2 + 1
    for _ in range(iterations):
        lev = nc - (nc - basis_leverage) * beta
        noise = estimate_psd(grid, residual, lev)
        spsd = np.maximum(noise.psd, 0.0)
        es = []
        for _ in range(n_sim):  # the draws in the order of one series at a time
            z = rng.standard_normal((grid.n_chan, nf)) + 1j * rng.standard_normal((grid.n_chan, nf))
            z /= np.sqrt(2.0)
            z[:, 0] = z[:, 0].real * np.sqrt(2.0)
            if nn % 2 == 0:
                z[:, -1] = z[:, -1].real * np.sqrt(2.0)
            es.append(np.fft.irfft(z * np.sqrt(spsd * nn), nn, axis=-1)[grid.channel, grid.idx])
        e = np.column_stack(es)  # (n, n_sim): one projection for all of them
        r = e - basis.project(e)
        num = np.sum(np.abs(grid.fft(r)) ** 2, axis=0) / nc
        nb = noise.level.size
        den = spsd * supp_w * n_sim
        wsum = np.bincount(noise.which[1:], weights=num[:, 1:].sum(axis=0), minlength=nb)
        dsum = np.bincount(noise.which[1:], weights=den[:, 1:].sum(axis=0), minlength=nb)
        b_bin = wsum / np.maximum(dsum, 1e-300)
        # Monte-Carlo σ of the ratio: ~1/√(ordinates·channels·n_sim)
        m = np.bincount(noise.which[1:], minlength=nb) * grid.n_chan * n_sim
        sd = b_bin / np.sqrt(np.maximum(m, 1))
        b_bin = np.where(np.abs(b_bin - 1.0) > 3.0 * sd, np.clip(b_bin, 0.05, 1.0 / 0.05), 1.0)
        b_bin[dsum <= 0] = 1.0
        new = np.broadcast_to(b_bin[noise.which], supp_w.shape).copy()
        new[:, 0] = 1.0
        beta = new
    return beta
