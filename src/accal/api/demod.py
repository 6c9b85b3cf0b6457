"""demod in memory: :func:`demodulate` and its result :class:`Demodulation`.

Part of :mod:`accal.api` (see its docstring); split from one module for size.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal import __version__
from accal.api.closure_result import Closure
from accal.api.common import CF_UNITS, cf_dataset
from accal.demodjob.summary import summary_of_extended
from accal.pipeline_demod import summary_warnings

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    import pandas as pd
    import xarray as xr


# ---------------------------------------------------------------------------
# demod


@dataclass(frozen=True)
class Demodulation:
    """Unbiased acceleration per modulation period of one run (``accal demod``).

    Attributes
    ----------
    source : str
        Run file name (the ``source`` column of ``periods``).
    tau, mask : float
        Modulation period τ and masking time [s].
    method : str
        ``"ls"`` or ``"gls"``.
    periods : dict of str to ndarray
        The rows of ``periods.<fmt>`` for this run (columns as arrays; with
        ``close_loop`` the extended model's, the declared ones as ``*_before``).
    units : dict of str to str
        Units of the columns.
    summary : dict
        The run summary (``summary.json``: Rd, σ(T), noise, leakage, masking; with
        ``close_loop`` the mean of the extended model, the declared one in
        ``summary["declared"]``, as the CLI writes it).
    result : accal.estimators.demod.DemodResult
        The estimator's result.
    closure : Closure or None
        With ``close_loop``.

    Examples
    --------
    >>> import accal, tempfile, pathlib
    >>> from accal.pipeline_demod import write_simulated_gap  # accal simulate gap
    >>> run, _ = write_simulated_gap(
    ...     pathlib.Path(tempfile.mkdtemp()) / "run.parquet", days=0.1, tau=600, mask=200
    ... )
    >>> res = accal.demodulate(run, tau=600, mask=200)
    >>> df = res.to_dataframe()
    >>> df.columns[:6].tolist(), df.attrs["units"]["a_Y"].split()[0]
    (['t_start', 't_mid', 'a_Y', 'a_Z', 'sigma_Y', 'sigma_Z'], 'm/s^2')
    >>> ds = res.to_xarray()
    >>> ds["a_Y"].attrs["units"], ds["t_mid"].attrs["units"], ds.sizes["period"]
    ('m s-2', 's', 14)
    """

    source: str
    tau: float
    mask: float
    method: str
    periods: dict[str, NDArray[Any]] = field(repr=False)
    units: dict[str, str] = field(repr=False)
    summary: dict[str, Any] = field(repr=False)
    result: Any = field(repr=False)
    closure: Closure | None = field(default=None, repr=False)
    arguments: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def a_Y(self) -> NDArray[np.float64]:  # noqa: N802 (the paper's name)
        """a_Y per period [m/s²]."""
        return np.asarray(self.periods["a_Y"], dtype=np.float64)

    @property
    def a_Z(self) -> NDArray[np.float64]:  # noqa: N802
        """a_Z per period [m/s²]."""
        return np.asarray(self.periods["a_Z"], dtype=np.float64)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the CLI prints as warning lines for this run."""
        return tuple(summary_warnings(self.summary))

    def to_dataframe(self) -> pd.DataFrame:
        """The per-period table: index ``period``; ``t_mid`` [s], ``a_Y``, ``a_Z``, σ, ...

        The columns of the CLI's ``periods.<fmt>`` for this run (without ``source``,
        which is in ``df.attrs``); units in ``df.attrs["units"]``.  Times are seconds
        in the run's own time origin (example: :class:`Demodulation`).
        """
        import pandas as pd

        data = {k: v for k, v in self.periods.items() if k not in ("source", "period")}
        index = pd.Index(np.asarray(self.periods["period"]), name="period")
        df = pd.DataFrame(data, index=index)
        df.attrs.update(
            units={c: self.units.get(c, "") for c in df.columns},
            source=self.source,
            tau=self.tau,
            mask=self.mask,
            method=self.method,
            accal_version=__version__,
        )
        return df

    def to_xarray(self) -> xr.Dataset:
        """The per-period table as an :class:`xarray.Dataset` over ``period``.

        ``t_start`` and ``t_mid`` are coordinates; every variable has CF ``units``
        and a ``long_name`` (the CLI's unit text); τ, the mask, method, PSD and
        source are attributes (example: :class:`Demodulation`).
        """
        coords: dict[str, Any] = {"period": ("period", np.asarray(self.periods["period"]))}
        columns = {k: v for k, v in self.periods.items() if k not in ("source", "period")}
        data_vars = table_variables(
            columns, self.units, "period", coords=coords, coord_names=("t_start", "t_mid")
        )
        models = {k: str(self.arguments.get(k, "")) for k in ("psd", "signal_model", "bias_model")}
        title = f"accal demod: {self.source}"
        return cf_dataset(
            data_vars, coords, title=title, source=self.source, tau=self.tau, mask=self.mask,
            method=self.method, **models,
        )  # fmt: skip


def table_variables(
    columns: Mapping[str, Any],
    units: Mapping[str, str],
    dim: str,
    *,
    coords: dict[str, Any],
    coord_names: Sequence[str] = (),
) -> dict[str, Any]:
    """A table's columns as xarray variables over ``dim``, with CF attributes.

    Each variable's ``long_name`` is its accal unit text (the column name without
    one) and a numeric one has CF ``units`` (:func:`_cf_unit`); a datetime column
    (a UTC column, naive or time-zone aware) becomes naive UTC ``datetime64[ns]``
    with ``standard_name = "time"``, which xarray encodes as CF time.

    Parameters
    ----------
    columns : mapping of str to array
        The columns, in order.
    units : mapping of str to str
        accal's unit text of each column.
    dim : str
        The dimension (``period``, ``row``).
    coords : dict
        Receives the columns named in ``coord_names`` (and every datetime column)
        as coordinates.
    coord_names : sequence of str
        Columns that are coordinates.

    Returns
    -------
    dict
        The data variables, ``name -> (dim, values, attrs)``.
    """
    data_vars: dict[str, Any] = {}
    for k, v in columns.items():
        text = units.get(k, "")
        attrs = {"long_name": text or k}
        values = np.asarray(v)
        if hasattr(v, "dt") and getattr(v.dt, "tz", None) is not None:  # pandas, tz-aware
            values = v.dt.tz_convert(None).to_numpy(dtype="datetime64[ns]")
        if values.dtype.kind in "fiu":
            attrs["units"] = _cf_unit(text)
        target = data_vars
        if values.dtype.kind == "M":
            attrs = {"standard_name": "time", "long_name": f"{k}: {text}" if text else k}
            target = coords
        elif k in coord_names:
            target = coords
        target[k] = (dim, values, attrs)
    return data_vars


def _cf_unit(text: str) -> str:
    """CF/UDUNITS form of the unit at the head of an accal unit text (``"1"`` if none).

    ``"m/s^2 (period mean ...)"`` → ``"m s-2"``; ``"m/s^2 per K of temperature
    (m_y)"`` (a bias-model channel's coefficient) → ``"m s-2 K-1"``.
    """
    head = text.split(" (")[0].strip()
    base, _, per = head.partition(" per ")
    unit = CF_UNITS.get(base.strip(), "1")
    per_unit = per.split(" of ")[0].strip()
    if unit != "1" and per_unit:
        return f"{unit} {CF_UNITS.get(per_unit, per_unit)}-1" if " " not in per_unit else "1"
    return unit


def demodulate(
    run: str | Path,
    *,
    tau: float,
    mask: float,
    method: str = "ls",
    psd: str = "auto",
    signal_model: str = "mean",
    bias_model: str = "affine",
    sinusoid_period: float | None = None,
    sinusoid_constant: bool = False,
    resample: bool = False,
    gap_factor: float = 2.0,
    rest_tol: float = 1e-9,
    integration: float = 10800.0,
    chunk_size: int | None = None,
    close_loop: bool = False,
    alpha: float = 0.01,
) -> Demodulation:
    """Unbiased a_Y, a_Z per modulation period of a rotating-platform run (``accal demod``).

    The same chain and defaults as the command line (read in chunks, validate,
    LS/GLS demodulation with the noise PSD, summary; with ``close_loop`` the
    closure with the demodulation model as base and the periods of the extended
    model), in memory.

    Parameters
    ----------
    run : str or Path
        Run file (CSV/Parquet with ``time``, ``m_y``, ``m_z``, ``theta``; e.g. from
        ``accal simulate gap``).
    tau, mask : float
        Modulation period τ and nominal masking time TM per period [s].
    method : {"ls", "gls"}
    psd : str
        ``"auto"`` (from the run's residual), ``"microstar"`` (eq. 1) or a PSD table.
    signal_model : {"mean", "affine"}
    bias_model : str
        ``"affine"`` or ``"affine+CHANNEL[+CHANNEL]"``.
    sinusoid_period : float, optional
        Fit ``α cos + β sin`` of this period [s] to the per-period values.
    sinusoid_constant : bool
        Add a constant to that fit.
    resample : bool
        Resample irregular sampling onto a uniform grid.
    gap_factor : float
        With ``resample``: a step longer than this many grid steps is a gap.
    rest_tol : float
        θ rest tolerance [rad].
    integration : float
        Integration time of the standard σ(T) of the summary [s].
    chunk_size : int, optional
        Rows read at a time (default the CLI's; results do not depend on it).
    close_loop : bool
        Close the loop (``--close-loop``).
    alpha : float
        False-detection probability per selection step of the closure.

    Returns
    -------
    Demodulation

    Examples
    --------
    >>> import accal, tempfile, pathlib
    >>> from accal.pipeline_demod import write_simulated_gap
    >>> run, truth = write_simulated_gap(
    ...     pathlib.Path(tempfile.mkdtemp()) / "run.parquet", days=0.1, tau=600, mask=200
    ... )
    >>> res = accal.demodulate(run, tau=600, mask=200)
    >>> res.a_Y.size, res.method, res.summary["psd"] if "psd" in res.summary else "auto"
    (14, 'ls', 'auto')
    """
    arguments = {k: v for k, v in locals().items() if k not in ("run", "close_loop")}
    from accal.pipeline_demod import (
        CHUNK_ROWS,
        DemodOptions,
        apply_closure,
        close_run,
        closure_summary,
        estimate,
        leak_of,
        load_psd,
        misfit_of,
        period_rows,
        summarise,
    )

    options = {k: v for k, v in arguments.items() if k != "chunk_size"}
    rows_at_a_time = CHUNK_ROWS if chunk_size is None else int(chunk_size)
    opts = DemodOptions(**options, chunk_rows=rows_at_a_time, close_loop=close_loop)
    path = Path(run)
    noise = load_psd(psd)
    res, info = estimate(path, opts, noise)
    rows, units = period_rows(res, path.name, info.units)
    summary = summarise(path, info, res, opts)
    closure = None
    if close_loop:
        step = info.step if info.resample is not None else None
        used = res.noise.used if getattr(res, "noise", None) is not None else noise
        entry, extended, _ = close_run(path, opts, path.parent, step=step, psd=used)
        rows, units = apply_closure(rows, units, extended, leak_of(res, opts), misfit_of(res))
        summary["closure"] = closure_summary(entry)
        summary_of_extended(summary, rows, entry["model"])  # the mean of the extended model
        closure = Closure({path.name: entry}, gps_time=False)
    result = Demodulation(
        source=path.name,
        tau=float(tau),
        mask=float(mask),
        method=method,
        periods=rows,
        units=units,
        summary=summary,
        result=res,
        closure=closure,
        arguments=arguments,
    )
    if closure is not None:
        closure.fit = result
    return result
