"""Closing the loop on rotating-platform data: the demodulation model as a block base.

:func:`close_loop_demod` is the rotating-platform front end of the shared
mechanism :func:`accal.closure.close_loop` (one mechanism, not two copies).  It
builds the demodulation model of Lenoir et al. (2013) as a
:class:`~accal.closure.blockbase.BlockBase` (one block per modulation period), with
the two measurement axes as two data channels interleaved in time, and offers the
generic candidates plus the two platform ones, :func:`~accal.closure.candidates.angle_offset`
and :func:`~accal.closure.candidates.intra_period_shape`.

Model (per period ``i`` of ``q = τ·fs`` samples, at rest samples, eq. 17 with the
bases of eqs. 18-19)::

    m_y = cos θ · Va a_Y + sin θ · Va a_Z + Vb b_y
    m_z = −sin θ · Va a_Y + cos θ · Va a_Z + Vb b_z

``Va = [1]`` (``signal_model="mean"``) or ``[1, u]`` (``"affine"``), ``Vb = [1]``
(``bias_model="constant"``), ``[1, u]`` (``"affine"``) plus the ``bias_aux``
channels (eq. 18's temperature), with ``u = (k − (q−1)/2)/q`` centred on the
period's mean sample time (as :func:`accal.estimators.demod.demodulate`), so the
intercepts are period means at ``t_mid``.  The joint least squares of eq. 17 is
exact whatever the eq. 16 leakage; with rests only at θ = 0 and π it equals the
eq. 14 demodulation.  Rotation samples are masked (discrete θ̇ = θ̈ = 0, §4.2).

References
----------
B. Lenoir, B. Christophe, S. Reynaud, "Unbiased acceleration measurements with an
electrostatic accelerometer on a rotating platform", Adv. Space Res. 51 (2013)
188-197, doi:10.1016/j.asr.2012.08.001.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.closure.basis import Basis
from accal.closure.blockbase import BlockBase
from accal.closure.platform import PlatformInfo
from accal.closure.results import ClosureResult
from accal.closure.select import close_loop
from accal.errors import ValidationError, check_option
from accal.estimators.demod import regular_step, theta_in_range
from accal.estimators.design import rest_mask

__all__ = ["DEMOD_CANDIDATES", "DemodClosure", "DemodPeriods", "close_loop_demod"]

#: Candidates tried by default on rotating-platform data.
DEMOD_CANDIDATES = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
    "angle_offset",
    "intra_period_shape",
)

_F64 = NDArray[np.float64]


@dataclass(frozen=True)
class DemodPeriods:
    """Per-period demodulated accelerations before and after closing the loop.

    Only periods whose ``a_Y`` and ``a_Z`` are determined (enough rest samples,
    full rank) and whose samples the closure did not thin (:func:`_shifted_periods`;
    said in a note) are listed.  "before": the declared demodulation model alone;
    "after": with the effects found added to the fit.  Sigmas are the
    coloured-noise uncertainties (residual PSD, sandwich covariance) [m s⁻²];
    ``sigma_change_*`` is that of the difference of the two correlated estimates.

    Attributes
    ----------
    period_index : ndarray of int
        Index of the period from the start of the record.
    t_start, t_mid : ndarray
        First sample time and mean sample time of the period [s].
    n_used : ndarray of int
        Rest samples used (per axis).
    a_Y_before, sigma_Y_before, a_Y_after, sigma_Y_after, change_Y, sigma_change_Y : ndarray
        Mean of a_Y over the period [m s⁻²].
    a_Z_before, sigma_Z_before, a_Z_after, sigma_Z_after, change_Z, sigma_change_Z : ndarray
        Same for a_Z.
    slope_Y_before, slope_Y_after, slope_Z_before, slope_Z_after : ndarray
        Slopes within the period (``signal_model="affine"``; NaN otherwise) [m s⁻³].
    sigma_slope_Y_after, sigma_slope_Z_after : ndarray
        Their uncertainty after [m s⁻³].
    effects : tuple of str
        Names of the effects added to the model (``name:channel``).
    """

    period_index: NDArray[np.int64]
    t_start: _F64
    t_mid: _F64
    n_used: NDArray[np.int64]
    a_Y_before: _F64
    sigma_Y_before: _F64
    a_Y_after: _F64
    sigma_Y_after: _F64
    change_Y: _F64
    sigma_change_Y: _F64
    a_Z_before: _F64
    sigma_Z_before: _F64
    a_Z_after: _F64
    sigma_Z_after: _F64
    change_Z: _F64
    sigma_change_Z: _F64
    slope_Y_before: _F64
    slope_Y_after: _F64
    sigma_slope_Y_after: _F64
    slope_Z_before: _F64
    slope_Z_after: _F64
    sigma_slope_Z_after: _F64
    effects: tuple[str, ...] = ()

    def to_table(self) -> dict[str, NDArray]:
        """Columns for a ``periods`` table (the "after" values under the plain names).

        ``period``, ``t_start``, ``t_mid`` [s], ``a_Y``, ``sigma_Y``, ``a_Z``,
        ``sigma_Z`` [m s⁻²] (extended model), ``a_Y_before``, ``sigma_Y_before``,
        ``a_Z_before``, ``sigma_Z_before``, ``change_Y``, ``sigma_change_Y``,
        ``change_Z``, ``sigma_change_Z``, ``n_used``, and with the affine signal
        model ``slope_Y``, ``sigma_slope_Y``, ``slope_Z``, ``sigma_slope_Z`` [m s⁻³].
        """
        out: dict[str, NDArray] = {
            "period": self.period_index,
            "t_start": self.t_start,
            "t_mid": self.t_mid,
            "a_Y": self.a_Y_after,
            "sigma_Y": self.sigma_Y_after,
            "a_Z": self.a_Z_after,
            "sigma_Z": self.sigma_Z_after,
            "a_Y_before": self.a_Y_before,
            "sigma_Y_before": self.sigma_Y_before,
            "a_Z_before": self.a_Z_before,
            "sigma_Z_before": self.sigma_Z_before,
            "change_Y": self.change_Y,
            "sigma_change_Y": self.sigma_change_Y,
            "change_Z": self.change_Z,
            "sigma_change_Z": self.sigma_change_Z,
            "n_used": self.n_used,
        }
        if np.any(np.isfinite(self.slope_Y_after)):
            out.update(
                {
                    "slope_Y": self.slope_Y_after,
                    "sigma_slope_Y": self.sigma_slope_Y_after,
                    "slope_Z": self.slope_Z_after,
                    "sigma_slope_Z": self.sigma_slope_Z_after,
                }
            )
        return out


class DemodClosure(NamedTuple):
    """What :func:`close_loop_demod` returns: ``result, periods = close_loop_demod(...)``.

    Attributes
    ----------
    result : ClosureResult
        The shared closure result (effects, notes, residuals of both axes as two
        channels ``"y"``/``"z"``, base coefficients ``a_Y[i]``, ``bias_y[i]``, ...).
    periods : DemodPeriods
        Per-period ``a_Y``, ``a_Z`` before/after with sigmas.
    """

    result: ClosureResult
    periods: DemodPeriods


def _as_two_axes(m) -> tuple[_F64, _F64]:
    if isinstance(m, Sequence) and not isinstance(m, np.ndarray) and len(m) == 2:
        my, mz = (np.asarray(x, dtype=np.float64) for x in m)
    else:
        a = np.asarray(m, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 2:
            raise ValidationError(f"m must have shape (N, 2) (m_y, m_z), got {a.shape}")
        my, mz = a[:, 0], a[:, 1]
    if my.shape != mz.shape or my.ndim != 1:
        raise ValidationError(
            f"m_y and m_z must be 1-D of equal length, got {my.shape}, {mz.shape}"
        )
    return my, mz


def _rest_runs(theta: _F64, rest: NDArray[np.bool_], fs: float):
    """Time since rest began, direction of the last rotation, rest angle (time samples).

    Per rest run: its angle is the median of θ over the run rounded to 1e-3 rad, the
    time since rest ``k / fs`` at its ``k``-th sample (unknown, NaN, for a run at the
    record's start), the direction the sign of the change from the previous run's
    angle (0 for the first run and where the angle is unchanged).  All runs at once:
    the medians from one sort of θ by run (the middle value, or the mean of the two
    middle values, as :func:`numpy.median` takes them; NaN for a run holding a NaN).
    """
    n = theta.size
    since = np.full(n, np.nan)
    direction = np.zeros(n)
    angle = np.full(n, np.nan)
    starts = np.flatnonzero(rest & ~np.r_[False, rest[:-1]])
    stops = np.flatnonzero(rest & ~np.r_[rest[1:], False]) + 1
    if starts.size == 0:
        return since, direction, angle
    lens = stops - starts
    run = np.repeat(np.arange(starts.size), lens)
    vals = theta[rest]  # the runs' samples, run after run
    srt = vals[np.lexsort((vals, run))]  # sorted within each run (NaN last)
    first = np.r_[0, np.cumsum(lens)[:-1]]
    hi = srt[first + lens // 2]
    lo = srt[first + (lens - 1) // 2]
    med = np.where(lens % 2 == 1, hi, (lo + hi) / 2.0)
    med[np.add.reduceat(np.isnan(vals), first) > 0] = np.nan
    ang = np.round(med, 3)
    angle[rest] = ang[run]
    pos = (np.arange(run.size) - first[run]) / fs
    if starts[0] == 0:  # the first run's history is unknown
        pos[: lens[0]] = np.nan
    since[rest] = pos
    dirs = np.zeros(starts.size)
    chg = ang[1:] != ang[:-1]
    dirs[1:][chg] = np.sign(ang[1:] - ang[:-1])[chg]
    direction[rest] = dirs[run]
    return since, direction, angle


def close_loop_demod(
    time: ArrayLike,
    m: ArrayLike | Sequence[ArrayLike],
    theta: ArrayLike,
    valid: ArrayLike | None = None,
    *,
    tau: float,
    signal_model: str = "mean",
    bias_model: str = "affine",
    bias_aux: Mapping[str, ArrayLike] | None = None,
    aux: Mapping[str, ArrayLike] | None = None,
    candidates: Sequence[str | Callable] = DEMOD_CANDIDATES,
    rest_tol: float = 1e-9,
    settle: float = 0.0,
    min_fraction: float = 0.5,
    alpha: float = 0.01,
    max_effects: int = 5,
    orbit_period: float | None = None,
    catchall_knots: int = 24,
    options: dict[str, Any] | None = None,
    noise_psd: Any = None,
    psd_update: Any = None,
) -> DemodClosure:
    """Close the loop on rotating-platform data with the demodulation model as base.

    Parameters
    ----------
    time : array_like, shape (N,)
        Sample times, uniform step [s].
    m : array_like, shape (N, 2), or (m_y, m_z)
        Measurements of the two axes in the rotation plane [m s⁻²] (eq. 4).
    theta : array_like, shape (N,)
        Platform angle θ [rad].
    valid : array_like of bool, shape (N,), optional
        Samples to use (rotation samples are masked in addition, §4.2).
    tau : float
        Modulation period τ [s]; ``τ·fs`` must be an integer.
    signal_model : {"mean", "affine"}
        ``Va``: signal mean per period (eq. 18) or mean and slope (eq. 19).
    bias_model : {"affine", "constant"}
        ``Vb``: bias affine in time per period (eqs. 19, :func:`demodulate`) or constant.
    bias_aux : mapping of str to array_like, shape (N,), optional
        Channels in the declared per-period bias (eq. 18's temperature column;
        per-period coefficient) [channel units].
    aux : mapping of str to array_like, shape (N,), optional
        Channels offered to the ``auxiliary`` candidate (one global coupling per
        axis, with lag and first-order response search).
    candidates : sequence of str or callable
        Effect builders (default :data:`DEMOD_CANDIDATES`).
    rest_tol : float
        Tolerance on the discrete θ̇ and θ̈ of the rest mask [rad].
    settle : float
        Extra time masked on each side of every rotation [s].
    min_fraction : float
        A period is used when it has at least this fraction of the median number of
        rest samples per period.
    alpha, max_effects, orbit_period, catchall_knots, options, noise_psd, psd_update
        As in :func:`accal.closure.close_loop` (``options["settle_taus"]``: time
        constants searched by ``intra_period_shape`` [s]; ``options["max_lag"]``:
        longest auxiliary lag searched, default the larger of ``τ/2`` and
        min(span/20, 1 h); ``options["lag_period"]``, default ``τ``: a channel that
        repeats with the pattern couples the same at lags a period apart, and the
        shortest such lag that explains as much is taken; ``options["lag_scan"]``,
        default ``"fine"``: the couplings' lags are scanned at every sample,
        ``"grid"`` at 31 lags, :mod:`accal.closure.lagscan`).

    Returns
    -------
    DemodClosure
        ``(result, periods)``.

    Raises
    ------
    ValidationError
        Bad shapes, irregular sampling, non-integer ``τ·fs``, θ in degrees, no
        usable period.

    Notes
    -----
    What the platform candidates can and cannot see is decided numerically (the
    regressor must keep part of its norm after the base is projected out) and
    reported in ``result.notes``: a *common* angle offset is a rotation of
    ``(a_Y, a_Z)`` and is never identifiable; an offset of one rest angle relative
    to the others is identifiable only with rests at three or more angles (see
    :func:`accal.closure.candidates.angle_offset`).
    """
    check_option("signal_model", signal_model, ("mean", "affine"))
    check_option("bias_model", bias_model, ("affine", "constant"))
    t, my, mz, th, v, fs, q = _check_record(time, m, theta, valid, tau)
    n = t.size
    n_per = n // q

    finite = np.isfinite(my) & np.isfinite(mz) & np.isfinite(th)
    rest = rest_mask(np.nan_to_num(th), tol=rest_tol, settle=int(round(settle * fs)))
    period = np.arange(n) // q
    period[n_per * q :] = -1
    use_t = v & finite & rest & (period >= 0)
    counts = np.bincount(period[use_t], minlength=n_per)
    rest_counts = np.bincount(period[rest & (period >= 0)], minlength=n_per)
    u = (np.arange(n) % q - (q - 1) / 2) / q

    # columns per time sample (eq. 17): signal (Va) and bias (Vb) kinds
    va = [np.ones(n)] + ([u] if signal_model == "affine" else [])
    vb, vb_names, vb_scale = _bias_kinds(bias_model, u, tau, bias_aux, period, use_t, counts)
    need = max(min_fraction * float(np.median(rest_counts)), 2 * (2 * len(va) + 2 * len(vb)))
    good_period = counts >= need
    if not good_period.any():
        raise ValidationError(
            f"no period has enough rest samples (need {need:g}, best has {int(counts.max())})"
        )
    use_t &= good_period[np.maximum(period, 0)] & (period >= 0)

    c, s = np.cos(th), np.sin(th)
    base, cols, names = _demod_base(c, s, u, va, vb, vb_names, vb_scale, tau, period, n_per)
    y_s = np.empty(2 * n)
    y_s[0::2], y_s[1::2] = my, mz
    use_s = np.repeat(use_t, 2)
    chan = np.tile(np.array([0, 1]), n)
    info = _platform_info(th, rest, fs, u, len(va), period, cols, y_s, use_s, chan, n_per)
    aux_s = _aux_samples(aux, n)
    res = close_loop(
        np.repeat(t, 2),
        y_s,
        base=base,
        aux=aux_s,
        valid=use_s,
        candidates=candidates,
        alpha=alpha,
        max_effects=max_effects,
        orbit_period=orbit_period,
        catchall_knots=catchall_knots,
        # lags beyond τ/2 for channels that do not repeat with τ (QA: a slow channel at
        # 1000 s was missed, a_Y std z 31); one that repeats takes its shortest lag
        options={
            "max_lag": max(0.5 * float(tau), min(float(t[-1] - t[0]) / 20.0, 3600.0)),
            "lag_period": float(tau),
            **(options or {}),
            "platform": info,
        },
        channel=chan,
        channel_names=("y", "z"),
        noise_psd=noise_psd,
        psd_update=psd_update,
        # rounding of the measurements (a noise-free simulation leaves nothing else)
        resolution=float(np.finfo(np.float64).eps * np.nanmax(np.abs(y_s[use_s]))),
    )
    shifted = _shifted_periods(res.use[0::2] | res.use[1::2], use_t, t, period, n_per, 1.0 / fs)
    if shifted.any():
        res = replace(res, notes=(*res.notes, _shifted_note(np.flatnonzero(shifted))))
    return DemodClosure(res, _periods(res, names, n_per, q, fs, float(t[0]), counts, shifted))


def _shifted_periods(use_after, use_t, t, period, n_per: int, step: float) -> NDArray[np.bool_]:
    """Periods whose used samples the closure thinned so that their mean time moved by
    over a sample step (e.g. the first ``L`` seconds of a coupling at lag ``L``, left
    out as its lagged channel is unknown there).

    A period's values are means over its used samples (eq. 18): a signal that varies
    over the day moves them by its slope times the shift of that mean time (QA: the
    first period of a platform run with 343 s of 600 left out had a_Y 2.2e-10 m/s², 52σ,
    from the period's mean, the same before and after closure: the mean time of its rest
    samples moved by 175 s, times the signal's 9.2e-13 m/s² per s, 1.6e-10 m/s²).  Such
    a period is not comparable with the declared model's and is left out of the table,
    as the demodulation leaves out a period with too few rest samples.
    """
    ok = period >= 0

    def mean_time(mask):
        m = mask & ok
        n = np.bincount(period[m], minlength=n_per)
        return np.bincount(period[m], weights=t[m], minlength=n_per) / np.maximum(n, 1), n

    t0, n0 = mean_time(use_t)
    t1, n1 = mean_time(use_after & use_t)
    return (n0 > 0) & (n1 > 0) & (np.abs(t1 - t0) > step)


def _shifted_note(periods: NDArray[np.int64]) -> dict[str, Any]:
    """The closure note on the periods :func:`_shifted_periods` left out."""
    listed = ", ".join(str(int(k)) for k in periods[:10]) + (", ..." if periods.size > 10 else "")
    return {
        "name": "closure",
        "channel": None,
        "note": f"{periods.size} period(s) left out of the table ({listed}): the closure "
        "left out part of their samples (a lagged channel unknown there), so their "
        "means would refer to another time than the period's",
        "details": {"periods": [int(k) for k in periods]},
    }


def _check_record(time, m, theta, valid, tau: float):
    """Checked ``(t, m_y, m_z, θ, valid, fs, q)`` of a record, ``q = τ·fs`` samples a period."""
    t = np.asarray(time, dtype=np.float64)
    my, mz = _as_two_axes(m)
    th = np.asarray(theta, dtype=np.float64)
    n = t.size
    if t.ndim != 1 or my.size != n or th.shape != t.shape:
        raise ValidationError(
            f"time, m and theta must have the same length, got {t.shape}, {my.shape}, {th.shape}"
        )
    if n < 3:
        raise ValidationError(f"need at least 3 samples, got {n}")

    dt, dt_rtol = regular_step(t)
    fs = 1.0 / dt
    qf = float(tau) * fs
    if not np.isfinite(qf) or qf <= 0 or abs(qf - round(qf)) > max(1e-6, qf * dt_rtol):
        raise ValidationError(f"tau·fs = {qf:g} must be a positive integer (fs = {fs:g} Hz)")
    q = int(round(qf))
    th = theta_in_range(th, None, 1e-6)
    v = np.ones(n, bool) if valid is None else np.asarray(valid, dtype=bool)
    if v.shape != t.shape:
        raise ValidationError(f"valid must have shape {t.shape}, got {v.shape}")
    if n // q < 1:
        raise ValidationError(f"record of {n} samples is shorter than one period ({q})")
    return t, my, mz, th, v, fs, q


def _bias_kinds(bias_model: str, u, tau: float, bias_aux, period, use_t, counts):
    """The bias columns ``Vb`` per time sample (eqs. 18-19), their names and scales.

    A ``bias_aux`` channel enters with its per-period mean removed, scaled to unit
    standard deviation over the used samples.
    """
    n = u.size
    n_per = counts.size
    vb = [np.ones(n)] + ([u] if bias_model == "affine" else [])
    vb_names = ["bias"] + (["drift"] if bias_model == "affine" else [])
    vb_scale = [1.0] + ([1.0 / tau] if bias_model == "affine" else [])
    for name, x in (bias_aux or {}).items():
        a = np.asarray(x, dtype=np.float64)
        if a.shape != u.shape:
            raise ValidationError(
                f"bias_aux channel {name!r} must have shape {u.shape}, got {a.shape}"
            )
        sums = np.bincount(period[use_t], weights=a[use_t], minlength=n_per)
        mean = sums / np.maximum(counts, 1)
        a = a - np.where(period >= 0, mean[np.maximum(period, 0)], 0.0)
        sc = float(np.std(a[use_t])) or 1.0
        vb.append(a / sc)
        vb_names.append(name)
        vb_scale.append(1.0 / sc)
    return vb, vb_names, vb_scale


def _demod_base(c, s, u, va, vb, vb_names, vb_scale, tau: float, period, n_per: int):
    """The eq. 17 block base (one block a period), the two axes interleaved in time.

    Returns the base, its columns (2N, p) and the names of its parameters.
    """
    n = c.size
    zero = np.zeros(n)
    # a_Y, a_Z (then slopes), bias_y..., bias_z...
    sig_y = [c * va[0], s * va[0]] + ([c * va[1], s * va[1]] if len(va) > 1 else [])
    sig_z = [-s * va[0], c * va[0]] + ([-s * va[1], c * va[1]] if len(va) > 1 else [])
    cols_y = sig_y + vb + [zero] * len(vb)
    cols_z = sig_z + [zero] * len(vb) + vb
    names = ["a_Y", "a_Z"] + (["slope_Y", "slope_Z"] if len(va) > 1 else [])
    scale = [1.0, 1.0] + ([1.0 / tau, 1.0 / tau] if len(va) > 1 else [])
    names += [f"{x}_y" for x in vb_names] + [f"{x}_z" for x in vb_names]
    scale += vb_scale + vb_scale
    p = len(names)
    cols = np.empty((2 * n, p))
    cols[0::2] = np.column_stack(cols_y)
    cols[1::2] = np.column_stack(cols_z)
    base = BlockBase(
        np.repeat(period, 2),
        cols,
        tuple(names),
        scale=np.asarray(scale),
        block_labels=tuple(range(n_per)),
        signal=tuple(range(len(sig_y))),  # a_Y, a_Z (and slopes): the modulated signal
        signal_extension=_signal_extension(c, s, u, len(va)),
    )
    return base, cols, names


def _platform_info(th, rest, fs, u, n_va, period, cols, y_s, use_s, chan, n_per):
    """θ, the base-alone fitted signal and the rest runs, per interleaved sample."""
    block = np.repeat(period, 2)
    p = cols.shape[1]
    b0 = Basis(block[use_s], cols[use_s], n_blocks=n_per)
    beta = b0.fit(np.nan_to_num(y_s[use_s])).beta.reshape(n_per, p)
    pk = np.maximum(period, 0)
    ay = beta[pk, 0] + (beta[pk, 2] * u if n_va > 1 else 0.0)
    az = beta[pk, 1] + (beta[pk, 3] * u if n_va > 1 else 0.0)
    since, direction, angle = _rest_runs(th, rest, fs)
    return PlatformInfo(
        theta=np.repeat(th, 2),
        signal_y=np.repeat(np.nan_to_num(ay), 2),
        signal_z=np.repeat(np.nan_to_num(az), 2),
        axis_index=chan,
        since_rest=np.repeat(since, 2),
        direction=np.repeat(direction, 2),
        rest_angle=np.repeat(angle, 2),
    )


def _aux_samples(aux, n: int) -> dict[str, _F64]:
    """The ``aux`` channels repeated onto the interleaved samples, each checked for length."""
    aux_s = {k: np.repeat(np.asarray(x, dtype=np.float64), 2) for k, x in (aux or {}).items()}
    for k, x in aux_s.items():
        if x.size != 2 * n:
            raise ValidationError(
                f"auxiliary channel {k!r} must have {n} samples, got {x.size // 2}"
            )
    return aux_s


def _signal_extension(c, s, u, n_va: int) -> NDArray[np.float64]:
    """Signal columns one degree beyond the declared signal model, interleaved (y, z).

    The mean model's signal may still change within a period (its slope), the affine
    model's its curvature: a candidate inside their span is that change, modulated
    by θ (QA: lines at the modulation's sidebands 585 and 615 s on a τ = 600 s run).
    """
    w = u**n_va
    cols = np.empty((2 * u.size, 2))
    cols[0::2] = np.column_stack([c * w, s * w])
    cols[1::2] = np.column_stack([-s * w, c * w])
    return cols


def _periods(res: ClosureResult, names, n_per, q, fs, t0, counts, dropped) -> DemodPeriods:
    """The per-period table of a closure result (periods in ``dropped`` left out)."""
    p = len(names)

    def col(attr: str, name: str) -> _F64:
        j = names.index(name)
        return np.array([getattr(res.base[i * p + j], attr) for i in range(n_per)])

    def opt(attr: str, name: str) -> _F64:
        return col(attr, name) if name in names else np.full(n_per, np.nan)

    ok = np.isfinite(col("after", "a_Y")) & np.isfinite(col("after", "a_Z")) & ~dropped
    kk = np.flatnonzero(ok)
    t_start = t0 + kk * q / fs

    def sel(x: _F64) -> _F64:
        return x[kk]

    return DemodPeriods(
        period_index=kk,
        t_start=t_start,
        t_mid=t_start + 0.5 * (q - 1) / fs,
        n_used=counts[kk].astype(np.int64),
        a_Y_before=sel(col("before", "a_Y")),
        sigma_Y_before=sel(col("sigma_before", "a_Y")),
        a_Y_after=sel(col("after", "a_Y")),
        sigma_Y_after=sel(col("sigma_after", "a_Y")),
        change_Y=sel(col("change", "a_Y")),
        sigma_change_Y=sel(col("sigma_change", "a_Y")),
        a_Z_before=sel(col("before", "a_Z")),
        sigma_Z_before=sel(col("sigma_before", "a_Z")),
        a_Z_after=sel(col("after", "a_Z")),
        sigma_Z_after=sel(col("sigma_after", "a_Z")),
        change_Z=sel(col("change", "a_Z")),
        sigma_change_Z=sel(col("sigma_change", "a_Z")),
        slope_Y_before=sel(opt("before", "slope_Y")),
        slope_Y_after=sel(opt("after", "slope_Y")),
        sigma_slope_Y_after=sel(opt("sigma_after", "slope_Y")),
        slope_Z_before=sel(opt("before", "slope_Z")),
        slope_Z_after=sel(opt("after", "slope_Z")),
        sigma_slope_Z_after=sel(opt("sigma_after", "slope_Z")),
        effects=tuple(
            e.name if e.channel is None else f"{e.name}:{e.channel}" for e in res.effects
        ),
    )
