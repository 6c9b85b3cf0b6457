"""The options and the result records of ``accal demod``.

:class:`DemodOptions` (the CLI flags and ``[demod]`` config keys, validated when
made), :class:`RunOutcome` (one run file), :class:`DemodRunSummary` (a batch) and
:class:`RunInfo` (what reading a run found out), with the defaults they share.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from accal.batch import Outcome
from accal.batch_summary import BatchSummary
from accal.errors import ValidationError, check_option

#: Standard integration time for σ(T) in the summary: 3 h, as in the paper (Fig. 5) [s].
STANDARD_INTEGRATION = 3 * 3600.0
#: Rows read at a time (~3 days at 1 Hz; ~0.3 GB peak for LS, see docs/demod.md).
CHUNK_ROWS = 1 << 18
#: Smallest chunk accepted (the sampling step is taken from the first chunk).
MIN_CHUNK_ROWS = 16


@dataclass(frozen=True)
class DemodOptions:
    """Options of ``accal demod`` (CLI flags and ``[demod]`` config keys of the same names).

    Attributes
    ----------
    tau : float
        Modulation period τ [s].
    mask : float
        Nominal masking time TM per period [s].
    method : str
        ``"ls"`` or ``"gls"``.
    psd : str
        ``"auto"`` (σ, Rd[k] and GLS from the noise PSD estimated from the run's own
        residual when the run has at least
        :data:`accal.estimators.demod.MIN_PERIODS_DATA_PSD` usable periods, else
        eq. 1), ``"microstar"`` (eq. 1, the a-priori budget) or a path to a
        CSV/Parquet table with ``f``, ``S`` (a-priori).
    signal_model : str
        ``"mean"`` or ``"affine"``.
    bias_model : str
        ``"affine"`` or ``"affine+CHANNEL[+CHANNEL...]"`` (auxiliary channels of the run file).
    fmt : str
        ``"parquet"`` or ``"csv"``.
    sinusoid_period : float or None
        Fit ``α cos + β sin`` of this period [s] to the per-period values (eq. 24).
    sinusoid_constant : bool
        Add a constant term to that fit (``α cos + β sin + c``).
    resample : bool
        Resample irregular sampling onto a uniform grid (linear interpolation within
        continuous stretches; gaps longer than ``gap_factor`` steps stay gaps,
        masked) instead of refusing it.
    gap_factor : float
        With ``resample``: an input step longer than this many grid steps is a gap.
    integration : float
        Integration time of the "standard" σ(T) in the summary [s].
    close_loop : bool
        Close the loop (:func:`accal.closure.demod.close_loop_demod`): trace the
        residual of the demodulation model to effects it lacks, add them, refit;
        ``periods`` then holds the extended model's values (and the declared
        model's as ``*_before``).  Reads the run whole.
    alpha : float
        False-detection probability per selection step of the closure.
    plots : bool
        With ``close_loop``: write the closure's PNG plots.
    chunk_rows : int
        Rows read at a time (memory knob; results do not depend on it).
    rest_tol : float
        A sample is at rest when θ's first and second differences are within this
        [rad] (section 4.2).  Raise it for an angle readout with noise at rest
        (QA: N(0, 1e-8 rad) on θ left no usable period at the default 1e-9 rad).
    """

    tau: float
    mask: float
    method: str = "ls"
    psd: str = "auto"
    signal_model: str = "mean"
    bias_model: str = "affine"
    fmt: str = "parquet"
    sinusoid_period: float | None = None
    sinusoid_constant: bool = False
    resample: bool = False
    gap_factor: float = 2.0
    integration: float = STANDARD_INTEGRATION
    chunk_rows: int = CHUNK_ROWS
    close_loop: bool = False
    alpha: float = 0.01
    rest_tol: float = 1e-9
    plots: bool = False

    def __post_init__(self) -> None:
        check_option("method", self.method, ("ls", "gls"))
        check_option("signal_model", self.signal_model, ("mean", "affine"))
        check_option("format", self.fmt, ("parquet", "csv"))
        head, *chans = self.bias_model.split("+")
        if head != "affine" or any(not c for c in chans):
            raise ValidationError(
                f"Invalid value for the 'bias_model' parameter: expected 'affine' or "
                f"'affine+CHANNEL[+CHANNEL]', got {self.bias_model!r}"
            )
        if not 0 < self.tau < np.inf:
            raise ValidationError(f"tau must be positive and finite, got {self.tau} s")
        if not 0 <= self.mask < self.tau:
            raise ValidationError(
                f"mask (masking time TM) must be in [0, tau) s, got {self.mask} s "
                f"for tau = {self.tau} s"
            )
        if self.sinusoid_period is not None and not 0 < self.sinusoid_period < np.inf:
            raise ValidationError(
                f"sinusoid period must be positive and finite, got {self.sinusoid_period} s"
            )
        if not 0 < self.integration < np.inf:
            raise ValidationError(
                f"integration time must be positive and finite, got {self.integration} s"
            )
        if not 0 < self.rest_tol < 0.1:
            raise ValidationError(
                f"rest tolerance must be in (0, 0.1) rad, got {self.rest_tol} rad"
            )
        if not self.gap_factor > 1:
            raise ValidationError(f"gap factor must be > 1 step, got {self.gap_factor}")
        if int(self.chunk_rows) < MIN_CHUNK_ROWS:
            raise ValidationError(
                f"chunk size must be at least {MIN_CHUNK_ROWS} rows, got {self.chunk_rows}"
            )

    @property
    def aux_channels(self) -> tuple[str, ...]:
        """Auxiliary channels of the bias model."""
        return tuple(self.bias_model.split("+")[1:])


@dataclass(frozen=True)
class RunOutcome(Outcome):
    """What happened to one run file (:class:`accal.batch.Outcome` plus demod results).

    ``outputs`` are the cumulative periods table, the summary JSON and Markdown
    (and the closure's plots).

    Attributes
    ----------
    summary : dict
        The JSON summary (empty on failure, and when skipped).
    warnings : tuple of str
        Findings worth telling the user (mask mismatch, dropped periods, ...).
    skipped : bool
        True when the manifest says the outputs are current (nothing was done).
    n_samples : int
        Samples demodulated.
    n_bytes : int
        Size of the run file [bytes].
    peak_rss : float
        Peak resident memory of the process that demodulated the run [MB] (0 where
        unknown).
    signature : dict or None
        Size and mtime of the run file before it was read (see
        :meth:`accal.batch.Manifest.record`).
    n_rows : int
        Rows of the run in the periods table.
    result : DemodResult or None
        What the worker computed and this process writes
        (:func:`accal.demodjob.batch.write_run`); None once written.
    """

    summary: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    skipped: bool = False
    n_samples: int = 0
    n_bytes: int = 0
    peak_rss: float = 0.0
    signature: dict[str, Any] | None = None
    n_rows: int = 0
    result: DemodResult | None = None


@dataclass(frozen=True)
class DemodResult:
    """A demodulated run not yet written: its periods rows and what goes with them.

    Attributes
    ----------
    rows : dict
        Columns of the run's rows of the periods table.
    units : dict
        Units of those columns.
    source_meta : dict
        The run's entry of the table metadata (``accal.meta["sources"]``), without
        the name of its summary (known where it is written).
    closure : dict or None
        The run's entry of ``closure.json`` (``--close-loop``), else None.
    """

    rows: dict[str, Any]
    units: dict[str, str]
    source_meta: dict[str, Any]
    closure: dict[str, Any] | None = None


@dataclass(frozen=True)
class DemodRunSummary(BatchSummary):
    """Result of :func:`accal.demodjob.batch.run_demod` over a batch.

    :class:`accal.batch_summary.BatchSummary` (the counts and end-of-run line every
    batch command shares) of :class:`RunOutcome`, its line naming ``accal demod``;
    ``table_path`` is the periods table.
    """

    outcomes: list[RunOutcome]

    command: ClassVar[str] = "accal demod"


@dataclass
class RunInfo:
    """What the reading pass found out about a run (filled while streaming).

    Attributes
    ----------
    n_input : int
        Rows of the file.
    n_samples : int
        Samples demodulated (grid points when resampled).
    step : float
        Sampling step [s] (nominal, from the first chunk).
    t_first : float
        First sample time [s].
    axes, aux_channels : list of str
        Accelerometer axes and auxiliary channels of the file.
    units : dict
        Units of the file's channels.
    resample : dict or None
        :class:`accal.estimators.resample.ResampleReport` as a dict, if resampled.
    warnings : list of str
        Reader findings.
    """

    n_input: int = 0
    n_samples: int = 0
    step: float = float("nan")
    t_first: float = float("nan")
    axes: list[str] = field(default_factory=list)
    aux_channels: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=dict)
    resample: dict[str, Any] | None = None
    warnings: list[str] = field(default_factory=list)
