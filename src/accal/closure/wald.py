"""The coloured-noise significance test of extra regressors (sandwich Wald test).

:func:`wald_test`: is a block of extra regressors significant *under the
residual's own coloured noise*?  :func:`sandwich_cov` is the same covariance for
dense linear estimators; :func:`white_plus_flicker` extrapolates a white + 1/f
noise model below a frequency, for a test against a model PSD.

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
from scipy.optimize import nnls

from accal.closure.distributions import chi2_sf, f_sf
from accal.closure.noise_psd import (
    Grid,
    NoisePSD,
    as_leverage,
    estimate_psd,
    leverage_of,
    two_sided_weights,
)


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


def quad_form(fa: NDArray[np.complex128], wt: NDArray[np.float64], size: int, fb=None):
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
    lev = as_leverage(basis_leverage, grid.n_chan) + np.sum(np.abs(z_fft) ** 2, axis=0)
    noise = estimate_psd(grid, r1, lev, min_bin=min_bin)
    nf = z_fft.shape[-1]
    used = noise.psd if psd is None else np.asarray(psd, dtype=np.float64)
    w = two_sided_weights(grid.size, nf) * used
    cov = quad_form(z_fft, w, grid.size)
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
    w = two_sided_weights(grid.size, g_fft.shape[-1]) * noise.psd
    cov = quad_form(g_fft, w, grid.size)
    return 0.5 * (cov + cov.T)


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
