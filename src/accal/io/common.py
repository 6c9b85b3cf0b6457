"""Helpers shared by the readers: safe file access, sniffing, quirk repair.

Every reader goes through :func:`read_bytes` (so a directory, a missing or
unreadable file and a corrupt ``.gz`` all become :class:`~accal.errors.FormatError`)
and through :func:`tidy` (so duplicated epochs, out-of-order rows and gaps are
handled and counted the same way for every format).
"""

from __future__ import annotations

import errno
import gzip
import os
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError
from accal.timescale import nominal_step

GZIP_MAGIC = b"\x1f\x8b"
PARQUET_MAGIC = b"PAR1"
#: UTF-8 byte-order mark: some editors (and Windows tools) start a text file with it.
#: The readers and sniffers skip it; it is not part of any format.
UTF8_BOM = b"\xef\xbb\xbf"

#: A time step larger than this many nominal steps is a gap.
GAP_FACTOR = 1.5

#: Largest input accepted, on disk and after gunzip [bytes].  A 1 Hz L1B day is
#: ~17 MB of ASCII; this refuses a gzip bomb or a wrong multi-GB file with a
#: FormatError instead of exhausting memory.
MAX_INPUT_BYTES = 1 << 31

_GUNZIP_STEP = 64 << 20

#: Plausible GPS epochs [s since 2000-01-01 12:00:00 GPS]: from the GPS epoch
#: (1980-01-06 00:00:00) to 2100-01-01 00:00:00.  A time outside is corrupt (a
#: flipped exponent, a binary field read as time), and would break every date
#: computation downstream.
GPS_TIME_RANGE = (-630_763_200.0, 3_155_716_800.0)

#: Largest plausible magnitude of an acceleration in an input [m/s² or rad/s²].
#: Electrostatic accelerometers measure below ~1e-3 m/s² (GRACE ±5e-5); a value
#: beyond 1000 (100 g) is a damaged field or a wrong unit, and one near 1e300 would
#: overflow every sum of squares downstream (infinite sigmas, failed closures).
MAX_ABS_ACCELERATION = 1e3


def implausible(arr: NDArray, limit: float = MAX_ABS_ACCELERATION) -> NDArray[np.intp]:
    """Indices of the finite values of ``arr`` whose magnitude exceeds ``limit``."""
    a = np.asarray(arr, dtype=np.float64)
    return np.flatnonzero(np.abs(np.where(np.isfinite(a), a, 0.0)) > limit)


def open_error(exc: OSError, path: str | Path) -> FormatError:
    """The one-line error of an input that could not be opened or read: missing
    (:func:`missing` says how), not readable, or the system's reason."""
    if isinstance(exc, FileNotFoundError) or exc.errno == errno.ELOOP:
        return FormatError(missing(path), path)
    if isinstance(exc, PermissionError):
        return FormatError("permission denied (file not readable)", path)
    return FormatError(f"cannot read file: {exc.strerror or exc}", path)


def implausible_message(name: str, value: float, unit: str = "m/s²") -> str:
    """The reader message for a value beyond :data:`MAX_ABS_ACCELERATION`."""
    return (
        f"{name}: {value:.6g} {unit} is not a plausible acceleration "
        f"(|value| > {MAX_ABS_ACCELERATION:g}): a damaged value or a wrong unit"
    )


def missing(path: str | Path) -> str:
    """Why an input that cannot be opened is not there: ``no such file``, ``a broken
    symbolic link`` or ``a symbolic link loop`` (issue 23: a loop read "no such file")."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a symbolic link loop"
        if os.path.islink(path):
            return "a broken symbolic link (its target does not exist)"
    return "no such file"


def read_bytes(path: str | Path, limit: int | None = None, why: str = "") -> bytes:
    """Return the (decompressed) content of ``path``, without a leading UTF-8 BOM.

    Gzip is detected by its magic bytes, not by the file name.  A UTF-8
    byte-order mark (:data:`UTF8_BOM`) at the start of the text is dropped
    (without copying the content of an uncompressed file).

    Parameters
    ----------
    path : str or Path
        The input.
    limit : int, optional
        Most bytes accepted, on disk and after decompression: a reader that knows
        its record count passes a tighter bound; never more than
        :data:`MAX_INPUT_BYTES` (the default).
    why : str, optional
        What ``limit`` is, for the message (default: "not an input file?").

    Raises
    ------
    FormatError
        Missing file, directory, unreadable file, corrupt gzip stream, empty file,
        or more than ``limit`` bytes on disk or after decompression.
    """
    p = Path(path)
    if p.is_dir():
        raise FormatError("is a directory, not a file", p)
    if limit is None or limit >= MAX_INPUT_BYTES:
        limit, why = MAX_INPUT_BYTES, ""
    why = why or "not an input file?"
    try:
        if p.stat().st_size > limit:
            raise FormatError(f"file larger than {limit:,} bytes ({why})", p)
        # Unbuffered: readall() sizes its one read by fstat (a buffered read() after a
        # small read is ~25x slower).  A BOM is skipped by reading after it: no copy.
        with open(p, "rb", buffering=0) as fh:
            _refuse_nul_start(fh.read(NUL_PROBE), p)  # before reading gigabytes of it
            fh.seek(0)
            if fh.read(3) != UTF8_BOM:
                fh.seek(0)
            raw = fh.readall()
    except OSError as exc:
        raise open_error(exc, p) from None
    if raw[:2] == GZIP_MAGIC:
        raw = gunzip(raw, p, limit, why)
        if raw.startswith(UTF8_BOM):
            raw = raw[len(UTF8_BOM) :]
    if not raw or raw.isspace():
        raise FormatError("empty file", p)
    return raw


#: Bytes at the start of an input that must not all be NUL (:func:`_refuse_nul_start`).
NUL_PROBE = 1 << 16


def _refuse_nul_start(head: bytes, path: str | Path, where: str = "") -> None:
    """FormatError when ``head`` is :data:`NUL_PROBE` NUL bytes: a zero-filled or sparse
    file, or a gzip bomb of zeros, which no format starts with (issue 23: a 2 GB sparse
    ``.asc`` or 9.4 MB ``.gz`` of 2.1 GB zeros reached 4.3 GB of memory and 30 s before
    failing with "truncated last line")."""
    if len(head) == NUL_PROBE and not head.strip(b"\x00"):
        raise FormatError(
            f"the first {NUL_PROBE:,} bytes{where} are NUL (a zero-filled or sparse file?)", path
        )


def read_head(path: str | Path, size: int) -> bytes:
    """The first ``size`` bytes of the (decompressed) content of ``path``, no UTF-8 BOM.

    What a reader needs to look at a header before it decides how much of the
    file it will read (:func:`read_bytes` with a ``limit``).  Returns ``b""`` when the
    file cannot be read or its gzip stream is corrupt: the full read that follows
    says what is wrong.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(size)
            if head[:2] == GZIP_MAGIC:
                d = zlib.decompressobj(wbits=31)
                head = d.decompress(head, size)
    except (OSError, zlib.error):
        return b""
    return head[len(UTF8_BOM) :] if head.startswith(UTF8_BOM) else head


def gunzip(raw: bytes, path: str | Path, limit: int = MAX_INPUT_BYTES, why: str = "") -> bytes:
    """Decompress a (multi-member) gzip stream, refusing more than ``limit`` bytes of output.

    Same semantics as :func:`gzip.decompress` (members are concatenated, NUL
    padding after the last member is ignored, CRC and length are checked), but the
    output is capped, so a gzip bomb is a FormatError and not an exhausted memory.

    Raises
    ------
    FormatError
        Corrupt or truncated stream, data after the last member, output over ``limit``.
    """
    out: list[bytes] = []
    total = 0
    rest = raw
    while rest:
        if rest[:2] != GZIP_MAGIC:
            raise FormatError("corrupt gzip stream (garbage after the compressed data)", path)
        d = zlib.decompressobj(wbits=31)  # one gzip member: header, deflate, CRC32 + ISIZE
        data = rest
        while True:
            try:
                # Bounded steps: a small max_length is ~3x slower, an unbounded one uncapped.
                chunk = d.decompress(data, min(_GUNZIP_STEP, limit - total + 1))
            except zlib.error as exc:
                raise FormatError(f"corrupt gzip stream ({exc})", path) from None
            if not total:
                _refuse_nul_start(chunk[:NUL_PROBE], path, " after gunzip")
            total += len(chunk)
            if total > limit:
                raise FormatError(
                    f"gzip stream decompresses to more than {limit:,} bytes "
                    f"({why or 'not an input file?'})",
                    path,
                )
            out.append(chunk)
            data = d.unconsumed_tail
            if not data:
                break
        if not d.eof:
            raise FormatError("corrupt gzip stream (truncated: no end-of-stream marker)", path)
        rest = d.unused_data.lstrip(b"\x00")
    return b"".join(out)


def check_gps_time(
    time: NDArray[np.float64],
    path: str | Path,
    line_of: Callable[[int], int | None] | None = None,
    *,
    name: str = "gps_time",
    unit: str = "record",
) -> None:
    """Raise FormatError if an epoch lies outside :data:`GPS_TIME_RANGE`.

    Parameters
    ----------
    time : ndarray of float64
        Epochs in file order [s, GPS since 2000-01-01 12:00:00]; already finite.
    path : str or Path
        The file, for the message.
    line_of : callable, optional
        Row index -> 1-based file line (text formats).  Without it the message
        names the ``unit`` number instead (``"record 12"`` for binary L1B).
    name, unit : str
        Column name and row noun used in the message.
    """
    lo, hi = GPS_TIME_RANGE
    if time.size and (time.min() < lo or time.max() > hi):
        i = int(np.flatnonzero((time < lo) | (time > hi))[0])
        where = f"{unit} {i + 1}: " if line_of is None else ""
        raise FormatError(
            f"{where}{name} {time[i]:.9g} s is outside 1980-01-06 ... 2100-01-01 "
            "(GPS seconds since 2000-01-01 12:00:00)",
            path,
            None if line_of is None else line_of(i),
        )


def one_line(text: str, limit: int = 200) -> str:
    """``text`` as one short line: control characters escaped, cut at ``limit``."""
    text = str(text)
    if not text.isprintable():
        text = repr(text)[1:-1]
    return text[:limit]


def string_at(arr: Any, i: int) -> str:
    """Value ``i`` of an Arrow string array, undecodable bytes replaced (for messages).

    The L1B parse skips pyarrow's UTF-8 check, so a damaged id or flag may not be
    valid UTF-8 and ``arr[i].as_py()`` would raise.
    """
    import pyarrow as pa

    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    value = arr.cast(pa.binary())[i].as_py()
    return "" if value is None else value.decode("utf-8", "replace")


def csv_read_options(**kwargs: Any) -> Any:
    """``pyarrow.csv.ReadOptions`` for every CSV parse of accal: single-threaded.

    pyarrow's threaded reader finishes its clean-up on a worker thread after
    ``read_csv`` has returned; when the process exits right after a read (a bad
    file that is the last of a run) that clean-up can meet the interpreter's
    shutdown and abort the process (``terminate called without an active
    exception``, exit 134; seen in 1-3 of 40 runs).  accal parallelises over
    files instead (``--workers``), so one parsing thread per process costs
    nothing there (~8 ms per 1 Hz day in a one-process run).
    """
    import pyarrow.csv as pacsv

    return pacsv.ReadOptions(use_threads=False, **kwargs)


def shorten(value: Any, n: int = 40) -> str:
    """``repr`` of a value cut to ``n`` characters, for error messages."""
    return repr(value[:n] if isinstance(value, str | bytes) else value)


def peek(path: str | Path, n: int = 8192) -> bytes:
    """Return up to ``n`` leading (decompressed) bytes of ``path``; b"" on any error.

    A leading UTF-8 BOM is skipped (the bytes after it are returned), as
    :func:`read_bytes` does, so that sniffers see what the readers will parse.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(n + len(UTF8_BOM))
            if head[:2] == GZIP_MAGIC:
                fh.seek(0)
                with gzip.GzipFile(fileobj=fh) as gz:
                    head = gz.read(n + len(UTF8_BOM))
    except Exception:
        return b""
    if head.startswith(UTF8_BOM):
        head = head[len(UTF8_BOM) :]
    return head[:n]


def row_to_line(
    text: bytes, first_line: int, *, text_line: int | None = None
) -> Callable[[int], int]:
    """Map a 0-based data row (as pyarrow counts them) to its 1-based file line.

    Parameters
    ----------
    text : bytes
        Text that starts at file line ``text_line`` (default ``first_line``).
    first_line : int
        1-based file line of data row 0.
    text_line : int, optional
        1-based file line of the start of ``text`` (lines before ``first_line`` are
        header lines, skipped).

    Returns
    -------
    callable
        ``line_of(row) -> line``.  pyarrow skips empty lines, so with blank lines
        among the data the row index is not ``line - first_line``; the scan for
        them runs only when ``line_of`` is called (the error path).
    """
    skip = first_line - (first_line if text_line is None else text_line)

    def line_of(row: int) -> int:
        start = 0
        for _ in range(skip):
            nl = text.find(b"\n", start)
            start = len(text) if nl < 0 else nl + 1
        data = text[start:] if start else text
        if b"\n\n" not in data and b"\n\r\n" not in data and data[:1] not in (b"\n", b"\r"):
            return first_line + row
        k = -1
        for j, bline in enumerate(data.split(b"\n")):
            if bline.rstrip(b"\r"):
                k += 1
                if k == row:
                    return first_line + j
        return first_line + row

    return line_of


def check_binary(text: bytes, path: str | Path, first_line: int = 1) -> None:
    """Raise FormatError if ``text`` holds NUL or non-UTF-8 bytes (binary garbage)."""
    if b"\x00" in text:
        line = first_line + text[: text.index(b"\x00")].count(b"\n")
        raise FormatError("binary data where text was expected", path, line)
    try:
        text.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = first_line + text[: exc.start].count(b"\n")
        raise FormatError("binary data where text was expected (not UTF-8)", path, line) from None


def arrow_to_numpy(col: Any, out: NDArray | None = None) -> NDArray:
    """A numeric Arrow (chunked) array without nulls as a writable numpy array.

    Reads the value buffers directly: pyarrow's own ``to_numpy`` imports pandas
    (~0.3 s), which would dominate the start-up time of a one-file run.  The
    chunks are copied once, into ``out`` when given (e.g. a column of a 2-D
    array; its dtype converts) or a new array.  Booleans and arrays with nulls
    fall back to pyarrow's conversion.
    """
    import pyarrow as pa

    t = col.type
    chunks = col.chunks if isinstance(col, pa.ChunkedArray) else [col]
    if col.null_count == 0 and (pa.types.is_integer(t) or pa.types.is_floating(t)):
        dtype = np.dtype(t.to_pandas_dtype())
        if out is None:
            out = np.empty(len(col), dtype=dtype)
        pos = 0
        for c in chunks:
            m = len(c)
            if m:
                out[pos : pos + m] = np.frombuffer(
                    c.buffers()[1], dtype=dtype, count=m, offset=c.offset * dtype.itemsize
                )
            pos += m
        return out
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    arr = np.asarray(col.to_numpy(zero_copy_only=False))
    if out is not None:
        out[...] = arr
        return out
    return arr


def bits_from_strings(
    arr: Any,
    path: str | Path,
    first_line: int,
    width: int = 8,
    *,
    line_of: Callable[[int], int | None] | None = None,
    name: str = "qualflg",
) -> NDArray:
    """Convert an Arrow string array of ``width`` '0'/'1' characters to uint32 bitmasks.

    Bit 0 is the rightmost character.  Vectorised on the Arrow buffers.  The line
    of a bad value is ``line_of(row)`` when given (for files with blank lines),
    else ``first_line + row``; ``name`` is the column named in the message.

    Raises
    ------
    FormatError
        A value of the wrong length or with characters other than 0 and 1.
    """
    import pyarrow as pa

    def where(i: int) -> int | None:
        return first_line + i if line_of is None else line_of(i)

    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    n = len(arr)
    if n == 0:
        return np.zeros(0, dtype=np.uint32)
    if pa.types.is_large_string(arr.type):
        arr = arr.cast(pa.string())
    _, off_buf, data_buf = arr.buffers()
    offsets = np.frombuffer(off_buf, dtype=np.int32, count=n + 1, offset=4 * arr.offset)
    lengths = np.diff(offsets)
    bad = np.flatnonzero(lengths != width)
    if bad.size:
        i = int(bad[0])
        raise FormatError(
            f"{name}: quality flag {shorten(string_at(arr, i))} is not {width} characters of 0/1",
            path,
            where(i),
        )
    chars = np.frombuffer(
        data_buf, dtype=np.uint8, count=n * width, offset=int(offsets[0])
    ).reshape(n, width)
    ones = chars == ord("1")
    if not np.all(ones | (chars == ord("0"))):
        i = int(np.flatnonzero(~(ones | (chars == ord("0"))).all(axis=1))[0])
        raise FormatError(
            f"{name}: quality flag {shorten(string_at(arr, i))} is not {width} characters of 0/1",
            path,
            where(i),
        )
    # first character = most significant bit; packbits pads the last byte on the right
    if width % 8 == 0:  # whole bytes: a flat packbits is ~100x faster than per row
        packed = np.packbits(ones.ravel()).reshape(n, width // 8)
    else:
        packed = np.packbits(ones, axis=1)
    bits = packed[:, 0].astype(np.uint32)
    for k in range(1, packed.shape[1]):
        bits = (bits << np.uint32(8)) | packed[:, k]
    return bits >> np.uint32(8 * packed.shape[1] - width)


@dataclass
class Tidied:
    """Result of :func:`tidy`: arrays reordered and the counts for the ReadReport."""

    time: NDArray[np.float64]
    arrays: dict[str, NDArray]
    report: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def tidy(time: NDArray[np.float64], arrays: dict[str, NDArray]) -> Tidied:
    """Sort by time, drop duplicated epochs (first kept) and find gaps.

    Parameters
    ----------
    time : ndarray of float64, shape (n,)
        Epochs in file order [s].
    arrays : dict of str to ndarray
        Per-row arrays (first dimension n) to reorder the same way.

    Returns
    -------
    Tidied
        ``report`` holds ``n_rows``, ``n_duplicates``, ``n_out_of_order``, ``n_gaps``,
        ``gap_seconds`` and ``nominal_step`` for :class:`~accal.series.ReadReport`.

    Notes
    -----
    ``n_out_of_order`` counts rows whose epoch is smaller than that of the row
    before them in the file.  Sorting is stable, so of duplicated epochs the one
    that came first in the file is kept.  The nominal step is the median of the
    positive steps; a step larger than ``GAP_FACTOR`` nominal steps is a gap and
    contributes ``step − nominal_step`` to ``gap_seconds`` (the missing time).
    """
    n = time.shape[0]
    warnings: list[str] = []
    d = np.diff(time)
    n_ooo = int(np.count_nonzero(d < 0))
    if n_ooo:
        order = np.argsort(time, kind="stable")
        time = time[order]
        arrays = {k: v[order] for k, v in arrays.items()}
        warnings.append(f"{n_ooo} rows out of time order (sorted)")
        d = np.diff(time)
    dup = d == 0
    n_dup = int(np.count_nonzero(dup))
    if n_dup:
        # of the dropped records, how many disagree with the record before them
        differ = np.zeros(n_dup, dtype=bool)
        for v in arrays.values():
            a, b = v[1:][dup], v[:-1][dup]
            ne = a != b
            if a.dtype.kind == "f":
                ne &= ~(np.isnan(a) & np.isnan(b))
            differ |= ne.reshape(n_dup, -1).any(axis=1)
        keep = np.concatenate(([True], ~dup))
        time = time[keep]
        arrays = {k: v[keep] for k, v in arrays.items()}
        n_differ = int(np.count_nonzero(differ))
        warnings.append(
            f"{n_dup} duplicated epochs dropped (first kept)"
            + (f"; {n_differ} of them with different values" if n_differ else "")
        )
        d = np.diff(time)
    step = nominal_step(d)
    if d.size:
        gaps = d > GAP_FACTOR * step
        n_gaps = int(np.count_nonzero(gaps))
        gap_seconds = float(np.sum(d[gaps] - step))
    else:
        n_gaps, gap_seconds = 0, 0.0
    if n_gaps:
        warnings.append(f"{n_gaps} gaps totalling {gap_seconds:g} s")
    report = {
        "n_rows": n,
        "n_duplicates": n_dup,
        "n_out_of_order": n_ooo,
        "n_gaps": n_gaps,
        "gap_seconds": gap_seconds,
        "nominal_step": step,
    }
    return Tidied(time, arrays, report, warnings)
