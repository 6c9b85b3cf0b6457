"""The demodulation itself: :func:`demodulate_stream`, :func:`demodulate`, :func:`demodulate_table`.

A record in chunks (or in one piece) → per-period unbiased accelerations with
their uncertainties (:class:`DemodResult`), by the two passes of
:mod:`accal.estimators.demod.passes`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace
from functools import partial

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ValidationError, check_option
from ..noise import PSD, as_psd
from .blocks import _Setup
from .checks import _Checker, _validate
from .layout import _pattern_of_shifts
from .passes import _Estimates, _first_pass, _new_setup, _noise_kernels, _Scan, _second_pass
from .records import DemodChunk, DemodResult, NoiseReport
from .residual import MIN_PERIODS_DATA_PSD, _noise_report, _with_sigma_ratio
from .series import with_signal_leak

#: Columns :func:`demodulate_table` needs.
REQUIRED_COLUMNS = ("time", "m_y", "m_z", "theta")


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
    # pass 1: checks, rest masks, usable periods, eq. 16 leakage
    setup = partial(
        _new_setup,
        tau=tau,
        mask=mask,
        method=method,
        signal_model=signal_model,
        aux_names=aux_names,
        min_fraction=min_fraction,
        n_lags=n_lags,
    )
    chk = _Checker(aux_names, tau, mask, fs, live=noise != "apriori")
    scan = _first_pass(source, chk, setup, rest_tol=rest_tol, settle=settle, noise=noise)
    st = scan.st
    layout = _pattern_of_shifts(scan.shifts)
    used = _solver_used(method, solver, aux_names, scan.leak_max, leak_tol)
    report = _noise_report(scan.spectra, psd, noise, int(min_periods_data), tau, st.fs)
    _noise_kernels(st, psd if report is None else report.used, report, used)
    # pass 2: estimates, covariances, Rd[k] across block borders
    acc = _second_pass(
        source, st, used, _Checker(aux_names, tau, mask, st.fs), rest_tol=rest_tol, settle=settle
    )
    # a period's leakage of the signal's in-period variation, in its σ where significant
    return with_signal_leak(_with_misfit(_result(st, scan, acc, used, layout, report)))


def _with_misfit(res: DemodResult) -> DemodResult:
    """``res`` with the σ of the periods left out of the data's noise estimate for their
    misfit (``res.noise.misfit``, :data:`accal.estimators.demod.residual.MISFIT_POWER`)
    scaled by the root of their power ratio: their residual is not the noise the PSD
    describes, and their values hold what made it (QA, a 1e-9 m/s² signal step inside
    a rotation: that period's error 1.6e-11 m/s², 32 times the noise σ)."""
    rep = res.noise
    if rep is None or not (rep.misfit or rep.level) or rep.source != "data":
        return res
    f = np.array([sigma_factor(rep, int(k)) for k in res.period_index], dtype=np.float64)
    return replace(res, sigma_Y=res.sigma_Y * f, sigma_Z=res.sigma_Z * f)


def sigma_factor(rep: NoiseReport, period: int) -> float:
    """The factor a period's σ is scaled by: its misfit's, else its block's noise level
    (:func:`accal.estimators.demod.residual.level_factors`), else 1."""
    if period in rep.misfit:
        return rep.misfit[period]
    return rep.level.get(period, 1.0)


def _solver_used(
    method: str, solver: str, aux_names: tuple[str, ...], leak_max: float, leak_tol: float
) -> str:
    """The estimator of pass 2: ``"gls-eq17"``, ``"eq14"`` or ``"joint"``.

    ``solver="auto"`` takes eq. 14 when there is no auxiliary channel and no kept
    period's eq. 16 leakage exceeds ``leak_tol``, the joint LS of eq. 17 otherwise.
    """
    if method == "gls":
        return "gls-eq17"
    if solver == "auto":
        return "eq14" if (not aux_names and leak_max <= leak_tol) else "joint"
    return solver


def _result(
    st: _Setup,
    scan: _Scan,
    acc: _Estimates,
    solver: str,
    layout: tuple[float, int, bool],
    report: NoiseReport | None,
) -> DemodResult:
    """The :class:`DemodResult` of the two passes (Rd[k] averaged over the period pairs)."""
    rows = acc.rows
    n_per = scan.n_per
    cat = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
    n_lag_max = min(st.n_lags, n_per - 1)
    with np.errstate(invalid="ignore"):
        rd = np.where(acc.rd_cnt > 0, acc.rd_sum / np.maximum(acc.rd_cnt, 1), np.nan)[
            : n_lag_max + 1
        ]
    pa = st.pa
    est, sig = cat["est"], cat["sig"]
    nanp = np.full(est.shape[0], np.nan)
    names = ("bias", "drift", *st.aux_names)
    kk = cat["period_index"]
    rotation_shift, pattern_periods, steady = layout
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
        nominal_masked_time=st.mask,
        masked_fraction=float(acc.n_masked / acc.n_samples),
        leakage=cat["leakage"],
        Rd=np.asarray(rd),
        cov=cat["cov"],
        dropped=int(n_per - kk.size),
        n_periods=int(n_per),
        tau=st.tau,
        fs=float(st.fs),
        method=st.method,
        solver=solver,
        signal_model=st.signal_model,
        rotation_shift=rotation_shift,
        pattern_periods=pattern_periods,
        rotation_shift_steady=steady,
        noise=_with_sigma_ratio(report, acc.rd_sum[0], acc.rd_other),
        shape_gain=cat["gain"],
        cross_gain=cat["xgain"],
    )


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
