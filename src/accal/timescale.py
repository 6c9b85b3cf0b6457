"""GPS time <-> UTC with a leap-second table.

accal carries time as **GPS seconds since 2000-01-01 12:00:00 GPS** (the GRACE /
GRACE-FO Level-1B epoch, equal to 2000-01-01 11:59:47 UTC).  GPS time has no
leap seconds; UTC does.  Their difference is taken from the table of TAI−UTC
(:data:`LEAP_SECONDS`) with GPS = TAI − 19 s, so GPS−UTC was 13 s in 2000–2005
and has been 18 s since 2017-01-01.  No constant offset is used anywhere.

Day boundaries
--------------
GRACE and GRACE-FO daily L1B files run from 00:00:00 to 23:59:59 **GPS** time:
the 2003-09-14 file starts at 116769600 s, which is (date − 2000-01-01)·86400 −
43200.  That is GPS-calendar midnight, which happens 13 s (in 2003) before UTC
midnight.  :func:`gps_day_start` returns this by default (``scale="gps"``);
``scale="utc"`` gives true UTC midnight (the GPS value is larger by GPS−UTC).

References
----------
.. [1] IERS Bulletin C (leap second announcements),
   https://hpiers.obspm.fr/eoppc/bul/bulc/Leap_Second.dat
.. [2] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product
   User Handbook, JPL D-22027.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import check_option

#: (UTC date from which it applies, TAI−UTC [s]), from IERS Bulletin C (1972 onwards).
LEAP_SECONDS: tuple[tuple[str, int], ...] = (
    ("1972-01-01", 10),
    ("1972-07-01", 11),
    ("1973-01-01", 12),
    ("1974-01-01", 13),
    ("1975-01-01", 14),
    ("1976-01-01", 15),
    ("1977-01-01", 16),
    ("1978-01-01", 17),
    ("1979-01-01", 18),
    ("1980-01-01", 19),
    ("1981-07-01", 20),
    ("1982-07-01", 21),
    ("1983-07-01", 22),
    ("1985-07-01", 23),
    ("1988-01-01", 24),
    ("1990-01-01", 25),
    ("1991-01-01", 26),
    ("1992-07-01", 27),
    ("1993-07-01", 28),
    ("1994-07-01", 29),
    ("1996-01-01", 30),
    ("1997-07-01", 31),
    ("1999-01-01", 32),
    ("2006-01-01", 33),
    ("2009-01-01", 34),
    ("2012-07-01", 35),
    ("2015-07-01", 36),
    ("2017-01-01", 37),
)

#: Last UTC day the table is known to hold: IERS Bulletin C 70 (July 2025) announced no
#: leap second at the end of December 2025, and the IERS ``Leap_Second.dat`` of that
#: bulletin expires on this date.  A conversion of a later instant warns
#: (:class:`LeapSecondTableWarning`): a leap second announced since is not in the table.
LEAP_SECONDS_VALID_UNTIL = "2026-06-28"


class LeapSecondTableWarning(UserWarning):
    """A UTC conversion beyond :data:`LEAP_SECONDS_VALID_UNTIL`."""


#: TAI − GPS [s] (constant by definition of GPS time).
TAI_MINUS_GPS = 19

#: Epoch of accal times as a naive calendar instant (GPS calendar).
EPOCH = np.datetime64("2000-01-01T12:00:00", "ns")

_NS = 1_000_000_000
_EPOCH_NS = EPOCH.astype(np.int64)
# UTC instants (ns since 1970, naive) of each table entry and GPS−UTC from then on.
_LEAP_UTC_NS = np.array([np.datetime64(d, "ns").astype(np.int64) for d, _ in LEAP_SECONDS])
_LEAP_GPS_UTC = np.array([v - TAI_MINUS_GPS for _, v in LEAP_SECONDS], dtype=np.int64)
# The same transitions expressed in accal GPS seconds.
_LEAP_GPS_S = (_LEAP_UTC_NS - _EPOCH_NS) // _NS + _LEAP_GPS_UTC
#: First GPS second the table converts (1972-01-01 UTC) [s, accal GPS seconds].
GPS_TABLE_START = float(_LEAP_GPS_S[0])
# end of the table's validity (UTC ns since 1970; the day after the last valid day)
_VALID_UNTIL_NS = (np.datetime64(LEAP_SECONDS_VALID_UNTIL, "ns") + np.timedelta64(1, "D")).astype(
    np.int64
)


def _warn_past_table(utc_ns: NDArray[np.int64]) -> None:
    """Warn when an instant lies after :data:`LEAP_SECONDS_VALID_UNTIL`."""
    if utc_ns.size and int(utc_ns.max()) >= _VALID_UNTIL_NS:
        last = np.datetime64(int(utc_ns.max()), "ns").astype("datetime64[s]")
        warnings.warn(
            f"UTC {last} is after {LEAP_SECONDS_VALID_UNTIL}, the last day of accal's "
            "leap-second table (IERS Bulletin C 70): a leap second announced since is "
            "not applied (GPS-UTC taken as 18 s); update accal",
            LeapSecondTableWarning,
            stacklevel=3,
        )


def _as_datetime_ns(values: Any) -> NDArray[np.datetime64]:
    arr = np.asarray(values)
    if arr.dtype.kind in "USO":
        import pandas as pd

        flat = pd.to_datetime(arr.ravel(), format="ISO8601", utc=True)
        arr = flat.tz_convert(None).to_numpy(dtype="datetime64[ns]").reshape(arr.shape)
    elif arr.dtype.kind != "M":
        raise TypeError(f"expected datetime64 values or ISO-8601 strings, got dtype {arr.dtype}")
    return arr.astype("datetime64[ns]")


def gps_minus_utc(utc: ArrayLike) -> NDArray[np.int64]:
    """Return GPS−UTC at the given UTC instants.

    Parameters
    ----------
    utc : array_like of datetime64 or ISO-8601 str
        UTC instants (1972-01-01 or later).

    Returns
    -------
    ndarray of int64
        GPS−UTC [s] (13 in 2003, 18 since 2017-01-01).

    Raises
    ------
    ValueError
        For instants before 1972-01-01 or NaT.
    """
    ns = _as_datetime_ns(utc).astype(np.int64)
    return _gps_minus_utc_ns(ns)


def _gps_minus_utc_ns(ns: NDArray[np.int64]) -> NDArray[np.int64]:
    if np.any(ns == np.iinfo(np.int64).min):
        raise ValueError("time contains NaT")
    idx = np.searchsorted(_LEAP_UTC_NS, ns, side="right") - 1
    if np.any(idx < 0):
        raise ValueError("UTC before 1972-01-01 is not supported (no leap-second table)")
    return _LEAP_GPS_UTC[idx]


def utc_to_gps(utc: ArrayLike) -> NDArray[np.float64]:
    """Convert UTC instants to GPS seconds since 2000-01-01 12:00:00 GPS.

    Parameters
    ----------
    utc : array_like of datetime64 or ISO-8601 str
        UTC instants; strings may carry a ``Z`` or numeric offset.

    Returns
    -------
    ndarray of float64
        GPS seconds [s], same shape as ``utc``.

    Notes
    -----
    ``gps = (utc − 2000-01-01T12:00:00) + (GPS−UTC)(utc)`` where the first term is
    the naive calendar difference.  The result is exact to the nanosecond before
    the conversion to float64 (≈ 0.1 µs resolution in 2024).  Instants after
    :data:`LEAP_SECONDS_VALID_UNTIL` warn (:class:`LeapSecondTableWarning`).
    """
    ns = _as_datetime_ns(utc).astype(np.int64)
    offset = _gps_minus_utc_ns(ns)
    _warn_past_table(ns)
    d = ns - _EPOCH_NS
    whole, frac = np.divmod(d, _NS)
    return (whole + offset).astype(np.float64) + frac / _NS


def gps_to_utc(seconds: ArrayLike) -> NDArray[np.datetime64]:
    """Convert GPS seconds since 2000-01-01 12:00:00 GPS to UTC.

    Parameters
    ----------
    seconds : array_like of float
        GPS seconds [s].

    Returns
    -------
    ndarray of datetime64[ns]
        UTC instants (naive).  An inserted leap second (23:59:60) cannot be
        represented by datetime64 and maps onto the following 00:00:00.

    Raises
    ------
    ValueError
        For non-finite input or instants before 1972-01-01.

    Warns
    -----
    LeapSecondTableWarning
        For instants after :data:`LEAP_SECONDS_VALID_UNTIL`.
    """
    g = np.asarray(seconds, dtype=np.float64)
    if not np.all(np.isfinite(g)):
        raise ValueError("GPS seconds must be finite")
    whole = np.floor(g)
    frac_ns = np.round((g - whole) * _NS).astype(np.int64)
    whole = whole.astype(np.int64)
    idx = np.searchsorted(_LEAP_GPS_S, whole, side="right") - 1
    if np.any(idx < 0):
        raise ValueError("GPS time before 1972-01-01 is not supported (no leap-second table)")
    ns = (whole - _LEAP_GPS_UTC[idx]) * _NS + frac_ns + _EPOCH_NS
    _warn_past_table(ns)
    return ns.astype("datetime64[ns]")


def gps_day_start(date: str | np.datetime64, *, scale: str = "gps") -> float:
    """Return the GPS seconds at the start of a calendar day.

    Parameters
    ----------
    date : str or datetime64
        The day, e.g. ``"2003-09-14"``.
    scale : {"gps", "utc"}
        ``"gps"`` (default): midnight of the GPS calendar, the boundary of GRACE /
        GRACE-FO daily files, ``(date − 2000-01-01)·86400 − 43200``
        (2003-09-14 → 116769600, 2005-01-01 → 157809600).  ``"utc"``: UTC midnight,
        larger by GPS−UTC (2003-09-14 → 116769613).

    Returns
    -------
    float
        GPS seconds [s].
    """
    check_option("scale", scale, ("gps", "utc"))
    day = np.datetime64(date, "D")
    if scale == "utc":
        return float(utc_to_gps(day.astype("datetime64[ns]")))
    days = (day - np.datetime64("2000-01-01", "D")).astype(np.int64)
    return float(days * 86400 - 43200)


def gps_to_date(seconds: float, *, scale: str = "gps") -> str:
    """Return the calendar date ``'YYYY-MM-DD'`` containing a GPS time.

    Parameters
    ----------
    seconds : float
        GPS seconds [s].
    scale : {"gps", "utc"}
        Calendar to use; ``"gps"`` (default) is the inverse of
        :func:`gps_day_start` and names GRACE daily files.

    Returns
    -------
    str
        The date.
    """
    check_option("scale", scale, ("gps", "utc"))
    if scale == "utc":
        return str(gps_to_utc(seconds).astype("datetime64[D]"))
    days = int(np.floor((float(seconds) + 43200.0) / 86400.0))
    return str(np.datetime64("2000-01-01", "D") + np.timedelta64(days, "D"))


def gps_to_gps_calendar(seconds: ArrayLike) -> NDArray[np.datetime64]:
    """Return GPS seconds as naive GPS-calendar instants (no leap seconds).

    Parameters
    ----------
    seconds : array_like of float
        GPS seconds [s].

    Returns
    -------
    ndarray of datetime64[ns]
        ``2000-01-01T12:00:00 + seconds`` (as printed in GRACE headers).
    """
    g = np.asarray(seconds, dtype=np.float64)
    whole = np.floor(g)
    ns = whole.astype(np.int64) * _NS + np.round((g - whole) * _NS).astype(np.int64)
    return (ns + _EPOCH_NS).astype("datetime64[ns]")


def nominal_step(steps: NDArray[np.float64]) -> float:
    """Nominal sampling step [s]: the median of the steps between epochs.

    Parameters
    ----------
    steps : ndarray of float64
        ``np.diff(time)`` [s].

    Returns
    -------
    float
        The median step; NaN for no steps.  A uniform grid (every step equal,
        the usual case) returns the common step without computing the median.
    """
    if steps.size == 0:
        return float("nan")
    if steps[0] == steps[-1] and steps.min() == steps.max():
        return float(steps[0])
    return float(np.median(steps))
