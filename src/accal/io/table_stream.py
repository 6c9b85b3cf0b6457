"""Streamed reading of any Parquet or CSV (optionally gzipped) table, in chunks of rows.

Used by :mod:`accal.io.rawlog` for files too large to hold whole.
"""

from __future__ import annotations

import gzip
import io
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from accal.errors import FormatError, ValidationError
from accal.io.common import (
    PARQUET_MAGIC,
    UTF8_BOM,
    check_binary,
    csv_read_options,
    one_line,
    open_error,
    read_bytes,
)
from accal.io.table_meta import _comment, _json_object, _plain_name, _units_object
from accal.io.table_parse import (
    _column_names,
    _csv_error,
    _exc_text,
    check_single_line_values,
    check_unique_names,
    last_line_complete,
)
from accal.io.writers import read_csv_metadata

#: Rows per chunk of :func:`open_table` by default (~3 days at 1 Hz).
STREAM_ROWS = 1 << 18


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
    except OSError as exc:
        raise open_error(exc, path) from None
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
    threads : bool
        Whether pyarrow may decode Parquet column chunks on its thread pool (CSV is
        always read on the calling thread, :func:`accal.io.common.csv_read_options`).
        False for a read in a process that forks workers afterwards: the pool's
        threads would make :func:`accal.batch_workers.start_method` choose the
        slower fork server.
    """

    def __init__(self, path: str | Path, *, rows: int = STREAM_ROWS, threads: bool = True) -> None:
        self.path = Path(path)
        self.rows = int(rows)
        self.threads = bool(threads)
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
        batches = pf.iter_batches(batch_size=self.rows, use_threads=self.threads)
        try:
            for batch in batches:
                if batch.num_rows:
                    yield row, pa.Table.from_batches([batch])
                    row += batch.num_rows
        except (pa.ArrowException, OSError) as exc:
            raise FormatError(f"corrupt Parquet file ({_exc_text(exc)})", self.path) from None
        finally:
            # a reader left open (a caller that stops early, an error) kept pyarrow's
            # decoding threads alive at exit: "terminate called without an active
            # exception", exit 134 instead of 1 (QA, 2026-11-29: a rejected reference)
            batches.close()
            pf.close()
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
