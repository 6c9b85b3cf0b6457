"""Uncertainty budget of a calibration pattern (section 5).

``Rd[k]`` of a designed pattern for LS (eq. 21) and GLS (eq. 25), σ over an
integration time (Fig. 5) and the scan of σ versus τ (Fig. 6).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ValidationError, check_option
from ..design import CalibrationPattern, design_pattern
from ..noise import PSD, as_psd, cov_linear, precision_linear_freq, structure_function
from .records import _F64
from .series import sigma_mean


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
