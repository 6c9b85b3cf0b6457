"""Reader and writer for GRACE / GRACE-FO Level-1B accelerometer files (ACC1B, ACT1B).

A facade: the code lives in the sub-package :mod:`accal.io.grace` (the format
specification in :mod:`accal.io.grace.spec`, headers in
:mod:`accal.io.grace.header`, records in :mod:`accal.io.grace.ascii` and
:mod:`accal.io.grace.binary`, their checks in :mod:`accal.io.grace.checks`, the
reader :func:`read_grace_acc1b` in :mod:`accal.io.grace.acc`, the writer
:func:`write_grace_acc1b` in :mod:`accal.io.grace.writer`).  Every public name this
module defined before the split is importable from here as before; the private
helpers are the sub-package's own.
"""

from __future__ import annotations

from accal.io.grace.acc import read_grace_acc1b
from accal.io.grace.ascii import LOOSE_LAYOUT
from accal.io.grace.checks import HEADER_SPAN_TOLERANCE
from accal.io.grace.header import (
    L1B_SIZE_FLOOR,
    MAX_RECORD_BYTES,
    grace_int,
    header_satellite,
    load_yaml_header,
    parse_grace_header,
    read_l1b_bytes,
    refuse_binary,
    sniff_grace_acc1b,
    split_header,
)
from accal.io.grace.spec import (
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
)
from accal.io.grace.writer import calendar_text, write_grace_acc1b, yaml_header_lines

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
    "grace_int",
    "header_satellite",
    "load_yaml_header",
    "parse_grace_header",
    "read_grace_acc1b",
    "read_l1b_bytes",
    "refuse_binary",
    "sniff_grace_acc1b",
    "split_header",
    "write_grace_acc1b",
    "yaml_header_lines",
]
