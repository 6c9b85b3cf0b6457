"""Reader of GRACE / GRACE-FO Level-1B accelerometer files (ACC1B, ACT1B).

The format is described in :mod:`accal.io.grace.spec`; headers are parsed by
:mod:`accal.io.grace.header`, records by :mod:`accal.io.grace.ascii` and
:mod:`accal.io.grace.binary`, and checked by :mod:`accal.io.grace.checks`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accal.errors import ValidationError
from accal.io.common import tidy
from accal.io.grace.ascii import _parse_ascii
from accal.io.grace.binary import _parse_binary
from accal.io.grace.checks import _check_ids, _name_letter, check_header_span
from accal.io.grace.header import (
    _interpret_grace,
    _interpret_gracefo,
    read_l1b_bytes,
    split_header,
)
from accal.io.grace.spec import AUX_COLUMNS, COLUMN_UNITS, DEFAULT_INVALID_BITS, SATELLITES
from accal.series import UNITS, AccSeries, ReadReport


def read_grace_acc1b(path: str | Path, *, invalid_bits: int = DEFAULT_INVALID_BITS) -> AccSeries:
    """Read a GRACE or GRACE-FO Level-1B accelerometer file (ACC1B / ACT1B).

    Parameters
    ----------
    path : str or Path
        ASCII (GRACE RL00-RL03, GRACE-FO RL04) or GRACE binary file, optionally gzipped.
    invalid_bits : int, optional
        ``qualflg`` bits that make a sample invalid; default
        :data:`DEFAULT_INVALID_BITS` (bits 0 and 2).

    Returns
    -------
    AccSeries
        ``time`` [s, GPS since 2000-01-01 12:00:00], ``acc`` = ``lin_accl_x/y/z``
        [m/s²], ``quality`` = ``qualflg`` (bit 0 = rightmost character),
        ``aux`` = ``ang_accl_x/y/z`` [rad/s²] and ``acl_x/y/z_res`` [m/s²],
        header in ``meta["grace"]`` or ``meta["gracefo"]``, findings in ``report``.

    Raises
    ------
    FormatError
        The file is missing, unreadable, a directory, empty, corrupt or not a valid
        L1B accelerometer file (``.line`` is the 1-based line where known).
    UnsupportedFormatError
        A recognised L1B file of another product (e.g. AHK1B).
    accal.errors.ValidationError
        ``invalid_bits`` is not an 8-bit mask.

    Notes
    -----
    Duplicated epochs are dropped (first kept), out-of-order records sorted, gaps
    counted; a record count different from the header's is a warning.  All of this
    is reported in :attr:`AccSeries.report`.  Epochs outside 1980-2100
    (:data:`TIME_RANGE`), non-finite values and malformed records are errors.
    A leading UTF-8 byte-order mark is skipped.  A last record without its final
    newline is read when it is complete (all 12 fields, ending with the
    fixed-width 8-character qualflg), else it is a truncated last line.
    """
    if isinstance(invalid_bits, bool) or not isinstance(invalid_bits, int | np.integer):
        raise ValidationError(f"invalid_bits must be an integer bit mask, got {invalid_bits!r}")
    if not 0 <= invalid_bits <= 0xFF:
        raise ValidationError(
            f"invalid_bits must be an 8-bit qualflg mask (0-255), got {invalid_bits}"
        )
    path = Path(path)
    raw = read_l1b_bytes(path)
    flavour, header, data_start, first_line = split_header(raw, path)
    info = (_interpret_gracefo if flavour == "gracefo" else _interpret_grace)(header, path)
    cols = (
        _parse_binary(raw[data_start:], path)
        if info["binary"]
        else _parse_ascii(raw, data_start, first_line, path)
    )
    warn, letter = _check_ids(cols["GRACE_id"], info["letter"], path, cols["line_of"])
    if not letter:  # no platform in the header and no record: the file name
        letter = _name_letter(path)
        warn.append(f"the header names no satellite; the file name's {letter!r} is used")
    warn = [*cols.get("warnings", ()), *warn]
    time = cols["gps_time"]
    warn += check_header_span(time, info.get("span"), path, cols["line_of"])
    acc = cols["acc"]
    arrays = {"acc": acc, "quality": cols["qualflg"], **{c: cols[c] for c in AUX_COLUMNS}}
    t = tidy(time, arrays)
    quality = t.arrays["quality"].astype(np.uint32)
    valid = (quality & np.uint32(invalid_bits)) == 0
    n_header = info["n_header"]
    if n_header is None:  # said, as a missing first/last observation is (issue 23)
        warn.append(
            "the header gives no NUMBER OF DATA RECORDS: a truncated or padded file is "
            "not detected by its record count"
        )
    elif n_header != t.report["n_rows"]:
        warn.append(f"header announces {n_header} data records, file has {t.report['n_rows']}")
    n_flagged = int(np.count_nonzero(~valid))
    if n_flagged:
        warn.append(f"{n_flagged} samples flagged invalid (qualflg bits {invalid_bits:#010b})")
    report = ReadReport(
        n_records_header=n_header,
        n_flagged=n_flagged,
        warnings=tuple(warn + t.warnings),
        **t.report,
    )
    units = dict(UNITS)
    units.update({c: COLUMN_UNITS[c] for c in AUX_COLUMNS})
    return AccSeries(
        time=t.time,
        acc=t.arrays["acc"],
        axes=("x", "y", "z"),
        valid=valid,
        quality=quality,
        aux={c: t.arrays[c] for c in AUX_COLUMNS},
        frame="SRF",
        satellite=SATELLITES[letter],
        units=units,
        meta=info["meta"],
        report=report,
    )
