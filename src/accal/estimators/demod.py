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

Streaming
---------
:func:`demodulate_stream` takes the record in chunks of any size (a year of 1 Hz
data in bounded memory) and gives the same per-period results as
:func:`demodulate`, which is the one-chunk case: the incomplete last period of a
chunk is carried over, the rest mask sees the neighbouring samples across chunk
borders, the GLS covariance is per period, and the lagged products of Rd[k]
pair periods across chunk borders.  Missing samples (``valid`` False, e.g. the
gaps left by resampling) are masked like rotation samples.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ValidationError, check_option
from .design import CalibrationPattern, design_pattern, rest_mask
from .noise import (
    PSD,
    PSDFit,
    ResidualSpectrum,
    as_psd,
    cov_linear,
    fit_residual_psd,
    precision_linear_freq,
    psd_nodes,
    regularised_autocov,
    residual_kernel,
    structure_function,
)

__all__ = [
    "DemodChunk",
    "DemodResult",
    "NoiseReport",
    "BudgetResult",
    "SinusoidFit",
    "demodulate",
    "demodulate_stream",
    "demodulate_table",
    "budget",
    "tau_scan",
    "sigma_mean",
    "fit_sinusoid",
    "signal_leakage",
    "SignalLeakage",
    "REQUIRED_COLUMNS",
    "MIN_PERIODS_DATA_PSD",
]

#: Columns :func:`demodulate_table` needs.
REQUIRED_COLUMNS = ("time", "m_y", "m_z", "theta")

_F64 = NDArray[np.float64]


#: Fewest kept periods for σ from the data (``noise="data"``, ``accal demod --psd auto``):
#: a shorter run keeps the a-priori PSD.  With 24 periods (4 h at τ = 600 s) the σ from
#: the data scatters by ~6 % from run to run (docs/demod.md, "σ from the data").
MIN_PERIODS_DATA_PSD = 24
#: Distinct rest-mask layouts whose residual kernels are computed for the PSD estimate;
#: the periods of further layouts (gaps, jitter) are left out of it.
MAX_PSD_LAYOUTS = 24


@dataclass(frozen=True)
class NoiseReport:
    """The a-priori and the empirical noise of a demodulation (issue 20).

    Attributes
    ----------
    source : str
        ``"data"`` when σ, Rd[k] and the GLS weights use the PSD estimated from the
        run's residual, ``"apriori"`` when they use the given PSD.
    reason : str
        Why the a-priori PSD was used ('' when it was asked for, or for ``"data"``).
    fit : PSDFit or None
        The PSD estimated from the residual (None when it could not be).
    apriori : PSD
        The a-priori PSD (eq. 1 or a table) [m² s⁻⁴ Hz⁻¹].
    used : PSD
        The PSD behind σ, Rd[k] and GLS.
    sigma_ratio : float
        σ that the a-priori PSD gives / σ that the data PSD gives, for the same
        estimator weights (mean over the kept periods of Rd[0], square-rooted);
        NaN without a fit.
    check_ratio : float
        Consistency check: observed / expected (under ``used``) periodogram of the
        residual in ``band``; 1 within ``check_scatter`` when the PSD used describes
        the noise (a χ²/dof).
    check_scatter : float
        1-σ scatter of ``check_ratio`` for χ² bins (``sqrt(2/dof)``).
    band : tuple of float
        Frequencies of the check [Hz]: ``1/τ … 4/τ``, where the per-period σ is set
        (eq. 26, Fig. 3).
    n_periods : int
        Periods the residual spectrum rests on.
    """

    source: str
    reason: str
    fit: PSDFit | None
    apriori: Any
    used: Any
    sigma_ratio: float = float("nan")
    check_ratio: float = float("nan")
    check_scatter: float = float("nan")
    band: tuple[float, float] = (float("nan"), float("nan"))
    n_periods: int = 0


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
    rotation_shift : float
        Median shift of the rotation layout (the masked samples) from one period
        to the next [samples]: 0 when the pattern repeats every τ; ``d`` when it
        repeats every ``τ + d/fs`` (``--tau`` does not match the pattern).  NaN
        with fewer than two periods.
    pattern_periods : int
        Smallest ``m`` in 1…:data:`LAYOUT_LAGS` such that the rotation layout of
        (nearly) every period is that of ``m`` periods before: 1 when the pattern
        repeats every τ, ``m`` when ``--tau`` is 1/m of its period (QA: a 600 s
        pattern demodulated with ``--tau 300``); 0 when none is (a steady shift,
        see ``rotation_shift``, or no repeat at all), or with too few periods.
    rotation_shift_steady : bool
        True when (nearly) every period's layout is shifted by ``rotation_shift``
        from the one before: the pattern then repeats every ``τ + d/fs``.
    noise : NoiseReport or None
        The a-priori and the empirical noise (None with ``noise="apriori"``).
    shape_gain : ndarray, shape (n, 2, 2)
        Response of ``(a_Y, a_Z)`` to an in-period signal ``u`` and ``u² − ⟨u²⟩``
        on the same axis, minus the shape's mean over the period (which the true
        per-period mean holds), with ``u`` the time in periods from ``t_mid``: the
        leakage of a signal's slope and curvature (:func:`signal_leakage`).
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
    rotation_shift: float = float("nan")
    pattern_periods: int = 0
    rotation_shift_steady: bool = False
    noise: NoiseReport | None = None
    shape_gain: _F64 = field(default_factory=lambda: np.empty((0, 2, 2)))

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


# ---------------------------------------------------------------------------
# validation


def _first_bad(name: str, x: NDArray, valid: NDArray | None = None, offset: int = 0) -> None:
    bad = ~np.isfinite(x)
    if valid is not None:
        bad &= valid
    if bad.any():
        raise ValidationError(
            f"{name} contains {int(bad.sum())} NaN/inf value(s) "
            f"(first at index {offset + int(np.argmax(bad))})"
        )


#: Relative tolerance of a sampling step against the nominal step.
STEP_RTOL = 1e-6


def step_tolerance(dt: float, t_abs: float) -> float:
    """Largest ``|step − dt|`` [s] still taken as regular sampling.

    ``STEP_RTOL·dt`` plus the float64 rounding of the times themselves: each time
    is stored to within half its ulp, so a difference of two is off by up to one
    ulp of the larger.  With absolute times that is not negligible: at 1.4e9 s (GPS
    seconds of 2024) the ulp is 2.4e-7 s, 2.4e-6 of a 10 Hz step (QA: a regular
    10 Hz run was refused as irregular once its times were GPS seconds).

    Parameters
    ----------
    dt : float
        Nominal step [s].
    t_abs : float
        Largest ``|t|`` of the times compared [s].

    Returns
    -------
    float
        [s]
    """
    return STEP_RTOL * dt + 2.0 * float(np.spacing(abs(t_abs)))


def sampling_step(t: NDArray[np.float64]) -> tuple[float, float]:
    """The sampling step of increasing times, and its relative uncertainty.

    The median step; when every step is within :func:`step_tolerance` of it, the
    mean step ``(t[-1] − t[0])/(n − 1)`` instead, whose only error is the rounding
    of the two end times (``2 ulp / span``, returned).  The median of steps that
    are each rounded to the ulp of large absolute times is off by up to that ulp,
    enough to make ``τ·fs`` non-integer (QA: ``tau·fs = 6000.0057`` for 10 Hz at
    1.4e9 s).

    Parameters
    ----------
    t : ndarray, shape (n,), n >= 2
        Times [s].

    Returns
    -------
    dt : float
        [s]
    rtol : float
        Relative uncertainty of ``dt`` from the rounding of the times (0 when the
        steps are irregular: the caller reports them).
    """
    steps = np.diff(t)
    dt = float(np.median(steps))
    if not dt > 0:
        return dt, 0.0
    t_abs = max(abs(float(t[0])), abs(float(t[-1])))
    if np.all(np.abs(steps - dt) <= step_tolerance(dt, t_abs)):
        span = float(t[-1] - t[0])
        return span / (t.size - 1), 2.0 * float(np.spacing(t_abs)) / span
    return dt, 0.0


def regular_step(t: NDArray[np.float64]) -> tuple[float, float]:
    """:func:`sampling_step` of times that must be regular.

    Raises
    ------
    ValidationError
        A step further than :func:`step_tolerance` from the nominal one (the worst is
        named, with its index), or times that do not increase.
    """
    dt, rtol = sampling_step(t)
    steps = np.diff(t)
    if dt <= 0 or np.any(np.abs(steps - dt) > step_tolerance(dt, max(abs(t[0]), abs(t[-1])))):
        k = int(np.argmax(np.abs(steps - dt)))
        raise ValidationError(
            f"sampling is irregular: step {steps[k]:.10g} s at index {k} vs nominal "
            f"{dt:.10g} s (resample or split the record at gaps)"
        )
    return dt, rtol


def _check_tau_mask(fs: float, tau: float, tm: float, fs_rtol: float = 0.0) -> int:
    """``q = τ·fs`` (an integer within 1e-6, or within ``fs_rtol`` of ``fs``), after checking τ and TM."""
    q = tau * fs
    if not np.isfinite(q) or q <= 0:
        raise ValidationError(f"tau must be positive, got {tau}")
    if q < 1 - 1e-6:
        raise ValidationError(
            f"tau = {tau:.10g} s is shorter than one sample (fs = {fs:.10g} Hz): tau must be "
            f"a whole number of samples, at least {1 / fs:.10g} s"
        )
    if abs(q - round(q)) > max(1e-6, q * fs_rtol):
        lo, hi = np.floor(q) / fs, np.ceil(q) / fs
        raise ValidationError(
            f"tau·fs = {q:.10g} is not an integer (fs = {fs:.10g} Hz); "
            f"use tau = {lo:.10g} s or {hi:.10g} s"
        )
    if not 0 <= tm < tau:
        raise ValidationError(
            f"mask (masking time TM) must be in [0, tau) s, got {tm} s for tau = {tau} s"
        )
    return int(round(q))


#: A θ value this close to a multiple of π/2 [rad] counts as a rest angle of a pattern.
REST_ANGLE_TOL = 1e-6


def theta_in_range(th: NDArray[np.float64], valid: NDArray | None, tol: float) -> NDArray:
    """θ in ``[0, 2π]``: as given, or wrapped when it is radians in another convention.

    A θ outside ``[−tol, 2π + tol]`` whose rests are at multiples of π/2 (over a tenth
    of the samples away from 0 lie within :data:`REST_ANGLE_TOL` of one) is radians
    in another convention, ``[−π, π)`` (atan2) or unwrapped (always rotating one
    way): it is wrapped into ``[0, 2π)``, with values within ``REST_ANGLE_TOL`` below
    2π taken as 0, so a rest at 0 stays continuous.  Degrees rest at 90, 180, 270,
    which are not multiples of π/2 rad: refused with that diagnosis.  QA: θ of
    ``[−π, π)`` was refused ("must lie in [0, 2π]"), unwrapped radians were taken for
    degrees.

    Parameters
    ----------
    th : ndarray
        θ [rad].
    valid : ndarray of bool or None
        Samples to judge by (others may hold anything).
    tol : float
        Tolerance on the ``[0, 2π]`` range [rad].

    Returns
    -------
    ndarray
        θ in ``[−REST_ANGLE_TOL, 2π + tol]`` [rad].

    Raises
    ------
    ValidationError
        θ outside the range and not radians of another convention.
    """
    x = th if valid is None else th[valid]
    x = x[np.isfinite(x)]
    if not x.size or (x.min() >= -tol and x.max() <= 2 * np.pi + tol):
        # in range; a rest at 0 whose noise dips below it reads just under 2π: those
        # samples are taken as the same rest, not a turn away (QA: θ mod 2π with
        # N(0, 1e-8 rad) at rest masked 352 s per period instead of 208 s, a_Y off 5σ)
        near = th > 2 * np.pi - REST_ANGLE_TOL
        return np.where(near, th - 2 * np.pi, th) if near.any() else th
    away = x[np.abs(x) > REST_ANGLE_TOL]
    r = np.mod(away, 0.5 * np.pi)
    at_rest_angle = np.minimum(r, 0.5 * np.pi - r) < REST_ANGLE_TOL
    if away.size and at_rest_angle.mean() > 0.1:
        w = np.mod(th, 2 * np.pi)
        return np.where(w > 2 * np.pi - REST_ANGLE_TOL, w - 2 * np.pi, w)
    if x.max() > 2 * np.pi + tol:
        raise ValidationError(
            f"theta reaches {x.max():g} > 2π and its rests are not at multiples of π/2 rad: "
            "it looks like degrees; give theta in radians (or declare its unit 'deg')"
        )
    raise ValidationError(
        f"theta must lie in [0, 2π] rad (or be radians resting at multiples of π/2 in "
        f"another convention), got minimum {x.min():g}"
    )


def _validate(time, m_y, m_z, theta, aux, valid, tau, tm, theta_tol):
    arrs = {}
    for name, x in (("time", time), ("m_y", m_y), ("m_z", m_z), ("theta", theta), *aux.items()):
        a = np.asarray(x, dtype=float)
        if a.ndim != 1:
            raise ValidationError(f"{name} must be 1-D, got shape {a.shape}")
        arrs[name] = a
    n = arrs["time"].size
    ok = None if valid is None else np.asarray(valid, dtype=bool)
    if ok is not None and ok.shape != (n,):
        raise ValidationError(f"valid has shape {ok.shape} but time has {n} samples")
    for name, a in arrs.items():
        if a.size != n:
            raise ValidationError(f"{name} has {a.size} samples but time has {n}")
    for name, a in arrs.items():
        _first_bad(name, a, None if name == "time" else ok)
    if n < 3:
        raise ValidationError(f"need at least 3 samples, got {n}")
    dt, dt_rtol = regular_step(arrs["time"])
    fs = 1.0 / dt
    _check_tau_mask(fs, tau, tm, dt_rtol)
    arrs["theta"] = theta_in_range(arrs["theta"], ok, theta_tol)
    return arrs, ok, fs


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
    # va (P,q,pa) unmasked, vb (P,q,pb); normalised max |ṽ' Λ b̂| / (|ṽ||M b̂|)  (eq. 16)
    vt = va * m[..., None]
    nv = np.sqrt(np.einsum("pqa,pqa->pa", vt, vt))
    bm = vb * m[..., None]
    nb = np.sqrt(np.einsum("pqb,pqb->pb", bm, bm))
    out = np.zeros(va.shape[0])
    for lam in (cmask, smask):
        g = np.abs(np.einsum("pqa,pq,pqb->pab", vt, lam, vb))
        den = nv[:, :, None] * nb[:, None, :]
        g = np.divide(g, den, out=np.zeros_like(g), where=den > 0)
        out = np.maximum(out, np.max(g.reshape(g.shape[0], -1), axis=1))
    return out


def _weights_eq14(va, c, s, m):
    # returns W (P, 2q, 2pa): params (aY..., aZ...) from stacked data (my; mz)  (eq. 14)
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


#: Cholesky factors of distinct mask layouts kept between blocks (GLS).
_GLS_CACHE_SIZE = 32


def _weights_gls(x, m, r_reg, cache=None):
    import scipy.linalg as sla

    npr, q2, p = x.shape
    q = q2 // 2
    w = np.full(x.shape, np.nan)
    ok = np.zeros(npr, bool)
    cache = {} if cache is None else cache
    if "toeplitz" not in cache:
        cache["toeplitz"] = sla.toeplitz(r_reg[:q])
    full = cache["toeplitz"]
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
        cf = cache.pop(key, None)  # re-inserted below: most recently used last
        if cf is None:
            cf = sla.cho_factor(full[np.ix_(idx, idx)], lower=True)
        cache[key] = cf
        while len(cache) > _GLS_CACHE_SIZE + 1:
            del cache[next(k for k in cache if k != "toeplitz")]
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


def _fft_length(q: int) -> int:
    return 1 << int(np.ceil(np.log2(3 * q)))


def _lag_kernel(d: NDArray, q: int, k: int) -> NDArray:
    """Frequency kernel of ``T_k[a, b] = D[|k q + b - a|]`` for :func:`_lag_cov`.

    With ``h[j] = D[|kq - j|]`` (j = a - b), ``Σ_ab x_a T_k[a, b] y_b`` is a linear
    correlation of ``x`` with ``h ⊛ y``; by Parseval it is
    ``Σ_f w_f Re(conj(X_f) H_f Y_f)`` over the rfft bins (``w_f`` = 1 at 0 and
    Nyquist, 2 elsewhere), ``H = rfft(h)·exp(2πi f (q-1)/N)/N``.  No inverse FFT
    is needed, and the spectra of the weights are computed once per period.
    """
    nfft = _fft_length(q)
    j = np.arange(-(q - 1), q)
    g = d[np.abs(k * q - j)]
    f = np.arange(nfft // 2 + 1)
    wf = np.full(f.size, 2.0)
    wf[0] = 1.0
    if nfft % 2 == 0:
        wf[-1] = 1.0
    return np.fft.rfft(g, nfft) * np.exp(2j * np.pi * f * (q - 1) / nfft) * wf / nfft


def _weight_spectra(w: NDArray, q: int) -> NDArray:
    """rfft of each estimator's weights on each data axis: (P, 2q, r) → (P, r, 2, F)."""
    p, _, r = w.shape
    x = np.transpose(w.reshape(p, 2, q, r), (0, 3, 1, 2))
    return np.fft.rfft(x, _fft_length(q), axis=3)


def _lag_cov(xa: NDArray, xb: NDArray, kernel: NDArray) -> NDArray:
    """Σ over both data axes of ``-wa_i' T_k wb_i`` from weight spectra: (P, ra, rb).

    ``xa[i]`` belongs to a period ``k`` periods before ``xb[i]``'s (eq. 21 in the
    time domain, with the structure function D; see :func:`_lag_kernel`).
    """
    p, ra, nx, nf = xa.shape
    a = np.conj(xa).reshape(p, ra, nx * nf) * np.tile(kernel, nx)
    b = xb.reshape(p, xb.shape[1], nx * nf)
    return -np.matmul(a, np.transpose(b, (0, 2, 1))).real


# ---------------------------------------------------------------------------
# streaming machinery: chunks -> blocks of whole periods -> per-period results


@dataclass(frozen=True)
class DemodChunk:
    """Consecutive samples of a record, the unit :func:`demodulate_stream` consumes.

    Attributes
    ----------
    time : array_like, shape (n,)
        Epochs [s]; consecutive chunks continue the same uniform grid.
    m_y, m_z : array_like, shape (n,)
        Accelerometer outputs on the rotating axes [m s⁻²].
    theta : array_like, shape (n,)
        Platform angle [rad].
    aux : mapping of str to array_like
        The auxiliary channels of the bias basis (``bias_aux`` names).
    valid : array_like of bool, shape (n,), optional
        False for missing samples (e.g. inside a resampling gap): they are
        masked like rotation samples and may hold NaN.
    """

    time: ArrayLike
    m_y: ArrayLike
    m_z: ArrayLike
    theta: ArrayLike
    aux: Mapping[str, ArrayLike] = field(default_factory=dict)
    valid: ArrayLike | None = None


class _Checker:
    """Per-chunk checks of a stream (the whole-record checks of :func:`_validate`)."""

    def __init__(self, aux_names, tau, tm, fs, theta_tol=1e-6):
        self.aux_names = tuple(aux_names)
        self.tau, self.tm, self.theta_tol = float(tau), float(tm), theta_tol
        self.fs = None if fs is None else float(fs)
        self.fs_rtol = 0.0  # relative uncertainty of fs from the rounding of the times
        self.q = None  # checked when the first chunk arrives (its own checks come first)
        self.n = 0
        self.last_t = None
        self.th_min, self.th_max = np.inf, -np.inf
        self.reaches_pi = False

    def __call__(self, ch: DemodChunk) -> dict[str, NDArray]:
        arrs = {}
        aux = dict(ch.aux)
        missing = [k for k in self.aux_names if k not in aux]
        if missing:
            raise ValidationError(f"chunk lacks the auxiliary channel(s) {', '.join(missing)}")
        cols = (("time", ch.time), ("m_y", ch.m_y), ("m_z", ch.m_z), ("theta", ch.theta))
        for name, x in (*cols, *((k, aux[k]) for k in self.aux_names)):
            a = np.asarray(x, dtype=float)
            if a.ndim != 1:
                raise ValidationError(f"{name} must be 1-D, got shape {a.shape}")
            arrs[name] = a
        n = arrs["time"].size
        for name, a in arrs.items():
            if a.size != n:
                raise ValidationError(f"{name} has {a.size} samples but time has {n}")
        ok = np.ones(n, bool) if ch.valid is None else np.asarray(ch.valid, dtype=bool)
        if ok.shape != (n,):
            raise ValidationError(f"valid has shape {ok.shape} but time has {n} samples")
        for name, a in arrs.items():
            _first_bad(name, a, None if name == "time" else ok, self.n)
        t = arrs["time"]
        if self.fs is None:
            if n < 3:
                raise ValidationError(
                    f"need at least 3 samples in the first chunk to find the sampling step, got {n}"
                )
            dt, self.fs_rtol = sampling_step(t)
            self.fs = 1.0 / dt
        if self.q is None:
            self.q = _check_tau_mask(self.fs, self.tau, self.tm, self.fs_rtol)
        dt = 1.0 / self.fs
        steps = np.diff(t) if self.last_t is None else np.diff(np.concatenate([[self.last_t], t]))
        off = (
            np.abs(steps - dt) > step_tolerance(dt, max(abs(t[0]), abs(t[-1]))) if n else steps > 0
        )
        if off.any():
            k = int(np.argmax(np.abs(steps - dt)))
            idx = self.n + k - (0 if self.last_t is None else 1)
            raise ValidationError(
                f"sampling is irregular: step {steps[k]:.10g} s at index {idx} vs nominal "
                f"{dt:.10g} s (resample or split the record at gaps)"
            )
        arrs["theta"] = theta_in_range(arrs["theta"], ok, self.theta_tol)
        th = arrs["theta"][ok]
        if th.size:
            self.th_min = min(self.th_min, float(th.min()))
            self.th_max = max(self.th_max, float(th.max()))
            self.reaches_pi |= bool(np.any(np.abs(np.cos(th) + 1.0) < 1e-3))
        if n:
            self.last_t = float(t[-1])
        self.n += n
        arrs["valid"] = ok
        return arrs

    def finish(self) -> None:
        if self.n < 3:
            raise ValidationError(f"need at least 3 samples, got {self.n}")
        if not self.reaches_pi:
            raise ValidationError(
                f"theta never reaches π (range {self.th_min:.3g} to {self.th_max:.3g} rad): "
                "the pattern must measure at θ = 0 and θ = π"
            )


@dataclass
class _Block:
    p0: int  # index of the first period
    arrs: dict[str, NDArray]  # (P, q) arrays
    rest: NDArray  # (P, q) bool: discrete θ̇ = θ̈ = 0 (section 4.2)


class _Periods:
    """Cut a stream of sample arrays into blocks of whole periods.

    The incomplete last period of a chunk is carried over to the next one; the
    rest mask (which looks ``settle + 1`` samples to each side) is computed with
    the neighbouring samples of the adjacent chunks, so it is the same as on the
    whole record.
    """

    def __init__(self, q: int, settle: int, rest_tol: float) -> None:
        self.q, self.settle, self.rest_tol = q, settle, rest_tol
        self.ctx = settle + 1
        self.buf: dict[str, NDArray] | None = None
        self.before = np.empty(0)
        self.p0 = 0

    def feed(self, arrs: dict[str, NDArray]) -> _Block | None:
        if self.buf is None:
            buf = arrs
        else:
            buf = {k: np.concatenate([self.buf[k], arrs[k]]) for k in arrs}
        n_per = max(0, buf["time"].size - self.ctx) // self.q
        return self._emit(buf, n_per)

    def finish(self) -> _Block | None:
        if self.buf is None:
            return None
        return self._emit(self.buf, self.buf["time"].size // self.q)

    @property
    def tail(self) -> int:
        """Samples waiting for the rest of their period."""
        return 0 if self.buf is None else int(self.buf["time"].size)

    def _emit(self, buf: dict[str, NDArray], n_per: int) -> _Block | None:
        q = self.q
        if n_per == 0:
            self.buf = buf
            return None
        nn = n_per * q
        th = buf["theta"]
        after = th[nn : nn + self.ctx]
        ext = np.concatenate([self.before, th[:nn], after])
        rest = rest_mask(ext, tol=self.rest_tol, settle=self.settle)
        rest = rest[self.before.size : self.before.size + nn]
        self.before = np.concatenate([self.before, th[:nn]])[-self.ctx :]
        blk = _Block(self.p0, {k: v[:nn].reshape(n_per, q) for k, v in buf.items()}, rest)
        blk.rest = rest.reshape(n_per, q)
        self.buf = {k: v[nn:] for k, v in buf.items()}
        self.p0 += n_per
        return blk


@dataclass
class _Setup:
    """Everything that is the same for every block of a record."""

    q: int
    fs: float
    tau: float
    mask: float
    method: str
    signal_model: str
    aux_names: tuple[str, ...]
    need: float
    d: NDArray
    r_reg: NDArray | None
    n_lags: int
    kernels: list[NDArray] = field(default_factory=list)
    kernel_other: NDArray | None = None  # lag-0 kernel of the other PSD (NoiseReport)

    @property
    def u(self) -> NDArray:
        # normalised time within the period, centred on the mean sample time:
        # u_k = (k - (q-1)/2)/q (t = u·τ), so intercepts are period means
        return (np.arange(self.q) - (self.q - 1) / 2) / self.q

    @property
    def pa(self) -> int:
        return 1 if self.signal_model == "mean" else 2


def _block_basis(st: _Setup, blk: _Block, with_aux: bool = True):
    """Mask, cos/sin, Va and V̂b of a block (eqs. 18-19; aux channels centred and scaled)."""
    a = blk.arrs
    ok = a["valid"].astype(bool)
    m = (blk.rest & ok).astype(float)
    th = np.where(ok, a["theta"], 0.0)
    c, s = np.cos(th), np.sin(th)
    n_per = m.shape[0]
    ones = np.ones((n_per, st.q))
    u = st.u
    va = ones[..., None] if st.pa == 1 else np.stack([ones, ones * u], axis=2)
    bcols = [ones, ones * u]
    scales = []
    if with_aux:
        n_m = np.maximum(m.sum(axis=1), 1)
        for k in st.aux_names:
            x = np.where(ok, a[k], 0.0)
            mean = np.sum(x * m, axis=1) / n_m
            x = x - mean[:, None]
            # per-period scale (conditioning only; divided out of the coefficients)
            sc = np.sqrt(np.sum(x * x * m, axis=1) / n_m)
            sc = np.where(sc > 0, sc, 1.0)
            bcols.append(x / sc[:, None])
            scales.append(sc)
    vb = np.stack(bcols, axis=2)
    return m, c, s, va, vb, scales


def _scan_block(st: _Setup, blk: _Block) -> tuple[NDArray, NDArray, NDArray]:
    """Pass 1: n_used, keep (enough samples at 0 and π), eq. 16 leakage with V̂b = [1, t]."""
    m, c, s, va, vb, _ = _block_basis(st, blk, with_aux=False)
    n_used = m.sum(axis=1).astype(np.int64)
    atrest = m > 0
    has0 = np.any(atrest & (c > 0.999), axis=1)
    hasp = np.any(atrest & (c < -0.999), axis=1)
    keep = (n_used >= st.need) & has0 & hasp
    return n_used, keep, _leakage(va, vb, c * m, s * m, m)


class _ResidualSpectra:
    """Periodogram of the per-period residual, grouped by rest-mask layout (pass 1).

    The residual is that of a least-squares fit, per period and on the unmasked
    samples, of eq. 17 with an affine signal (eq. 19) and the affine bias plus
    the auxiliary channels (``Va = V̂b = [1, u]``): a signal that varies within
    the period (a slope) does not enter the noise estimate, whatever
    ``signal_model``.  A quadratic term in either would take what is left of the
    noise around ``2/τ``, the band that sets σ (eq. 26): a period of ``q``
    unmasked samples has ~6 degrees of freedom per axis below ``4/τ``.  What the fit removes from the noise is in
    the kernel (:func:`accal.estimators.noise.residual_kernel`), computed once per
    layout (the first period of the layout stands for its auxiliary channels).
    """

    def __init__(self, q: int, fs: float) -> None:
        self.q, self.fs = q, fs
        top = q // 2
        low = np.arange(1, min(32, top) + 1)
        high = np.round(np.geomspace(33, top, 96)).astype(np.int64) if top > 33 else low[:0]
        self.bins = np.unique(np.concatenate([low, high]))
        self.groups: dict[bytes, list[Any]] = {}
        self.skipped = 0

    def add(self, st: _Setup, blk: _Block, keep: NDArray) -> None:
        m, c, s, _, vb, _ = _block_basis(st, blk)
        ones = np.ones_like(m)
        va = np.stack([ones, ones * st.u, ones * (st.u**2 - np.mean(st.u**2))], axis=2)
        x = _design_joint(va, vb, c, s, m)
        a = blk.arrs
        ok = a["valid"].astype(bool)
        data = np.concatenate([np.where(ok, a["m_y"], 0.0), np.where(ok, a["m_z"], 0.0)], axis=1)
        mm = np.concatenate([m, m], axis=1)
        data = data * mm
        n = np.einsum("pqa,pqb->pab", x, x)
        sol, good = _batched_solve(n, np.einsum("pqa,pq->pa", x, data)[..., None])
        use = keep & good
        if not use.any():
            return
        r = (data - np.einsum("pqa,pa->pq", x, np.nan_to_num(sol[..., 0]))) * mm
        q = st.q
        spec = np.fft.rfft(r[:, :q], axis=1)[:, self.bins]
        power = np.abs(spec) ** 2
        spec = np.fft.rfft(r[:, q:], axis=1)[:, self.bins]
        power += np.abs(spec) ** 2
        cm, sm = np.round(c * m, 6), np.round(s * m, 6)
        for i in np.flatnonzero(use):
            key = m[i].astype(bool).tobytes() + cm[i].tobytes() + sm[i].tobytes()
            g = self.groups.get(key)
            if g is None:
                if len(self.groups) >= MAX_PSD_LAYOUTS:
                    self.skipped += 1
                    continue
                g = self.groups[key] = [0, np.zeros(self.bins.size), x[i], m[i]]
            g[0] += 1
            g[1] += power[i]

    @property
    def n_periods(self) -> int:
        return sum(g[0] for g in self.groups.values())

    def spectrum(self) -> ResidualSpectrum | None:
        if not self.groups:
            return None
        f_grid, kern, power = None, 0.0, 0.0
        for count, pw, x, m in self.groups.values():
            f_grid, k = residual_kernel(x, m, self.bins, self.fs)
            kern = kern + count * k
            power = power + pw
        return ResidualSpectrum(
            self.bins * self.fs / self.q, power, f_grid, kern, self.n_periods, n_axes=2
        )


#: Period lags at which rotation layouts are compared (a pattern of up to this many τ).
LAYOUT_LAGS = 4
#: Fraction of period pairs that must agree for a layout to count as repeating.
LAYOUT_AGREE = 0.9


def _layout_shifts(rest: NDArray, prev: NDArray | None) -> tuple[dict[int, NDArray], NDArray]:
    """Shift of each period's rotation layout against the periods before it [samples].

    The circular cross-correlation of the masked samples (``~rest``) of two
    periods peaks at the shift ``d`` by which the rotations moved: at lag 1, 0
    when the pattern repeats every τ, ``d`` when it repeats every ``τ + d/fs``.
    Circular, so a rotation that leaves the end of a period and comes back at
    its start does not break the estimate.  Lags up to :data:`LAYOUT_LAGS` tell a
    ``--tau`` that is a fraction of the pattern's period (layouts that differ
    from one period to the next but repeat every m periods).

    Parameters
    ----------
    rest : ndarray of bool, shape (P, q)
        Rest masks of consecutive periods.
    prev : ndarray of complex or None
        Spectra of the masks of the (up to :data:`LAYOUT_LAGS`) periods before the
        first one (from the previous block).

    Returns
    -------
    shifts : dict of int to ndarray of int
        Per lag ``m``: one shift per pair (period, period − m) whose later period
        is in ``rest``, in ``(-q/2, q/2]``.
    last : ndarray of complex
        Spectra of the last periods' masks (``prev`` of the next block).
    """
    q = rest.shape[1]
    spec = np.fft.rfft((~rest).astype(np.float64), axis=1)
    n_prev = 0 if prev is None else prev.shape[0]
    if prev is not None:
        spec = np.concatenate([prev, spec])
    out: dict[int, NDArray] = {}
    for lag in range(1, LAYOUT_LAGS + 1):
        i = np.arange(max(n_prev, lag), spec.shape[0])
        if not i.size:
            out[lag] = np.empty(0, np.int64)
            continue
        xc = np.fft.irfft(spec[i] * np.conj(spec[i - lag]), n=q, axis=1)
        shift = np.argmax(np.round(xc, 6), axis=1)  # rounding: ties (no rotation) go to 0
        out[lag] = np.where(shift > q // 2, shift - q, shift).astype(np.int64)
    return out, spec[-LAYOUT_LAGS:]


def _pattern_of_shifts(shifts: dict[int, list[NDArray]]) -> tuple[float, int, bool]:
    """(median lag-1 shift [samples], pattern_periods, steady) of :class:`DemodResult`."""
    lag1 = np.concatenate(shifts[1]) if shifts[1] else np.empty(0, np.int64)
    if not lag1.size:
        return float("nan"), 0, False
    med = float(np.median(lag1))
    steady = bool(np.mean(np.abs(lag1 - med) <= 1) >= LAYOUT_AGREE)
    for lag in range(1, LAYOUT_LAGS + 1):
        d = np.concatenate(shifts[lag]) if shifts[lag] else np.empty(0, np.int64)
        if d.size and np.mean(d == 0) >= LAYOUT_AGREE:
            return med, lag, steady
    return med, 0, steady


def _estimate_block(st: _Setup, blk: _Block, solver: str, cache: dict) -> dict[str, Any]:
    """Pass 2: per-period estimates, weights and covariances of one block."""
    pa, q, tau = st.pa, st.q, st.tau
    m, c, s, va, vb, scales = _block_basis(st, blk)
    pb = vb.shape[2]
    a = blk.arrs
    ok = a["valid"].astype(bool)
    n_used = m.sum(axis=1).astype(np.int64)
    atrest = m > 0
    has0 = np.any(atrest & (c > 0.999), axis=1)
    hasp = np.any(atrest & (c < -0.999), axis=1)
    keep = (n_used >= st.need) & has0 & hasp
    leak = _leakage(va, vb, c * m, s * m, m)
    my = np.where(ok, a["m_y"], 0.0)
    mz = np.where(ok, a["m_z"], 0.0)
    data = np.concatenate([my, mz], axis=1)
    if solver == "eq14":
        w, good = _weights_eq14(va, c, s, m)
    else:
        x = _design_joint(va, vb, c, s, m)
        if solver == "joint":
            w, good = _weights_joint(x)
        else:
            w, good = _weights_gls(x, m, st.r_reg, cache)
        w = w[:, :, : 2 * pa]
    keep &= good
    w[~keep] = 0.0
    w = np.nan_to_num(w)
    est = np.einsum("pqa,pq->pa", w, data)
    # bias coefficients: LS fit of the residual on the unmasked samples (eqs. 17-19)
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
        for j, sc in enumerate(scales):
            b[:, 2 + j] /= sc
    spec = _weight_spectra(w, q)
    cov0 = _lag_cov(spec, spec, st.kernels[0])  # eq. 21, lag 0
    unit = np.ones(2 * pa)
    if pa == 2:
        unit[[1, 3]] = 1.0 / tau  # slope = coefficient/τ (normalised time)
    rd0 = cov0[:, 0, 0].copy()
    rd0_other = (
        _lag_cov(spec[:, :1], spec[:, :1], st.kernel_other)[:, 0, 0]
        if st.kernel_other is not None
        else None
    )
    gain = _shape_gain(st, w, c, s, pa)
    est = est * unit
    cov0 = cov0 * unit[None, :, None] * unit[None, None, :]
    sig = np.sqrt(np.maximum(np.einsum("paa->pa", cov0), 0.0))
    kk = np.flatnonzero(keep)
    t = a["time"]
    return {
        "keep": keep,
        "spec1": spec[:, :1],
        "rd0": rd0,
        "rd0_other": rd0_other,
        "n_masked": float(m.size - m.sum()),
        "n_samples": int(m.size),
        "rows": {
            "period_index": blk.p0 + kk,
            "t_start": t[kk, 0],
            "t_mid": 0.5 * (t[kk, 0] + t[kk, -1]),
            "est": est[kk],
            "sig": sig[kk],
            "bias_y": bias_y[kk],
            "bias_z": bias_z[kk],
            "n_used": n_used[kk],
            "leakage": leak[kk],
            "cov": cov0[kk],
            "gain": gain[kk],
        },
    }


def _shape_gain(st: _Setup, w: NDArray, c: NDArray, s: NDArray, pa: int) -> NDArray:
    """(P, 2, 2): response of (a_Y, a_Z) to ``u`` and ``u² − ⟨u²⟩`` minus their period means.

    The signal of eq. 4 on its own axis, ``m_y = c·h, m_z = −s·h`` (Y) and
    ``m_y = s·h, m_z = c·h`` (Z), through the estimator's weights; the true
    per-period mean of ``h`` (0 for ``u``; ``⟨u²⟩`` removed) is subtracted.
    """
    u = st.u
    out = np.empty((w.shape[0], 2, 2))
    for j, h in enumerate((u, u**2 - np.mean(u**2))):
        for ax, (top, bot) in enumerate(((c, -s), (s, c))):
            x = np.concatenate([top * h, bot * h], axis=1)
            out[:, ax, j] = np.einsum("pq,pq->p", w[:, :, ax * pa], x)
    return out


def _chunks_of(source: Callable[[], Iterable[DemodChunk]]) -> Iterator[DemodChunk]:
    """The chunks of ``source()``, the leading ones merged until there are 3 samples
    (enough for the median step)."""
    it = source()
    if isinstance(it, DemodChunk):
        raise ValidationError("source() must return an iterable of DemodChunk, got one chunk")
    head: list[DemodChunk] | None = []
    for ch in it:
        if head is None:
            yield ch
            continue
        head.append(ch)
        if sum(np.size(c.time) for c in head) >= 3:
            yield _concat_chunks(head)
            head = None
    if head:
        yield _concat_chunks(head)


def _concat_chunks(chunks: list[DemodChunk]) -> DemodChunk:
    if len(chunks) == 1:
        return chunks[0]

    def cat(xs):
        return np.concatenate([np.asarray(x, float) for x in xs])

    valid = None
    if any(c.valid is not None for c in chunks):
        valid = np.concatenate(
            [
                np.ones(np.size(c.time), bool) if c.valid is None else np.asarray(c.valid, bool)
                for c in chunks
            ]
        )
    return DemodChunk(
        cat(c.time for c in chunks),
        cat(c.m_y for c in chunks),
        cat(c.m_z for c in chunks),
        cat(c.theta for c in chunks),
        {k: cat(c.aux[k] for c in chunks) for k in chunks[0].aux},
        valid,
    )


# ---------------------------------------------------------------------------
# public API


def demodulate_stream(
    source: Callable[[], Iterable[DemodChunk]],
    *,
    tau: float,
    mask: float,
    fs: float | None = None,
    method: str = "ls",
    signal_model: str = "mean",
    bias_aux: Sequence[str] = (),
    psd: PSD | tuple[ArrayLike, ArrayLike] | None = None,
    solver: str = "auto",
    rest_tol: float = 1e-9,
    settle: float = 0.0,
    min_fraction: float = 0.5,
    n_lags: int = 5,
    leak_tol: float = 1e-9,
    noise: str = "apriori",
    min_periods_data: int = MIN_PERIODS_DATA_PSD,
) -> DemodResult:
    """Demodulate a record delivered in chunks, in memory bounded by the chunk size.

    The same estimator as :func:`demodulate` (which calls this with one chunk),
    period by period; chunks may have any length, the incomplete last period of
    a chunk is carried over to the next.  Per-period results do not depend on
    the chunking (up to rounding): the rest mask sees the samples of the
    neighbouring chunks, the GLS covariance is per period (section 5.3), and the
    lagged covariances of Rd[k] (eq. 23) pair periods across chunk borders.

    Two passes over ``source()``: the first checks every chunk (NaNs, uniform
    sampling, θ in radians and reaching π, usable periods) and, for
    ``solver="auto"``, decides between eq. 14 and the joint LS of eq. 17 on the
    leakage of every period; the second estimates.  Nothing is estimated from
    a record that fails a check.

    Parameters
    ----------
    source : callable
        Returns a fresh iterable of :class:`DemodChunk` each time it is called
        (e.g. a function re-opening the run file).
    tau, mask : float
        Modulation period τ and nominal masking time TM [s].
    fs : float, optional
        Sampling frequency [Hz]; by default ``1/median step`` of the first chunk.
    method, signal_model, psd, solver, rest_tol, settle, min_fraction, n_lags, leak_tol
        As :func:`demodulate`.
    noise, min_periods_data
        As :func:`demodulate`.
    bias_aux : sequence of str
        Names of the auxiliary channels (keys of :attr:`DemodChunk.aux`) added
        to the bias basis (eq. 18's temperature).

    Returns
    -------
    DemodResult

    Raises
    ------
    ValidationError
        As :func:`demodulate`.

    Notes
    -----
    The auxiliary channels of the bias basis are centred and scaled per period
    (the scale only conditions the least squares and is divided out of the
    coefficients); before streaming, the scale was one standard deviation over
    the whole record, which changed the coefficients only by rounding.
    """
    check_option("method", method, ("ls", "gls"))
    check_option("signal_model", signal_model, ("mean", "affine"))
    check_option("solver", solver, ("auto", "eq14", "joint"))
    check_option("noise", noise, ("apriori", "report", "data"))
    tau, mask = float(tau), float(mask)
    aux_names = tuple(bias_aux)
    psd = as_psd(psd)
    spectra: _ResidualSpectra | None = None
    # pass 1: checks, rest masks, usable periods, eq. 16 leakage
    chk = _Checker(aux_names, tau, mask, fs)
    cutter = None
    st = None
    n_per, n_keep, best, leak_max = 0, 0, 0, 0.0
    shifts: dict[int, list[NDArray]] = {lag: [] for lag in range(1, LAYOUT_LAGS + 1)}
    last_spec: NDArray | None = None

    def scan(blk: _Block | None) -> None:
        nonlocal n_per, n_keep, best, leak_max, last_spec
        if blk is None:
            return
        n_used, keep, leak = _scan_block(st, blk)
        if spectra is not None:
            spectra.add(st, blk, keep)
        sh, last_spec = _layout_shifts(blk.rest, last_spec)
        for lag, d in sh.items():
            shifts[lag].append(d)
        n_per += n_used.size
        n_keep += int(keep.sum())
        best = max(best, int(n_used.max()))
        if keep.any():
            leak_max = max(leak_max, float(np.max(leak[keep])))

    for ch in _chunks_of(source):
        arrs = chk(ch)
        if cutter is None:
            q = chk.q
            cutter = _Periods(q, int(round(settle * chk.fs)), rest_tol)
            pa = 1 if signal_model == "mean" else 2
            st = _Setup(
                q=q,
                fs=chk.fs,
                tau=tau,
                mask=mask,
                method=method,
                signal_model=signal_model,
                aux_names=aux_names,
                need=max(min_fraction * (q - mask * chk.fs), 2 * (pa + 2 + len(aux_names))),
                d=np.empty(0),
                r_reg=None,
                n_lags=int(n_lags),
            )
            if noise != "apriori":
                spectra = _ResidualSpectra(q, chk.fs)
        scan(cutter.feed(arrs))
    if cutter is None:
        raise ValidationError("need at least 3 samples, got 0")
    chk.finish()
    scan(cutter.finish())
    if n_per < 1:
        raise ValidationError(f"record of {chk.n} samples is shorter than one period ({st.q})")
    if n_keep == 0:
        raise ValidationError(
            f"no period has enough unmasked samples at both θ = 0 and π (need {st.need:g} of "
            f"{st.q}; best period has {best}). A sample is at rest where θ's first and second "
            f"differences are within {rest_tol:g} rad (--rest-tol; raise it if θ is noisy at "
            "rest), and the rests must be at θ = 0 and π"
        )
    rotation_shift, pattern_periods, steady = _pattern_of_shifts(shifts)
    if method == "gls":
        used = "gls-eq17"
    elif solver == "auto":
        used = "eq14" if (not aux_names and leak_max <= leak_tol) else "joint"
    else:
        used = solver
    report = _noise_report(spectra, psd, noise, int(min_periods_data), tau, st.fs)
    used_psd = psd if report is None else report.used
    st.d = structure_function(used_psd, (st.n_lags + 2) * st.q, st.fs)
    st.kernels = [_lag_kernel(st.d, st.q, k) for k in range(st.n_lags + 1)]
    if report is not None and report.fit is not None:
        other = report.apriori if report.source == "data" else report.fit.psd
        st.kernel_other = _lag_kernel(structure_function(other, st.q + 1, st.fs), st.q, 0)
    if used == "gls-eq17":
        st.r_reg, _ = regularised_autocov(st.d, st.q)

    # pass 2: estimates, covariances, Rd[k] across block borders
    rows: list[dict[str, NDArray]] = []
    rd_sum = np.zeros(st.n_lags + 1)
    rd_cnt = np.zeros(st.n_lags + 1, dtype=np.int64)
    rd_other = [0.0]
    prev_w = np.zeros((0, 1, 2, _fft_length(st.q) // 2 + 1), complex)
    prev_keep = np.zeros(0, bool)
    n_masked, n_samples = 0.0, 0
    cache: dict = {}
    cutter = _Periods(st.q, int(round(settle * st.fs)), rest_tol)
    chk2 = _Checker(aux_names, tau, mask, st.fs)

    def estimate(blk: _Block | None) -> None:
        nonlocal prev_w, prev_keep, n_masked, n_samples
        if blk is None:
            return
        r = _estimate_block(st, blk, used, cache)
        rows.append(r["rows"])
        keep = r["keep"]
        rd_sum[0] += float(np.sum(r["rd0"][keep]))
        if r["rd0_other"] is not None:
            rd_other[0] += float(np.sum(r["rd0_other"][keep]))
        rd_cnt[0] += int(keep.sum())
        n_masked += r["n_masked"]
        n_samples += r["n_samples"]
        w_ext = np.concatenate([prev_w, r["spec1"]])
        k_ext = np.concatenate([prev_keep, keep])
        lp = prev_w.shape[0]
        for k in range(1, st.n_lags + 1):
            i0, i1 = max(0, lp - k), w_ext.shape[0] - k
            if i1 <= i0:
                continue
            both = k_ext[i0:i1] & k_ext[i0 + k : i1 + k]
            if not both.any():
                continue
            ck = _lag_cov(w_ext[i0:i1][both], w_ext[i0 + k : i1 + k][both], st.kernels[k])
            rd_sum[k] += float(np.sum(ck[:, 0, 0]))
            rd_cnt[k] += int(both.sum())
        prev_w = w_ext[-st.n_lags :] if st.n_lags else w_ext[:0]
        prev_keep = k_ext[-st.n_lags :] if st.n_lags else k_ext[:0]

    for ch in _chunks_of(source):
        estimate(cutter.feed(chk2(ch)))
    estimate(cutter.finish())
    if not any(r["period_index"].size for r in rows):
        raise ValidationError(
            "the design is singular in every period (auxiliary channel constant?)"
        )
    cat = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
    n_lag_max = min(st.n_lags, n_per - 1)
    with np.errstate(invalid="ignore"):
        rd = np.where(rd_cnt > 0, rd_sum / np.maximum(rd_cnt, 1), np.nan)[: n_lag_max + 1]
    pa = st.pa
    est, sig = cat["est"], cat["sig"]
    nanp = np.full(est.shape[0], np.nan)
    names = ("bias", "drift", *aux_names)
    kk = cat["period_index"]
    return DemodResult(
        period_index=kk,
        t_start=cat["t_start"],
        t_mid=cat["t_mid"],
        a_Y=est[:, 0],
        a_Z=est[:, pa],
        sigma_Y=sig[:, 0],
        sigma_Z=sig[:, pa],
        slope_Y=est[:, 1] if pa == 2 else nanp,
        slope_Z=est[:, 3] if pa == 2 else nanp,
        sigma_slope_Y=sig[:, 1] if pa == 2 else nanp,
        sigma_slope_Z=sig[:, 3] if pa == 2 else nanp,
        bias_y=cat["bias_y"],
        bias_z=cat["bias_z"],
        bias_names=names,
        n_used=cat["n_used"],
        masked_time=(st.q - cat["n_used"]) / st.fs,
        nominal_masked_time=mask,
        masked_fraction=float(n_masked / n_samples),
        leakage=cat["leakage"],
        Rd=np.asarray(rd),
        cov=cat["cov"],
        dropped=int(n_per - kk.size),
        n_periods=int(n_per),
        tau=tau,
        fs=float(st.fs),
        method=method,
        solver=used,
        signal_model=signal_model,
        rotation_shift=rotation_shift,
        pattern_periods=pattern_periods,
        rotation_shift_steady=steady,
        noise=_with_sigma_ratio(report, rd_sum[0], rd_other[0]),
        shape_gain=cat["gain"],
    )


def _noise_report(
    spectra: _ResidualSpectra | None,
    apriori: PSD,
    noise: str,
    min_periods: int,
    tau: float,
    fs: float,
) -> NoiseReport | None:
    """Estimate the PSD from the residual spectrum and decide which PSD is used."""
    if spectra is None:
        return None
    spec = spectra.spectrum()
    n = 0 if spec is None else spec.n_segments
    fit = None
    reason = ""
    if spec is None or n < min_periods or spectra.q < 8:
        reason = f"{n} period(s) for the noise estimate, fewer than {min_periods}" + (
            f" ({spectra.skipped} in rest-mask layouts beyond the first {MAX_PSD_LAYOUTS})"
            if spectra.skipped
            else ""
        )
        if spectra.q < 8:
            reason = f"{spectra.q} samples per period are too few for a noise spectrum"
    else:
        fit = fit_residual_psd(spec, psd_nodes(tau, fs))
    use_data = noise == "data" and fit is not None
    used = fit.psd if use_data else apriori
    band = (1.0 / tau, 4.0 / tau)
    ratio = scatter = float("nan")
    if spec is not None:
        ratio = spec.power_ratio(used, band)
        nb = int(np.count_nonzero((spec.f_bins >= band[0]) & (spec.f_bins <= band[1])))
        scatter = float(np.sqrt(2.0 / max(spec.dof * nb, 1)))
    if noise == "report":
        reason = "a-priori PSD asked for"
    return NoiseReport(
        source="data" if use_data else "apriori",
        reason=reason,
        fit=fit,
        apriori=apriori,
        used=used,
        check_ratio=ratio,
        check_scatter=scatter,
        band=band,
        n_periods=n,
    )


def _with_sigma_ratio(
    report: NoiseReport | None, rd_used: float, rd_other: float
) -> NoiseReport | None:
    """``report`` with ``sigma_ratio`` = σ(a-priori PSD)/σ(data PSD) for the same weights."""
    if report is None or report.fit is None or not (rd_used > 0 and rd_other > 0):
        return report
    from dataclasses import replace

    r = rd_other / rd_used if report.source == "data" else rd_used / rd_other
    return replace(report, sigma_ratio=float(np.sqrt(r)))


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
    valid: ArrayLike | None = None,
    noise: str = "apriori",
    min_periods_data: int = MIN_PERIODS_DATA_PSD,
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
    valid : array_like of bool, optional
        False for missing samples (e.g. gaps left by resampling): masked like
        rotation samples; they may hold NaN (also in θ, which then masks their
        neighbours too, since θ̇ and θ̈ cannot be evaluated there).
    noise : {"apriori", "report", "data"}
        ``"apriori"``: σ, Rd[k] and GLS from ``psd`` (eq. 21, eq. 25), nothing else.
        ``"report"``: the same, and the noise PSD is also estimated from the
        run's residual (:class:`_ResidualSpectra`,
        :func:`accal.estimators.noise.fit_residual_psd`) and compared
        (``result.noise``).  ``"data"``: σ, Rd[k] and GLS from that estimate when
        at least ``min_periods_data`` periods carry it, else from ``psd``
        (``result.noise.reason`` says why).
    min_periods_data : int
        Fewest periods for the PSD from the data (:data:`MIN_PERIODS_DATA_PSD`).

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
    arrs, ok, fs = _validate(time, m_y, m_z, theta, aux, valid, float(tau), float(mask), 1e-6)
    chunk = DemodChunk(
        arrs["time"], arrs["m_y"], arrs["m_z"], arrs["theta"], {k: arrs[k] for k in aux}, ok
    )
    return demodulate_stream(
        lambda: [chunk],
        tau=tau,
        mask=mask,
        fs=fs,
        method=method,
        signal_model=signal_model,
        bias_aux=tuple(aux),
        psd=psd,
        solver=solver,
        rest_tol=rest_tol,
        settle=settle,
        min_fraction=min_fraction,
        n_lags=n_lags,
        leak_tol=leak_tol,
        noise=noise,
        min_periods_data=min_periods_data,
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
