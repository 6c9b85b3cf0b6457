"""Reader of housekeeping from a generic table (CSV or Parquet) into :class:`Housekeeping`.

A ``gps_time`` or ``time`` column [s, GPS] (or ``time_utc``) and numeric channel
columns; units from the CSV's ``-metadata.json`` sidecar or ``# units:`` lines, or
``accal.units`` metadata.  Voltages and currents declared with an SI prefix are
converted to V and A (:data:`SI_PREFIXED`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from accal.errors import AccalError, FormatError
from accal.io.common import PARQUET_MAGIC, check_gps_time
from accal.io.hk_data import Housekeeping, _listing, _sort_merge
from accal.io.table_columns import numeric_column, utc_column_to_gps
from accal.io.table_parse import read_csv_table, read_parquet_table
from accal.series import UNITS

#: Time columns of a generic table, in order of preference (GPS seconds, GPS seconds, UTC).
TIME_COLUMNS = ("gps_time", "time", "time_utc")


#: Declared table units converted to SI: unit -> (factor, SI unit).
SI_PREFIXED = {
    f"{p}{u}": (s, u)
    for u in ("V", "A")
    for p, s in (("n", 1e-9), ("u", 1e-6), ("µ", 1e-6), ("μ", 1e-6), ("m", 1e-3), ("k", 1e3))
}


def _to_si(values: NDArray[np.float64], unit: str) -> tuple[NDArray[np.float64], str]:
    """Convert a prefixed voltage or current (mV, µA, ...) to V or A."""
    key = unit.strip()
    if key in SI_PREFIXED:
        factor, si = SI_PREFIXED[key]
        with np.errstate(over="ignore"):  # |x| > 1.8e305 kV is inf V
            return values * factor, si
    return values, unit


def read_hk_table(raw: bytes, path: Path) -> Housekeeping:
    reader = read_parquet_table if raw.startswith(PARQUET_MAGIC) else read_csv_table
    try:
        table, units, fmeta, first_line = reader(raw, path)
    except AccalError:
        raise
    except ValueError as exc:  # e.g. metadata that is not UTF-8 (UnicodeDecodeError)
        raise FormatError(f"corrupt table ({type(exc).__name__})", path) from None
    names = list(table.column_names)
    if table.num_rows == 0:
        raise FormatError("header but no data rows", path, first_line or None)
    tname = next((c for c in TIME_COLUMNS if c in names), None)
    if tname is None:
        raise FormatError(
            "no time column (gps_time or time [s GPS], or time_utc); "
            f"columns are {_listing(names)}",
            path,
        )
    line_of = (lambda i: first_line + i) if first_line else None
    tcol = table.column(tname)
    if tname == "time_utc":
        time = utc_column_to_gps(tcol, tname, path, line_of)
    else:
        time = numeric_column(tcol, tname, path, line_of, locate=True).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        line = first_line + int(bad[0]) if first_line else None
        raise FormatError(f"{tname}: missing or non-finite time", path, line)
    check_gps_time(time, path, line_of, name=tname, unit="row")
    units = units if isinstance(units, dict) else {}
    channels: dict[str, NDArray[np.float64]] = {}
    col_units = {"time": UNITS["time"]}
    converted, skipped = {}, []
    for name in names:
        if name == tname:
            continue
        try:
            values = numeric_column(table.column(name), name, path).astype(np.float64)
        except FormatError:
            skipped.append(name)
            continue
        declared = str(units.get(name, "unknown"))
        values, unit = _to_si(values, declared)
        if unit != declared:
            converted[name] = f"{declared} -> {unit}"
        channels[name] = values
        col_units[name] = unit
    if not channels:
        raise FormatError(
            f"no numeric channel besides {tname!r}; columns are {_listing(names)}", path
        )
    warn = [f"non-numeric columns ignored: {_listing(skipped)}"] if skipped else []
    n_rows = int(time.size)
    time, channels, _, more = _sort_merge(time, channels, {})
    meta = {
        "table": {"time_column": tname, "file_meta": fmeta},
        "housekeeping": {"format": "table", "converted_units": converted, "n_rows": n_rows},
    }
    return Housekeeping(
        time=time, channels=channels, units=col_units, meta=meta, warnings=tuple(warn + more)
    )
