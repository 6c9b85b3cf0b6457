"""Reader and writer for GRACE / GRACE-FO Level-1B accelerometer files (ACC1B, ACT1B).

The module constants below are the file specification.  Supported variants:

* GRACE RL00–RL02 ASCII: fixed-width ``KEY : value`` header ending with the line
  ``END OF HEADER`` (RL03: ``# END OF HEADER``), then 12 space-separated fields per
  record, with two spaces before ``qualflg``.  Header kept in ``meta["grace"]``.
* GRACE binary (``FILE FORMAT 0=BINARY 1=ASCII : 0``): the same header, then
  big-endian 78-byte records (:data:`BINARY_DTYPE`).
* GRACE-FO RL04 ASCII: YAML header ending with ``# End of YAML header``, kept in
  ``meta["gracefo"]`` with every scalar as the string written in the file.

All may be gzip-compressed (detected by magic bytes).  Times stay GPS seconds
since 2000-01-01 12:00:00 GPS; accelerations are in m/s².

References
----------
.. [1] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product User
   Handbook, JPL D-22027.
.. [2] Wen, H. Y., Kruizinga, G., Paik, M., Landerer, F., Bertiger, W., Sakumura, C.,
   Bandikova, T., Mccullough, C. (2019). Gravity Recovery and Climate Experiment
   Follow-On (GRACE-FO) Level-1 Data Product User Handbook, JPL D-56935.
"""

from __future__ import annotations

import functools
import gzip
import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError, UnsupportedFormatError, ValidationError, check_option
from accal.io._common import (
    GPS_TIME_RANGE,
    MAX_ABS_ACCELERATION,
    _short,
    arrow_to_numpy,
    bits_from_strings,
    check_binary,
    check_gps_time,
    csv_read_options,
    implausible,
    implausible_message,
    one_line,
    peek,
    read_bytes,
    read_head,
    row_to_line,
    string_at,
    tidy,
)
from accal.io.writers import atomic_path
from accal.series import UNITS, AccSeries, ReadReport
from accal.timescale import gps_to_date, gps_to_gps_calendar

#: Data columns of ACC1B / ACT1B, in file order (GRACE-FO names the id ``GRACEFO_id``).
COLUMNS = (
    "gps_time",
    "GRACE_id",
    "lin_accl_x",
    "lin_accl_y",
    "lin_accl_z",
    "ang_accl_x",
    "ang_accl_y",
    "ang_accl_z",
    "acl_x_res",
    "acl_y_res",
    "acl_z_res",
    "qualflg",
)
GRACEFO_COLUMNS = ("gps_time", "GRACEFO_id", *COLUMNS[2:])

#: Column types as parsed (qualflg: 8 characters of 0/1, bit 0 = rightmost).
DTYPES = {
    "gps_time": "float64",
    "GRACE_id": "str",
    **{c: "float64" for c in COLUMNS[2:11]},
    "qualflg": "str",
}

#: Units of the numeric columns.
COLUMN_UNITS = {
    "gps_time": UNITS["time"],
    "lin_accl_x": "m/s^2",
    "lin_accl_y": "m/s^2",
    "lin_accl_z": "m/s^2",
    "ang_accl_x": "rad/s^2",
    "ang_accl_y": "rad/s^2",
    "ang_accl_z": "rad/s^2",
    "acl_x_res": "m/s^2",
    "acl_y_res": "m/s^2",
    "acl_z_res": "m/s^2",
}


def _unit(name: str) -> str:
    """A column's unit as messages write it (``m/s²``)."""
    return COLUMN_UNITS.get(name, "").replace("^2", "²")


#: Columns carried in ``AccSeries.aux``.
AUX_COLUMNS = COLUMNS[5:11]

#: Header end markers (a whole line, trailing blanks allowed).
HEADER_END = {"grace": ("END OF HEADER", "# END OF HEADER"), "gracefo": ("# End of YAML header",)}

#: Meaning of the ACC1B / ACT1B ``qualflg`` bits (GRACE-FO RL04 YAML header of the real
#: ACT1B files; the GRACE L1B handbook [1] lists the same bits for ACC1B).
QUALFLG_BITS = {
    0: "Vp (proof mass voltage) out of nominal range",
    1: "not defined",
    2: "at least one of acl_x_res, acl_y_res, acl_z_res is > 10 µm/s²",
    3: "extrapolated CLK1B clock offset used, data point > 5 s from CRN window centre",
    4: "extrapolated CLK1B clock offset used, data point <= 5 s from CRN window centre",
    5: "interpolated data point (gap) exists > 15 s from CRN window centre",
    6: "interpolated data point (gap) exists > 5 s and < 15 s from CRN window centre",
    7: "interpolated data point (gap) exists < 5 s from CRN window centre",
}

#: Bits of ``qualflg`` that make a sample invalid by default: 0 (proof-mass voltage out of
#: range, the instrument is not in its nominal state) and 2 (CRN-filter residual > 10 µm/s²,
#: the value is not trustworthy).  Bits 3-7 only report clock extrapolation or gap
#: interpolation somewhere in the 70-s filter window; they are common in good data (bit 5
#: is set on 32 of 60 records of the real GRACE-A 2003-09-14 file) and do not exclude.
DEFAULT_INVALID_BITS = 0b0000_0101

#: Satellite id letter -> accal satellite name.
SATELLITES = {"A": "GRACE-A", "B": "GRACE-B", "C": "GRACE-FO-C", "D": "GRACE-FO-D"}

#: Record of the binary GRACE L1B ACC1B format (big-endian, 78 bytes).
BINARY_DTYPE = np.dtype(
    [("gps_time", ">u4"), ("GRACE_id", "S1")]
    + [(c, ">f8") for c in COLUMNS[2:11]]
    + [("qualflg", "u1")]
)

#: Key width of the GRACE fixed-width header (``KEY`` padded to 30, then ``: value``).
GRACE_KEY_WIDTH = 30

#: Accepted ``gps_time`` range [s since 2000-01-01 12:00:00 GPS]: from the GPS epoch
#: (1980-01-06 00:00:00) to 2100-01-01 00:00:00.  Anything outside is a corrupt time
#: (a flipped exponent, a binary field read as time), not an L1B epoch.
TIME_RANGE = GPS_TIME_RANGE

#: Deepest nesting accepted in a GRACE-FO YAML header (the real headers nest 5 deep).
YAML_MAX_DEPTH = 32

_GRACE_END_RE = re.compile(rb"^(?:# )?END OF HEADER[ \t]*\r?$", re.M)
_GRACEFO_END_RE = re.compile(rb"^# End of YAML header[ \t]*\r?$", re.M)
_GRACE_KEY_RE = re.compile(rb"^(?:# )?[A-Z][A-Za-z0-9 ()=/.\-]{3,}:")
_HEADER_SEARCH = 1 << 20
_SNIFF_BYTES = 8192


@functools.cache
def _yaml() -> tuple[Any, Any, Any]:
    """Import pyyaml lazily (only GRACE-FO files need it) and build our loader/dumper.

    The loader keeps every plain scalar as the string written in the file and
    builds nothing but ``str``, ``list`` and ``dict``: explicit tags (``!!float``,
    ``!!timestamp``, ``!!binary``, ...), aliases (``*a``, which can expand a small
    header into an enormous ``meta``), duplicated keys and nesting deeper than
    :data:`YAML_MAX_DEPTH` are YAML errors.  The dumper writes strings plain where
    YAML allows it (like the real files).
    """
    import yaml
    from yaml.composer import ComposerError
    from yaml.constructor import ConstructorError, SafeConstructor
    from yaml.events import AliasEvent

    class _StrLoader(yaml.SafeLoader):
        _depth = 0

        def compose_node(self, parent: Any, index: Any) -> Any:
            event = self.peek_event()
            if isinstance(event, AliasEvent):
                raise ComposerError(None, None, "aliases (*name) are not allowed", event.start_mark)
            if self._depth >= YAML_MAX_DEPTH:
                raise ComposerError(
                    None, None, f"nested deeper than {YAML_MAX_DEPTH} levels", event.start_mark
                )
            self._depth += 1
            try:
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            seen = set()
            for key_node, _ in node.value:
                key = getattr(key_node, "value", None)
                if isinstance(key, str):
                    if key in seen:
                        raise ConstructorError(
                            None, None, f"duplicated key {key[:40]!r}", key_node.start_mark
                        )
                    seen.add(key)
            return super().construct_mapping(node, deep=deep)

    class _StrDumper(yaml.SafeDumper):
        pass

    _StrLoader.yaml_implicit_resolvers = {}
    _StrLoader.yaml_constructors = {
        "tag:yaml.org,2002:str": SafeConstructor.construct_yaml_str,
        "tag:yaml.org,2002:seq": SafeConstructor.construct_yaml_seq,
        "tag:yaml.org,2002:map": SafeConstructor.construct_yaml_map,
        None: SafeConstructor.construct_undefined,
    }
    _StrDumper.yaml_implicit_resolvers = {}
    return yaml, _StrLoader, _StrDumper


# --------------------------------------------------------------------------- sniff


def sniff_grace_acc1b(path: str | Path) -> bool:
    """Return True if ``path`` looks like a GRACE / GRACE-FO L1B file (never raises).

    Reads at most 8 kB (decompressed); a true result does not guarantee the file
    is an ACC1B/ACT1B product or valid.
    """
    head = peek(path, _SNIFF_BYTES)
    if head.startswith(b"header:"):
        return b"num_records" in head and b"GRACE" in head
    first = head.split(b"\n", 1)[0]
    return (
        _GRACE_KEY_RE.match(first) is not None
        and b"\nSATELLITE NAME" in head
        and (b"FILE FORMAT 0=BINARY 1=ASCII" in head or b"END OF HEADER" in head)
    )


# --------------------------------------------------------------------------- header


#: Most bytes a data record of any L1B product takes, ASCII or binary (the longest
#: line of the bundled real ACC, ACT, AHK, GNV, SCA and THR samples is 346 bytes).
MAX_RECORD_BYTES = 1024
#: Below this size a file is read whatever its header announces: a wrong record
#: count stays a warning (:func:`read_grace_acc1b`), not a refusal.
L1B_SIZE_FLOOR = 64 << 20
_RECORD_COUNT_RE = re.compile(rb"(?:NUMBER OF DATA RECORDS|\bnum_records)\s*:\s*(\d{1,12})\b")


def read_l1b_bytes(path: str | Path) -> bytes:
    """The content of an L1B file, read only if its size fits the header's record count.

    A file larger than :data:`MAX_RECORD_BYTES` per record the header announces
    (and than :data:`L1B_SIZE_FLOOR`) is refused after reading its first MiB, before
    gigabytes of a wrong or padded file are read and parsed (issue 23, finding 9: a
    2 GB file reached 4.3 GB of memory and 30 s before failing).  Without a record
    count in the first MiB, :func:`accal.io._common.read_bytes` and its global
    limit decide.

    Raises
    ------
    FormatError
        As :func:`accal.io._common.read_bytes`, or the file is larger than its
        header's record count allows.
    """
    head = read_head(path, _HEADER_SEARCH)
    m = _RECORD_COUNT_RE.search(head)
    if m is None:
        return read_bytes(path)
    n = int(m.group(1))
    limit = max(m.end() + n * MAX_RECORD_BYTES + (1 << 20), L1B_SIZE_FLOOR)
    return read_bytes(
        path, limit, f"more than its header's {n:,} records can fill: padded, or not one L1B file?"
    )


def _split_header(raw: bytes, path: Path) -> tuple[str, bytes, int, int]:
    """Return (flavour, header bytes, offset of data, 1-based line of first data row)."""
    head = raw[:_HEADER_SEARCH]
    flavour = "gracefo" if head.startswith(b"header:") else "grace"
    m = (_GRACEFO_END_RE if flavour == "gracefo" else _GRACE_END_RE).search(head)
    if m is None:
        check_binary(head[:4096], path)
        want = " or ".join(repr(s) for s in HEADER_END[flavour])
        raise FormatError(f"no end-of-header marker ({want}) found", path)
    header = raw[: m.start()]
    check_binary(header, path)
    nl = raw.find(b"\n", m.end())
    data_start = len(raw) if nl < 0 else nl + 1
    first_data_line = raw[:data_start].count(b"\n") + 1
    return flavour, header, data_start, first_data_line


def _parse_grace_header(header: bytes, path: Path) -> tuple[dict[str, Any], dict[str, int]]:
    meta: dict[str, Any] = {}
    lines: dict[str, int] = {}
    for i, raw_line in enumerate(header.decode("utf-8").split("\n"), start=1):
        line = raw_line.rstrip()
        if line.startswith("#"):
            line = line[1:].lstrip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        if not sep:
            raise FormatError(f"header line is not 'KEY : value': {_short(line, 40)}", path, i)
        key, value = key.strip(), value.strip()
        if key in meta:
            prev = meta[key]
            meta[key] = [*prev, value] if isinstance(prev, list) else [prev, value]
        else:
            meta[key] = value
            lines[key] = i
    return meta, lines


def _grace_int(meta: dict, lines: dict, key: str, path: Path) -> int | None:
    if key not in meta:
        return None
    value = meta[key]
    try:
        return int(str(value).split()[0])
    except (ValueError, IndexError):
        raise FormatError(
            f"header {key!r} is not an integer: {_short(str(value), 40)}", path, lines.get(key)
        ) from None


def _record_count(meta: dict, lines: dict, path: Path) -> int | None:
    """The header's NUMBER OF DATA RECORDS (None if absent); negative is an error."""
    key = "NUMBER OF DATA RECORDS"
    n = _grace_int(meta, lines, key, path)
    if n is not None and n < 0:
        raise FormatError(f"header {key!r} is negative: {n}", path, lines.get(key))
    return n


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = _parse_grace_header(header, path)
    file_type = next((k for k in meta if k.startswith("FILE TYPE")), None)
    if file_type is not None:
        m = re.search(r"ip(\w{3}1[AB])F", file_type)
        if m and m.group(1) not in ("ACC1B", "ACT1B"):
            raise UnsupportedFormatError(
                f"file type {m.group(0)!r} is not ACC1B/ACT1B accelerometer data "
                "(housekeeping such as AHK1B is not supported)",
                path,
                lines[file_type],
            )
    letter = header_satellite(meta, lines, path)
    fmt = _grace_int(meta, lines, "FILE FORMAT 0=BINARY 1=ASCII", path)
    if fmt not in (None, 0, 1):
        raise FormatError(f"header 'FILE FORMAT' is {fmt}, expected 0 or 1", path)
    first, last = (
        _header_time(meta.get(key), key, path, lines.get(key))
        for key in ("TIME FIRST OBS(SEC PAST EPOCH)", "TIME LAST OBS(SEC PAST EPOCH)")
    )
    return {
        "meta": {"grace": meta},
        "letter": letter,
        "n_header": _record_count(meta, lines, path),
        "binary": fmt == 0,
        "columns": COLUMNS,
        "span": _span(first, last, path),
    }


def _header_time(value: Any, key: str, path: Path, line: int | None) -> float | None:
    """A header's observation time [s GPS]: None if absent, FormatError if not a time.

    GRACE headers give it as ``116769600.0 (2003-09-14 00:00:00.00)``: the first word.
    """
    if value is None:
        return None
    words = str(value).split()
    try:
        t = float(words[0]) if words else float("nan")
    except ValueError:
        t = float("nan")
    lo, hi = GPS_TIME_RANGE
    if not (np.isfinite(t) and lo <= t <= hi):
        raise FormatError(
            f"header {key!r} is not a GPS time in seconds: {_short(str(value), 40)}", path, line
        )
    return t


def _span(first: float | None, last: float | None, path: Path) -> tuple[float, float] | None:
    """The header's (first, last) observation times, both or None; last before first is wrong."""
    if first is None or last is None:
        return None
    if last < first:
        raise FormatError(
            f"header's last observation {last:.9g} s is before its first {first:.9g} s", path
        )
    return first, last


def load_yaml_header(header: bytes, path: Path) -> dict[str, Any]:
    """Parse a GRACE-FO YAML header into its ``header:`` mapping (scalars kept as str).

    Raises
    ------
    FormatError
        Invalid YAML (with its line), a construct refused by the loader of
        :func:`_yaml`, or no ``header:`` mapping.
    """
    yaml, str_loader, _ = _yaml()
    try:
        doc = yaml.load(header.decode("utf-8"), Loader=str_loader)  # noqa: S506 (safe loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise FormatError(f"YAML header: {problem}", path, line) from None
    except RecursionError:  # the loader caps nesting; belt and braces
        raise FormatError("YAML header: nested too deeply", path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("header"), dict):
        raise FormatError("YAML header has no 'header:' mapping", path, 1)
    return doc["header"]


def _interpret_gracefo(header: bytes, path: Path) -> dict[str, Any]:
    hdr = load_yaml_header(header, path)
    dims = hdr.get("dimensions")
    try:
        n_header = int(dims["num_records"]) if isinstance(dims, dict) else None
    except (KeyError, TypeError, ValueError):
        n_header = None
    if n_header is None:
        raise FormatError("YAML header: 'dimensions: num_records' missing or not an integer", path)
    variables = hdr.get("variables") or []
    if not isinstance(variables, list) or not all(isinstance(v, dict) and v for v in variables):
        raise FormatError("YAML header: 'variables' is not a list of mappings", path)
    names = tuple(next(iter(v)) for v in variables)
    if names and names != GRACEFO_COLUMNS:
        raise UnsupportedFormatError(
            f"columns {_short(' '.join(names[:6]), 80)} ... are not ACC1B/ACT1B columns "
            "(only accelerometer data are supported)",
            path,
        )
    attrs = hdr.get("global_attributes") or {}
    if not isinstance(attrs, dict):
        raise FormatError("YAML header: 'global_attributes' is not a mapping", path)
    platform = attrs.get("platform", "")
    letter = platform.split()[-1] if isinstance(platform, str) and platform.split() else ""
    if platform is None or (isinstance(platform, str) and not platform.strip()):
        letter = ""  # no platform: the records' GRACEFO_id, else the file name (issue 23)
    elif letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {_short(platform, 40)}, expected 'GRACE C' or 'GRACE D'",
            path,
        )
    nsa = hdr.get("non-standard_attributes") or {}
    if not isinstance(nsa, dict):
        raise FormatError("YAML header: 'non-standard_attributes' is not a mapping", path)
    first, last = (
        _header_time(nsa.get(key), key, path, _yaml_line(header, key))
        for key in ("start_time_epoch_secs", "stop_time_epoch_secs")
    )
    return {
        "meta": {"gracefo": hdr},
        "letter": letter,
        "n_header": n_header,
        "binary": False,
        "columns": GRACEFO_COLUMNS,
        "span": _span(first, last, path),
    }


def _yaml_line(header: bytes, key: str) -> int | None:
    """1-based line of the header where ``key:`` first appears (for messages)."""
    i = header.find(key.encode() + b":")
    return None if i < 0 else header.count(b"\n", 0, i) + 1


# --------------------------------------------------------------------------- data


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
                return FormatError(f"{name}: not a number: {_short(tok)}", path, lineno)
            if not np.isfinite(v):
                return FormatError(f"{name}: non-finite value {_short(tok)}", path, lineno)
            if not _NUMBER_RE.fullmatch(tok):
                return FormatError(f"{name}: not a number: {_short(tok)}", path, lineno)
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
    # the three linear accelerations go straight into the (n, 3) array of the series
    acc = np.empty((table.num_rows, 3))
    for name in COLUMNS[:11]:
        if name == "GRACE_id":
            continue
        col = table.column(name)
        if col.null_count:
            raise _locate_bad_line(raw[start:], first_line, len(names), path)
        k = _LIN_ACCL.get(name)
        arr = arrow_to_numpy(col, None if k is None else acc[:, k])
        if name == "gps_time":
            ok = np.isfinite(arr).all()  # its range is checked below, with the line
        else:  # finite and plausible; NaN makes min/max NaN, which fails too
            ok = arr.min() >= -MAX_ABS_ACCELERATION and arr.max() <= MAX_ABS_ACCELERATION
        if not ok:
            raise _locate_bad_line(raw[start:], first_line, len(names), path)
        out[name] = arr
    out["acc"] = acc
    line_of = row_to_line(raw, first_line, text_line=1)
    check_gps_time(out["gps_time"], path, line_of)
    out["GRACE_id"] = table.column("GRACE_id")
    out["qualflg"] = bits_from_strings(table.column("qualflg"), path, first_line, line_of=line_of)
    out["line_of"] = line_of
    out["warnings"] = notes
    return out


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
            f"{where}satellite id {_short(string_at(ids, i), 10)} is not one of A, B, C, D",
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


def _check_header_span(
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


# --------------------------------------------------------------------------- read


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
    flavour, header, data_start, first_line = _split_header(raw, path)
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
    warn += _check_header_span(time, info.get("span"), path, cols["line_of"])
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


# --------------------------------------------------------------------------- write


def _calendar(t: float) -> str:
    s = str(gps_to_gps_calendar([t])[0])  # 'YYYY-MM-DDTHH:MM:SS.fffffffff'
    date, _, clock = s.partition("T")
    return f"{date} {clock[:11]}"


def header_satellite(meta: dict[str, Any], lines: dict[str, int], path: Path) -> str:
    """The satellite letter (A-D) of a GRACE-style header's ``SATELLITE NAME``.

    Raises
    ------
    FormatError
        Naming the file and header line when the name is not 'GRACE A' ... 'GRACE D'.
    """
    sat = str(meta.get("SATELLITE NAME", ""))
    letter = sat.split()[-1] if sat.split() else ""
    if letter not in SATELLITES:
        raise FormatError(
            f"header 'SATELLITE NAME' is {_short(sat, 40)}, expected 'GRACE A' ... 'GRACE D'",
            path,
            lines.get("SATELLITE NAME"),
        )
    return letter


def refuse_binary(meta: dict[str, Any], lines: dict[str, int], path: Path, product: str) -> None:
    """UnsupportedFormatError for a binary (``FILE FORMAT 0``) file of an ASCII-only reader."""
    if _grace_int(meta, lines, "FILE FORMAT 0=BINARY 1=ASCII", path) == 0:
        raise UnsupportedFormatError(
            f"binary {product} files are not supported (use the ASCII product)",
            path,
            lines.get("FILE FORMAT 0=BINARY 1=ASCII"),
        )


def calendar_text(t: float) -> str:
    """GPS calendar time of ``t`` [s GPS] as L1B headers write it: ``YYYY-MM-DD HH:MM:SS.ff``."""
    return _calendar(t)


def yaml_header_lines(header: dict[str, Any]) -> list[str]:
    """A GRACE-FO YAML header ``{"header": header}`` as text lines, with the end marker.

    Written with the reader's own dumper (strings plain where YAML allows, as the
    real files), so :func:`read_grace_l1b`-style readers read it back unchanged.
    """
    yaml, _, dumper = _yaml()
    text = yaml.dump(
        {"header": header}, Dumper=dumper, sort_keys=False, allow_unicode=True, width=1 << 16
    )
    return [*text.rstrip("\n").split("\n"), "# End of YAML header"]


def _grace_header(series: AccSeries, letter: str) -> list[str]:
    n = len(series)
    t0, t1 = (float(series.time[0]), float(series.time[-1])) if n else (0.0, 0.0)
    hdr: dict[str, Any] = dict(series.meta.get("grace") or {})
    if not hdr:
        hdr = {
            "PRODUCER AGENCY": "accal",
            "PRODUCER INSTITUTION": "accal",
            "FILE TYPE ipACC1BF": "8",
            "FILE FORMAT 0=BINARY 1=ASCII": "1",
            "NUMBER OF HEADER RECORDS": "",
            "SOFTWARE VERSION": "accal.io.grace_l1b.write_grace_acc1b",
            "REFERENCE DOCUMENTATION": "GRACE Level 1 Software Handbook",
            "SATELLITE NAME": "",
            "SENSOR NAME": "ACC",
            "TIME EPOCH (GPS TIME)": "2000-01-01 12:00:00",
            "TIME FIRST OBS(SEC PAST EPOCH)": "",
            "TIME LAST OBS(SEC PAST EPOCH)": "",
            "NUMBER OF DATA RECORDS": "",
            "PROCESS LEVEL (1A OR 1B)": "1B",
        }
    hdr["FILE FORMAT 0=BINARY 1=ASCII"] = "1"
    hdr["SATELLITE NAME"] = f"GRACE {letter}"
    hdr["TIME FIRST OBS(SEC PAST EPOCH)"] = f"{t0:.6f} ({_calendar(t0)})"
    hdr["TIME LAST OBS(SEC PAST EPOCH)"] = f"{t1:.6f} ({_calendar(t1)})"
    hdr["NUMBER OF DATA RECORDS"] = str(n)
    n_lines = sum(len(v) if isinstance(v, list) else 1 for v in hdr.values())
    hdr["NUMBER OF HEADER RECORDS"] = str(n_lines)
    lines = []
    for key, value in hdr.items():
        for v in value if isinstance(value, list) else [value]:
            lines.append(f"{key:<{GRACE_KEY_WIDTH}}: {v}".ljust(80))
    lines.append("END OF HEADER".ljust(80))
    return lines


_ORDINAL = {1: "st", 2: "nd", 3: "rd"}


def _gracefo_header(series: AccSeries, letter: str) -> list[str]:
    import copy

    n = len(series)
    t0, t1 = (float(series.time[0]), float(series.time[-1])) if n else (0.0, 0.0)
    hdr = copy.deepcopy(series.meta.get("gracefo") or {})
    if not hdr:
        variables = []
        for i, name in enumerate(GRACEFO_COLUMNS, start=1):
            unit = {"GRACEFO_id": "char", "qualflg": "none"}.get(
                name, COLUMN_UNITS.get(name, "").replace("^", "")
            )
            if name == "gps_time":
                unit = "second"
            suffix = _ORDINAL.get(i if i < 20 else i % 10, "th")
            variables.append({name: {"comment": f"{i}{suffix} column", "units": unit}})
        hdr = {
            "dimensions": {"num_records": ""},
            "global_attributes": {
                "creator_name": "accal",
                "platform": "",
                "processing_level": "1B",
                "product_version": "04",
                "title": "GRACE-FO Level-1B Transformed Accelerometer Data (written by accal)",
            },
            "non-standard_attributes": {"epoch_time": "2000-01-01T12:00:00.00"},
            "variables": variables,
        }
    hdr.setdefault("dimensions", {})["num_records"] = str(n)
    ga = hdr.setdefault("global_attributes", {})
    ga["platform"] = f"GRACE {letter}"
    ga["time_coverage_start"] = _calendar(t0).replace(" ", "T")
    ga["time_coverage_stop"] = _calendar(t1).replace(" ", "T")
    nsa = hdr.setdefault("non-standard_attributes", {})
    nsa["start_time_epoch_secs"] = f"{t0:.0f}" if t0 == int(t0) else repr(t0)
    nsa["stop_time_epoch_secs"] = f"{t1:.0f}" if t1 == int(t1) else repr(t1)
    yaml, _, str_dumper = _yaml()
    text = yaml.dump(
        {"header": hdr}, Dumper=str_dumper, sort_keys=False, allow_unicode=True, width=1 << 16
    )
    return [*text.rstrip("\n").split("\n"), HEADER_END["gracefo"][0]]


def _format_floats(a: np.ndarray) -> list[str]:
    # repr() is the shortest string that reads back to the same double: exact round trip.
    return [repr(v) for v in a.tolist()]


def write_grace_acc1b(series: AccSeries, path: str | Path, *, flavour: str | None = None) -> Path:
    """Write ``series`` as a GRACE (RL02-style) or GRACE-FO (RL04) ACC1B ASCII file.

    Parameters
    ----------
    series : AccSeries
        Three axes x, y, z [m/s²]; satellite one of ``GRACE-A``, ``GRACE-B``,
        ``GRACE-FO-C``, ``GRACE-FO-D``; ``quality`` < 256 (8-bit qualflg).
        ``aux`` channels ``ang_accl_*`` [rad/s²] and ``acl_*_res`` [m/s²] are written
        when present (else 0); other auxiliary channels are dropped with a warning.
    path : str or Path
        Output file, written atomically; gzip-compressed if the name ends in ``.gz``.
    flavour : {"grace", "gracefo"}, optional
        Header style; default from the satellite (A/B: grace, C/D: gracefo).

    Returns
    -------
    Path
        The written path.

    Notes
    -----
    The header is ``meta["grace"]`` / ``meta["gracefo"]`` when present (so a file
    read and written again keeps its header), else a minimal one; the record
    count, first/last time and satellite fields are always refreshed.  Floats are
    written with ``repr`` (shortest exact representation, <= 17 significant
    digits; real files use 16), times as integers when integral, and two spaces
    before the 8-character ``qualflg`` as the JPL writer does.  Reading the
    output gives back the same time, acc, quality, valid, aux and meta.
    """
    inv = {v: k for k, v in SATELLITES.items()}
    if series.satellite not in inv:
        raise ValidationError(
            f"satellite must be one of {', '.join(inv)} to write GRACE L1B, "
            f"got {series.satellite!r}"
        )
    letter = inv[series.satellite]
    if flavour is None:
        flavour = "grace" if letter in "AB" else "gracefo"
    check_option("flavour", flavour, ("grace", "gracefo"))
    if (flavour == "grace") != (letter in "AB"):
        raise ValidationError(f"flavour {flavour!r} does not match satellite {series.satellite!r}")
    if tuple(series.axes) != ("x", "y", "z"):
        raise ValidationError(f"GRACE L1B needs axes ('x', 'y', 'z'), got {series.axes}")
    if len(series) == 0:
        raise ValidationError("cannot write an empty series (L1B files need data records)")
    q = series.quality
    if q.size and int(q.max()) > 255:
        raise ValidationError(f"quality must fit 8 bits (qualflg), got max {int(q.max())}")
    extra = sorted(set(series.aux) - set(AUX_COLUMNS))
    if extra:
        warnings.warn(
            f"{len(extra)} auxiliary channels not representable in L1B dropped: {extra}",
            stacklevel=2,
        )
    n = len(series)
    header = (
        _grace_header(series, letter) if flavour == "grace" else _gracefo_header(series, letter)
    )
    t = series.time
    integral = np.all(t == np.round(t)) and np.all(np.abs(t) < 2**53)
    tcol = [str(int(v)) for v in t.tolist()] if integral else _format_floats(t)
    cols = [tcol, [letter] * n]
    cols += [_format_floats(series.acc[:, i]) for i in range(3)]
    zero = ["0"] * n
    for c in AUX_COLUMNS:
        cols.append(_format_floats(np.asarray(series.aux[c], float)) if c in series.aux else zero)
    qual = [format(v, "08b") for v in q.tolist()]
    body = "\n".join(" ".join(row[:-1]) + "  " + row[-1] for row in zip(*cols, qual, strict=True))
    text = ("\n".join(header) + "\n" + body + "\n").encode("utf-8")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if path.suffix == ".gz" else text)
    return path
