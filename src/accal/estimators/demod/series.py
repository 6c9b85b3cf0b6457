"""Statistics of the series of per-period values.

σ of the mean of correlated periods (:func:`sigma_mean`, Fig. 5), the eq. 24
sinusoid fit with the banded covariance of ``Rd[k]`` (:func:`fit_sinusoid`) and the
leakage of a signal's in-period slope and curvature (:func:`signal_leakage`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import ValidationError
from .records import _F64, DemodResult


@dataclass(frozen=True)
class SinusoidFit:
    """Fit of ``α cos(2π f* t) + β sin(2π f* t) [+ c]`` to per-period values (eq. 24).

    Attributes
    ----------
    alpha, beta : float
        Amplitudes [m s⁻²].
    cov : ndarray, shape (2, 2) or (3, 3)
        Covariance of ``(α, β)``, or of ``(α, β, c)`` with the constant term [m² s⁻⁴].
    f_star : float
        Frequency [Hz].
    t_origin : float
        Time origin of the cos/sin [s] (``t`` is used as given).
    offset : float
        The constant term ``c`` [m s⁻²]; NaN when it was not fitted (eq. 24 as
        in the paper).
    """

    alpha: float
    beta: float
    cov: _F64
    f_star: float
    t_origin: float = 0.0
    offset: float = float("nan")

    @property
    def constant(self) -> bool:
        """True if the constant term was fitted."""
        return self.cov.shape[0] == 3

    @property
    def sigma_alpha(self) -> float:
        """``sqrt(Cov(α, α))`` [m s⁻²]."""
        return float(np.sqrt(self.cov[0, 0]))

    @property
    def sigma_beta(self) -> float:
        """``sqrt(Cov(β, β))`` [m s⁻²]."""
        return float(np.sqrt(self.cov[1, 1]))

    @property
    def sigma_offset(self) -> float:
        """``sqrt(Cov(c, c))`` [m s⁻²] (NaN without the constant term)."""
        return float(np.sqrt(self.cov[2, 2])) if self.constant else float("nan")


def sigma_mean(rd: ArrayLike, n: int, *, index: ArrayLike | None = None) -> float:
    """σ of the mean of ``n`` per-period values with autocovariance ``rd`` (Fig. 5).

    Consecutive periods: ``Var = (n Rd[0] + 2 Σ_{k=1}^{n-1} (n-k) Rd[k]) / n²``.
    With ``index`` (the periods kept when some were dropped):
    ``Var = (n Rd[0] + 2 Σ_k c_k Rd[k]) / n²`` where ``c_k`` counts the pairs of
    kept periods ``k`` apart, so only the lags that occur are needed (every
    other period dropped: no odd lag).  Lags beyond ``len(rd)`` are taken as 0.

    Parameters
    ----------
    rd : array_like
        Rd[k] [m² s⁻⁴]; NaN for a lag no pair of kept periods had (unknown).
    n : int
        Number of periods averaged (``len(index)`` when given).
    index : array_like of int, optional
        Increasing period indices of the averaged values.

    Returns
    -------
    float
        [m s⁻²]; NaN when a lag that occurs has an unknown ``Rd``.
    """
    rd = np.asarray(rd, float)
    if index is None:
        n = int(n)
        k = np.arange(1, min(n, rd.size))
        counts = (n - k).astype(float)
    else:
        idx = np.asarray(index, np.int64)
        n = idx.size
        k = np.arange(1, min(int(idx[-1] - idx[0]) + 1 if n else 1, rd.size))
        counts = np.array([np.count_nonzero(np.isin(idx + j, idx)) for j in k], dtype=float)
        k = k[counts > 0]
        counts = counts[counts > 0]
    if n < 1:
        return float("nan")
    var = (n * rd[0] + 2.0 * np.sum(counts * rd[k])) / n**2
    return float(np.sqrt(var))


@dataclass(frozen=True)
class SignalLeakage:
    """How much a signal's variation within a period leaks into the per-period values.

    Attributes
    ----------
    rms : ndarray, shape (2,)
        RMS over the periods of the estimated leakage into ``(a_Y, a_Z)``, the noise of
        the estimate removed (0 when it is all noise) [m s⁻²].
    rms_sigma : ndarray, shape (2,)
        RMS of the reported σ over the same periods [m s⁻²].
    ratio : ndarray, shape (2,)
        ``rms / rms_sigma``.
    ratio_slope : ndarray, shape (2,)
        The same for the slope's leakage alone (what ``signal_model="affine"``
        removes; the rest is the curvature's, which a shorter τ reduces).
    max : ndarray, shape (2,)
        Largest ``|leakage|`` estimate of a period (noise included) [m s⁻²].
    n : int
        Periods with both neighbours kept (the estimate needs them).
    """

    rms: _F64
    rms_sigma: _F64
    ratio: _F64
    ratio_slope: _F64
    max: _F64
    n: int


def signal_leakage(res: DemodResult) -> SignalLeakage:
    """Leakage of the signal's in-period slope and curvature into each period's value.

    Within period ``i`` the signal is ``a(u) ≈ ā + b u + c (u² − ⟨u²⟩)`` (``u`` in
    periods from ``t_mid``); the estimator returns ``ā + g_b b + g_c c``
    (``res.shape_gain``; 0 for a layout symmetric about ``t_mid`` and an exact
    model, eqs. 18–19).  ``b`` and ``c`` are estimated from the neighbouring
    periods' values, ``b = (a_{i+1} − a_{i−1})/2``, ``c = (a_{i+1} − 2a_i + a_{i−1})/2``
    (central differences: exact for a quadratic signal), so the leakage estimate
    ``L_i = g_b b + g_c c`` carries noise of variance ``Σ_j w_j² σ_j²``
    (``w`` its weights on the three values, independent periods, eq. 23 with
    Rd[1] ≈ 0), which is removed from the mean square.

    Parameters
    ----------
    res : DemodResult
        A demodulation (needs ``shape_gain``).

    Returns
    -------
    SignalLeakage
    """
    idx = np.asarray(res.period_index)
    gain = np.asarray(res.shape_gain)
    n = idx.size
    out = {k: np.full(2, np.nan) for k in ("rms", "rms_sigma", "ratio", "ratio_slope", "max")}
    if n < 3 or gain.shape != (n, 2, 2):
        return SignalLeakage(n=0, **out)
    mid = np.flatnonzero(idx[2:] - idx[:-2] == 2)  # i-1, i, i+1 all kept
    i = mid + 1
    for ax, (a, sg) in enumerate(((res.a_Y, res.sigma_Y), (res.a_Z, res.sigma_Z))):
        a, sg = np.asarray(a, float), np.asarray(sg, float)
        if not i.size:
            continue
        gb, gc = gain[i, ax, 0], gain[i, ax, 1]
        b = 0.5 * (a[i + 1] - a[i - 1])
        c = 0.5 * (a[i + 1] - 2.0 * a[i] + a[i - 1])
        leak = gb * b + gc * c
        var = (
            (0.5 * (gc - gb) * sg[i - 1]) ** 2
            + (gc * sg[i]) ** 2
            + (0.5 * (gc + gb) * sg[i + 1]) ** 2
        )
        ms = float(np.mean(leak**2) - np.mean(var))
        out["rms"][ax] = np.sqrt(max(ms, 0.0))
        out["rms_sigma"][ax] = float(np.sqrt(np.mean(sg[i] ** 2)))
        out["ratio"][ax] = out["rms"][ax] / out["rms_sigma"][ax]
        out["max"][ax] = float(np.max(np.abs(leak)))
        ms_b = float(
            np.mean((gb * b) ** 2) - np.mean((0.5 * gb) ** 2 * (sg[i - 1] ** 2 + sg[i + 1] ** 2))
        )
        out["ratio_slope"][ax] = np.sqrt(max(ms_b, 0.0)) / out["rms_sigma"][ax]
    return SignalLeakage(n=int(i.size), **out)


#: A period's estimated leakage (:func:`period_leakage`) enters its σ when it exceeds
#: this many σ of its own estimate (by chance in 0.27 % of the periods of a clean run).
LEAK_SIGNIFICANT = 3.0


def period_leakage(res: DemodResult) -> tuple[_F64, _F64]:
    """Each period's leakage of the signal's in-period slope and curvature, and its σ.

    As :func:`signal_leakage` (``L_i = g_b b + g_c c``, ``g`` the period's
    ``shape_gain``), period by period, and also where a neighbour is missing: a
    period cut by a gap or by the run's end has its samples on one side of ``t_mid``,
    so its ``g_b`` is large (QA: a period that lost its last third to a 3,000 s gap was
    167σ off under the ``mean`` model, the signal falling by 4.4e-10 m/s² per period).
    With both neighbours kept, central differences (exact for a quadratic signal);
    with neighbours on one side only, the quadratic through the three nearest there
    (``b = a₋₁ − a₋₂ + 3c``, ``c = (a₋₁ − 2a₋₂ + a₋₃)/2`` before it, mirrored after
    it), or the line through two; else NaN.  The σ is that of the estimate from the neighbours' noise (independent
    periods, eq. 23 with Rd[1] ≈ 0).

    Parameters
    ----------
    res : DemodResult
        A demodulation (needs ``shape_gain``).

    Returns
    -------
    leak, sd : ndarray, shape (n, 2)
        The estimate for ``(a_Y, a_Z)`` [m s⁻²] and its σ (NaN where not estimable).
    """
    idx = np.asarray(res.period_index)
    gain = np.asarray(res.shape_gain)
    n = idx.size
    leak, sd = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    if n < 3 or gain.shape != (n, 2, 2):
        return leak, sd
    where = {int(k): j for j, k in enumerate(idx)}

    def at(j: int, d: int) -> int:
        return where.get(int(idx[j]) + d, -1)

    for ax, (a, sg) in enumerate(((res.a_Y, res.sigma_Y), (res.a_Z, res.sigma_Z))):
        a, sg = np.asarray(a, float), np.asarray(sg, float)
        for j in range(n):
            gb, gc = gain[j, ax, 0], gain[j, ax, 1]
            p1, m1 = at(j, 1), at(j, -1)
            if p1 >= 0 and m1 >= 0:
                b = 0.5 * (a[p1] - a[m1])
                c = 0.5 * (a[p1] - 2.0 * a[j] + a[m1])
                var = (
                    (0.5 * (gc - gb) * sg[m1]) ** 2
                    + (gc * sg[j]) ** 2
                    + (0.5 * (gc + gb) * sg[p1]) ** 2
                )
                leak[j, ax], sd[j, ax] = gb * b + gc * c, np.sqrt(var)
                continue
            side = -1 if m1 >= 0 else 1  # the neighbours' side: before or after
            near = [at(j, side * d) for d in (1, 2, 3)]
            if near[1] < 0:
                continue
            if near[2] >= 0:  # a quadratic through the three, at this period
                bw, cw, rows = np.array([2.5, -4.0, 1.5]), np.array([0.5, -1.0, 0.5]), near
            else:  # a line through the two
                bw, cw, rows = np.array([1.0, -1.0]), np.zeros(2), near[:2]
            w = -side * gb * bw + gc * cw  # u → −u turns the slope's sign
            leak[j, ax] = float(w @ a[rows])
            sd[j, ax] = float(np.sqrt(np.sum((w * sg[rows]) ** 2)))
    return leak, sd


def with_signal_leak(res: DemodResult) -> DemodResult:
    """``res`` with each period's leakage (:func:`period_leakage`) as ``signal_leak``,
    and in ``sigma_Y``/``sigma_Z`` (added in quadrature) where it exceeds
    :data:`LEAK_SIGNIFICANT` σ of its estimate: the σ of a period then covers the
    difference between the period's mean and what the signal model returns for it.
    """
    leak, sd = period_leakage(res)
    with np.errstate(invalid="ignore"):
        big = np.abs(leak) > LEAK_SIGNIFICANT * sd
    sig = np.column_stack([res.sigma_Y, res.sigma_Z]).astype(np.float64)
    sig = np.where(big, np.hypot(sig, np.where(big, leak, 0.0)), sig)
    return replace(
        res, sigma_Y=sig[:, 0], sigma_Z=sig[:, 1], signal_leak=leak, signal_leak_in_sigma=big
    )


def fit_sinusoid(
    t: ArrayLike,
    a: ArrayLike,
    f_star: float,
    *,
    rd: ArrayLike | None = None,
    cov: ArrayLike | None = None,
    t_origin: float = 0.0,
    index: ArrayLike | None = None,
    constant: bool = False,
) -> SinusoidFit:
    """Fit ``α cos(2π f*(t - t0)) + β sin(2π f*(t - t0)) [+ c]`` to per-period values (eq. 24).

    Generalised least squares with the full covariance of the points (from
    ``rd``, or ``cov``); ordinary LS if neither is given (then ``cov`` of the
    result is the formal one with unit variance).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times of the points (e.g. ``i·τ``, i = 1..n, as in the paper) [s].
    a : array_like, shape (n,)
        Values [m s⁻²].
    f_star : float
        Known frequency f* [Hz].
    rd : array_like, optional
        Rd[k] (eq. 23) of the points, lag k in periods; lags beyond its length
        are 0 [m² s⁻⁴].  The covariance is banded and solved as such, so a year
        of periods costs O(n).
    cov : array_like, shape (n, n), optional
        Full covariance of the points [m² s⁻⁴].
    t_origin : float
        Time origin ``t0`` [s]; the covariance of (α, β) depends on it.
    index : array_like of int, shape (n,), optional
        Period index of each point, for ``rd`` when some periods are missing
        (``Cov(i, j) = Rd[|index_i - index_j|]``); consecutive by default.
    constant : bool
        Also fit a constant ``c``.  Eq. 24 has none (the default, which
        reproduces the paper): a non-zero mean acceleration then leaks into α
        and β unless the points span whole periods of the sinusoid.

    Returns
    -------
    SinusoidFit

    Raises
    ------
    ValidationError
        Shapes that do not match, or fewer points than parameters.
    """
    t = np.asarray(t, float) - t_origin
    y = np.asarray(a, float)
    n = t.size
    if y.shape != t.shape:
        raise ValidationError(f"t and a must have the same shape, got {t.shape} and {y.shape}")
    cols = [np.cos(2 * np.pi * f_star * t), np.sin(2 * np.pi * f_star * t)]
    if constant:
        cols.append(np.ones(n))
    A = np.column_stack(cols)
    if n < A.shape[1]:
        raise ValidationError(f"need at least {A.shape[1]} points for the sinusoid fit, got {n}")
    rhs = np.column_stack([A, y])
    if cov is not None:
        sol = np.linalg.solve(np.asarray(cov, float), rhs)
    elif rd is not None:
        idx = np.arange(n) if index is None else np.asarray(index, np.int64)
        if idx.shape != (n,) or np.any(np.diff(idx) <= 0):
            raise ValidationError("index must hold one increasing period index per point")
        sol = _solve_banded_rd(np.asarray(rd, float), idx, rhs)
    else:
        sol = rhs
    ci_a, ci_y = sol[:, :-1], sol[:, -1]
    v = np.linalg.inv(A.T @ ci_a)
    coef = v @ (A.T @ ci_y)
    return SinusoidFit(
        float(coef[0]),
        float(coef[1]),
        v,
        float(f_star),
        float(t_origin),
        float(coef[2]) if constant else float("nan"),
    )


def _solve_banded_rd(rd: NDArray, idx: NDArray, rhs: NDArray) -> NDArray:
    """``C⁻¹ rhs`` for ``C[i, j] = rd[|idx_i - idx_j|]`` (0 beyond ``len(rd)``), banded."""
    from scipy.linalg import solve_banded

    n = idx.size
    u = min(rd.size - 1, n - 1)
    if u <= 0:
        return rhs / rd[0]
    ab = np.zeros((2 * u + 1, n))
    ab[u] = rd[0]
    for o in range(1, u + 1):
        lag = idx[o:] - idx[:-o]
        vals = np.where(lag < rd.size, rd[np.minimum(lag, rd.size - 1)], 0.0)
        ab[u - o, o:] = vals  # C[j - o, j]
        ab[u + o, :-o] = vals  # C[j + o, j]
    return solve_banded((u, u), ab, rhs)
