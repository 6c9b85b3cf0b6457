"""Parsing of the binary records of GRACE ACC1B files (big-endian, :data:`BINARY_DTYPE`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError
from accal.io.common import GPS_TIME_RANGE, check_gps_time, implausible, implausible_message
from accal.io.grace.checks import _ID_LOOKUP
from accal.io.grace.spec import BINARY_DTYPE, COLUMNS, _unit


def _parse_binary(data: bytes, path: Path) -> dict[str, Any]:
    if not data:
        raise FormatError("header but no data records", path)
    rest = len(data) % BINARY_DTYPE.itemsize
    head = data[:256]
    if head.isascii() and all(c in b"0123456789+-.eE ABCD\r\n\t" for c in head):
        raise FormatError(
            "the header says binary records (FILE FORMAT 0) but the data are text; "
            "fix the header's FILE FORMAT line (1 = ASCII)",
            path,
        )
    if rest:
        raise FormatError(
            f"truncated binary record: {len(data)} bytes is not a multiple of "
            f"{BINARY_DTYPE.itemsize}-byte records",
            path,
        )
    rec = np.frombuffer(data, dtype=BINARY_DTYPE)
    if _little_endian(rec["gps_time"][:10]):
        raise FormatError(
            "the binary records are little-endian (their gps_time reads "
            f"{float(rec['gps_time'][:1].byteswap()[0]):.0f} s, ... only byte-swapped); "
            "GRACE binary L1B is big-endian",
            path,
        )
    out: dict[str, Any] = {"gps_time": rec["gps_time"].astype(np.float64)}
    check_gps_time(out["gps_time"], path)
    for name in COLUMNS[2:11]:
        arr = rec[name].astype(np.float64)
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise FormatError(f"{name}: non-finite value in binary record {bad[0] + 1}", path)
        big = implausible(arr)
        if big.size:
            i = int(big[0])
            msg = implausible_message(name, float(arr[i]), _unit(name))
            raise FormatError(f"record {i + 1}: {msg}", path)
        out[name] = arr
    out["GRACE_id"] = np.char.decode(rec["GRACE_id"], "latin-1")
    out["qualflg"] = rec["qualflg"].astype(np.uint32)
    out["line_of"] = None
    out["acc"] = np.column_stack([out["lin_accl_x"], out["lin_accl_y"], out["lin_accl_z"]])
    return out


def _binary_records(data: bytes) -> bool:
    """Whether ``data`` look like binary L1B records (whole 78-byte records, the first
    with a GPS time and a satellite letter where binary records have them)."""
    size = BINARY_DTYPE.itemsize
    if len(data) < size or len(data) % size or data[:size].isascii():
        return False
    t = int.from_bytes(data[:4], "big")
    lo, hi = GPS_TIME_RANGE
    return lo <= t <= hi and bool(_ID_LOOKUP[data[4]])


def _little_endian(t: NDArray) -> bool:
    """Whether the first record times ``t`` (read big-endian) were written little-endian.

    Byte-swapped they are GPS times, and either read as given they are not, or
    they step by far more than swapped (a 1 s step read the wrong way is 2²⁴ s).
    """
    if t.size == 0:
        return False
    lo, hi = GPS_TIME_RANGE
    orig, swapped = t.astype(np.float64), t.byteswap().astype(np.float64)
    if not np.all((swapped >= lo) & (swapped <= hi)):
        return False
    if not np.all((orig >= lo) & (orig <= hi)):
        return True
    return t.size > 1 and np.median(np.abs(np.diff(swapped))) < np.median(np.abs(np.diff(orig)))
