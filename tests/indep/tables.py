"""Writer of Parquet / CSV tables with units in the metadata (pyarrow only, no ``accal``).

The layout is the one accal's table reader understands (read from
``src/accal/io/tables.py`` and ``writers.py`` to match the format, not imported):

* a time column ``gps_time`` or ``time`` (GPS seconds since 2000-01-01 12:00:00, or run
  seconds for a rotating-platform run) or ``time_utc`` (a Parquet timestamp column, naive
  = UTC, or ISO-8601 strings in CSV);
* numeric columns;
* units: Parquet schema key-value metadata ``accal.units`` (a JSON object column → unit)
  plus a per-field ``unit`` metadata entry; CSV: a first comment line
  ``# units: {...}`` (and ``# meta: {...}`` for free metadata).
"""

from __future__ import annotations

import gzip
import io
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

#: Formats and the suffixes that select them.
SUFFIXES = {".parquet": "parquet", ".pq": "parquet", ".csv": "csv", ".gz": "csv.gz"}


def _format_of(path: Path, fmt: str | None) -> str:
    if fmt is not None:
        if fmt not in ("parquet", "csv", "csv.gz"):
            raise ValueError(f"fmt: expected 'parquet', 'csv' or 'csv.gz', got {fmt!r}")
        return fmt
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(
            f"path: expected a name ending in .parquet, .pq, .csv or .csv.gz, got {path.name!r}"
        )
    return SUFFIXES[suffix]


def _column(name: str, values: Any, text_time: bool) -> Any:
    import pyarrow as pa

    arr = np.asarray(values)
    if arr.dtype.kind == "M":
        if text_time:
            iso = np.datetime_as_string(arr.astype("datetime64[ms]"), unit="ms")
            return pa.array(iso.tolist(), pa.string())
        return pa.array(arr)
    if arr.dtype.kind in "USO":
        return pa.array([str(v) for v in arr.tolist()], pa.string())
    return pa.array(arr)


def write_table(
    path: str | Path,
    columns: Mapping[str, Any],
    units: Mapping[str, str] | None = None,
    *,
    meta: Mapping[str, Any] | None = None,
    fmt: str | None = None,
) -> Path:
    """Write columns as a Parquet or CSV table with their units in the metadata.

    Parameters
    ----------
    path : str or Path
        Output file; ``.parquet``/``.pq`` → Parquet, ``.csv`` → CSV, ``.csv.gz`` → gzipped
        CSV (unless ``fmt`` says otherwise).  Parent directories are created.
    columns : mapping of str to array-like, or pandas.DataFrame
        Column name → values, in order.  ``datetime64`` columns (e.g. ``time_utc``) become
        Parquet timestamps (naive, UTC) or ISO-8601 strings in CSV; strings stay strings.
    units : mapping of str to str, optional
        Unit of each column (e.g. ``{"gps_time": "s", "a_cal_x": "m/s^2"}``).
    meta : mapping, optional
        Free metadata (JSON-serialisable), stored as ``accal.meta`` / ``# meta:``.
    fmt : {"parquet", "csv", "csv.gz"}, optional
        Overrides the suffix.

    Returns
    -------
    Path

    Notes
    -----
    Floats are written at full precision: Parquet stores the doubles, and pyarrow's CSV
    writer prints the shortest representation that reads back to the same double.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    path = Path(path)
    kind = _format_of(path, fmt)
    units_json = json.dumps(dict(units or {}), sort_keys=True)
    meta_json = json.dumps(dict(meta or {}), sort_keys=True, default=str)
    if hasattr(columns, "columns") and hasattr(columns, "to_dict"):  # a DataFrame
        columns = {str(c): columns[c].to_numpy() for c in columns.columns}
    text = kind != "parquet"
    arrays = [_column(k, v, text) for k, v in columns.items()]
    table = pa.Table.from_arrays(arrays, names=[str(k) for k in columns])
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "parquet":
        fields = [
            f.with_metadata({"unit": units[f.name]}) if units and f.name in units else f
            for f in table.schema
        ]
        md = {b"accal.units": units_json.encode()}
        if meta:
            md[b"accal.meta"] = meta_json.encode()
        schema = pa.schema(fields).with_metadata(md)
        pq.write_table(pa.Table.from_arrays(table.columns, schema=schema), path)
        return path
    buf = io.BytesIO()
    buf.write(f"# units: {units_json}\n".encode())
    if meta:
        buf.write(f"# meta: {meta_json}\n".encode())
    pacsv.write_csv(table, buf, pacsv.WriteOptions(quoting_style="needed"))
    data = buf.getvalue()
    if kind == "csv.gz":
        data = gzip.compress(data, compresslevel=6, mtime=0)
    path.write_bytes(data)
    return path


def read_units(path: str | Path) -> dict[str, str]:
    """The units written by :func:`write_table` (Parquet metadata or the ``# units:`` line)."""
    path = Path(path)
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic == b"PAR1":
        import pyarrow.parquet as pq

        md = pq.read_schema(path).metadata or {}
        return json.loads(md.get(b"accal.units", b"{}"))
    opener = gzip.open if magic[:2] == b"\x1f\x8b" else open
    with opener(path, "rt") as fh:
        for line in fh:
            if not line.startswith("#"):
                break
            key, _, rest = line[1:].partition(":")
            if key.strip() == "units":
                return json.loads(rest)
    return {}
