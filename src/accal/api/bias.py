"""grace-bias in memory: :func:`fit_bias` and its result :class:`BiasFit`.

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
from accal.api.closure_result import Closure, _orbit_period
from accal.api.common import (
    CALIBRATED_LONG_NAMES,
    CF_UNITS,
    ESTIMATE_VARIABLES,
    QUADRATIC_VARIABLES,
    cf_dataset,
    gps_to_utc_index,
    source_of,
    utc_instants,
)
from accal.errors import ValidationError
from accal.pipeline import (
    BIAS_DRIFT_UNITS,
    CALIBRATED_UNITS,
    GraceBiasOptions,
    calibrated_frame,
    fit_input,
    read_input,
    subtract_reference,
)
from accal.series import AccSeries

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    import pandas as pd
    import xarray as xr


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

    if not isinstance(series, AccSeries):
        raise ValidationError(f"series must be an AccSeries (accal.read), got {type(series)}")
    given = series
    methods, ref_path, opts = _grace_bias_options(
        method,
        order=order,
        scale=scale,
        keep_flagged=keep_flagged,
        reference=reference,
        close_loop=close_loop,
        aux=aux,
        truth=truth,
        alpha=alpha,
        orbit_period=orbit_period,
        degraded_days=degraded_days,
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


def _grace_bias_options(
    method,
    *,
    order,
    scale,
    keep_flagged,
    reference,
    close_loop,
    aux,
    truth,
    alpha,
    orbit_period,
    degraded_days,
):
    """``(methods, reference path, GraceBiasOptions)`` of :func:`fit_bias`'s arguments."""
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
    return methods, ref_path, opts
