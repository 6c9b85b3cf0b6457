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
.. [3] D. B. Percival & A. T. Walden, *Spectral Analysis for Physical Applications*,
   Cambridge University Press (1993): the variance of a linear functional of a
   stationary process, ``∫ |G(f)|² S(f) df`` over the DTFT ``G`` of its weights.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import ValidationError, check_option
from accal.timescale import nominal_step

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
    """

    method: str
    order: int
    t0: float
    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    n_used: int
    rms: float

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
    nominal = nominal_step(d)
    cap = 1.5 * nominal
    w = np.empty_like(t)
    np.minimum(d, cap, out=w[:-1])
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
    # segment boundaries at equal fractions of the time span: u is increasing, so
    # segment k is the slice bounds[k]:bounds[k+1] (u in [edge_k, edge_k+1))
    edges = np.linspace(-1.0, 1.0, p + 1)
    bounds = np.concatenate(([0], np.searchsorted(u, edges[1:-1], side="left"), [n]))
    if np.any(np.diff(bounds) == 0):
        # fall back to equal-count segments (e.g. a huge gap covering a segment)
        bounds = np.array([-((-k * n) // p) for k in range(p + 1)])
    seg = [slice(int(bounds[k]), int(bounds[k + 1])) for k in range(p)]
    wsum = np.array([w[s].sum() for s in seg])
    # M: (p, p) quadrature-weighted segment moments of u^j
    moments = np.empty((p, p))
    for k, s in enumerate(seg):
        uk, wk = u[s], w[s]
        for j in range(p):
            moments[k, j] = np.dot(wk, uk**j) / wsum[k]
    minv = np.linalg.inv(moments)  # (p coeffs, p segments)
    # coefficients in powers of (t - t0); G[:, i] = C[:, seg_i] * w_i / wsum[seg_i]
    c = _u_to_t0_basis(minv, t[0], centre, half) / wsum[None, :]
    g = np.empty((p, n))
    for k, s in enumerate(seg):
        np.multiply(c[:, k : k + 1], w[None, s], out=g[:, s])
    return g


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


#: The noise grid of :func:`linear_estimator_covariance` spans at most this many
#: times the number of samples; longer gaps are shortened (see :func:`_grid_index`).
MAX_GRID_FACTOR = 4


def _grid_index(t: NDArray[np.float64]) -> tuple[NDArray[np.int64] | None, int]:
    """Index of each sample on the nominal uniform grid starting at ``t[0]``.

    Returns ``(None, n)`` when the samples are that grid (every step equal).
    Gaps are kept at their length unless the grid would exceed
    :data:`MAX_GRID_FACTOR` × n points (e.g. two stretches of data months apart):
    then the longest gaps are shortened to a common length so that it does not.
    Noise correlated across such a gap is treated as correlated across the
    shortened gap; the alternative, a grid of months of samples, costs gigabytes.
    """
    n = t.size
    if n < 2:
        return np.zeros(n, dtype=np.int64), 1
    d = np.diff(t)
    step = nominal_step(d)
    if d.min() == d.max():
        return None, n
    # grid steps between consecutive samples (>= 1 even for jittered sampling)
    k = np.maximum(np.rint((t - t[0]) / step).astype(np.int64), np.arange(n))
    k = np.maximum.accumulate(k)
    steps = np.diff(k)
    limit = MAX_GRID_FACTOR * n
    if int(k[-1]) + 1 > limit:
        # the largest cap c with sum(min(steps, c)) + 1 <= limit (rare path: bisect)
        lo, hi = 1, int(steps.max())  # c = 1 fits: n <= limit
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if int(np.minimum(steps, mid).sum()) + 1 <= limit:
                lo = mid
            else:
                hi = mid - 1
        cap = lo
        steps = np.minimum(steps, max(cap, 1))
        k = np.concatenate(([0], np.cumsum(steps)))
    return k, int(k[-1]) + 1


def _on_grid(rows: NDArray[np.float64], idx: NDArray[np.int64] | None, ngrid: int) -> NDArray:
    """Place ``rows`` (shape (k, n)) on the uniform grid, zeros in the gaps."""
    if idx is None:
        return rows
    grid = np.zeros((rows.shape[0], ngrid))
    breaks = np.flatnonzero(np.diff(idx) != 1) + 1
    if breaks.size > 64:
        grid[:, idx] = rows
        return grid
    # few gaps: copy the contiguous runs (a scatter is several times slower)
    for a, b in zip((0, *breaks.tolist()), (*breaks.tolist(), idx.size), strict=True):
        grid[:, idx[a] : idx[a] + b - a] = rows[:, a:b]
    return grid


def _orthonormal_columns(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """An orthonormal basis of the columns of ``x`` (shape (n, p), p small).

    Gram–Schmidt applied twice ("twice is enough"), as accurate as a Householder
    QR for these few well-scaled columns and several times faster.
    """
    q = np.array(x, dtype=np.float64, order="F")
    for j in range(q.shape[1]):
        v = q[:, j]
        for _ in range(2):
            if j:
                v -= q[:, :j] @ (q[:, :j].T @ v)
        v /= np.linalg.norm(v)
    return q


def linear_estimator_covariance(
    t: ArrayLike,
    residual: ArrayLike,
    weights: ArrayLike,
    *,
    order: int = 1,
    min_bin: int = 3,
) -> NDArray[np.float64]:
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
    order : int
        Order of the polynomial that was removed to form ``residual``.
    min_bin : int
        Width of the lowest frequency bin of the PSD estimate, in Fourier bins.

    Returns
    -------
    ndarray, shape (p, p)
        ``G C Gᵀ`` [m²/s⁴ × weight units²].

    Notes
    -----
    For stationary noise with two-sided PSD ``S``, ``Cov(g_j'e, g_k'e) =
    ∫ G_j(f) G_k(f)* S(f) df`` over the DTFT ``G`` of the weights on the nominal
    sampling grid of ``N`` points, gaps as zeros (Percival & Walden 1993, module
    references).
    The integral is taken on a grid twice finer than the Fourier frequencies (the
    weights' DFT zero-padded to ``2N``: exact for a PSD known on that grid, the
    circulant embedding of the ``N × N`` Toeplitz form); the sum over the ``N``
    Fourier frequencies alone treats the noise as periodic with the record and put
    σ 1.5× too high under a noise band near 1/rev.  ``S`` is estimated from the
    residual's periodogram in three steps:

    1. periodogram ``P_f = |R(f)|²/n`` of the residual on the grid (``n`` used
       samples);
    2. *projection correction*: removing the fitted polynomial also removed noise
       power near ``f = 0``.  For white noise ``E[P_f] = S·(1 − Σ_j |Q_j(f)|²/n)``
       where ``Q_j`` are the DFTs of an orthonormal basis of the polynomial on the
       used samples; ``P_f`` is divided by that factor (floored at 0.2);
    3. log-spaced binning: bins of ``min_bin`` Fourier bins at the low end,
       growing by 25 % per bin; ``S`` below ``f_1`` takes the lowest bin's value,
       between Fourier frequencies the value of the bin of the one below.

    This resolves the noise PSD down to ``min_bin/T``, where the estimators'
    weights have their power, unlike a lag-window estimate whose resolution is
    the inverse window length.  Monte-Carlo checks (``tests/estimators``): scatter
    / sigma within 0.9–1.35 for white, AR(1) and 1/f-below-1-mHz noise over a day.
    No N×N matrix is formed; the cost is a handful of length-N FFTs.
    """
    g = np.atleast_2d(np.asarray(weights, dtype=np.float64))
    if np.asarray(t).size <= order + 2:
        return np.full((g.shape[0], g.shape[0]), np.nan)
    return _CovarianceKernel(t, g, order, min_bin).covariances(
        np.asarray(residual, dtype=np.float64)[None, :]
    )[0]


#: Grid refinement of the frequency integral of :class:`_CovarianceKernel`.
_OVERSAMPLE = 2


class _CovarianceKernel:
    """The residual-independent part of :func:`linear_estimator_covariance`.

    The DFTs of the estimator weights and of the polynomial basis depend only on
    the sample times, so several residuals (the axes of one file) share them and
    cost one FFT each.
    """

    def __init__(self, t: ArrayLike, g: NDArray[np.float64], order: int, min_bin: int = 3) -> None:
        t = np.asarray(t, dtype=np.float64)
        self.n = t.size
        self.order = order
        self.idx, self.ngrid = _grid_index(t)
        u, _, _ = _scaled_time(t)
        q = _orthonormal_columns(np.vander(u, order + 1, increasing=True))
        qspec = np.fft.rfft(_on_grid(q.T, self.idx, self.ngrid), axis=1)
        nf = qspec.shape[1]
        suppress = 1.0 - np.sum(np.abs(qspec) ** 2, axis=0) / self.n
        self.inv_suppress = 1.0 / np.clip(suppress, 0.2, None)
        # log-spaced bins over f_k, k = 1 .. nf-1
        edges = [1]
        while edges[-1] < nf:
            edges.append(edges[-1] + max(min_bin, int(0.25 * edges[-1])))
        edges[-1] = nf
        edges_arr = np.asarray(edges)
        self.nbins = edges_arr.size - 1
        self.counts = np.diff(edges_arr)  # every bin holds >= 1 frequency
        self.starts = edges_arr[:-1] - 1  # bin starts as indices into f_1 .. f_nf-1
        # Var(g'e) = ∫ |G(f)|² S(f) df over the DTFT of the weights (Percival &
        # Walden 1993, module references), not the sum over the N Fourier
        # frequencies, which treats the noise as periodic with the record: |G|² of
        # a polynomial weight has its sidelobe peaks at the Fourier frequencies, so
        # a PSD concentrated away from f = 0 (a band near 1/rev) came out 1.5x too
        # large in σ.  The integral is taken on a grid OVERSAMPLE times finer (zero padding),
        # with the estimate of S constant over each bin (f below f_1 takes the lowest
        # bin's value, as S(0) did); for a flat PSD the two sums agree exactly.
        m = _OVERSAMPLE * self.ngrid
        gs = np.fft.rfft(_on_grid(g, self.idx, self.ngrid), n=m, axis=1)
        nfm = gs.shape[1]
        two_sided = np.full(nfm, 2.0)
        two_sided[0] = 1.0
        if m % 2 == 0:
            two_sided[-1] = 1.0
        k = np.clip(np.arange(nfm) // _OVERSAMPLE, 1, nf - 1)  # Fourier bin below each f
        bin_of = np.searchsorted(edges_arr, k, side="right") - 1
        # The PSD estimate is constant over each bin, so
        #   Re(G diag(w) G^H)_ij = Σ_b S_b Σ_{f in b} P_ij(f),
        #   P_ij(f) = two_sided(f) · Re(G_i(f) conj(G_j(f))):
        # the residual-independent sums over each bin are formed once here.
        p = gs.shape[0]
        self.p = p
        self.scale = float(m)
        self.pair_bins = np.empty((p, p, self.nbins))
        for i in range(p):
            for j in range(i + 1):
                prod = gs[i].real * gs[j].real + gs[i].imag * gs[j].imag
                prod *= two_sided
                summed = np.bincount(bin_of, weights=prod, minlength=self.nbins)
                self.pair_bins[i, j] = self.pair_bins[j, i] = summed

    def covariances(self, residuals: NDArray[np.float64]) -> NDArray[np.float64]:
        """``G C Gᵀ`` for each row of ``residuals`` (shape (k, n)) -> (k, p, p)."""
        rspec = np.fft.rfft(_on_grid(residuals, self.idx, self.ngrid), axis=1)
        pgram = (rspec.real**2 + rspec.imag**2) * (self.inv_suppress / self.n)  # (k, nf)
        # mean over each log-spaced bin of f_1 .. f_nf-1 (bins are contiguous runs)
        sbin = np.add.reduceat(pgram[:, 1:], self.starts, axis=1) / self.counts  # (k, nbins)
        p = self.p
        cov = (sbin @ self.pair_bins.reshape(p * p, self.nbins).T).reshape(-1, p, p)
        return cov / self.scale


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

    Returns
    -------
    TrendFit
        Coefficients at ``t0`` = first used sample, their covariance, residual RMS.

    Raises
    ------
    ValidationError
        Bad method/order, mismatched lengths, or too few usable samples.
    """
    t = np.asarray(t, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    if t.shape != a.shape or t.ndim != 1:
        raise ValidationError(f"t and a must be 1-D of equal length, got {t.shape} and {a.shape}")
    return fit_trends(t, a[:, None], method=method, order=order, valid=valid)[0]


def fit_trends(
    t: ArrayLike,
    a: ArrayLike,
    *,
    method: str = "wavelet",
    order: int = 1,
    valid: ArrayLike | None = None,
) -> list[TrendFit]:
    """:func:`fit_trend` of every column of ``a`` (shape (n, k)), sharing the work.

    Columns with the same usable samples share the estimator weights and the
    DFTs of :func:`linear_estimator_covariance`; the results are those of
    :func:`fit_trend` column by column (to rounding).
    """
    check_option("method", method, tuple(METHODS))
    t = np.asarray(t, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != t.size or t.ndim != 1:
        raise ValidationError(f"a must have shape ({t.size}, k), got {a.shape}")
    use = np.isfinite(t)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != t.shape:
            raise ValidationError(f"valid must have shape {t.shape}, got {valid.shape}")
        use &= valid
    finite = np.isfinite(a)
    if finite.all() or finite[use].all():
        return _fit_columns(t, a, use, method, order)
    # columns with their own non-finite samples: each its own mask
    return [
        _fit_columns(t, a[:, j : j + 1], use & finite[:, j], method, order)[0]
        for j in range(a.shape[1])
    ]


@functools.lru_cache(maxsize=8)
def _uniform_design(
    n: int, step: float, method: str, order: int
) -> tuple[NDArray[np.float64], _CovarianceKernel]:
    """Weights and covariance kernel of ``n`` samples ``step`` apart (read-only, cached).

    Computed on ``t = k·step``; the coefficients are in powers of ``t − t0``, so
    they hold for any ``t0``, and a uniform layout gives the same result whether
    or not it was cached.
    """
    t = np.arange(n) * step
    g = METHODS[method](t, order)
    kernel = _CovarianceKernel(t, g, order)
    g.setflags(write=False)
    return g, kernel


def _fit_columns(
    t: NDArray[np.float64],
    a: NDArray[np.float64],
    use: NDArray[np.bool_],
    method: str,
    order: int,
) -> list[TrendFit]:
    """Trend fits of the columns of ``a`` on the samples ``use`` (finite there)."""
    tu, au = (t, a) if use.all() else (np.compress(use, t), np.compress(use, a, axis=0))
    if tu.size < order + 2:
        raise ValidationError(
            f"only {tu.size} usable samples; an order-{order} trend needs at least {order + 2}"
        )
    d = np.diff(tu)
    if np.any(d <= 0):
        raise ValidationError("sample times must be strictly increasing")
    if d[0] == d[-1] and d.min() == d.max():
        # every step equal (a complete day): weights and kernel depend only on
        # (n, step), so they come from the canonical grid k·step, shared by all such days
        g, kernel = _uniform_design(tu.size, float(d[0]), method, order)
    else:
        g, kernel = METHODS[method](tu, order), None
    coef = g @ au  # (p, k)
    # residual rows (k, n), C-ordered for the row FFTs: a - Σ_j coef_j (t - t0)^j
    dt = tu - tu[0]
    resid = np.empty((au.shape[1], tu.size))
    resid[:] = coef[-1][:, None]
    for j in range(order - 1, -1, -1):  # Horner
        resid *= dt
        resid += coef[j][:, None]
    np.subtract(au.T, resid, out=resid)
    covs = (kernel or _CovarianceKernel(tu, g, order)).covariances(resid)
    return [
        TrendFit(
            method=method,
            order=order,
            t0=float(tu[0]),
            coef=coef[:, j].copy(),
            cov=covs[j],
            n_used=int(tu.size),
            rms=float(np.sqrt(np.dot(resid[j], resid[j]) / tu.size)),
        )
        for j in range(a.shape[1])
    ]
