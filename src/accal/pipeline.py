"""The ``grace-bias`` pipeline: read → validate → estimate → correct → write, per input.

This module only sequences the other layers (readers in :mod:`accal.io`,
estimators in :mod:`accal.estimators`, writers in :mod:`accal.io.writers`); it
computes nothing itself.  One input's failure never stops the others: each is
reported as a :class:`FileOutcome` with a one-line message.
"""

from __future__ import annotations

import json
import time as _time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.errors import AccalError, ValidationError, check_option
from accal.series import AccSeries

#: Columns of ``bias_drift.<fmt>`` and their units (written into the file metadata).
BIAS_DRIFT_UNITS = {
    "source": "input file name",
    "satellite": "satellite identifier",
    "date": "UTC date of t0 (YYYY-MM-DD)",
    "axis": "accelerometer axis (x|y|z), frame in 'frame'",
    "frame": "reference frame of the axes",
    "method": "estimator (wavelet|lsq)",
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
    """

    methods: tuple[str, ...] = ("wavelet",)
    order: int = 1
    fmt: str = "parquet"
    scale: str | None = None
    keep_flagged: bool = False
    reference: Path | None = None
    columns: dict[str, str] = field(default_factory=dict)
    input_format: str | None = None

    def __post_init__(self) -> None:
        from accal.estimators.trend import METHODS

        for m in self.methods:
            check_option("method", m, tuple(METHODS))
        check_option("order", self.order, (1, 2))
        check_option("format", self.fmt, ("parquet", "csv"))


@dataclass(frozen=True)
class FileOutcome:
    """What happened to one input.

    Attributes
    ----------
    path : Path
        The input.
    ok : bool
        True if processed and written.
    message : str
        One-line error (``FILE[:LINE]: what is wrong``) when not ok.
    rows : list of dict
        Rows for ``bias_drift`` (one per axis and method).
    n_samples : int
        Samples read.
    outputs : tuple of Path
        Files written for this input.
    """

    path: Path
    ok: bool
    message: str = ""
    rows: list[dict[str, Any]] = field(default_factory=list)
    n_samples: int = 0
    outputs: tuple[Path, ...] = ()


@dataclass(frozen=True)
class RunSummary:
    """Result of a batch run."""

    outcomes: list[FileOutcome]
    table_path: Path | None
    seconds: float

    @property
    def n_ok(self) -> int:
        """Inputs processed."""
        return sum(o.ok for o in self.outcomes)

    @property
    def n_failed(self) -> int:
        """Inputs that failed."""
        return sum(not o.ok for o in self.outcomes)


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
    from accal.io import read

    kwargs: dict[str, Any] = {}
    if opts.columns:
        kwargs["columns"] = dict(opts.columns)
    return read(path, format=opts.input_format, **kwargs)


def subtract_reference(series: AccSeries, reference: AccSeries, ref_path: Path) -> AccSeries:
    """Return ``series`` minus ``reference`` interpolated onto its epochs.

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
    cols = []
    for ax in series.axes:
        if ax not in reference.axes:
            raise ValidationError(f"{ref_path}: reference has no axis {ax!r}")
        cols.append(series.axis(ax) - np.interp(t, tr, reference.axis(ax)))
    valid = series.valid & (np.interp(t, tr, reference.valid.astype(float)) > 0.999)
    return series.replace(acc=np.column_stack(cols), valid=valid).with_history(
        f"accal {__version__}: subtract_reference({ref_path.name})"
    )


def estimate(series: AccSeries, opts: GraceBiasOptions) -> dict[tuple[str, str], Any]:
    """Fit every (axis, method) of ``series``; returns ``{(axis, method): TrendFit}``."""
    from accal.estimators.trend import fit_trend

    use = np.ones(len(series), bool) if opts.keep_flagged else series.valid
    fits = {}
    for ax in series.axes:
        for m in opts.methods:
            fits[(ax, m)] = fit_trend(
                series.time, series.axis(ax), method=m, order=opts.order, valid=use
            )
    return fits


def calibrate(
    series: AccSeries, fits: dict[tuple[str, str], Any], method: str, scale: Sequence[float] | None
) -> AccSeries:
    """Remove the trend of ``method`` from every axis and apply ``scale``.

    ``a_cal = scale · (a_raw − trend)`` (TN-02 convention, see :mod:`accal.calibration`).
    """
    cols = []
    for ax in series.axes:
        s = 1.0 if scale is None else float(scale["xyz".index(ax)])
        cols.append(s * (series.axis(ax) - fits[(ax, method)].evaluate(series.time)))
    return series.replace(acc=np.column_stack(cols)).with_history(
        f"accal {__version__}: calibrate(method={method!r}, scale={scale})"
    )


def table_rows(
    path: Path, series: AccSeries, fits: dict, scale: Sequence[float] | None, opts: GraceBiasOptions
) -> list[dict[str, Any]]:
    """Build the ``bias_drift`` rows of one input."""
    from accal.timescale import gps_to_date

    rep = series.report
    rows = []
    for (ax, m), fit in fits.items():
        sig = fit.sigma
        s = 1.0 if scale is None else float(scale["xyz".index(ax)])
        cov = fit.cov
        denom = np.sqrt(cov[0, 0] * cov[1, 1])
        rows.append(
            {
                "source": path.name,
                "satellite": series.satellite,
                "date": gps_to_date(fit.t0),
                "axis": ax,
                "frame": series.frame,
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
                "n_total": len(series),
                "n_flagged": 0 if opts.keep_flagged else int((~series.valid).sum()),
                "n_duplicates": rep.n_duplicates,
                "n_out_of_order": rep.n_out_of_order,
                "n_gaps": rep.n_gaps,
                "gap_seconds": rep.gap_seconds,
                "accal_version": __version__,
            }
        )
    return rows


def calibrated_frame(series: AccSeries, use: np.ndarray) -> dict[str, np.ndarray]:
    """The calibrated series as columns (``gps_time``, ``lin_accl_*``, ``valid``, ``qualflg``)."""
    data: dict[str, Any] = {"gps_time": series.time}
    for ax in series.axes:
        data[f"lin_accl_{ax}"] = series.axis(ax)
    data["valid"] = use
    data["qualflg"] = series.quality
    return data


def process_file(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    """Run the whole chain on one input and write its calibrated series and report.

    Raises
    ------
    AccalError
        On bad input; nothing is written for this input then.
    """
    from accal.calibration import parse_scale
    from accal.io.writers import write_table

    series = read_input(path, opts)
    if len(series) == 0:
        raise ValidationError("no data records")
    fit_series = series
    if opts.reference is not None:
        ref = read_input(opts.reference, GraceBiasOptions(columns=opts.columns))
        fit_series = subtract_reference(series, ref, opts.reference)
    scale = parse_scale(opts.scale, series.satellite)
    fits = estimate(fit_series, opts)
    rows = table_rows(path, series, fits, scale, opts)
    cal = calibrate(series, fits, opts.methods[0], scale)
    use = np.ones(len(series), bool) if opts.keep_flagged else fit_series.valid
    stem = output_stem(path)
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
    )
    report = {
        "source": str(path),
        "accal_version": __version__,
        "satellite": series.satellite,
        "read_report": series.report.as_dict(),
        "fits": rows,
        "history": list(cal.history),
    }
    rep_path = out_dir / f"{stem}.report.json"
    _write_json(rep_path, report)
    return FileOutcome(path, True, rows=rows, n_samples=len(series), outputs=(cal_path, rep_path))


def _write_json(path: Path, obj: Any) -> None:
    from accal.io.writers import _json_default, atomic_path

    with atomic_path(path) as tmp:
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


def _bias_drift_schema():
    import pyarrow as pa

    strings = {"source", "satellite", "date", "axis", "frame", "method", "accal_version"}
    ints = {"order", "n", "n_total", "n_flagged", "n_duplicates", "n_out_of_order", "n_gaps"}
    return pa.schema(
        [
            (c, pa.string() if c in strings else pa.int64() if c in ints else pa.float64())
            for c in BIAS_DRIFT_UNITS
        ]
    )


def _read_bias_drift_arrow(path: Path):
    """Read a ``bias_drift`` table as a pyarrow Table in the current schema."""
    import pyarrow as pa

    schema = _bias_drift_schema()
    if path.suffix == ".csv":
        import pyarrow.csv as pacsv

        with open(path, "rb") as fh:
            skip = 0
            for line in fh:
                if not line.startswith(b"#"):
                    break
                skip += 1
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(skip_rows=skip),
            convert_options=pacsv.ConvertOptions(
                column_types={f.name: f.type for f in schema}, strings_can_be_null=False
            ),
        )
    else:
        import pyarrow.parquet as pq

        table = pq.ParquetFile(path).read()
    cols = [
        table.column(f.name).cast(f.type)
        if f.name in table.column_names
        else pa.nulls(table.num_rows, f.type)
        for f in schema
    ]
    return pa.Table.from_arrays(cols, schema=schema)


def merge_bias_drift(out_dir: Path, rows: list[dict[str, Any]], fmt: str) -> Path | None:
    """Merge ``rows`` into ``out_dir/bias_drift.<fmt>`` atomically.

    Rows of an existing table with the same (source, axis, method) are replaced;
    all others are kept, so the table accumulates every input processed there.
    """
    import pyarrow as pa

    from accal.io.writers import arrow_column, write_table

    path = out_dir / f"bias_drift.{fmt}"
    schema = _bias_drift_schema()
    new = pa.Table.from_arrays(
        [
            arrow_column(np.array([r[f.name] for r in rows], dtype=_NP_TYPES[str(f.type)]))
            for f in schema
        ],
        schema=schema,
    )
    if path.exists():
        old = _read_bias_drift_arrow(path)
        if new.num_rows:
            replaced = set(_keys(new))
            keep = np.array([k not in replaced for k in _keys(old)], dtype=bool)
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
            vals = np.array(col.to_pylist(), dtype=object)[index]
        else:
            vals = arrow_to_numpy(col)[index]
        arr = arrow_column(vals)
        cols.append(arr if arr.type == f.type else arr.cast(f.type))
    return pa.Table.from_arrays(cols, schema=table.schema)


def _keys(table: Any) -> list[tuple[str, ...]]:
    return list(zip(*(table.column(k).to_pylist() for k in KEY_COLUMNS), strict=True))


def read_bias_drift(path: str | Path) -> Any:
    """Read a ``bias_drift`` table written by :func:`merge_bias_drift` as a pandas DataFrame."""
    return _read_bias_drift_arrow(Path(path)).to_pandas()


def run(
    paths: Iterable[Path],
    out_dir: Path,
    opts: GraceBiasOptions,
    *,
    fail_fast: bool = False,
    progress: Callable[[Iterable[Path]], Iterable[Path]] | None = None,
) -> RunSummary:
    """Process every input; failures are recorded, not raised.

    Parameters
    ----------
    paths : iterable of Path
        Inputs.
    out_dir : Path
        Output directory (created).
    opts : GraceBiasOptions
        Options.
    fail_fast : bool
        Stop at the first failure (the inputs already processed are still written).
    progress : callable, optional
        Wraps the iterable of paths (e.g. ``tqdm``).

    Returns
    -------
    RunSummary
    """
    start = _time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = list(paths)
    outcomes: list[FileOutcome] = []
    for path in progress(paths) if progress else paths:
        try:
            outcomes.append(process_file(Path(path), out_dir, opts))
        except AccalError as exc:
            outcomes.append(FileOutcome(Path(path), False, _one_line(path, exc)))
        except Exception as exc:  # a bug, not bad input: still keep the batch going
            outcomes.append(
                FileOutcome(
                    Path(path),
                    False,
                    f"{path}: internal error ({type(exc).__name__}: {exc}); "
                    "please report it with --debug output",
                )
            )
        if fail_fast and not outcomes[-1].ok:
            break
    rows = [r for o in outcomes if o.ok for r in o.rows]
    table = merge_bias_drift(out_dir, rows, opts.fmt)
    return RunSummary(outcomes, table, _time.perf_counter() - start)


def _one_line(path: Path | str, exc: AccalError) -> str:
    msg = str(exc).replace("\n", " ")
    file_path = getattr(exc, "path", None)
    if file_path is None:
        msg = f"{path}: {msg}"
    return msg
