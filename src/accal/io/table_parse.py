"""Whole-table parsing of CSV (optionally gzipped) and Parquet files into Arrow tables.

With the checks every table reader needs: unique column names, single-line CSV
values, a complete last line, and pyarrow's CSV errors turned into one clean line
that names the file line.
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path
from typing import Any

from accal.errors import FormatError
from accal.io.common import PARQUET_MAGIC, check_binary, csv_read_options, one_line, read_bytes
from accal.io.table_meta import _comment, _json_object, _plain_name, _units_object
from accal.io.writers import read_csv_metadata


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
        # pandas (~0.5 s, a third of a one-file run).  One thread, and the file closed:
        # a threaded read's clean-up can meet the interpreter's shutdown when a bad
        # --aux or --reference ends the run right after it (exit 134, "terminate called
        # without an active exception", 4-9 of 12-15 runs of a QA helper; see
        # accal.io.common.csv_read_options)
        with pq.ParquetFile(io.BytesIO(raw)) as pf:
            table = pf.read(use_threads=False)
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
