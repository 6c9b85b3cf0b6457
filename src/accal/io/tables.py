"""Reader and writer for generic tables (Parquet, CSV, optionally gzipped CSV).

A facade: the code lives in single-purpose modules, the reader
:func:`read_table_series` (and the column conventions it understands) in
:mod:`accal.io.table_read`, the writer :func:`write_series` in
:mod:`accal.io.table_write`, whole-table CSV/Parquet parsing in
:mod:`accal.io.table_parse`, column conversion and checks in
:mod:`accal.io.table_columns`, units and metadata (comment lines, sidecars, the
``accal_series`` description) in :mod:`accal.io.table_meta`, and the chunked
reader :func:`open_table` / :class:`TableStream` in :mod:`accal.io.table_stream`.
Every name this module defined before the split, public or not, is importable from
here as before.
"""

from __future__ import annotations

from accal.io.table_columns import (  # noqa: F401 (private names kept importable from here)
    _NUMBER_PATTERN,
    _UTC_TEXT_RANGE,
    FLAG_MAX,
    UTC_RANGE,
    _bad_flags,
    _bad_utc,
    _bitmask,
    _cast_aux,
    _first_non_number,
    _row_error,
    numeric_column,
    utc_column_to_gps,
)
from accal.io.table_meta import (  # noqa: F401 (private names kept importable from here)
    _DTYPE_NAME,
    MAX_META_DEPTH,
    META_KEY,
    SERIES_META_TYPES,
    _aux_dtype,
    _comment,
    _json_object,
    _json_type,
    _plain_name,
    _series_meta,
    _too_deep,
    _units_object,
)
from accal.io.table_parse import (  # noqa: F401 (private names kept importable from here)
    _column_names,
    _csv_error,
    _exc_text,
    check_single_line_values,
    check_unique_names,
    column_list,
    last_line_complete,
    read_csv_table,
    read_parquet_table,
    read_table_arrow,
)
from accal.io.table_read import (  # noqa: F401 (private names kept importable from here)
    AXIS_COLUMNS,
    SATELLITE_PATTERNS,
    TIME_COLUMNS,
    _guess_satellite,
    read_table_series,
    sniff_table,
)
from accal.io.table_stream import (  # noqa: F401 (private names kept importable from here)
    _READ_ERRORS,
    STREAM_ROWS,
    TableStream,
    _open_binary,
    _read_failed,
    open_table,
)
from accal.io.table_write import (  # noqa: F401 (private names kept importable from here)
    _FMTS,
    write_series,
)

__all__ = [
    "AXIS_COLUMNS",
    "FLAG_MAX",
    "MAX_META_DEPTH",
    "META_KEY",
    "SATELLITE_PATTERNS",
    "SERIES_META_TYPES",
    "STREAM_ROWS",
    "TIME_COLUMNS",
    "TableStream",
    "UTC_RANGE",
    "check_single_line_values",
    "check_unique_names",
    "column_list",
    "last_line_complete",
    "numeric_column",
    "open_table",
    "read_csv_table",
    "read_parquet_table",
    "read_table_arrow",
    "read_table_series",
    "sniff_table",
    "utc_column_to_gps",
    "write_series",
]
