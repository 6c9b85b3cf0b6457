"""The cumulative bias/drift table of an output directory, filtered, printed or exported.

What ``accal table`` does with the table (:mod:`accal.cli.table` parses the options
and reports errors): select rows by satellite, date, method, axis and day status,
pick columns, write the rows to a file or format them for a terminal.  A directory of
``accal demod`` (no ``bias_drift`` table, a ``periods`` table) is read too: its rows
are printed or exported whole (the filters are the bias/drift table's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from accal import __version__
from accal.api import cf_dataset, table_variables
from accal.batch import MANIFEST
from accal.errors import ValidationError
from accal.io.tables import read_table_arrow
from accal.io.writers import atomic_path, write_table
from accal.pipeline import BIAS_DRIFT_UNITS, find_bias_drift, read_bias_drift
from accal.products.utc import instants_arrow, utc_units, with_utc_columns

#: Suffixes ``--export`` writes, and the format of each.
EXPORT_FORMATS = {".csv": "csv", ".parquet": "parquet", ".nc": "netcdf"}

#: Columns printed when none are asked for (``day_status`` and ``model`` when present).
PRINTED_COLUMNS = (
    "source", "satellite", "date", "axis", "method", "bias", "bias_sigma",
    "drift", "drift_sigma", "n", "rms",
)  # fmt: skip
OPTIONAL_PRINTED_COLUMNS = ("day_status", "model")
#: ... and of a demod ``periods`` table.
PERIODS_PRINTED_COLUMNS = (
    "source", "period", "t_mid_utc", "a_Y", "a_Z", "sigma_Y", "sigma_Z", "leakage",
)  # fmt: skip
#: The GPS-seconds columns of a demod ``periods`` table (:mod:`accal.demodjob.table`).
PERIOD_TIME_COLUMNS = ("t_start", "t_mid")


def load(directory: Path, *, periods: bool = False) -> tuple[Path, pd.DataFrame]:
    """The cumulative table of an output directory and the file it was read from.

    Parameters
    ----------
    directory : Path
        An ``accal grace-bias`` output directory.
    periods : bool
        Read the ``periods`` table of an ``accal demod`` directory when there is no
        ``bias_drift`` table (``accal table``; ``accal plot`` wants a bias_drift table).

    Returns
    -------
    path : Path
        ``DIRECTORY/bias_drift.parquet`` or ``.csv``; with ``periods``, in an ``accal
        demod`` directory, ``DIRECTORY/periods.parquet`` or ``.csv``.
    table : pandas.DataFrame
        Its rows; the units of its columns in ``table.attrs["units"]``.

    Raises
    ------
    accal.errors.AccalError
        No table, or one that cannot be read.
    """
    try:
        path = find_bias_drift(directory)
    except ValidationError:
        found = [Path(directory) / f"periods.{f}" for f in ("parquet", "csv")]
        found = [p for p in found if p.exists()]
        if not periods or not found:
            raise
        return found[0], read_periods(found[0])
    table = read_bias_drift(path)
    table.attrs["units"] = {c: BIAS_DRIFT_UNITS.get(c, "") for c in table.columns}
    return path, table


def is_periods(path: Path) -> bool:
    """Whether :func:`load` read a demod ``periods`` table (not a ``bias_drift`` one)."""
    return path.name.startswith("periods.")


def read_periods(path: Path) -> pd.DataFrame:
    """A demod ``periods`` table, with ``t_start_utc``/``t_mid_utc`` (UTC, time-zone aware).

    The UTC columns are computed from ``t_start``/``t_mid`` (also for a table of an
    earlier version, which has none); units in ``attrs["units"]``.

    Raises
    ------
    accal.errors.FormatError
        The table cannot be read.
    """
    arrow, units, _, _ = read_table_arrow(path)
    columns = {c: arrow.column(c).to_pandas() for c in arrow.column_names}
    instants = with_utc_columns(columns, PERIOD_TIME_COLUMNS, "parquet")
    table = pd.DataFrame({c: _as_series(v) for c, v in instants.items()})
    table.attrs["units"] = utc_units(units, PERIOD_TIME_COLUMNS)
    return table


def _as_series(values: object) -> pd.Series:
    if isinstance(values, pd.Series):
        return values
    return values.to_pandas()  # a pyarrow array: a UTC column


def short_satellite(name: str) -> str:
    """The letter a satellite is known by in the table's rows.

    Parameters
    ----------
    name : str
        ``GRACE-A``, ``grace-a``, ``a``, ``GRACE-FO-C``, ...

    Returns
    -------
    str
        ``A`` for the first three, ``C`` for the last; other names in upper case.
    """
    return name.upper().removeprefix("GRACE-FO-").removeprefix("GRACE-")


def _short_names(table: pd.DataFrame) -> pd.Series:
    return table["satellite"].astype(str).str.upper().str.split("-").str[-1]


def held_satellites(table: pd.DataFrame) -> list[str]:
    """The satellites of the table's rows, sorted, as written (``GRACE-A``).

    Parameters
    ----------
    table : pandas.DataFrame
        The cumulative table.

    Returns
    -------
    list of str
        Each satellite once.
    """
    return sorted(set(table["satellite"].astype(str)))


def unknown_satellites(table: pd.DataFrame, satellites: Sequence[str]) -> list[str]:
    """The ``satellites`` asked for that no row of ``table`` has, in the order given.

    A satellite is known by its full name (``GRACE-A``) or its letter in any case
    (``a``, ``grace-a``): a typo would otherwise select nothing, silently.

    Parameters
    ----------
    table : pandas.DataFrame
        The cumulative table.
    satellites : sequence of str
        The satellites asked for.

    Returns
    -------
    list of str
        Those not in the table (empty when all are).
    """
    known = set(_short_names(table)) | set(held_satellites(table))
    return [s for s in satellites if short_satellite(s) not in known and s not in known]


def select_rows(
    table: pd.DataFrame,
    *,
    satellites: Sequence[str] = (),
    start: str | None = None,
    end: str | None = None,
    methods: Sequence[str] = (),
    axes: Sequence[str] = (),
    statuses: Sequence[str] = (),
) -> pd.DataFrame:
    """The rows that match every filter given (an empty filter keeps everything).

    Parameters
    ----------
    table : pandas.DataFrame
        The cumulative table.
    satellites : sequence of str
        Full names or letters, any case.
    start, end : str or None
        First and last day kept, ``YYYY-MM-DD``.
    methods, axes : sequence of str
        Estimators (``wavelet``, ``lsq``) and axes (``x``, ``y``, ``z``), any case.
    statuses : sequence of str
        Day statuses (``nominal``, ``degraded``, ``transplant``, ``off``).

    Returns
    -------
    pandas.DataFrame
        The rows kept, in the table's order.
    """
    keep = np.ones(len(table), dtype=bool)
    if satellites:
        want = {short_satellite(s) for s in satellites}
        keep &= (
            _short_names(table).isin(want).to_numpy()
            | table["satellite"].isin(satellites).to_numpy()
        )
    if start:
        keep &= (table["date"] >= start).to_numpy()
    if end:
        keep &= (table["date"] <= end).to_numpy()
    if methods:
        keep &= table["method"].isin([m.lower() for m in methods]).to_numpy()
    if axes:
        keep &= table["axis"].isin([a.lower() for a in axes]).to_numpy()
    if statuses:
        keep &= table["day_status"].isin(statuses).to_numpy()
    return table[keep]


def column_names(table: pd.DataFrame) -> list[str]:
    """The table's columns, in order.

    Parameters
    ----------
    table : pandas.DataFrame
        The (selected) table.

    Returns
    -------
    list of str
        Its column names.
    """
    return [str(c) for c in table.columns]


def export_conflict(export: Path) -> str | None:
    """Why ``export`` may not be written, or None.

    QA: ``accal table OUT --export OUT/bias_drift.parquet --satellite B`` replaced
    the cumulative table with B's rows; the next runs skipped A's inputs as current,
    so their rows were lost until ``--force``.  A ``bias_drift.csv`` beside a
    Parquet table made every later run refuse the directory.  A missing directory
    is refused too, not created (a typo in the path would go unnoticed).

    Parameters
    ----------
    export : Path
        The file asked for.

    Returns
    -------
    str or None
        The one-line message, or None when the file may be written.
    """
    parent = export.parent
    if not parent.is_dir():
        return f"--export {export}: directory {parent} does not exist"
    stem = export.name.lower().rsplit(".", 1)[0]
    if stem in ("bias_drift", "periods") and (
        (parent / MANIFEST).exists() or any(parent.glob(f"{stem}.*"))
    ):
        return (
            f"--export {export} is the name of the cumulative table of the output "
            f"directory {parent}; export to another name or directory"
        )
    return None


def export_rows(
    table: pd.DataFrame,
    export: Path,
    source: Path,
    columns: Sequence[str] | None = None,
    units: Mapping[str, str] | None = None,
) -> None:
    """Write rows to ``export``, atomically, with units: Parquet, CSV or netCDF.

    ``.parquet`` → Parquet, ``.nc`` → netCDF (:func:`write_netcdf`), else CSV.  A UTC
    column (``t0_utc``) is ``timestamp[ns, tz=UTC]`` in Parquet and ISO 8601 text in
    CSV, as in the table itself.

    Parameters
    ----------
    table : pandas.DataFrame
        The rows.
    export : Path
        The file written.
    source : Path
        The table they come from (``exported_from`` in the file's metadata).
    columns : sequence of str, optional
        The columns written (default: all).
    units : mapping of str to str, optional
        The unit texts of the columns (default: :data:`BIAS_DRIFT_UNITS`).
    """
    if columns:
        table = table[list(columns)]
    fmt = EXPORT_FORMATS.get(export.suffix.lower(), "csv")
    known = BIAS_DRIFT_UNITS if units is None else units
    units = {c: known.get(c, "") for c in table.columns}
    if fmt == "netcdf":
        write_netcdf(table, export, units, source)
        return
    write_table(
        {c: _file_column(table[c], fmt) for c in table.columns},
        export,
        fmt=fmt,
        units=units,
        meta={"exported_from": str(source)},
    )


def _file_column(column: pd.Series, fmt: str) -> object:
    """A column as written: numpy values, or a UTC column as :func:`instants_arrow` makes it."""
    if isinstance(column.dtype, pd.DatetimeTZDtype):
        return instants_arrow(column.dt.tz_convert(None).to_numpy(dtype="datetime64[ns]"), fmt)
    return column.to_numpy()


def write_netcdf(table: pd.DataFrame, export: Path, units: dict[str, str], source: Path) -> None:
    """Write rows as a CF netCDF file (netCDF 3, 64-bit offsets: xarray's scipy engine).

    One dimension ``row``; each column a variable with CF ``units`` (numbers) and its
    accal unit text as ``long_name`` (:func:`accal.api.table_variables`, as
    :meth:`accal.Demodulation.to_xarray`); a UTC column (``t0_utc``) is a time
    coordinate (CF ``microseconds since 1970-01-01``, float64: netCDF 3 has no 64-bit
    integers); the provenance (``Conventions``, accal version, the table exported,
    ``history``) in the global attributes.  Integer columns are stored as 32-bit
    integers (netCDF 3).

    Parameters
    ----------
    table : pandas.DataFrame
        The rows.
    export : Path
        The ``.nc`` file, written atomically.
    units : dict of str to str
        accal's unit text of each column.
    source : Path
        The table the rows come from.
    """
    coords: dict[str, object] = {"row": ("row", np.arange(len(table), dtype=np.int32))}
    columns = {c: table[c] for c in table.columns}
    data_vars = table_variables(columns, units, "row", coords=coords)
    for name, (dim, values, attrs) in list(data_vars.items()):
        if values.dtype.kind == "O":  # text: fixed-width str, which netCDF 3 stores as chars
            data_vars[name] = (dim, values.astype(str), attrs)
        elif values.dtype.kind in "iu":
            data_vars[name] = (dim, values.astype(np.int32), attrs)
    ds = cf_dataset(
        data_vars,
        coords,
        title=f"accal {source.name.split('.')[0]} table: {len(table)} rows of {source}",
        exported_from=str(source),
        history=f"accal {__version__}: accal table --export {export.name}",
    )
    times = [n for n, v in ds.variables.items() if v.dtype.kind == "M"]
    encoding = {
        n: {"units": "microseconds since 1970-01-01 00:00:00", "dtype": "float64"} for n in times
    }
    with atomic_path(export) as tmp:
        ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT", encoding=encoding)


def table_text(table: pd.DataFrame, columns: Sequence[str] | None = None) -> str:
    """The rows as a terminal table (``(no rows)`` when there are none).

    Parameters
    ----------
    table : pandas.DataFrame
        The rows.
    columns : sequence of str, optional
        The columns shown (default: :data:`PRINTED_COLUMNS` and those of
        :data:`OPTIONAL_PRINTED_COLUMNS` the table has; for a demod ``periods``
        table those of :data:`PERIODS_PRINTED_COLUMNS` it has).

    Returns
    -------
    str
        One line a row under a header, numbers to 6 significant digits.
    """
    if not columns and "a_Y" in table.columns:
        columns = [c for c in PERIODS_PRINTED_COLUMNS if c in table.columns]
    elif not columns:
        columns = [*PRINTED_COLUMNS]
        columns += [c for c in OPTIONAL_PRINTED_COLUMNS if c in table.columns]
    table = table[list(columns)]
    with pd.option_context("display.width", 250, "display.max_rows", None):
        text = table.to_string(index=False, float_format=lambda v: f"{v:.6g}")
    return text if len(table) else "(no rows)"
