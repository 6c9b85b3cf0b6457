"""The demodulation itself: :func:`demodulate_stream`, :func:`demodulate`, :func:`demodulate_table`.

A record in chunks (or in one piece) → per-period unbiased accelerations with
their uncertainties (:class:`DemodResult`), in two passes over the blocks of
whole periods.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import ValidationError, check_option
from ..noise import PSD, as_psd, regularised_autocov, structure_function
from .blocks import _Block, _chunks_of, _Periods, _Setup
from .checks import _Checker, _validate
from .estimate import _estimate_block, _scan_block
from .lagcov import _fft_length, _lag_cov, _lag_kernel
from .layout import LAYOUT_LAGS, _layout_shifts, _pattern_of_shifts
from .records import DemodChunk, DemodResult
from .residual import (
    MIN_PERIODS_DATA_PSD,
    _noise_report,
    _ResidualSpectra,
    _with_sigma_ratio,
)

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
