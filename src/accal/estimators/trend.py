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
which :func:`linear_estimator_covariance` evaluates with FFTs (no N×N matrix)
for a noise model fitted to the residual (:mod:`accal.estimators.lowfreq`).

References
----------
.. [1] T. Andreas & G. Treviño, "Using wavelets to detect trends", J. Atmos.
   Oceanic Technol. 14, 554–564 (1997).
.. [2] "Calibration of the accelerometers on board GRACE satellites using discrete
   wavelet transform" (``shared/papers/grace_wavelet_calibration.txt``), eqs. 1–11.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import ValidationError, check_option
from accal.estimators.lowfreq import (
    ALPHAS,
    GOF_P_FLAG,
    LOW_BINS,
    MAX_BIN,
    LowFreqModel,
    LowFreqSpectrum,
    shape_values,
)
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
    notes : tuple of str
        Warnings about ``cov``: a residual spectrum that the noise model does not
        describe, noise at the model's steepness limit, a record too short for a
        spectrum (see :func:`linear_estimator_covariance`).
    noise : LowFreqModel or None
        The fitted noise model behind ``cov`` (None for a record too short for it).
    """

    method: str
    order: int
    t0: float
    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    n_used: int
    rms: float
    notes: tuple[str, ...] = field(default=())
    noise: LowFreqModel | None = field(default=None, compare=False)

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
    grid = np.zeros((rows.shape[0], ngrid), dtype=rows.dtype)
    breaks = np.flatnonzero(np.diff(idx) != 1) + 1
    if breaks.size > 64:
        grid[:, idx] = rows
        return grid
    # few gaps: copy the contiguous runs (a scatter is several times slower)
    for a, b in zip((0, *breaks.tolist()), (*breaks.tolist(), idx.size), strict=True):
        grid[:, idx[a] : idx[a] + b - a] = rows[:, a:b]
    return grid


def _midpoint_spectra(
    rows: NDArray[np.float64], m: int, nodes: NDArray[np.int64]
) -> NDArray[np.complex128]:
    """DTFTs of real ``rows`` (shape (k, N)) at the midpoints ``(j + 1/2)/m``, j in ``nodes``.

    ``X((j + ½)/m) = FFT_m(x_t e^{−iπt/m})[j]``; two real rows share one complex FFT
    (``y = a + ib``: ``A_j = (Y_j + conj Y_{m−1−j})/2``, ``B_j = (Y_j − conj Y_{m−1−j})/2i``,
    as node ``m−1−j`` is ``−f`` of node ``j`` and a real row's DTFT is Hermitian).
    """
    k, n = rows.shape
    shift = np.exp(-1j * np.pi * np.arange(n) / m)
    if k % 2:
        rows = np.vstack([rows, np.zeros((1, n))])
    y = np.fft.fft((rows[0::2] + 1j * rows[1::2]) * shift, m, axis=1)
    yj = y[:, nodes]
    yr = y[:, m - 1 - nodes].conj()
    out = np.empty((rows.shape[0], nodes.size), dtype=np.complex128)
    out[0::2] = 0.5 * (yj + yr)
    out[1::2] = -0.5j * (yj - yr)
    return out[:k]


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
    max_bin: int = MAX_BIN,
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
        Estimator weights (:func:`wavelet_weights` or :func:`lsq_weights`); row 0
        is the bias (weights summing to 1), the others sum to 0.
    order : int
        Order of the polynomial that was removed to form ``residual``.
    max_bin : int
        Upper end of the band of the noise-model fit [Fourier bins of the record].

    Returns
    -------
    ndarray, shape (p, p)
        ``G C Gᵀ`` [m²/s⁴ × weight units²].

    Notes
    -----
    1. *Noise model*: ``S(f) = W + A·L_θ(f)``, a white level plus a power law
       ``f^(−α)`` (``0 ≤ α ≤ 2.5``) or an AR(1) Lorentzian, fitted by Whittle
       likelihood to the residual's periodogram: bins 1 … 4 of the Hann-tapered
       residual, with their exact expectation (the fit's projection included),
       and bins 7 … ``max_bin`` of its Hann-tapered first differences; lines
       (ordinates 12× above the model) are left out of the fit.  See
       :mod:`accal.estimators.lowfreq` (Whittle 1953, Robinson 1995,
       Percival & Walden 1993).
    2. *Covariance* of the weights under that model, ``W·G Gᵀ + A·Q_θ`` for the
       best shape ``θ`` (interpolated linearly towards the vertex of a parabola
       through the profile likelihood; white noise alone when no shape is
       clearly better), plus, for each line left out, its excess power at its own
       frequency, with

       .. math:: Q_{θ,ij} = \\int_{-1/2}^{1/2} \\mathrm{Re}[\\tilde G_i(f)\\tilde G_j(f)^*]\\,L_θ(f)\\,df

       (Parseval's theorem for a stationary process; ``G̃`` the DTFT of the
       weights on the nominal grid, gaps as zeros), integrated by the midpoint
       rule at the ``N`` half-integer bins ``(j + ½)/N`` (the lowest 128 nodes one
       by one, log-spaced sums of nodes up to node 2048, the rest as the Parseval
       remainder): 1e-4 from the exact random-walk covariance (the same as on
       ``2N`` or ``8N`` nodes), exact for white noise.  Node 0 covers
       ``[0, 1/T]`` with ``L_θ(1/(2T))``.  The integer bins ``k/N`` instead
       (the periodic, circulant evaluation used before) put a random walk's
       drift variance 4–6× too low, the main cause of the scatter/σ ≈ 3 of
       issue 20.
    3. *The level at f → 0* (``α ≥ 1`` makes ``∫ L_θ`` diverge, so the bias of a
       record — its weights sum to 1 — needs a convention; drift and quadratic
       weights sum to 0 and their integrand ``|G̃|² L_θ ∝ f^(2−α)`` converges for
       ``α < 3``, so no convention enters them):

       * *stationary*: the coloured part is flat below ``1/(2T)`` for the level
         only: ``G̃_i = s_i Ũ + (G̃_i − s_i Ũ)``, ``Ũ`` the DTFT of the mean over
         the used samples, ``s_i = Σ g_i``; the ``|Ũ|²`` term takes
         ``L_θ(max(f, 1/(2T)))`` (on the nodes: node 0 at ``1/(2T)``), everything
         else the unmodified model (the fluctuation terms converge for ``α < 3``).  What white and AR(1)
         noise and power laws up to ``α ≈ 1.3`` get;
       * *pinned at t0*: the coloured part is taken relative to its own value at
         the first sample (weights ``g_i − s_i δ_{t0}``, which sum to 0): the
         random-walk or flicker part of an instrument's bias at ``t0`` *is* its
         bias at ``t0`` (a process with stationary increments,
         Mandelbrot & Van Ness 1968, has no other level to refer to).  Exact for
         a random walk that starts at ``t0``.

       Of the two, the one giving the smaller bias variance is used for each
       shape; for power laws they cross near ``α = 1.3`` (pinned is 3.4–3.8×
       larger at ``α = 1``, 0.34–0.40× at ``α = 2``), so σ is continuous in
       ``α``.  The bias σ under red noise therefore depends on this convention
       (a random walk that began before the record has no defined "true" bias
       at ``t0``); the drift σ does not.

    See ``docs/grace_bias.md`` ("How σ is estimated") for the Monte Carlo.

    References
    ----------
    .. [1] B. B. Mandelbrot & J. W. Van Ness, "Fractional Brownian motions,
       fractional noises and applications", SIAM Review 10, 422–437 (1968).
    .. [2] D. B. Percival & A. T. Walden, *Spectral Analysis for Physical
       Applications*, Cambridge University Press (1993).
    """
    g = np.atleast_2d(np.asarray(weights, dtype=np.float64))
    if np.asarray(t).size <= order + 2:
        return np.full((g.shape[0], g.shape[0]), np.nan)
    return _CovarianceKernel(t, g, order, max_bin).covariances(
        np.asarray(residual, dtype=np.float64)[None, :]
    )[0]


#: Midpoint-quadrature nodes of :class:`_CovarianceKernel` kept one by one at the
#: low end; above, nodes are summed in bins growing by :data:`_QUAD_GROWTH`.
_QUAD_SINGLE = 128
_QUAD_GROWTH = 0.04
#: Nodes summed explicitly; the weights' power above them is a Parseval remainder.
_QUAD_NODES = 2048


class _CovarianceKernel:
    """The residual-independent part of :func:`linear_estimator_covariance`.

    The DFTs of the estimator weights, the shape table of the noise model and the
    quadratic forms ``Q_θ`` depend only on the sample times, so several residuals
    (the axes of one file) share them and cost one FFT each.
    """

    def __init__(
        self, t: ArrayLike, g: NDArray[np.float64], order: int, max_bin: int = MAX_BIN
    ) -> None:
        t = np.asarray(t, dtype=np.float64)
        self.n = t.size
        self.order = order
        self.idx, self.ngrid = _grid_index(t)
        ngrid = self.ngrid
        step = nominal_step(np.diff(t)) if t.size > 1 else 1.0
        used = np.zeros(ngrid, dtype=bool)
        used[self.idx if self.idx is not None else slice(None)] = True
        sp = LowFreqSpectrum(used, step, max_bin, exact_low=True)
        self.spectrum = sp
        p = g.shape[0]
        self.p = p
        self.white_cov = g @ g.T  # white noise of unit variance per sample
        if not sp.ok:
            return
        # (1) DTFTs at the midpoints (j + 1/2)/M, M = N, of: the weights, the mean
        # over the used samples, and c_k = (I − V G)ᵀ (h z_k)/‖h‖, whose inner product
        # with the noise is the Hann-tapered residual's DFT at bin k = 1 … LOW_BINS
        # (tapered so that a line in the band does not leak into them)
        m = ngrid
        pos = np.arange(self.n) if self.idx is None else self.idx
        hann = np.sin(np.pi * (pos + 0.5) / ngrid) ** 2
        hann /= np.sqrt(np.dot(hann, hann))
        z1 = np.exp((-2j * np.pi / ngrid) * pos)
        self.zlow = np.empty((self.n, LOW_BINS), dtype=np.complex128)
        self.zlow[:, 0] = hann * z1
        for j in range(1, LOW_BINS):
            np.multiply(self.zlow[:, j - 1], z1, out=self.zlow[:, j])
        vander = np.vander(t - t[0], p, increasing=True)  # the basis of G's coefficients
        beta = self.zlow.T @ vander  # c_k = h z_k − Σ_i beta_ki g_i
        # Σ_t |c_k|² = Σ|h z_k|² − 2 Re Σ_i beta_ki (g_i · conj(h z_k)) + beta_k^H (g gᵀ) beta_k
        gw = g @ self.zlow.conj()  # (p, LOW_BINS)
        c_total = (
            np.sum(np.abs(self.zlow) ** 2, axis=0)
            - 2.0 * np.einsum("ki,ik->k", beta, gw).real
            + np.einsum("ki,ij,kj->k", beta.conj(), g @ g.T, beta).real
        )
        rows = np.empty((p + 2, self.n))
        rows[:p] = g
        rows[p] = 1.0 / self.n
        rows[p + 1] = hann
        # nodes j < nj (f < nj/M) are summed node by node or in bins; above them the
        # weights' power is a small tail, taken from Parseval (its total minus the
        # nodes below) and given L_θ at 2·nj/M (at most 1/2)
        nj = min(_QUAD_NODES, m // 2)  # f < 1/2: the other half is the mirror
        jj = np.arange(nj)
        # nodes used: 0 … L−1 (L = nj + LOW_BINS) and the mirrored −f nodes m−L … m−1
        span = nj + LOW_BINS
        if 2 * span < m:
            wanted = np.concatenate([np.arange(span), np.arange(m - span, m)])

            def col(node: NDArray[np.int64]) -> NDArray[np.int64]:
                return np.where(node < span, node, node - m + 2 * span)
        else:
            wanted = np.arange(m)

            def col(node: NDArray[np.int64]) -> NDArray[np.int64]:
                return node

        spec = _midpoint_spectra(_on_grid(rows, self.idx, ngrid), m, wanted)
        gs, us = spec[:p, :nj], spec[p, :nj]
        # C_k(±f) = H(±f + k/N) − Σ_i beta_ki G_i(±f): +f + k/N is node j + k, −f is
        # node M−1−j (c_k is complex: both signs)
        cpow = np.zeros((LOW_BINS, nj))
        neg = m - 1 - jj
        for j in range(LOW_BINS):
            for nodes in (jj, neg):
                c = spec[p + 1, col((nodes + j + 1) % m)] - beta[j] @ spec[:p, col(nodes)]
                cpow[j] += c.real**2 + c.imag**2
        # Re(G̃_i G̃_j*) at the tapered ordinates' frequencies k/N (between nodes k−1, k)
        ks = np.arange(sp.kmin, sp.kmax + 1)
        lo_k, hi_k = spec[:p, col(ks - 1)], spec[:p, col(ks)]
        pair = np.einsum("ib,jb->ijb", lo_k, lo_k.conj()).real
        pair += np.einsum("ib,jb->ijb", hi_k, hi_k.conj()).real
        self.pair_k = 0.5 * pair
        s = g.sum(axis=1)
        # (2) node bins: the lowest one by one, then log-spaced (L_θ is smooth there),
        # then the tail; every sum in units of the frequency integral
        edges = list(range(min(_QUAD_SINGLE, nj) + 1))
        while edges[-1] < nj:
            edges.append(edges[-1] + max(1, int(_QUAD_GROWTH * edges[-1])))
        edges[-1] = nj
        e = np.asarray(edges)
        starts = e[:-1]
        nu = np.sqrt(e[:-1] + 0.5) * np.sqrt(e[1:] - 0.5) / m  # midpoint / geometric centre
        nu = np.append(nu, min(2.0 * nj / m, 0.5))
        pin = gs - s[:, None]  # g − s·δ_t0
        uu = us.real**2 + us.imag**2
        p_pin = np.einsum("ib,jb->ijb", pin, pin.conj()).real
        p_st = np.einsum("ib,jb->ijb", gs, gs.conj()).real - np.multiply.outer(np.outer(s, s), uu)
        gg = g @ g.T
        g0 = np.outer(s, g[:, 0])
        totals = (  # Parseval: the integrals over the whole circle
            gg - g0 - g0.T + np.outer(s, s),
            gg - np.outer(s, s) / self.n,
            1.0 / self.n,
            c_total,
        )
        binned = []
        for arr, scale, total in zip(
            (p_pin, p_st, uu, cpow), (2.0 / m, 2.0 / m, 2.0 / m, 1.0 / m), totals, strict=True
        ):
            sums = np.add.reduceat(arr, starts, axis=-1) * scale
            tail = total - sums.sum(axis=-1)
            binned.append(np.concatenate([sums, np.asarray(tail)[..., None]], axis=-1))
        p_pin, p_st, uu, cpow = binned
        shapes = shape_values(sp.kinds, sp.params, sp.f_ref, nu)  # (n_shapes, nbins)
        flat = shape_values(sp.kinds, sp.params, sp.f_ref, np.maximum(nu, 0.5 / ngrid))
        q_pin = np.einsum("ijb,sb->sij", p_pin, shapes)
        q_st = np.einsum("ijb,sb->sij", p_st, shapes) + np.multiply.outer(flat @ uu, np.outer(s, s))
        self.pinned = q_pin[:, 0, 0] < q_st[:, 0, 0]
        self.q = np.where(self.pinned[:, None, None], q_pin, q_st)
        # (3) exact expectations of the low ordinates |c_kᵀ e|² (c_k ⊥ the polynomial,
        # so no convention at f → 0 enters them)
        sp.add_low(totals[3], shapes @ cpow.T)

    def fit(
        self, residuals: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], list[LowFreqModel | None], list[tuple[str, ...]]]:
        """Covariances (k, p, p), noise models and notes of residual rows (k, n)."""
        k = residuals.shape[0]
        sp = self.spectrum
        if not sp.ok:
            # too few Fourier bins for a spectrum: white noise from the residual
            dof = max(self.n - self.order - 1, 1)
            var = np.einsum("ij,ij->i", residuals, residuals) / dof
            note = (
                f"{self.n} samples are too few for a noise spectrum: sigma assumes white noise",
            )
            return var[:, None, None] * self.white_cov, [None] * k, [note] * k
        low = residuals @ self.zlow
        low = low.real**2 + low.imag**2
        pgram = sp.periodograms(_on_grid(residuals, self.idx, self.ngrid), low)
        fitted = sp.fit_robust(pgram)
        covs = np.empty((k, self.p, self.p))
        models: list[LowFreqModel | None] = []
        notes: list[tuple[str, ...]] = []
        for r in range(k):
            s, nb, wt = sp.select(fitted, r)
            if s < 0:  # white noise
                covs[r] = fitted["W_white"][r] * self.white_cov + self._lines(pgram[r], fitted, r)
                model = sp.model(fitted, r, pgram[r])
                models.append(model)
                notes.append(_noise_notes(model))
                continue
            cov = np.zeros((self.p, self.p))
            for shape, weight in ((s, 1.0 - wt), (nb, wt)):
                if weight:
                    cov += weight * (
                        fitted["W"][r, shape] * self.white_cov
                        + fitted["A"][r, shape] * self.q[shape]
                    )
            covs[r] = cov + self._lines(pgram[r], fitted, r)
            model = sp.model(fitted, r, pgram[r])
            models.append(model)
            notes.append(_noise_notes(model))
        return covs, models, notes

    def _lines(self, pgram_row: NDArray, fitted: dict[str, NDArray], row: int) -> NDArray:
        """Covariance of the lines left out of the fit: their excess at their frequency.

        A tapered ordinate ``k`` estimates ``S_d(f_k) = 4 sin²(π f_k) S(f_k)`` over a
        bin ``1/N``; its excess over the model, ``I_k − E_k``, adds
        ``2/N · Re(G̃_i G̃_j*)(f_k) · (I_k − E_k)/(4 sin²(π f_k))`` (both signs of f).
        """
        sp = self.spectrum
        out = ~fitted["keep"][row, sp.n_low :]
        if not out.any():
            return np.zeros((self.p, self.p))
        excess = np.maximum(pgram_row - sp.expected(fitted, row), 0.0)[sp.n_low :][out]
        k = np.arange(sp.kmin, sp.kmax + 1)[out]
        s_line = excess / (4.0 * np.sin(np.pi * k / self.ngrid) ** 2)
        return np.einsum("ijk,k->ij", self.pair_k[..., out], s_line) * (2.0 / self.ngrid)

    def covariances(self, residuals: NDArray[np.float64]) -> NDArray[np.float64]:
        """``G C Gᵀ`` for each row of ``residuals`` (shape (k, n)) -> (k, p, p)."""
        return self.fit(residuals)[0]


def _noise_notes(model: LowFreqModel) -> tuple[str, ...]:
    """Notes on a fitted noise model: a spectrum the model does not describe."""
    notes = []
    if model.p_misfit < GOF_P_FLAG:
        notes.append(
            f"noise spectrum misfit: the residual's periodogram below {MAX_BIN} Fourier bins "
            f"is not white + power law / AR(1) (chi2 {model.chi2:.0f} for {model.dof} dof, "
            f"p = {model.p_misfit:.1e}); sigma may be off"
        )
    if model.kind == "power" and model.alpha >= ALPHAS[-1] - 0.025:
        notes.append(
            f"residual noise as steep as f^-{ALPHAS[-1]:g} (the model's limit): "
            "sigma may be too small"
        )
    return tuple(notes)


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
    covs, models, notes = (kernel or _CovarianceKernel(tu, g, order)).fit(resid)
    return [
        TrendFit(
            method=method,
            order=order,
            t0=float(tu[0]),
            coef=coef[:, j].copy(),
            cov=covs[j],
            n_used=int(tu.size),
            rms=float(np.sqrt(np.dot(resid[j], resid[j]) / tu.size)),
            notes=notes[j],
            noise=models[j],
        )
        for j in range(a.shape[1])
    ]
