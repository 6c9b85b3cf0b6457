"""The ``bias_drift`` table of ``accal grace-bias``: columns, schema, reading, merging.

:data:`BIAS_DRIFT_UNITS` lists the columns and their units; :func:`merge_bias_drift`
merges a batch's rows into the cumulative table atomically; :func:`read_bias_drift`
and :func:`read_bias_drift_arrow` read it back (checked: a damaged table is a
:class:`~accal.errors.FormatError`); :func:`find_bias_drift` finds it in a directory.
"""

from __future__ import annotations

import collections
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.errors import FormatError, ValidationError
from accal.io.common import arrow_to_numpy, csv_read_options, one_line
from accal.io.writers import arrow_column, write_table
from accal.products.utc import utc_arrow, utc_unit

# pyarrow is imported in the functions that use it, as in accal.io.writers: its import
# (with pyarrow.csv/.parquet) costs ~0.1 s and starts jemalloc's thread (measured), which
# reading an input (accal.api.read) does not need

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
    "t0_utc": utc_unit("t0"),
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

KEY_COLUMNS = ["source", "axis", "method"]

#: Columns computed from another one when the table is read or written, never merged:
#: ``t0_utc`` is ``t0`` in UTC (a table of an older version, without it, gets it from
#: its ``t0`` at the next merge).
DERIVED_COLUMNS = {"t0_utc": "t0"}


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
            if c not in DERIVED_COLUMNS
        ]
    )


def _with_derived(table: Any, fmt: str) -> Any:
    """``table`` (stored columns) with each derived column after its source column.

    ``t0_utc``: ``timestamp[ns, tz=UTC]`` for Parquet (and in memory), ISO 8601 text
    for CSV (:func:`accal.products.utc.utc_arrow`).
    """
    import pyarrow as pa

    names, cols = list(table.column_names), list(table.columns)
    for derived, source in DERIVED_COLUMNS.items():
        at = names.index(source) + 1
        names.insert(at, derived)
        cols.insert(at, utc_arrow(arrow_to_numpy(table.column(source)), fmt))
    return pa.Table.from_arrays(cols, names=names)


def read_bias_drift_arrow(path: Path):
    """Read a ``bias_drift`` table as a pyarrow Table in the current schema.

    ``t0_utc`` is computed from ``t0`` (``timestamp[ns, tz=UTC]``), also for a
    table of an older version, which has no ``t0_utc``.

    Raises
    ------
    FormatError
        The table is damaged (truncated, ragged, a value of the wrong type).
    """
    return _with_derived(_read_bias_drift_stored(path), "parquet")


def _read_bias_drift_stored(path: Path):
    """The stored columns of a ``bias_drift`` table (without the derived ones), checked."""
    import pyarrow as pa

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
CORE_COLUMNS = tuple(
    c
    for c in tuple(BIAS_DRIFT_UNITS)[: tuple(BIAS_DRIFT_UNITS).index("accal_version") + 1]
    if c not in DERIVED_COLUMNS
)


def _read_bias_drift_unchecked(path: Path):
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
    processed there.  ``t0_utc`` is computed anew from ``t0`` for every row (a row
    of an older table, without it, gets it too; a row's own ``t0_utc`` is ignored).
    """
    import pyarrow as pa

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
        old = _read_bias_drift_stored(path)
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
    new = _with_derived(_take(new, order), fmt)
    return write_table(
        new, path, fmt=fmt, units=BIAS_DRIFT_UNITS, meta={"accal_version": __version__}
    )


_SORT_COLUMNS = ("satellite", "date", "source", "axis", "method")


def _take(table: Any, index: np.ndarray) -> Any:
    """Rows ``index`` of an Arrow table, via numpy (``Table.take`` imports pyarrow.compute)."""
    import pyarrow as pa

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
    return read_bias_drift_arrow(Path(path)).to_pandas()


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
