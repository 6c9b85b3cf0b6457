"""Autoregressive noise models and exact prewhitening of gapped records.

Least squares against a reference acceleration (:mod:`accal.estimators.reference`)
is weighted by the residual's spectrum the way large geodetic adjustments do it:
an autoregressive (AR) model of the residual is fitted, and observations and
design columns are passed through its prediction-error (whitening) filter, so
that ordinary least squares on the filtered quantities is the generalised
least-squares estimate (Klees, Ditmar & Broersen 2003 [1]_).

A record with gaps is split into segments of consecutive samples.  Inside a
segment the first ``p`` samples are whitened with the partial-order predictors
of the Durbin–Levinson recursion ([2]_, §5.2) and their prediction-error
variances; this *is* the Cholesky factor of the stationary AR(p) covariance
matrix of the segment (innovations algorithm, [2]_ §5.2.2), so no sample is
dropped and each segment is whitened exactly.  Correlation across a gap is
ignored (the segments are treated as independent): this costs a little
efficiency, not bias.

References
----------
.. [1] R. Klees, P. Ditmar & P. Broersen, "How to handle colored observation
   noise in large least-squares problems", J. Geodesy 76, 629–640 (2003).
.. [2] P. J. Brockwell & R. A. Davis, *Introduction to Time Series and
   Forecasting*, 2nd ed., Springer (2002).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from accal.errors import ValidationError

__all__ = ["ArModel", "fit_ar", "levinson", "segment_positions"]


def levinson(gamma: NDArray[np.float64]) -> tuple[list[NDArray[np.float64]], NDArray[np.float64]]:
    """Durbin–Levinson recursion ([2]_ eqs. 2.5.18–2.5.20).

    Parameters
    ----------
    gamma : ndarray, shape (p + 1,)
        Autocovariances γ(0) … γ(p) [any unit²]; must be a positive-definite
        sequence (the biased estimator of :func:`fit_ar` always is).

    Returns
    -------
    phi : list of ndarray
        ``phi[k]`` (length ``k``) are the coefficients of the best linear
        predictor of order ``k``: x̂_t = Σ_j phi[k][j-1] x_{t-j}.
    v : ndarray, shape (p + 1,)
        One-step prediction-error variances v_0 = γ(0), …, v_p.
    """
    gamma = np.asarray(gamma, dtype=np.float64)
    p = gamma.size - 1
    if gamma[0] <= 0 or not np.isfinite(gamma).all():
        raise ValidationError("AR noise model: the residual has zero or non-finite variance")
    phi: list[NDArray[np.float64]] = [np.zeros(0)]
    v = np.empty(p + 1)
    v[0] = gamma[0]
    for k in range(1, p + 1):
        prev = phi[-1]
        kk = (gamma[k] - prev @ gamma[k - 1 : 0 : -1]) / v[k - 1] if k > 1 else gamma[1] / v[0]
        kk = float(np.clip(kk, -1 + 1e-12, 1 - 1e-12))
        cur = np.empty(k)
        cur[: k - 1] = prev - kk * prev[::-1]
        cur[k - 1] = kk
        phi.append(cur)
        v[k] = v[k - 1] * (1.0 - kk * kk)
    return phi, v


def segment_positions(
    time: NDArray[np.float64], breaks: NDArray[np.bool_] | None = None
) -> NDArray[np.int64]:
    """Index of every sample within its segment of consecutive samples.

    A new segment starts where the time step exceeds 1.5 nominal (median) steps
    or where ``breaks`` is True (e.g. the first sample of each day of an arc).
    """
    time = np.asarray(time, dtype=np.float64)
    n = time.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    start = np.zeros(n, dtype=bool)
    start[0] = True
    if n > 1:
        d = np.diff(time)
        step = float(np.median(d))
        start[1:] = d > 1.5 * step
    if breaks is not None:
        start |= breaks
    idx = np.arange(n)
    first = np.maximum.accumulate(np.where(start, idx, 0))
    return idx - first


@dataclass(frozen=True)
class ArModel:
    """An AR(p) noise model with its partial-order predictors.

    Attributes
    ----------
    phi : tuple of ndarray
        Predictor coefficients of orders 0 … p (see :func:`levinson`).
    v : ndarray, shape (p + 1,)
        Prediction-error variances of orders 0 … p [unit²].
    """

    phi: tuple[NDArray[np.float64], ...]
    v: NDArray[np.float64]

    @property
    def order(self) -> int:
        """The model order p."""
        return len(self.phi) - 1

    @classmethod
    def white(cls, variance: float = 1.0) -> ArModel:
        """White noise of ``variance`` (order 0)."""
        return cls((np.zeros(0),), np.array([float(variance)]))

    def whiten(self, x: NDArray[np.float64], pos: NDArray[np.int64]) -> NDArray[np.float64]:
        """Apply the exact whitening filter to ``x`` (samples along axis 0).

        ``pos`` is each sample's index within its segment (:func:`segment_positions`).
        The output has unit variance if ``x`` is the modelled noise:
        e_t = (x_t − Σ_{j≤m} φ_{m,j} x_{t−j}) / √v_m with m = min(pos_t, p).
        """
        x = np.asarray(x, dtype=np.float64)
        p = self.order
        # the order-p prediction-error filter (FIR); its first p outputs are redone below
        out = signal.lfilter(np.r_[1.0, -self.phi[p]], [1.0], x, axis=0) if p else x.copy()
        out /= np.sqrt(self.v[p])
        for m in range(min(p, int(pos.max(initial=0)) + 1)):
            idx = np.flatnonzero(pos == m)
            if idx.size == 0:
                continue
            e = x[idx].copy()
            for j in range(1, m + 1):
                e -= self.phi[m][j - 1] * x[idx - j]
            out[idx] = e / np.sqrt(self.v[m])
        return out

    def whiten_adjoint(self, v: NDArray[np.float64], pos: NDArray[np.int64]) -> NDArray[np.float64]:
        """``Wᵀ v``: the transpose of :meth:`whiten` (samples along axis 0).

        Needed for the weights of the estimator in the data domain,
        ``g = Wᵀ X̃ A⁻¹`` (:func:`accal.estimators.reference.fit_reference`).
        """
        v = np.asarray(v, dtype=np.float64)
        p = self.order
        n = v.shape[0]
        # rows with m = pos < p use the partial predictors; the others the order-p filter
        part = pos < p
        main = np.where(part, 0.0, 1.0)
        vm = v * (main / np.sqrt(self.v[p])).reshape((-1,) + (1,) * (v.ndim - 1))
        out = vm.copy()
        for j in range(1, p + 1):
            out[: n - j] -= self.phi[p][j - 1] * vm[j:]
        for m in range(min(p, int(pos.max(initial=0)) + 1)):
            idx = np.flatnonzero(pos == m)
            if idx.size == 0:
                continue
            vk = v[idx] / np.sqrt(self.v[m])
            out[idx] += vk
            for j in range(1, m + 1):
                np.subtract.at(out, idx - j, self.phi[m][j - 1] * vk)
        return out

    def psd(self, f: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
        """One-sided power spectral density of the model at ``f`` [Hz] [unit²/Hz]."""
        p = self.order
        z = np.exp(-2j * np.pi * np.outer(f, np.arange(1, p + 1)) * dt)
        a = 1.0 - z @ self.phi[p] if p else np.ones(np.size(f))
        return 2.0 * dt * self.v[p] / np.abs(a) ** 2


def fit_ar(
    residual: NDArray[np.float64],
    time: NDArray[np.float64],
    max_order: int = 20,
) -> ArModel:
    """Fit an AR model to a gapped residual, its order chosen by BIC.

    The autocovariances are the biased estimates on the record's regular grid
    with gaps zero-filled, γ(k) = Σ r_t r_{t+k} / n ([2]_ eq. 1.4.5; positive
    definite by construction, so the recursion is stable); the order minimises
    BIC(p) = n ln v_p + p ln n (Schwarz 1978; [2]_ §5.5.2).

    Parameters
    ----------
    residual, time : ndarray, shape (n,)
        Residual values and their times [s] (valid samples only).
    max_order : int
        Largest order tried.
    """
    r = np.asarray(residual, dtype=np.float64)
    t = np.asarray(time, dtype=np.float64)
    n = r.size
    if n < 3 * max_order + 10:
        max_order = max(0, (n - 10) // 3)
    if n < 2:
        return ArModel.white(float(np.mean(r * r)) if n else 1.0)
    step = float(np.median(np.diff(t)))
    grid = np.rint((t - t[0]) / step).astype(np.int64)
    full = np.zeros(int(grid[-1]) + 1)
    full[grid] = r - r.mean()
    gamma = np.array([full[: full.size - k] @ full[k:] for k in range(max_order + 1)]) / n
    phi, v = levinson(gamma)
    bic = n * np.log(v) + np.arange(max_order + 1) * np.log(n)
    p = int(np.argmin(bic))
    return ArModel(tuple(phi[: p + 1]), v[: p + 1].copy())
