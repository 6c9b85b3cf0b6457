"""Reader and writer for GRACE / GRACE-FO Level-1B accelerometer files (ACC1B, ACT1B).

A facade: the code lives in the sub-package :mod:`accal.io.grace` (the format
specification in :mod:`accal.io.grace.spec`, headers in
:mod:`accal.io.grace.header`, records in :mod:`accal.io.grace.ascii` and
:mod:`accal.io.grace.binary`, their checks in :mod:`accal.io.grace.checks`, the
reader :func:`read_grace_acc1b` in :mod:`accal.io.grace.acc`, the writer
:func:`write_grace_acc1b` in :mod:`accal.io.grace.writer`).  Every name this module
defined before the split, public or not, is importable from here as before.
"""

from __future__ import annotations

from accal.io.grace.acc import read_grace_acc1b
from accal.io.grace.ascii import (  # noqa: F401 (private names kept importable from here)
    _BLANK_LINE,
    _BLANKS,
    _EDGE_BLANK,
    _LIN_ACCL,
    _NON_SPACE,
    _NUMBER_RE,
    LOOSE_LAYOUT,
    _check_last_line,
    _field_names,
    _locate_bad_line,
    _loose_table,
    _parse_ascii,
    _respaced,
)
from accal.io.grace.binary import (  # noqa: F401 (private names kept importable from here)
    _binary_records,
    _little_endian,
    _parse_binary,
)
from accal.io.grace.checks import (  # noqa: F401 (private names kept importable from here)
    _ID_LOOKUP,
    HEADER_SPAN_TOLERANCE,
    _check_header_span,
    _check_ids,
    _name_day,
    _name_letter,
)
from accal.io.grace.header import (  # noqa: F401 (private names kept importable from here)
    _GRACE_END_RE,
    _GRACE_KEY_RE,
    _GRACEFO_END_RE,
    _HEADER_SEARCH,
    _RECORD_COUNT_RE,
    _SNIFF_BYTES,
    L1B_SIZE_FLOOR,
    MAX_RECORD_BYTES,
    _header_time,
    _interpret_grace,
    _interpret_gracefo,
    _record_count,
    _span,
    _yaml,
    _yaml_line,
    grace_int,
    header_satellite,
    load_yaml_header,
    parse_grace_header,
    read_l1b_bytes,
    refuse_binary,
    sniff_grace_acc1b,
    split_header,
)
from accal.io.grace.spec import (  # noqa: F401 (private names kept importable from here)
    AUX_COLUMNS,
    BINARY_DTYPE,
    COLUMN_UNITS,
    COLUMNS,
    DEFAULT_INVALID_BITS,
    DTYPES,
    GRACE_KEY_WIDTH,
    GRACEFO_COLUMNS,
    HEADER_END,
    QUALFLG_BITS,
    SATELLITES,
    TIME_RANGE,
    YAML_MAX_DEPTH,
    _unit,
)
from accal.io.grace.writer import (  # noqa: F401 (private names kept importable from here)
    _ORDINAL,
    _calendar,
    _format_floats,
    _grace_header,
    _gracefo_header,
    calendar_text,
    write_grace_acc1b,
    yaml_header_lines,
)

__all__ = [
    "AUX_COLUMNS",
    "BINARY_DTYPE",
    "COLUMNS",
    "COLUMN_UNITS",
    "DEFAULT_INVALID_BITS",
    "DTYPES",
    "GRACEFO_COLUMNS",
    "GRACE_KEY_WIDTH",
    "HEADER_END",
    "HEADER_SPAN_TOLERANCE",
    "L1B_SIZE_FLOOR",
    "LOOSE_LAYOUT",
    "MAX_RECORD_BYTES",
    "QUALFLG_BITS",
    "SATELLITES",
    "TIME_RANGE",
    "YAML_MAX_DEPTH",
    "calendar_text",
    "header_satellite",
    "load_yaml_header",
    "read_grace_acc1b",
    "read_l1b_bytes",
    "refuse_binary",
    "sniff_grace_acc1b",
    "write_grace_acc1b",
    "yaml_header_lines",
]
