"""Atomic writers for tables (Parquet or CSV) with units in the metadata.

Every output of accal goes through :func:`write_table`: the data are written to a
temporary file in the destination directory and renamed over the target only when
complete, so a crash or an error never leaves a partial output file.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from accal.errors import check_option

FORMATS = ("parquet", "csv")


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it to ``path`` on success.

    The temporary file is removed if the body raises, so the target is either the
    complete new file or untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; outputs follow the umask
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "item"):
        return obj.item()
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return str(obj)


def write_table(
    df: pd.DataFrame,
    path: str | Path,
    *,
    fmt: str | None = None,
    units: Mapping[str, str] | None = None,
    meta: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``df`` atomically as Parquet or CSV.

    Parameters
    ----------
    df : pandas.DataFrame
        The table (the index is not written).
    path : str or Path
        Destination file.
    fmt : {"parquet", "csv"}, optional
        Output format; default from the suffix of ``path`` (``.parquet`` or ``.csv``).
    units : mapping of str to str, optional
        Unit of each column.  Parquet: schema key-value metadata ``accal.units``
        (JSON) plus per-field metadata ``unit``.  CSV: ``# units: {...}`` comment
        line at the top.
    meta : mapping, optional
        Free metadata, stored as JSON under ``accal.meta`` (Parquet) or a
        ``# meta: {...}`` comment line (CSV).

    Returns
    -------
    Path
        The written path.
    """
    path = Path(path)
    if fmt is None:
        fmt = "csv" if path.suffix.lower() == ".csv" else "parquet"
    check_option("fmt", fmt, FORMATS)
    units = dict(units or {})
    meta_json = json.dumps(dict(meta or {}), default=_json_default, sort_keys=True)
    units_json = json.dumps(units, sort_keys=True)
    with atomic_path(path) as tmp:
        if fmt == "parquet":
            import pyarrow as pa
            import pyarrow.parquet as pq

            table = pa.Table.from_pandas(df, preserve_index=False)
            fields = [
                f.with_metadata({"unit": units[f.name]}) if f.name in units else f
                for f in table.schema
            ]
            schema = pa.schema(fields).with_metadata(
                {
                    **(table.schema.metadata or {}),
                    b"accal.units": units_json.encode(),
                    b"accal.meta": meta_json.encode(),
                }
            )
            pq.write_table(table.cast(schema), tmp)
        else:
            with open(tmp, "w", newline="") as fh:
                fh.write(f"# units: {units_json}\n")
                fh.write(f"# meta: {meta_json}\n")
                df.to_csv(fh, index=False, float_format="%.17g")
    return path


def read_table_metadata(path: str | Path) -> tuple[dict[str, str], dict[str, Any]]:
    """Return ``(units, meta)`` stored by :func:`write_table` in ``path``."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        units: dict[str, str] = {}
        meta: dict[str, Any] = {}
        with open(path) as fh:
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
