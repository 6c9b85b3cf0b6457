"""Demodulation of rotating-platform accelerometer data (Lenoir et al. 2013).

``accal demod`` calls :func:`demodulate` (data → per-period unbiased accelerations
with uncertainties) and :func:`budget` (pattern → Rd[k], σ over an integration
time, optimal modulation period).  Everything here is a pure function over
arrays returning frozen dataclasses.

Method (equation numbers of the paper)
--------------------------------------
Per modulation period of ``q = τ·fs`` samples, with the rest mask ``M``
(section 4.2: discrete θ̇ = 0 and θ̈ = 0), ``Ṽa = M Va`` and ``Va = [1]`` (signal
mean, eq. 18) or ``[1, t]`` (affine signal, eq. 19):

* ``solver="eq14"``: ``âY = (Ṽa'Ṽa)⁻¹ Ṽa'(Λc my - Λs mz)``,
  ``âZ = (Ṽa'Ṽa)⁻¹ Ṽa'(Λs my + Λc mz)`` (eq. 14 normalised as in section 5.1);
  exact when eq. 16 holds, ``Ṽa' Λ V̂b = 0``.  The normalised leakage
  ``max |ṽ' Λ b̂| / (|ṽ| |M b̂|)`` is reported per period.
* ``solver="joint"``: least squares of eq. 17 on the unmasked samples, with the
  bias basis ``V̂b = [1, t]`` (+ auxiliary channels, eq. 18's temperature) in
  the model; needs no orthogonality.  ``"auto"`` uses eq. 14 when the leakage is
  below ``leak_tol`` and there is no auxiliary channel, eq. 17 otherwise.
* ``method="gls"``: generalised least squares of eq. 17 per period (section 5.3),
  with the noise covariance of the period's unmasked samples built from the PSD
  (rotation samples are gaps; the 1/f part is handled by the structure function,
  see :mod:`accal.estimators.noise`).

Every estimator is linear, ``â = W'm``; its covariance with any other period's is
``-W_i' T_D W_j`` (eq. 21 in the time domain), which gives σ per period and
``Rd[k]`` (eq. 23).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ValidationError, check_option
from .design import CalibrationPattern, design_pattern, rest_mask
from .noise import (
    PSD,
    as_psd,
    cov_linear,
    precision_linear_freq,
    regularised_autocov,
    structure_function,
)

__all__ = [
    "DemodResult",
    "BudgetResult",
    "SinusoidFit",
    "demodulate",
    "demodulate_table",
    "budget",
    "tau_scan",
    "sigma_mean",
    "fit_sinusoid",
    "REQUIRED_COLUMNS",
]

#: Columns :func:`demodulate_table` needs.
REQUIRED_COLUMNS = ("time", "m_y", "m_z", "theta")

_F64 = NDArray[np.float64]


@dataclass(frozen=True)
class DemodResult:
    """Per-period demodulated accelerations (only periods that were kept).

    Attributes
    ----------
    period_index : ndarray of int
        Index of the period from the start of the record.
    t_start, t_mid : ndarray
        Time of the first sample and mean sample time of each period (the
        epoch the per-period means and bias values refer to) [s, input origin].
    a_Y, a_Z : ndarray
        Mean non-gravitational acceleration per period, spacecraft axes Y, Z [m s⁻²].
    sigma_Y, sigma_Z : ndarray
        Their 1-σ uncertainty from the noise PSD (eq. 21 for LS, GLS covariance) [m s⁻²].
    slope_Y, slope_Z : ndarray
        Slope of the acceleration within the period (affine model; NaN for mean) [m s⁻³].
    sigma_slope_Y, sigma_slope_Z : ndarray
        Their uncertainty [m s⁻³] (NaN for the mean model).
    bias_y, bias_z : ndarray, shape (n, pb)
        Bias coefficients per period, in the order of ``bias_names``: value at ``t_mid``
        [m s⁻²], drift [m s⁻³], then one per auxiliary channel
        [m s⁻² per channel unit] (channels centred on their period mean).
    bias_names : tuple of str
        Names of the bias coefficients.
    n_used : ndarray of int
        Unmasked samples used per period.
    masked_time : ndarray
        Measured masked time per period [s] (compare with ``nominal_masked_time``).
    nominal_masked_time : float
        The nominal masking time TM given by the user [s].
    masked_fraction : float
        Fraction of the samples of all whole periods that were masked.
    leakage : ndarray
        Normalised eq. 16 residual per period, ``max |ṽ'Λb̂| / (|ṽ||Mb̂|)`` (0 = perfect).
    Rd : ndarray
        Autocovariance of âY (eq. 23) for lags ``0 .. len(Rd)-1`` periods [m² s⁻⁴]
        (identical for âZ when both axes share the PSD).
    cov : ndarray, shape (n, 2p, 2p)
        Covariance of ``(âY params, âZ params)`` per period (``p`` = 1 or 2) [SI].
    dropped : int
        Whole periods dropped (too few unmasked samples, or θ never at 0 or π).
    n_periods : int
        Whole periods in the record.
    tau : float
        Modulation period [s].
    fs : float
        Sampling frequency [Hz].
    method, solver, signal_model : str
        What was computed.
    """

    period_index: NDArray[np.int64]
    t_start: _F64
    t_mid: _F64
    a_Y: _F64
    a_Z: _F64
    sigma_Y: _F64
    sigma_Z: _F64
    slope_Y: _F64
    slope_Z: _F64
    sigma_slope_Y: _F64
    sigma_slope_Z: _F64
    bias_y: _F64
    bias_z: _F64
    bias_names: tuple[str, ...]
    n_used: NDArray[np.int64]
    masked_time: _F64
    nominal_masked_time: float
    masked_fraction: float
    leakage: _F64
    Rd: _F64
    cov: _F64
    dropped: int
    n_periods: int
    tau: float
    fs: float
    method: str
    solver: str
    signal_model: str

    @property
    def max_leakage(self) -> float:
        """Largest normalised eq. 16 residual over the kept periods."""
        return float(np.max(self.leakage)) if self.leakage.size else float("nan")


@dataclass(frozen=True)
class BudgetResult:
    """Uncertainty budget of a calibration pattern (section 5).

    Attributes
    ----------
    pattern : CalibrationPattern
        The pattern analysed.
    method : str
        ``"ls"`` or ``"gls"``.
    Rd : ndarray
        Autocovariance of the per-period mean (eq. 23), lags 0.. [m² s⁻⁴].
    T : float
        Integration time [s].
    sigma_T : float
        σ of the mean over ``T`` using the full Rd[k] (Fig. 5) [m s⁻²].
    sigma_T_indep : float
        Same assuming independent periods, ``sqrt(Rd[0] τ/T)`` [m s⁻²].
    taus : ndarray
        Modulation periods scanned (Fig. 6) [s].
    sigma_scan : ndarray
        ``sqrt(Rd[0] τ / T_scan)`` for each τ [m s⁻²].
    tau_opt : float
        τ of the smallest ``sigma_scan`` [s] (NaN if no scan).
    T_scan : float
        Integration time of the scan [s].
    """

    pattern: CalibrationPattern
    method: str
    Rd: _F64
    T: float
    sigma_T: float
    sigma_T_indep: float
    taus: _F64 = field(default_factory=lambda: np.empty(0))
    sigma_scan: _F64 = field(default_factory=lambda: np.empty(0))
    tau_opt: float = float("nan")
    T_scan: float = 3600.0


@dataclass(frozen=True)
class SinusoidFit:
    """Fit of ``α cos(2π f* t) + β sin(2π f* t)`` to per-period values (eq. 24).

    Attributes
    ----------
    alpha, beta : float
        Amplitudes [m s⁻²].
    cov : ndarray, shape (2, 2)
        Covariance of ``(α, β)`` [m² s⁻⁴].
    f_star : float
        Frequency [Hz].
    t_origin : float
        Time origin of the cos/sin [s] (``t`` is used as given).
    """

    alpha: float
    beta: float
    cov: _F64
    f_star: float
    t_origin: float = 0.0

    @property
    def sigma_alpha(self) -> float:
        """``sqrt(Cov(α, α))`` [m s⁻²]."""
        return float(np.sqrt(self.cov[0, 0]))

    @property
    def sigma_beta(self) -> float:
        """``sqrt(Cov(β, β))`` [m s⁻²]."""
        return float(np.sqrt(self.cov[1, 1]))


# ---------------------------------------------------------------------------
# validation


def _first_bad(name: str, x: NDArray) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        raise ValidationError(
            f"{name} contains {int(bad.sum())} NaN/inf value(s) (first at index {int(np.argmax(bad))})"
        )


def _validate(time, m_y, m_z, theta, aux, tau, tm, theta_tol):
    arrs = {}
    for name, x in (("time", time), ("m_y", m_y), ("m_z", m_z), ("theta", theta), *aux.items()):
        a = np.asarray(x, dtype=float)
        if a.ndim != 1:
            raise ValidationError(f"{name} must be 1-D, got shape {a.shape}")
        arrs[name] = a
    n = arrs["time"].size
    for name, a in arrs.items():
        if a.size != n:
            raise ValidationError(f"{name} has {a.size} samples but time has {n}")
    for name, a in arrs.items():
        _first_bad(name, a)
    if n < 3:
        raise ValidationError(f"need at least 3 samples, got {n}")
    dt_all = np.diff(arrs["time"])
    dt = float(np.median(dt_all))
    if dt <= 0 or np.any(np.abs(dt_all - dt) > 1e-6 * dt):
        k = int(np.argmax(np.abs(dt_all - dt)))
        raise ValidationError(
            f"sampling is irregular: step {dt_all[k]:g} s at index {k} vs nominal {dt:g} s "
            "(resample or split the record at gaps)"
        )
    fs = 1.0 / dt
    q = tau * fs
    if not np.isfinite(q) or q <= 0:
        raise ValidationError(f"tau must be positive, got {tau}")
    if abs(q - round(q)) > 1e-6:
        lo, hi = np.floor(q) / fs, np.ceil(q) / fs
        raise ValidationError(
            f"tau·fs = {q:g} is not an integer (fs = {fs:g} Hz); use tau = {lo:g} s or {hi:g} s"
        )
    if not 0 <= tm < tau:
        raise ValidationError(
            f"mask (masking time TM) must be in [0, tau) s, got {tm} s for tau = {tau} s"
        )
    th = arrs["theta"]
    if th.max() > 2 * np.pi + theta_tol:
        raise ValidationError(
            f"theta reaches {th.max():g} > 2π: it looks like degrees; give theta in radians"
        )
    if th.min() < -theta_tol:
        raise ValidationError(f"theta must lie in [0, 2π] rad, got minimum {th.min():g}")
    if not np.any(np.abs(np.cos(th) + 1.0) < 1e-3):
        raise ValidationError(
            f"theta never reaches π (range {th.min():.3g} to {th.max():.3g} rad): "
            "the pattern must measure at θ = 0 and θ = π"
        )
    return arrs, fs, int(round(q))


# ---------------------------------------------------------------------------
# weights of the linear estimators


def _batched_solve(a, b):
    # a (P, p, p), b (P, p, k); returns None rows for singular systems
    cond = np.linalg.cond(a)
    ok = np.isfinite(cond) & (cond < 1e12)
    out = np.full(b.shape, np.nan)
    if ok.any():
        out[ok] = np.linalg.solve(a[ok], b[ok])
    return out, ok


def _leakage(va, vb, cmask, smask, m):
    # va (P,q,pa) unmasked, vb (P,q,pb); normalised max |ṽ' Λ b̂| / (|ṽ||M b̂|)
    vt = va * m[..., None]
    nv = np.sqrt(np.einsum("pqa,pqa->pa", vt, vt))
    bm = vb * m[..., None]
    nb = np.sqrt(np.einsum("pqb,pqb->pb", bm, bm))
    out = np.zeros(va.shape[0])
    for lam in (cmask, smask):
        g = np.abs(np.einsum("pqa,pq,pqb->pab", vt, lam, vb))
        with np.errstate(invalid="ignore", divide="ignore"):
            g = g / (nv[:, :, None] * nb[:, None, :])
        out = np.maximum(out, np.nanmax(g.reshape(g.shape[0], -1), axis=1))
    return out


def _weights_eq14(va, c, s, m):
    # returns W (P, 2q, 2pa): params (aY..., aZ...) from stacked data (my; mz)
    vt = va * m[..., None]
    a = np.einsum("pqa,pqb->pab", vt, vt)
    eye = np.broadcast_to(np.eye(va.shape[2]), a.shape)
    ainv, ok = _batched_solve(a, np.array(eye))
    base = np.einsum("pqa,pab->pqb", vt, ainv)  # Ṽa (Ṽa'Ṽa)⁻¹
    wc = base * c[..., None]
    ws = base * s[..., None]
    top = np.concatenate([wc, ws], axis=2)  # weights on my for (aY, aZ)
    bot = np.concatenate([-ws, wc], axis=2)  # weights on mz
    return np.concatenate([top, bot], axis=1), ok


def _design_joint(va, vb, c, s, m):
    # eq. 17 design (P, 2q, 2pa+2pb), masked rows zero
    z = np.zeros_like(vb)
    cv, sv = va * c[..., None], va * s[..., None]
    top = np.concatenate([cv, sv, vb, z], axis=2)
    bot = np.concatenate([-sv, cv, z, vb], axis=2)
    x = np.concatenate([top, bot], axis=1)
    mm = np.concatenate([m, m], axis=1)
    return x * mm[..., None]


def _weights_joint(x):
    n = np.einsum("pqa,pqb->pab", x, x)
    sol, ok = _batched_solve(n, np.transpose(x, (0, 2, 1)))
    return np.transpose(sol, (0, 2, 1)), ok


def _weights_gls(x, m, r_reg):
    import scipy.linalg as sla

    npr, q2, p = x.shape
    q = q2 // 2
    w = np.full(x.shape, np.nan)
    ok = np.zeros(npr, bool)
    full = sla.toeplitz(r_reg[:q])
    keys = [m[i].astype(bool).tobytes() for i in range(npr)]
    groups: dict[bytes, list[int]] = {}
    for i, k in enumerate(keys):
        groups.setdefault(k, []).append(i)
    for key, members in groups.items():
        rows = np.array(members)
        idx = np.flatnonzero(np.frombuffer(key, dtype=bool))
        n_o = idx.size
        if n_o == 0:
            continue
        cf = sla.cho_factor(full[np.ix_(idx, idx)], lower=True)
        # stack both data axes of every period in the group as right-hand sides
        xo = np.concatenate([x[rows][:, :q][:, idx], x[rows][:, q:][:, idx]], axis=1)
        g = len(members)
        rhs = np.transpose(xo.reshape(g, 2, n_o, p), (2, 0, 1, 3)).reshape(n_o, -1)
        sol = sla.cho_solve(cf, rhs).reshape(n_o, g, 2, p)
        ox = np.transpose(sol, (1, 2, 0, 3)).reshape(g, 2 * n_o, p)  # Ω⁻¹ X
        nmat = np.einsum("gna,gnb->gab", xo, ox)
        inv, good = _batched_solve(nmat, np.broadcast_to(np.eye(p), nmat.shape).copy())
        wo = np.einsum("gna,gab->gnb", ox, np.nan_to_num(inv))
        wg = np.zeros((g, q2, p))
        wg[:, idx] = wo[:, :n_o]
        wg[:, q + idx] = wo[:, n_o:]
        w[rows[good]] = wg[good]
        ok[rows[good]] = True
    return w, ok


# ---------------------------------------------------------------------------
# covariance between periods


def _lag_products(wa, wb, d, q, k):
    """Σ over both data axes of -Wa_i' T_k Wb_{i+k}: returns (P-k, pa, pb)."""
    # T_k[a, b] = D[|k q + b - a|]
    j = np.arange(-(q - 1), q)
    g = d[np.abs(k * q - j)]  # h[j] = D[|kq - j|], j = a - b
    nfft = 1 << int(np.ceil(np.log2(3 * q)))
    hf = np.fft.rfft(g, nfft)
    xa = np.ascontiguousarray(np.transpose(wa[: wa.shape[0] - k], (0, 2, 1)))
    xb = np.ascontiguousarray(np.transpose(wb[k:], (0, 2, 1)))
    out = 0.0
    for ax in (slice(0, q), slice(q, 2 * q)):
        y = np.fft.irfft(np.fft.rfft(xb[:, :, ax], nfft, axis=2) * hf, nfft, axis=2)
        y = y[:, :, q - 1 : 2 * q - 1]  # (T_k xb)[a]
        out = out - np.matmul(xa[:, :, ax], np.transpose(y, (0, 2, 1)))
    return out


# ---------------------------------------------------------------------------
# public API


def demodulate(
    time: ArrayLike,
    m_y: ArrayLike,
    m_z: ArrayLike,
    theta: ArrayLike,
    *,
    tau: float,
    mask: float,
    method: str = "ls",
    signal_model: str = "mean",
    bias_aux: Mapping[str, ArrayLike] | None = None,
    psd: PSD | tuple[ArrayLike, ArrayLike] | None = None,
    solver: str = "auto",
    rest_tol: float = 1e-9,
    settle: float = 0.0,
    min_fraction: float = 0.5,
    n_lags: int = 5,
    leak_tol: float = 1e-9,
) -> DemodResult:
    """Demodulate accelerometer data taken on a rotating platform, period by period.

    Parameters
    ----------
    time : array_like, shape (n,)
        Regularly sampled epochs [s]; periods start at ``time[0]``.
    m_y, m_z : array_like, shape (n,)
        Accelerometer outputs on the rotating axes y and z [m s⁻²].
    theta : array_like, shape (n,)
        Platform angle θ, radians in [0, 2π] [rad].
    tau : float
        Modulation period τ [s]; ``τ·fs`` must be an integer (eq. 18).
    mask : float
        Nominal masking time TM per period [s], compared with the measured one.
    method : {"ls", "gls"}
        Least squares (sections 3.3-5.2) or generalised least squares (section 5.3).
    signal_model : {"mean", "affine"}
        ``Va`` of eq. 18 (mean per period) or eq. 19 (mean and slope).
    bias_aux : dict of str to array_like, optional
        Auxiliary channels added to the affine bias basis (eq. 18's temperature).
    psd : MicroStarPSD, TabulatedPSD or (f, S), optional
        Two-sided noise PSD [m² s⁻⁴ Hz⁻¹]; eq. 1 by default.
    solver : {"auto", "eq14", "joint"}
        LS only: eq. 14 demodulation or the joint LS of eq. 17 (see module notes).
    rest_tol : float
        Tolerance on the discrete θ̇ and θ̈ for the rest mask [rad].
    settle : float
        Extra time masked on each side of every rotation [s].
    min_fraction : float
        Keep a period when it has at least this fraction of ``(τ - TM)·fs``
        unmasked samples.
    n_lags : int
        Number of lags of Rd[k] computed besides k = 0.
    leak_tol : float
        ``solver="auto"`` uses eq. 14 only when every period's leakage is below this.

    Returns
    -------
    DemodResult

    Raises
    ------
    ValidationError
        On NaNs, irregular sampling, θ in degrees or never at π, non-integer
        ``τ·fs``, ``mask >= tau``, or no usable period.
    """
    check_option("method", method, ("ls", "gls"))
    check_option("signal_model", signal_model, ("mean", "affine"))
    check_option("solver", solver, ("auto", "eq14", "joint"))
    aux = dict(bias_aux or {})
    arrs, fs, q = _validate(time, m_y, m_z, theta, aux, float(tau), float(mask), 1e-6)
    psd = as_psd(psd)
    t = arrs["time"]
    n_per = t.size // q
    if n_per < 1:
        raise ValidationError(f"record of {t.size} samples is shorter than one period ({q})")
    nn = n_per * q
    rest = rest_mask(arrs["theta"], tol=rest_tol, settle=int(round(settle * fs)))[:nn]
    th = arrs["theta"][:nn].reshape(n_per, q)
    m = rest.reshape(n_per, q).astype(float)
    c, s = np.cos(th), np.sin(th)
    # normalised time within the period, centred on the mean sample time:
    # u_k = (k - (q-1)/2)/q (t = u·τ), so intercepts are period means
    u = (np.arange(q) - (q - 1) / 2) / q
    ones = np.ones((n_per, q))
    va = ones[..., None] if signal_model == "mean" else np.stack([ones, ones * u], axis=2)
    pa = va.shape[2]
    bcols = [ones, ones * u]
    names = ["bias", "drift"]
    aux_scale = []
    for k, v in aux.items():
        a = v[:nn].reshape(n_per, q)
        mean = np.sum(a * m, axis=1) / np.maximum(m.sum(axis=1), 1)
        a = a - mean[:, None]
        sc = float(np.std(a)) or 1.0
        bcols.append(a / sc)
        aux_scale.append(sc)
        names.append(k)
    vb = np.stack(bcols, axis=2)
    pb = vb.shape[2]

    n_used = m.sum(axis=1).astype(np.int64)
    need = max(min_fraction * (q - mask * fs), 2 * (pa + pb))
    atrest = m > 0
    has0 = np.any(atrest & (c > 0.999), axis=1)
    hasp = np.any(atrest & (c < -0.999), axis=1)
    keep = (n_used >= need) & has0 & hasp
    if not keep.any():
        raise ValidationError(
            f"no period has enough unmasked samples at both θ = 0 and π (need {need:g} of "
            f"{q}; best period has {int(n_used.max())})"
        )
    leak = _leakage(va, vb, c * m, s * m, m)

    if method == "gls":
        used = "gls-eq17"
    elif solver == "auto":
        used = "eq14" if (not aux and np.all(leak[keep] <= leak_tol)) else "joint"
    else:
        used = solver
    my = arrs["m_y"][:nn].reshape(n_per, q)
    mz = arrs["m_z"][:nn].reshape(n_per, q)
    data = np.concatenate([my, mz], axis=1)
    d = structure_function(psd, (n_lags + 2) * q, fs)
    if used == "eq14":
        w, ok = _weights_eq14(va, c, s, m)
    else:
        x = _design_joint(va, vb, c, s, m)
        if used == "joint":
            w, ok = _weights_joint(x)
        else:
            r_reg, _ = regularised_autocov(d, q)
            w, ok = _weights_gls(x, m, r_reg)
        w = w[:, :, : 2 * pa]
    keep &= ok
    if not keep.any():
        raise ValidationError(
            "the design is singular in every period (auxiliary channel constant?)"
        )
    w[~keep] = 0.0
    est = np.einsum("pqa,pq->pa", np.nan_to_num(w), data)
    # bias coefficients: LS fit of the residual on the unmasked samples
    cy = np.einsum("pqa,pa->pq", va, est[:, :pa])
    cz = np.einsum("pqa,pa->pq", va, est[:, pa:])
    ry = (my - c * cy - s * cz) * m
    rz = (mz + s * cy - c * cz) * m
    vbm = vb * m[..., None]
    nb = np.einsum("pqa,pqb->pab", vbm, vbm)
    nb[~keep] = np.eye(pb)
    bsol, _ = _batched_solve(
        nb, np.stack([np.einsum("pqa,pq->pa", vbm, ry), np.einsum("pqa,pq->pa", vbm, rz)], axis=2)
    )
    bias_y, bias_z = bsol[..., 0].copy(), bsol[..., 1].copy()
    for b in (bias_y, bias_z):
        b[:, 1] /= tau
        for j, sc in enumerate(aux_scale):
            b[:, 2 + j] /= sc
    # covariances (eq. 21 / 23)
    cov0 = _lag_products(w, w, d, q, 0)
    rd = [np.mean(cov0[keep, 0, 0])]
    for k in range(1, n_lags + 1):
        if k >= n_per:
            break
        ck = _lag_products(w[:, :, :1], w[:, :, :1], d, q, k)[:, 0, 0]
        both = keep[:-k] & keep[k:]
        rd.append(np.mean(ck[both]) if both.any() else np.nan)
    unit = np.ones(2 * pa)
    if pa == 2:
        unit[[1, 3]] = 1.0 / tau  # slope = coefficient/τ (normalised time)
    est = est * unit
    cov0 = cov0 * unit[None, :, None] * unit[None, None, :]
    sig = np.sqrt(np.maximum(np.einsum("paa->pa", cov0), 0.0))
    kk = np.flatnonzero(keep)
    nanp = np.full(kk.size, np.nan)
    t_start = t[0] + kk * q / fs
    return DemodResult(
        period_index=kk,
        t_start=t_start,
        t_mid=t_start + 0.5 * (q - 1) / fs,
        a_Y=est[kk, 0],
        a_Z=est[kk, pa],
        sigma_Y=sig[kk, 0],
        sigma_Z=sig[kk, pa],
        slope_Y=est[kk, 1] if pa == 2 else nanp,
        slope_Z=est[kk, 3] if pa == 2 else nanp,
        sigma_slope_Y=sig[kk, 1] if pa == 2 else nanp,
        sigma_slope_Z=sig[kk, 3] if pa == 2 else nanp,
        bias_y=bias_y[kk],
        bias_z=bias_z[kk],
        bias_names=tuple(names),
        n_used=n_used[kk],
        masked_time=(q - n_used[kk]) / fs,
        nominal_masked_time=float(mask),
        masked_fraction=float(1.0 - m.sum() / m.size),
        leakage=leak[kk],
        Rd=np.asarray(rd),
        cov=cov0[kk],
        dropped=int(n_per - kk.size),
        n_periods=int(n_per),
        tau=float(tau),
        fs=float(fs),
        method=method,
        solver=used,
        signal_model=signal_model,
    )


def demodulate_table(table: Mapping[str, ArrayLike], **kwargs) -> DemodResult:
    """Call :func:`demodulate` on a table (DataFrame or dict) with ``REQUIRED_COLUMNS``.

    Parameters
    ----------
    table : mapping of str to array_like
        Needs ``time``, ``m_y``, ``m_z``, ``theta`` [s, m s⁻², m s⁻², rad].
    **kwargs
        Passed to :func:`demodulate`; ``bias_aux`` may be a list of column names.

    Returns
    -------
    DemodResult
    """
    cols = list(table.keys())
    missing = [c for c in REQUIRED_COLUMNS if c not in cols]
    if missing:
        raise ValidationError(
            f"missing column(s) {', '.join(missing)}; need {', '.join(REQUIRED_COLUMNS)}, "
            f"got {', '.join(map(str, cols))}"
        )
    aux = kwargs.pop("bias_aux", None)
    if aux is not None and not isinstance(aux, Mapping):
        absent = [a for a in aux if a not in cols]
        if absent:
            raise ValidationError(f"missing auxiliary column(s) {', '.join(absent)}")
        aux = {a: np.asarray(table[a], float) for a in aux}
    return demodulate(
        np.asarray(table["time"], float),
        np.asarray(table["m_y"], float),
        np.asarray(table["m_z"], float),
        np.asarray(table["theta"], float),
        bias_aux=aux,
        **kwargs,
    )


def sigma_mean(rd: ArrayLike, n: int) -> float:
    """σ of the mean of ``n`` consecutive per-period values with autocovariance ``rd`` (Fig. 5).

    ``Var = (n Rd[0] + 2 Σ_{k=1}^{n-1} (n-k) Rd[k]) / n²``; lags beyond ``len(rd)``
    are taken as 0.

    Parameters
    ----------
    rd : array_like
        Rd[k] [m² s⁻⁴].
    n : int
        Number of periods averaged.

    Returns
    -------
    float
        [m s⁻²]
    """
    rd = np.asarray(rd, float)
    n = int(n)
    k = np.arange(1, min(n, rd.size))
    var = (n * rd[0] + 2.0 * np.sum((n - k) * rd[k])) / n**2
    return float(np.sqrt(var))


def fit_sinusoid(
    t: ArrayLike,
    a: ArrayLike,
    f_star: float,
    *,
    rd: ArrayLike | None = None,
    cov: ArrayLike | None = None,
    t_origin: float = 0.0,
) -> SinusoidFit:
    """Fit ``α cos(2π f*(t - t0)) + β sin(2π f*(t - t0))`` to per-period values (eq. 24).

    Generalised least squares with the full covariance of the points (from
    ``rd`` for equally spaced points, or ``cov``); ordinary LS if neither is given
    (then ``cov`` of the result is the formal one with unit variance).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times of the points (e.g. ``i·τ``, i = 1..n, as in the paper) [s].
    a : array_like, shape (n,)
        Values [m s⁻²].
    f_star : float
        Known frequency f* [Hz].
    rd : array_like, optional
        Rd[k] of equally spaced points (lags beyond its length are 0) [m² s⁻⁴].
    cov : array_like, shape (n, n), optional
        Full covariance of the points [m² s⁻⁴].
    t_origin : float
        Time origin ``t0`` [s]; the covariance of (α, β) depends on it.

    Returns
    -------
    SinusoidFit
    """
    t = np.asarray(t, float) - t_origin
    y = np.asarray(a, float)
    n = t.size
    if y.shape != t.shape:
        raise ValidationError(f"t and a must have the same shape, got {t.shape} and {y.shape}")
    A = np.column_stack([np.cos(2 * np.pi * f_star * t), np.sin(2 * np.pi * f_star * t)])
    if cov is None and rd is not None:
        rd = np.asarray(rd, float)
        full = np.zeros(n)
        full[: min(n, rd.size)] = rd[:n]
        ij = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :])
        cov = full[ij]
    if cov is None:
        cov = np.eye(n)
    cov = np.asarray(cov, float)
    ci_a = np.linalg.solve(cov, A)
    v = np.linalg.inv(A.T @ ci_a)
    coef = v @ (ci_a.T @ y)
    return SinusoidFit(float(coef[0]), float(coef[1]), v, float(f_star), float(t_origin))


def _rd_pattern(pattern: CalibrationPattern, psd, method, n_lags, use_mask):
    q = pattern.q
    mk = pattern.mask if use_mask == "discrete" else pattern.mask_nominal
    c = np.cos(pattern.theta) * mk
    if method == "ls":
        w = c / mk.sum()
        d = structure_function(psd, (n_lags + 1) * q, pattern.fs)
        rd = []
        for k in range(n_lags + 1):
            w1 = np.zeros((k + 1) * q)
            w2 = np.zeros((k + 1) * q)
            w1[:q] = w
            w2[k * q :] = w
            rd.append(float(cov_linear(w1, w2, d)))
        return np.asarray(rd)
    # GLS, eq. 25: circulant over P periods, rotation samples as noise-only data
    p = max(16, 2 * n_lags + 4)
    x = np.zeros((p * q, p))
    for i in range(p):
        x[i * q : (i + 1) * q, i] = c
    v = np.linalg.inv(precision_linear_freq(x, psd, pattern.fs))
    i0 = p // 2
    return np.array([v[i0, i0 + k] if i0 + k < p else 0.0 for k in range(n_lags + 1)])


def tau_scan(
    tm: float,
    taus: ArrayLike,
    fs: float = 1.0,
    *,
    psd: PSD | tuple[ArrayLike, ArrayLike] | None = None,
    method: str = "gls",
    T: float = 3600.0,
    kind: str = "fig2",
) -> tuple[_F64, _F64, float]:
    """σ over ``T`` of the demodulated mean versus τ for a masking time TM (Fig. 6).

    ``σ(τ) = sqrt(Rd[0] τ/T)`` with a pattern designed for each τ; τ values for which
    no symmetric pattern exists on the sample grid are skipped.

    Parameters
    ----------
    tm : float
        Masking time [s].
    taus : array_like
        Candidate modulation periods [s].
    fs : float
        Sampling frequency [Hz].
    psd : PSD, optional
        Two-sided noise PSD (eq. 1 by default).
    method : {"ls", "gls"}
        Estimator.
    T : float
        Integration time [s].
    kind : {"fig2", "fig1"}
        Pattern family.

    Returns
    -------
    taus : ndarray
        The τ values kept [s].
    sigma : ndarray
        σ at each [m s⁻²].
    tau_opt : float
        τ of the minimum [s].
    """
    check_option("method", method, ("ls", "gls"))
    psd = as_psd(psd)
    out_t, out_s = [], []
    for tau in np.asarray(taus, float):
        try:
            pat = design_pattern(tau, tm, fs, kind=kind)
        except ValidationError:
            continue
        rd0 = _rd_pattern(pat, psd, method, 0, "discrete")[0]
        out_t.append(tau)
        out_s.append(np.sqrt(rd0 * tau / T))
    if not out_t:
        raise ValidationError(f"no τ in the scan admits a {kind} pattern with TM = {tm} s")
    ts, ss = np.asarray(out_t), np.asarray(out_s)
    return ts, ss, float(ts[np.argmin(ss)])


def budget(
    tau: float = 600.0,
    tm: float = 200.0,
    fs: float = 1.0,
    *,
    psd: PSD | tuple[ArrayLike, ArrayLike] | None = None,
    method: str = "ls",
    T: float = 3 * 3600.0,
    pattern: CalibrationPattern | None = None,
    mask: str = "discrete",
    n_lags: int | None = None,
    taus: ArrayLike | None = None,
    T_scan: float = 3600.0,
) -> BudgetResult:
    """Uncertainty budget of a calibration pattern: Rd[k], σ over T, optimal τ.

    Parameters
    ----------
    tau, tm : float
        Modulation period and masking time [s] (ignored when ``pattern`` is given).
    fs : float
        Sampling frequency [Hz].
    psd : PSD, optional
        Two-sided noise PSD (eq. 1 by default).
    method : {"ls", "gls"}
        ``"ls"``: eq. 21 with ``c = cos θ·mask`` normalised by the unmasked count;
        ``"gls"``: eq. 25 over the whole record with the rotation samples as
        noise-only data (the paper's convention).
    T : float
        Integration time for ``sigma_T`` [s] (Fig. 5; 3 h in the paper).
    pattern : CalibrationPattern, optional
        Pattern to analyse; ``design_pattern(tau, tm, fs)`` by default.
    mask : {"discrete", "nominal"}
        Rest mask from θ̇ = θ̈ = 0 on the samples, or the nominal rotation windows.
    n_lags : int, optional
        Lags of Rd; enough for ``T`` by default.
    taus : array_like, optional
        Modulation periods to scan for Fig. 6 (same TM, fs, method).
    T_scan : float
        Integration time of the scan [s] (1 h in Fig. 6).

    Returns
    -------
    BudgetResult
    """
    check_option("method", method, ("ls", "gls"))
    check_option("mask", mask, ("discrete", "nominal"))
    psd = as_psd(psd)
    pat = pattern if pattern is not None else design_pattern(tau, tm, fs)
    n_avg = max(1, int(round(T / pat.tau)))
    nl = n_avg if n_lags is None else int(n_lags)
    rd = _rd_pattern(pat, psd, method, nl, mask)
    ts = ss = np.empty(0)
    t_opt = float("nan")
    if taus is not None:
        ts, ss, t_opt = tau_scan(pat.tm, taus, fs, psd=psd, method=method, T=T_scan, kind=pat.kind)
    return BudgetResult(
        pattern=pat,
        method=method,
        Rd=rd,
        T=float(T),
        sigma_T=sigma_mean(rd, n_avg),
        sigma_T_indep=float(np.sqrt(rd[0] / n_avg)),
        taus=ts,
        sigma_scan=ss,
        tau_opt=t_opt,
        T_scan=float(T_scan),
    )
