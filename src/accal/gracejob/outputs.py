"""The per-input files of ``accal grace-bias``: names, calibrated columns, JSON.

:func:`output_stem` names an input's outputs, :func:`calibrated_frame` (in memory),
:func:`calibrated_file_columns` (with ``time_utc``) and :data:`CALIBRATED_UNITS` are
the columns of ``<stem>.calibrated.<fmt>``, and
:func:`write_json` writes the standard JSON of ``<stem>.report.json`` (non-finite
floats as null, atomically).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from accal.io.writers import atomic_path, json_default
from accal.products.utc import utc_unit, with_utc_columns
from accal.series import AccSeries

#: Name endings of the calibrated series files (``<stem>.calibrated.<fmt>``).
CALIBRATED_SUFFIXES = (".calibrated.parquet", ".calibrated.csv")

#: The GPS-seconds column of the calibrated series, which the files carry in UTC too.
CALIBRATED_TIME_COLUMNS = ("gps_time",)

CALIBRATED_UNITS = {
    "gps_time": "s (GPS seconds since 2000-01-01 12:00:00)",
    "time_utc": utc_unit("gps_time"),
    "lin_accl_x": "m/s^2 (trend removed, scale applied)",
    "lin_accl_y": "m/s^2 (trend removed, scale applied)",
    "lin_accl_z": "m/s^2 (trend removed, scale applied)",
    "valid": "True where the sample was used in the fit",
    "qualflg": "source quality bitmask (bit 0 = LSB)",
}


def output_stem(path: Path) -> str:
    """Input name without compression and format suffixes (``x.asc.gz`` → ``x``)."""
    name = path.name
    for suffix in (".gz", ".bz2", ".xz"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    stem = Path(name).stem
    return stem or name


def calibrated_frame(series: AccSeries, use: np.ndarray) -> dict[str, np.ndarray]:
    """The calibrated series as columns (``gps_time``, ``lin_accl_*``, ``valid``, ``qualflg``)."""
    data: dict[str, Any] = {"gps_time": series.time}
    for ax in series.axes:
        data[f"lin_accl_{ax}"] = series.axis(ax)
    data["valid"] = use
    data["qualflg"] = series.quality
    return data


def calibrated_file_columns(series: AccSeries, use: np.ndarray, fmt: str) -> dict[str, Any]:
    """The columns of ``<stem>.calibrated.<fmt>``: :func:`calibrated_frame` and ``time_utc``.

    Parameters
    ----------
    series : AccSeries
        The calibrated series.
    use : ndarray of bool
        The samples used in the fit (``valid``).
    fmt : {"parquet", "csv"}
        The file format: ``time_utc`` is ``timestamp[ns, tz=UTC]`` in Parquet, ISO 8601
        text in CSV (:func:`accal.products.utc.utc_arrow`).

    Returns
    -------
    dict of str to array
        ``gps_time``, ``time_utc``, ``lin_accl_*``, ``valid``, ``qualflg``.
    """
    return with_utc_columns(calibrated_frame(series, use), CALIBRATED_TIME_COLUMNS, fmt)


def file_size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def write_json(path: Path, obj: Any, *, sync: bool = True) -> None:
    with atomic_path(path, sync=sync) as tmp:
        tmp.write_text(json.dumps(nan_to_none(obj), indent=2, default=json_default) + "\n")


def nan_to_none(obj: Any) -> Any:
    """Replace non-finite floats by None so the JSON is standard (no NaN literals)."""
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [nan_to_none(v) for v in obj]
    return obj
