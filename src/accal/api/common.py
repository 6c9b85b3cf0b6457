"""Reading and the helpers every result shares: UTC instants, CF datasets, units.

Part of :mod:`accal.api` (see its docstring); split from one module for size.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal import __version__
from accal.errors import ValidationError
from accal.pipeline import GraceBiasOptions, name_mismatch, read_input
from accal.plausibility import flag_wild_samples
from accal.series import AccSeries
from accal.timescale import gps_to_utc

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    import pandas as pd
    import xarray as xr


#: History entry :func:`read` leaves (the input's name: ``source`` of :func:`fit_bias`).
READ_ENTRY = f"accal {__version__}: read("

#: accal's unit texts → CF-style (UDUNITS) units, as ``to_xarray`` writes them.
CF_UNITS = {"m/s^2": "m s-2", "m/s^3": "m s-3", "m/s^4": "m s-4", "s": "s", "rad": "rad", "K": "K"}

#: Long names of the calibrated series' columns.
CALIBRATED_LONG_NAMES = {
    "gps_time": "GPS seconds since 2000-01-01 12:00:00 GPS",
    "lin_accl_x": "calibrated linear acceleration, x axis (trend removed, scale applied)",
    "lin_accl_y": "calibrated linear acceleration, y axis (trend removed, scale applied)",
    "lin_accl_z": "calibrated linear acceleration, z axis (trend removed, scale applied)",
    "valid": "sample used in the fit",
    "qualflg": "source quality bitmask (bit 0 = LSB)",
}

#: Per-(method, axis) estimates of :meth:`BiasFit.to_xarray`: (units, long name).
ESTIMATE_VARIABLES = {
    "bias": ("m s-2", "bias: trend value at t0 (raw-data sign, a_raw = s*a + bias + drift*(t-t0))"),
    "bias_sigma": ("m s-2", "1 sigma of the bias (coloured-noise aware)"),
    "drift": ("m s-3", "bias drift"),
    "drift_sigma": ("m s-3", "1 sigma of the drift"),
    "bias_drift_corr": ("1", "correlation coefficient of bias and drift"),
    "t0": ("s", "GPS seconds of the first sample used"),
    "rms": ("m s-2", "residual RMS after removing the trend"),
    "scale": ("1", "scale applied to the calibrated series"),
}
#: ... and with ``order=2``.
QUADRATIC_VARIABLES = {
    "quadratic": ("m s-4", "quadratic term of the trend"),
    "quadratic_sigma": ("m s-4", "1 sigma of the quadratic term"),
}


def read(
    path: str | Path,
    *,
    columns: Mapping[str, str] | None = None,
    format: str | None = None,  # noqa: A002 (the CLI's --input-format)
) -> AccSeries:
    """Read an accelerometer file as ``accal grace-bias`` reads it.

    GRACE/GRACE-FO Level-1B ACC1B and ACT1B files (ASCII, YAML-headed, gzip) and
    tables (CSV, Parquet: Swarm ACCACAL, ``accal simulate`` references, ...).  As
    the command line, it then flags samples too far from their axis' median to be
    accelerometer data invalid (:func:`accal.plausibility.flag_wild_samples`) and
    appends to the read report's warnings what the file name and the content
    disagree on.

    Parameters
    ----------
    path : str or Path
        The input file.
    columns : mapping of str to str, optional
        Axis → table column (the CLI's ``--column x=a_cal_x``); for tables only.
    format : {"grace-l1b", "table"}, optional
        Force the format (the CLI's ``--input-format``); sniffed by default.

    Returns
    -------
    AccSeries
        Time in GPS seconds, accelerations in m/s², ``valid``/``quality`` flags,
        auxiliary channels with their units, the reader's findings in ``report``.

    Raises
    ------
    accal.errors.AccalError
        A missing, unreadable or malformed file (the message names it and the line).

    Examples
    --------
    >>> import accal
    >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
    >>> day.satellite, day.axes, len(day)
    ('GRACE-A', ('x', 'y', 'z'), 60)
    >>> swarm = accal.read(
    ...     "data/samples/SW_A_ACCACAL_20240511_a_cal_x.csv.gz", columns={"x": "a_cal_x"}
    ... )
    >>> swarm.satellite, swarm.axes, len(swarm), swarm.units["acc"]
    ('Swarm-A', ('x',), 86400, 'm/s^2')
    """
    path = Path(path)
    opts = GraceBiasOptions(columns=dict(columns or {}), input_format=format)
    series = read_input(path, opts)
    if len(series) == 0:
        raise ValidationError(f"{path}: no data records")
    series, wild = flag_wild_samples(series)
    warnings = (*series.report.warnings, *name_mismatch(path, series), *wild)
    series = series.replace(report=dataclasses.replace(series.report, warnings=warnings))
    return series.with_history(f"{READ_ENTRY}{path.name})")


def source_of(series: AccSeries, default: str = "series") -> str:
    """The input name :func:`read` recorded in ``series.history`` (``default`` if none)."""
    for entry in series.history:
        if entry.startswith(READ_ENTRY) and entry.endswith(")"):
            return entry[len(READ_ENTRY) : -1]
    return default


def utc_instants(gps: NDArray[np.float64]) -> NDArray[np.datetime64]:
    """GPS seconds as UTC instants (naive ``datetime64[ns]``), rounded to the microsecond.

    A float64 GPS time of ~7e8 s carries ~0.1 µs of rounding (``2024-05-11
    00:00:00.796000004``); the instants are rounded to the microsecond, the
    resolution of the L1B time stamps.  The exact value stays in ``gps_time``.
    """
    ns = gps_to_utc(gps).astype(np.int64)
    return ((ns + 500) // 1000 * 1000).astype("datetime64[ns]")


def gps_to_utc_index(gps: NDArray[np.float64], name: str = "time_utc") -> pd.DatetimeIndex:
    """GPS seconds as a UTC (time-zone aware) :class:`pandas.DatetimeIndex` (see
    :func:`utc_instants`)."""
    import pandas as pd

    return pd.DatetimeIndex(utc_instants(gps), name=name).tz_localize("UTC")


def cf_dataset(data_vars: dict[str, Any], coords: dict[str, Any], **attrs: Any) -> xr.Dataset:
    """An :class:`xarray.Dataset` with the provenance every result carries in its attributes
    (CF ``Conventions``, accal version, then ``attrs``; netCDF-friendly: strings and numbers)."""
    import xarray as xr

    meta: dict[str, Any] = {"Conventions": "CF-1.8", "accal_version": __version__}
    meta.update({k: v for k, v in attrs.items() if v is not None and v != ""})
    return xr.Dataset(data_vars, coords=coords, attrs=meta)
