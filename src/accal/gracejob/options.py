"""The options of ``accal grace-bias``: :class:`GraceBiasOptions`.

The CLI flags and config keys of the same names, checked when made: a usage
error (an unknown method, a malformed ``--scale``, a reference-fit option
without ``--reference``, ...) is raised before any input is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from accal.calibration import parse_scale
from accal.degraded import load_periods
from accal.errors import ValidationError, check_option
from accal.estimators.trend import METHODS


@dataclass(frozen=True)
class GraceBiasOptions:
    """Options of ``accal grace-bias`` (CLI flags and config keys of the same names).

    Attributes
    ----------
    methods : tuple of str
        Estimators to run, the first one calibrates the series.
    order : int
        Trend order (1 or 2).
    fmt : str
        Output format, ``"parquet"`` or ``"csv"``.
    scale : str or None
        ``None``, ``"tn02"`` or ``"sx,sy,sz"`` (see :mod:`accal.calibration`).
    keep_flagged : bool
        Use samples that the source's quality flags mark invalid.
    reference : Path or None
        File with reference accelerations; the fit is made on ``raw − reference``.
    columns : dict
        Axis → source column mapping for table inputs (``--column x=a_cal_x``).
    input_format : str or None
        Force an input format instead of sniffing.
    close_loop : bool
        Analyse each axis' residual, add the effects the bias + drift model lacks
        (:func:`accal.closure.close_loop`) and refit with the extended model.
    aux : Path or None
        Housekeeping file (AHK1B or a table) whose channels are candidate
        auxiliary effects of the closure (joined on time).
    truth : Path or None
        Truth JSON of a simulation (``accal simulate grace``): the closure report
        gives the true error of bias and drift before and after.
    alpha : float
        Family-wise false-detection probability of the closure per step.
    orbit_period : float or None
        Nominal orbit period [s] of the closure's orbit-signal model (refined on the
        data) and orbit harmonics.
    plots : bool
        With ``close_loop``: write the closure's PNG plots.
    degraded_days : Path or None
        TOML/YAML table of degraded/transplant/off periods ahead of the built-in
        one (:func:`accal.degraded.load_periods`).
    pool_days : int
        ``>= 2``: the σ of the ``bias_drift`` table come from a noise model fitted to
        this many adjacent days together (:mod:`accal.pooling`); ``0``: each day's
        own estimate.
    bias_basis : str or None
        With ``reference``: fit the bias on this temporal basis (``poly0``,
        ``poly1``, ``poly2``, ``spline:6h``, ...) by AR-weighted least squares
        against the reference (:mod:`accal.estimators.reference`).  ``scale`` may
        then also be ``"fit"`` (a scale per axis) or ``"fit-matrix"`` (3×3).
    thrusters : Path or None
        THR1B file whose firings the reference fit leaves out (default: the THR1B
        file beside the input, if any).
    thruster_margins : tuple of 2 float or None
        Seconds left out before and after each firing (GROOPS: 0.1, 0.7); ``None``:
        no thruster screening.
    reference_frame : str
        ``"srf"`` or ``"inertial"`` (rotated into the SRF with the SCA1B attitude).
    attitude : Path or None
        SCA1B file for ``reference_frame="inertial"`` (default: the one beside the input).
    arc : str
        ``"day"`` (each input alone), ``"<N>d"`` (up to N consecutive days of one
        satellite in one reference fit) or ``"month"`` (the days of a calendar month).
    """

    methods: tuple[str, ...] = ("wavelet",)
    order: int = 1
    fmt: str = "parquet"
    scale: str | None = None
    keep_flagged: bool = False
    reference: Path | None = None
    columns: dict[str, str] = field(default_factory=dict)
    input_format: str | None = None
    close_loop: bool = False
    aux: Path | None = None
    truth: Path | None = None
    alpha: float = 0.01
    orbit_period: float | None = 5600.0
    plots: bool = False
    degraded_days: Path | None = None
    pool_days: int = 0
    bias_basis: str | None = None
    thrusters: Path | None = None
    thruster_margins: tuple[float, float] | None = (0.1, 0.7)
    reference_frame: str = "srf"
    attitude: Path | None = None
    arc: str = "day"

    @property
    def reference_fit(self) -> bool:
        """True when the bias is fitted against the reference with a basis and/or scales."""
        return self.bias_basis is not None or self.scale in ("fit", "fit-matrix")

    def __post_init__(self) -> None:
        for m in self.methods:
            check_option("method", m, tuple(METHODS))
        check_option("order", self.order, (1, 2))
        check_option("format", self.fmt, ("parquet", "csv"))
        if not (isinstance(self.pool_days, int) and (self.pool_days == 0 or self.pool_days >= 2)):
            raise ValidationError(f"pool_days must be 0 (off) or >= 2, got {self.pool_days!r}")
        check_option("reference_frame", self.reference_frame, ("srf", "inertial"))
        if self.arc != "day":
            # imported here: the reference fit's modules import scipy (~0.3 s of start-up)
            from accal.pipeline_reference import parse_arc

            parse_arc(self.arc)
            if not self.reference_fit:
                raise ValidationError(
                    f"--arc {self.arc} groups days into one reference fit: add --bias-basis "
                    "or --scale fit"
                )
        if self.attitude is not None and self.reference_frame != "inertial":
            raise ValidationError(
                "--attitude rotates an inertial reference: add --reference-frame inertial"
            )
        if self.reference_fit:
            self._check_reference_fit()
        elif self.reference_frame != "srf" or self.attitude is not None:
            raise ValidationError(
                "--reference-frame inertial / --attitude are used by the reference fit: "
                "add --bias-basis or --scale fit"
            )
        elif self.scale is not None and str(self.scale).lower() != "tn02":
            parse_scale(self.scale, "")  # a numeric --scale is checked once, up front
        if self.degraded_days is not None:
            load_periods(self.degraded_days)  # a malformed table: a usage error, up front

    def _check_reference_fit(self) -> None:
        """Usage errors of ``--bias-basis`` / ``--scale fit|fit-matrix``, up front."""
        # imported here: the bias bases are B-splines of scipy (~0.6 s of start-up)
        from accal.estimators.refbasis import parse_bias_basis

        what = f"--bias-basis {self.bias_basis}" if self.bias_basis else f"--scale {self.scale}"
        if self.reference is None:
            raise ValidationError(f"{what} fits against a reference: give --reference REF")
        if self.pool_days:
            raise ValidationError(f"--pool-days applies to the wavelet/lsq fits, not to {what}")
        if self.bias_basis is not None:
            parse_bias_basis(self.bias_basis, 0.0, 1.0)
        if (
            self.scale not in ("fit", "fit-matrix")
            and self.scale is not None
            and str(self.scale).lower() != "tn02"
        ):
            parse_scale(self.scale, "")
        m = self.thruster_margins
        if m is not None and not (len(m) == 2 and all(np.isfinite(v) and v >= 0 for v in m)):
            raise ValidationError(f"thruster margins must be two seconds >= 0, got {m!r}")
