"""Reader of accelerometer series from generic tables (Parquet, CSV, optionally gzipped CSV).

Column conventions understood by :func:`read_table_series`:

* time: ``gps_time`` or ``time`` (GPS seconds since 2000-01-01 12:00:00 GPS) or
  ``time_utc`` (ISO-8601 UTC, or a timestamp column in Parquet; converted with the
  leap-second table of :mod:`accal.timescale`);
* axes: ``lin_accl_x``, ``lin_accl_y``, ``lin_accl_z`` [m/s²], or any column mapped
  with ``columns={"x": "a_cal_x"}``;
* quality: ``valid`` (bool), ``flag_val`` (1 = invalid), ``quality`` or ``qualflg``
  (integer bitmask or 8-character 0/1 string, GRACE bits);
* every other numeric column goes to ``aux``.

Files written by :func:`accal.io.table_write.write_series` carry the series'
satellite, frame, units, history and meta (``accal.meta`` / the CSV's sidecar), so
reading them gives back the same :class:`~accal.series.AccSeries`.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError, check_option
from accal.io.common import (
    PARQUET_MAGIC,
    bits_from_strings,
    check_gps_time,
    implausible,
    implausible_message,
    peek,
    read_bytes,
    row_to_line,
    tidy,
)
from accal.io.grace.spec import DEFAULT_INVALID_BITS
from accal.io.table_columns import (
    _bad_flags,
    _bitmask,
    _cast_aux,
    _row_error,
    numeric_column,
    utc_column_to_gps,
)
from accal.io.table_meta import _aux_dtype, _series_meta
from accal.io.table_parse import column_list, read_csv_table, read_parquet_table
from accal.series import UNITS, AccSeries, ReadReport
from accal.timescale import EPOCH, gps_to_date

#: Time columns, in order of preference; the first two are GPS seconds, the last UTC.
TIME_COLUMNS = ("gps_time", "time", "time_utc")
#: Default source column of each axis.
AXIS_COLUMNS = {"x": "lin_accl_x", "y": "lin_accl_y", "z": "lin_accl_z"}
#: Quality columns: boolean validity, 0/1 invalid flag, bitmasks.
VALID_COLUMN, FLAG_COLUMN, QUALITY_COLUMNS = "valid", "flag_val", ("quality", "qualflg")
#: File-name patterns that name the satellite when the file does not.
SATELLITE_PATTERNS = (
    (re.compile(r"(?:^|[_/])SW_(?:OPER_\w*?_)?([ABC])_"), "Swarm-{}"),
    (re.compile(r"^AC[CT]1[AB]_\d{4}-\d{2}-\d{2}_([AB])_"), "GRACE-{}"),
    (re.compile(r"^AC[CT]1[AB]_\d{4}-\d{2}-\d{2}_([CD])_"), "GRACE-FO-{}"),
)


def sniff_table(path: str | Path) -> bool:
    """Return True if ``path`` looks like a Parquet or CSV table (never raises)."""
    try:
        name = Path(path).name.lower()
    except Exception:
        return False
    head = peek(path, 4096)
    if not head:
        return False
    if head.startswith(PARQUET_MAGIC):
        return True
    if not (name.endswith((".csv", ".csv.gz", ".txt.gz", ".txt")) or b"," in head):
        return False
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return bool(lines) and "," in lines[0]


def _guess_satellite(path: Path) -> str:
    for pattern, fmt in SATELLITE_PATTERNS:
        m = pattern.search(path.name)
        if m:
            return fmt.format(m.group(1))
    return ""


def read_table_series(path: str | Path, *, columns: dict[str, str] | None = None) -> AccSeries:
    """Read an accelerometer series from a Parquet or CSV (optionally gzipped) table.

    Parameters
    ----------
    path : str or Path
        The file.  Parquet is recognised by its magic bytes, gzip likewise;
        anything else is read as CSV (comment lines starting with ``#`` at the top
        are skipped; ``# units:`` and ``# meta:`` lines are read as JSON, as is the
        ``<file>-metadata.json`` sidecar accal writes).
    columns : dict of str to str, optional
        Map an axis (``"x"``, ``"y"``, ``"z"``) to a source column, e.g.
        ``{"x": "a_cal_x"}``; unmapped axes use ``lin_accl_<axis>`` if present.
        ``"time"`` names the time column (GPS seconds, or UTC timestamps or strings),
        e.g. ``{"time": "t"}``; else the first of :data:`TIME_COLUMNS`.

    Returns
    -------
    AccSeries
        ``time`` [s, GPS], ``acc`` [m/s²] for the axes found, ``valid`` and
        ``quality`` from the quality columns, other numeric columns in ``aux``
        (units from the file metadata, else ``"unknown"``).

    Raises
    ------
    FormatError
        Unreadable, corrupt or empty file, duplicated column names, no time or
        axis column, non-numeric values, missing or non-finite times, times
        outside 1980-01-06 ... 2100-01-01, quality/flag values that are not
        integers 0 ... 2³²−1, file metadata of the wrong type (units that are not
        strings, ``accal_series`` fields, ``aux_dtypes`` that are not numeric
        dtypes or would change a value).  The message gives the CSV line, or the
        Parquet row, of the first bad value.
    ValidationError
        A ``columns`` key that is not an axis or ``"time"``.
    """
    path = Path(path)
    columns = dict(columns or {})
    for key in columns:
        check_option("columns key", key, (*AXIS_COLUMNS, "time"))
    time_name = columns.pop("time", None)
    raw = read_bytes(path)
    if raw.startswith(PARQUET_MAGIC):
        table, units, fmeta, first_line = read_parquet_table(raw, path)
    else:
        table, units, fmeta, first_line = read_csv_table(raw, path)
    names = list(table.column_names)
    if table.num_rows == 0:
        raise FormatError("header but no data rows", path, first_line or None)
    series_meta = _series_meta(fmeta, path)
    aux_dtypes = {
        k: _aux_dtype(k, v, path) for k, v in (series_meta or {}).get("aux_dtypes", {}).items()
    }
    # 1-based CSV line of data row i (blank lines counted on the error path only);
    # Parquet rows have no line
    line_of = row_to_line(raw, first_line, text_line=1) if first_line else None

    tname, time = _time_column(table, names, path, line_of, time_name)
    axes, acc_cols, acc = _acc_columns(table, names, columns, path, line_of)

    warn: list[str] = [*_unit_warnings(acc, acc_cols), *_future_times(time, tname)]
    quality, valid, used = _quality_columns(table, names, path, first_line, line_of)
    # the other time columns are the same instants (an accal series carries time_utc
    # beside gps_time): not auxiliary channels, and not "non-numeric columns ignored"
    used |= {tname, *acc_cols, *(c for c in TIME_COLUMNS if c in names)}
    nonfinite = ~np.isfinite(acc).all(axis=1)
    if nonfinite.any():
        warn.append(
            f"{int(nonfinite.sum())} rows with missing or non-finite acceleration (invalid)"
        )
        valid = valid & ~nonfinite

    aux, skipped = _aux_columns(table, names, used, aux_dtypes, path, line_of)
    if skipped:
        warn.append(f"non-numeric columns ignored: {', '.join(skipped)}")

    t = tidy(
        time,
        {"acc": acc, "valid": valid, "quality": quality, **{"aux:" + k: v for k, v in aux.items()}},
    )
    valid = t.arrays["valid"]
    n_flagged = int(np.count_nonzero(~valid))
    if n_flagged:
        warn.append(f"{n_flagged} samples flagged invalid")
    report = ReadReport(n_flagged=n_flagged, warnings=tuple(warn + t.warnings), **t.report)

    satellite, frame, meta, history, col_units = _description(
        series_meta, fmeta, units, path, tname, dict(zip(axes, acc_cols, strict=True)), aux
    )
    return AccSeries(
        time=t.time,
        acc=t.arrays["acc"],
        axes=tuple(axes),
        valid=valid,
        quality=t.arrays["quality"],
        aux={k[4:]: v for k, v in t.arrays.items() if k.startswith("aux:")},
        frame=frame,
        satellite=satellite,
        units=col_units,
        meta=meta,
        report=report,
        history=history,
    )


def _time_column(
    table: Any,
    names: list[str],
    path: Path,
    line_of: Callable[[int], int] | None,
    name: str | None = None,
) -> tuple[str, np.ndarray]:
    """The time column's name and its values [s GPS]: finite, 1980-01-06 ... 2100-01-01.

    ``name`` (``columns={"time": NAME}``, the CLI's ``--column time=NAME``), else the
    first of :data:`TIME_COLUMNS` in ``names``; ``time_utc``, and a time column of
    timestamps or strings, are UTC, converted by
    :func:`accal.io.table_columns.utc_column_to_gps`; numbers are GPS seconds.

    Raises
    ------
    FormatError
        No time column, a value that is not a number or not a UTC time, a missing
        or non-finite time, a time outside the accepted range.
    """
    if name is not None and name not in names:
        raise FormatError(
            f"no column {name!r} for the time (--column time={name}); columns are "
            f"{column_list(names)}",
            path,
        )
    tname = name or next((c for c in TIME_COLUMNS if c in names), None)
    if tname is None:
        raise FormatError(
            f"no time column (one of {', '.join(TIME_COLUMNS)}, or name one with --column "
            f"time=NAME); columns are {column_list(names)}",
            path,
        )
    tcol = table.column(tname)
    if tname == "time_utc" or (tname != "gps_time" and _is_datetime_like(tcol)):
        # a "time" column of UTC timestamps or ISO strings is UTC, like time_utc (QA:
        # refused as "not numeric")
        time = utc_column_to_gps(tcol, tname, path, line_of)
    else:
        time = numeric_column(tcol, tname, path, line_of, locate=True).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise _row_error(f"{tname}: missing or non-finite time", path, int(bad[0]), line_of)
    check_gps_time(time, path, line_of, name=tname, unit="row")
    return tname, time


def _is_datetime_like(col: Any) -> bool:
    """Whether an Arrow column holds timestamps or strings (UTC times, not seconds)."""
    import pyarrow as pa

    t = col.type
    return bool(pa.types.is_timestamp(t) or pa.types.is_string(t) or pa.types.is_large_string(t))


def _acc_columns(
    table: Any,
    names: list[str],
    columns: dict[str, str],
    path: Path,
    line_of: Callable[[int], int] | None,
) -> tuple[list[str], list[str], np.ndarray]:
    """The axes found, their source columns and the (n, n_axes) accelerations [m/s²].

    ``columns`` maps an axis to its source column (else :data:`AXIS_COLUMNS`).
    Missing values (NaN) are gaps, left to the caller.

    Raises
    ------
    FormatError
        A mapped column that is missing, no axis column at all, a value that is
        not a number, an implausibly large acceleration.
    """
    axes, acc_cols = [], []
    for ax, default in AXIS_COLUMNS.items():
        src = columns.get(ax, default)
        if src in names:
            axes.append(ax)
            acc_cols.append(src)
        elif ax in columns:
            raise FormatError(
                f"column {src!r} (for axis {ax}) not found; columns are {column_list(names)}", path
            )
    if not axes:
        raise FormatError(
            "no acceleration column lin_accl_x/y/z (map one with --column x=NAME, "
            "or columns={'x': NAME} in Python); "
            f"columns are {column_list(names)}",
            path,
        )
    acc = np.column_stack(
        [numeric_column(table.column(c), c, path, line_of, locate=True) for c in acc_cols]
    ).astype(np.float64)
    for j, c in enumerate(acc_cols):  # missing values are gaps; absurd ones are damage
        big = implausible(acc[:, j])
        if big.size:
            i = int(big[0])
            raise _row_error(implausible_message(c, float(acc[i, j])), path, i, line_of)
    return axes, acc_cols, acc


#: Median |acceleration| [m/s²] above which a table's column is taken to be in another
#: unit: electrostatic accelerometers measure below ~1e-3 m/s² (GRACE ±5e-5 m/s²).
UNIT_WARN_ACCELERATION = 1e-2


def _future_times(time: np.ndarray, name: str) -> list[str]:
    """A warning when the times lie in the future (a Unix-seconds column read as GPS).

    QA (2026-11-30): a ``time`` column of Unix seconds was read as GPS seconds since
    2000-01-01 12:00 and the data were dated 2054-05-12, without a word.
    """
    finite = time[np.isfinite(time)]
    if finite.size == 0:
        return []
    # GPS-UTC (18 s) does not matter at a day's margin
    now = (np.datetime64("now", "ns") - EPOCH) / np.timedelta64(1, "s")
    if float(finite.min()) <= now + 86_400.0:
        return []
    return [
        f"column {name!r} dates the data from {gps_to_date(float(finite.min()))} on, in the "
        "future: it is read as GPS "
        "seconds since 2000-01-01 12:00:00; Unix seconds count from 1970 (give the "
        "instants as time_utc)"
    ]


def _unit_warnings(acc: np.ndarray, acc_cols: list[str]) -> list[str]:
    """A warning for each acceleration column whose median magnitude is beyond
    :data:`UNIT_WARN_ACCELERATION` (QA: a table in µm/s² without units was read as
    m/s², and its bias reported as −10.69 m/s² without a word)."""
    out = []
    for j, c in enumerate(acc_cols):
        x = np.abs(acc[:, j][np.isfinite(acc[:, j])])
        med = float(np.median(x)) if x.size else 0.0
        if med > UNIT_WARN_ACCELERATION:
            out.append(
                f"{c}: median |value| {med:.3g} m/s² is far beyond what an electrostatic "
                f"accelerometer measures (< 1e-3 m/s²): a table's accelerations are read in "
                "m/s²; is the column in another unit (µm/s², nm/s²)?"
            )
    return out


def _quality_columns(
    table: Any,
    names: list[str],
    path: Path,
    first_line: int,
    line_of: Callable[[int], int] | None,
) -> tuple[np.ndarray, np.ndarray, set[str]]:
    """``quality`` (uint32 bitmask), ``valid`` and the quality columns used.

    A bitmask column (:data:`QUALITY_COLUMNS`: integers or 8-character 0/1 strings)
    sets both, valid where no bit of :data:`~accal.io.grace.spec.DEFAULT_INVALID_BITS`
    is set; a ``flag_val`` column (0 = valid, missing = invalid) then decides
    ``valid``, and a ``valid`` column (1 = valid) last.  Without any, every sample is
    valid with quality 0.

    Raises
    ------
    FormatError
        Flags that are neither 0/1 strings nor integers 0 ... 2³²−1.
    """
    n = table.num_rows
    quality = np.zeros(n, dtype=np.uint32)
    valid = np.ones(n, dtype=bool)
    used: set[str] = set()
    qname = next((c for c in QUALITY_COLUMNS if c in names), None)
    if qname is not None:
        import pyarrow as pa

        qcol = table.column(qname)
        if pa.types.is_string(qcol.type) or pa.types.is_large_string(qcol.type):
            try:
                quality = bits_from_strings(qcol, path, first_line or 1)
            except FormatError:
                try:  # an integer bitmask read as text
                    q = numeric_column(qcol.cast(pa.int64()), qname, path)
                except (pa.ArrowException, FormatError):
                    raise _bad_flags(qcol, qname, path, line_of) from None
                quality = _bitmask(q, qname, path, line_of)
        else:
            q = numeric_column(qcol, qname, path, line_of, locate=True)
            quality = _bitmask(q, qname, path, line_of)
        valid = (quality & np.uint32(DEFAULT_INVALID_BITS)) == 0
        used.add(qname)
    if FLAG_COLUMN in names:
        f = numeric_column(table.column(FLAG_COLUMN), FLAG_COLUMN, path, line_of, locate=True)
        flag = _bitmask(f, FLAG_COLUMN, path, line_of, allow_nan=True)
        if qname is None:  # a missing flag counts as invalid
            quality = np.where(np.isnan(f), np.uint32(1), flag) if f.dtype.kind == "f" else flag
        valid = f == 0
        used.add(FLAG_COLUMN)
    if VALID_COLUMN in names:
        v = numeric_column(table.column(VALID_COLUMN), VALID_COLUMN, path, line_of, locate=True)
        valid = np.asarray(v == 1, dtype=bool)
        used.add(VALID_COLUMN)
    return quality, valid, used


def _aux_columns(
    table: Any,
    names: list[str],
    used: set[str],
    aux_dtypes: dict[str, np.dtype],
    path: Path,
    line_of: Callable[[int], int] | None,
) -> tuple[dict[str, np.ndarray], list[str]]:
    """The numeric columns not in ``used`` (cast to their recorded dtypes), and the others.

    Raises
    ------
    FormatError
        A value that does not fit its recorded dtype
        (:func:`accal.io.table_columns._cast_aux`).
    """
    aux: dict[str, np.ndarray] = {}
    skipped = []
    for name in names:
        if name in used:
            continue
        try:
            aux[name] = numeric_column(table.column(name), name, path)
        except FormatError:
            skipped.append(name)
    for k, dt in aux_dtypes.items():
        if k in aux:
            aux[k] = _cast_aux(aux[k], dt, k, path, line_of)
    return aux, skipped


def _description(
    series_meta: dict[str, Any] | None,
    fmeta: dict,
    units: dict[str, str],
    path: Path,
    tname: str,
    axis_columns: dict[str, str],
    aux: dict[str, np.ndarray],
) -> tuple[str, str, dict[str, Any], tuple[str, ...], dict[str, str]]:
    """Satellite, frame, meta, history and units of the series read from a table.

    From the ``accal_series`` description (``series_meta``, a file written by
    :func:`accal.io.table_write.write_series`) when there is one; else the units from
    the file metadata (``"unknown"`` for an aux column without one), satellite and
    frame from the file metadata or the file name, and ``meta["table"]`` describing
    the columns read.
    """
    acc_cols = list(axis_columns.values())
    col_units = {
        "time": units.get(tname, UNITS["time"]) if tname != "time_utc" else UNITS["time"],
        "acc": units.get(acc_cols[0], UNITS["acc"]),
    }
    col_units.update({k: units.get(k, "unknown") for k in aux})
    if series_meta is not None:  # types checked by _series_meta
        satellite = series_meta.get("satellite", "")
        frame = series_meta.get("frame", "SRF")
        meta = series_meta.get("meta", {})
        history = tuple(series_meta.get("history", ()))
        col_units = dict(series_meta.get("units") or col_units)
    else:
        # an accal output (e.g. grace-bias's calibrated file) names its satellite and
        # frame in its metadata; else the file name may
        named = fmeta.get("satellite") if isinstance(fmeta, dict) else None
        satellite = named if isinstance(named, str) and named else _guess_satellite(path)
        fr = fmeta.get("frame") if isinstance(fmeta, dict) else None
        frame = fr if isinstance(fr, str) and fr else "SRF"
        meta = {
            "table": {
                "time_column": tname,
                "axis_columns": axis_columns,
                "file_meta": fmeta,
            }
        }
        history = ()
    return satellite, frame, meta, history, col_units
