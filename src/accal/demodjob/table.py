"""The per-period rows of ``accal demod`` (the ``periods`` table) and their units."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from accal.io.tables import read_table_arrow
from accal.io.writers import read_table_metadata, write_table
from accal.products.utc import utc_units, with_utc_columns

#: The period time columns, which the periods file carries in UTC too (``t_start_utc``,
#: ``t_mid_utc``: the instants when the run's time is GPS seconds since 2000-01-01
#: 12:00:00 GPS, as accal's own tables; a run timed from 0 starts at 2000-01-01T11:59:47Z).
PERIOD_TIME_COLUMNS = ("t_start", "t_mid")

PERIOD_UNITS = {
    "source": "input file name",
    "period": "index of the modulation period from the start of the run",
    "t_start": "s (first sample of the period; time origin of the input)",
    "t_mid": "s (mean sample time of the period: the epoch a_Y, a_Z and the bias refer to)",
    "a_Y": "m/s^2 (period mean of the acceleration along Y, bias removed)",
    "a_Z": "m/s^2 (period mean of the acceleration along Z, bias removed)",
    "sigma_Y": "m/s^2 (1 sigma of a_Y from the noise PSD; with signal_leak_Y in "
    "quadrature where that is significant)",
    "sigma_Z": "m/s^2 (1 sigma of a_Z from the noise PSD; with signal_leak_Z in "
    "quadrature where that is significant)",
    "signal_leak_Y": "m/s^2 (estimated leakage of the signal's in-period slope and "
    "curvature into a_Y, from the neighbouring periods; NaN: not estimable)",
    "signal_leak_Z": "m/s^2 (the same for a_Z)",
    "slope_Y": "m/s^3 (slope of a_Y within the period; affine signal model)",
    "slope_Z": "m/s^3 (slope of a_Z within the period; affine signal model)",
    "sigma_slope_Y": "m/s^3 (1 sigma)",
    "sigma_slope_Z": "m/s^3 (1 sigma)",
    "bias_y": "m/s^2 (bias of m_y at t_mid)",
    "bias_z": "m/s^2 (bias of m_z at t_mid)",
    "drift_y": "m/s^3 (bias drift of m_y)",
    "drift_z": "m/s^3 (bias drift of m_z)",
    "n_used": "unmasked samples used",
    "masked_time": "s (measured masked time of the period)",
    "leakage": "normalised eq. 16 residual, max |v'Lambda b|/(|v||Mb|) (0 = exact rejection)",
}


def period_rows(
    res: Any, source: str, units_of: dict[str, str]
) -> tuple[dict[str, Any], dict[str, str]]:
    """The per-period rows of one source (columns as numpy arrays) and their units."""
    n = res.a_Y.size
    data: dict[str, Any] = {
        "source": np.array([source] * n, dtype=object),
        "period": res.period_index.astype(np.int64),
        "t_start": res.t_start,
        "t_mid": res.t_mid,
        "a_Y": res.a_Y,
        "a_Z": res.a_Z,
        "sigma_Y": res.sigma_Y,
        "sigma_Z": res.sigma_Z,
    }
    if res.signal_model == "affine":
        for k in ("slope_Y", "slope_Z", "sigma_slope_Y", "sigma_slope_Z"):
            data[k] = getattr(res, k)
    units = {k: PERIOD_UNITS[k] for k in data}
    for j, name in enumerate(res.bias_names):
        for ax, b in (("y", res.bias_y), ("z", res.bias_z)):
            if name in ("bias", "drift"):
                col = f"{name}_{ax}"
                units[col] = PERIOD_UNITS[col]
            else:
                col = f"bias_{ax}_{name}"
                units[col] = f"m/s^2 per {units_of.get(name, 'unit')} of {name} (m_{ax})"
            data[col] = np.ascontiguousarray(b[:, j])
    leak = np.asarray(getattr(res, "signal_leak", np.empty((0, 2))))
    if leak.shape == (n, 2):
        data["signal_leak_Y"], data["signal_leak_Z"] = leak[:, 0].copy(), leak[:, 1].copy()
        units.update({k: PERIOD_UNITS[k] for k in ("signal_leak_Y", "signal_leak_Z")})
    data["n_used"] = res.n_used.astype(np.int64)
    data["masked_time"] = res.masked_time
    data["leakage"] = res.leakage
    units.update({k: PERIOD_UNITS[k] for k in ("n_used", "masked_time", "leakage")})
    return data, units


def add_utc_columns(written: Path, path: Path, fmt: str) -> None:
    """Give the periods table just merged into ``written`` its UTC columns, for every row.

    ``t_start_utc`` and ``t_mid_utc`` (:data:`PERIOD_TIME_COLUMNS`) are computed anew
    from ``t_start`` and ``t_mid`` after each merge, so the rows of a table of an older
    version, which has none, get them too; each follows its GPS-seconds column
    (``timestamp[ns, tz=UTC]`` in Parquet, ISO 8601 text in CSV:
    :func:`accal.products.utc.utc_arrow`).  The table is rewritten in place with the
    units and metadata the merge gave it.

    Parameters
    ----------
    written : Path
        The merged table (the temporary name of ``path`` that the caller renames).
    path : Path
        The periods table it becomes (its CSV sidecar holds the units and metadata).
    fmt : {"parquet", "csv"}
        Its format.
    """
    table, units, meta, _ = read_table_arrow(written)
    if fmt == "csv":  # the merge wrote the sidecar under the final name
        units, meta = read_table_metadata(path)
    columns = with_utc_columns(
        dict(zip(table.column_names, table.columns, strict=True)), PERIOD_TIME_COLUMNS, fmt
    )
    write_table(
        columns,
        written,
        fmt=fmt,
        units=utc_units(units, PERIOD_TIME_COLUMNS),
        meta=meta,
        csv_name=path if fmt == "csv" else None,
    )
