"""UTC columns beside the GPS-seconds columns of accal's output files (issue 21).

Every series and table accal writes keeps its times in GPS seconds since
2000-01-01 12:00:00 GPS (exact, what accal reads back) and carries the same
instants in UTC beside them, for readers that open the file without the docs:
``gps_time`` → ``time_utc`` (calibrated series), ``t0`` → ``t0_utc``
(``bias_drift``), ``t_start``/``t_mid`` → ``t_start_utc``/``t_mid_utc`` (demod's
``periods``).  The instants come from :func:`accal.timescale.gps_to_utc` (accal's
leap-second table), rounded to the microsecond as in :func:`accal.api.utc_instants`.

In Parquet a UTC column is ``timestamp[ns, tz=UTC]``; in CSV it is ISO 8601 text
with a ``Z`` (``2003-09-13T23:59:47.000000Z``), which ``pandas.read_csv`` keeps as
text and ``pandas.to_datetime`` parses.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.io.common import arrow_to_numpy
from accal.timescale import GPS_TABLE_START, LeapSecondTableWarning, gps_to_utc

#: Suffix of a UTC column: ``<gps column>_utc`` (``gps_time`` → ``time_utc``).
UTC_SUFFIX = "_utc"


def utc_name(gps_column: str) -> str:
    """Name of the UTC column of a GPS-seconds column (``gps_time`` → ``time_utc``)."""
    return gps_column.removeprefix("gps_") + UTC_SUFFIX


def utc_unit(gps_column: str) -> str:
    """Unit text of the UTC column of ``gps_column`` (file metadata).

    Parameters
    ----------
    gps_column : str
        The GPS-seconds column the UTC column is computed from.

    Returns
    -------
    str
        ``UTC (ISO 8601 ...)``: the time scale first, as the other columns give their unit.
    """
    return (
        f"UTC (ISO 8601 instant of {gps_column}, converted with the leap-second table of "
        "accal.timescale and rounded to the microsecond; the exact time is the GPS seconds "
        f"of {gps_column})"
    )


def utc_instants(gps: ArrayLike) -> NDArray[np.datetime64]:
    """GPS seconds as UTC instants (naive ``datetime64[ns]``), rounded to the microsecond.

    As :func:`accal.api.utc_instants`, but total for output files: a non-finite time
    or one before 1972 (no leap-second table) is NaT, and an instant after
    :data:`accal.timescale.LEAP_SECONDS_VALID_UNTIL` is converted with the last
    GPS−UTC without a warning (the column's unit names the table used).

    Parameters
    ----------
    gps : array_like of float
        GPS seconds since 2000-01-01 12:00:00 GPS [s].

    Returns
    -------
    ndarray of datetime64[ns]
        UTC, NaT where the time cannot be converted.
    """
    g = np.asarray(gps, dtype=np.float64)
    ok = np.isfinite(g) & (g >= GPS_TABLE_START)
    every = bool(ok.all())
    ns = np.full(g.shape, np.iinfo(np.int64).min, dtype=np.int64)
    if every or ok.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LeapSecondTableWarning)
            got = gps_to_utc(g if every else g[ok]).view(np.int64)
        got += 500  # to the microsecond, in place (a 1 Hz day: 86,400 values)
        got //= 1000
        got *= 1000
        if every:
            return got.view("datetime64[ns]")
        ns[ok] = got
    return ns.view("datetime64[ns]")


def iso_text(instants: NDArray[np.datetime64]) -> Any:
    """UTC instants as ISO 8601 text to the microsecond with a ``Z``.

    Parameters
    ----------
    instants : ndarray of datetime64
        Naive UTC instants (1970 to 9999).

    Returns
    -------
    pyarrow.Array of string
        ``2003-09-13T23:59:47.000000Z``; an empty string for NaT.

    Notes
    -----
    Formatted with integer arithmetic on a byte matrix (a 1 Hz day: a few ms, where
    ``numpy.datetime_as_string`` takes ~90 ms and pyarrow's ``strftime`` ~0.4 s).
    """
    import pyarrow as pa

    width = 27  # YYYY-MM-DDTHH:MM:SS.ffffffZ
    us = np.asarray(instants).astype("datetime64[us]")
    ok = ~np.isnat(us)
    t = us[ok].view(np.int64)
    day, rem = np.divmod(t, 86_400_000_000)
    buf = np.empty((t.size, width), dtype=np.uint8)
    if t.size:  # the dates of the days spanned, each formatted once
        first = int(day.min())
        days = np.arange(first, int(day.max()) + 1).astype("datetime64[D]")
        dates = np.datetime_as_string(days).astype("S10").view(np.uint8).reshape(-1, 10)
        buf[:, :10] = dates[day - first]
    second, micro = np.divmod(rem, 1_000_000)
    hour, second = np.divmod(second, 3600)
    minute, second = np.divmod(second, 60)
    centi, micro = np.divmod(micro, 100)
    milli, centi = np.divmod(centi, 100)
    for pos, value in (
        (11, hour),
        (14, minute),
        (17, second),
        (20, milli),
        (22, centi),
        (24, micro),
    ):
        two = value.astype(np.uint8)  # 0..99: the digits in uint8 arithmetic
        buf[:, pos] = two // 10 + 48
        buf[:, pos + 1] = two % 10 + 48
    for pos, char in ((10, "T"), (13, ":"), (16, ":"), (19, "."), (26, "Z")):
        buf[:, pos] = ord(char)
    lengths = np.where(ok, width, 0)
    offsets = np.zeros(us.size + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    return pa.Array.from_buffers(
        pa.string(), us.size, [None, pa.py_buffer(offsets), pa.py_buffer(buf.tobytes())]
    )


def utc_arrow(gps: ArrayLike, fmt: str) -> Any:
    """The UTC column of ``gps`` as a pyarrow array for a file of format ``fmt``.

    Parameters
    ----------
    gps : array_like of float
        GPS seconds [s].
    fmt : {"parquet", "csv"}
        ``parquet``: ``timestamp[ns, tz=UTC]``; ``csv``: ISO 8601 strings ending in ``Z``.

    Returns
    -------
    pyarrow.Array
        Null (Parquet) or empty (CSV) where the time cannot be converted.
    """
    return instants_arrow(utc_instants(gps), fmt)


def instants_arrow(instants: NDArray[np.datetime64], fmt: str) -> Any:
    """Naive UTC instants as the pyarrow array of a UTC column (see :func:`utc_arrow`).

    Parameters
    ----------
    instants : ndarray of datetime64
        UTC instants, NaT where unknown.
    fmt : {"parquet", "csv"}
        The file format.

    Returns
    -------
    pyarrow.Array
        ``timestamp[ns, tz=UTC]`` (Parquet) or ISO 8601 text (CSV).
    """
    import pyarrow as pa

    instants = np.asarray(instants).astype("datetime64[ns]", copy=False)
    if fmt == "csv":  # an empty field for NaT: what the CSV writer writes for a null
        return iso_text(instants)
    # from buffers: pa.array and casts import pandas (~0.3 s of a one-file run)
    ns = np.ascontiguousarray(instants).view(np.int64)
    nat = np.isnat(instants)
    valid = pa.py_buffer(np.packbits(~nat, bitorder="little")) if nat.any() else None
    return pa.Array.from_buffers(
        pa.timestamp("ns", tz="UTC"), ns.size, [valid, pa.py_buffer(ns)], null_count=-1
    )


def with_utc_columns(
    data: Mapping[str, Any], gps_columns: tuple[str, ...], fmt: str
) -> dict[str, Any]:
    """``data`` with the UTC column of each of ``gps_columns`` right after it.

    Parameters
    ----------
    data : mapping of str to array
        The columns (numpy arrays or pyarrow arrays); a UTC column already there is
        recomputed from its GPS column.
    gps_columns : tuple of str
        GPS-seconds columns to convert (those absent from ``data`` are skipped).
    fmt : {"parquet", "csv"}
        The file format (:func:`utc_arrow`).

    Returns
    -------
    dict of str to array
        The columns in their order, each UTC column after its GPS column.
    """
    return _after_each(data, gps_columns, lambda v: utc_arrow(_float_values(v), fmt))


def utc_units(units: Mapping[str, str], gps_columns: tuple[str, ...]) -> dict[str, str]:
    """``units`` with the unit of each UTC column right after its GPS column's."""
    return _after_each(units, gps_columns, None)


def _after_each(
    items: Mapping[str, Any], gps_columns: tuple[str, ...], make: Callable[[Any], Any] | None
) -> dict[str, Any]:
    """``items`` with ``make(item)`` (None: the unit text) after each of ``gps_columns``;
    a UTC entry already there is dropped and made anew."""
    derived = {utc_name(c) for c in gps_columns if c in items}
    out: dict[str, Any] = {}
    for name, value in items.items():
        if name in derived:
            continue
        out[name] = value
        if name in gps_columns:
            out[utc_name(name)] = utc_unit(name) if make is None else make(value)
    return out


def _float_values(values: Any) -> NDArray[np.float64]:
    import pyarrow as pa

    if isinstance(values, pa.ChunkedArray | pa.Array):
        return np.asarray(arrow_to_numpy(values.cast(pa.float64())), dtype=np.float64)
    return np.asarray(values, dtype=np.float64)
