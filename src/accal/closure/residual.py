"""Residual characterisation and the coloured-noise significance test.

Two jobs, both pure functions over arrays:

* :func:`characterise`: what is left in a residual (gap-tolerant Welch PSD on the
  continuous segments, per-segment means, low-frequency share, kurtosis);
* :func:`wald_test`: is a block of extra regressors significant *under the
  residual's own coloured noise*?

Why a sandwich Wald test and not AR prewhitening
------------------------------------------------
Accelerometer noise rises as 1/f below ~1 mHz, and the effects we look for (drifts,
steps, slow couplings) live at 1e-5–1e-4 Hz.  A low-order AR model fitted at 1 Hz
is dominated by the white part and cannot represent that rise; prewhitening with
it leaves red noise in the "whitened" data and an F-test then reports steps and
quadratics in clean data.  Instead we estimate the PSD ``S(f)`` of the residual on
the nominal grid, resolved down to ``min_bin/T`` (the estimator already validated
for :func:`accal.estimators.trend.linear_estimator_covariance`), and evaluate the
covariance of the extra coefficients exactly as the quadratic form
``Σ = G C Gᵀ = (1/N) Σ_f G(f) S(f) G(f)*`` (a sandwich covariance, no N×N matrix).
The statistic ``W = γᵀ Σ⁻¹ γ / q`` is referred to ``F(q, ν)``, where ``ν`` is the
Satterthwaite number of degrees of freedom of ``Σ``: each PSD bin ``b`` is an
average of ``m_b`` periodogram ordinates (``2 m_b`` degrees of freedom) and
contributes ``c_b`` to ``tr(Σ⁻¹ Σ)``, so ``ν = q² / Σ_b c_b² / (2 m_b)``.  This is
what makes the test honest for the slowest regressors, whose variance rests on a
handful of periodogram ordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from accal.closure.distributions import chi2_sf, excess_kurtosis, f_sf

__all__ = [
    "Grid",
    "NoisePSD",
    "ResidualStats",
    "WaldResult",
    "characterise",
    "estimate_psd",
    "make_grid",
    "projection_bias",
    "wald_test",
    "white_plus_flicker",
]


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


def make_grid(t: NDArray[np.float64], chan: NDArray[np.int64] | None = None) -> Grid:
    """Nominal-grid indices of sample times ``t`` [s], increasing within each channel.

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
        return Grid(idx, int(idx[-1]) + 1, step)
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
    return Grid(idx, int(idx.max()) + 1, step, chan, n_chan)


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


def _two_sided(size: int, nf: int) -> NDArray[np.float64]:
    w = np.full(nf, 2.0)
    w[0] = 1.0
    if size % 2 == 0:
        w[-1] = 1.0
    return w


def _as_leverage(basis: NDArray, n_chan: int) -> NDArray[np.float64]:
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
    lev = _as_leverage(basis_leverage, grid.n_chan)
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
    from scipy.optimize import nnls

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


@dataclass(frozen=True)
class WaldResult:
    """Outcome of :func:`wald_test`.

    Attributes
    ----------
    gamma : ndarray, shape (q,)
        Coefficients of the orthonormalised extra regressors.
    cov : ndarray, shape (q, q)
        Their sandwich covariance.
    stat : float
        ``W/q`` (F-distributed under the null).
    dof : float
        Satterthwaite denominator degrees of freedom.
    pvalue : float
        ``P(F(q, dof) > stat)`` (not corrected for multiplicity).
    residual : ndarray, shape (n,)
        Residual of the augmented model.
    psd : ndarray, shape (nf,) or None
        The one-sided-grid PSD the covariance used (None when none was formed): a
        later test of the same columns can hold it (:func:`accal.closure.validation.
        signal_proxy_test`).
    """

    gamma: NDArray[np.float64]
    cov: NDArray[np.float64]
    stat: float
    dof: float
    pvalue: float
    residual: NDArray[np.float64]
    psd: NDArray[np.float64] | None = None

    @property
    def q(self) -> int:
        return int(self.gamma.size)


def orthonormal_complement(z: NDArray[np.float64], qx, tol: float = 1e-8) -> NDArray[np.float64]:
    """Orthonormal basis of the part of the columns ``z`` orthogonal to ``qx``.

    ``qx`` is a dense orthonormal basis (n, p) or a :class:`~accal.closure.basis.Basis`.
    Columns that are (numerically) in the span of ``qx`` or of each other are dropped.
    """
    if hasattr(qx, "complement"):
        return qx.complement(z, tol)
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == 1:
        z = z[:, None]
    zt = z - qx @ (qx.T @ z)
    norms0 = np.linalg.norm(z, axis=0)
    if not np.any(norms0 > 0):
        return np.zeros((z.shape[0], 0))
    u, s, _ = np.linalg.svd(zt, full_matrices=False)
    keep = s > tol * max(float(norms0.max()), 1e-300)
    return u[:, keep]


def _quad(fa: NDArray[np.complex128], wt: NDArray[np.float64], size: int, fb=None):
    """``Σ_{c,f} A_i(f) w(f) B_j(f)* / N`` for spectra (k, C, nf) -> (ka, kb), real."""
    fb = fa if fb is None else fb
    a = fa.reshape(fa.shape[0], -1)
    b = fb.reshape(fb.shape[0], -1)
    w = np.broadcast_to(wt, fa.shape[1:]).reshape(-1)
    # Re(a w b^H) with real products (contiguous, BLAS)
    aw_r = np.ascontiguousarray(a.real * w)
    aw_i = np.ascontiguousarray(a.imag * w)
    return (aw_r @ np.ascontiguousarray(b.real).T + aw_i @ np.ascontiguousarray(b.imag).T) / size


def wald_test(
    grid: Grid,
    residual: NDArray[np.float64],
    zt: NDArray[np.float64],
    basis_leverage: NDArray,
    *,
    min_bin: int = 3,
    psd: NDArray[np.float64] | None = None,
    psd_dof: float = np.inf,
) -> WaldResult:
    """Sandwich Wald/F test of extra regressors ``zt`` against coloured noise.

    Parameters
    ----------
    grid : Grid
        Sample placement.
    residual : ndarray, shape (n,)
        Residual of the current model (orthogonal to its design).
    zt : ndarray, shape (n, q)
        Orthonormal extra regressors, orthogonal to the current design
        (:func:`orthonormal_complement`).
    basis_leverage : ndarray, shape (C, nf)
        Leverage spectrum of the current design (see :func:`estimate_psd`).
    min_bin : int
        Lowest PSD bin width, in DFT ordinates.
    psd : ndarray, shape (nf,), optional
        A given (model) two-sided PSD instead of the estimate; the statistic is
        then referred to F(q, ``psd_dof``) (χ²_q when ``psd_dof`` is infinite).
    psd_dof : float
        Equivalent degrees of freedom of a given ``psd`` (its estimation uncertainty).

    Returns
    -------
    WaldResult
        The PSD is estimated from the residual of the *augmented* model, so a real
        effect does not inflate its own uncertainty.
    """

    q = zt.shape[1]
    if q == 0:
        return WaldResult(np.zeros(0), np.zeros((0, 0)), 0.0, np.inf, 1.0, residual)
    gamma = zt.T @ residual  # OLS coefficients of orthonormal columns: weights G = ztᵀ
    r1 = residual - zt @ gamma
    z_fft = grid.fft(zt)  # (q, C, nf)
    lev = _as_leverage(basis_leverage, grid.n_chan) + np.sum(np.abs(z_fft) ** 2, axis=0)
    noise = estimate_psd(grid, r1, lev, min_bin=min_bin)
    nf = z_fft.shape[-1]
    used = noise.psd if psd is None else np.asarray(psd, dtype=np.float64)
    w = _two_sided(grid.size, nf) * used
    cov = _quad(z_fft, w, grid.size)
    cov = 0.5 * (cov + cov.T)
    try:
        cinv = np.linalg.pinv(cov, rcond=1e-12)
    except np.linalg.LinAlgError:
        return WaldResult(gamma, cov, 0.0, np.inf, 1.0, r1, used)
    stat = float(gamma @ cinv @ gamma) / q
    if psd is not None:
        if np.isfinite(psd_dof):
            return WaldResult(gamma, cov, stat, psd_dof, float(f_sf(stat, q, psd_dof)), r1, used)
        return WaldResult(gamma, cov, stat, np.inf, float(chi2_sf(stat * q, q)), r1, used)
    # Satterthwaite: contribution of each PSD bin to tr(Σ⁻¹Σ) = q
    zf = z_fft.reshape(q, -1)
    zr, zi = zf.real, zf.imag
    h = np.sum(zr * (cinv @ zr) + zi * (cinv @ zi), axis=0).reshape(grid.n_chan, nf).sum(axis=0)
    h = h * w / grid.size
    c = np.bincount(noise.which, weights=h, minlength=noise.level.size)
    m = noise.counts.astype(float)
    denom = float(np.sum(c**2 / (2.0 * m)))
    dof = float(max(q**2 / denom, 2.0)) if denom > 0 else np.inf
    pvalue = float(f_sf(stat, q, dof)) if np.isfinite(dof) else float(chi2_sf(stat * q, q))
    return WaldResult(gamma, cov, stat, dof, pvalue, r1, used)


def sandwich_cov(
    grid: Grid,
    residual: NDArray[np.float64],
    weights: NDArray[np.float64],
    basis_leverage,
    *,
    min_bin: int = 3,
) -> NDArray[np.float64]:
    """Covariance ``G C Gᵀ`` of dense linear estimators ``weights @ y`` (shape (p, n)).

    ``basis_leverage`` is the leverage spectrum of the fitted design (for the
    projection correction of the PSD estimate); a dense orthonormal basis (n, p)
    or a :class:`~accal.closure.basis.Basis` is accepted too.  Block-local
    estimators use :meth:`accal.closure.basis.Basis.block_cov` instead.
    """
    noise = estimate_psd(grid, residual, leverage_of(grid, basis_leverage), min_bin=min_bin)
    g_fft = grid.fft(np.atleast_2d(weights).T)
    w = _two_sided(grid.size, g_fft.shape[-1]) * noise.psd
    cov = _quad(g_fft, w, grid.size)
    return 0.5 * (cov + cov.T)


def leverage_of(grid: Grid, basis) -> NDArray[np.float64]:
    """Leverage spectrum (C, nf) of a basis object, a dense orthonormal basis, or itself."""
    if hasattr(basis, "leverage"):
        return basis.leverage(grid)
    b = np.asarray(basis)
    if not np.iscomplexobj(b) and b.ndim == 2 and b.shape[0] == grid.idx.size:
        return np.sum(np.abs(grid.fft(b)) ** 2, axis=0)
    return _as_leverage(b, grid.n_chan)


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
        num = np.zeros((grid.n_chan, nf))
        for _ in range(n_sim):
            z = rng.standard_normal((grid.n_chan, nf)) + 1j * rng.standard_normal((grid.n_chan, nf))
            z /= np.sqrt(2.0)
            z[:, 0] = z[:, 0].real * np.sqrt(2.0)
            if nn % 2 == 0:
                z[:, -1] = z[:, -1].real * np.sqrt(2.0)
            e = np.fft.irfft(z * np.sqrt(spsd * nn), nn, axis=-1)[grid.channel, grid.idx]
            r = e - basis.project(e)
            num += np.abs(grid.fft(r)[0]) ** 2 / nc
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


def white_plus_flicker(
    grid: Grid,
    noise: NoisePSD,
    f_lo: float,
    band: float | None = None,
    *,
    return_dof: bool = False,
) -> tuple:
    """Fit ``S(f) = a + b/f`` to the binned PSD above ``f_lo`` and extrapolate it.

    The accelerometer noise model (white plus 1/f below the corner, as in
    :func:`accal.simulate.grace.coloured_noise` and eq. 1 of Lenoir et al. 2013
    without its f⁴ rise), fitted by iteratively reweighted non-negative least
    squares in relative error (weights ``√counts/model``: weights from the noisy
    levels would bias the fit low) to the bins whose frequencies all lie in
    ``[f_lo, f_hi]``.  With ``band`` given, ``f_hi = band·f_lo``; by default
    ``f_hi`` starts at ``30·f_lo`` and doubles while the added bins agree with the
    fit (mean of ``((level/model − 1)·√counts)²`` below 4): a rise or roll-off at
    high frequency (MicroSTAR's f⁴ term, an anti-alias filter) then cannot set the
    fit, while a long white + 1/f band makes it precise.  Used by the final
    ``unexplained`` test: slow structure is power in excess of this extrapolation.
    Returns ``(psd on every DFT frequency, (a, b))``, and with ``return_dof`` also
    the equivalent χ² degrees of freedom ``2/v`` of the extrapolation below
    ``f_lo`` (``v``: its largest relative variance there, from the fit's covariance),
    for :func:`wald_test`'s ``psd_dof``.
    """
    from scipy.optimize import nnls

    f = grid.freqs
    lvl = noise.binned
    nb = lvl.size
    lo = np.full(nb, np.inf)
    np.minimum.at(lo, noise.which[1:], f[1:])
    hi = np.zeros(nb)
    np.maximum.at(hi, noise.which[1:], f[1:])
    fc = np.bincount(noise.which[1:], weights=f[1:], minlength=nb) / np.maximum(
        np.bincount(noise.which[1:], minlength=nb), 1
    )
    ok = (lo >= f_lo) & (lvl > 0)

    def fit(f_hi: float):
        sel = ok & (hi <= f_hi)
        if sel.sum() < 3:
            return None
        x = np.column_stack([np.ones(sel.sum()), 1.0 / fc[sel]])
        sc = x.max(axis=0)
        ref = lvl[sel]
        for _ in range(4):  # weights from the model, not the noisy levels (IRLS)
            wgt = np.sqrt(noise.counts[sel]) / np.maximum(ref, 1e-300)
            coef, _ = nnls(x / sc * wgt[:, None], lvl[sel] * wgt)
            coef = coef / sc
            ref = np.maximum(x @ coef, 1e-3 * lvl[sel])
        # covariance of (a, b): unit-variance weighted residuals (a bin level has
        # relative variance 1/counts)
        aw = x * (np.sqrt(noise.counts[sel]) / ref)[:, None]
        try:
            cov = np.linalg.inv(aw.T @ aw)
        except np.linalg.LinAlgError:
            cov = np.full((2, 2), np.nan)
        return float(coef[0]), float(coef[1]), cov

    f_top = float(f[-1])
    if band is not None:
        ab = fit(band * f_lo)
    else:
        f_hi = 30.0 * f_lo
        ab = fit(f_hi)
        while ab is not None and f_hi < f_top:
            nxt = fit(2.0 * f_hi)
            new = ok & (hi > f_hi) & (hi <= 2.0 * f_hi)
            if nxt is None or not new.any():
                f_hi *= 2.0
                continue
            model_new = nxt[0] + nxt[1] / fc[new]
            z = (lvl[new] / np.maximum(model_new, 1e-300) - 1.0) * np.sqrt(noise.counts[new])
            if float(np.mean(z**2)) > 4.0:
                break
            ab, f_hi = nxt, 2.0 * f_hi
    if ab is None:
        return (noise.psd, (float("nan"), float("nan"))) + ((np.inf,) if return_dof else ())
    a, b, cov = ab
    model = np.empty_like(f)
    model[1:] = a + b / f[1:]
    model[0] = model[1]
    if not return_dof:
        return model, (a, b)
    # relative variance of the extrapolation below f_lo -> equivalent χ² dof 2/v
    fl = f[1:][f[1:] < f_lo]
    if fl.size == 0 or not np.all(np.isfinite(cov)):
        return model, (a, b), np.inf
    g = np.column_stack([np.ones(fl.size), 1.0 / fl])
    var = np.einsum("fi,ij,fj->f", g, cov, g)
    v = float(np.max(var / np.maximum(a + b / fl, 1e-300) ** 2))
    return model, (a, b), (2.0 / v if v > 0 else np.inf)


# --------------------------------------------------------------------------------------
# characterisation
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ResidualStats:
    """What is left in a residual.

    Attributes
    ----------
    rms : float
        Root mean square [m/s²].
    kurtosis : float
        Excess kurtosis (0 for Gaussian; large values mean outliers/steps).
    freq : ndarray
        Frequencies of the Welch PSD [Hz].
    psd : ndarray
        One-sided Welch PSD averaged over continuous segments [(m/s²)²/Hz]; when
        no gap-free segment reaches ``nperseg``, Welch with the longest power-of-two
        window that fits one (≥ 256 samples), else the binned periodogram of the
        gapped residual on its nominal grid (first entry: frequency 0, PSD 0).
    segment_edges : ndarray
        Start times of the segments used for ``segment_means`` [s].
    segment_means : ndarray
        Mean residual per segment (per orbit when the orbit period is known) [m/s²].
    lowfreq_fraction : float
        Share of the residual variance below 1/(segment length) (slow structure).
    """

    rms: float
    kurtosis: float
    freq: NDArray[np.float64]
    psd: NDArray[np.float64]
    segment_edges: NDArray[np.float64]
    segment_means: NDArray[np.float64]
    lowfreq_fraction: float


def continuous_segments(t: NDArray[np.float64], step: float) -> list[slice]:
    """Slices of runs of samples without a gap (> 1.5 nominal steps)."""
    if t.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(t) > 1.5 * step) + 1
    starts = np.r_[0, breaks]
    stops = np.r_[breaks, t.size]
    return [slice(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def welch_segments(
    t: NDArray[np.float64], r: NDArray[np.float64], nperseg: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Welch PSD averaged over the continuous segments of at least ``nperseg`` samples.

    Returns ``(freq [Hz], psd [(m/s²)²/Hz])``, weighted by each segment's number of
    Welch windows; empty arrays when no segment is long enough.
    """
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    acc = None
    total = 0.0
    freq = np.zeros(0)
    for sl in continuous_segments(t, step):
        seg = r[sl]
        if seg.size < nperseg:
            continue
        # imported here: scipy.signal costs ~0.6 s, and a platform run's residual
        # (rests every period) has no segment long enough for Welch
        from scipy.signal import welch

        freq, p = welch(seg, fs=1.0 / step, nperseg=nperseg, detrend="constant")
        nwin = 1 + (seg.size - nperseg) // (nperseg // 2)
        acc = p * nwin if acc is None else acc + p * nwin
        total += nwin
    if acc is None:
        return np.zeros(0), np.zeros(0)
    return freq, acc / total


def characterise(
    t: NDArray[np.float64],
    r: NDArray[np.float64],
    *,
    segment: float | None = None,
    nperseg: int | None = None,
    chan: NDArray[np.int64] | None = None,
) -> ResidualStats:
    """Characterise a residual (used samples only).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times of the used samples [s].
    r : ndarray, shape (n,)
        Residual [m/s²].
    segment : float, optional
        Length of the segments for the segment means [s], e.g. the orbit period;
        default span/16.
    nperseg : int, optional
        Welch window length [samples]; default the largest power of two ≤ span/8
        (at least 64).
    chan : ndarray of int, shape (n,), optional
        Channel of each sample: the Welch PSD is averaged over the channels;
        segment means, RMS and kurtosis pool them.
    """

    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    span = float(t[-1] - t[0]) if t.size > 1 else 1.0
    t1 = t if chan is None else t[np.asarray(chan) == chan[0]]
    step = float(np.median(np.diff(t1))) if t1.size > 1 else 1.0
    if segment is None or not segment > 0:
        segment = span / 16.0
    if nperseg is None:
        nperseg = int(2 ** np.floor(np.log2(max(span / step / 8.0, 64))))
    if chan is None or int(np.max(chan, initial=0)) == 0:
        freq, psd = welch_segments(t, r, nperseg)
    else:
        freq, psd, tot = np.zeros(0), np.zeros(0), 0
        for c in np.unique(chan):
            m = chan == c
            f_c, p_c = welch_segments(t[m], r[m], nperseg)
            if f_c.size:
                freq = f_c
                psd = p_c if tot == 0 else psd + p_c
                tot += 1
        if tot:
            psd = psd / tot
    if freq.size == 0 and t.size > 16 and (chan is None or int(np.max(chan, initial=0)) == 0):
        # no gap-free stretch of span/8: Welch with the longest window that fits
        segs = continuous_segments(t, step)
        longest = max((sl.stop - sl.start for sl in segs), default=0)
        if longest >= 256:
            freq, psd = welch_segments(t, r, int(2 ** np.floor(np.log2(longest))))
    if freq.size == 0 and t.size > 16:
        # no gap-free stretch long enough for Welch (e.g. the rests of a rotating
        # platform): the gap-tolerant binned periodogram on the nominal grid
        grid = make_grid(t, None if chan is None else np.asarray(chan, dtype=np.int64))
        noise = estimate_psd(grid, r, np.zeros((grid.n_chan, grid.size // 2 + 1)), tilt=False)
        f = grid.freqs
        nb = noise.level.size
        cnt = np.bincount(noise.which[1:], minlength=nb)
        fc = np.bincount(noise.which[1:], weights=f[1:], minlength=nb) / np.maximum(cnt, 1)
        keep = cnt > 0
        freq = np.r_[0.0, fc[keep]]
        psd = np.r_[0.0, 2.0 * noise.level[keep] * grid.step]  # one-sided [(m/s²)²/Hz]
    edges = np.arange(t[0], t[-1] + segment, segment)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 1)
    counts = np.bincount(which, minlength=edges.size)
    sums = np.bincount(which, weights=r, minlength=edges.size)
    means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    var = float(np.mean(r**2)) if r.size else np.nan
    seg_var = float(np.nansum(counts * np.nan_to_num(means) ** 2) / max(r.size, 1))
    return ResidualStats(
        rms=float(np.sqrt(var)),
        kurtosis=excess_kurtosis(r) if r.size > 3 else np.nan,
        freq=freq,
        psd=psd,
        segment_edges=edges,
        segment_means=means,
        lowfreq_fraction=seg_var / var if var > 0 else 0.0,
    )
