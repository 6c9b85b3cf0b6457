"""Writer of accelerometer series as Parquet or CSV tables.

:func:`accal.io.table_read.read_table_series` reads them back unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import ValidationError, check_option
from accal.io.table_meta import META_KEY
from accal.io.table_read import AXIS_COLUMNS
from accal.io.writers import write_table
from accal.series import UNITS, AccSeries

_FMTS = ("parquet", "csv")


def write_series(series: AccSeries, path: str | Path, fmt: str | None = None) -> Path:
    """Write ``series`` as a Parquet or CSV table that :func:`read_table_series` reads back.

    Parameters
    ----------
    series : AccSeries
        The series.
    path : str or Path
        Output file (written atomically by :func:`accal.io.writers.write_table`).
    fmt : {"parquet", "csv"}, optional
        Default from the suffix of ``path`` (``.csv`` -> CSV, else Parquet).

    Returns
    -------
    Path
        The written path.

    Notes
    -----
    Columns: ``gps_time``, ``lin_accl_<axis>``, ``valid``, ``quality``, then the aux
    channels.  Satellite, frame, units, history and meta go to the file metadata
    under ``accal_series``; the reader restores them, so the round trip gives an
    identical series (the ``report`` describes the new read).  CSV floats are
    written with 17 significant digits (exact).
    """
    import pandas as pd

    path = Path(path)
    if fmt is None:
        fmt = "csv" if path.suffix.lower() == ".csv" else "parquet"
    check_option("fmt", fmt, _FMTS)
    reserved = {"gps_time", "valid", "quality", *(AXIS_COLUMNS[a] for a in series.axes)}
    clash = sorted(reserved & set(series.aux))
    if clash:
        raise ValidationError(f"auxiliary channel names clash with table columns: {clash}")
    data: dict[str, Any] = {"gps_time": series.time}
    for i, ax in enumerate(series.axes):
        data[AXIS_COLUMNS[ax]] = series.acc[:, i]
    data["valid"] = series.valid
    data["quality"] = series.quality.astype(np.int64)
    data.update(series.aux)
    units = {"gps_time": series.units.get("time", UNITS["time"])}
    units.update({AXIS_COLUMNS[a]: series.units.get("acc", UNITS["acc"]) for a in series.axes})
    units.update({k: series.units.get(k, "unknown") for k in series.aux})
    meta = {
        META_KEY: {
            "satellite": series.satellite,
            "frame": series.frame,
            "units": dict(series.units),
            "history": list(series.history),
            "aux_dtypes": {k: np.asarray(v).dtype.str for k, v in series.aux.items()},
            "meta": series.meta,
        }
    }
    return write_table(pd.DataFrame(data), path, fmt=fmt, units=units, meta=meta)
