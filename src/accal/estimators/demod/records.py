"""The records of a demodulation: the chunk it reads and the results it returns.

:class:`DemodChunk` (consecutive samples, the unit :func:`demodulate_stream`
consumes), :class:`DemodResult` (per-period accelerations, σ, Rd[k], eqs. 14-23)
and :class:`NoiseReport` (the a-priori and the empirical noise, issue 20).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..noise import PSDFit

_F64 = NDArray[np.float64]


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
    misfit : dict of int to float
        Periods left out of the noise estimate because their residual power near
        ``2/τ`` is over :data:`~accal.estimators.demod.residual.MISFIT_POWER` times the
        median period's (a feature the model lacks, not noise): period index → the
        square root of that ratio, by which their σ is scaled.
    level : dict of int to float
        When the noise level near ``2/τ`` changes over the run: period index → the
        root of its block's level over the run's, by which its σ is scaled
        (:func:`~accal.estimators.demod.residual.level_factors`); empty otherwise.
    level_spread : float
        Highest over lowest block level of the run (1 for a stationary one).
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
    misfit: dict[int, float] = field(default_factory=dict)
    level: dict[int, float] = field(default_factory=dict)
    level_spread: float = 1.0


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
    cross_gain : ndarray, shape (n, 2, 2)
        The same response of ``(a_Y, a_Z)`` to the other axis' in-period signal (0 with
        rests at two opposite angles; not with four under the mean model).
    signal_leak : ndarray, shape (n, 2)
        Each period's estimated leakage into ``(a_Y, a_Z)`` [m s⁻²]
        (:func:`period_leakage`; NaN where not estimable).
    signal_leak_in_sigma : ndarray of bool, shape (n, 2)
        Where it is significant and included in ``sigma_Y``/``sigma_Z``.
    signal_leak_added : ndarray, shape (n, 2)
        What was added to them in quadrature there (the leakage with the uncertainty
        of its extrapolation) [m s⁻²]; 0 elsewhere.
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
    cross_gain: _F64 = field(default_factory=lambda: np.empty((0, 2, 2)))
    signal_leak: _F64 = field(default_factory=lambda: np.empty((0, 2)))
    signal_leak_in_sigma: NDArray[np.bool_] = field(
        default_factory=lambda: np.empty((0, 2), dtype=bool)
    )
    signal_leak_added: _F64 = field(default_factory=lambda: np.empty((0, 2)))

    @property
    def max_leakage(self) -> float:
        """Largest normalised eq. 16 residual over the kept periods."""
        return float(np.max(self.leakage)) if self.leakage.size else float("nan")


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
