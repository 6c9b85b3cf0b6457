"""Calibration against a reference acceleration: bias on a temporal basis and scales.

The observation model is the one of GROOPS's
``InstrumentAccelerometerEstimateBiasScale`` and of the CSR/JPL/TU Delft
calibrations of GRACE against POD-derived or modelled non-gravitational
accelerations, in accal's TN-02 sign convention (:mod:`accal.calibration`)::

    a_ref(t) = S · (a_raw(t) − b(t)) + e(t)                                   (1)

with ``S`` a diagonal (``scale="fit"``) or full 3×3 (``"fit-matrix"``) scale
matrix, or fixed (``"fixed"``: the a-priori diagonal), and ``b(t)`` on a temporal
basis (:mod:`accal.estimators.refbasis`).  The reference is the observation: its
error ``e`` (a POD-derived reference is noisy at high frequency) then does not
enter the regressors, so the scales are not attenuated (errors in variables,
e.g. Fuller, *Measurement Error Models*, 1987, §1.1).  Writing ``d = −S b``
makes (1) linear, row by row::

    a_ref,i = Σ_j S_ij a_raw,j + Σ_k d_ik φ_k(t) + e_i                        (2)

Each row is a separate least-squares problem, weighted by an AR model of its own
residual (exact prewhitening, :mod:`accal.estimators.arnoise`), iterated: OLS,
then the AR model of the residual, then GLS, then the AR model again (the
iteration GROOPS makes with variance-component estimation of the noise PSD).
``B = −S⁻¹ D`` and its covariance follow by the exact Jacobian of that
reparametrisation (the Gauss–Newton covariance of (1) at the optimum).

A scale that is not identifiable (the reference barely varies over the arc, so
scale and bias cannot be told apart: see ``max_scale_sigma``) is not returned:
it is fixed at its a-priori value and the axis is refitted, with a note saying so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, stats

from accal.errors import ValidationError, check_option
from accal.estimators.arnoise import ArModel, levinson, segment_positions
from accal.estimators.refbasis import BiasBasis
from accal.estimators.trend import linear_estimator_covariance

__all__ = ["SCALE_MODES", "ReferenceFit", "fit_reference"]

SCALE_MODES = ("fixed", "fit", "fit-matrix")


@dataclass(frozen=True)
class ReferenceFit:
    """Result of :func:`fit_reference` (all three axes of an arc).

    Attributes
    ----------
    basis : BiasBasis
    scale : ndarray, shape (3, 3)
        ``S`` of eq. (1) [1]; fixed entries hold their a-priori value.
    scale_cov : ndarray, shape (9, 9)
        Covariance of ``scale.ravel()`` (zero rows for fixed entries).
    bias_coef : ndarray, shape (3, K)
        ``b_i(t) = Σ_k bias_coef[i, k] φ_k(t)`` [m/s²].
    bias_cov : ndarray, shape (3K, 3K)
        Covariance of ``bias_coef.ravel()``, scale uncertainty included.
    modes : tuple of str
        Scale model used per axis (``fit-matrix``, ``fit`` or ``fixed``).
    notes : tuple of str
        What was decided and why (identifiability, fall-backs).
    noise : tuple of ArModel
        Whitening model per axis (of the reference residual).
    sigma0 : ndarray, shape (3,)
        √(whitened RSS / dof) per axis (≈ 1 when the AR model fits).
    rms : ndarray, shape (3,)
        RMS of the residual ``a_ref − S(a_raw − b)`` over the used samples [m/s²].
    n_used : int
    crosstalk_test : dict
        χ² test of the full matrix against the diagonal one: ``chi2``, ``dof``, ``p``.
    unsupported : ndarray of bool, shape (K,)
        Basis coefficients without data under them (NaN in ``bias_coef``).
    cov : ndarray, shape (9 + 3K, 9 + 3K)
        Full covariance of ``(scale.ravel(), bias_coef.ravel())`` (the two blocks
        above are its diagonal blocks; the scale–bias correlation is off-diagonal).
    used : ndarray of bool, shape (n,)
        The samples the fit used (``valid`` less non-finite values and the samples
        next to a gap that only unsupported coefficients could describe).
    """

    basis: BiasBasis
    scale: NDArray[np.float64]
    scale_cov: NDArray[np.float64]
    bias_coef: NDArray[np.float64]
    bias_cov: NDArray[np.float64]
    modes: tuple[str, ...]
    notes: tuple[str, ...]
    noise: tuple[ArModel, ...]
    sigma0: NDArray[np.float64]
    rms: NDArray[np.float64]
    n_used: int
    crosstalk_test: dict = field(default_factory=dict)
    unsupported: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    used: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    cov: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def scale_sigma(self) -> NDArray[np.float64]:
        """1σ of each entry of ``scale`` (0 for fixed entries), shape (3, 3)."""
        return np.sqrt(np.clip(np.diag(self.scale_cov), 0, None)).reshape(3, 3)

    def bias(self, t: NDArray[np.float64], deriv: int = 0) -> tuple[NDArray, NDArray]:
        """Bias (or its rate, ``deriv=1``) at times ``t`` and its 1σ, each shape (n, 3).

        Units m/s² (m/s³ for the rate); σ includes the scales' uncertainty.
        """
        t = np.asarray(t, dtype=np.float64)
        k = self.basis.size
        val = np.empty((t.size, 3))
        sig = np.empty((t.size, 3))
        cols, first = self.basis.design(t, deriv)
        sl = slice(first, first + cols.shape[1])
        coef = np.nan_to_num(self.bias_coef[:, sl])  # unsupported: NaN, masked below
        for i in range(3):
            val[:, i] = cols @ coef[i]
            c = self.bias_cov[i * k : (i + 1) * k, i * k : (i + 1) * k][sl, sl]
            sig[:, i] = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", cols, c, cols), 0, None))
        if self.unsupported.any():
            # no estimate where a coefficient without data acts
            basis_vals, f0 = self.basis.design(t)
            bad = self.unsupported[f0 : f0 + basis_vals.shape[1]]
            hole = (basis_vals[:, bad] > 0).any(1) if bad.any() else np.zeros(t.size, bool)
            val[hole] = np.nan
            sig[hole] = np.nan
        return val, sig

    def calibrate(self, t: NDArray[np.float64], raw: NDArray[np.float64]) -> NDArray[np.float64]:
        """``a_cal = S · (a_raw − b(t))`` (eq. 1), shape (n, 3) [m/s²]."""
        b, _ = self.bias(t)
        return (np.asarray(raw, dtype=np.float64) - b) @ self.scale.T


def _chunks(n: int, breaks: NDArray[np.bool_], size: int) -> list[tuple[int, int]]:
    """Index ranges of at most ``size`` samples, split at ``breaks`` where possible."""
    starts = [0]
    cand = np.flatnonzero(breaks)
    while starts[-1] + size < n:
        s = starts[-1]
        inside = cand[(cand > s) & (cand <= s + size)]
        starts.append(int(inside[-1]) if inside.size else s + size)
    return list(zip(starts, starts[1:] + [n], strict=True))


class _Axis:
    """Normal equations of one row of eq. (2), accumulated chunk by chunk."""

    def __init__(self, raw, y, pos, basis, chunks, cols):
        self.raw, self.y, self.pos = raw, y, pos
        self.basis, self.chunks = basis, chunks
        self.k = basis.size
        self._cols = cols  # basis.design of each chunk (shared by the three axes)

    def normal(self, ar: ArModel, keep: bool = False) -> NDArray[np.float64]:
        """``[X y]ᵀ W [X y]`` with X = [a_raw (3 columns), φ (K columns)].

        ``keep``: also keep the whitened blocks for :meth:`refine_step` (memory:
        n × (4 + local columns) floats).
        """
        m = 3 + self.k
        out = np.zeros((m + 1, m + 1))
        self._white = []
        for (a, b), (cols, first) in zip(self.chunks, self._cols, strict=True):
            block = np.column_stack([self.raw[a:b], cols, self.y[a:b]])
            w = ar.whiten(block, self.pos[a:b])
            idx = np.r_[0:3, 3 + first : 3 + first + cols.shape[1], m]
            out[np.ix_(idx, idx)] += w.T @ w
            if keep:
                self._white.append(w)
        return out

    def residual(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Residual ``y − Xθ`` (not whitened), sample by sample."""
        r = np.empty(self.y.size)
        for (a, b), (cols, first) in zip(self.chunks, self._cols, strict=True):
            sl = slice(3 + first, 3 + first + cols.shape[1])
            r[a:b] = self.y[a:b] - self.raw[a:b] @ theta[:3] - cols @ theta[sl]
        return r

    def refine_step(self, theta: NDArray[np.float64]) -> tuple[float, NDArray]:
        """Whitened RSS and ``XᵀW r`` at ``theta``, from the blocks kept by :meth:`normal`.

        ``W r = W y − (W X) θ`` is formed sample by sample, so the gradient has no
        cancellation of normal-equation sums (iterative refinement, Björck,
        *Numerical Methods for Least Squares Problems*, 1996, §2.9).
        """
        grad = np.zeros(3 + self.k)
        rss = 0.0
        for w, (cols, first) in zip(self._white, self._cols, strict=True):
            sl = slice(3 + first, 3 + first + cols.shape[1])
            th = np.concatenate([theta[:3], theta[sl]])
            wr = w[:, -1] - w[:, :-1] @ th
            rss += float(wr @ wr)
            g = w[:, :-1].T @ wr
            grad[:3] += g[:3]
            grad[sl] += g[3:]
        return rss, grad


def _solve(
    mat: NDArray, free: NDArray[np.bool_], fixed_theta: NDArray, eiv: NDArray | None = None
) -> tuple[NDArray, NDArray]:
    """Solve the normal equations for the ``free`` parameters, the others held at ``fixed_theta``.

    ``eiv``: expected whitened noise power of the three raw columns, subtracted from
    their diagonal (errors in variables, :func:`_eiv_power`).  Returns θ (all
    parameters) and the inverse normal matrix of the free ones (equilibrated
    Cholesky; raises ValidationError if singular).
    """
    m = free.size
    n_mat = mat[:m, :m].copy()
    if eiv is not None:
        n_mat[np.arange(3), np.arange(3)] -= eiv
    rhs = mat[:m, m] - n_mat[:, ~free] @ fixed_theta[~free]
    nf = n_mat[np.ix_(free, free)]
    d = np.sqrt(np.diag(nf))
    if not np.all(d > 0):
        raise ValidationError(
            "reference fit: a parameter has no data (a basis function over a gap?)"
        )
    try:
        c = linalg.cho_factor(nf / np.outer(d, d))
    except linalg.LinAlgError:
        raise ValidationError("reference fit: the normal equations are singular") from None
    theta = fixed_theta.copy()
    theta[free] = linalg.cho_solve(c, rhs[free] / d) / d
    inv = linalg.cho_solve(c, np.eye(d.size)) / np.outer(d, d)
    return theta, inv


def _refine(ax: _Axis, theta, free, inv, eiv):
    """One step of iterative refinement; returns θ and the whitened RSS at it.

    The corrected normal equations (XᵀWX − Σ)θ = XᵀWy have the residual
    XᵀW(y − Xθ) + Σθ_scale, Σ = diag(``eiv``) on the raw columns.
    """
    _, grad = ax.refine_step(theta)
    grad[:3] += eiv * theta[:3]
    theta = theta.copy()
    theta[free] += inv @ grad[free]
    rss, _ = ax.refine_step(theta)
    return theta, rss


def _raw_noise(a: NDArray, pos: NDArray) -> NDArray:
    """Variance of white noise in each raw axis, from robust second differences.

    Δ²x_t = x_t − 2x_{t−1} + x_{t−2} within segments: var(Δ²n) = 6σ² for white n,
    while a signal smooth over seconds contributes nothing; σ from the MAD
    (1.4826·MAD, Huber 1981) so thruster spikes do not count.  Band-limited raw
    data (GRACE's CRN filter) give ~0: no errors-in-variables correction then.
    """
    ok = pos[2:] >= 2
    d2 = a[2:] - 2 * a[1:-1] + a[:-2]
    d2 = d2[ok]
    if d2.shape[0] < 10:
        return np.zeros(a.shape[1])
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return (1.4826 * mad) ** 2 / 6.0


def _eiv_power(ar: ArModel, pos: NDArray, var: float, axis: int) -> NDArray:
    """E‖W n_i‖² of white noise of variance ``var`` in raw column ``axis`` under ``ar``.

    Returned as the (3,) correction of the raw columns (zero but for ``axis``: a
    cross term's own errors-in-variables bias is its relative one times |S_ij| ≪ 1).

    Each whitened sample is Σ_k h_k n_{t−k} / √v with h = (1, −φ_m): its variance is
    σ²(1 + ‖φ_m‖²)/v_m, m = min(pos_t, p).  Subtracting the sum from the raw
    columns' normal-matrix diagonal is the corrected least squares of a regression
    with noisy regressors (Fuller, *Measurement Error Models*, 1987, §2.2): the
    whitening gives most weight where the residual is smallest, which for a smooth
    (modelled, or sparser and interpolated) reference is where the raw data hold
    noise and no signal, and there the plain estimate shrinks the scale.
    """
    p = ar.order
    m = np.minimum(pos, p)
    gain = np.array([(1.0 + ar.phi[k] @ ar.phi[k]) / ar.v[k] for k in range(p + 1)])
    out = np.zeros(3)
    out[axis] = var * float(np.bincount(m, minlength=p + 1) @ gain)
    return out


def _unidentifiable(cov, theta, free, axis, max_rel_sigma) -> str:
    """Why the scales of one row are not identifiable ("" if they are).

    A free scale S_ij whose σ relative to |S_ii| exceeds ``max_rel_sigma`` says
    nothing about the instrument (TN-02's scales differ from 1 by 2–5 %).  Such a σ
    comes from a reference that barely varies over the arc beyond what the bias
    basis takes up.  (A variance-inflation test is no use here: the raw column
    carries the bias itself, so it is always nearly collinear with the basis.)
    """
    n_scale = int(free[:3].sum())
    if n_scale == 0:
        return ""
    rel = np.sqrt(np.diag(cov)[:n_scale]) / max(abs(theta[axis]), 1e-300)
    if np.any(rel > max_rel_sigma):
        return (
            f"relative σ up to {rel.max():.3g} > {max_rel_sigma:g}: the reference varies "
            "too little over the arc to tell scale from bias"
        )
    return ""


#: Largest number of parameters of one row whose data-domain weights the sandwich
#: covariance evaluates one by one; beyond it the basis coefficients share one factor
#: from :data:`SANDWICH_SAMPLE` evenly spaced ones (memory: one weight vector of the
#: arc's length per parameter evaluated).
SANDWICH_MAX = 24
SANDWICH_SAMPLE = 6


def _honest_cov(
    ax: _Axis, inv: NDArray, s0: float, free: NDArray, ar: ArModel, t, r, basis
) -> tuple[NDArray, NDArray]:
    """Covariance of the free parameters of one row that holds for noise the AR model misses.

    The estimate is linear in the reference, θ = G y with G = A⁻¹X̃ᵀW; its covariance
    under the residual's own spectrum, ``G C Gᵀ``, is evaluated with the FFT method of
    :func:`accal.estimators.trend.linear_estimator_covariance` (the one the wavelet
    fit's σ use) on the weights ``Wᵀ X̃ A⁻¹ e_j`` (:meth:`ArModel.whiten_adjoint`).
    The result is the model's covariance ``σ0² A⁻¹`` plus the positive part of the
    difference (eigenvalues clipped at 0): where the residual holds a red component,
    a spectral line or an f⁴ rise the AR(p) cannot follow, the σ (and the
    scale–bias correlations that the bias' σ depend on) come from the data, not the
    model.  With more than :data:`SANDWICH_MAX` free parameters (arcs) the scales
    and :data:`SANDWICH_SAMPLE` evenly spaced basis coefficients are evaluated and
    the row's whole covariance is scaled by the median of their variance ratios
    (at least 1).

    Returns the covariance and the variance inflation of each parameter (≥ 1).
    """
    idx = np.flatnonzero(free)
    p = idx.size
    model = inv * s0**2
    n_scale = int(free[:3].sum())
    if p <= SANDWICH_MAX:
        sel = np.arange(p)
    else:
        rest = np.arange(n_scale, p)
        pick = np.linspace(0, rest.size - 1, SANDWICH_SAMPLE).round().astype(int)
        sel = np.r_[np.arange(n_scale), rest[pick]]
    weights = np.zeros((sel.size, ax.y.size))
    for s, j in enumerate(sel):
        c = np.zeros(3 + ax.k)
        c[idx] = inv[:, j]
        v = np.empty(ax.y.size)
        for (a, b), w, (cols, first) in zip(ax.chunks, ax._white, ax._cols, strict=True):
            sl = slice(3 + first, 3 + first + cols.shape[1])
            v[a:b] = w[:, :-1] @ np.concatenate([c[:3], c[sl]])
        for a, b in ax.chunks:
            weights[s, a:b] = ar.whiten_adjoint(v[a:b], ax.pos[a:b])
    order = basis.degree if basis.kind == "poly" else 1
    sw = linear_estimator_covariance(t, r, weights, order=min(order, 2))
    del weights
    if not np.all(np.isfinite(sw)):
        return model, np.ones(p)
    if p > SANDWICH_MAX:
        # one factor for the row: the model's correlations stay whole (the bias of an
        # arc is B = −S⁻¹D, whose σ rests on cancelling scale–bias correlations that
        # a partial correction breaks: tried, bias σ 10× too large in make mc-reference)
        ratio = np.diag(sw) / np.diag(model)[sel]
        f = max(1.0, float(np.median(ratio[np.isfinite(ratio)])))
        return model * f, np.full(p, f)
    sub = model[np.ix_(sel, sel)]
    vals, vecs = np.linalg.eigh(sw - sub)
    extra = (vecs * np.clip(vals, 0, None)) @ vecs.T
    out = model + extra
    return out, np.diag(out) / np.diag(model)


def fit_reference(
    time: NDArray[np.float64],
    raw: NDArray[np.float64],
    reference: NDArray[np.float64],
    valid: NDArray[np.bool_],
    basis: BiasBasis,
    *,
    scale: str = "fit",
    apriori: tuple[float, float, float] = (1.0, 1.0, 1.0),
    breaks: NDArray[np.bool_] | None = None,
    max_order: int = 20,
    iterations: int = 2,
    max_scale_sigma: float = 0.05,
    chunk: int = 86_400,
) -> ReferenceFit:
    """Fit eq. (1) to an arc by iterated AR-weighted least squares.

    Parameters
    ----------
    time : ndarray, shape (n,)
        GPS seconds, increasing.
    raw, reference : ndarray, shape (n, 3)
        Raw accelerometer data and reference acceleration in the SRF [m/s²].
    valid : ndarray of bool, shape (n,)
        Samples to use (flags, thruster firings and reference holes excluded).
    basis : BiasBasis
        Temporal basis of the bias over the arc.
    scale : {"fixed", "fit", "fit-matrix"}
        Scale model.
    apriori : tuple of 3 float
        Diagonal scales used where a scale is fixed [1].
    breaks : ndarray of bool, shape (n,), optional
        Samples that start a new noise segment (e.g. each day's first sample).
    max_order : int
        Largest AR order of the noise model.
    iterations : int
        GLS iterations after the first (ordinary) least squares.
    max_scale_sigma : float
        A scale whose σ relative to the row's diagonal scale is larger is not
        identifiable: the row falls back from ``fit-matrix`` to ``fit``, from
        ``fit`` to ``fixed`` at ``apriori``.
    chunk : int
        Samples per accumulation block (memory, not results).
    """
    check_option("scale", scale, SCALE_MODES)
    t_all = np.asarray(time, dtype=np.float64)
    use = np.asarray(valid, dtype=bool) & np.isfinite(raw).all(1) & np.isfinite(reference).all(1)
    t = t_all[use]
    n = t.size
    k = basis.size
    if n < 3 * (3 + k):
        raise ValidationError(
            f"reference fit: {n} usable samples for {3 + k} parameters per axis "
            f"(basis {basis.name()}, scale {scale})"
        )
    unsupported, use, hole_note = _support(t_all, use, basis, chunk)
    t = t_all[use]
    n = t.size
    brk = None if breaks is None else np.asarray(breaks, dtype=bool)[use]
    pos = segment_positions(t, brk)
    chunks = _chunks(n, pos == 0, chunk)
    designs = [basis.design(t[c0:c1]) for c0, c1 in chunks]
    a = np.asarray(raw, dtype=np.float64)[use]
    noise_var = _raw_noise(a, pos)
    y_all = np.asarray(reference, dtype=np.float64)[use]
    thetas, invs, frees, models, notes, rss_d, ars = [], [], [], [], [], [], []
    if hole_note:
        notes.append(hole_note)
    sigma0, rms = np.empty(3), np.empty(3)
    chi2_total, chi2_dof = 0.0, 0
    for i, name in enumerate("xyz"):
        ax = _Axis(a, y_all[:, i], pos, basis, chunks, designs)
        mode = scale
        while True:
            try:
                free, theta, inv, rss, r, mat, eiv, ar = _fit_mode(
                    ax, i, mode, unsupported, apriori, pos, noise_var, t, iterations, max_order
                )
            except ValidationError as exc:
                if mode == "fixed":
                    raise
                why = str(exc).removeprefix("reference fit: ")
            else:
                dof = n - int(free.sum())
                s0 = np.sqrt(rss / dof)
                cov, _ = _honest_cov(ax, inv, s0, free, ar, t, r, basis)
                why = _unidentifiable(cov, theta, free, i, max_scale_sigma)
                if mode == "fixed" or not why:
                    break
            fallback = "fit" if mode == "fit-matrix" else "fixed"
            notes.append(
                f"{name}: scale not identifiable in mode {mode} ({why}); refitted with {fallback}"
                + (f" at {apriori[i]:g}" if fallback == "fixed" else "")
            )
            mode = fallback
        # cross-talk test: the full row against the diagonal one (eq. 2)
        chi2 = _crosstalk_chi2(ax, i, mode, theta, cov, mat, eiv, s0, ar, t, basis, unsupported)
        if chi2 is not None:
            chi2_total += chi2
            chi2_dof += 2
        thetas.append(theta)
        invs.append(cov)
        frees.append(free)
        models.append(mode)
        ars.append(ar)
        rss_d.append(rss)
        sigma0[i] = s0
        rms[i] = float(np.sqrt(np.mean(r * r)))
    s_mat, b_coef, cov = _transform(thetas, invs, frees, apriori, k)
    s_cov, b_cov = cov[:9, :9], cov[9:, 9:]
    b_coef[:, unsupported] = np.nan
    test = {}
    if chi2_dof:
        test = {
            "chi2": chi2_total,
            "dof": chi2_dof,
            "p": float(stats.chi2.sf(chi2_total, chi2_dof)),
        }
    return ReferenceFit(
        basis=basis,
        scale=s_mat,
        scale_cov=s_cov,
        bias_coef=b_coef,
        bias_cov=b_cov,
        modes=tuple(models),
        notes=tuple(notes),
        noise=tuple(ars),
        sigma0=sigma0,
        rms=rms,
        n_used=n,
        crosstalk_test=test,
        unsupported=unsupported,
        used=use,
        cov=cov,
    )


#: White-noise loading of the residual's autocovariance before its AR model is fitted,
#: relative to its variance: bounds the whitening's dynamic range (:func:`_fit_noise`).
NOISE_FLOOR = 1e-3


def _fit_noise(r: NDArray, t: NDArray, max_order: int) -> ArModel:
    """AR model of the residual ``r`` with a white floor of :data:`NOISE_FLOOR` of its variance.

    As :func:`accal.estimators.arnoise.fit_ar` (biased autocovariances on the gap-filled
    grid, Durbin–Levinson, order by BIC) with ``γ(0)`` multiplied by ``1 + NOISE_FLOOR``:
    the diagonal loading of a covariance estimate (Carlson, IEEE Trans. AES 24, 1988),
    i.e. white noise of that variance added to the model, whose PSD then never drops
    below ~1e-3 of the residual's mean level.  Without it, a noise-free reference left a
    residual that is the raw data's CRN-filtered noise alone, whose PSD falls by many
    decades above 35 mHz; Yule–Walker AR models of such spectra are ill-conditioned
    (Percival & Walden, *Spectral Analysis for Physical Applications*, 1993, §9.4) and
    their whitening multiplies what the raw data hold there (rounding, the signal's
    own mismatch) by up to ~1e10: the GLS iterations then wandered (x: 0.96 → 0.969 →
    2.08 → 0.19) and returned y 0.856 for 0.98, x and z "not identifiable" (issue 22,
    QA).  A reference noisier than 1e-3 of the residual's variance at every frequency
    (any real one) is not affected: the default simulated POD noise and 1e-10 of it
    gave the same scales to 4 digits with and without the floor.
    """
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    grid = np.rint((t - t[0]) / step).astype(np.int64)
    full = np.zeros(int(grid[-1]) + 1 if t.size else 0)
    full[grid] = r - r.mean()
    n = r.size
    max_order = min(max_order, max(0, (n - 10) // 3))
    gamma = np.array([full[: full.size - k] @ full[k:] for k in range(max_order + 1)]) / n
    gamma[0] *= 1.0 + NOISE_FLOOR
    phi, v = levinson(gamma)
    bic = n * np.log(v) + np.arange(max_order + 1) * np.log(n)
    p = int(np.argmin(bic))
    return ArModel(tuple(phi[: p + 1]), v[: p + 1].copy())


def _fit_mode(ax: _Axis, i, mode, unsupported, apriori, pos, noise_var, t, iterations, max_order):
    """Iterated AR-weighted least squares of axis ``i`` with the scale model ``mode``.

    Returns ``(free, theta, inv, rss, r, mat, eiv, ar)``: the free parameters, the
    estimate, its inverse normal matrix, residual sum of squares and residual, the
    last normal equations, errors-in-variables power and AR noise model.
    """
    k = unsupported.size
    free = np.ones(3 + k, dtype=bool)
    free[3:] = ~unsupported
    fixed = np.zeros(3 + k)
    if mode != "fit-matrix":
        free[:3] = False
    if mode == "fit":
        free[i] = True
    if mode == "fixed":
        fixed[i] = apriori[i]
    ar = ArModel.white(1.0)
    var_n = 0.0  # white noise of the raw column i (errors in variables)
    for _ in range(iterations + 1):
        mat = ax.normal(ar)
        theta, inv = _solve(mat, free, fixed, _eiv_power(ar, pos, var_n, i))
        r = ax.residual(theta)
        ar = _fit_noise(r, t, max_order)
        if free[i]:  # bounded by what the residual holds: −S_ii n_i is in it
            var_n = min(noise_var[i], _raw_noise(r[:, None], pos)[0] / theta[i] ** 2)
    mat = ax.normal(ar, keep=True)
    eiv = _eiv_power(ar, pos, var_n, i)
    theta, inv = _solve(mat, free, fixed, eiv)
    theta, rss = _refine(ax, theta, free, inv, eiv)
    r = ax.residual(theta)
    return free, theta, inv, rss, r, mat, eiv, ar


def _crosstalk_chi2(ax: _Axis, i, mode, theta, cov, mat, eiv, s0, ar, t, basis, unsupported):
    """Wald χ² (2 dof) of row ``i``'s two cross terms (eq. 2), or None if it cannot be had."""
    k = unsupported.size
    full = np.ones(3 + k, dtype=bool)
    full[3:] = ~unsupported
    try:
        # a Wald test on the two cross terms of the full row, with their covariance
        # from the residual's own spectrum (_honest_cov): the likelihood-ratio form
        # under the AR model alarmed on 40 % of one-day fits with red noise
        if mode == "fit-matrix":
            th_f, cov_f = theta, cov
        else:
            th_f, inv_f = _solve(mat, full, np.zeros(3 + k), eiv)
            cov_f, _ = _honest_cov(ax, inv_f, s0, full, ar, t, ax.residual(th_f), basis)
        cross = [j for j in range(3) if j != i]
        pos_f = np.cumsum(full) - 1  # parameter index → index among the free ones
        c = cov_f[np.ix_(pos_f[cross], pos_f[cross])]
        return float(th_f[cross] @ np.linalg.solve(c, th_f[cross]))
    except (ValidationError, np.linalg.LinAlgError):
        return None


def _support(t: NDArray, use: NDArray, basis: BiasBasis, chunk: int):
    """Coefficients without data under them, and the samples they would decide.

    A basis function whose summed weight over the used samples is below 1 % of the
    best-supported one's (a gap longer than a spline's node step) is not estimated:
    its coefficient is NaN and the few samples it acts on are left out, so no
    bias is extrapolated across the gap.
    """
    k = basis.size
    if basis.kind != "spline":  # a polynomial acts everywhere
        return np.zeros(k, bool), use, ""
    idx = np.flatnonzero(use)
    weight = np.zeros(k)
    for a in range(0, idx.size, chunk):
        cols, first = basis.design(t[idx[a : a + chunk]])
        weight[first : first + cols.shape[1]] += cols.sum(0)
    bad = weight < 0.01 * weight.max(initial=0.0)
    if not bad.any():
        return bad, use, ""
    use = use.copy()
    for a in range(0, idx.size, chunk):
        sel = idx[a : a + chunk]
        cols, first = basis.design(t[sel])
        hit = (cols[:, bad[first : first + cols.shape[1]]] > 0).any(1)
        use[sel[hit]] = False
    note = (
        f"bias not estimated under {int(bad.sum())} of {k} basis coefficients (no data "
        f"there: a gap longer than the node step); {int(use[idx].size - use[idx].sum())} "
        "samples next to the gap left out"
    )
    return bad, use, note


def _transform(thetas, covs, frees, apriori, k):
    """(S, D) of eq. (2) with their covariance → (S, B = −S⁻¹D) with theirs (exact Jacobian).

    ``dB = −S⁻¹ dD − S⁻¹ dS B``, i.e. ∂B_ij/∂D_kl = −(S⁻¹)_ik δ_jl and
    ∂B_ij/∂S_kl = −(S⁻¹)_ik B_lj.
    """
    s = np.zeros((3, 3))
    d = np.zeros((3, k))
    npar = 9 + 3 * k
    cov = np.zeros((npar, npar))
    for i in range(3):
        th, free = thetas[i], frees[i]
        s[i] = th[:3]
        if not free[i]:
            s[i, i] = apriori[i] if th[i] == 0 else th[i]
        d[i] = th[3:]
        idx = np.r_[3 * i : 3 * i + 3, 9 + k * i : 9 + k * (i + 1)][free]
        cov[np.ix_(idx, idx)] = covs[i]
    s_inv = np.linalg.inv(s)
    b = -s_inv @ d
    jac = np.zeros((3 * k, npar))
    for i in range(3):
        for kk in range(3):
            jac[i * k : (i + 1) * k, 9 + kk * k : 9 + (kk + 1) * k] = -s_inv[i, kk] * np.eye(k)
            for m in range(3):
                jac[i * k : (i + 1) * k, 3 * kk + m] = -s_inv[i, kk] * b[m]
    full = np.zeros((npar, npar))  # Jacobian of (S, B) with respect to (S, D)
    full[:9, :9] = np.eye(9)
    full[9:] = jac
    return s, b, full @ cov @ full.T
