"""Cumulative tables: merge new rows into a table that accumulates over runs.

``accal grace-bias`` keeps ``bias_drift.<fmt>`` and ``accal demod`` keeps
``periods.<fmt>``: one table per output directory, to which every run adds its
rows.  Rows are keyed (``source`` and whatever else identifies a row); a re-run
replaces the rows of its keys, never duplicates them.  The table is rewritten
atomically (:func:`accal.io.writers.write_table`), so a crash leaves either the
old or the new table.

Generic on purpose: any columns, Parquet or CSV, and a schema that may grow
(a new column is null in the older rows; a column left entirely null by a
replacement is dropped).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import ValidationError
from accal.io.common import arrow_to_numpy
from accal.io.tables import read_table_arrow
from accal.io.writers import arrow_column, write_table

__all__ = ["as_arrow_table", "merge_table", "sort_rows"]


def as_arrow_table(data: Any) -> Any:
    """A pyarrow Table from a Table or a mapping of columns (numpy arrays, lists of str).

    Built from buffers (:func:`accal.io.writers.arrow_column`), so pandas is not imported.
    """
    import pyarrow as pa

    if isinstance(data, pa.Table):
        return data
    if isinstance(data, Mapping):
        return pa.Table.from_arrays(
            [arrow_column(np.asarray(v)) for v in data.values()], names=[str(k) for k in data]
        )
    raise TypeError(f"expected a pyarrow Table or a mapping of columns, got {type(data)}")


def _sort_key(col: Any) -> np.ndarray:
    import pyarrow as pa

    if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
        # buffers, not to_numpy: pyarrow's conversion imports pandas (~0.4 s per run)
        return arrow_to_numpy(col.cast(pa.float64()))
    return np.array(["" if v is None else str(v) for v in col.to_pylist()], dtype=str)


def sort_rows(table: Any, columns: Sequence[str]) -> Any:
    """Rows of ``table`` sorted by ``columns`` (first column first; numbers numerically).

    Uses numpy's ``lexsort`` and ``Table.take``.
    """

    cols = [c for c in columns if c in table.column_names]
    if not cols or table.num_rows < 2:
        return table
    order = np.lexsort([_sort_key(table.column(c)) for c in reversed(cols)])
    return table.take(arrow_column(order.astype(np.int64)))


def _keys(table: Any, key: Sequence[str]) -> list[tuple]:
    return list(zip(*(table.column(k).to_pylist() for k in key), strict=True))


def merge_table(
    path: str | Path,
    new: Any,
    *,
    key: Sequence[str],
    sort: Sequence[str] = (),
    fmt: str | None = None,
    units: Mapping[str, str] | None = None,
    meta: Mapping[str, Any] | Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
    out: str | Path | None = None,
) -> Path:
    """Merge ``new`` rows into the cumulative table at ``path`` and write it atomically.

    Parameters
    ----------
    path : str or Path
        The cumulative table (Parquet or CSV written by accal); created if missing.
    new : pyarrow.Table or mapping of str to array
        Rows to add.
    key : sequence of str
        Columns identifying a row's owner, e.g. ``("source",)``: every existing row
        whose key values occur in ``new`` is removed first (a re-run replaces its
        rows, even when it has fewer of them).
    sort : sequence of str
        Columns to sort the result by.
    fmt : {"parquet", "csv"}, optional
        Output format; default from the suffix.
    units : mapping, optional
        Units of the new columns; merged over the existing table's units.
    meta : mapping or callable, optional
        The table's metadata, or a function of the existing metadata (``{}`` if
        there is no table yet) returning it.
    out : str or Path, optional
        Where to write (default ``path``), e.g. a temporary file that the caller
        renames together with other outputs.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValidationError
        The existing table lacks a key column.
    FormatError
        The existing table cannot be read.
    """
    import pyarrow as pa

    path = Path(path)
    table = as_arrow_table(new)
    missing = [k for k in key if k not in table.column_names]
    if missing:
        raise ValidationError(f"new rows lack the key column(s) {', '.join(missing)}")
    old_units: dict[str, str] = {}
    old_meta: dict[str, Any] = {}
    if path.exists():
        old, old_units, old_meta, _ = read_table_arrow(path)
        absent = [k for k in key if k not in old.column_names]
        if absent:
            raise ValidationError(
                f"{path}: existing table has no {', '.join(absent)} column to merge on "
                "(written by another command or an older accal?); move it away"
            )
        replaced = set(_keys(table, key))
        keep = np.array([k not in replaced for k in _keys(old, key)], dtype=bool)
        old = old.take(arrow_column(np.flatnonzero(keep).astype(np.int64)))
        table = pa.concat_tables([old, table], promote_options="permissive")
        empty = [
            n
            for n, c in zip(table.column_names, table.columns, strict=True)
            if c.null_count == len(c) and len(c)
        ]
        if empty:
            table = table.drop_columns(empty)
    table = sort_rows(table, sort)
    all_units = {**old_units, **dict(units or {})}
    all_units = {k: v for k, v in all_units.items() if k in table.column_names}
    md = meta(dict(old_meta)) if callable(meta) else dict(meta or {})
    return write_table(
        table, out or path, fmt=fmt, units=all_units, meta=md, csv_name=path if out else None
    )
