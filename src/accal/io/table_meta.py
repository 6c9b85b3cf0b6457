"""Metadata of tables: units and series description (JSON), comment lines, sidecars.

Parquet keeps them in its ``accal.units`` / ``accal.meta`` schema metadata, CSV in
``# units: {...}`` / ``# meta: {...}`` comment lines and the
``<file>-metadata.json`` sidecar (:func:`accal.io.writers.write_csv_metadata`).
The series description that :func:`accal.io.table_write.write_series` records
under :data:`META_KEY` is type-checked here.
"""

from __future__ import annotations

import contextlib
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError
from accal.io.common import one_line

#: Key of the series description in the file metadata written by :func:`write_series`.
META_KEY = "accal_series"


#: Deepest nesting of lists/objects accepted in the JSON metadata (deeper is corrupt,
#: and would overflow the stack of whatever serialises ``meta`` again).
MAX_META_DEPTH = 64


#: Fields of the ``accal_series`` metadata and the JSON type each must have.
SERIES_META_TYPES = {
    "satellite": (str, "a string"),
    "frame": (str, "a string"),
    "history": (list, "a list of strings"),
    "units": (dict, "an object of strings"),
    "aux_dtypes": (dict, "an object of strings"),
    "meta": (dict, "an object"),
}


def _too_deep(obj: Any, limit: int) -> bool:
    """True if the JSON value ``obj`` nests lists/objects more than ``limit`` levels deep."""
    stack = [(obj, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            children: Any = value.values()
        elif isinstance(value, list):
            children = value
        else:
            continue
        if depth > limit:
            return True
        stack.extend((c, depth + 1) for c in children)
    return False


def _json_object(raw: bytes | str, path: Path, line: int | None, what: str) -> dict:
    """Parse metadata JSON that must be an object; FormatError otherwise."""
    deep = False
    try:
        obj = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise FormatError(f"{what} is not valid JSON", path, line) from None
    except RecursionError:
        deep = True
    if deep or _too_deep(obj, MAX_META_DEPTH):
        raise FormatError(f"{what} is nested more than {MAX_META_DEPTH} levels deep", path, line)
    if not isinstance(obj, dict):
        raise FormatError(f"{what} is not a JSON object", path, line)
    return obj


def _json_type(value: Any) -> str:
    """The JSON name of the type of ``value``, for messages ("a number", "a list", ...)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return "a list" if isinstance(value, list) else "an object"


def _units_object(raw: bytes | str, path: Path, line: int | None, what: str) -> dict[str, str]:
    """Parse a units JSON object (column name -> unit string); FormatError otherwise."""
    units = _json_object(raw, path, line, what)
    for k, v in units.items():
        if not isinstance(v, str):
            raise FormatError(
                f"{what}: unit of {one_line(k, 40)!r} is {_json_type(v)}, not a string", path, line
            )
    return units


def _comment(line: bytes, path: Path, lineno: int, units: dict, meta: dict) -> None:
    """Parse one ``# key: value`` comment line into ``units``/``meta`` (in place)."""
    text = line.decode("utf-8", "replace").rstrip("\r\n")
    key, _, rest = text[1:].partition(":")
    key = key.strip()
    if key in ("units", "meta"):
        what = f"comment '{key}:'"
        obj = (
            _units_object(rest, path, lineno, what)
            if key == "units"
            else _json_object(rest, path, lineno, what)
        )
        target = units if key == "units" else meta
        target.clear()
        target.update(obj)


def _plain_name(path: Path) -> Path:
    """``x.csv`` for ``x.csv.gz`` (a compressed CSV's sidecar keeps the CSV's name)."""
    for suffix in (".gz", ".bz2", ".xz"):
        if path.name.lower().endswith(suffix):
            return path.with_name(path.name[: -len(suffix)])
    return path


def _series_meta(fmeta: dict, path: Path) -> dict[str, Any] | None:
    """The ``accal_series`` description in ``fmeta``, type-checked; None if there is none.

    Fields that are null are dropped (the reader's defaults apply).

    Raises
    ------
    FormatError
        A field of the wrong JSON type (see :data:`SERIES_META_TYPES`).
    """
    sm = fmeta.get(META_KEY)
    if not isinstance(sm, dict):
        return None
    out: dict[str, Any] = {}
    for key, value in sm.items():
        if value is None or key not in SERIES_META_TYPES:
            continue
        typ, expected = SERIES_META_TYPES[key]
        got = _json_type(value)
        if isinstance(value, typ):
            items = value.items() if isinstance(value, dict) else enumerate(value)
            strings = key in ("history", "units", "aux_dtypes")
            bad = next((k for k, v in items if strings and not isinstance(v, str)), None)
            if bad is None:
                out[key] = value
                continue
            which = f"{one_line(bad, 40)!r}" if isinstance(value, dict) else str(bad)
            got = f"{got} whose item {which} is {_json_type(value[bad])}"
        raise FormatError(
            f"accal metadata: {META_KEY} field {key!r} must be {expected}, got {got}", path
        )
    return out


_DTYPE_NAME = re.compile(r"[<>=|]?(?:\?|[A-Za-z][A-Za-z0-9]*)")


def _aux_dtype(name: str, spec: str, path: Path) -> np.dtype:
    """The numpy dtype ``spec`` recorded for auxiliary column ``name``, if it is numeric.

    Raises
    ------
    FormatError
        ``spec`` is not a numpy dtype, or not a bool, integer or float scalar of at
        most 64 bits (what a table column can hold).
    """
    dt: np.dtype | None = None
    # A plain type code or name only: np.dtype parses "(2,)f8" or "f8,i4" into
    # subarray/record types, and some strings ("000000002") into a SyntaxError.
    if _DTYPE_NAME.fullmatch(spec):
        with contextlib.suppress(TypeError, ValueError):
            dt = np.dtype(spec)
    if dt is None or dt.kind not in "biuf" or dt.itemsize > 8 or dt.shape:
        raise FormatError(
            f"accal metadata: aux_dtypes of {one_line(name, 40)!r} is {one_line(spec, 40)!r}, "
            "not a bool, integer or float dtype of at most 64 bits",
            path,
        )
    return dt.newbyteorder("=")
