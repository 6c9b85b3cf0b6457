"""Fitting one read input of ``accal grace-bias``: trends, calibration, table rows.

:func:`estimate` fits the trend of every (axis, method), :func:`calibrate` removes
it, :func:`table_rows` makes the ``bias_drift`` rows, and :func:`fit_input` runs
the chain (with the closure of ``--close-loop``) into an :class:`InputFit`,
writing nothing but the closure's plots.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.calibration import parse_scale
from accal.degraded import classify_day, load_periods
from accal.errors import ValidationError
from accal.estimators.trend import fit_trends
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.reading import with_warnings
from accal.series import AccSeries
from accal.timescale import gps_to_date


def estimate(
    series: AccSeries,
    opts: GraceBiasOptions,
    exclude: dict[str, np.ndarray] | None = None,
) -> dict[tuple[str, str], Any]:
    """Fit every (axis, method) of ``series``; returns ``{(axis, method): TrendFit}``.

    ``exclude``: per axis, samples left out of that axis' fit only (where a coupling
    removed from it is unknown: ``--aux`` does not cover them).
    """
    use = np.ones(len(series), bool) if opts.keep_flagged else series.valid
    if exclude:
        fits: dict[tuple[str, str], Any] = {}
        plain = [ax for ax in series.axes if ax not in exclude]
        groups = ([(plain, use)] if plain else []) + [
            ([ax], use & ~exclude[ax]) for ax in series.axes if ax in exclude
        ]
        for axes, mask in groups:
            idx = [series.axes.index(ax) for ax in axes]
            sub = series.replace(acc=series.acc[:, idx], axes=tuple(axes), valid=mask)
            fits.update(estimate(sub, dataclasses.replace(opts, keep_flagged=False)))
        return {(ax, m): fits[(ax, m)] for ax in series.axes for m in opts.methods}
    n_use = int(np.count_nonzero(use))
    if n_use < opts.order + 2 and n_use < len(series):
        # say why (QA: a day with every sample flagged got "only 0 usable samples")
        raise ValidationError(
            f"only {n_use} usable samples of {len(series)}: {len(series) - n_use} are flagged "
            f"invalid (qualflg, gaps or --reference holes); an order-{opts.order} trend needs "
            f"at least {opts.order + 2} (--keep-flagged fits them all)"
        )
    fits = {}
    for m in opts.methods:
        for ax, fit in zip(
            series.axes,
            fit_trends(series.time, series.acc, method=m, order=opts.order, valid=use),
            strict=True,
        ):
            fits[(ax, m)] = fit
    return {(ax, m): fits[(ax, m)] for ax in series.axes for m in opts.methods}


def calibrate(
    series: AccSeries, fits: dict[tuple[str, str], Any], method: str, scale: Sequence[float] | None
) -> AccSeries:
    """Remove the trend of ``method`` from every axis and apply ``scale``.

    ``a_cal = scale · (a_raw − trend)`` (TN-02 convention, see :mod:`accal.calibration`).
    """
    acc = np.empty((len(series), len(series.axes)))
    for k, ax in enumerate(series.axes):
        col = acc[:, k]
        np.subtract(series.axis(ax), fits[(ax, method)].evaluate(series.time), out=col)
        if scale is not None:
            col *= float(scale["xyz".index(ax)])
    return series.replace(
        acc=acc,
        history=(
            *series.history,
            f"accal {__version__}: calibrate(method={method!r}, scale={scale})",
        ),
    )


def signal_share(
    series: AccSeries, minus_ref: AccSeries | None, ax: str, use: np.ndarray
) -> dict[str, Any]:
    """``bias_includes`` and ``signal_mean`` of one axis (see :data:`BIAS_DRIFT_UNITS`).

    Without a reference the fitted bias is the instrument's plus the day-mean of the
    non-gravitational signal (paper eq. 9 with a zero-mean signal assumed); with one,
    ``signal_mean`` is the mean of ``series − minus_ref`` (the reference on the data's
    epochs) over the used samples, the share a reference-free fit would have taken.
    """
    if minus_ref is None:
        return {"bias_includes": "instrument+signal_mean", "signal_mean": float("nan")}
    ref = (series.axis(ax) - minus_ref.axis(ax))[use]
    ref = ref[np.isfinite(ref)]
    return {
        "bias_includes": "instrument",
        "signal_mean": float(np.mean(ref)) if ref.size else float("nan"),
    }


def table_rows(
    path: Path, series: AccSeries, fits: dict, scale: Sequence[float] | None, opts: GraceBiasOptions
) -> list[dict[str, Any]]:
    """Build the ``bias_drift`` rows of one input."""
    periods = load_periods(opts.degraded_days) if opts.degraded_days else None
    status: dict[str, tuple[str, str]] = {}
    rows = []
    # the day of the record's midpoint: a day file may start a few seconds before
    # midnight (QA: first record 10 s early; the date of t0 was the day before, and
    # date filters missed the day)
    t = series.time
    date = gps_to_date(0.5 * (float(t[0]) + float(t[-1]))) if len(t) else ""
    for (ax, m), fit in fits.items():
        sig = fit.sigma
        s = 1.0 if scale is None else float(scale["xyz".index(ax)])
        cov = fit.cov
        denom = np.sqrt(cov[0, 0] * cov[1, 1])
        rows.append(
            {
                **row_source(path, series, opts, date or gps_to_date(fit.t0), ax),
                "method": m,
                "order": fit.order,
                "bias": fit.bias,
                "drift": fit.drift,
                "quadratic": fit.quadratic,
                "t0": fit.t0,
                "bias_sigma": float(sig[0]),
                "drift_sigma": float(sig[1]),
                "quadratic_sigma": float(sig[2]) if fit.order >= 2 else float("nan"),
                "bias_drift_corr": float(cov[0, 1] / denom) if denom > 0 else float("nan"),
                "n": fit.n_used,
                "rms": fit.rms,
                "scale": s,
                "bias_correction": -s * fit.bias,
                "sigma_model": "day",  # accal.pooling.DAY_MODEL (imported with scipy)
            }
        )
        day = rows[-1]["date"]
        if day not in status:
            status[day] = classify_day(series.satellite, day, series.meta, periods=periods)
        rows[-1]["day_status"], rows[-1]["day_status_reason"] = status[day]
    return rows


def _short_record_warning(series: AccSeries, use: np.ndarray, opts: GraceBiasOptions) -> AccSeries:
    """``series`` with a warning when its used samples span less than one orbit.

    The σ come from the record's own residual spectrum, which holds no noise slower
    than the record: on 10 samples of a real GRACE-FO day they were 20× smaller than
    on its 100 (QA, 2026-11-30: "~1000× smaller than a full day's, with only a
    record-count warning"), and such a bias is the mean level of a few seconds, not a
    day's bias.
    """
    t = series.time[use]
    span = float(t[-1] - t[0]) if t.size else 0.0
    orbit = float(opts.orbit_period or 5600.0)
    if span >= orbit:
        return series
    return with_warnings(
        series,
        f"short record ({t.size} used samples over {span:.0f} s, under one orbit of "
        f"{orbit:.0f} s): the bias is its mean level and its σ count only the noise within "
        "it; noise slower than the record is not in them (not comparable to a day's)",
    )


def row_source(
    path: Path, series: AccSeries, opts: GraceBiasOptions, date: str, ax: str
) -> dict[str, Any]:
    """The ``bias_drift`` entries that describe the input, not the fit."""
    rep = series.report
    return {
        "source": path.name,
        "satellite": series.satellite,
        "date": date,
        "axis": ax,
        "frame": series.frame,
        "n_total": len(series),
        "n_flagged": 0 if opts.keep_flagged else int((~series.valid).sum()),
        "n_duplicates": rep.n_duplicates,
        "n_out_of_order": rep.n_out_of_order,
        "n_gaps": rep.n_gaps,
        "gap_seconds": rep.gap_seconds,
        "accal_version": __version__,
        "sigma_days": 1,
    }


@dataclass(frozen=True)
class InputFit:
    """The fits of one input and its calibrated series, before anything is written.

    What :func:`fit_input` returns (and :func:`process_file` writes; the Python API,
    :mod:`accal.api`, returns it in memory).

    Attributes
    ----------
    series : AccSeries
        The input, with the warnings of the fit appended to its report.
    fit_series : AccSeries
        The series the estimators fitted (``raw − reference``, minus the instrument
        effects the closure removed).
    calibrated : AccSeries
        ``scale·(a_raw − trend)`` of the first method (effects removed with ``close_loop``).
    use : ndarray of bool
        The samples used (the calibrated file's ``valid`` column).
    fits : dict
        ``{(axis, method): TrendFit}``.
    rows : list of dict
        The ``bias_drift`` rows (one per axis and method).
    closure : dict
        ``{axis: {"summary", "instrument", "model", ...}}`` with ``close_loop`` (else empty).
    exclude : dict
        Per axis, samples left out of that axis' refit (a coupling's uncovered samples).
    outputs : tuple of Path
        The closure's plots (``opts.plots``).
    """

    series: AccSeries
    fit_series: AccSeries
    calibrated: AccSeries
    use: np.ndarray
    fits: dict[tuple[str, str], Any]
    rows: list[dict[str, Any]]
    closure: dict[str, Any]
    exclude: dict[str, np.ndarray]
    outputs: tuple[Path, ...] = ()


def fit_input(
    path: Path,
    series: AccSeries,
    fit_series: AccSeries,
    ref_series: AccSeries | None,
    opts: GraceBiasOptions,
    prefix: Path,
) -> InputFit:
    """Fit one read input (wavelet/lsq, closure with ``opts.close_loop``) and calibrate it.

    ``series`` is the input as read, ``fit_series`` what is fitted (``series`` or
    ``ref_series`` = ``series − reference``); ``path`` names the input in the rows
    (``source``) and reports; ``prefix`` is where the closure's plots go
    (``<prefix>.closure.<axis>.png``).  Writes nothing else.
    """
    scale = parse_scale(opts.scale, series.satellite)
    use = np.ones(len(series), bool) if opts.keep_flagged else fit_series.valid
    closure: dict[str, Any] = {}
    plots: list[Path] = []
    close_loop = opts.close_loop
    if close_loop:
        # imported here: accal.closure imports scipy's signal processing (~0.4 s of start-up)
        from accal.closure.select import MIN_SAMPLES

        n_use = int(np.count_nonzero(use))
        if n_use < MIN_SAMPLES:  # the declared fit still stands; say why there is no closure
            close_loop = False
            series = with_warnings(
                series,
                f"too short to close the loop ({n_use} usable samples, the residual analysis "
                f"needs {MIN_SAMPLES}): fitted with poly{opts.order} only",
            )
    if close_loop:
        # imported here: the closure modules cost ~0.4 s of start-up (scipy.signal)
        from accal.pipeline_closure import (
            before_after,
            close_the_loop,
            load_truth,
            with_effect_uncertainty,
            with_effects_removed,
        )

        fits_before = estimate(fit_series, opts)
        fit_series, closure, plots, notes = close_the_loop(
            path, series, fit_series, use, opts, prefix
        )
        series = with_warnings(series, *notes)
    exclude = {ax: c["exclude"] for ax, c in closure.items() if c.get("exclude") is not None}
    if exclude and not opts.keep_flagged:  # samples a removed coupling does not cover
        use = use & ~np.logical_or.reduce(list(exclude.values()))
    fits = estimate(fit_series, opts, exclude)
    if close_loop:
        fits = with_effect_uncertainty(fits, closure)
        truth = load_truth(opts.truth, series, opts.reference is not None) if opts.truth else {}
        for ax, entry in closure.items():
            entry["summary"]["estimates"] = before_after(fits_before, fits, ax, truth.get(ax))
    rows = table_rows(path, series, fits, scale, opts)
    for r in rows:
        r["model"] = closure.get(r["axis"], {}).get("model", f"poly{opts.order}")
        r.update(signal_share(series, ref_series, r["axis"], use))
    off = sorted({r["day_status_reason"] for r in rows if r["day_status"] == "off"})
    if off:  # a day the accelerometer was off: whatever the file holds is not its data
        series = with_warnings(
            series, f"instrument off on this day ({'; '.join(off)}): fitted, flagged 'off'"
        )
    cal = calibrate(
        series if not close_loop else with_effects_removed(series, closure),
        fits,
        opts.methods[0],
        scale,
    )
    series = _short_record_warning(series, use, opts)
    return InputFit(
        series=series,
        fit_series=fit_series,
        calibrated=cal,
        use=use,
        fits=fits,
        rows=rows,
        closure=closure,
        exclude=exclude,
        outputs=tuple(plots),
    )
