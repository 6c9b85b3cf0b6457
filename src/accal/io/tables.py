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
history and meta (``accal.meta`` / the CSV's sidecar), so reading them gives back the same
:class:`~accal.series.AccSeries`.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import gzip
import io
import json
import re
import warnings
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError, ValidationError, check_option
from accal.io._common import (
    PARQUET_MAGIC,
    UTF8_BOM,
    arrow_to_numpy,
    bits_from_strings,
    check_binary,
    check_gps_time,
    csv_read_options,
    implausible,
    implausible_message,
    missing,
    one_line,
    peek,
    read_bytes,
    row_to_line,
    tidy,
)
from accal.io.grace_l1b import DEFAULT_INVALID_BITS
from accal.io.writers import read_csv_metadata, write_table
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
SATELLITE_PATTERNS = (
    (re.compile(r"(?:^|[_/])SW_(?:OPER_\w*?_)?([ABC])_"), "Swarm-{}"),
    (re.compile(r"^AC[CT]1[AB]_\d{4}-\d{2}-\d{2}_([AB])_"), "GRACE-{}"),
    (re.compile(r"^AC[CT]1[AB]_\d{4}-\d{2}-\d{2}_([CD])_"), "GRACE-FO-{}"),
)
#: Deepest nesting of lists/objects accepted in the JSON metadata (deeper is corrupt,
#: and would overflow the stack of whatever serialises ``meta`` again).
MAX_META_DEPTH = 64
#: Largest value of a ``quality``/``qualflg``/``flag_val`` bitmask (stored as uint32).
FLAG_MAX = 0xFFFFFFFF
#: Fields of the ``accal_series`` metadata and the JSON type each must have.
SERIES_META_TYPES = {
    "satellite": (str, "a string"),
    "frame": (str, "a string"),
    "history": (list, "a list of strings"),
    "units": (dict, "an object of strings"),
    "aux_dtypes": (dict, "an object of strings"),
    "meta": (dict, "an object"),
}

_FMTS = ("parquet", "csv")


def _exc_text(exc: BaseException, limit: int = 200) -> str:
    """The first line of an exception's message (its type if empty), for a one-line error."""
    return one_line((str(exc).splitlines() or [type(exc).__name__])[0], limit)


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


def _too_deep(obj: Any, limit: int) -> bool:
    """True if the JSON value ``obj`` nests lists/objects more than ``limit`` levels deep."""
    stack = [(obj, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            children: Any = value.values()
        elif isinstance(value, list):
            children = value
        else:
            continue
        if depth > limit:
            return True
        stack.extend((c, depth + 1) for c in children)
    return False


def _json_object(raw: bytes | str, path: Path, line: int | None, what: str) -> dict:
    """Parse metadata JSON that must be an object; FormatError otherwise."""
    deep = False
    try:
        obj = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise FormatError(f"{what} is not valid JSON", path, line) from None
    except RecursionError:
        deep = True
    if deep or _too_deep(obj, MAX_META_DEPTH):
        raise FormatError(f"{what} is nested more than {MAX_META_DEPTH} levels deep", path, line)
    if not isinstance(obj, dict):
        raise FormatError(f"{what} is not a JSON object", path, line)
    return obj


def _json_type(value: Any) -> str:
    """The JSON name of the type of ``value``, for messages ("a number", "a list", ...)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return "a list" if isinstance(value, list) else "an object"


def _units_object(raw: bytes | str, path: Path, line: int | None, what: str) -> dict[str, str]:
    """Parse a units JSON object (column name -> unit string); FormatError otherwise."""
    units = _json_object(raw, path, line, what)
    for k, v in units.items():
        if not isinstance(v, str):
            raise FormatError(
                f"{what}: unit of {one_line(k, 40)!r} is {_json_type(v)}, not a string", path, line
            )
    return units


def _column_names(schema: Any, path: Path) -> list[str]:
    """The field names of an Arrow schema; FormatError if one is not UTF-8."""
    try:
        return list(schema.names)
    except UnicodeDecodeError:
        raise FormatError("corrupt Parquet file (a column name is not UTF-8)", path) from None


def check_unique_names(names: list[str], path: Path, line: int | None = None) -> None:
    """Raise FormatError if a column name occurs more than once.

    Parameters
    ----------
    names : list of str
        Column names in file order.
    path : Path
        The file (for the message).
    line : int, optional
        1-based line of the CSV header.

    Raises
    ------
    FormatError
        ``duplicated column name(s) ...`` (pyarrow cannot select such a column).
    """
    if len(set(names)) == len(names):
        return
    seen: set[str] = set()
    dups: list[str] = []
    for n in names:
        if n in seen and n not in dups:
            dups.append(n)
        seen.add(n)
    shown = column_list(d or "''" for d in dups)  # an empty name as ''
    raise FormatError(f"duplicated column name(s) {shown}", path, line)


def check_single_line_values(table: Any, path: Path, first_line: int) -> None:
    """Raise FormatError if a CSV text value spans lines: a stray double quote.

    pyarrow reads from an unmatched ``"`` to the next one, or to the end of the
    buffer, as one value: the rows in between would silently vanish into a text
    column (which accal then ignores as non-numeric).

    Parameters
    ----------
    table : pyarrow.Table
        A table parsed from CSV.
    path : Path
        The file (for the message).
    first_line : int
        1-based line of the table's first data row.

    Raises
    ------
    FormatError
        Naming the column and the line where the value starts.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    for name, col in zip(table.column_names, table.columns, strict=True):
        if not (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
            continue
        for eol in ("\n", "\r"):
            hit = pc.match_substring(col, eol)
            if pc.any(hit).as_py():
                row = int(pc.index(hit, True).as_py())
                raise FormatError(
                    f"column {one_line(name, 40)!r}: a quoted value runs over several lines "
                    "(a stray '\"'?)",
                    path,
                    first_line + row,
                )


def _comment(line: bytes, path: Path, lineno: int, units: dict, meta: dict) -> None:
    """Parse one ``# key: value`` comment line into ``units``/``meta`` (in place)."""
    text = line.decode("utf-8", "replace").rstrip("\r\n")
    key, _, rest = text[1:].partition(":")
    key = key.strip()
    if key in ("units", "meta"):
        what = f"comment '{key}:'"
        obj = (
            _units_object(rest, path, lineno, what)
            if key == "units"
            else _json_object(rest, path, lineno, what)
        )
        target = units if key == "units" else meta
        target.clear()
        target.update(obj)


def _csv_error(exc: BaseException, body: bytes, header_line: int) -> tuple[str, int | None]:
    """pyarrow's CSV error as one clean line, and the file line it is about (error path only).

    Parameters
    ----------
    exc : Exception
        pyarrow's exception.
    body : bytes
        The CSV text that was parsed: the header line, then the rows.
    header_line : int
        1-based file line of the header line.

    Returns
    -------
    message : str
        ``Expected 4 columns, got 3: ...`` or ``column 'x': invalid value 'abc'
        (expected double)``.
    line : int or None
        The first row with the wrong number of fields, or with the invalid value in
        that column; None when it cannot be found.
    """
    msg = re.sub(r"^CSV parse error: ", "", _exc_text(exc))
    m = re.search(r"Row #(\d+)", msg)
    # the single-threaded reader names the row ("Row #3: ..."); the line is found below,
    # counting blank lines, so the message is the same for either reader
    msg = re.sub(r"(^|: )Row #\d+: ", r"\1", msg)
    count = re.search(r"Expected (\d+) columns, got \d+", msg)
    conv = re.match(
        r"In CSV column #(\d+): CSV conversion error to (\w+): invalid value '(.*)'$", msg
    )
    if not (count or conv):
        return msg, (header_line + int(m.group(1)) - 1) if m else None
    rows = csv.reader(io.StringIO(body.decode("utf-8", "replace"), newline=""))
    header = next(rows, [])
    if conv:
        k, typ, value = int(conv.group(1)), conv.group(2), conv.group(3)
        if k < len(header):
            msg = f"column {one_line(header[k], 40)!r}: invalid value {value!r} (expected {typ})"
    end = rows.line_num
    for row in rows:
        start, end = end + 1, rows.line_num
        if not row:  # a blank line (skipped by pyarrow)
            continue
        if (count and len(row) != int(count.group(1))) or (
            conv and len(row) > k and row[k] == value
        ):
            return msg, header_line + start - 1
    return msg, None


def last_line_complete(body: bytes, header: bytes | None = None) -> bool:
    """Whether the last line of a CSV ``body`` (no final newline) has every field.

    A file cut inside its last line leaves fewer fields than the header line
    (``header``, default the first line of ``body``); a line with all of them is
    read (editors and some tools omit the final newline).  A cut inside the last
    field itself cannot be told from a complete value.
    """
    import csv

    first = body.split(b"\n", 1)[0] if header is None else header
    last = body[body.rfind(b"\n") + 1 :]
    try:
        n_header = len(next(csv.reader([first.decode("utf-8").rstrip("\r\n")])))
        row = next(csv.reader([last.decode("utf-8").rstrip("\r")]), [])
    except (UnicodeDecodeError, csv.Error, StopIteration):
        return False
    return len(row) == n_header and row[-1].strip() != ""


def _plain_name(path: Path) -> Path:
    """``x.csv`` for ``x.csv.gz`` (a compressed CSV's sidecar keeps the CSV's name)."""
    for suffix in (".gz", ".bz2", ".xz"):
        if path.name.lower().endswith(suffix):
            return path.with_name(path.name[: -len(suffix)])
    return path


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
        From the sidecar ``<file>-metadata.json`` (:func:`accal.io.writers.write_csv_metadata`)
        and the ``# units: {...}`` and ``# meta: {...}`` comment lines (which win).
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
    side = read_csv_metadata(_plain_name(path))
    if side is not None:  # accal's own CSVs: units in the sidecar (comment lines win)
        units, meta = {**side[0], **units}, {**side[1], **meta}
    body = raw[pos:]
    check_binary(body[:65536], path, n_comment + 1)
    if not body.strip():
        raise FormatError("no table after the comment lines", path, n_comment + 1)
    if body.count(b"\n") <= 1 and not body.rstrip(b"\r\n").count(b"\n"):
        raise FormatError("header but no data rows", path, n_comment + 2)
    if not body.endswith(b"\n"):
        if not last_line_complete(body):
            raise FormatError(
                "truncated last line (no newline at end of file)",
                path,
                n_comment + body.count(b"\n") + 1,
            )
        body += b"\n"
    try:
        table = pacsv.read_csv(
            pa.py_buffer(body),
            read_options=csv_read_options(),
            parse_options=pacsv.ParseOptions(ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(
                timestamp_parsers=[pacsv.ISO8601],
                strings_can_be_null=False,
                # 8-character 0/1 flags must stay strings ("00100000" is not 100000).
                column_types={"qualflg": pa.string()},
            ),
        )
    except (pa.ArrowException, ValueError) as exc:
        msg, line = _csv_error(exc, body, n_comment + 1)
        raise FormatError(f"CSV: {msg}", path, line) from None
    check_unique_names(table.column_names, path, n_comment + 1)
    check_single_line_values(table, path, n_comment + 2)
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
        # ParquetFile, not pq.read_table: that one imports pyarrow.dataset and with it
        # pandas (~0.5 s, a third of a one-file run)
        table = pq.ParquetFile(io.BytesIO(raw)).read()
    except UnicodeDecodeError:  # the field names are decoded as the file is read
        raise FormatError("corrupt Parquet file (a column name is not UTF-8)", path) from None
    except (pa.ArrowException, OSError, ValueError) as exc:
        try:  # pyarrow refuses duplicated names with "Multiple matches for FieldRef"
            names = pq.read_schema(io.BytesIO(raw)).names
        except (pa.ArrowException, OSError, ValueError):  # incl. UnicodeDecodeError
            names = []
        check_unique_names(names, path)
        raise FormatError(f"corrupt Parquet file ({_exc_text(exc)})", path) from None
    md = table.schema.metadata or {}
    units = _units_object(md.get(b"accal.units", b"{}"), path, None, "accal metadata")
    meta = _json_object(md.get(b"accal.meta", b"{}"), path, None, "accal metadata")
    check_unique_names(_column_names(table.schema, path), path)
    return table, units, meta, 0


#: A number as pyarrow's CSV reader reads one (RE2 syntax), for finding the value
#: that made a column text (error path only).
_NUMBER_PATTERN = r"(?i)^[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?|nan|inf|infinity)$"


def _first_non_number(col: Any) -> int | None:
    """Row of the first non-empty value of a text column that is not a number, if any."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if not (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
        return None
    bad = pc.and_(
        pc.invert(pc.match_substring_regex(col, _NUMBER_PATTERN)), pc.not_equal(col, "")
    ).fill_null(False)
    row = pc.index(bad, True).as_py()
    return None if row is None or row < 0 else int(row)


def numeric_column(
    col: Any,
    name: str,
    path: Path,
    line_of: Callable[[int], int] | None = None,
    *,
    locate: bool = False,
) -> np.ndarray:
    """An integer, float or boolean Arrow column as numpy; nulls become NaN.

    Parameters
    ----------
    col : pyarrow.ChunkedArray or pyarrow.Array
        The column.
    name : str
        Its name, for messages.
    path : Path
        The file, for messages.
    line_of : callable, optional
        Row index -> 1-based file line (CSV).  Given, the error names the line of
        the first value that is not a number.
    locate : bool
        Name that value's row (``row N:``) when there are no lines (Parquet).  The
        search runs on the error path only; leave both off for columns that may
        legitimately be text (e.g. auxiliary columns that are tried and skipped).

    Raises
    ------
    FormatError
        The column is not numeric (names the column, and the line or row of the
        first value that is not a number where asked and found).
    """
    import pyarrow as pa

    t = col.type
    if not (pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t)):
        msg = f"column {one_line(name, 40)!r} is not numeric (type {t})"
        row = _first_non_number(col) if locate or line_of is not None else None
        if row is None:
            raise FormatError(msg, path)
        value = one_line(str(col[row].as_py()), 40)
        raise _row_error(f"{msg}: {value!r} is not a number", path, row, line_of)
    arr = arrow_to_numpy(col)
    if col.null_count:
        arr = np.asarray(col.cast(pa.float64()).fill_null(np.nan).to_numpy(), float)
    return arr


#: UTC instants accepted in a ``time_utc`` column: the GPS epoch to 2100 (as
#: :data:`accal.io._common.GPS_TIME_RANGE`).
UTC_RANGE = (np.datetime64("1980-01-06T00:00:00", "s"), np.datetime64("2100-01-01T00:00:00", "s"))
#: :data:`UTC_RANGE` as ISO-8601 text, compared with the smallest and largest string.
_UTC_TEXT_RANGE = ("1980-01-06", "2100-01-01T00:00:00")


def utc_column_to_gps(
    col: Any, name: str, path: Path, line_of: Callable[[int], int] | None = None
) -> np.ndarray:
    """GPS seconds of a UTC column: Arrow timestamps or ISO-8601 strings.

    Parameters
    ----------
    col : pyarrow.ChunkedArray
        The column (naive timestamps are UTC).
    name : str
        Its name, for messages.
    path : Path
        The file, for messages.
    line_of : callable, optional
        Row index -> 1-based file line (CSV); without it messages name the row.

    Returns
    -------
    ndarray of float64
        [s, GPS since 2000-01-01 12:00:00], converted by :func:`accal.timescale.utc_to_gps`.

    Raises
    ------
    FormatError
        Empty values, a timestamp outside 1980-01-06 ... 2100-01-01 (checked before
        the conversion, whose int64 nanoseconds would wrap a year like 2600 into the
        GPS era), values that are not ISO-8601 UTC.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    if col.null_count:
        row = int(pc.index(col.is_null(), True).as_py())
        raise _row_error(f"{name}: empty value", path, row, line_of)
    if pa.types.is_timestamp(col.type):
        vals = col.to_numpy()
        bad = np.flatnonzero((vals < UTC_RANGE[0]) | (vals > UTC_RANGE[1]))
        if bad.size:
            i = int(bad[0])
            raise _row_error(
                f"{name} {vals[i]} is outside 1980-01-06 ... 2100-01-01", path, i, line_of
            )
    else:
        vals = np.asarray(col.to_pylist())
        if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
            # ISO-8601 text sorts by date: a cheap range check before the conversion,
            # whose datetime64[ns] would wrap a year like 2600 into the GPS era
            lo, hi = pc.min_max(col).values()
            if lo.as_py() < _UTC_TEXT_RANGE[0] or hi.as_py() > _UTC_TEXT_RANGE[1]:
                err = _bad_utc(vals, name, path, line_of)
                if err is not None:
                    raise err
    try:
        return utc_to_gps(vals)
    except (ValueError, TypeError) as exc:
        err = _bad_utc(vals, name, path, line_of)
        raise err or FormatError(f"{name}: {_exc_text(exc)}", path) from None


def _bad_utc(
    vals: np.ndarray,
    name: str,
    path: Path,
    line_of: Callable[[int], int] | None,
) -> FormatError | None:
    """The error for the first bad value of a UTC text column, or None (error path).

    A value is bad when it is not ISO-8601 or lies outside :data:`UTC_RANGE`; the
    error gives its line (CSV) or row (Parquet).
    """
    import pandas as pd

    if vals.dtype.kind in "USO":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ts = pd.to_datetime(
                pd.Series(vals.ravel(), dtype=object), format="ISO8601", utc=True, errors="coerce"
            )
        t = ts.dt.tz_convert(None).to_numpy()  # its own unit: [ns] would wrap year 2600
        bad = np.flatnonzero(np.isnat(t) | (t < UTC_RANGE[0]) | (t > UTC_RANGE[1]))
        if bad.size:
            i = int(bad[0])
            shown = one_line(str(vals[i]), 40)
            msg = (
                f"{name}: {shown!r} is not an ISO-8601 UTC time (YYYY-MM-DDThh:mm:ss[.fff][Z])"
                if np.isnat(t[i])
                else f"{name} {shown} is outside 1980-01-06 ... 2100-01-01"
            )
            return _row_error(msg, path, i, line_of)
    return None


def _bad_flags(
    col: Any, name: str, path: Path, line_of: Callable[[int], int] | None
) -> FormatError:
    """The error for a text flag column that is neither 0/1 flags nor integers (error path)."""
    import pyarrow.compute as pc

    msg = f"column {name!r} is neither 8-character 0/1 flags nor integers"
    ok = pc.or_(
        pc.match_substring_regex(col, r"^[01]{8}$"), pc.match_substring_regex(col, r"^[+-]?\d+$")
    )
    row = pc.index(pc.invert(ok).fill_null(True), True).as_py()
    if row is None or row < 0:
        return FormatError(msg, path)
    value = one_line(str(col[int(row)].as_py()), 40)
    return _row_error(f"{msg}: {value!r}", path, int(row), line_of)


def _row_error(msg: str, path: Path, row: int, line_of: Callable[[int], int] | None) -> FormatError:
    """FormatError about data row ``row`` (0-based): its line (CSV) or ``row N:`` (Parquet)."""
    if line_of is None:
        return FormatError(f"row {row + 1}: {msg}", path)
    return FormatError(msg, path, line_of(row))


def _bitmask(
    values: np.ndarray,
    name: str,
    path: Path,
    line_of: Callable[[int], int] | None,
    *,
    allow_nan: bool = False,
) -> np.ndarray:
    """Check that a flag column holds integers 0 ... :data:`FLAG_MAX`; return it as uint32.

    ``astype(np.uint32)`` alone would wrap a negative or too large value (1e30 -> 0,
    a flagged sample would look valid).  With ``allow_nan`` NaN passes (as 0; the
    caller decides what a missing flag means).

    Raises
    ------
    FormatError
        The first offending value, with its line (CSV) or row (Parquet).
    """
    if values.dtype.kind == "b":
        return values.astype(np.uint32)
    if values.dtype.kind in "iu":
        bad = (values < 0) | (values > FLAG_MAX)
    else:
        with np.errstate(invalid="ignore"):
            bad = ~((values >= 0) & (values <= FLAG_MAX) & (values == np.floor(values)))
        if allow_nan:
            bad &= ~np.isnan(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise _row_error(
            f"column {name!r} must hold integers 0 ... {FLAG_MAX} (a bitmask), "
            f"got {values[i].item()!r}",
            path,
            i,
            line_of,
        )
    if allow_nan and values.dtype.kind == "f":
        values = np.where(np.isnan(values), 0, values)
    return values.astype(np.uint32)


def _series_meta(fmeta: dict, path: Path) -> dict[str, Any] | None:
    """The ``accal_series`` description in ``fmeta``, type-checked; None if there is none.

    Fields that are null are dropped (the reader's defaults apply).

    Raises
    ------
    FormatError
        A field of the wrong JSON type (see :data:`SERIES_META_TYPES`).
    """
    sm = fmeta.get(META_KEY)
    if not isinstance(sm, dict):
        return None
    out: dict[str, Any] = {}
    for key, value in sm.items():
        if value is None or key not in SERIES_META_TYPES:
            continue
        typ, expected = SERIES_META_TYPES[key]
        got = _json_type(value)
        if isinstance(value, typ):
            items = value.items() if isinstance(value, dict) else enumerate(value)
            strings = key in ("history", "units", "aux_dtypes")
            bad = next((k for k, v in items if strings and not isinstance(v, str)), None)
            if bad is None:
                out[key] = value
                continue
            which = f"{one_line(bad, 40)!r}" if isinstance(value, dict) else str(bad)
            got = f"{got} whose item {which} is {_json_type(value[bad])}"
        raise FormatError(
            f"accal metadata: {META_KEY} field {key!r} must be {expected}, got {got}", path
        )
    return out


_DTYPE_NAME = re.compile(r"[<>=|]?(?:\?|[A-Za-z][A-Za-z0-9]*)")


def _aux_dtype(name: str, spec: str, path: Path) -> np.dtype:
    """The numpy dtype ``spec`` recorded for auxiliary column ``name``, if it is numeric.

    Raises
    ------
    FormatError
        ``spec`` is not a numpy dtype, or not a bool, integer or float scalar of at
        most 64 bits (what a table column can hold).
    """
    dt: np.dtype | None = None
    # A plain type code or name only: np.dtype parses "(2,)f8" or "f8,i4" into
    # subarray/record types, and some strings ("000000002") into a SyntaxError.
    if _DTYPE_NAME.fullmatch(spec):
        with contextlib.suppress(TypeError, ValueError):
            dt = np.dtype(spec)
    if dt is None or dt.kind not in "biuf" or dt.itemsize > 8 or dt.shape:
        raise FormatError(
            f"accal metadata: aux_dtypes of {one_line(name, 40)!r} is {one_line(spec, 40)!r}, "
            "not a bool, integer or float dtype of at most 64 bits",
            path,
        )
    return dt.newbyteorder("=")


def _cast_aux(
    values: np.ndarray,
    dt: np.dtype,
    name: str,
    path: Path,
    line_of: Callable[[int], int] | None,
) -> np.ndarray:
    """``values`` cast to the recorded dtype ``dt``, refusing a cast that changes a value.

    An integer cast must be exact (a NaN, a fraction or an out-of-range value would be
    silently replaced); a float cast may round but not overflow.
    """
    if values.dtype == dt:
        return values
    with np.errstate(invalid="ignore", over="ignore"):
        out = values.astype(dt)
        lost = np.isfinite(out) != np.isfinite(values) if dt.kind == "f" else out != values
    if lost.any():
        i = int(np.flatnonzero(lost)[0])
        raise _row_error(
            f"column {name!r}: {values[i].item()!r} does not fit its recorded dtype {dt.name}",
            path,
            i,
            line_of,
        )
    return out


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
        A ``columns`` key that is not an axis.
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
    series_meta = _series_meta(fmeta, path)
    aux_dtypes = {
        k: _aux_dtype(k, v, path) for k, v in (series_meta or {}).get("aux_dtypes", {}).items()
    }
    # 1-based CSV line of data row i (blank lines counted on the error path only);
    # Parquet rows have no line
    line_of = row_to_line(raw, first_line, text_line=1) if first_line else None

    tname = next((c for c in TIME_COLUMNS if c in names), None)
    if tname is None:
        raise FormatError(
            f"no time column (one of {', '.join(TIME_COLUMNS)}); columns are {column_list(names)}",
            path,
        )
    tcol = table.column(tname)
    if tname == "time_utc":
        time = utc_column_to_gps(tcol, tname, path, line_of)
    else:
        time = numeric_column(tcol, tname, path, line_of, locate=True).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise _row_error(f"{tname}: missing or non-finite time", path, int(bad[0]), line_of)
    check_gps_time(time, path, line_of, name=tname, unit="row")

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
    for k, dt in aux_dtypes.items():
        if k in aux:
            aux[k] = _cast_aux(aux[k], dt, k, path, line_of)
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


#: What reading an open file can raise besides FormatError: a corrupt or truncated
#: gzip stream (``gzip.BadGzipFile``, an OSError; ``zlib.error``; ``EOFError``) or an
#: I/O error.
_READ_ERRORS = (OSError, EOFError, zlib.error)


def _read_failed(exc: BaseException, path: Path) -> FormatError:
    """The FormatError for an exception of :data:`_READ_ERRORS` raised while reading ``path``."""
    if isinstance(exc, EOFError):
        return FormatError("corrupt gzip stream (truncated: no end-of-stream marker)", path)
    if isinstance(exc, gzip.BadGzipFile) and str(exc).startswith("Not a gzipped file"):
        # the magic was checked on opening: this is a second "member" that is not one
        return FormatError("corrupt gzip stream (garbage after the compressed data)", path)
    if isinstance(exc, zlib.error | gzip.BadGzipFile):
        return FormatError(f"corrupt gzip stream ({one_line(str(exc), 100)})", path)
    reason = getattr(exc, "strerror", None) or str(exc)
    return FormatError(f"cannot read file: {one_line(reason, 100)}", path)


def _open_binary(path: Path) -> Any:
    """Open ``path`` for reading bytes, decompressing gzip (by magic); FormatError on failure."""
    if path.is_dir():
        raise FormatError("is a directory, not a file", path)
    try:
        fh = open(path, "rb")  # noqa: SIM115 (returned to the caller, who closes it)
    except FileNotFoundError:
        raise FormatError(missing(path), path) from None
    except PermissionError:
        raise FormatError("permission denied (file not readable)", path) from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FormatError(missing(path), path) from None
        raise FormatError(f"cannot read file: {exc.strerror or exc}", path) from None
    try:
        magic = fh.read(2)
        fh.seek(0)
    except OSError as exc:
        fh.close()
        raise _read_failed(exc, path) from None
    if magic == b"\x1f\x8b":
        return gzip.GzipFile(fileobj=fh, mode="rb")
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
        ``accal.units`` / ``accal.meta`` (Parquet) or the sidecar and ``# units:`` /
        ``# meta:`` lines (CSV).
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
            head = self._read(fh.read, 4)
            gz = not isinstance(fh, io.BufferedReader)
            if head.startswith(UTF8_BOM):  # a UTF-8 CSV that starts with a byte-order mark
                head = head[len(UTF8_BOM) :] + self._read(fh.read, len(UTF8_BOM))
            blank = not head.strip() and not self._read(fh.read, 1 << 16).strip()
        if blank:
            raise FormatError("empty file", self.path)
        self.units: dict[str, str] = {}
        self.meta: dict[str, Any] = {}
        if head == PARQUET_MAGIC:
            self.kind = "parquet-gz" if gz else "parquet"
            self._open_parquet_header()
        else:
            self.kind = "csv"
            self._open_csv_header()

    def _read(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``, a read of the open file, with read errors as FormatError."""
        try:
            return fn(*args)
        except _READ_ERRORS as exc:
            raise _read_failed(exc, self.path) from None

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
            raise FormatError(f"corrupt Parquet file ({_exc_text(exc)})", self.path) from None

    def _open_parquet_header(self) -> None:
        pf = self._parquet_file()
        schema = pf.schema_arrow
        md = schema.metadata or {}
        self.units = _units_object(md.get(b"accal.units", b"{}"), self.path, None, "accal metadata")
        self.meta = _json_object(md.get(b"accal.meta", b"{}"), self.path, None, "accal metadata")
        self.names = _column_names(schema, self.path)
        check_unique_names(self.names, self.path)
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
            raise FormatError(f"corrupt Parquet file ({_exc_text(exc)})", self.path) from None
        expected = pf.metadata.num_rows
        if row != expected:  # a corrupt page can end a column early without an error
            raise FormatError(
                f"corrupt Parquet file (read {row} rows, the footer says {expected})", self.path
            )

    # -- CSV ----------------------------------------------------------------

    def _read_csv_header(self, fh: Any) -> tuple[bytes, int]:
        lineno = 0
        while True:
            line = self._read(fh.readline)
            lineno += 1
            if lineno == 1 and line.startswith(UTF8_BOM):
                line = line[len(UTF8_BOM) :]
            if not line.startswith(b"#"):
                break
            _comment(line, self.path, lineno, self.units, self.meta)
        check_binary(line, self.path, lineno)
        if not line.strip():
            what = "no table after the comment lines" if lineno > 1 else "blank first line"
            raise FormatError(f"{what} (expected the CSV header)", self.path, lineno)
        if not line.endswith(b"\n"):
            raise FormatError("header but no data rows", self.path, lineno + 1)
        return line, lineno

    def _open_csv_header(self) -> None:
        import pyarrow as pa
        import pyarrow.csv as pacsv

        with _open_binary(self.path) as fh:
            header, lineno = self._read_csv_header(fh)
        try:
            self.names = pacsv.read_csv(
                pa.py_buffer(header), read_options=csv_read_options()
            ).column_names
        except (pa.ArrowException, ValueError) as exc:
            msg = _exc_text(exc)
            raise FormatError(f"CSV header: {msg}", self.path, lineno) from None
        check_unique_names(self.names, self.path, lineno)
        self.first_line = lineno + 1
        self.num_rows = None
        side = read_csv_metadata(_plain_name(self.path))
        if side is not None:  # accal's own CSVs: units in the sidecar (comment lines win)
            self.units, self.meta = {**side[0], **self.units}, {**side[1], **self.meta}

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
                lines = self._read(lambda: list(itertools.islice(fh, self.rows)))
                if not lines:
                    break
                if not lines[-1].endswith(b"\n"):
                    if not last_line_complete(lines[-1], header):
                        raise FormatError(
                            "truncated last line (no newline at end of file)",
                            self.path,
                            line + len(lines) - 1,
                        )
                    lines[-1] += b"\n"
                body = b"".join(lines)
                check_binary(body, self.path, line)
                try:
                    table = pacsv.read_csv(
                        pa.py_buffer(header + body),
                        read_options=csv_read_options(),
                        parse_options=pacsv.ParseOptions(ignore_empty_lines=True),
                        convert_options=pacsv.ConvertOptions(
                            timestamp_parsers=[pacsv.ISO8601],
                            strings_can_be_null=False,
                            column_types=types,
                        ),
                    )
                except (pa.ArrowException, ValueError) as exc:
                    msg, at = _csv_error(exc, header + body, line - 1)
                    if at is not None:
                        raise FormatError(f"CSV: {msg}", self.path, at) from None
                    raise FormatError(
                        f"CSV: {msg} (in lines {line}-{line + len(lines) - 1})", self.path
                    ) from None
                check_single_line_values(table, self.path, line)
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
        Missing, unreadable, empty or corrupt file (also a corrupt gzip stream),
        bad comment header or metadata, duplicated column names.  While
        iterating: a corrupt gzip stream or Parquet page (also one that silently
        ends a column early), CSV parse errors.
    """
    return TableStream(path, rows=rows)
