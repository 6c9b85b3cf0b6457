"""Reader and writer for generic tables (Parquet, CSV, optionally gzipped CSV).

Column conventions understood by :func:`read_table_series`:

* time: ``gps_time`` or ``time`` (GPS seconds since 2000-01-01 12:00:00 GPS) or
  ``time_utc`` (ISO-8601 UTC, or a timestamp column in Parquet; converted with the
  leap-second table of :mod:`accal.timescale`);
* axes: ``lin_accl_x``, ``lin_accl_y``, ``lin_accl_z`` [m/s²], or any column mapped
  with ``columns={"x": "a_cal_x"}``;
* quality: ``valid`` (bool), ``flag_val`` (1 = invalid), ``quality`` or ``qualflg``
  (integer bitmask or 8-character 0/1 string, GRACE bits);
* every other numeric column goes to ``aux``.

Files written by :func:`write_series` carry the series' satellite, frame, units,
history and meta (``accal.meta`` / ``# meta:``), so reading them gives back the same
:class:`~accal.series.AccSeries`.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError, ValidationError, check_option
from accal.io._common import (
    PARQUET_MAGIC,
    arrow_to_numpy,
    bits_from_strings,
    check_binary,
    peek,
    read_bytes,
    tidy,
)
from accal.io.grace_l1b import DEFAULT_INVALID_BITS
from accal.io.writers import write_table
from accal.series import UNITS, AccSeries, ReadReport
from accal.timescale import utc_to_gps

#: Time columns, in order of preference; the first two are GPS seconds, the last UTC.
TIME_COLUMNS = ("gps_time", "time", "time_utc")
#: Default source column of each axis.
AXIS_COLUMNS = {"x": "lin_accl_x", "y": "lin_accl_y", "z": "lin_accl_z"}
#: Quality columns: boolean validity, 0/1 invalid flag, bitmasks.
VALID_COLUMN, FLAG_COLUMN, QUALITY_COLUMNS = "valid", "flag_val", ("quality", "qualflg")
#: Key of the series description in the file metadata written by :func:`write_series`.
META_KEY = "accal_series"
#: File-name patterns that name the satellite when the file does not.
SATELLITE_PATTERNS = ((re.compile(r"(?:^|[_/])SW_(?:OPER_\w*?_)?([ABC])_"), "Swarm-{}"),)

_FMTS = ("parquet", "csv")


def one_line(text: str, limit: int = 200) -> str:
    """``text`` as one short line: control characters escaped, cut at ``limit``."""
    text = str(text)
    if not text.isprintable():
        text = repr(text)[1:-1]
    return text[:limit]


def column_list(names: Any, limit: int = 160) -> str:
    """Column names for a one-line message (non-printable names escaped, cut at ``limit``)."""
    names = list(names)
    out, size = [], 0
    for n in names:
        shown = one_line(n, 40)
        if out and size + len(shown) > limit:
            break
        out.append(shown)
        size += len(shown) + 2
    more = len(names) - len(out)
    return ", ".join(out) + (f", ... ({more} more)" if more > 0 else "") if names else "none"


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


def _json_object(raw: bytes | str, path: Path, line: int | None, what: str) -> dict:
    """Parse metadata JSON that must be an object; FormatError otherwise."""
    try:
        obj = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise FormatError(f"{what} is not valid JSON", path, line) from None
    if not isinstance(obj, dict):
        raise FormatError(f"{what} is not a JSON object", path, line)
    return obj


def _comment(line: bytes, path: Path, lineno: int, units: dict, meta: dict) -> None:
    """Parse one ``# key: value`` comment line into ``units``/``meta`` (in place)."""
    text = line.decode("utf-8", "replace").rstrip("\r\n")
    key, _, rest = text[1:].partition(":")
    key = key.strip()
    if key in ("units", "meta"):
        obj = _json_object(rest, path, lineno, f"comment '{key}:'")
        target = units if key == "units" else meta
        target.clear()
        target.update(obj)


def read_csv_table(raw: bytes, path: Path) -> tuple[Any, dict, dict, int]:
    """Parse a whole CSV table (comment header, then a header line and rows).

    Parameters
    ----------
    raw : bytes
        The decompressed file content.
    path : Path
        The file (for messages).

    Returns
    -------
    table : pyarrow.Table
        The columns, types inferred by pyarrow (``qualflg`` kept as strings).
    units, meta : dict
        From the ``# units: {...}`` and ``# meta: {...}`` comment lines.
    first_line : int
        1-based line number of the first data row.

    Raises
    ------
    FormatError
        Bad comment JSON, binary data, no rows, truncated last line, parse errors.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    units: dict[str, str] = {}
    meta: dict[str, Any] = {}
    pos, n_comment = 0, 0
    while raw.startswith(b"#", pos):
        nl = raw.find(b"\n", pos)
        nl = len(raw) if nl < 0 else nl
        _comment(raw[pos:nl], path, n_comment + 1, units, meta)
        pos, n_comment = nl + 1, n_comment + 1
    body = raw[pos:]
    check_binary(body[:65536], path, n_comment + 1)
    if not body.strip():
        raise FormatError("no table after the comment lines", path, n_comment + 1)
    if body.count(b"\n") <= 1 and not body.rstrip(b"\r\n").count(b"\n"):
        raise FormatError("header but no data rows", path, n_comment + 2)
    if not body.endswith(b"\n"):
        raise FormatError(
            "truncated last line (no newline at end of file)",
            path,
            n_comment + body.count(b"\n") + 1,
        )
    try:
        table = pacsv.read_csv(
            pa.py_buffer(body),
            parse_options=pacsv.ParseOptions(ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(
                timestamp_parsers=[pacsv.ISO8601],
                strings_can_be_null=False,
                # 8-character 0/1 flags must stay strings ("00100000" is not 100000).
                column_types={"qualflg": pa.string()},
            ),
        )
    except (pa.ArrowException, ValueError) as exc:
        msg = str(exc).splitlines()[0]
        line = None
        m = re.search(r"Row #(\d+)", msg)
        if m:
            line = n_comment + int(m.group(1)) + 1
        raise FormatError(f"CSV: {msg[:200]}", path, line) from None
    return table, units, meta, n_comment + 2


def read_parquet_table(raw: bytes, path: Path) -> tuple[Any, dict, dict, int]:
    """Parse a whole Parquet table held in memory.

    Parameters
    ----------
    raw : bytes
        The file content.
    path : Path
        The file (for messages).

    Returns
    -------
    table : pyarrow.Table
    units, meta : dict
        From the ``accal.units`` and ``accal.meta`` schema metadata.
    first_line : int
        Always 0 (Parquet has no lines).

    Raises
    ------
    FormatError
        Corrupt file or metadata.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(io.BytesIO(raw))
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise FormatError(
            f"corrupt Parquet file ({str(exc).splitlines()[0][:200]})", path
        ) from None
    md = table.schema.metadata or {}
    units = _json_object(md.get(b"accal.units", b"{}"), path, None, "accal metadata")
    meta = _json_object(md.get(b"accal.meta", b"{}"), path, None, "accal metadata")
    return table, units, meta, 0


def numeric_column(col: Any, name: str, path: Path) -> np.ndarray:
    """An integer, float or boolean Arrow column as numpy; nulls become NaN.

    Raises
    ------
    FormatError
        The column is not numeric (names the column).
    """
    import pyarrow as pa

    t = col.type
    if not (pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t)):
        raise FormatError(f"column {name!r} is not numeric (type {t})", path)
    arr = arrow_to_numpy(col)
    if col.null_count:
        arr = np.asarray(col.cast(pa.float64()).fill_null(np.nan).to_numpy(), float)
    return arr


def read_table_series(path: str | Path, *, columns: dict[str, str] | None = None) -> AccSeries:
    """Read an accelerometer series from a Parquet or CSV (optionally gzipped) table.

    Parameters
    ----------
    path : str or Path
        The file.  Parquet is recognised by its magic bytes, gzip likewise;
        anything else is read as CSV (comment lines starting with ``#`` at the top
        are skipped; ``# units:`` and ``# meta:`` lines are read as JSON).
    columns : dict of str to str, optional
        Map an axis (``"x"``, ``"y"``, ``"z"``) to a source column, e.g.
        ``{"x": "a_cal_x"}``; unmapped axes use ``lin_accl_<axis>`` if present.

    Returns
    -------
    AccSeries
        ``time`` [s, GPS], ``acc`` [m/s²] for the axes found, ``valid`` and
        ``quality`` from the quality columns, other numeric columns in ``aux``
        (units from the file metadata, else ``"unknown"``).

    Raises
    ------
    FormatError
        Unreadable, corrupt or empty file, no time or axis column, non-numeric
        values, bad times.
    """
    path = Path(path)
    columns = dict(columns or {})
    for key in columns:
        check_option("columns key", key, tuple(AXIS_COLUMNS))
    raw = read_bytes(path)
    if raw.startswith(PARQUET_MAGIC):
        table, units, fmeta, first_line = read_parquet_table(raw, path)
    else:
        table, units, fmeta, first_line = read_csv_table(raw, path)
    names = list(table.column_names)
    if table.num_rows == 0:
        raise FormatError("header but no data rows", path, first_line or None)
    series_meta = fmeta.get(META_KEY) if isinstance(fmeta.get(META_KEY), dict) else None

    tname = next((c for c in TIME_COLUMNS if c in names), None)
    if tname is None:
        raise FormatError(
            f"no time column (one of {', '.join(TIME_COLUMNS)}); columns are {column_list(names)}",
            path,
        )
    tcol = table.column(tname)
    if tname == "time_utc":
        import pyarrow as pa

        if tcol.null_count:
            raise FormatError("time_utc has empty values", path)
        vals = tcol.to_numpy() if pa.types.is_timestamp(tcol.type) else np.asarray(tcol.to_pylist())
        try:
            time = utc_to_gps(vals)
        except (ValueError, TypeError) as exc:
            raise FormatError(f"time_utc: {one_line(str(exc))}", path) from None
    else:
        time = numeric_column(tcol, tname, path).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise FormatError(
            f"{tname}: missing or non-finite time", path, (first_line + int(bad[0])) or None
        )

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
            "no acceleration column (lin_accl_x/y/z, or map one with columns={'x': name}); "
            f"columns are {column_list(names)}",
            path,
        )
    acc = np.column_stack([numeric_column(table.column(c), c, path) for c in acc_cols]).astype(
        np.float64
    )

    warn: list[str] = []
    n = table.num_rows
    quality = np.zeros(n, dtype=np.uint32)
    valid = np.ones(n, dtype=bool)
    used = {tname, *acc_cols}
    qname = next((c for c in QUALITY_COLUMNS if c in names), None)
    if qname is not None:
        import pyarrow as pa

        qcol = table.column(qname)
        if pa.types.is_string(qcol.type) or pa.types.is_large_string(qcol.type):
            try:
                quality = bits_from_strings(qcol, path, first_line or 1)
            except FormatError:
                try:  # an integer bitmask read as text
                    quality = numeric_column(qcol.cast(pa.int64()), qname, path).astype(np.uint32)
                except (pa.ArrowException, FormatError):
                    raise FormatError(
                        f"column {qname!r} is neither 8-character 0/1 flags nor integers", path
                    ) from None
        else:
            q = numeric_column(qcol, qname, path)
            if not np.all(np.isfinite(q)) or np.any(q < 0) or np.any(q != np.round(q)):
                raise FormatError(f"column {qname!r} must hold non-negative integers", path)
            quality = q.astype(np.uint32)
        valid = (quality & np.uint32(DEFAULT_INVALID_BITS)) == 0
        used.add(qname)
    if FLAG_COLUMN in names:
        f = numeric_column(table.column(FLAG_COLUMN), FLAG_COLUMN, path)
        if qname is None:
            quality = np.where(np.isfinite(f), f, 1).astype(np.uint32)
        valid = f == 0
        used.add(FLAG_COLUMN)
    if VALID_COLUMN in names:
        v = numeric_column(table.column(VALID_COLUMN), VALID_COLUMN, path)
        valid = np.asarray(v == 1, dtype=bool)
        used.add(VALID_COLUMN)
    nonfinite = ~np.isfinite(acc).all(axis=1)
    if nonfinite.any():
        warn.append(
            f"{int(nonfinite.sum())} rows with missing or non-finite acceleration (invalid)"
        )
        valid = valid & ~nonfinite

    aux: dict[str, np.ndarray] = {}
    skipped = []
    for name in names:
        if name in used:
            continue
        try:
            aux[name] = numeric_column(table.column(name), name, path)
        except FormatError:
            skipped.append(name)
    if series_meta is not None:
        for k, dt in (series_meta.get("aux_dtypes") or {}).items():
            if k in aux:
                aux[k] = aux[k].astype(dt)
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

    col_units = {
        "time": units.get(tname, UNITS["time"]) if tname != "time_utc" else UNITS["time"],
        "acc": units.get(acc_cols[0], UNITS["acc"]),
    }
    col_units.update({k: units.get(k, "unknown") for k in aux})
    if series_meta is not None:
        satellite = series_meta.get("satellite", "")
        frame = series_meta.get("frame", "SRF")
        meta = series_meta.get("meta", {})
        history = tuple(series_meta.get("history", ()))
        col_units = dict(series_meta.get("units") or col_units)
    else:
        satellite = _guess_satellite(path)
        frame = "SRF"
        meta = {
            "table": {
                "time_column": tname,
                "axis_columns": dict(zip(axes, acc_cols, strict=True)),
                "file_meta": fmeta,
            }
        }
        history = ()
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


def write_series(series: AccSeries, path: str | Path, fmt: str | None = None) -> Path:
    """Write ``series`` as a Parquet or CSV table that :func:`read_table_series` reads back.

    Parameters
    ----------
    series : AccSeries
        The series.
    path : str or Path
        Output file (written atomically by :func:`accal.io.writers.write_table`).
    fmt : {"parquet", "csv"}, optional
        Default from the suffix of ``path`` (``.csv`` -> CSV, else Parquet).

    Returns
    -------
    Path
        The written path.

    Notes
    -----
    Columns: ``gps_time``, ``lin_accl_<axis>``, ``valid``, ``quality``, then the aux
    channels.  Satellite, frame, units, history and meta go to the file metadata
    under ``accal_series``; the reader restores them, so the round trip gives an
    identical series (the ``report`` describes the new read).  CSV floats are
    written with 17 significant digits (exact).
    """
    import pandas as pd

    path = Path(path)
    if fmt is None:
        fmt = "csv" if path.suffix.lower() == ".csv" else "parquet"
    check_option("fmt", fmt, _FMTS)
    reserved = {"gps_time", "valid", "quality", *(AXIS_COLUMNS[a] for a in series.axes)}
    clash = sorted(reserved & set(series.aux))
    if clash:
        raise ValidationError(f"auxiliary channel names clash with table columns: {clash}")
    data: dict[str, Any] = {"gps_time": series.time}
    for i, ax in enumerate(series.axes):
        data[AXIS_COLUMNS[ax]] = series.acc[:, i]
    data["valid"] = series.valid
    data["quality"] = series.quality.astype(np.int64)
    data.update(series.aux)
    units = {"gps_time": series.units.get("time", UNITS["time"])}
    units.update({AXIS_COLUMNS[a]: series.units.get("acc", UNITS["acc"]) for a in series.axes})
    units.update({k: series.units.get(k, "unknown") for k in series.aux})
    meta = {
        META_KEY: {
            "satellite": series.satellite,
            "frame": series.frame,
            "units": dict(series.units),
            "history": list(series.history),
            "aux_dtypes": {k: np.asarray(v).dtype.str for k, v in series.aux.items()},
            "meta": series.meta,
        }
    }
    return write_table(pd.DataFrame(data), path, fmt=fmt, units=units, meta=meta)


# ---------------------------------------------------------------------------
# whole-file and streamed reading of any table (used by accal.io.rawlog)

#: Rows per chunk of :func:`open_table` by default (~3 days at 1 Hz).
STREAM_ROWS = 1 << 18


def read_table_arrow(path: str | Path) -> tuple[Any, dict, dict, int]:
    """Read a whole Parquet or CSV (optionally gzipped) table.

    Parameters
    ----------
    path : str or Path
        The file; Parquet is recognised by its magic bytes, anything else is CSV.

    Returns
    -------
    table, units, meta, first_line
        As :func:`read_csv_table` / :func:`read_parquet_table`.

    Raises
    ------
    FormatError
        Unreadable or corrupt file.
    """
    path = Path(path)
    raw = read_bytes(path)
    if raw.startswith(PARQUET_MAGIC):
        return read_parquet_table(raw, path)
    return read_csv_table(raw, path)


def _open_binary(path: Path) -> Any:
    """Open ``path`` for reading bytes, decompressing gzip (by magic); FormatError on failure."""
    import gzip

    if path.is_dir():
        raise FormatError("is a directory, not a file", path)
    try:
        fh = open(path, "rb")  # noqa: SIM115 (returned to the caller, who closes it)
    except FileNotFoundError:
        raise FormatError("no such file", path) from None
    except PermissionError:
        raise FormatError("permission denied (file not readable)", path) from None
    except OSError as exc:
        raise FormatError(f"cannot read file: {exc.strerror or exc}", path) from None
    if fh.read(2) == b"\x1f\x8b":
        fh.seek(0)
        return gzip.GzipFile(fileobj=fh, mode="rb")
    fh.seek(0)
    return fh


class TableStream:
    """A Parquet or CSV table read in chunks of at most ``rows`` rows.

    Iterating yields ``(first_row, table)`` pairs: the 0-based index of the
    chunk's first data row and a ``pyarrow.Table`` of the next rows.  Each
    iteration re-opens the file, so a stream can be read several times.  Memory
    is bounded by the chunk, not the file (except gzipped Parquet, which has to
    be decompressed in memory).

    CSV column types are inferred on the first chunk; integer and all-empty
    columns are read as float64 from then on, so that a later chunk holding a
    decimal point reads the same way.

    Attributes
    ----------
    path : Path
        The file.
    names : list of str
        Column names.
    units, meta : dict
        ``accal.units`` / ``accal.meta`` (Parquet) or ``# units:`` / ``# meta:`` (CSV).
    first_line : int
        1-based line of the first data row (CSV); 0 for Parquet.
    rows : int
        Rows per chunk.
    """

    def __init__(self, path: str | Path, *, rows: int = STREAM_ROWS) -> None:
        self.path = Path(path)
        self.rows = int(rows)
        if self.rows < 1:
            raise ValidationError(f"rows per chunk must be >= 1, got {rows}")
        with _open_binary(self.path) as fh:
            head = fh.read(4)
            gz = not isinstance(fh, io.BufferedReader)
        if not head.strip():
            raise FormatError("empty file", self.path)
        self.units: dict[str, str] = {}
        self.meta: dict[str, Any] = {}
        if head == PARQUET_MAGIC:
            self.kind = "parquet-gz" if gz else "parquet"
            self._open_parquet_header()
        else:
            self.kind = "csv"
            self._open_csv_header()

    # -- Parquet ------------------------------------------------------------

    def _parquet_file(self) -> Any:
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            if self.kind == "parquet-gz":
                return pq.ParquetFile(io.BytesIO(read_bytes(self.path)), pre_buffer=False)
            # pre_buffer would keep every column chunk read so far (the whole file by the
            # end of a pass: 0.67 GB for a year of 1 Hz data)
            return pq.ParquetFile(self.path, pre_buffer=False)
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise FormatError(
                f"corrupt Parquet file ({str(exc).splitlines()[0][:200]})", self.path
            ) from None

    def _open_parquet_header(self) -> None:
        pf = self._parquet_file()
        schema = pf.schema_arrow
        md = schema.metadata or {}
        self.units = _json_object(md.get(b"accal.units", b"{}"), self.path, None, "accal metadata")
        self.meta = _json_object(md.get(b"accal.meta", b"{}"), self.path, None, "accal metadata")
        self.names = list(schema.names)
        self.first_line = 0
        self.num_rows: int | None = pf.metadata.num_rows

    def _iter_parquet(self) -> Iterator[tuple[int, Any]]:
        import pyarrow as pa

        pf = self._parquet_file()
        row = 0
        try:
            for batch in pf.iter_batches(batch_size=self.rows):
                if batch.num_rows:
                    yield row, pa.Table.from_batches([batch])
                    row += batch.num_rows
        except (pa.ArrowException, OSError) as exc:
            raise FormatError(
                f"corrupt Parquet file ({str(exc).splitlines()[0][:200]})", self.path
            ) from None

    # -- CSV ----------------------------------------------------------------

    def _read_csv_header(self, fh: Any) -> tuple[bytes, int]:
        lineno = 0
        while True:
            line = fh.readline()
            lineno += 1
            if not line.startswith(b"#"):
                break
            _comment(line, self.path, lineno, self.units, self.meta)
        check_binary(line, self.path, lineno)
        if not line.strip():
            raise FormatError("no table after the comment lines", self.path, lineno)
        if not line.endswith(b"\n"):
            raise FormatError("header but no data rows", self.path, lineno + 1)
        return line, lineno

    def _open_csv_header(self) -> None:
        import pyarrow as pa
        import pyarrow.csv as pacsv

        with _open_binary(self.path) as fh:
            header, lineno = self._read_csv_header(fh)
        try:
            self.names = pacsv.read_csv(pa.py_buffer(header)).column_names
        except (pa.ArrowException, ValueError) as exc:
            msg = str(exc).splitlines()[0][:200]
            raise FormatError(f"CSV header: {msg}", self.path, lineno) from None
        self.first_line = lineno + 1
        self.num_rows = None

    def _iter_csv(self) -> Iterator[tuple[int, Any]]:
        import itertools

        import pyarrow as pa
        import pyarrow.csv as pacsv

        types: dict[str, Any] = {"qualflg": pa.string()}
        fixed = False
        row = 0
        with _open_binary(self.path) as fh:
            header, lineno = self._read_csv_header(fh)
            line = lineno + 1
            while True:
                lines = list(itertools.islice(fh, self.rows))
                if not lines:
                    break
                if not lines[-1].endswith(b"\n"):
                    raise FormatError(
                        "truncated last line (no newline at end of file)",
                        self.path,
                        line + len(lines) - 1,
                    )
                body = b"".join(lines)
                check_binary(body, self.path, line)
                try:
                    table = pacsv.read_csv(
                        pa.py_buffer(header + body),
                        parse_options=pacsv.ParseOptions(ignore_empty_lines=True),
                        convert_options=pacsv.ConvertOptions(
                            timestamp_parsers=[pacsv.ISO8601],
                            strings_can_be_null=False,
                            column_types=types,
                        ),
                    )
                except (pa.ArrowException, ValueError) as exc:
                    msg = str(exc).splitlines()[0][:200]
                    raise FormatError(
                        f"CSV: {msg} (in lines {line}-{line + len(lines) - 1})", self.path
                    ) from None
                if not fixed:
                    for f in table.schema:
                        if pa.types.is_integer(f.type) or pa.types.is_null(f.type):
                            types[f.name] = pa.float64()
                        elif f.name not in types:
                            types[f.name] = f.type
                    table = pa.Table.from_arrays(
                        [
                            c.cast(types[f.name]) if c.type != types[f.name] else c
                            for f, c in zip(table.schema, table.columns, strict=True)
                        ],
                        names=table.column_names,
                    )
                    fixed = True
                if table.num_rows:
                    yield row, table
                    row += table.num_rows
                line += len(lines)

    # -- both ---------------------------------------------------------------

    def __iter__(self) -> Iterator[tuple[int, Any]]:
        it = self._iter_csv() if self.kind == "csv" else self._iter_parquet()
        empty = True
        for item in it:
            empty = False
            yield item
        if empty:
            raise FormatError("header but no data rows", self.path, self.first_line or None)


def open_table(path: str | Path, *, rows: int = STREAM_ROWS) -> TableStream:
    """Open a Parquet or CSV (optionally gzipped) table for reading in chunks.

    Parameters
    ----------
    path : str or Path
        The file.
    rows : int
        Rows per chunk.

    Returns
    -------
    TableStream
        Column names, units and metadata are read on opening; iterate it for
        ``(first_row, pyarrow.Table)`` chunks.

    Raises
    ------
    FormatError
        Missing, unreadable, empty or corrupt file, bad comment header.
    """
    return TableStream(path, rows=rows)
