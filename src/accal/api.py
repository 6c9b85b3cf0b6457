"""The Python API: read, fit, close the loop and demodulate in a notebook (issue 21).

Thin wrappers over the functions the command line runs (:mod:`accal.pipeline`,
:mod:`accal.pipeline_closure`, :mod:`accal.pipeline_demod`): the same defaults and
the same numbers as ``accal grace-bias`` and ``accal demod``, in memory, nothing
written.  The results are dataclasses with ``to_dataframe()`` (pandas) and
``to_xarray()`` (units and provenance in the attributes, CF-style ``units`` and
``long_name``).  Everything is in SI units (m/s², m/s³, s); times are GPS seconds
since 2000-01-01 12:00:00 GPS, given as UTC instants beside them in the tables.

The names are exported lazily by :mod:`accal` (``accal.read``, ``accal.fit_bias``,
``accal.close_loop``, ``accal.demodulate``): ``import accal`` stays as fast as the
command line needs.

Examples
--------
>>> import accal
>>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
>>> fit = accal.fit_bias(day, method="both")
>>> fit.table()[["axis", "method", "bias", "bias_sigma"]].shape
(6, 4)
>>> fit.to_dataframe().index.tz
datetime.timezone.utc
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal import __version__
from accal.errors import ValidationError
from accal.series import AccSeries

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    import pandas as pd
    import xarray as xr

__all__ = [
    "BiasFit",
    "Closure",
    "Demodulation",
    "close_loop",
    "demodulate",
    "fit_bias",
    "read",
]

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
    from accal.pipeline import GraceBiasOptions, name_mismatch, read_input
    from accal.plausibility import flag_wild_samples

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
    from accal.timescale import gps_to_utc

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


# ---------------------------------------------------------------------------
# closure


@dataclass
class Closure:
    """What closing the loop found (``closure.json`` entries), with a table of the effects.

    Attributes
    ----------
    entries : dict of str to dict
        Per axis (``grace-bias``) or per run (``demod``): the ``closure.json`` entry
        (:meth:`accal.closure.ClosureResult.to_dict` plus ``model``,
        ``estimates`` before/after, ``markdown``).
    orbit_period : float or None
        Orbit period of the orbit-signal model [s]: estimated from the data near the
        nominal one (as ``accal grace-bias --close-loop`` does), None where the
        closure had no orbit model (a reference, a short record, ``demod``).
    fit : BiasFit or Demodulation or None
        The refit with the extended model (set by :func:`fit_bias` /
        :func:`demodulate`).
    gps_time : bool
        Whether the epochs are GPS seconds (``grace-bias``; a ``demod`` run's
        times are seconds from its own origin: no UTC epochs then).
    """

    entries: dict[str, dict[str, Any]] = field(repr=False)
    orbit_period: float | None = None
    fit: Any = field(default=None, repr=False)
    gps_time: bool = field(default=True, repr=False)

    def __repr__(self) -> str:
        found = {k: [e.get("name") for e in v.get("effects", [])] for k, v in self.entries.items()}
        return f"Closure(effects={found}, model={self.model}, orbit_period={self.orbit_period})"

    @property
    def model(self) -> dict[str, str]:
        """Fitted model per entry, e.g. ``{"x": "poly1+bias_step@..."}``."""
        return {k: str(e.get("model", "")) for k, e in self.entries.items()}

    @property
    def markdown(self) -> str:
        """The closure report (``closure.md``'s sections)."""
        return "\n\n".join(str(e.get("markdown", "")) for e in self.entries.values())

    def to_dataframe(self) -> pd.DataFrame:
        """One row per effect found (``kind="effect"``) or unexplained structure.

        Columns: ``axis``, ``kind``, ``name``, ``channel``, ``coefficient`` (in
        ``unit``, SI), ``sigma``, ``significance`` (p-value), ``epoch`` (GPS
        seconds, steps), ``epoch_utc``, ``frequency`` [Hz], ``lag``, ``tau`` [s],
        ``instrument`` (removed from the calibrated series), ``model``.

        Examples
        --------
        >>> import accal
        >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
        >>> accal.close_loop(day).to_dataframe().columns[:4].tolist()
        ['axis', 'kind', 'name', 'channel']
        """
        import pandas as pd

        cols = ["coefficient", "unit", "sigma", "significance", "epoch", "frequency"]
        cols += ["lag", "tau", "instrument"]
        rows = []
        for key, entry in self.entries.items():
            for kind, items in (("effect", "effects"), ("unexplained", "unexplained")):
                for e in entry.get(items, []):
                    row = {"axis": e.get("axis") or key, "kind": kind, "name": e.get("name")}
                    row["channel"] = e.get("channel")
                    row.update({c: e.get(c) for c in cols})
                    row["model"] = entry.get("model", "")
                    rows.append(row)
        df = pd.DataFrame(rows, columns=["axis", "kind", "name", "channel", *cols, "model"])
        for c in ("coefficient", "sigma", "significance", "epoch", "frequency", "lag", "tau"):
            df[c] = pd.to_numeric(df[c], errors="coerce").astype(float)
        epochs = df["epoch"].to_numpy()
        utc = np.full(epochs.size, np.datetime64("NaT"), dtype="datetime64[ns]")
        known = np.isfinite(epochs) & (epochs > 0) & self.gps_time
        if known.any():
            from accal.timescale import gps_to_utc

            utc[known] = gps_to_utc(epochs[known])
        df.insert(
            df.columns.get_loc("epoch") + 1, "epoch_utc", pd.Series(utc).dt.tz_localize("UTC")
        )
        df.attrs["units"] = {
            "coefficient": "in 'unit' (SI)",
            "sigma": "in 'unit' (1 sigma)",
            "significance": "p-value of the effect's test",
            "epoch": "s (GPS seconds since 2000-01-01 12:00:00; steps)",
            "epoch_utc": "UTC",
            "frequency": "Hz",
            "lag": "s",
            "tau": "s",
        }
        df.attrs["orbit_period"] = self.orbit_period
        return df


def _orbit_period(entries: Mapping[str, Mapping[str, Any]]) -> float | None:
    """The period of the orbit-signal model the closure used (None if it had none)."""
    for entry in entries.values():
        period = (entry.get("signal_model") or {}).get("period")
        if period is not None:
            return float(period)
    return None


# ---------------------------------------------------------------------------
# grace-bias


@dataclass(frozen=True)
class BiasFit:
    """Bias and drift of one series per axis and method, and the calibrated series.

    What ``accal grace-bias`` writes for one input, in memory: the rows of
    ``bias_drift`` (:meth:`table`), the calibrated series (:attr:`calibrated`,
    :meth:`to_dataframe`, :meth:`to_xarray`) and, with ``close_loop``, the closure.

    Attributes
    ----------
    source : str
        Input name (the ``source`` column).
    satellite, frame : str
        From the input.
    methods : tuple of str
        Estimators; the first calibrates the series.
    order : int
        Trend order.
    rows : tuple of dict
        The ``bias_drift`` rows (columns and units: :data:`accal.pipeline.BIAS_DRIFT_UNITS`).
    calibrated : AccSeries
        ``scale·(a_raw − trend)`` of ``methods[0]`` [m/s²].
    used : ndarray of bool
        Samples used in the fit (the calibrated file's ``valid``).
    series : AccSeries
        The input, with the warnings of reading and fitting in ``series.report``.
    fits : dict
        ``{(axis, method): accal.estimators.trend.TrendFit}`` (``evaluate(t)``, ``cov``).
    closure : Closure or None
        With ``close_loop``.
    """

    source: str
    satellite: str
    frame: str
    methods: tuple[str, ...]
    order: int
    rows: tuple[dict[str, Any], ...] = field(repr=False)
    calibrated: AccSeries = field(repr=False)
    used: NDArray[np.bool_] = field(repr=False)
    series: AccSeries = field(repr=False)
    fits: dict[tuple[str, str], Any] = field(repr=False)
    closure: Closure | None = field(default=None, repr=False)
    arguments: dict[str, Any] = field(default_factory=dict, repr=False)
    input: AccSeries | None = field(default=None, repr=False)

    def _values(self, key: str, method: str | None) -> dict[str, float]:
        m = method or self.methods[0]
        return {r["axis"]: float(r[key]) for r in self.rows if r["method"] == m}

    def bias(self, method: str | None = None) -> dict[str, float]:
        """Bias per axis [m/s²] of ``method`` (default: the calibrating one)."""
        return self._values("bias", method)

    def drift(self, method: str | None = None) -> dict[str, float]:
        """Drift per axis [m/s³]."""
        return self._values("drift", method)

    def bias_sigma(self, method: str | None = None) -> dict[str, float]:
        """1σ of the bias per axis [m/s²] (coloured-noise aware)."""
        return self._values("bias_sigma", method)

    def drift_sigma(self, method: str | None = None) -> dict[str, float]:
        """1σ of the drift per axis [m/s³]."""
        return self._values("drift_sigma", method)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What reading and fitting found worth telling (the CLI's warning lines)."""
        return tuple(self.series.report.warnings)

    def table(self) -> pd.DataFrame:
        """The ``bias_drift`` rows of this input (the CLI's table, same columns and values).

        Units of every column are in ``df.attrs["units"]``.

        Examples
        --------
        >>> import accal
        >>> fit = accal.fit_bias(accal.read("data/samples/ACC1B_2003-09-14_A_00.asc"))
        >>> df = fit.table()
        >>> df[["axis", "method", "n"]].to_string(index=False)
        'axis  method  n\\n   x wavelet 60\\n   y wavelet 60\\n   z wavelet 60'
        >>> df.attrs["units"]["bias"].split()[0]
        'm/s^2'
        """
        import pandas as pd

        from accal.pipeline import BIAS_DRIFT_UNITS

        df = pd.DataFrame(list(self.rows))
        df.attrs["units"] = {c: BIAS_DRIFT_UNITS.get(c, "") for c in df.columns}
        return df

    def to_dataframe(self) -> pd.DataFrame:
        """The calibrated series: UTC index, ``gps_time`` [s], ``lin_accl_*`` [m/s²], flags.

        The columns of the CLI's ``<stem>.calibrated.<fmt>``; their units are in
        ``df.attrs["units"]``, the provenance (source, methods, history) in
        ``df.attrs``.

        Examples
        --------
        >>> import accal
        >>> fit = accal.fit_bias(accal.read("data/samples/ACC1B_2003-09-14_A_00.asc"))
        >>> df = fit.to_dataframe()
        >>> df.columns.tolist()
        ['gps_time', 'lin_accl_x', 'lin_accl_y', 'lin_accl_z', 'valid', 'qualflg']
        >>> str(df.index[0]), float(df["gps_time"].iloc[0])  # 00:00 GPS is 23:59:47 UTC in 2003
        ('2003-09-13 23:59:47+00:00', 116769600.0)
        >>> df.attrs["units"]["lin_accl_x"].split()[0]
        'm/s^2'
        """
        import pandas as pd

        from accal.pipeline import CALIBRATED_UNITS, calibrated_frame

        data = calibrated_frame(self.calibrated, self.used)
        df = pd.DataFrame(data, index=gps_to_utc_index(self.calibrated.time))
        df.attrs.update(
            units={c: CALIBRATED_UNITS.get(c, "") for c in df.columns},
            source=self.source,
            satellite=self.satellite,
            frame=self.frame,
            method=self.methods[0],
            accal_version=__version__,
            history=list(self.calibrated.history),
        )
        return df

    def to_xarray(self) -> xr.Dataset:
        """The calibrated series and the estimates as an :class:`xarray.Dataset`.

        Dimensions ``time`` (UTC instants; coordinate ``gps_time`` in GPS seconds),
        ``method`` and ``axis``; variables ``lin_accl_<axis>(time)``, ``valid``,
        ``qualflg`` and ``bias``, ``bias_sigma``, ``drift``, ``drift_sigma``, ...
        ``(method, axis)``, each with CF ``units`` and ``long_name``; the provenance
        (source, satellite, methods, history, accal version) in the attributes.

        Examples
        --------
        >>> import accal
        >>> fit = accal.fit_bias(accal.read("data/samples/ACC1B_2003-09-14_A_00.asc"))
        >>> ds = fit.to_xarray()
        >>> ds["lin_accl_x"].attrs["units"], ds["drift"].attrs["units"], ds.sizes["time"]
        ('m s-2', 'm s-3', 60)
        >>> float(ds["bias"].sel(estimator="wavelet", axis="x")) == fit.bias()["x"]
        True
        """
        from accal.pipeline import CALIBRATED_UNITS

        cal = self.calibrated
        utc_attrs = {"standard_name": "time", "long_name": "time (UTC, to the microsecond)"}
        gps_attrs = {"units": "s", "long_name": CALIBRATED_LONG_NAMES["gps_time"]}
        coords: dict[str, Any] = {
            "time": ("time", utc_instants(cal.time), utc_attrs),
            "gps_time": ("time", cal.time, gps_attrs),
            "estimator": ("estimator", list(self.methods)),
            "axis": ("axis", list(cal.axes)),
        }
        data_vars: dict[str, Any] = {}
        for ax in cal.axes:
            name = f"lin_accl_{ax}"
            attrs = {"units": CF_UNITS["m/s^2"], "long_name": CALIBRATED_LONG_NAMES[name]}
            attrs["comment"] = CALIBRATED_UNITS[name]
            data_vars[name] = ("time", cal.axis(ax), attrs)
        data_vars["valid"] = ("time", self.used, {"long_name": CALIBRATED_LONG_NAMES["valid"]})
        data_vars["qualflg"] = (
            "time",
            cal.quality,
            {"long_name": CALIBRATED_LONG_NAMES["qualflg"]},
        )
        index = {(r["method"], r["axis"]): r for r in self.rows}
        estimates = {**ESTIMATE_VARIABLES, **(QUADRATIC_VARIABLES if self.order >= 2 else {})}
        for key, (unit, long_name) in estimates.items():
            values = np.array(
                [[float(index[(m, ax)][key]) for ax in cal.axes] for m in self.methods]
            )
            data_vars[key] = (
                ("estimator", "axis"),
                values,
                {"units": unit, "long_name": long_name},
            )
        return cf_dataset(
            data_vars,
            coords,
            title=f"accal grace-bias: {self.source}",
            source=self.source,
            satellite=self.satellite,
            frame=self.frame,
            methods=",".join(self.methods),
            order=self.order,
            model=";".join(sorted({f"{r['axis']}:{r['model']}" for r in self.rows})),
            history="\n".join(cal.history),
        )


def fit_bias(
    series: AccSeries,
    method: str | Sequence[str] = "wavelet",
    *,
    order: int = 1,
    scale: str | Sequence[float] | None = None,
    reference: str | Path | AccSeries | None = None,
    reference_columns: Mapping[str, str] | None = None,
    keep_flagged: bool = False,
    close_loop: bool = False,
    aux: str | Path | None = None,
    truth: str | Path | None = None,
    alpha: float = 0.01,
    orbit_period: float | None = None,
    degraded_days: str | Path | None = None,
    source: str | None = None,
) -> BiasFit:
    """Per-axis bias and drift of ``series`` and the calibrated series (``accal grace-bias``).

    The same chain and defaults as the command line for one input: the
    estimators of :mod:`accal.estimators.trend` on ``series`` (or on
    ``series − reference``), with ``close_loop`` the residual analysis of
    :mod:`accal.closure` and the refit with the effects it found, then
    ``a_cal = scale·(a_raw − trend)``.

    Parameters
    ----------
    series : AccSeries
        The data, e.g. from :func:`read` (which flags implausible samples as the
        CLI does; a series built by hand is fitted as it is).
    method : {"wavelet", "lsq", "both"} or sequence of them
        Estimator(s) (``--method``); the first one calibrates the series.
    order : {1, 2}
        Trend order: bias + drift, or with a quadratic term (``--order``).
    scale : str or sequence of 3 float, optional
        ``"tn02"`` (GRACE TN-02 a-priori scale factors) or the factors per axis
        x, y, z (``--scale``); None: 1.
    reference : str, Path or AccSeries, optional
        Reference accelerations (``--reference``): the fit is made on
        ``raw − reference`` (interpolated onto the data's epochs).
    reference_columns : mapping, optional
        Axis → column of a reference table given as a path (the CLI's ``--column``
        applies to it too).
    keep_flagged : bool
        Use the samples the quality flags mark invalid (``--keep-flagged``).
    close_loop : bool
        Close the loop (``--close-loop``; implied by ``aux`` and ``truth``): see
        :func:`close_loop`.
    aux : str or Path, optional
        Housekeeping file whose channels are candidate couplings (``--aux``).
    truth : str or Path, optional
        Truth JSON of ``accal simulate grace`` (``--truth``): the closure reports the
        true errors before and after.
    alpha : float
        Family-wise false-detection probability of the closure per step (``--alpha``).
    orbit_period : float, optional
        Nominal orbit period [s] the closure's orbit-signal model starts from; the
        period is then estimated from the data near it (on records of two
        revolutions or more, without a reference), as the CLI does.  Default: the
        CLI's nominal 5600 s.
    degraded_days : str or Path, optional
        Table of degraded/transplant/off periods (``--degraded-days``).
    source : str, optional
        Input name in the rows; default: the file name :func:`read` recorded.

    Returns
    -------
    BiasFit

    Raises
    ------
    accal.errors.AccalError
        Bad options (a ``ValidationError`` naming the option) or data the
        estimators cannot fit (too few usable samples, a reference not covering
        the data, ...).

    Examples
    --------
    >>> import accal
    >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
    >>> fit = accal.fit_bias(day, method="both")
    >>> fit.methods, sorted(fit.bias())
    (('wavelet', 'lsq'), ['x', 'y', 'z'])
    >>> fit.bias("lsq")["x"] == fit.table().query("axis == 'x' and method == 'lsq'")["bias"].item()
    True
    >>> all(s > 0 for s in fit.drift_sigma().values())
    True
    """
    arguments = {k: v for k, v in locals().items() if k != "series"}  # for close_loop(fit)
    from accal.pipeline import GraceBiasOptions, fit_input, read_input, subtract_reference

    if not isinstance(series, AccSeries):
        raise ValidationError(f"series must be an AccSeries (accal.read), got {type(series)}")
    given = series
    if isinstance(method, str):
        methods = ("wavelet", "lsq") if method == "both" else (method,)
    else:
        methods = tuple(method)
    if scale is not None and not isinstance(scale, str):
        scale = ",".join(repr(float(v)) for v in scale)
    ref_path = None
    if reference is not None:
        ref_path = Path(
            source_of(reference, "reference") if isinstance(reference, AccSeries) else reference
        )
    opts = GraceBiasOptions(
        methods=methods,
        order=int(order),
        scale=scale,
        keep_flagged=keep_flagged,
        reference=ref_path,
        close_loop=close_loop or aux is not None or truth is not None,
        aux=None if aux is None else Path(aux),
        truth=None if truth is None else Path(truth),
        alpha=alpha,
        orbit_period=GraceBiasOptions.orbit_period if orbit_period is None else orbit_period,
        degraded_days=None if degraded_days is None else Path(degraded_days),
    )
    if opts.reference_fit:  # scale "fit"/"fit-matrix": accal.pipeline_reference's job
        raise ValidationError(
            f"scale {scale!r}: the reference fit (--scale fit, --bias-basis) is not in the "
            "Python API yet; use accal grace-bias"
        )
    name = source or source_of(series)
    path = Path(name)
    fit_series = ref_series = None
    if reference is not None:
        if not isinstance(reference, AccSeries):
            ref_opts = GraceBiasOptions(columns=dict(reference_columns or {}))
            reference = read_input(ref_path, ref_opts)
        ref_series = subtract_reference(series, reference, ref_path)
        fit_series = ref_series
        series = series.replace(report=ref_series.report)
    fitted = fit_input(path, series, fit_series or series, ref_series, opts, path)
    closure = None
    if opts.close_loop:
        entries = {ax: c["summary"] for ax, c in fitted.closure.items()}
        closure = Closure(entries, orbit_period=_orbit_period(entries))
    result = BiasFit(
        source=path.name,
        satellite=fitted.series.satellite,
        frame=fitted.series.frame,
        methods=methods,
        order=int(order),
        rows=tuple(fitted.rows),
        calibrated=fitted.calibrated,
        used=fitted.use,
        series=fitted.series,
        fits=fitted.fits,
        closure=closure,
        arguments=arguments,
        input=given,
    )
    if closure is not None:
        closure.fit = result
    return result


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
        from accal.pipeline_demod import summary_warnings

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
    from accal.demodjob.summary import summary_of_extended
    from accal.pipeline_demod import (
        CHUNK_ROWS,
        DemodOptions,
        apply_closure,
        close_run,
        estimate,
        load_psd,
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
        rows, units = apply_closure(rows, units, extended)
        keys = ("effects", "unexplained", "rms_before", "rms_after", "model")
        summary["closure"] = {k: entry[k] for k in keys}
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


# ---------------------------------------------------------------------------
# close the loop


def close_loop(
    data: AccSeries | BiasFit | Demodulation,
    *,
    aux: str | Path | None = None,
    alpha: float | None = None,
    orbit_period: float | None = None,
    truth: str | Path | None = None,
    **fit_options: Any,
) -> Closure:
    """Trace the residual of the fit to effects its model lacks, add them, refit.

    ``accal grace-bias --close-loop`` (for a series or a :class:`BiasFit`) or
    ``accal demod --close-loop`` (for a :class:`Demodulation`), with the CLI's
    defaults: every channel of the data (and of ``aux``) a candidate coupling,
    steps, periodic terms, and, without a reference, the orbit-periodic signal in
    the null model with its period estimated from the data near ``orbit_period``.

    Parameters
    ----------
    data : AccSeries, BiasFit or Demodulation
        A series (fitted with ``fit_options``) or an earlier result (refitted with
        its own options; the ones given here win).
    aux : str or Path, optional
        Housekeeping file of candidate channels (``--aux``; grace-bias only).
    alpha : float, optional
        False-detection probability per step (``--alpha``; default 0.01).
    orbit_period : float, optional
        Nominal orbit period [s] (default the CLI's 5600 s); the one used is
        :attr:`Closure.orbit_period`.
    truth : str or Path, optional
        Truth JSON of a simulation (grace-bias only).
    **fit_options
        Further options of :func:`fit_bias` for a series (``method``, ``reference``, ...).

    Returns
    -------
    Closure
        The findings per axis (:meth:`Closure.to_dataframe`) and the refit
        (:attr:`Closure.fit`).

    Examples
    --------
    >>> import accal
    >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
    >>> closure = accal.close_loop(day)
    >>> sorted(closure.model), closure.fit.rows[0]["model"]
    (['x', 'y', 'z'], 'poly1')
    """
    given = {"aux": aux, "alpha": alpha, "orbit_period": orbit_period, "truth": truth}
    overrides = {k: v for k, v in given.items() if v is not None}
    if isinstance(data, Demodulation):
        if set(overrides) - {"alpha"} or fit_options:
            raise ValidationError("close_loop of a demodulation takes alpha only")
        run = Path(data.summary.get("source_path") or data.source)
        kwargs = {**data.arguments, **overrides, "close_loop": True}
        closure = demodulate(run, **kwargs).closure
        assert closure is not None
        return closure
    if isinstance(data, BiasFit):
        if data.input is None:
            raise ValidationError("this BiasFit does not keep its input series")
        kwargs = {**data.arguments, **fit_options}
        series = data.input
    elif isinstance(data, AccSeries):
        kwargs, series = dict(fit_options), data
    else:
        raise ValidationError(
            f"close_loop takes an AccSeries, a BiasFit or a Demodulation, got {type(data)}"
        )
    kwargs.update(overrides, close_loop=True)
    fit = fit_bias(series, **kwargs)
    assert fit.closure is not None
    return fit.closure
