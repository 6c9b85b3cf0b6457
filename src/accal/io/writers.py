"""Atomic writers for tables (Parquet or CSV) with units in the metadata.

Every output of accal goes through :func:`write_table`: the data are written to a
temporary file in the destination directory and renamed over the target only when
complete, so a crash or an error never leaves a partial output file.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from accal._runtime import libc
from accal.errors import AccalError, check_option

FORMATS = ("parquet", "csv")
#: In the name of every temporary file accal writes (``.NAME.accal-XXXXXXXX.tmp``), so
#: that the clean-up after a killed run removes accal's temporaries only (issue 23:
#: every ``.*.tmp`` of the output directory went, other programs' too).
TEMP_MARK = "accal-"


class RunSuperseded(AccalError):
    """A later run holds the output directory: this (orphaned) task must not write."""


#: (lock file, token) of the run whose task this process is doing (:func:`run_guard`).
_RUN_GUARD: tuple[Path, str] | None = None


@contextlib.contextmanager
def run_guard(lock_path: str | Path | None, token: str | None) -> Iterator[None]:
    """Let :func:`atomic_path` rename into the lock's directory only while ``token`` holds it.

    A batch task (a worker process, a Dask task) runs under the guard of the run that
    submitted it.  Each rename of an output into that directory first checks that the
    lock file still names ``token``: when the submitting run was killed and a later run
    took the lock, the orphaned task's outputs are dropped (:class:`RunSuperseded`)
    instead of overwriting the later run's (issue 23, finding 1).
    """
    global _RUN_GUARD
    before = _RUN_GUARD
    _RUN_GUARD = None if lock_path is None or token is None else (Path(lock_path), token)
    try:
        yield
    finally:
        _RUN_GUARD = before


def _check_run(path: Path) -> None:
    if _RUN_GUARD is None:
        return
    lock, token = _RUN_GUARD
    if os.path.realpath(path.parent) != os.path.realpath(lock.parent):
        return
    try:
        holder = lock.read_text(errors="replace")
    except OSError:
        holder = ""
    if f"run {token}" not in holder:
        raise RunSuperseded(
            f"{lock.parent}: a later accal run holds this output directory; {path.name} of "
            "this task of an earlier (interrupted) run is dropped"
        )


@contextlib.contextmanager
def atomic_path(path: str | Path, *, sync: bool = True) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it to ``path`` on success.

    The temporary file is removed if the body raises, so the target is either the
    complete new file or untouched (also when the process is killed: the rename
    is atomic).  With ``sync`` (default) the data is flushed to disk (``fsync``)
    before the rename, so it also survives a power loss; a batch that writes many
    files passes ``sync=False`` and makes them durable together with
    :func:`sync_files` before it records them.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:  # a component of the directory is a file
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(path.parent)) from None
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{path.name}.{TEMP_MARK}", suffix=".tmp", dir=path.parent
        )
    except OSError as exc:  # name the file asked for, not the temporary's random name
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; outputs follow the umask
    try:
        yield tmp_path
        if sync:
            with open(tmp_path, "rb+") as fh:
                os.fsync(fh.fileno())
        _check_run(path)
        try:
            os.replace(tmp_path, path)
        except OSError as exc:  # name the file asked for, not the temporary (issue 23)
            raise OSError(exc.errno, exc.strerror, str(path)) from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def sync_files(paths: Iterable[str | Path]) -> None:
    """Make files written with ``atomic_path(..., sync=False)`` durable.

    On Linux one ``syncfs`` per file system flushes them all at once (the cost of
    one ``fsync`` instead of one per file, which on a spinning disk is ~10 ms
    each); elsewhere each file and its directory is ``fsync``-ed.  Files that no
    longer exist are skipped.
    """
    paths = [Path(p) for p in paths]
    syncfs = _libc_syncfs()
    done: set[int] = set()
    dirs: set[Path] = set()
    for p in paths:
        try:
            st = p.stat()
        except OSError:
            continue
        if syncfs is not None:
            if st.st_dev in done:
                continue
            fd = os.open(p, os.O_RDONLY)
            try:
                if syncfs(fd) == 0:
                    done.add(st.st_dev)
                    continue
            finally:
                os.close(fd)
        fd = os.open(p, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        dirs.add(p.parent)
    for d in dirs:
        with contextlib.suppress(OSError):
            fd = os.open(d, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)


def _libc_syncfs() -> Any:
    """``syncfs(2)`` from the C library, or None where it is not available."""
    fn = getattr(libc(), "syncfs", None)
    if fn is not None:
        fn.argtypes = (ctypes.c_int,)
        fn.restype = ctypes.c_int
    return fn


def json_default(obj: Any) -> Any:
    if hasattr(obj, "item"):
        return obj.item()
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return str(obj)


_json_default = json_default  # the old name (accal.io.chunked, earlier callers)


def arrow_column(values: Any) -> Any:
    """A numpy array or list of str as an Arrow array, built from buffers.

    ``pa.array`` and ``pa.table`` import pandas on first use (~0.3 s, most of a
    one-file run); building from buffers does not.  Floats keep NaN as a value.
    """
    import pyarrow as pa

    if isinstance(values, pa.Array | pa.ChunkedArray):
        return values
    arr = np.asarray(values)
    n = arr.shape[0]
    if arr.dtype.kind == "b":
        bits = np.packbits(arr.astype(bool), bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), n, [None, pa.py_buffer(bits)])
    if arr.dtype.kind in "iuf":
        arr = np.ascontiguousarray(arr)
        typ = pa.from_numpy_dtype(arr.dtype)
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(arr)])
    if arr.dtype.kind in "USO":
        enc = [str(v).encode() for v in arr.tolist()]
        offsets = np.zeros(n + 1, dtype=np.int32)
        np.cumsum([len(e) for e in enc], out=offsets[1:])
        return pa.Array.from_buffers(
            pa.string(), n, [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(enc))]
        )
    return pa.array(arr)


def _as_arrow(data: Any) -> Any:
    """Convert a pyarrow Table, a mapping of columns or a pandas DataFrame to a Table."""
    import pyarrow as pa

    if isinstance(data, pa.Table):
        return data
    if isinstance(data, Mapping):
        return pa.Table.from_arrays(
            [arrow_column(v) for v in data.values()], names=[str(k) for k in data]
        )
    if hasattr(data, "to_dict") and hasattr(data, "columns"):  # pandas, without importing it
        return pa.Table.from_pandas(data, preserve_index=False)
    raise TypeError(
        f"expected a pyarrow Table, a mapping of columns or a DataFrame, got {type(data)}"
    )


def write_table(
    data: Any,
    path: str | Path,
    *,
    fmt: str | None = None,
    units: Mapping[str, str] | None = None,
    meta: Mapping[str, Any] | None = None,
    sync: bool = True,
    required: bool = False,
    csv_name: str | Path | None = None,
) -> Path:
    """Write a table atomically as Parquet or CSV.

    Parameters
    ----------
    data : pyarrow.Table, mapping of str to array, or pandas.DataFrame
        The table (a DataFrame's index is not written).
    path : str or Path
        Destination file.
    fmt : {"parquet", "csv"}, optional
        Output format; default from the suffix of ``path`` (``.csv`` or Parquet).
    units : mapping of str to str, optional
        Unit of each column.  Parquet: schema key-value metadata ``accal.units``
        (JSON) plus per-field metadata ``unit``.  CSV: the sidecar
        ``<file>-metadata.json`` (:func:`write_csv_metadata`), so that the CSV itself
        is a plain header line and rows that ``pandas.read_csv``, R and spreadsheets
        read with their defaults.
    meta : mapping, optional
        Free metadata, stored as JSON under ``accal.meta`` (Parquet) or in the CSV's
        sidecar.
    sync : bool
        ``fsync`` before the rename (see :func:`atomic_path`).
    required : bool
        Parquet: declare the columns that hold no null non-nullable (Parquet
        ``REQUIRED``: no definition levels to encode; ~0.5 ms less per calibrated
        1 Hz day, same values).  For tables that are written once, not for those
        merged with later rows, whose nulls would then not fit the schema.
    csv_name : str or Path, optional
        CSV: the file the sidecar describes when ``path`` is a temporary name that an
        outer :func:`atomic_path` renames (default ``path``).

    Returns
    -------
    Path
        The written path.

    Notes
    -----
    Both formats are written by pyarrow (no pandas import on the main path);
    CSV floats use the shortest representation that round-trips exactly.
    """
    import pyarrow as pa

    path = Path(path)
    if fmt is None:
        fmt = "csv" if path.suffix.lower() == ".csv" else "parquet"
    check_option("fmt", fmt, FORMATS)
    units = dict(units or {})
    meta_json = json.dumps(dict(meta or {}), default=json_default, sort_keys=True)
    units_json = json.dumps(units, sort_keys=True)
    table = _as_arrow(data)
    with atomic_path(path, sync=sync) as tmp:
        if fmt == "parquet":
            import pyarrow.parquet as pq

            fields = [
                f.with_metadata({"unit": units[f.name]}) if f.name in units else f
                for f in table.schema
            ]
            if required:
                fields = [
                    f.with_nullable(False) if table.column(f.name).null_count == 0 else f
                    for f in fields
                ]
            schema = pa.schema(fields).with_metadata(
                {
                    **(table.schema.metadata or {}),
                    b"accal.units": units_json.encode(),
                    b"accal.meta": meta_json.encode(),
                }
            )
            # dictionary-encoding float columns costs ~8x the write time for no gain;
            # byte-stream-split floats compress: a 1 Hz calibrated day is 1.6 MB
            # instead of 2.4 MB, at the same write time.  Only text columns are
            # dictionary-encoded: flags and booleans compress as well without it.
            floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
            texts = [
                f.name
                for f in table.schema
                if pa.types.is_string(f.type)
                or pa.types.is_large_string(f.type)
                or pa.types.is_binary(f.type)
                or pa.types.is_large_binary(f.type)
            ]
            pq.write_table(
                pa.Table.from_arrays(table.columns, schema=schema),
                tmp,
                use_dictionary=texts or False,
                use_byte_stream_split=floats or False,
            )
        else:
            import pyarrow.csv as pacsv

            with open(tmp, "wb") as fh:
                pacsv.write_csv(table, fh)
    if fmt == "csv":
        name = Path(csv_name) if csv_name is not None else path
        write_csv_metadata(name, table.column_names, units, json.loads(meta_json), sync=sync)
    return path


def csv_metadata_path(path: str | Path) -> Path:
    """The metadata sidecar of a CSV file: ``<file>-metadata.json`` (the CSV on the Web
    convention for a table's metadata document, W3C 2015)."""
    path = Path(path)
    return path.with_name(path.name + "-metadata.json")


def write_csv_metadata(
    path: str | Path,
    columns: Iterable[str],
    units: Mapping[str, str],
    meta: Mapping[str, Any],
    *,
    sync: bool = True,
) -> Path:
    """Write the sidecar of the CSV ``path`` (atomically): a CSVW metadata document
    (W3C, "Metadata Vocabulary for Tabular Data", 2015) whose columns carry their
    unit (``accal:unit``), with ``accal:units`` and ``accal:meta`` as
    :func:`read_table_metadata` returns them."""
    path = Path(path)
    doc = {
        "@context": "http://www.w3.org/ns/csvw",
        "url": path.name,
        "tableSchema": {
            "columns": [
                {"name": c, "titles": c, **({"accal:unit": units[c]} if c in units else {})}
                for c in columns
            ]
        },
        "accal:units": dict(units),
        "accal:meta": dict(meta),
    }
    out = csv_metadata_path(path)
    with atomic_path(out, sync=sync) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, default=json_default) + "\n")
    return out


def read_csv_metadata(path: str | Path) -> tuple[dict[str, str], dict[str, Any]] | None:
    """``(units, meta)`` of the sidecar of the CSV ``path``; None without one (or an
    unreadable one: the data stand without their units)."""
    side = csv_metadata_path(path)
    try:
        doc = json.loads(side.read_text())
    except (OSError, ValueError):
        return None
    units, meta = doc.get("accal:units", {}), doc.get("accal:meta", {})
    if not isinstance(units, dict) or not isinstance(meta, dict):
        return None
    return {str(k): str(v) for k, v in units.items()}, meta


def read_table_metadata(path: str | Path) -> tuple[dict[str, str], dict[str, Any]]:
    """Return ``(units, meta)`` stored by :func:`write_table` in ``path``."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        side = read_csv_metadata(path)
        if side is not None:
            return side
        units: dict[str, str] = {}
        meta: dict[str, Any] = {}
        with open(path) as fh:  # written before the sidecar: comment lines
            for line in fh:
                if not line.startswith("#"):
                    break
                key, _, rest = line[1:].partition(":")
                if key.strip() == "units":
                    units = json.loads(rest)
                elif key.strip() == "meta":
                    meta = json.loads(rest)
        return units, meta
    import pyarrow.parquet as pq

    md = pq.read_schema(path).metadata or {}
    return (
        json.loads(md.get(b"accal.units", b"{}")),
        json.loads(md.get(b"accal.meta", b"{}")),
    )
