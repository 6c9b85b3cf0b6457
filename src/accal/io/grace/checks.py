"""Checks of the parsed ACC1B / ACT1B records: satellite ids and the file's day.

The day is the header's first/last observation time, else the day of the L1B
file name.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError
from accal.io.common import shorten, string_at
from accal.io.grace.spec import SATELLITES
from accal.timescale import gps_to_date

_ID_LOOKUP = np.zeros(256, dtype=bool)
_ID_LOOKUP[np.frombuffer("".join(SATELLITES).encode(), np.uint8)] = True


def _check_ids(
    ids: Any, letter: str, path: Path, line_of: Callable[[int], int] | None
) -> tuple[list[str], str]:
    """Check the satellite-id column (one character per record) without pyarrow.compute.

    ``line_of`` maps a row to its file line (ASCII); None numbers binary records.
    Returns the warnings and the satellite letter to use: the records' when they
    disagree with the header's ``letter`` (every record says it, the header once).
    """
    import pyarrow as pa

    if not isinstance(ids, pa.ChunkedArray | pa.Array):
        ids = pa.array(ids)
    if isinstance(ids, pa.ChunkedArray):
        ids = ids.combine_chunks()
    n = len(ids)
    if n == 0:
        return [], letter
    if pa.types.is_large_string(ids.type):
        ids = ids.cast(pa.string())
    _, off_buf, data_buf = ids.buffers()
    offsets = np.frombuffer(off_buf, dtype=np.int32, count=n + 1, offset=4 * ids.offset)
    lengths = np.diff(offsets)
    total = int(offsets[-1])
    if total == 0:  # every id empty: no data buffer to index
        chars = np.zeros(n, dtype=np.uint8)
    else:
        starts = offsets[:-1]
        if starts[-1] >= total:  # empty ids at the end start at ``total``: clip (unused)
            starts = np.minimum(starts, total - 1)
        chars = np.frombuffer(data_buf, dtype=np.uint8, count=total)[starts]
    ok = (lengths == 1) & _ID_LOOKUP[chars]
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        where = f"record {i + 1}: " if line_of is None else ""
        raise FormatError(
            f"{where}satellite id {shorten(string_at(ids, i), 10)} is not one of A, B, C, D",
            path,
            None if line_of is None else line_of(i),
        )
    uniq = [chr(c) for c in np.flatnonzero(np.bincount(chars, minlength=256))]
    if len(uniq) > 1:
        raise FormatError(f"mixed satellite ids {uniq} in one file", path)
    if uniq and not letter:
        return [f"the header names no satellite; the records' {uniq[0]!r} is used"], uniq[0]
    if uniq and uniq[0] != letter:
        return [
            f"records carry satellite id {uniq[0]!r} but the header names {letter!r}; "
            f"the records' {uniq[0]!r} is used"
        ], uniq[0]
    return [], letter


#: How far a record may lie outside the header's first/last observation time [s].
HEADER_SPAN_TOLERANCE = 3600.0


def check_header_span(
    time: NDArray[np.float64],
    span: tuple[float, float] | None,
    path: Path,
    line_of: Callable[[int], int] | None,
) -> list[str]:
    """Raise FormatError for a record far outside the file's day.

    A day file whose header says 2003-09-14 00:00–23:59:59 cannot hold a record of
    2004: such a record is damage (a corrupted time stamp), and fitting through it
    would put a ~year-long gap into the day.  The day is the header's first/last
    observation (``span``); a header without them is checked against the day its
    L1B file name gives (``ACC1B_2003-09-14_A_02.asc``), and only if neither is
    known are the records not checked (a warning says so).  Tolerance:
    :data:`HEADER_SPAN_TOLERANCE`.  A header whose span covers no record at all (every
    record shifted by a day, or the header) is an error too: which one is right cannot be
    told (issue 23: it was a warning, and the row was dated by the records).
    """
    if time.size == 0:
        return []
    what = "the header's first/last observation"
    if span is None:
        day = _name_day(path)
        if day is None:
            return [
                "the header gives no first/last observation time and the file name no "
                "date: record times are not checked against the file's day"
            ]
        span, what = day, "the day of the file name"
    lo, hi = span[0] - HEADER_SPAN_TOLERANCE, span[1] + HEADER_SPAN_TOLERANCE
    if time.min() >= lo and time.max() <= hi:
        return []
    outside = (time < lo) | (time > hi)
    if outside.all():  # every record shifted (or the header): which is right is unknown
        off = (float(np.median(time)) - 0.5 * (span[0] + span[1])) / 86400.0
        raise FormatError(
            f"{what} {span[0]:.9g} ... {span[1]:.9g} s does not cover any record "
            f"({time.min():.9g} ... {time.max():.9g} s, {off:+.2f} days off): the file "
            "disagrees with itself on its day",
            path,
        )
    i = int(np.flatnonzero(outside)[0])
    where = f"record {i + 1}: " if line_of is None else ""
    raise FormatError(
        f"{where}gps_time {time[i]:.9g} s ({gps_to_date(float(time[i]))}) is outside "
        f"{what} {span[0]:.9g} ... {span[1]:.9g} s "
        f"(by more than {HEADER_SPAN_TOLERANCE:g} s)",
        path,
        None if line_of is None else line_of(i),
    )


def _name_letter(path: Path) -> str:
    """The satellite letter of an L1B file name; FormatError when it has none."""
    from accal.batch import name_key

    key = name_key(path)
    letter = key[0] if key else ""
    if letter not in SATELLITES:
        raise FormatError("no satellite: no platform in the header, no record, no L1B name", path)
    return letter


def _name_day(path: Path) -> tuple[float, float] | None:
    """(first, last) second of the GPS day an L1B file name gives, or None."""
    from accal.batch import name_key
    from accal.timescale import gps_day_start

    key = name_key(path)
    if key is None:
        return None
    try:
        t0 = gps_day_start(key[1])
    except ValueError:  # a name like ACC1B_2003-02-30_A_02
        return None
    return t0, t0 + 86399.0
