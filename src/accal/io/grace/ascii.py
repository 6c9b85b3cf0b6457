"""Parsing of the ASCII records of ACC1B / ACT1B files (pyarrow, with a strict error scan).

Records are read by pyarrow in JPL's layout (one space between fields, two
before ``qualflg``), else with any run of blanks as the separator (a warning);
on failure a Python scan names the bad line and the fault.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError
from accal.io.common import (
    MAX_ABS_ACCELERATION,
    arrow_to_numpy,
    bits_from_strings,
    check_gps_time,
    csv_read_options,
    implausible_message,
    one_line,
    row_to_line,
    shorten,
)
from accal.io.grace.binary import _binary_records
from accal.io.grace.spec import COLUMNS, DTYPES, _unit

#: A number as pyarrow parses one in a record (Python's float() also takes forms such
#: as "1_0" that pyarrow refuses); used on the error path to name the bad field.
_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def _field_names(n_fields: int) -> tuple[str, ...]:
    """Name of each space-separated token of a record (``""``: the blank before qualflg)."""
    return COLUMNS if n_fields == len(COLUMNS) else (*COLUMNS[:11], "", "qualflg")


def _locate_bad_line(
    data: bytes, first_line: int, n_fields: int, path: Path, reason: str = ""
) -> FormatError:
    """Scan the data rows in Python to say which line is bad and why (error path only).

    ``reason`` (pyarrow's message) is added to the fallback message when no line
    is found.
    """
    names = _field_names(n_fields)
    lines = data.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    for i, bline in enumerate(lines):
        lineno = first_line + i
        try:
            line = bline.decode("ascii")
        except UnicodeDecodeError:
            return FormatError("binary data where a text record was expected", path, lineno)
        line = line.rstrip("\r")
        if not line:
            continue
        if not line.strip():
            return FormatError("blank line of spaces or tabs among the data records", path, lineno)
        if any(ord(c) < 32 and c != "\t" for c in line):
            return FormatError("binary data where a text record was expected", path, lineno)
        if "\t" in line:
            return FormatError(
                "tab character inside a record (fields are space-separated)", path, lineno
            )
        tokens = line.split(" ")
        if len(tokens) != n_fields:
            ntok = len(line.split())
            if ntok != len(COLUMNS):
                return FormatError(
                    f"wrong number of columns: expected {len(COLUMNS)}, got {ntok}", path, lineno
                )
            return FormatError(
                "irregular spacing: expected one space between fields"
                + (" and two before qualflg, as on the first record" if n_fields > 12 else ""),
                path,
                lineno,
            )
        for name, tok in zip(names, tokens, strict=True):
            if not name:  # the blank before qualflg
                if tok:
                    return FormatError(
                        "irregular spacing: expected two spaces before qualflg, "
                        "as on the first record",
                        path,
                        lineno,
                    )
                continue
            if not tok:
                return FormatError(
                    f"{name}: empty field (two spaces where a value was expected)", path, lineno
                )
            if DTYPES[name] != "float64":
                continue
            try:
                v = float(tok)
            except ValueError:
                return FormatError(f"{name}: not a number: {shorten(tok)}", path, lineno)
            if not np.isfinite(v):
                return FormatError(f"{name}: non-finite value {shorten(tok)}", path, lineno)
            if not _NUMBER_RE.fullmatch(tok):
                return FormatError(f"{name}: not a number: {shorten(tok)}", path, lineno)
            if name != "gps_time" and abs(v) > MAX_ABS_ACCELERATION:
                return FormatError(implausible_message(name, v, _unit(name)), path, lineno)
    why = f" ({one_line(reason, 120)})" if reason else ""
    return FormatError(f"cannot parse data records{why}", path)


def _check_last_line(raw: bytes, start: int, first_line: int, path: Path) -> None:
    """Accept a last record without its newline only if it is complete (else FormatError).

    ``raw[start:]`` are the records, ``first_line`` the file line of the first.
    The record is complete when it has all fields and ends with the fixed-width
    8-character 0/1 ``qualflg``: a cut anywhere in the line leaves fewer fields or
    a shorter last field.  Only the last line is looked at (and copied).
    """
    last = raw[raw.rfind(b"\n", start) + 1 :].rstrip(b"\r")
    fields = last.split()
    flag = fields[-1] if fields else b""
    if not (
        len(fields) == len(COLUMNS)
        and last.endswith(flag)
        and len(flag) == 8
        and not flag.strip(b"01")
    ):
        raise FormatError(
            "truncated last line (no newline at end of file)",
            path,
            first_line + raw.count(b"\n", start),
        )


_NON_SPACE = re.compile(rb"\S")
_LIN_ACCL = {"lin_accl_x": 0, "lin_accl_y": 1, "lin_accl_z": 2}


#: Runs of blanks, and a blank at either end of a line (records in another layout).
_BLANKS = re.compile(rb"[ \t]+")
_EDGE_BLANK = re.compile(rb"(?m)^ | (?=\r?$)")
_BLANK_LINE = re.compile(rb"(?m)^[ \t]+\r?$")

#: Warning for records read with any blanks as separators.
LOOSE_LAYOUT = (
    "records are not in the L1B layout (one space between fields, two before qualflg): "
    "read with any run of blanks as the separator"
)


def _respaced(data: bytes) -> bytes:
    """``data`` with every run of blanks one space, and none at either end of a line."""
    return _EDGE_BLANK.sub(b"", _BLANKS.sub(b" ", data))


def _loose_table(data: bytes, convert: Any, parse: Any, read: Any) -> Any | None:
    """The records ``data`` parsed with any run of blanks as the separator, or None.

    JPL writes one space between fields and two before ``qualflg``; a file re-written by
    other tools may pad columns, end records with a blank or use tabs (QA: a trailing
    blank, right-aligned columns and a leading blank were refused as "irregular
    spacing").  The blanks are collapsed (lines stay where they are, so line numbers
    hold) and the 12 fields parsed again.  None when that fails too, or when a line
    holds only blanks: the strict scan then names the line and the fault (an empty
    field, a missing column, ...).
    """
    import pyarrow as pa

    if _BLANK_LINE.search(data):
        return None
    try:
        return read(pa.py_buffer(_respaced(data)), parse_options=parse, convert_options=convert)
    except (pa.ArrowException, ValueError):
        return None


def _parse_ascii(raw: bytes, start: int, first_line: int, path: Path) -> dict[str, Any]:
    """Parse the ASCII records ``raw[start:]`` (``first_line``: file line of the first).

    The records are handed to pyarrow as a slice of ``raw`` (a day file is ~9 MB:
    no copy); the error paths, which need the records as bytes, slice them.  Records
    in another layout than JPL's spacing are read by :func:`_loose_table`, with a
    warning (``out["warnings"]``).
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    if _NON_SPACE.search(raw, start) is None:
        raise FormatError("header but no data records", path, first_line)
    if _binary_records(raw[start:]):
        raise FormatError(
            "the header says ASCII records (FILE FORMAT 1) but the data are binary; "
            "fix the header's FILE FORMAT line (0 = binary)",
            path,
            first_line,
        )
    if not raw.endswith(b"\n"):
        _check_last_line(raw, start, first_line, path)
    nl = raw.find(b"\n", start)
    first = raw[start : nl if nl >= 0 else len(raw)].rstrip(b"\r")
    double = b"  " in first
    names = list(COLUMNS[:11]) + (["_blank", "qualflg"] if double else ["qualflg"])
    types = {n: pa.float64() for n in COLUMNS[2:11]}
    types.update(gps_time=pa.float64(), GRACE_id=pa.string(), qualflg=pa.string())
    if double:
        types["_blank"] = pa.null()
    parse = pacsv.ParseOptions(
        delimiter=" ", quote_char=False, double_quote=False, ignore_empty_lines=True
    )

    def convert(names: list[str]) -> Any:
        kinds = {n: pa.null() if n == "_blank" else types[n] for n in names}
        return pacsv.ConvertOptions(
            column_types=kinds,
            null_values=[""],
            strings_can_be_null=False,
            quoted_strings_can_be_null=False,
            include_columns=[n for n in names if n != "_blank"],
            # ids and flags are checked byte by byte below (A-D, 0/1): no UTF-8 pass
            check_utf8=False,
        )

    notes: list[str] = []
    try:
        table = pacsv.read_csv(
            pa.py_buffer(raw).slice(start),
            read_options=csv_read_options(column_names=names, block_size=1 << 22),
            parse_options=parse,
            convert_options=convert(names),
        )
    except (pa.ArrowException, ValueError) as exc:
        single = [*COLUMNS[:11], "qualflg"]
        read = functools.partial(
            pacsv.read_csv, read_options=csv_read_options(column_names=single, block_size=1 << 22)
        )
        table = _loose_table(raw[start:], convert(single), parse, read)
        if table is None:
            err = _locate_bad_line(raw[start:], first_line, len(names), path, str(exc))
            if "irregular spacing" in str(err) or "tab character" in str(err):
                # not the fault (the loose parse allows it): find the fault in any spacing
                err = _locate_bad_line(_respaced(raw[start:]), first_line, 12, path, str(exc))
            raise err from None
        names = single
        notes.append(LOOSE_LAYOUT)
    if table.num_rows == 0:  # only what pyarrow skips (e.g. a byte-order mark, blank lines)
        raise FormatError("header but no data records", path, first_line)
    out: dict[str, Any] = {}
    # a bad value is looked for in the records as parsed: with the blanks collapsed when
    # the loose layout was read (QA: a 'nan' on a record re-written with single spaces
    # was reported as "irregular spacing" on the first record, line 31, not line 50000)
    rows = _respaced(raw[start:]) if LOOSE_LAYOUT in notes else raw[start:]
    # the three linear accelerations go straight into the (n, 3) array of the series
    acc = np.empty((table.num_rows, 3))
    for name in COLUMNS[:11]:
        if name == "GRACE_id":
            continue
        col = table.column(name)
        if col.null_count:
            raise _locate_bad_line(rows, first_line, len(names), path)
        k = _LIN_ACCL.get(name)
        arr = arrow_to_numpy(col, None if k is None else acc[:, k])
        if name == "gps_time":
            ok = np.isfinite(arr).all()  # its range is checked below, with the line
        else:  # finite and plausible; NaN makes min/max NaN, which fails too
            ok = arr.min() >= -MAX_ABS_ACCELERATION and arr.max() <= MAX_ABS_ACCELERATION
        if not ok:
            raise _locate_bad_line(rows, first_line, len(names), path)
        out[name] = arr
    out["acc"] = acc
    line_of = row_to_line(raw, first_line, text_line=1)
    check_gps_time(out["gps_time"], path, line_of)
    out["GRACE_id"] = table.column("GRACE_id")
    out["qualflg"] = bits_from_strings(table.column("qualflg"), path, first_line, line_of=line_of)
    out["line_of"] = line_of
    out["warnings"] = notes
    return out
