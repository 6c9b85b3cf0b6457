"""Arrow table columns as checked numpy arrays: numbers, UTC times, flag bitmasks.

Errors name the CSV line (``line_of``) or the Parquet row of the first bad value.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError
from accal.io.common import arrow_to_numpy, one_line
from accal.io.table_parse import _exc_text
from accal.timescale import utc_to_gps

#: Largest value of a ``quality``/``qualflg``/``flag_val`` bitmask (stored as uint32).
FLAG_MAX = 0xFFFFFFFF


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
#: :data:`accal.io.common.GPS_TIME_RANGE`).
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
