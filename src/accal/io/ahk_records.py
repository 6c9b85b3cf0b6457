"""Vectorised parsing of AHK1B records: fixed columns, then the ``prod_flag``-selected fields.

The data section is tokenised without a Python loop (:func:`_tokenize`), and each
column converted in one pass per ``prod_flag`` layout.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError
from accal.io.ahk_spec import N_FIXED, TIME_RANGE, Field
from accal.io.common import check_binary
from accal.io.hk_data import _NOT_PRESENT

_WHITESPACE = np.zeros(256, dtype=bool)
_WHITESPACE[[9, 10, 11, 12, 13, 32]] = True  # what bytes.split() splits on


class _Tokens(NamedTuple):
    """Whitespace-separated tokens of the data section, found without a Python loop."""

    buf: NDArray[np.uint8]
    starts: NDArray[np.intp]  # byte offset of every token
    lens: NDArray[np.intp]  # its length
    first: NDArray[np.intp]  # index of the first token of every record (non-blank line)
    count: NDArray[np.intp]  # number of tokens of every record
    line: NDArray[np.intp]  # 0-based line (within the data section) of every record


def _tokenize(data: bytes) -> _Tokens:
    buf = np.frombuffer(data, dtype=np.uint8)
    is_tok = buf > 32
    low = buf[~is_tok]
    if not _WHITESPACE[low].all():  # control characters other than whitespace
        at = int(np.flatnonzero((buf < 32) & ~_WHITESPACE[buf])[0])
        raise ValueError(at)
    edge = np.diff(is_tok.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(edge == 1)
    lens = np.flatnonzero(edge == -1) - starts
    newlines = np.flatnonzero(buf == 10)
    tok_line = np.searchsorted(newlines, starts)
    per_line = np.bincount(tok_line, minlength=newlines.size + 1)
    line = np.flatnonzero(per_line)
    first = (np.cumsum(per_line) - per_line)[line]
    # pad so that every token can be read as a full-width window
    pad = int(lens.max()) if lens.size else 1
    padded = np.concatenate((buf, np.zeros(pad, dtype=np.uint8)))
    return _Tokens(padded, starts, lens, first, per_line[line], line)


def _gather(tok: _Tokens, index: NDArray[np.intp]) -> NDArray[np.bytes_]:
    """The tokens ``index`` as a fixed-width bytes array (one vectorised copy)."""
    starts, lens = tok.starts[index], tok.lens[index]
    width = int(lens.max()) if lens.size else 1
    windows = np.lib.stride_tricks.sliding_window_view(tok.buf, width)
    mat = windows[starts]
    mat[np.arange(width) >= lens[:, None]] = 0
    return np.ascontiguousarray(mat).view(f"S{width}").reshape(-1)


def _bits(col: NDArray[np.bytes_], width: int | None = None) -> NDArray[np.int64] | int:
    """0/1 strings (bit 0 rightmost) as int64; on failure the index of the first bad value.

    ``width`` is the exact number of characters required; None accepts 1 to 32.
    """
    w = col.dtype.itemsize
    if col.size and w == (width or w) <= 32:
        # fast path: every value is exactly w characters of 0/1
        mat = col.view(np.uint8).reshape(col.size, w)
        if np.all((mat == 48) | (mat == 49)):
            out = np.zeros(col.size, dtype=np.int64)
            for j in range(w):
                out = (out << 1) | (mat[:, j] == 49)
            return out
    uniq, inv = np.unique(col, return_inverse=True)
    vals = np.empty(uniq.size, dtype=np.int64)
    for j, u in enumerate(uniq.tolist()):
        good = len(u) == width if width else 0 < len(u) <= 32
        if not good or u.strip(b"01"):
            return int(np.flatnonzero(inv.reshape(-1) == j)[0])
        vals[j] = int(u, 2)
    return vals[inv.reshape(-1)]


def _convert(col: NDArray[np.bytes_], dtype: type) -> NDArray | int:
    """Convert byte tokens to ``dtype``; on failure the index of the first bad token."""
    try:
        out = col.astype(dtype)
    except (ValueError, OverflowError, TypeError):
        for i, tok in enumerate(col.tolist()):
            try:
                dtype(tok)
            except (ValueError, OverflowError, TypeError):
                return i
        return 0
    if dtype is np.float64:
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            return int(bad[0])
    return out


def _parse_records(
    data: bytes, first_line: int, fields: dict[int, Field], path: Path
) -> tuple[dict[str, NDArray], dict[str, int], list[str]]:
    """Parse AHK1B records: fixed columns and the ``prod_flag``-selected fields.

    Returns the per-record arrays (``time``, ``time_ref``, ``id``, ``qualflg``,
    ``f:<name>`` floats with NaN, ``i:<name>`` ints with -1), the ``prod_flag`` bit
    of every field present, and the names of the positional (unverified) fields.
    Tokenising and conversion are vectorised (one pass per ``prod_flag`` layout
    and column): a 10 Hz GRACE-FO day of 864,000 records takes a few seconds.
    """
    if not data.strip():
        raise FormatError("header but no data records", path, first_line)
    if not data.endswith(b"\n"):
        raise FormatError(
            "truncated last line (no newline at end of file)", path, first_line + data.count(b"\n")
        )
    check_binary(data, path, first_line)
    try:
        tok = _tokenize(data)
    except ValueError as exc:
        at = int(exc.args[0])
        line = first_line + data[:at].count(b"\n")
        raise FormatError("control character inside a record", path, line) from None
    n = int(tok.first.size)

    def fail(msg: str, row: int) -> FormatError:
        return FormatError(msg, path, first_line + int(tok.line[row]))

    short = np.flatnonzero(tok.count < N_FIXED)
    if short.size:
        r = int(short[0])
        raise fail(
            f"record has {tok.count[r]} fields, expected at least {N_FIXED} "
            "(time, time fraction, time_ref, id, qualflg, prod_flag)",
            r,
        )
    cols = [_gather(tok, tok.first + j) for j in range(N_FIXED)]
    intg = _convert(cols[0], np.int64)
    if isinstance(intg, int):
        raise fail(f"time: not an integer number of seconds: {cols[0][intg][:20]!r}", intg)
    frac = _convert(cols[1], np.int64)
    if isinstance(frac, int):
        raise fail(f"time fraction: not an integer [µs]: {cols[1][frac][:20]!r}", frac)
    bad = np.flatnonzero((intg < TIME_RANGE[0]) | (intg > TIME_RANGE[1]))
    if bad.size:
        raise fail(
            f"time {intg[bad[0]]} s is outside {TIME_RANGE[0]:.0f} ... {TIME_RANGE[1]:.0f} s "
            "(GPS epoch ... 2100)",
            int(bad[0]),
        )
    bad = np.flatnonzero((frac < 0) | (frac > 999_999))
    if bad.size:
        raise fail(f"time fraction {frac[bad[0]]} µs is not in 0 ... 999999", int(bad[0]))
    for j, what in ((2, "time_ref"), (3, "satellite id")):
        long = np.flatnonzero(np.char.str_len(cols[j]) != 1)
        if long.size:
            r = int(long[0])
            raise fail(f"{what} {cols[j][r][:10]!r} is not one character", r)
    qualflg = _bits(cols[4], 8)
    if isinstance(qualflg, int):
        raise fail(f"qualflg {cols[4][qualflg][:20]!r} is not 8 characters of 0/1", qualflg)
    prod_flag = _bits(cols[5], 32)
    if isinstance(prod_flag, int):
        raise fail(f"prod_flag {cols[5][prod_flag][:40]!r} is not 32 characters of 0/1", prod_flag)
    out: dict[str, NDArray] = {}
    present: dict[str, int] = {}
    positional: list[str] = []
    layouts, which = np.unique(prod_flag, return_inverse=True)
    order = np.argsort(which.reshape(-1), kind="stable")
    bounds = np.searchsorted(which.reshape(-1)[order], np.arange(layouts.size + 1))
    for g, pf in enumerate(layouts.tolist()):
        rows = order[bounds[g] : bounds[g + 1]]
        bits = [b for b in range(32) if pf >> b & 1]
        width = N_FIXED + len(bits)
        wrong = np.flatnonzero(tok.count[rows] != width)
        if wrong.size:
            r = int(rows[wrong[0]])
            raise fail(
                f"record has {tok.count[r]} fields, its prod_flag {pf:032b} announces {width}", r
            )
        for c, bit in enumerate(bits, start=N_FIXED):
            fld = fields.get(bit)
            if fld is None:
                fld = Field(f"ahk_field_{bit}", "unknown", "f")
                if fld.name not in positional:
                    positional.append(fld.name)
            col = _gather(tok, tok.first[rows] + c)
            if fld.kind == "b":
                v = _bits(col)
            else:
                v = _convert(col, np.float64 if fld.kind == "f" else np.int64)
            if isinstance(v, int):
                kind = {"f": "not a finite number", "i": "not an integer", "b": "not 0/1 bits"}
                raise fail(f"{fld.name}: {kind[fld.kind]}: {col[v][:20]!r}", int(rows[v]))
            key = ("f:" if fld.kind == "f" else "i:") + fld.name
            if key not in out:
                out[key] = (
                    np.full(n, np.nan) if fld.kind == "f" else np.full(n, _NOT_PRESENT, np.int64)
                )
                present[fld.name] = bit
            out[key][rows] = v
    out.update(time=intg + frac * 1e-6, time_ref=cols[2], id=cols[3], qualflg=qualflg)
    return out, present, positional
