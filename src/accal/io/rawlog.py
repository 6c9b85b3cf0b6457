"""Reader of rotating-platform run files (``accal demod`` input) and of PSD tables.

A run file is a Parquet or CSV (optionally gzipped) table with the columns below;
every other numeric column is an auxiliary channel (a temperature, a current, ...)
carried in :attr:`AccSeries.aux` with its unit from the file metadata.  The parsing
itself is :mod:`accal.io.tables`' (a CSV's ``-metadata.json`` sidecar or comment
header, ``# units:`` / ``# meta:`` lines, Parquet ``accal.units`` metadata); this module only fixes the column
names, the units and the checks that belong to the file.

The reader normalises and checks, it does not repair: time must be finite and
strictly increasing (a run file is not sorted or de-duplicated behind the user's
back).  Columns declared in a non-SI unit (m_y in g, θ in degrees, time in ms)
are converted to SI with a warning, and a unit accal does not know is refused
(:mod:`accal.io.units`).  Checks that
need the modulation period (uniform sampling, θ range, masking) are made by the
demodulation, see :mod:`accal.estimators.demod`.

Two entry points: :func:`read_rawlog` reads a whole file into an
:class:`~accal.series.AccSeries`; :func:`open_rawlog` reads it in chunks of a
bounded number of rows (a year of 1 Hz data in a few hundred MB), with the same
checks carried across chunk borders.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError
from accal.io.common import implausible, implausible_message
from accal.io.tables import (
    STREAM_ROWS,
    TableStream,
    column_list,
    numeric_column,
    read_table_arrow,
)
from accal.io.units import SI, known_units, si_factor
from accal.series import AccSeries, ReadReport

#: Columns every run file must have.
REQUIRED_COLUMNS = ("time", "m_y", "m_z", "theta")
#: Largest |θ| accepted [rad]: 1.6 million turns, over 30 years of a platform turning
#: every 10 minutes with θ unwrapped (where float64 still resolves 2e-9 rad).  A
#: larger value is damage: θ = -1e308 on ten samples had only been masked and moved
#: its period by 2.5 σ (issue 23, the mutation fuzzer).
MAX_ABS_THETA = 1e7
#: Optional accelerometer column (the axis along the rotation axis).
OPTIONAL_COLUMNS = ("m_x",)
#: Units of the fixed columns (SI; θ in radians).
UNITS = {
    "time": "s (run time, origin as in the file)",
    "acc": "m/s^2",
    "theta": "rad",
}
#: Kind of unit of each fixed column: a declared non-SI unit is converted
#: (:mod:`accal.io.units`), an unknown one refused.
COLUMN_KINDS = {
    "time": "time",
    "m_x": "acceleration",
    "m_y": "acceleration",
    "m_z": "acceleration",
    "theta": "angle",
}
#: File-name suffixes that promise Parquet, and text (a mismatch is a warning).
PARQUET_SUFFIXES = (".parquet", ".pq")
TEXT_SUFFIXES = (".csv", ".txt")
#: Columns of a PSD table (``--psd FILE``): frequency [Hz] and two-sided PSD [m² s⁻⁴ Hz⁻¹].
PSD_COLUMNS = ("f", "S")


@dataclass(frozen=True)
class RawlogChunk:
    """Consecutive rows of a run file.

    Attributes
    ----------
    first_row : int
        0-based index of the chunk's first data row in the file.
    time : ndarray, shape (n,)
        [s], finite and strictly increasing (also across chunks).
    acc : ndarray, shape (n, k)
        ``(m_x,) m_y, m_z`` [m s⁻²], columns in the order of :attr:`RawlogStream.axes`.
    theta : ndarray, shape (n,)
        Platform angle [rad].
    aux : dict of str to ndarray
        The other numeric channels.
    axes : tuple of str
        ``("x",) "y", "z"``.
    """

    first_row: int
    time: NDArray[np.float64]
    acc: NDArray[np.float64]
    theta: NDArray[np.float64]
    aux: dict[str, NDArray] = field(default_factory=dict)
    axes: tuple[str, ...] = ("y", "z")

    def __len__(self) -> int:
        return int(self.time.size)

    def axis(self, name: str) -> NDArray[np.float64]:
        """Column of ``acc`` for axis ``name`` [m s⁻²]."""
        return self.acc[:, self.axes.index(name)]


class RawlogStream:
    """A run file opened for reading in chunks (see :func:`open_rawlog`).

    Attributes
    ----------
    path : Path
        The file.
    names : list of str
        Its columns.
    axes : tuple of str
        Accelerometer axes present: ``("x",) "y", "z"``.
    units : dict
        Units as in :attr:`AccSeries.units`: ``time``, ``acc``, ``theta``, and one
        per other column (``"unknown"`` when the file does not say).
    file_meta : dict
        The file's own metadata.
    warnings : list of str
        Findings: a name that says another format than the content
        (:func:`name_mismatch`), and of the last pass (non-numeric columns ignored).
    """

    def __init__(
        self, path: str | Path, rows: int | None = STREAM_ROWS, *, threads: bool = True
    ) -> None:
        self.path = Path(path)
        self.rows = rows
        if rows is None:
            self._whole = read_table_arrow(self.path)
            table, units, fmeta, first_line = self._whole
            names = list(table.column_names)
        else:
            self._stream = TableStream(self.path, rows=rows, threads=threads)
            units, fmeta = self._stream.units, self._stream.meta
            names, first_line = list(self._stream.names), self._stream.first_line
        missing = [c for c in REQUIRED_COLUMNS if c not in names]
        if missing:
            raise FormatError(
                f"missing column(s) {', '.join(missing)} (need {', '.join(REQUIRED_COLUMNS)}; "
                f"columns are {column_list(names)})",
                self.path,
            )
        #: Factor to SI of each fixed column whose declared unit is not SI.
        self.factors: dict[str, float] = {}
        #: The units the file declares, as written.
        self.declared_units: dict[str, str] = {k: str(v) for k, v in units.items()}
        conversions = []
        for col, kind in COLUMN_KINDS.items():
            if col not in names or col not in units:
                continue
            f = si_factor(units[col], kind)
            if f is None:
                raise FormatError(
                    f"{col} is declared in {units[col]!r}, not a unit of {kind} accal knows "
                    f"({known_units(kind)}); declare one of these (or convert the column to "
                    f"{SI[kind]})",
                    self.path,
                )
            if f != 1.0:
                self.factors[col] = f
                conversions.append(f"{col} from {units[col]!r} (× {f:.10g})")
        self.names = names
        self.first_line = first_line
        self.file_meta = fmeta
        self.axes = (("x",) if "m_x" in names else ()) + ("y", "z")
        self.units = dict(UNITS)
        if "m_y" in units and "m_y" not in self.factors:
            self.units["acc"] = units["m_y"]  # the file's own spelling of m/s²
        self.units.update(
            {
                k: units.get(k, "unknown")
                for k in names
                if k not in REQUIRED_COLUMNS and k not in OPTIONAL_COLUMNS
            }
        )
        #: Findings about the file itself (kept by every pass).
        self.file_warnings: list[str] = []
        parquet = (self._stream.kind != "csv") if rows is not None else not first_line
        named = name_mismatch(self.path, parquet=parquet)
        if named:
            self.file_warnings.append(named)
        if conversions:
            self.file_warnings.append(f"declared units converted to SI: {'; '.join(conversions)}")
        self.warnings: list[str] = list(self.file_warnings)

    def _line(self, row: int) -> int | None:
        # CSV: 1-based line of data row ``row``; Parquet has no lines (first_line = 0)
        return self.first_line + int(row) if self.first_line else None

    def _row_error(self, msg: str, row: int) -> FormatError:
        """FormatError about data row ``row`` (0-based): its CSV line, or ``row N:`` (Parquet)."""
        line = self._line(row)
        if line is None:
            return FormatError(f"row {int(row) + 1}: {msg}", self.path)
        return FormatError(msg, self.path, line)

    def _tables(self) -> Iterator[tuple[int, object]]:
        if self.rows is None:
            table = self._whole[0]
            if table.num_rows == 0:
                raise FormatError("header but no data rows", self.path, self.first_line or None)
            yield 0, table
        else:
            yield from self._stream

    def __iter__(self) -> Iterator[RawlogChunk]:
        path = self.path
        last_t: float | None = None
        aux_names: list[str] | None = None
        self.warnings = list(self.file_warnings)
        for row0, table in self._tables():

            def csv_line(i: int, row0: int = row0) -> int:
                return self.first_line + row0 + int(i)

            line_of = csv_line if self.first_line else None  # Parquet: the message names rows

            axes_cols = ("m_x", *REQUIRED_COLUMNS) if "x" in self.axes else REQUIRED_COLUMNS
            _refuse_boolean(table, axes_cols, path)
            cols = {
                c: numeric_column(table.column(c), c, path, line_of, locate=True).astype(np.float64)
                for c in REQUIRED_COLUMNS
            }
            for c in REQUIRED_COLUMNS:
                if c in self.factors:
                    cols[c] *= self.factors[c]
            time = cols["time"]
            bad = np.flatnonzero(~np.isfinite(time))
            if bad.size:
                raise self._row_error("time: missing or non-finite value", row0 + bad[0])
            if last_t is not None and time[0] <= last_t:
                raise self._row_error(
                    f"time is not strictly increasing: {time[0]:.9g} s after {last_t:.9g} s",
                    row0,
                )
            back = np.flatnonzero(np.diff(time) <= 0)
            if back.size:
                i = int(back[0]) + 1
                raise self._row_error(
                    f"time is not strictly increasing: {time[i]:.9g} s after {time[i - 1]:.9g} s "
                    f"({back.size} such step(s))",
                    row0 + i,
                )
            last_t = float(time[-1])
            acc = []
            if "x" in self.axes:
                acc.append(
                    numeric_column(table.column("m_x"), "m_x", path, line_of, locate=True).astype(
                        np.float64
                    )
                    * self.factors.get("m_x", 1.0)
                )
            acc += [cols["m_y"], cols["m_z"]]
            acc_names = (["m_x"] if "x" in self.axes else []) + ["m_y", "m_z"]
            for name, a in zip(acc_names, acc, strict=True):
                big = implausible(a)
                if big.size:
                    i = int(big[0])
                    raise self._row_error(implausible_message(name, float(a[i])), row0 + i)
            theta = cols["theta"]
            wild = np.flatnonzero(np.abs(theta) > MAX_ABS_THETA)  # NaN (a gap) is not wild
            if wild.size:
                i = int(wild[0])
                raise self._row_error(
                    f"theta: {theta[i]:.6g} rad is not a plausible angle (|theta| > "
                    f"{MAX_ABS_THETA:g} rad, {MAX_ABS_THETA / (2 * np.pi):,.0f} turns): a damaged value",
                    row0 + i,
                )
            if aux_names is None:  # decided on the first chunk (CSV types are fixed there)
                aux_names, skipped = [], []
                for name in self.names:
                    if name in REQUIRED_COLUMNS or name in OPTIONAL_COLUMNS:
                        continue
                    try:
                        numeric_column(table.column(name), name, path)
                        aux_names.append(name)
                    except FormatError:
                        skipped.append(name)
                if skipped:
                    self.warnings.append(f"non-numeric columns ignored: {column_list(skipped)}")
            aux = {k: numeric_column(table.column(k), k, path) for k in aux_names}
            yield RawlogChunk(row0, time, np.column_stack(acc), cols["theta"], aux, self.axes)


def _refuse_boolean(table: Any, names: tuple[str, ...], path: Path) -> None:
    """FormatError for a Boolean time, acceleration or angle column.

    A flag column is numeric to :func:`numeric_column` (the auxiliary channels may be
    flags), but a Boolean ``m_y`` had been read as 0/1 m/s² and demodulated without a
    word (issue 23, the mutation fuzzer: a_Y ≈ -4.6e-17).
    """
    for name in names:
        # the type's name, not pyarrow.types: pyarrow is imported lazily (accal.io.tables)
        if name in table.column_names and str(table.column(name).type) == "bool":
            unit = UNITS["acc"] if name.startswith("m_") else UNITS[name]
            raise FormatError(f"{name}: a Boolean column, not a number in {unit}", path)


def name_mismatch(path: str | Path, *, parquet: bool) -> str | None:
    """The warning for a file whose name says another format than its content, or None.

    The readers go by the content (Parquet by its magic bytes, anything else is
    CSV), as for gzip; a ``.parquet`` file that is text, or a ``.csv`` file that
    is Parquet, is read all the same, with this warning.

    Parameters
    ----------
    path : str or Path
        The file.
    parquet : bool
        Whether its content is Parquet.

    Returns
    -------
    str or None
        ``"named .parquet but is text: read as CSV"`` (or the converse).
    """
    name = Path(path).name.lower().removesuffix(".gz")
    suffix = name[name.rfind(".") :] if "." in name else ""
    if not parquet and suffix in PARQUET_SUFFIXES:
        return f"named {suffix} but is text: read as CSV"
    if parquet and suffix in TEXT_SUFFIXES:
        return f"named {suffix} but is Parquet: read as Parquet"
    return None


def open_rawlog(
    path: str | Path, *, rows: int | None = STREAM_ROWS, threads: bool = True
) -> RawlogStream:
    """Open a rotating-platform run file for reading in chunks.

    Parameters
    ----------
    path : str or Path
        Parquet, CSV or gzipped CSV table (columns as in :func:`read_rawlog`).
    rows : int or None
        Rows per chunk; ``None`` reads the whole file as one chunk.
    threads : bool
        Whether pyarrow may use its thread pool for a chunked Parquet read
        (:class:`accal.io.table_stream.TableStream`).

    Returns
    -------
    RawlogStream
        Iterate it (as often as needed; each pass re-reads the file) for
        :class:`RawlogChunk` objects.

    Raises
    ------
    FormatError
        On opening: unreadable or corrupt file, missing columns (all listed), a
        fixed column declared in a unit accal does not know.  While iterating: non-numeric required columns,
        non-finite or not strictly increasing time (checked across chunks, with
        the CSV line or the Parquet row).
    """
    return RawlogStream(path, rows, threads=threads)


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
        columns, non-finite or not strictly increasing time, a fixed column declared in a unit
        accal does not know.
    """
    stream = open_rawlog(path, rows=None)
    (chunk,) = list(stream)
    aux = {"theta": chunk.theta, **chunk.aux}
    step = np.diff(chunk.time)
    report = ReadReport(
        n_rows=len(chunk),
        nominal_step=float(np.median(step)) if step.size else float("nan"),
        warnings=tuple(stream.warnings),
    )
    units = {k: v for k, v in stream.units.items() if k in ("time", "acc", "theta") or k in aux}
    return AccSeries(
        time=chunk.time,
        acc=chunk.acc,
        axes=chunk.axes,
        aux=aux,
        frame="platform",
        units=units,
        meta={"rawlog": {"file_meta": stream.file_meta, "columns": stream.names}},
        report=report,
    )


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
    table, _, _, _ = read_table_arrow(path)
    names = list(table.column_names)
    missing = [c for c in PSD_COLUMNS if c not in names]
    if missing:
        raise FormatError(
            f"PSD table: missing column(s) {', '.join(missing)} (need f [Hz], S [m^2 s^-4 Hz^-1]; "
            f"columns are {column_list(names)})",
            path,
        )
    return tuple(numeric_column(table.column(c), c, path).astype(np.float64) for c in PSD_COLUMNS)
