"""Bias and drift (polynomial trend) estimators for accelerometer time series.

Two methods, selected by name through :data:`METHODS`:

``"wavelet"``
    The inverted-Haar wavelet detrending scheme of Andreas & Treviño (1997) as
    applied to GRACE by the wavelet calibration paper (eqs. 2–8 and 10),
    discretised so that it is *exact* for any polynomial of the fitted order on
    any sample layout (odd or even length, gaps, uneven sampling).
``"lsq"``
    Ordinary least squares of a polynomial in time (QR of the Vandermonde matrix).

Both are linear estimators: every coefficient is ``g_j @ a`` for a weight vector
``g_j`` computed from the sample times alone.  This makes their uncertainty under
coloured noise a quadratic form ``g_j' C g_k`` in the residual covariance ``C``,
which :func:`linear_estimator_covariance` evaluates with FFTs (no N×N matrix).

References
----------
.. [1] T. Andreas & G. Treviño, "Using wavelets to detect trends", J. Atmos.
   Oceanic Technol. 14, 554–564 (1997).
.. [2] "Calibration of the accelerometers on board GRACE satellites using discrete
   wavelet transform" (``shared/papers/grace_wavelet_calibration.txt``), eqs. 1–11.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import ValidationError, check_option

__all__ = [
    "METHODS",
    "TrendFit",
    "fit_trend",
    "linear_estimator_covariance",
    "lsq_weights",
    "wavelet_weights",
]


@dataclass(frozen=True)
class TrendFit:
    """Result of a bias/drift fit of one axis.

    The trend is ``coef[0] + coef[1]·(t − t0) + coef[2]·(t − t0)²``.

    Attributes
    ----------
    method : str
        ``"wavelet"`` or ``"lsq"``.
    order : int
        Polynomial order (1: bias + drift, 2: + quadratic term).
    t0 : float
        Reference epoch, the first sample used [s].
    coef : ndarray, shape (order + 1,)
        Bias [m/s²], drift [m/s³] and, for order 2, the quadratic term [m/s⁴].
    cov : ndarray, shape (order + 1, order + 1)
        Covariance of ``coef`` under the residual's estimated coloured-noise
        covariance (see :func:`linear_estimator_covariance`) [SI units squared].
    n_used : int
        Number of samples used.
    rms : float
        Root mean square of the residual (data − trend) over the used samples [m/s²].
    sigma_lag_window : int
        Lag window (samples) of the autocovariance estimate behind ``cov``.
    """

    method: str
    order: int
    t0: float
    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    n_used: int
    rms: float
    sigma_lag_window: int = 0
    notes: tuple[str, ...] = field(default=())

    @property
    def bias(self) -> float:
        """Value of the trend at ``t0`` [m/s²]."""
        return float(self.coef[0])

    @property
    def drift(self) -> float:
        """First derivative of the trend at ``t0`` [m/s³]."""
        return float(self.coef[1])

    @property
    def quadratic(self) -> float:
        """Quadratic coefficient [m/s⁴] (NaN for order 1)."""
        return float(self.coef[2]) if self.order >= 2 else float("nan")

    @property
    def sigma(self) -> NDArray[np.float64]:
        """1σ uncertainties of ``coef`` (square root of the diagonal of ``cov``)."""
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def evaluate(self, t: ArrayLike) -> NDArray[np.float64]:
        """Evaluate the trend at times ``t`` [s] -> [m/s²]."""
        dt = np.asarray(t, dtype=np.float64) - self.t0
        return np.polynomial.polynomial.polyval(dt, self.coef)


# --------------------------------------------------------------------------------------
# weights of the two linear estimators
# --------------------------------------------------------------------------------------


def _scaled_time(t: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float]:
    """Map ``t`` onto ``u`` in [-1, 1] for a well-conditioned polynomial basis."""
    centre = 0.5 * (t[0] + t[-1])
    half = 0.5 * (t[-1] - t[0])
    if half <= 0:
        half = 1.0
    return (t - centre) / half, centre, half


def _cell_widths(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quadrature weights: the time each sample represents [s].

    Each sample stands for the interval up to the next sample (rectangle rule),
    capped at 1.5 nominal (median) steps so that a gap is not integrated over; the
    last sample gets the nominal step.  On a uniform grid every weight is equal,
    which makes the half-interval integrals of eq. (4) plain sample means: the
    rectangle rule is exact for sinusoids over whole periods (Table 1 case).
    """
    if t.size < 2:
        return np.ones_like(t)
    d = np.diff(t)
    nominal = float(np.median(d))
    cap = 1.5 * nominal
    w = np.empty_like(t)
    w[:-1] = np.minimum(d, cap)
    w[-1] = nominal
    return w


def wavelet_weights(t: ArrayLike, order: int = 1) -> NDArray[np.float64]:
    """Weights of the generalised inverted-Haar (segment-moment) estimator.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times of the used samples, increasing [s].
    order : {1, 2}
        Polynomial order of the trend.

    Returns
    -------
    ndarray, shape (order + 1, n)
        ``G`` such that the trend coefficients in powers of ``t − t[0]`` are
        ``G @ a`` [bias m/s², drift m/s³, quadratic m/s⁴ per m/s² of input].

    Notes
    -----
    Continuous form (paper eqs. 2–4, 6): with the inverted Haar wavelet of
    eq. (3) the wavelet coefficient at ``L/2`` is

    .. math:: \\hat\\mu_1 = WT(L/2, L) = (2/L)^2 \\int_0^{L/2} [\\tilde g(s + L/2) - \\tilde g(s)] ds

    i.e. the difference of the means of the two halves of the record divided by
    ``L/2``, the distance between the halves' centroids; eq. (8)/(10) then gives
    the bias as the record mean minus the drift times the centroid offset.

    Discrete, exact generalisation used here: split the record at ``t[0] + L/2``
    into two halves; in each half ``k`` take the quadrature-weighted mean of the
    data, ``ā_k``, and of the time, ``t̄_k`` (weights: :func:`_cell_widths`, the
    time each sample represents, so gaps and uneven sampling are integrated over
    the actual sample times).  Then

    * drift ``d = (ā_2 − ā_1) / (t̄_2 − t̄_1)`` (eq. 4/6 with ``L/2`` replaced by the
      actual centroid distance, which equals ``L/2`` for continuous sampling);
    * bias ``b = ā − d (t̄ − t0)`` (eq. 8/10 with ``L/2`` replaced by the actual
      centroid offset ``t̄ − t0``).

    Both are exact for any ``b + d t`` on any sample layout, because a weighted
    mean of a linear function is the function at the weighted centroid.  For
    ``order = 2`` (the Andreas & Treviño quadratic extension) the record is split
    into three equal-time segments and the 3×3 system of segment moments
    ``Σ_j c_j · mean_k(u^j) = ā_k`` is solved; this reduces to the above for
    order 1 and is exact for any quadratic.
    """
    t = np.asarray(t, dtype=np.float64)
    check_option("order", order, (1, 2))
    n = t.size
    p = order + 1
    if n < p:
        raise ValidationError(f"need at least {p} samples for an order-{order} trend, got {n}")
    u, centre, half = _scaled_time(t)
    w = _cell_widths(t)
    # segment boundaries at equal fractions of the time span
    edges = np.linspace(-1.0, 1.0, p + 1)
    seg = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, p - 1)
    counts = np.bincount(seg, minlength=p)
    if np.any(counts == 0):
        # fall back to equal-count segments (e.g. a huge gap covering a segment)
        seg = np.minimum((np.arange(n) * p) // n, p - 1)
    wsum = np.bincount(seg, weights=w, minlength=p)
    # S: (p, n) segment-averaging operator; M: (p, p) segment moments of u^j
    powers = np.vander(u, p, increasing=True)  # (n, p)
    moments = np.empty((p, p))
    for j in range(p):
        moments[:, j] = np.bincount(seg, weights=w * powers[:, j], minlength=p) / wsum
    minv = np.linalg.inv(moments)  # (p coeffs, p segments)
    # G_u[j, i] = minv[j, seg_i] * w_i / wsum[seg_i]  -> coefficients in powers of u
    g_u = minv[:, seg] * (w / wsum[seg])[None, :]
    return _u_to_t0_basis(g_u, t[0], centre, half)


def lsq_weights(t: ArrayLike, order: int = 1) -> NDArray[np.float64]:
    """Weights of the ordinary least-squares polynomial fit.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times of the used samples [s].
    order : {1, 2}
        Polynomial order.

    Returns
    -------
    ndarray, shape (order + 1, n)
        ``G = R⁻¹ Qᵀ`` from the QR factorisation of the Vandermonde matrix in
        scaled time, converted to coefficients in powers of ``t − t[0]``.
    """
    t = np.asarray(t, dtype=np.float64)
    check_option("order", order, (1, 2))
    p = order + 1
    if t.size < p:
        raise ValidationError(f"need at least {p} samples for an order-{order} trend, got {t.size}")
    u, centre, half = _scaled_time(t)
    x = np.vander(u, p, increasing=True)
    q, r = np.linalg.qr(x)
    g_u = np.linalg.solve(r, q.T)
    return _u_to_t0_basis(g_u, t[0], centre, half)


def _u_to_t0_basis(
    g_u: NDArray[np.float64], t0: float, centre: float, half: float
) -> NDArray[np.float64]:
    """Convert weights for coefficients in ``u = (t − centre)/half`` to ``(t − t0)``.

    With ``u = (t − t0)/half + s`` and ``s = (t0 − centre)/half``, the polynomial
    ``Σ c_j u^j`` equals ``Σ_k [Σ_j c_j C(j,k) s^(j−k)] half^(−k) (t − t0)^k``.
    """
    from math import comb

    p = g_u.shape[0]
    s = (t0 - centre) / half
    tmat = np.zeros((p, p))
    for k in range(p):
        for j in range(k, p):
            tmat[k, j] = comb(j, k) * s ** (j - k) / half**k
    return tmat @ g_u


METHODS = {"wavelet": wavelet_weights, "lsq": lsq_weights}


# --------------------------------------------------------------------------------------
# uncertainty under coloured noise
# --------------------------------------------------------------------------------------


def _grid_index(t: NDArray[np.float64]) -> tuple[NDArray[np.int64], int]:
    """Index of each sample on the nominal uniform grid starting at ``t[0]``."""
    if t.size < 2:
        return np.zeros(t.size, dtype=np.int64), 1
    step = float(np.median(np.diff(t)))
    idx = np.rint((t - t[0]) / step).astype(np.int64)
    # keep indices strictly increasing even for jittered sampling
    idx = np.maximum.accumulate(np.maximum(idx, np.arange(idx.size)))
    return idx, int(idx[-1]) + 1


def linear_estimator_covariance(
    t: ArrayLike,
    residual: ArrayLike,
    weights: ArrayLike,
    *,
    max_lag: int | None = None,
) -> tuple[NDArray[np.float64], int]:
    """Covariance of linear estimators ``G @ a`` under the residual's coloured noise.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times [s].
    residual : array_like, shape (n,)
        Residual of the fit (data − trend) [m/s²], taken as one realisation of the
        noise.
    weights : array_like, shape (p, n)
        Estimator weights (:func:`wavelet_weights` or :func:`lsq_weights`).
    max_lag : int, optional
        Lag window ``M`` in samples.  Default: adaptive, see Notes.

    Returns
    -------
    cov : ndarray, shape (p, p)
        ``G C Gᵀ`` with ``C`` the lag-window (Parzen) estimate of the residual
        autocovariance [m²/s⁴ × weight units].
    max_lag : int
        The lag window used.

    Notes
    -----
    ``Var(g'a) = Σ_l γ(l) ρ_g(l)`` where ``γ`` is the noise autocovariance at lag
    ``l`` and ``ρ_g(l) = Σ_i g_i g_{i+l}`` the weights' autocorrelation; this is
    the time-domain form of ``∫ |G(f)|² S(f) df``.  ``γ`` is estimated from the
    residual on the nominal sampling grid (gaps as missing pairs), tapered by a
    Parzen lag window of width ``M`` (Blackman–Tukey), which gives a smoothed,
    non-negative PSD estimate.  ``M`` adapts to the noise colour: four times the
    first lag at which the residual autocorrelation falls below ``2/√n`` (its
    white-noise significance level), at least 32 and at most ``n/4`` samples.
    White noise therefore gets a short window (small estimation scatter) and
    correlated noise or orbital signal a long one (low bias).  All correlations
    are computed with FFTs; no ``n × n`` matrix is formed.
    """
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(residual, dtype=np.float64)
    g = np.atleast_2d(np.asarray(weights, dtype=np.float64))
    n = t.size
    p = g.shape[0]
    if n < 3:
        return np.full((p, p), np.nan), 0
    idx, ngrid = _grid_index(t)
    nfft = 1 << int(np.ceil(np.log2(2 * ngrid)))
    rg = np.zeros(ngrid)
    mg = np.zeros(ngrid)
    rg[idx] = r - r.mean()
    mg[idx] = 1.0
    fr = np.fft.rfft(rg, nfft)
    fm = np.fft.rfft(mg, nfft)
    acov_sum = np.fft.irfft(np.abs(fr) ** 2, nfft)[:ngrid]
    pairs = np.fft.irfft(np.abs(fm) ** 2, nfft)[:ngrid]
    pairs = np.rint(pairs)
    with np.errstate(invalid="ignore", divide="ignore"):
        gamma = np.where(pairs > 0.5, acov_sum / np.maximum(pairs, 1.0), 0.0)
    if max_lag is None:
        rho = gamma / gamma[0] if gamma[0] > 0 else np.zeros_like(gamma)
        limit = 2.0 / np.sqrt(n)
        below = np.nonzero(np.abs(rho[1:]) < limit)[0]
        first = int(below[0]) + 1 if below.size else ngrid
        max_lag = int(np.clip(4 * first, 32, max(32, ngrid // 4)))
    max_lag = int(min(max_lag, ngrid - 1))
    lags = np.arange(max_lag + 1)
    x = lags / max(max_lag, 1)
    parzen = np.where(x <= 0.5, 1 - 6 * x**2 + 6 * x**3, 2 * (1 - x) ** 3)
    gam = gamma[: max_lag + 1] * parzen
    # weights on the grid and their (cross-)correlations via FFT
    gg = np.zeros((p, ngrid))
    gg[:, idx] = g
    fg = np.fft.rfft(gg, nfft, axis=1)
    cov = np.empty((p, p))
    for j in range(p):
        for k in range(j, p):
            # rho_jk(l) = Σ_i g_j[i] g_k[i + l]  for l >= 0, and the mirror for l < 0
            cc = np.fft.irfft(np.conj(fg[j]) * fg[k], nfft)
            pos = cc[: max_lag + 1]
            neg = cc[::-1][:max_lag]  # lags -1 .. -max_lag
            val = gam[0] * pos[0] + np.dot(gam[1:], pos[1:]) + np.dot(gam[1:], neg)
            cov[j, k] = cov[k, j] = val
    return cov, max_lag


# --------------------------------------------------------------------------------------
# the public estimator
# --------------------------------------------------------------------------------------


def fit_trend(
    t: ArrayLike,
    a: ArrayLike,
    *,
    method: str = "wavelet",
    order: int = 1,
    valid: ArrayLike | None = None,
    max_lag: int | None = None,
) -> TrendFit:
    """Estimate bias and drift (and optionally a quadratic term) of one axis.

    Model (paper eq. 9): ``a_raw(t) = s·a_true(t) + b + d·(t − t0) [+ c·(t − t0)²]``.
    The scale ``s`` is assumed known (eq. 11) and is not estimated here.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times, increasing [s].
    a : array_like, shape (n,)
        Accelerations [m/s²].  For the reference-based calibration pass
        ``a_raw − a_reference``.
    method : {"wavelet", "lsq"}
        ``"wavelet"``: generalised inverted-Haar scheme (eqs. 2–8, 10), see
        :func:`wavelet_weights`.  ``"lsq"``: ordinary least squares.
    order : {1, 2}
        1 for bias + drift, 2 adds a quadratic term.
    valid : array_like of bool, shape (n,), optional
        Samples to use (default all finite samples).
    max_lag : int, optional
        Lag window for the uncertainty (default adaptive,
        :func:`linear_estimator_covariance`).

    Returns
    -------
    TrendFit
        Coefficients at ``t0`` = first used sample, their covariance, residual RMS.

    Raises
    ------
    ValidationError
        Bad method/order, mismatched lengths, or too few usable samples.
    """
    check_option("method", method, tuple(METHODS))
    t = np.asarray(t, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    if t.shape != a.shape or t.ndim != 1:
        raise ValidationError(f"t and a must be 1-D of equal length, got {t.shape} and {a.shape}")
    use = np.isfinite(a) & np.isfinite(t)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != t.shape:
            raise ValidationError(f"valid must have shape {t.shape}, got {valid.shape}")
        use &= valid
    tu = t[use]
    au = a[use]
    if tu.size < order + 2:
        raise ValidationError(
            f"only {tu.size} usable samples; an order-{order} trend needs at least {order + 2}"
        )
    if np.any(np.diff(tu) <= 0):
        raise ValidationError("sample times must be strictly increasing")
    g = METHODS[method](tu, order)
    coef = g @ au
    resid = au - np.polynomial.polynomial.polyval(tu - tu[0], coef)
    cov, lag = linear_estimator_covariance(tu, resid, g, max_lag=max_lag)
    return TrendFit(
        method=method,
        order=order,
        t0=float(tu[0]),
        coef=coef,
        cov=cov,
        n_used=int(tu.size),
        rms=float(np.sqrt(np.mean(resid**2))),
        sigma_lag_window=lag,
    )
