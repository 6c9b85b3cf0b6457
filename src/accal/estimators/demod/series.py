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


def _gains(res: DemodResult) -> NDArray[np.float64] | None:
    """(n, 2, 2, 2): the response of the estimate of axis ``e`` to the in-period shape
    ``k`` (slope ``u``, curvature ``u² − ⟨u²⟩``) of the signal on axis ``s``, as
    ``[period, e, s, k]`` (``shape_gain`` on the diagonal, ``cross_gain`` off it; None
    without ``shape_gain``)."""
    n = np.asarray(res.period_index).size
    same = np.asarray(res.shape_gain)
    if same.shape != (n, 2, 2):
        return None
    g = np.zeros((n, 2, 2, 2))
    cross = np.asarray(getattr(res, "cross_gain", np.empty((0, 2, 2))))
    for e in (0, 1):
        g[:, e, e] = same[:, e]
        if cross.shape == (n, 2, 2):
            g[:, e, 1 - e] = cross[:, e]
    return g


def _noise_sigma(res: DemodResult) -> NDArray[np.float64]:
    """(n, 2): the σ of ``(a_Y, a_Z)`` without the leakage :func:`with_signal_leak`
    put in them."""
    sig = np.column_stack([res.sigma_Y, res.sigma_Z]).astype(np.float64)
    added = np.asarray(getattr(res, "signal_leak_added", np.empty((0, 2))), dtype=np.float64)
    if added.shape != sig.shape:
        return sig
    return np.sqrt(np.maximum(sig**2 - added**2, 0.0))


def _leak_estimates(res: DemodResult, central_only: bool = False) -> dict[str, NDArray]:
    """Each period's leakage estimate and its noise variance (module notes of
    :func:`signal_leakage` and :func:`period_leakage`).

    Returns ``leak``, ``var`` (n, 2), the slope's part ``leak_b``, ``var_b`` (n, 2),
    ``model`` (n, 2: where extrapolated from three periods on one side, the difference
    to the line through the two nearest, the extrapolation's own uncertainty; else 0)
    and ``central`` (n,): NaN where not estimable.  The slope ``b`` and curvature ``c`` of
    each axis' signal are differences of its values in the neighbouring periods
    (weights ``bw``, ``cw`` on the rows ``R``); ``L_e = Σ_s g_b[e, s] b_s + g_c[e, s] c_s``
    over both axes ``s`` (:func:`_gains`: with four rest angles the mean model's
    value of one axis follows the other's slope, QA: 54σ RMS on a clean run).
    """
    g = _gains(res)
    n = np.asarray(res.period_index).size
    a_raw = np.column_stack([res.a_Y, res.a_Z]).astype(np.float64)
    sg = _noise_sigma(res)
    out = _leak_pass(res.period_index, a_raw, sg, g, central_only)
    if g is None or n < 3:
        return out
    for _ in range(LEAK_PASSES - 1):
        # the neighbours' values hold their own leakage (a run that starts mid-pattern:
        # every period lopsided, and the first period's, extrapolated from the next
        # three, was 2.7e-13 for an error of 6.4e-12): take it out and estimate again
        a = a_raw - np.nan_to_num(out["leak"])
        out = _leak_pass(res.period_index, a, sg, g, central_only)
    return out


#: Passes of :func:`_leak_estimates` (each with the values less the last one's leakage).
LEAK_PASSES = 4


def _leak_pass(period_index, a, sg, g, central_only: bool) -> dict[str, NDArray]:
    """One pass of :func:`_leak_estimates` on the values ``a`` (n, 2) with noise σ ``sg``."""
    idx = np.asarray(period_index)
    n = idx.size
    out = {k: np.full((n, 2), np.nan) for k in ("leak", "var", "leak_b", "var_b")}
    out["model"] = np.zeros((n, 2))
    out["central"] = np.zeros(n, dtype=bool)
    if n < 3 or g is None:
        return out
    where = {int(k): j for j, k in enumerate(idx)}

    def at(j: int, d: int) -> int:
        return where.get(int(idx[j]) + d, -1)

    for j in range(n):
        p1, m1 = at(j, 1), at(j, -1)
        if p1 >= 0 and m1 >= 0:
            rows = [m1, j, p1]
            bw, cw = np.array([-0.5, 0.0, 0.5]), np.array([0.5, -1.0, 0.5])
            out["central"][j] = True
        elif central_only:
            continue
        else:
            side = -1 if m1 >= 0 else 1  # the neighbours' side: before or after
            near = [at(j, side * d) for d in (1, 2, 3)]
            if near[1] < 0:
                continue
            if near[2] >= 0:  # a quadratic through the three, at this period
                rows, bw, cw = near, np.array([2.5, -4.0, 1.5]), np.array([0.5, -1.0, 0.5])
            else:  # a line through the two
                rows, bw, cw = near[:2], np.array([1.0, -1.0]), np.zeros(2)
            bw = -side * bw  # u → −u turns the slope's sign
        for e in (0, 1):
            # weights on the rows' values of each source axis s: (2, len(rows))
            wb = g[j, e, :, 0][:, None] * bw[None, :]
            w = wb + g[j, e, :, 1][:, None] * cw[None, :]
            vals, sig = a[rows].T, sg[rows].T
            out["leak"][j, e] = float(np.sum(w * vals))
            out["var"][j, e] = float(np.sum((w * sig) ** 2))
            out["leak_b"][j, e] = float(np.sum(wb * vals))
            out["var_b"][j, e] = float(np.sum((wb * sig) ** 2))
            if len(rows) == 3 and not out["central"][j]:
                # extrapolated: the line through the two nearest is the other guess
                lin = g[j, e, :, 0] @ (-side * (vals[:, 0] - vals[:, 1]))
                out["model"][j, e] = abs(out["leak"][j, e] - float(lin))
    return out


def signal_leakage(res: DemodResult) -> SignalLeakage:
    """Leakage of the signal's in-period slope and curvature into each period's value.

    Within period ``i`` the signal is ``a(u) ≈ ā + b u + c (u² − ⟨u²⟩)`` (``u`` in
    periods from ``t_mid``); the estimator returns ``ā + g_b b + g_c c``
    (``res.shape_gain``; 0 for a layout symmetric about ``t_mid`` and an exact
    model, eqs. 18–19), plus the same of the other axis' signal through
    ``res.cross_gain`` (not 0 with four rest angles under the mean model).  ``b`` and
    ``c`` are estimated from the neighbouring periods' values,
    ``b = (a_{i+1} − a_{i−1})/2``, ``c = (a_{i+1} − 2a_i + a_{i−1})/2`` (central
    differences: exact for a quadratic signal), so the leakage estimate ``L_i``
    carries noise of variance ``Σ_j w_j² σ_j²`` (``w`` its weights on the values,
    independent periods, eq. 23 with Rd[1] ≈ 0), which is removed from the mean
    square.  The σ are the noise's (without the leakage :func:`with_signal_leak`
    adds).

    Parameters
    ----------
    res : DemodResult
        A demodulation (needs ``shape_gain``).

    Returns
    -------
    SignalLeakage
    """
    out = {k: np.full(2, np.nan) for k in ("rms", "rms_sigma", "ratio", "ratio_slope", "max")}
    est = _leak_estimates(res, central_only=True)
    i = np.flatnonzero(est["central"])
    if not i.size:
        return SignalLeakage(n=0, **out)
    sg = _noise_sigma(res)
    for ax in (0, 1):
        leak, var = est["leak"][i, ax], est["var"][i, ax]
        out["rms"][ax] = np.sqrt(max(float(np.mean(leak**2) - np.mean(var)), 0.0))
        out["rms_sigma"][ax] = float(np.sqrt(np.mean(sg[i, ax] ** 2)))
        out["ratio"][ax] = out["rms"][ax] / out["rms_sigma"][ax]
        out["max"][ax] = float(np.max(np.abs(leak)))
        ms_b = float(np.mean(est["leak_b"][i, ax] ** 2) - np.mean(est["var_b"][i, ax]))
        out["ratio_slope"][ax] = np.sqrt(max(ms_b, 0.0)) / out["rms_sigma"][ax]
    return SignalLeakage(n=int(i.size), **out)


#: A period's estimated leakage (:func:`period_leakage`) enters its σ when it exceeds
#: this many σ of its own estimate (by chance in 0.27 % of the periods of a clean run).
LEAK_SIGNIFICANT = 3.0


def period_leakage(res: DemodResult) -> tuple[_F64, _F64]:
    """Each period's leakage of the signal's in-period slope and curvature, and its σ.

    As :func:`signal_leakage` (both axes' signal), period by period, and also where a
    neighbour is missing: a period cut by a gap or by the run's end has its samples
    on one side of ``t_mid``, so its ``g_b`` is large (QA: a period that lost its last
    third to a 3,000 s gap was 167σ off under the ``mean`` model, the signal falling
    by 4.4e-10 m/s² per period).  With both neighbours kept, central differences
    (exact for a quadratic signal); with neighbours on one side only, the quadratic
    through the three nearest there (``b = a₋₁ − a₋₂ + 3c``,
    ``c = (a₋₁ − 2a₋₂ + a₋₃)/2`` before it, mirrored after it), or the line through
    two; else NaN.  The σ is that of the estimate from the neighbours' noise
    (independent periods, eq. 23 with Rd[1] ≈ 0).

    Parameters
    ----------
    res : DemodResult
        A demodulation (needs ``shape_gain``).

    Returns
    -------
    leak, sd : ndarray, shape (n, 2)
        The estimate for ``(a_Y, a_Z)`` [m s⁻²] and its σ (NaN where not estimable).
    """
    est = _leak_estimates(res)
    return est["leak"], np.sqrt(est["var"])


def with_signal_leak(res: DemodResult) -> DemodResult:
    """``res`` with each period's leakage (:func:`period_leakage`) as ``signal_leak``,
    and in ``sigma_Y``/``sigma_Z`` (added in quadrature, with the uncertainty of its
    extrapolation where it was extrapolated) where the two together exceed
    :data:`LEAK_SIGNIFICANT` σ of its estimate: the σ of a period then covers the difference between the
    period's mean and what the signal model returns for it (QA: a run starting
    mid-pattern, its first period 10.6σ off with the leakage of the quadratic through
    the next three alone).
    """
    est = _leak_estimates(res)
    leak = est["leak"]
    size = np.hypot(leak, est["model"])  # the leakage and its extrapolation's doubt
    with np.errstate(invalid="ignore"):
        big = size > LEAK_SIGNIFICANT * np.sqrt(est["var"])
    sig = np.column_stack([res.sigma_Y, res.sigma_Z]).astype(np.float64)
    add = np.where(big, size, 0.0)
    sig = np.where(big, np.hypot(sig, add), sig)
    return replace(
        res,
        sigma_Y=sig[:, 0],
        sigma_Z=sig[:, 1],
        signal_leak=leak,
        signal_leak_in_sigma=big,
        signal_leak_added=add,
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
