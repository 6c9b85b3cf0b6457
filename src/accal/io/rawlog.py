"""Reader of rotating-platform run files (``accal demod`` input) and of PSD tables.

A run file is a Parquet or CSV (optionally gzipped) table with the columns below;
every other numeric column is an auxiliary channel (a temperature, a current, ...)
carried in :attr:`AccSeries.aux` with its unit from the file metadata.  The parsing
itself is :mod:`accal.io.tables`' (comment header, ``# units:`` / ``# meta:``
lines, Parquet ``accal.units`` metadata); this module only fixes the column
names, the units and the checks that belong to the file.

The reader normalises and checks, it does not repair: time must be finite and
strictly increasing (a run file is not sorted or de-duplicated behind the user's
back), and a θ column whose declared unit is degrees is refused.  Checks that
need the modulation period (uniform sampling, θ range, masking) are made by the
demodulation, see :mod:`accal.estimators.demod`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accal.errors import FormatError
from accal.io._common import PARQUET_MAGIC, read_bytes
from accal.io.tables import _numeric, _read_csv, _read_parquet
from accal.series import AccSeries, ReadReport

#: Columns every run file must have.
REQUIRED_COLUMNS = ("time", "m_y", "m_z", "theta")
#: Optional accelerometer column (the axis along the rotation axis).
OPTIONAL_COLUMNS = ("m_x",)
#: Units of the fixed columns (SI; θ in radians).
UNITS = {
    "time": "s (run time, origin as in the file)",
    "acc": "m/s^2",
    "theta": "rad",
}
#: Declared units of θ that mean degrees (refused: give radians).
DEGREE_UNITS = ("deg", "degree", "degrees", "°")
#: Columns of a PSD table (``--psd FILE``): frequency [Hz] and two-sided PSD [m² s⁻⁴ Hz⁻¹].
PSD_COLUMNS = ("f", "S")


def _read_any(path: Path):
    raw = read_bytes(path)
    if raw.startswith(PARQUET_MAGIC):
        return _read_parquet(raw, path)
    return _read_csv(raw, path)


def read_rawlog(path: str | Path) -> AccSeries:
    """Read a rotating-platform run file.

    Parameters
    ----------
    path : str or Path
        Parquet, CSV or gzipped CSV table with ``time`` [s], ``m_y``, ``m_z``
        [m s⁻²], ``theta`` [rad], optional ``m_x`` [m s⁻²]; other numeric
        columns are auxiliary channels.

    Returns
    -------
    AccSeries
        ``acc`` holds the columns ``(m_x,) m_y, m_z`` with ``axes`` ``("x",) "y", "z"``
        in the platform frame (``frame="platform"``); ``aux["theta"]`` is the
        platform angle [rad]; the other channels follow in ``aux``.  ``meta["rawlog"]``
        keeps the file's own metadata; ``units`` the declared units.

    Raises
    ------
    FormatError
        Unreadable or corrupt file, missing columns (all listed), non-numeric
        columns, non-finite or not strictly increasing time, θ declared in degrees.
    """
    path = Path(path)
    table, units, fmeta, first_line = _read_any(path)
    names = list(table.column_names)
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        raise FormatError(
            f"missing column(s) {', '.join(missing)} (need {', '.join(REQUIRED_COLUMNS)}; "
            f"columns are {', '.join(names) or 'none'})",
            path,
        )
    if table.num_rows == 0:
        raise FormatError("header but no data rows", path, first_line or None)
    th_unit = str(units.get("theta", "rad")).strip().lower()
    if th_unit.split(" ")[0] in DEGREE_UNITS:
        raise FormatError(f"theta is declared in {units['theta']!r}; give it in radians", path)
    cols = {c: _numeric(table.column(c), c, path).astype(np.float64) for c in REQUIRED_COLUMNS}
    time = cols["time"]
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise FormatError("time: missing or non-finite value", path, _line(first_line, bad[0]))
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise FormatError(
            f"time is not strictly increasing: {time[i]:.9g} s after {time[i - 1]:.9g} s "
            f"({back.size} such step(s))",
            path,
            _line(first_line, i),
        )
    axes, acc = [], []
    if "m_x" in names:
        axes.append("x")
        acc.append(_numeric(table.column("m_x"), "m_x", path).astype(np.float64))
    axes += ["y", "z"]
    acc += [cols["m_y"], cols["m_z"]]
    aux = {"theta": cols["theta"]}
    skipped = []
    for name in names:
        if name in aux or name in REQUIRED_COLUMNS or name in OPTIONAL_COLUMNS:
            continue
        try:
            aux[name] = _numeric(table.column(name), name, path)
        except FormatError:
            skipped.append(name)
    warnings = (f"non-numeric columns ignored: {', '.join(skipped)}",) if skipped else ()
    step = np.diff(time)
    report = ReadReport(
        n_rows=int(time.size),
        nominal_step=float(np.median(step)) if step.size else float("nan"),
        warnings=warnings,
    )
    col_units = dict(UNITS)
    col_units["acc"] = units.get("m_y", UNITS["acc"])
    col_units.update({k: units.get(k, "unknown") for k in aux if k != "theta"})
    return AccSeries(
        time=time,
        acc=np.column_stack(acc),
        axes=tuple(axes),
        aux=aux,
        frame="platform",
        units=col_units,
        meta={"rawlog": {"file_meta": fmeta, "columns": names}},
        report=report,
    )


def _line(first_line: int, row: int) -> int | None:
    # CSV: 1-based line of data row ``row``; Parquet has no lines (first_line = 0)
    return first_line + int(row) if first_line else None


def read_psd(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a noise PSD table (``--psd FILE``): CSV or Parquet with columns ``f``, ``S``.

    Parameters
    ----------
    path : str or Path
        Table with ``f`` [Hz] (positive, increasing) and ``S``, the two-sided PSD
        [m² s⁻⁴ Hz⁻¹].

    Returns
    -------
    f, S : ndarray
        The columns; :class:`accal.estimators.noise.TabulatedPSD` checks their values.

    Raises
    ------
    FormatError
        Unreadable file, missing or non-numeric columns.
    """
    path = Path(path)
    table, _, _, _ = _read_any(path)
    names = list(table.column_names)
    missing = [c for c in PSD_COLUMNS if c not in names]
    if missing:
        raise FormatError(
            f"PSD table: missing column(s) {', '.join(missing)} (need f [Hz], S [m^2 s^-4 Hz^-1]; "
            f"columns are {', '.join(names)})",
            path,
        )
    return tuple(_numeric(table.column(c), c, path).astype(np.float64) for c in PSD_COLUMNS)
