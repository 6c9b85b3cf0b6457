"""Writing a table chunk by chunk (Parquet or CSV), atomically.

For outputs too large to hold in memory at once, e.g. a simulated year of 1 Hz
data: the chunks go to a temporary file next to the target, renamed over it only
when the writer is closed without an error (:func:`accal.io.writers.atomic_path`).
The file layout is :func:`accal.io.writers.write_table`'s: units in the
``accal.units`` schema metadata and per-field ``unit`` (Parquet) or the CSV's
``<file>-metadata.json`` sidecar, free metadata in ``accal.meta`` / the sidecar.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from accal.errors import check_option
from accal.io.merge import as_arrow_table
from accal.io.writers import FORMATS, _json_default, atomic_path, write_csv_metadata

__all__ = ["ChunkedTableWriter", "chunked_table_writer"]


class ChunkedTableWriter:
    """Append chunks (mappings of equal-length columns) to an open table file.

    Every chunk must have the columns and types of the first.
    """

    def __init__(
        self, tmp: Path, fmt: str, units: Mapping[str, str], meta: Mapping[str, Any]
    ) -> None:
        self.tmp, self.fmt = tmp, fmt
        self.units = dict(units)
        self.meta_json = json.dumps(dict(meta), default=_json_default, sort_keys=True)
        self.units_json = json.dumps(self.units, sort_keys=True)
        self._writer: Any = None
        self._fh: Any = None
        self.schema: Any = None
        self.rows = 0

    def write(self, chunk: Mapping[str, Any]) -> None:
        """Append one chunk."""
        import pyarrow as pa

        table = as_arrow_table(chunk)
        if self._writer is None:
            # units of the columns present only (as write_table's callers do)
            self.units = {k: v for k, v in self.units.items() if k in table.column_names}
            self.units_json = json.dumps(self.units, sort_keys=True)
            if self.fmt == "parquet":
                import pyarrow.parquet as pq

                fields = [
                    f.with_metadata({"unit": self.units[f.name]}) if f.name in self.units else f
                    for f in table.schema
                ]
                self.schema = pa.schema(fields).with_metadata(
                    {
                        b"accal.units": self.units_json.encode(),
                        b"accal.meta": self.meta_json.encode(),
                    }
                )
                dict_cols = [f.name for f in table.schema if not pa.types.is_floating(f.type)]
                self._writer = pq.ParquetWriter(self.tmp, self.schema, use_dictionary=dict_cols)
            else:
                import pyarrow.csv as pacsv

                self._fh = open(self.tmp, "wb")  # noqa: SIM115 (closed in close())
                self.schema = table.schema
                self._writer = pacsv.CSVWriter(self._fh, table.schema)
        self._writer.write_table(pa.Table.from_arrays(table.columns, schema=self.schema))
        self.rows += table.num_rows

    def close(self) -> None:
        """Finish the file (called by :func:`chunked_table_writer`)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self._fh is not None:
            self._fh.close()
            self._fh = None


@contextlib.contextmanager
def chunked_table_writer(
    path: str | Path,
    *,
    fmt: str | None = None,
    units: Mapping[str, str] | None = None,
    meta: Mapping[str, Any] | None = None,
) -> Iterator[ChunkedTableWriter]:
    """Open ``path`` for writing a table chunk by chunk; atomic on success.

    Parameters
    ----------
    path : str or Path
        Destination.
    fmt : {"parquet", "csv"}, optional
        Default from the suffix (``.csv`` or Parquet).
    units, meta : mapping, optional
        As :func:`accal.io.writers.write_table`.

    Yields
    ------
    ChunkedTableWriter
        Call ``write(chunk)`` for each chunk; the file appears at ``path`` when the
        ``with`` block ends without an error, and not at all otherwise.
    """
    path = Path(path)
    if fmt is None:
        fmt = "csv" if path.suffix.lower() == ".csv" else "parquet"
    check_option("fmt", fmt, FORMATS)
    with atomic_path(path) as tmp:
        w = ChunkedTableWriter(tmp, fmt, units or {}, meta or {})
        try:
            yield w
        finally:
            w.close()
    if fmt == "csv":  # the units and metadata beside the CSV (write_table's convention)
        names = list(w.schema.names) if w.schema is not None else []
        write_csv_metadata(path, names, w.units, json.loads(w.meta_json))
