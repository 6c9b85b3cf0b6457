"""Input/output: one module per format and a small registry of (sniff, read, write).

``FORMATS`` maps a format name to its triple, as ObsPy's isFormat/readFormat/
writeFormat.  :func:`read` sniffs the file when no format is given; sniffers are
cheap (a few kB) and never raise.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from accal.errors import FormatError, check_option
from accal.io.common import GZIP_MAGIC, missing, open_error, peek, read_bytes
from accal.io.grace_l1b import read_grace_acc1b, sniff_grace_acc1b, write_grace_acc1b
from accal.io.tables import read_table_series, sniff_table, write_series
from accal.series import AccSeries

#: Format name -> (sniff(path) -> bool, read(path, **kw) -> AccSeries, write(series, path, **kw)).
FORMATS: dict[str, tuple[Callable[..., bool], Callable[..., AccSeries], Callable[..., Any]]] = {
    "grace-l1b": (sniff_grace_acc1b, read_grace_acc1b, write_grace_acc1b),
    "table": (sniff_table, read_table_series, write_series),
}


def _check_path(path: Path) -> None:
    if path.is_dir():
        raise FormatError("is a directory, not a file", path)
    if not path.exists():
        raise FormatError(missing(path), path)
    try:
        with open(path, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise open_error(exc, path) from None


def detect_format(path: str | Path) -> str:
    """Return the name of the first format in :data:`FORMATS` whose sniffer accepts ``path``.

    Raises
    ------
    FormatError
        The path is missing, a directory or unreadable, empty (``empty file``), a
        gzip stream that cannot be decompressed (``corrupt gzip stream ...``), or
        no format matches.

    Notes
    -----
    A leading UTF-8 byte-order mark does not stop sniffing (the readers skip it too).
    """
    path = Path(path)
    _check_path(path)
    for name, (sniff, _, _) in FORMATS.items():
        if sniff(path):
            return name
    _check_content(path)
    raise FormatError(
        f"format not recognised (known formats: {', '.join(FORMATS)}); name one explicitly",
        path,
    )


def _check_content(path: Path) -> None:
    """Raise the real problem of a file no sniffer accepts, if it has one (error path only).

    An empty (or blank) file and a gzip stream that cannot be decompressed are
    reported as the readers report them (:func:`accal.io.common.read_bytes`:
    ``empty file``, ``corrupt gzip stream (...)``), not as an unknown format.
    """
    head = peek(path, 4096)
    try:
        with open(path, "rb") as fh:
            gz = fh.read(2) == GZIP_MAGIC
    except OSError:
        return
    if gz or not head.strip():
        read_bytes(path)  # raises FormatError: empty file, corrupt gzip stream, too large


def read(path: str | Path, *, format: str | None = None, **kw: Any) -> AccSeries:  # noqa: A002
    """Read an accelerometer series from ``path``.

    Parameters
    ----------
    path : str or Path
        Input file.
    format : str, optional
        A key of :data:`FORMATS`; sniffed from the content when None.
    **kw
        Passed to the format's reader (e.g. ``columns={"x": "a_cal_x"}`` for tables).

    Returns
    -------
    AccSeries
        The series with the reader's findings in ``report``.

    Raises
    ------
    FormatError
        Unreadable or invalid file, or no format recognised.
    accal.errors.ValidationError
        Unknown format name (the message lists the known ones).
    """
    path = Path(path)
    if format is None:
        format = detect_format(path)
    else:
        check_option("format", format, tuple(FORMATS))
        _check_path(path)
    return FORMATS[format][1](path, **kw)


def write(series: AccSeries, path: str | Path, *, format: str, **kw: Any) -> Path:  # noqa: A002
    """Write ``series`` to ``path`` in the named format (a key of :data:`FORMATS`)."""
    check_option("format", format, tuple(FORMATS))
    return FORMATS[format][2](series, path, **kw)


__all__ = ["FORMATS", "detect_format", "read", "write"]
