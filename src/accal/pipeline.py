"""The ``grace-bias`` pipeline: read → validate → estimate → correct → write, per input.

This module only sequences the other layers (readers in :mod:`accal.io`,
estimators in :mod:`accal.estimators`, writers in :mod:`accal.io.writers`); it
computes nothing itself.  One input's failure never stops the others: each is
reported as a :class:`FileOutcome` with a one-line message.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import os
import sys
import time as _time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.batch import (
    LOCK,
    Outcome,
    check_input,
    failure_message,
    file_signature,
    internal_error_message,
    write_error_message,
)
from accal.errors import AccalError, ValidationError, check_option
from accal.io.writers import run_guard
from accal.plausibility import flag_wild_samples
from accal.series import ACC_UNIT_FACTORS, AccSeries, acceleration_factor

#: Columns the reference fit adds to ``bias_drift`` (NaN/"" for the wavelet/lsq methods;
#: :mod:`accal.pipeline_reference`).
REFERENCE_UNITS = {
    "scale_x": "1 (row of the scale matrix S for this axis: a_cal_axis = sum_j S_axis,j "
    "(a_raw_j - bias_j); the diagonal entry equals 'scale'; NaN unless --bias-basis/--scale fit)",
    "scale_y": "1 (see scale_x)",
    "scale_z": "1 (see scale_x)",
    "scale_x_sigma": "1 (1 sigma; 0 where fixed)",
    "scale_y_sigma": "1 (1 sigma; 0 where fixed)",
    "scale_z_sigma": "1 (1 sigma; 0 where fixed)",
    "scale_mode": "given (a-priori --scale) | fit | fit-matrix | fixed (not identifiable, "
    "a-priori kept)",
    "bias_basis": "temporal basis of the bias (poly<d> or spline:<node step>s); empty for "
    "the wavelet/lsq methods",
    "n_thruster": "samples excluded as within a thruster firing (with its margins)",
}

#: Columns of ``bias_drift.<fmt>`` and their units (written into the file metadata).
BIAS_DRIFT_UNITS = {
    "source": "input file name",
    "satellite": "satellite identifier",
    "date": "GPS-calendar date of the record's midpoint (YYYY-MM-DD; the L1B file day)",
    "axis": "accelerometer axis (x|y|z), frame in 'frame'",
    "frame": "reference frame of the axes",
    "method": "estimator (wavelet|lsq|reference: AR-weighted LS against --reference)",
    "order": "polynomial order of the trend",
    "bias": "m/s^2 (trend value at t0, raw-data sign: a_raw = s*a + bias + drift*(t-t0))",
    "drift": "m/s^3",
    "quadratic": "m/s^4 (order 2 only, else NaN)",
    "t0": "s (GPS seconds of the first sample used)",
    "bias_sigma": "m/s^2 (1 sigma, coloured-noise aware)",
    "drift_sigma": "m/s^3 (1 sigma)",
    "quadratic_sigma": "m/s^4 (1 sigma)",
    "bias_drift_corr": "correlation coefficient of bias and drift",
    "n": "samples used",
    "rms": "m/s^2 (residual RMS after removing the trend)",
    "scale": "scale applied to the calibrated series (a_cal = scale*(a_raw - trend)), 1 if none",
    "bias_correction": "m/s^2 (-scale*bias: the additive correction in GRACE TN-02's sign)",
    "n_total": "samples in the file after de-duplication",
    "n_flagged": "samples excluded by quality flags",
    "n_duplicates": "duplicated epochs dropped",
    "n_out_of_order": "out-of-order epochs sorted",
    "n_gaps": "gaps longer than 1.5 nominal steps",
    "gap_seconds": "s (total length of the gaps)",
    "accal_version": "accal version that produced the row",
    "model": "fitted model: poly<order> plus the effects --close-loop added, '+'-separated",
    "day_status": "nominal|degraded|transplant|off: whether the day is the instrument's own "
    "nominal measurement (accal.degraded; GRACE-FO D transplant, GRACE-B off/transplant 2016-17)",
    "day_status_reason": "why the day is not nominal (empty when nominal)",
    "bias_includes": "what 'bias' holds: 'instrument' (fitted to raw - reference) or "
    "'instrument+signal_mean' (no reference: the day-mean of the non-gravitational signal, "
    "e.g. -1e-7 m/s^2 of drag on the along-track axis, is in the bias; paper eq. 9 assumes "
    "a zero-mean signal)",
    "signal_mean": "m/s^2 (mean of the reference over the used samples: the non-gravitational "
    "signal's share a fit without --reference would put into the bias; NaN without one)",
    "sigma_model": "noise model of the sigmas: 'day' (the day's own binned residual periodogram) "
    "or 'pooled: <model>' (--pool-days: white + power-law/AR(1) noise fitted to adjacent days, "
    "accal.estimators.lowfreq)",
    "sigma_days": "days whose residual spectra the sigmas rest on",
    **REFERENCE_UNITS,
}

CALIBRATED_UNITS = {
    "gps_time": "s (GPS seconds since 2000-01-01 12:00:00)",
    "lin_accl_x": "m/s^2 (trend removed, scale applied)",
    "lin_accl_y": "m/s^2 (trend removed, scale applied)",
    "lin_accl_z": "m/s^2 (trend removed, scale applied)",
    "valid": "True where the sample was used in the fit",
    "qualflg": "source quality bitmask (bit 0 = LSB)",
}

KEY_COLUMNS = ["source", "axis", "method"]


@dataclass(frozen=True)
class GraceBiasOptions:
    """Options of ``accal grace-bias`` (CLI flags and config keys of the same names).

    Attributes
    ----------
    methods : tuple of str
        Estimators to run, the first one calibrates the series.
    order : int
        Trend order (1 or 2).
    fmt : str
        Output format, ``"parquet"`` or ``"csv"``.
    scale : str or None
        ``None``, ``"tn02"`` or ``"sx,sy,sz"`` (see :mod:`accal.calibration`).
    keep_flagged : bool
        Use samples that the source's quality flags mark invalid.
    reference : Path or None
        File with reference accelerations; the fit is made on ``raw − reference``.
    columns : dict
        Axis → source column mapping for table inputs (``--column x=a_cal_x``).
    input_format : str or None
        Force an input format instead of sniffing.
    close_loop : bool
        Analyse each axis' residual, add the effects the bias + drift model lacks
        (:func:`accal.closure.close_loop`) and refit with the extended model.
    aux : Path or None
        Housekeeping file (AHK1B or a table) whose channels are candidate
        auxiliary effects of the closure (joined on time).
    truth : Path or None
        Truth JSON of a simulation (``accal simulate grace``): the closure report
        gives the true error of bias and drift before and after.
    alpha : float
        Family-wise false-detection probability of the closure per step.
    orbit_period : float or None
        Nominal orbit period [s] of the closure's orbit-signal model (refined on the
        data) and orbit harmonics.
    plots : bool
        With ``close_loop``: write the closure's PNG plots.
    degraded_days : Path or None
        TOML/YAML table of degraded/transplant/off periods ahead of the built-in
        one (:func:`accal.degraded.load_periods`).
    pool_days : int
        ``>= 2``: the σ of the ``bias_drift`` table come from a noise model fitted to
        this many adjacent days together (:mod:`accal.pooling`); ``0``: each day's
        own estimate.
    bias_basis : str or None
        With ``reference``: fit the bias on this temporal basis (``poly0``,
        ``poly1``, ``poly2``, ``spline:6h``, ...) by AR-weighted least squares
        against the reference (:mod:`accal.estimators.reference`).  ``scale`` may
        then also be ``"fit"`` (a scale per axis) or ``"fit-matrix"`` (3×3).
    thrusters : Path or None
        THR1B file whose firings the reference fit leaves out (default: the THR1B
        file beside the input, if any).
    thruster_margins : tuple of 2 float or None
        Seconds left out before and after each firing (GROOPS: 0.1, 0.7); ``None``:
        no thruster screening.
    reference_frame : str
        ``"srf"`` or ``"inertial"`` (rotated into the SRF with the SCA1B attitude).
    attitude : Path or None
        SCA1B file for ``reference_frame="inertial"`` (default: the one beside the input).
    arc : str
        ``"day"`` (each input alone), ``"<N>d"`` (up to N consecutive days of one
        satellite in one reference fit) or ``"month"`` (the days of a calendar month).
    """

    methods: tuple[str, ...] = ("wavelet",)
    order: int = 1
    fmt: str = "parquet"
    scale: str | None = None
    keep_flagged: bool = False
    reference: Path | None = None
    columns: dict[str, str] = field(default_factory=dict)
    input_format: str | None = None
    close_loop: bool = False
    aux: Path | None = None
    truth: Path | None = None
    alpha: float = 0.01
    orbit_period: float | None = 5600.0
    plots: bool = False
    degraded_days: Path | None = None
    pool_days: int = 0
    bias_basis: str | None = None
    thrusters: Path | None = None
    thruster_margins: tuple[float, float] | None = (0.1, 0.7)
    reference_frame: str = "srf"
    attitude: Path | None = None
    arc: str = "day"

    @property
    def reference_fit(self) -> bool:
        """True when the bias is fitted against the reference with a basis and/or scales."""
        return self.bias_basis is not None or self.scale in ("fit", "fit-matrix")

    def __post_init__(self) -> None:
        from accal.estimators.trend import METHODS

        for m in self.methods:
            check_option("method", m, tuple(METHODS))
        check_option("order", self.order, (1, 2))
        check_option("format", self.fmt, ("parquet", "csv"))
        if not (isinstance(self.pool_days, int) and (self.pool_days == 0 or self.pool_days >= 2)):
            raise ValidationError(f"pool_days must be 0 (off) or >= 2, got {self.pool_days!r}")
        check_option("reference_frame", self.reference_frame, ("srf", "inertial"))
        if self.arc != "day":
            from accal.pipeline_reference import parse_arc

            parse_arc(self.arc)
            if not self.reference_fit:
                raise ValidationError(
                    f"--arc {self.arc} groups days into one reference fit: add --bias-basis "
                    "or --scale fit"
                )
        if self.attitude is not None and self.reference_frame != "inertial":
            raise ValidationError(
                "--attitude rotates an inertial reference: add --reference-frame inertial"
            )
        if self.reference_fit:
            self._check_reference_fit()
        elif self.reference_frame != "srf" or self.attitude is not None:
            raise ValidationError(
                "--reference-frame inertial / --attitude are used by the reference fit: "
                "add --bias-basis or --scale fit"
            )
        elif self.scale is not None and str(self.scale).lower() != "tn02":
            from accal.calibration import parse_scale

            parse_scale(self.scale, "")  # a numeric --scale is checked once, up front
        if self.degraded_days is not None:
            from accal.degraded import load_periods

            load_periods(self.degraded_days)  # a malformed table: a usage error, up front

    def _check_reference_fit(self) -> None:
        """Usage errors of ``--bias-basis`` / ``--scale fit|fit-matrix``, up front."""
        from accal.estimators.refbasis import parse_bias_basis

        what = f"--bias-basis {self.bias_basis}" if self.bias_basis else f"--scale {self.scale}"
        if self.reference is None:
            raise ValidationError(f"{what} fits against a reference: give --reference REF")
        if self.close_loop:
            raise ValidationError(f"--close-loop is not available with {what} yet")
        if self.pool_days:
            raise ValidationError(f"--pool-days applies to the wavelet/lsq fits, not to {what}")
        if self.bias_basis is not None:
            parse_bias_basis(self.bias_basis, 0.0, 1.0)
        if self.scale not in ("fit", "fit-matrix") and self.scale is not None:
            from accal.calibration import parse_scale

            if str(self.scale).lower() != "tn02":
                parse_scale(self.scale, "")
        m = self.thruster_margins
        if m is not None and not (len(m) == 2 and all(np.isfinite(v) and v >= 0 for v in m)):
            raise ValidationError(f"thruster margins must be two seconds >= 0, got {m!r}")


@dataclass(frozen=True)
class FileOutcome(Outcome):
    """What happened to one input (:class:`accal.batch.Outcome` plus grace-bias results).

    Attributes
    ----------
    rows : list of dict
        Rows for ``bias_drift`` (one per axis and method).
    n_samples : int
        Samples read.
    skipped : bool
        True when the manifest says the outputs are current (nothing was done).
    n_bytes : int
        Size of the input [bytes].
    closure : dict
        ``{axis: closure summary}`` of a ``--close-loop`` run (see ``closure.json``).
    warnings : tuple of str
        What the reader and the pipeline found worth telling (duplicated or
        out-of-order records, gaps, header/record/file-name disagreements, ...).
    peak_rss : float
        Peak resident memory of the process that ran the input, when it finished
        [MB] (0 where unknown).
    signature : dict or None
        Size and mtime of the input before it was read (see
        :meth:`accal.batch.Manifest.record`).
    kept_earlier : bool
        A failed input whose calibrated file from an earlier run is in the directory:
        those outputs (calibrated file, report, table rows) are kept, not removed.
    """

    rows: list[dict[str, Any]] = field(default_factory=list)
    n_samples: int = 0
    skipped: bool = False
    n_bytes: int = 0
    closure: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    peak_rss: float = 0.0
    signature: dict[str, Any] | None = None
    kept_earlier: bool = False


@dataclass(frozen=True)
class RunSummary:
    """Result of a batch run.

    ``outcomes`` are in input order; inputs not run (``--fail-fast``) are absent.
    """

    outcomes: list[FileOutcome]
    table_path: Path | None
    seconds: float
    n_inputs: int = 0
    log_path: Path | None = None
    workers: int = 1

    @property
    def n_ok(self) -> int:
        """Inputs processed now."""
        return sum(o.ok and not o.skipped for o in self.outcomes)

    @property
    def n_skipped(self) -> int:
        """Inputs whose outputs were current."""
        return sum(o.skipped for o in self.outcomes)

    @property
    def n_failed(self) -> int:
        """Inputs that failed."""
        return sum(not o.ok for o in self.outcomes)

    @property
    def n_not_run(self) -> int:
        """Inputs never started (after a failure with ``fail_fast``)."""
        return self.n_inputs - len(self.outcomes)

    @property
    def n_samples(self) -> int:
        """Samples read."""
        return sum(o.n_samples for o in self.outcomes)

    @property
    def n_bytes(self) -> int:
        """Bytes read (inputs processed now)."""
        return sum(o.n_bytes for o in self.outcomes if not o.skipped)

    @property
    def peak_rss(self) -> float:
        """Largest peak resident memory of a process that ran inputs [MB]."""
        return max((o.peak_rss for o in self.outcomes), default=0.0)

    def line(self, command: str = "accal grace-bias") -> str:
        """The one-line end-of-run summary."""
        done = self.n_ok + self.n_failed
        rate = (
            f"{self.n_bytes / 1e6 / self.seconds:.1f} MB/s, {done / self.seconds:.2f} files/s"
            if self.seconds > 0
            else "-"
        )
        rss = f", peak RSS {self.peak_rss:.0f} MB per worker" if self.peak_rss > 0 else ""
        return (
            f"{command}: {self.n_ok} ok, {self.n_skipped} skipped (current), {self.n_failed} "
            f"failed, {self.n_not_run} not run; {self.n_samples:,} samples, "
            f"{self.n_bytes / 1e6:.1f} MB in {self.seconds:.2f} s ({rate}, {self.workers} "
            f"worker{'s' if self.workers != 1 else ''}{rss}); table: "
            f"{self.table_path or '(none written)'}"
        )


#: What a failed input's earlier outputs are (said in the log and on stderr).
KEPT_EARLIER = (
    "the outputs of an earlier run for it are kept (calibrated file, report, table rows); "
    "they are replaced once it is processed again"
)


def output_stem(path: Path) -> str:
    """Input name without compression and format suffixes (``x.asc.gz`` → ``x``)."""
    name = path.name
    for suffix in (".gz", ".bz2", ".xz"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    stem = Path(name).stem
    return stem or name


def read_input(path: Path, opts: GraceBiasOptions) -> AccSeries:
    """Read one input with the registry (format sniffed unless forced)."""
    from accal.io import FORMATS, detect_format, read

    kwargs: dict[str, Any] = {}
    fmt = opts.input_format or detect_format(path)  # detect_format also checks the path
    if opts.columns and fmt == "table":  # --column maps table columns; L1B files have fixed ones
        kwargs["columns"] = dict(opts.columns)
    if opts.input_format is None:  # sniffed and checked above: call the reader directly
        series = FORMATS[fmt][1](path, **kwargs)
    else:
        series = read(path, format=fmt, **kwargs)
    if opts.columns and fmt != "table":  # QA (issue 23): silently ignored
        cols = ", ".join(f"{a}={c}" for a, c in sorted(opts.columns.items()))
        series = _with_warnings(
            series, f"--column {cols} is for table inputs; this {fmt} file's columns are fixed"
        )
    return series


#: Longest spacing of two reference samples that :func:`subtract_reference` interpolates
#: across, in nominal reference steps: one missing sample is bridged, a longer hole is not.
REFERENCE_MAX_BRIDGE = 2.5


def subtract_reference(series: AccSeries, reference: AccSeries, ref_path: Path) -> AccSeries:
    """Return ``series`` minus ``reference`` interpolated onto its epochs.

    Samples that fall in a hole of the reference (two reference samples more than
    :data:`REFERENCE_MAX_BRIDGE` nominal steps apart) are not bridged: they are
    marked invalid (left out of the fit) and a warning in the returned series'
    report says how many.  A reference sampled more sparsely than that relative to
    the data (or so holed that its median step is a hole) is interpolated, with a
    warning that gives both steps.  QA: 96 missing samples of a 1 Hz reference were bridged
    by a straight line and moved the bias by 8.7e-10 m/s² (2.5σ), silently.

    Raises
    ------
    ValidationError
        If the reference does not cover the series' time span or lacks an axis.
    """
    t = series.time
    tr = reference.time
    if tr.size < 2 or tr[0] > t[0] or tr[-1] < t[-1]:
        raise ValidationError(
            f"{ref_path}: reference covers [{tr[0] if tr.size else 'nan'}, "
            f"{tr[-1] if tr.size else 'nan'}] s, the data [{t[0]}, {t[-1]}] s"
        )
    unit = reference.units.get("acc")
    factor = acceleration_factor(unit)
    if factor is None:
        raise ValidationError(
            f"{ref_path}: reference unit {unit!r} is not an acceleration unit accal knows "
            f"({', '.join(sorted({k for k in ACC_UNIT_FACTORS if k.isascii()}))})"
        )
    cols = []
    for ax in series.axes:
        if ax not in reference.axes:
            raise ValidationError(f"{ref_path}: reference has no axis {ax!r}")
        cols.append(series.axis(ax) - factor * np.interp(t, tr, reference.axis(ax)))
    valid = series.valid & (np.interp(t, tr, reference.valid.astype(float)) > 0.999)
    step = float(np.median(np.diff(tr)))
    j = np.clip(np.searchsorted(tr, t, side="right"), 1, tr.size - 1)
    lo, hi = tr[j - 1], tr[j]
    hole = (hi - lo > REFERENCE_MAX_BRIDGE * step) & (t != lo) & (t != hi)
    warnings = []
    if factor != 1.0:
        warnings.append(f"--reference {ref_path.name} is in {unit}: converted to m/s^2")
    step_data = float(np.median(np.diff(t))) if t.size > 1 else step
    if step > REFERENCE_MAX_BRIDGE * step_data:
        # too few reference samples to tell a hole from its sampling: say how it is used
        warnings.append(
            f"--reference {ref_path.name} is sampled every {step:g} s (median), the data "
            f"every {step_data:g} s: it is interpolated linearly between its samples"
        )
    n_hole = int(np.count_nonzero(hole & valid))
    if n_hole:
        valid &= ~hole
        warnings.append(
            f"--reference {ref_path.name} has holes longer than "
            f"{REFERENCE_MAX_BRIDGE * step:g} s: {n_hole} sample(s) of the data "
            f"({n_hole / t.size:.1%}) fall in them and are left out of the fit"
        )
    out = series.replace(acc=np.column_stack(cols), valid=valid).with_history(
        f"accal {__version__}: subtract_reference({ref_path.name})"
    )
    return _with_warnings(out, *warnings)


def estimate(
    series: AccSeries,
    opts: GraceBiasOptions,
    exclude: dict[str, np.ndarray] | None = None,
) -> dict[tuple[str, str], Any]:
    """Fit every (axis, method) of ``series``; returns ``{(axis, method): TrendFit}``.

    ``exclude``: per axis, samples left out of that axis' fit only (where a coupling
    removed from it is unknown: ``--aux`` does not cover them).
    """
    from accal.estimators.trend import fit_trends

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
        from accal.errors import ValidationError

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
    from accal.degraded import classify_day, load_periods
    from accal.timescale import gps_to_date

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
                **_row_source(path, series, opts, date or gps_to_date(fit.t0), ax),
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


def _row_source(
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


def calibrated_frame(series: AccSeries, use: np.ndarray) -> dict[str, np.ndarray]:
    """The calibrated series as columns (``gps_time``, ``lin_accl_*``, ``valid``, ``qualflg``)."""
    data: dict[str, Any] = {"gps_time": series.time}
    for ax in series.axes:
        data[f"lin_accl_{ax}"] = series.axis(ax)
    data["valid"] = use
    data["qualflg"] = series.quality
    return data


def _read_with_reference(
    path: Path, opts: GraceBiasOptions, reference: AccSeries | None = None
) -> tuple[AccSeries, AccSeries, AccSeries | None]:
    """Read one input: (series, series to fit, ``series − reference`` or None).

    ``reference``: the reference already read (an arc reads it once for all inputs).
    """
    series = read_input(path, opts)
    if len(series) == 0:
        raise ValidationError("no data records")
    series, wild = flag_wild_samples(series)
    series = _with_warnings(series, *name_mismatch(path, series), *wild)
    if opts.reference is None:
        return series, series, None
    if reference is None:
        reference = read_input(opts.reference, GraceBiasOptions(columns=opts.columns))
    minus_ref = subtract_reference(series, reference, opts.reference)
    return series.replace(report=minus_ref.report), minus_ref, minus_ref


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
    from accal.calibration import parse_scale

    scale = parse_scale(opts.scale, series.satellite)
    use = np.ones(len(series), bool) if opts.keep_flagged else fit_series.valid
    closure: dict[str, Any] = {}
    plots: list[Path] = []
    close_loop = opts.close_loop
    if close_loop:
        from accal.closure.select import MIN_SAMPLES

        n_use = int(np.count_nonzero(use))
        if n_use < MIN_SAMPLES:  # the declared fit still stands; say why there is no closure
            close_loop = False
            series = _with_warnings(
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
        series = _with_warnings(series, *notes)
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
        series = _with_warnings(
            series, f"instrument off on this day ({'; '.join(off)}): fitted, flagged 'off'"
        )
    cal = calibrate(
        series if not close_loop else with_effects_removed(series, closure),
        fits,
        opts.methods[0],
        scale,
    )
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


def process_file(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    """Run the whole chain on one input and write its calibrated series and report.

    Raises
    ------
    AccalError
        On bad input; nothing is written for this input then.
    """
    from accal.io.writers import write_table

    series, fit_series, ref_series = _read_with_reference(path, opts)
    stem = output_stem(path)
    if opts.reference_fit:
        # imported here: the reference fit's modules import scipy (~0.3 s of start-up)
        from accal.pipeline_arcs import reference_outputs
        from accal.pipeline_reference import fit_day

        day = fit_day(path, series, ref_series, opts)
        return reference_outputs(path, out_dir, opts, series, ref_series, day)
    fitted = fit_input(path, series, fit_series, ref_series, opts, out_dir / stem)
    series, cal, use, rows = fitted.series, fitted.calibrated, fitted.use, fitted.rows
    closure, extra_outputs = fitted.closure, list(fitted.outputs)
    meta = {
        "source": path.name,
        "satellite": series.satellite,
        "frame": series.frame,
        "method": opts.methods[0],
        "order": opts.order,
        "history": list(cal.history),
        "input_meta": series.meta,
    }
    cal_path = write_table(
        calibrated_frame(cal, use),
        out_dir / f"{stem}.calibrated.{opts.fmt}",
        fmt=opts.fmt,
        units=CALIBRATED_UNITS,
        meta=meta,
        sync=False,  # made durable with the batch commit (sync_files)
        required=True,
    )
    report = {
        "source": str(path),
        "accal_version": __version__,
        "satellite": series.satellite,
        "read_report": series.report.as_dict(),
        "fits": rows,
        "history": list(cal.history),
    }
    if closure:
        report["closure"] = {ax: c["summary"] for ax, c in closure.items()}
    rep_path = out_dir / f"{stem}.report.json"
    _write_json(rep_path, report, sync=False)
    if opts.pool_days:
        extra_outputs.append(
            _save_spectra(out_dir / stem, fitted.fit_series, opts, fitted.exclude, fitted.fits)
        )
    return FileOutcome(
        path,
        True,
        rows=rows,
        n_samples=len(series),
        outputs=(cal_path, rep_path, *extra_outputs),
        n_bytes=_size(path),
        closure={ax: c["summary"] for ax, c in closure.items()},
        warnings=tuple(report["read_report"]["warnings"]),
    )


def _save_spectra(
    stem_path: Path,
    fit_series: AccSeries,
    opts: GraceBiasOptions,
    exclude: dict[str, np.ndarray],
    fits: dict[tuple[str, str], Any],
) -> Path:
    """Write ``<stem>.noise.npz``: the residual spectra of ``fits`` (``--pool-days``)."""
    from accal.pooling import day_spectra, spectra_path, write_spectra

    base = np.ones(len(fit_series), bool) if opts.keep_flagged else fit_series.valid
    base = base & np.isfinite(fit_series.time)
    masks = {}
    for k, ax in enumerate(fit_series.axes):
        m = base & np.isfinite(fit_series.acc[:, k])
        masks[ax] = m & ~exclude[ax] if ax in exclude else m
    spectra = day_spectra(fit_series.time, fit_series.acc, fit_series.axes, masks, fits)
    return write_spectra(spectra_path(stem_path.parent, stem_path.name), spectra, fits)


def _pool_table(out_dir: Path, opts: GraceBiasOptions, table_path: Path | None, rlog) -> None:
    """Give the ``bias_drift`` rows pooled σ (``--pool-days``, :mod:`accal.pooling`)."""
    if table_path is None:
        return
    from accal.pooling import pool_rows

    table = _read_bias_drift_arrow(table_path)
    rows = table.to_pylist()
    stems = {r["source"]: output_stem(Path(r["source"])) for r in rows}
    n = pool_rows(rows, out_dir, stems, opts.pool_days)
    merge_bias_drift(out_dir, rows, opts.fmt)
    rlog(f"pooled sigmas (--pool-days {opts.pool_days}): {n} of {len(rows)} rows")


def _with_warnings(series: AccSeries, *warnings: str) -> AccSeries:
    """``series`` with ``warnings`` appended to its read report (itself if none)."""
    if not warnings:
        return series
    rep = series.report
    return series.replace(report=dataclasses.replace(rep, warnings=(*rep.warnings, *warnings)))


def name_mismatch(path: Path, series: AccSeries) -> list[str]:
    """Disagreements between an L1B file name and its content (satellite, day).

    ``ACC1B_2005-01-01_A_02.asc`` names GRACE-A data of GPS day 2005-01-01; a
    file that holds another satellite or day was probably renamed or mixed up.
    Names that do not follow the L1B pattern are not checked.
    """
    from accal.batch import _L1B_NAME
    from accal.timescale import gps_to_date

    m = _L1B_NAME.search(path.name)
    if m is None or len(series) == 0:
        return []
    out = []
    letter = series.satellite[-1:] if series.satellite.startswith("GRACE") else ""
    if letter and m["sat"] != letter:
        out.append(f"file name says satellite {m['sat']}, the data are {series.satellite}")
    t = series.time
    days = {gps_to_date(float(t[0])), gps_to_date(float(t[len(t) // 2]))}
    if m["date"] not in days:
        out.append(f"file name says {m['date']}, the data are of {min(days)}")
    return out


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _write_json(path: Path, obj: Any, *, sync: bool = True) -> None:
    from accal.io.writers import _json_default, atomic_path

    with atomic_path(path, sync=sync) as tmp:
        tmp.write_text(json.dumps(_nan_to_none(obj), indent=2, default=_json_default) + "\n")


def _nan_to_none(obj: Any) -> Any:
    """Replace non-finite floats by None so the JSON is standard (no NaN literals)."""
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    return obj


_NP_TYPES = {"string": object, "int64": np.int64, "double": np.float64}
#: Value of a column a row does not have (a column added later, or another method's).
_MISSING = {"string": "", "int64": 0, "double": float("nan")}


def _bias_drift_schema():
    import pyarrow as pa

    strings = {
        "source",
        "satellite",
        "date",
        "axis",
        "frame",
        "method",
        "accal_version",
        "model",
        "day_status",
        "day_status_reason",
        "bias_includes",
        "sigma_model",
        "scale_mode",
        "bias_basis",
    }
    ints = {
        "order",
        "n",
        "n_total",
        "n_flagged",
        "n_duplicates",
        "n_out_of_order",
        "n_gaps",
        "sigma_days",
        "n_thruster",
    }
    return pa.schema(
        [
            (c, pa.string() if c in strings else pa.int64() if c in ints else pa.float64())
            for c in BIAS_DRIFT_UNITS
        ]
    )


def _read_bias_drift_arrow(path: Path):
    """Read a ``bias_drift`` table as a pyarrow Table in the current schema.

    Raises
    ------
    FormatError
        The table is damaged (truncated, ragged, a value of the wrong type).
    """
    import pyarrow as pa

    from accal.errors import FormatError
    from accal.io._common import one_line

    try:
        return _read_bias_drift_unchecked(path)
    except (pa.ArrowException, ValueError, KeyError, TypeError) as exc:
        raise FormatError(
            f"damaged bias_drift table ({one_line(str(exc), 120)}); move it away and re-run "
            "with --force to rebuild it",
            path,
        ) from None


#: Columns every ``bias_drift`` table has had since the first version: a table without
#: one is damaged (issue 23: a dropped ``drift`` column was read as NaN for every row,
#: which then stayed "current").  Columns added later may be absent (older tables).
CORE_COLUMNS = tuple(BIAS_DRIFT_UNITS)[: tuple(BIAS_DRIFT_UNITS).index("accal_version") + 1]


def _read_bias_drift_unchecked(path: Path):
    import pyarrow as pa

    schema = _bias_drift_schema()
    if path.suffix == ".csv":
        import pyarrow.csv as pacsv

        from accal.io._common import csv_read_options

        with open(path, "rb") as fh:
            skip = 0
            for line in fh:
                if not line.startswith(b"#"):
                    break
                skip += 1
        # (pyarrow's CSV reader starts an I/O thread even single-threaded: after a CSV
        # table is read, this process's workers start from a fork server)
        table = pacsv.read_csv(
            path,
            read_options=csv_read_options(skip_rows=skip),
            convert_options=pacsv.ConvertOptions(
                column_types={f.name: f.type for f in schema}, strings_can_be_null=False
            ),
        )
    else:
        import pyarrow.parquet as pq

        # no thread: the batch process must stay single-threaded for its workers to
        # be forked (accal.batch.start_method)
        table = pq.ParquetFile(path, pre_buffer=False).read(use_threads=False)
    missing = [c for c in CORE_COLUMNS if c not in table.column_names]
    if missing:
        raise ValueError(f"no {', '.join(missing)} column")
    keys = collections.Counter(
        zip(*(table.column(c).to_pylist() for c in ("source", "axis", "method")), strict=True)
    )
    dup = next((k for k, n in keys.items() if n > 1), None)
    if dup is not None:
        raise ValueError(f"row {'/'.join(map(str, dup))} more than once")
    cols = [
        table.column(f.name).cast(f.type)
        if f.name in table.column_names
        else (
            pa.array([""] * table.num_rows, pa.string())
            if pa.types.is_string(f.type)
            else pa.nulls(table.num_rows, f.type)
        )
        for f in schema
    ]
    return pa.Table.from_arrays(cols, schema=schema)


def merge_bias_drift(
    out_dir: Path, rows: list[dict[str, Any]], fmt: str, drop_sources: Iterable[str] = ()
) -> Path | None:
    """Merge ``rows`` into ``out_dir/bias_drift.<fmt>`` atomically.

    Rows of an existing table with the same (source, axis, method) are replaced,
    and every row of ``drop_sources`` is removed (inputs whose outputs a new input
    took over); all others are kept, so the table accumulates every input
    processed there.
    """
    import pyarrow as pa

    from accal.io.writers import arrow_column, write_table

    path = out_dir / f"bias_drift.{fmt}"
    schema = _bias_drift_schema()
    new = pa.Table.from_arrays(
        [
            arrow_column(
                np.array(
                    [r.get(f.name, _MISSING[str(f.type)]) for r in rows], _NP_TYPES[str(f.type)]
                )
            )
            for f in schema
        ],
        schema=schema,
    )
    drop = set(drop_sources)
    if path.exists():
        old = _read_bias_drift_arrow(path)
        if new.num_rows or drop:
            replaced = set(_keys(new))
            keep = np.array(
                [k not in replaced and k[0] not in drop for k in _keys(old)], dtype=bool
            )
            old = _take(old, np.flatnonzero(keep))
        new = pa.concat_tables([old, new])
    elif not rows:
        return None
    # sort by satellite, date, source, axis, method (numpy: pyarrow.compute imports pandas)
    cols = [np.array(new.column(c).to_pylist(), dtype=str) for c in reversed(_SORT_COLUMNS)]
    order = np.lexsort(cols) if new.num_rows else np.zeros(0, np.int64)
    new = _take(new, order)
    return write_table(
        new, path, fmt=fmt, units=BIAS_DRIFT_UNITS, meta={"accal_version": __version__}
    )


_SORT_COLUMNS = ("satellite", "date", "source", "axis", "method")


def _take(table: Any, index: np.ndarray) -> Any:
    """Rows ``index`` of an Arrow table, via numpy (``Table.take`` imports pyarrow.compute)."""
    import pyarrow as pa

    from accal.io._common import arrow_to_numpy
    from accal.io.writers import arrow_column

    cols = []
    for f, col in zip(table.schema, table.columns, strict=True):
        if pa.types.is_string(f.type):
            arr = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
            if arr.null_count == 0:
                cols.append(_take_strings(arr, index))
                continue
            vals = np.array(col.to_pylist(), dtype=object)[index]
        else:
            vals = arrow_to_numpy(col)[index]
        arr = arrow_column(vals)
        cols.append(arr if arr.type == f.type else arr.cast(f.type))
    return pa.Table.from_arrays(cols, schema=table.schema)


def _take_strings(arr: Any, index: np.ndarray) -> Any:
    """Rows ``index`` of a null-free Arrow string array, gathered on its buffers with numpy."""
    import pyarrow as pa

    index = np.asarray(index, dtype=np.int64)
    _, obuf, dbuf = arr.buffers()
    off = np.frombuffer(obuf, dtype=np.int32)[arr.offset : arr.offset + len(arr) + 1]
    data = np.frombuffer(dbuf, dtype=np.uint8) if dbuf is not None else np.zeros(0, np.uint8)
    starts = off[index].astype(np.int64)
    lens = off[index + 1].astype(np.int64) - starts
    new_off = np.zeros(index.size + 1, dtype=np.int64)
    np.cumsum(lens, out=new_off[1:])
    pos = np.repeat(starts - new_off[:-1], lens) + np.arange(new_off[-1])
    return pa.Array.from_buffers(
        pa.string(),
        index.size,
        [None, pa.py_buffer(new_off.astype(np.int32)), pa.py_buffer(data[pos].copy())],
    )


def _keys(table: Any) -> list[tuple[str, ...]]:
    return list(zip(*(table.column(k).to_pylist() for k in KEY_COLUMNS), strict=True))


def read_bias_drift(path: str | Path) -> Any:
    """Read a ``bias_drift`` table written by :func:`merge_bias_drift` as a pandas DataFrame."""
    return _read_bias_drift_arrow(Path(path)).to_pandas()


def options_key(opts: GraceBiasOptions) -> dict[str, Any]:
    """The options as a canonical JSON-able dict (what the manifest compares).

    Files named in the options (reference, aux, truth) enter with their size and
    mtime, so changing them makes the inputs out of date.  Without ``close_loop``
    its settings (``alpha``, ``orbit_period``, ``plots``) are left out: they change nothing.
    """
    from dataclasses import asdict

    from accal.batch import file_signature

    d = asdict(opts)
    # outputs differ only in whether the noise spectra are saved; the pooling itself
    # is redone over the whole table after every run
    if d.pop("pool_days"):
        d["noise_spectra"] = True
    if not opts.reference_fit:  # settings of the reference fit alone change nothing without it
        for k in (
            "bias_basis",
            "thrusters",
            "thruster_margins",
            "reference_frame",
            "attitude",
            "arc",
        ):
            d.pop(k)
    if not opts.close_loop:  # settings of the closure alone change nothing without it
        for k in ("alpha", "orbit_period", "plots"):
            d.pop(k)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            try:
                d[k] = {"path": os.path.realpath(v), **file_signature(v)}
            except OSError:
                d[k] = {"path": str(v)}
        elif isinstance(v, tuple):
            d[k] = list(v)
    return json.loads(json.dumps(d, sort_keys=True))


def process_one(
    path: Path, out_dir: Path, opts: GraceBiasOptions, run_token: str | None = None
) -> FileOutcome:
    """:func:`process_file` with every failure turned into a one-line :class:`FileOutcome`.

    Module-level and picklable: this is the task the worker processes and the
    dask workers run.  ``run_token``: the lock token of the submitting run; the
    task's outputs are renamed into ``out_dir`` only while that run holds the lock
    (:func:`accal.io.writers.run_guard`), so a task orphaned by a killed run cannot
    overwrite a later run's outputs.
    """
    with run_guard(Path(out_dir) / LOCK if run_token else None, run_token):
        return _process_one(Path(path), out_dir, opts)


def _process_one(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    # the peak memory of a failed input counts too: a hostile file that fails late is
    # exactly the one whose memory the summary must show (issue 23, finding 9)
    outcome = _try_one(path, out_dir, opts)
    return dataclasses.replace(outcome, peak_rss=_peak_rss_mb())


def _try_one(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    try:
        check_input(path)
        if path.is_dir():
            raise ValidationError("is a directory (use --recursive to process the files in it)")
        try:  # before the read: an input replaced while it is processed is redone next run
            before = file_signature(path)
        except OSError:
            before = None
        outcome = process_file(path, Path(out_dir), opts)
        return dataclasses.replace(outcome, signature=before)
    except AccalError as exc:
        return FileOutcome(path, False, failure_message(path, exc))
    except MemoryError:
        return FileOutcome(path, False, f"{path}: out of memory")
    except OSError as exc:  # writing the outputs (disk full, permissions, ...)
        return FileOutcome(path, False, write_error_message(path, exc))
    except Exception as exc:  # a bug, not bad input: still keep the batch going
        return _internal_error(path, exc)


def _peak_rss_mb() -> float:
    """Peak resident memory of this process [MB] (0 where ``resource`` is missing)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return 0.0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1 << 20) if sys.platform == "darwin" else peak / 1024.0


def _internal_error(path: Path, exc: BaseException) -> FileOutcome:
    return FileOutcome(Path(path), False, internal_error_message(path, exc))


def run(
    paths: Iterable[Path],
    out_dir: Path,
    opts: GraceBiasOptions,
    *,
    fail_fast: bool = False,
    progress: Callable[..., Iterable[Any]] | None = None,
    workers: int = 1,
    scheduler: str | Any | None = None,
    force: bool = False,
    checksum: bool = False,
    commit_seconds: float = 15.0,
    log: bool = True,
    unmatched: Sequence[tuple[Path, str]] = (),
) -> RunSummary:
    """Process every input into ``out_dir``; failures are recorded, not raised.

    Parameters
    ----------
    paths : iterable of Path
        Inputs (already expanded, see :func:`accal.batch.discover`).
    out_dir : Path
        Output directory (created).  It holds the cumulative ``bias_drift``
        table, a manifest, a log and a lock file.
    opts : GraceBiasOptions
        Options.
    fail_fast : bool
        Stop at the first failure (runs serially; the inputs already processed
        are still written).
    progress : callable, optional
        ``progress(iterable, total=N)`` wraps the completions (e.g. ``tqdm``).
    workers : int
        Local worker processes; results are identical to a serial run.
    scheduler : str or distributed.Client, optional
        A dask.distributed scheduler to run on instead of local workers.
    force : bool
        Redo inputs that the manifest says are current.
    checksum : bool
        Compare inputs by SHA-256 instead of size and mtime.
    commit_seconds : float
        How often the table and manifest are committed during a batch [s]
        (also at the end): a killed batch loses at most this much work.
    log : bool
        Append to ``out_dir/accal.log``.
    unmatched : sequence of (Path, str)
        Command-line inputs that expanded to no file, with their one-line message
        (``problems`` of :func:`accal.batch.discover`): counted and logged as failed.

    Returns
    -------
    RunSummary

    Raises
    ------
    accal.batch.LockedError
        If another run holds the output directory.
    """
    import functools

    from accal.batch import (
        Interrupted,
        Manifest,
        OutputLock,
        RunLog,
        execute,
        remove_stale_temporaries,
    )

    start = _time.perf_counter()
    out_dir = Path(out_dir)
    paths = [Path(p) for p in paths]
    if not out_dir.exists() and not any(os.path.lexists(p) for p in paths):
        # nothing to read: each input fails without a new output directory, lock and log
        # being created for it (issue 23: a failed run left them behind)
        gone = [FileOutcome(Path(p), False, msg) for p, msg in unmatched]
        gone += [
            FileOutcome(p, False, failure_message(p, ValidationError("no such file")))
            for p in paths
        ]
        return RunSummary(gone, None, _time.perf_counter() - start, n_inputs=len(gone))
    out_dir.mkdir(parents=True, exist_ok=True)
    if fail_fast:
        workers, scheduler = 1, None
    other = "csv" if opts.fmt == "parquet" else "parquet"
    if (out_dir / f"bias_drift.{other}").exists():
        raise AccalError(
            f"{out_dir} holds bias_drift.{other} of --format {other} runs; use --format "
            f"{other} there, or another --out for {opts.fmt}"
        )
    with OutputLock(out_dir, "accal grace-bias") as lock:
        remove_stale_temporaries(out_dir)
        rlog = RunLog(out_dir, enabled=log)
        try:
            key = options_key(opts)
            rlog(
                f"start accal {__version__} grace-bias: {len(paths)} inputs, workers={workers}, "
                f"scheduler={scheduler if isinstance(scheduler, str | None) else 'client'}, "
                f"force={force}, options={json.dumps(key, sort_keys=True)}"
            )
            manifest = Manifest.load(out_dir)
            results: dict[int, FileOutcome] = {}
            for k, (p, msg) in enumerate(unmatched):  # expanded to nothing: a failure
                results[k - len(unmatched)] = FileOutcome(Path(p), False, msg)
                rlog(f"FAILED {msg}")
            # an input is current only if its rows are still in the table: a deleted
            # or replaced table (QA: deleted, or overwritten by a filtered export) has
            # its inputs redone instead of skipped with no rows; a damaged one stops
            # the run here, every run, with its message (not only when work is due)
            table_path = _table_if_exists(out_dir, opts.fmt)
            tabled = collections.Counter(
                _read_bias_drift_arrow(table_path).column("source").to_pylist()
                if table_path is not None
                else ()
            )
            todo: list[int] = []
            owners: dict[str, Path] = {}
            for i, p in enumerate(paths):
                stem = output_stem(p)
                # a missing or empty input fails without writing: it claims no outputs
                claims = p.is_file() and _size(p) > 0
                if claims and owners.setdefault(stem, p) is not p:
                    results[i] = FileOutcome(
                        p,
                        False,
                        f"{p}: would write the same outputs ({stem}.*) as {owners[stem]} "
                        "in this run; rename one or give it another --out",
                    )
                    rlog(f"FAILED {results[i].message}")
                elif (
                    not force
                    and tabled[p.name] >= manifest.entries.get(manifest.key(p), {}).get("n_rows", 1)
                    and manifest.is_current(p, key, checksum=checksum)
                ):
                    results[i] = FileOutcome(p, True, skipped=True)
                    rlog(f"skip {p}: outputs current")
                else:
                    todo.append(i)
            task = functools.partial(process_one, out_dir=out_dir, opts=opts, run_token=lock.token)
            pending: list[FileOutcome] = []
            last = _time.monotonic()
            if opts.arc != "day":
                from accal.pipeline_arcs import arc_outcomes, redo_all

                if todo:  # an arc is fitted whole: any input to redo redoes all of them
                    todo = redo_all(todo, results, paths)
                gen = arc_outcomes([paths[i] for i in todo], out_dir, opts)
            else:
                gen = execute(
                    task,
                    [paths[i] for i in todo],
                    workers=workers,
                    scheduler=scheduler,
                    on_error=_internal_error,
                    on_note=rlog,
                )
            done = gen if progress is None else progress(gen, total=len(todo))
            interrupted = False
            try:
                for j, outcome in done:
                    if (
                        not outcome.ok
                        and (
                            out_dir / f"{output_stem(outcome.path)}.calibrated.{opts.fmt}"
                        ).exists()
                    ):
                        # processed by an earlier run: its outputs stay (nothing is lost),
                        # and the user is told they come from the file's earlier version
                        outcome = dataclasses.replace(outcome, kept_earlier=True)
                    results[todo[j]] = outcome
                    pending.append(outcome)
                    rlog(
                        f"ok {outcome.path}: {outcome.n_samples} samples"
                        if outcome.ok
                        else f"FAILED {outcome.message}"
                        + (f" ({KEPT_EARLIER})" if outcome.kept_earlier else "")
                    )
                    for w in outcome.warnings:
                        rlog(f"warning {outcome.path}: {w}")
                    if fail_fast and not outcome.ok:
                        break
                    if _time.monotonic() - last > commit_seconds:
                        table_path = (
                            _commit(out_dir, opts, manifest, key, pending, checksum) or table_path
                        )
                        pending, last = [], _time.monotonic()
            except KeyboardInterrupt:
                interrupted = True  # keep what finished: commit it below
                gen.close()  # stops the worker pool now if Ctrl-C came between results
            table_path = _commit(out_dir, opts, manifest, key, pending, checksum) or table_path
            if opts.pool_days and not interrupted:
                _pool_table(out_dir, opts, table_path, rlog)
            if manifest.changed:  # checksums added to entries recorded without one
                manifest.save()
            outcomes = [results[i] for i in sorted(results)]
            summary = RunSummary(
                outcomes,
                table_path,
                _time.perf_counter() - start,
                n_inputs=len(paths) + len(unmatched),
                log_path=rlog.path if log else None,
                workers=1
                if opts.arc != "day"
                else max(1, min(workers, len(todo)))
                if scheduler is None
                else workers,
            )
            rlog(summary.line())
            if interrupted:
                remove_stale_temporaries(out_dir)  # of the workers stopped mid-write
                rlog("interrupted (Ctrl-C): finished inputs kept; a re-run does the rest")
                raise Interrupted(summary)
            return summary
        finally:
            rlog.close()


def _table_if_exists(out_dir: Path, fmt: str) -> Path | None:
    p = out_dir / f"bias_drift.{fmt}"
    return p if p.exists() else None


def _commit(
    out_dir: Path,
    opts: GraceBiasOptions,
    manifest: Any,
    key: dict[str, Any],
    outcomes: list[FileOutcome],
    checksum: bool,
) -> Path | None:
    """Merge the rows of ``outcomes`` into the table, then record them in the manifest.

    The order matters for crash safety: an input is recorded only once its
    outputs are on disk (one ``syncfs`` for the whole commit, see
    :func:`accal.io.writers.sync_files`) and its rows are in the table; an input
    with rows but no record is redone (and its rows replaced, never duplicated).
    """
    from accal.io.writers import sync_files

    if not outcomes:
        return None
    sync_files(p for o in outcomes if o.ok for p in o.outputs)
    rows = [r for o in outcomes if o.ok for r in o.rows]
    # inputs of earlier runs whose outputs these took over (same name from another
    # directory, x.dat after x.asc): their records and rows go, they are no longer here
    displaced = {
        k: e
        for o in outcomes
        if o.ok
        for k, e in manifest.sharing_outputs(o.path, o.outputs).items()
    }
    new_sources = {o.path.name for o in outcomes if o.ok}
    drop = {e.get("source") for e in displaced.values()} - new_sources - {None}
    table = merge_bias_drift(out_dir, rows, opts.fmt, drop) if rows or drop else None
    for k in displaced:
        manifest.entries.pop(k, None)
    for o in outcomes:
        if o.ok:
            manifest.record(
                o.path,
                key,
                o.outputs,
                o.path.name,
                checksum=checksum,
                before=o.signature,
                n_rows=len(o.rows),
            )
        else:
            manifest.entries.pop(manifest.key(o.path), None)
    manifest.save()
    return table


def find_bias_drift(directory: Path) -> Path:
    """The ``bias_drift.<fmt>`` table of an output directory.

    Raises
    ------
    ValidationError
        If there is none (or two of different formats that disagree in age: the
        newer one is taken, which the message of a user's mix-up would not help).
    """
    directory = Path(directory)
    found = [directory / f"bias_drift.{f}" for f in ("parquet", "csv")]
    found = [p for p in found if p.exists()]
    if not found:
        raise ValidationError(f"{directory}: no bias_drift.parquet or bias_drift.csv here")
    return max(found, key=lambda p: p.stat().st_mtime_ns)
