"""The ``demod`` pipeline: read → validate → demodulate → write, per run file.

Like :mod:`accal.pipeline`, this module sequences the other layers (the reader
:func:`accal.io.rawlog.open_rawlog`, the estimators of
:mod:`accal.estimators.demod` and :mod:`accal.estimators.resample`, the writers
of :mod:`accal.io.writers` and :mod:`accal.io.merge`); the numbers come from the
estimators.  It also holds the library side of ``accal design``, ``accal budget``
and ``accal simulate gap`` so that the CLI stays thin.

A run is read in chunks of ``chunk_rows`` rows (two passes: checks, then
estimates; see :func:`accal.estimators.demod.demodulate_stream`), so memory is
bounded by the chunk, not by the run: a year of 1 Hz data fits in a few hundred
MB.  The results equal those of a whole-file run to rounding.

Outputs of :func:`run_demod`
----------------------------
``DIR/periods.<fmt>``: one cumulative table, one row per source and period, with
a ``source`` column (the input's file name).  Every run merges its rows into it;
a re-run of a source replaces that source's rows (never duplicates them).  The
options, solver and Rd of every source are in the table metadata
(``accal.meta["sources"]``).

Summaries: with one input ``DIR/summary.json`` and ``DIR/summary.md``; with
several ``DIR/<stem>.summary.json`` and ``DIR/<stem>.summary.md`` where ``<stem>``
is the input name without its suffixes (``run1.csv.gz`` → ``run1``); inputs whose
stems collide are refused before anything runs.  One input into a directory that
already holds the summary of another run (one run per call, from cron) is named
after its stem too, so the earlier run's summary stays beside its rows.  An input's summaries and its
rows in the table are written together (temporary files renamed at the end):
either all of them appear or none (a failed input leaves the directory as it was).
"""

from __future__ import annotations

import contextlib
import json
import os
import time as _time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.batch import Outcome, check_input, failure_message, internal_error_message
from accal.errors import AccalError, ValidationError, check_option

#: Standard integration time for σ(T) in the summary: 3 h, as in the paper (Fig. 5) [s].
STANDARD_INTEGRATION = 3 * 3600.0
#: Measured masked time differing from --mask by more than this fraction is flagged.
MASK_RTOL = 0.1
#: Rows read at a time (~3 days at 1 Hz; ~0.3 GB peak for LS, see docs/demod.md).
CHUNK_ROWS = 1 << 18
#: Smallest chunk accepted (the sampling step is taken from the first chunk).
MIN_CHUNK_ROWS = 16
#: Simulations longer than this are generated and written in blocks of this length [day].
SIMULATE_CHUNK_DAYS = 10.0

PERIOD_UNITS = {
    "source": "input file name",
    "period": "index of the modulation period from the start of the run",
    "t_start": "s (first sample of the period; time origin of the input)",
    "t_mid": "s (mean sample time of the period: the epoch a_Y, a_Z and the bias refer to)",
    "a_Y": "m/s^2 (period mean of the acceleration along Y, bias removed)",
    "a_Z": "m/s^2 (period mean of the acceleration along Z, bias removed)",
    "sigma_Y": "m/s^2 (1 sigma of a_Y from the noise PSD)",
    "sigma_Z": "m/s^2 (1 sigma of a_Z from the noise PSD)",
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

    ``outputs`` are the cumulative periods table, the summary JSON and Markdown.

    Attributes
    ----------
    summary : dict
        The JSON summary (empty on failure).
    warnings : tuple of str
        Findings worth telling the user (mask mismatch, dropped periods, ...).
    """

    summary: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class DemodRunSummary:
    """Result of :func:`run_demod` over a batch."""

    outcomes: list[RunOutcome]
    seconds: float

    @property
    def n_ok(self) -> int:
        """Inputs processed."""
        return sum(o.ok for o in self.outcomes)

    @property
    def n_failed(self) -> int:
        """Inputs that failed."""
        return sum(not o.ok for o in self.outcomes)


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


# ---------------------------------------------------------------------------
# steps


#: A-priori and empirical σ differing by more than this factor (either way) is a warning.
NOISE_RATIO_WARN = 2.0
#: Signal leakage (RMS over periods, in σ) above which ``summary_warnings`` tells.
LEAKAGE_WARN = 0.3


def load_psd(spec: str | None):
    """The a-priori PSD: ``"microstar"``/``"auto"``/None → eq. 1; else a table file (``f``, ``S``).

    With ``"auto"`` eq. 1 is the fall-back of a run too short for the PSD from the
    data, and the reference the data's noise is compared with.

    Raises
    ------
    AccalError
        Unreadable table or invalid values (the message names the file).
    """
    from accal.estimators.noise import as_psd
    from accal.io.rawlog import read_psd

    if spec is None or str(spec).lower() in ("microstar", "auto"):
        return as_psd(None)
    path = Path(spec)
    f, s = read_psd(path)
    try:
        return as_psd((f, s))
    except ValidationError as exc:
        raise ValidationError(f"{path}: {exc}") from None


def sampling_step(stream: Any, opts: DemodOptions) -> float:
    """Nominal sampling step of a run [s], from its first chunk.

    The step of :func:`accal.estimators.demod.sampling_step` (the mean step of a regular chunk);
    when ``τ/step`` is a whole number to within the rounding of the times (absolute
    times such as GPS seconds carry ~1e-7 s of it), ``τ/round(τ/step)``.  With
    ``opts.resample`` the estimate of :func:`accal.estimators.resample.nominal_step`
    (robust to jitter and snapped to a whole number of samples per τ).  Only the
    first chunk is read.
    """
    from accal.estimators.demod import sampling_step as regular_step
    from accal.estimators.resample import nominal_step

    for chunk in stream:
        if len(chunk) < 2:
            raise ValidationError(f"need at least 3 samples, got {len(chunk)}")
        if opts.resample:
            return nominal_step(chunk.time, opts.tau)
        step, rtol = regular_step(np.asarray(chunk.time, float))
        q = opts.tau / step if step > 0 else 0.0
        if rtol > 0 and round(q) >= 1 and abs(q - round(q)) <= q * rtol:
            step = opts.tau / round(q)
        return step
    raise ValidationError("need at least 3 samples, got 0")  # pragma: no cover (reader raises)


def _chunk(t: np.ndarray, cols: dict[str, np.ndarray], valid: Any, aux: Sequence[str]) -> Any:
    """A :class:`DemodChunk` of the validated columns (``aux``: channels carried along)."""
    from accal.estimators.demod import DemodChunk

    return DemodChunk(t, cols["m_y"], cols["m_z"], cols["theta"], {k: cols[k] for k in aux}, valid)


def validated_chunks(stream: Any, opts: DemodOptions, step: float, info: RunInfo) -> Iterator[Any]:
    """Check a run chunk by chunk and turn it into demodulation chunks.

    Checks (each a one-line :class:`ValidationError`): the ``--bias-model``
    channels exist; no NaN/inf in m_y, m_z, θ or those channels (count over the
    whole run, first time and row); uniform sampling (every step within 1e-6 of
    ``step``, counted over the whole run), unless ``opts.resample``, which
    resamples onto ``t0 + k·step`` (gaps longer than ``opts.gap_factor`` steps
    stay gaps, marked invalid); run at least one τ long.  When a check fails the
    rest of the file is still read (not demodulated) to count the problem.

    Parameters
    ----------
    stream : RawlogStream
        The opened run file.
    opts : DemodOptions
        Options.
    step : float
        Nominal sampling step [s] (:func:`sampling_step`).
    info : RunInfo
        Filled in while iterating.

    Yields
    ------
    accal.estimators.demod.DemodChunk
    """
    from accal.estimators.demod import step_tolerance
    from accal.estimators.resample import UniformResampler

    info.n_input = info.n_samples = 0
    info.step = step
    info.axes = list(stream.axes)
    resampler = UniformResampler(step, gap_factor=opts.gap_factor) if opts.resample else None
    problem: dict[str, Any] | None = None
    last_t: float | None = None
    n_steps = 0
    for chunk in stream:
        if info.n_input == 0:
            info.t_first = float(chunk.time[0])
            info.aux_channels = [k for k in chunk.aux]
            info.units = {k: v for k, v in stream.units.items() if k in chunk.aux}
            for ch in opts.aux_channels:
                if ch not in chunk.aux:
                    raise ValidationError(
                        f"--bias-model {opts.bias_model}: no auxiliary channel {ch!r} "
                        f"(channels: {', '.join(chunk.aux) or 'none'})"
                    )
        cols = {"m_y": chunk.axis("y"), "m_z": chunk.axis("z"), "theta": chunk.theta}
        cols.update({ch: np.asarray(chunk.aux[ch], float) for ch in opts.aux_channels})
        t = chunk.time
        steps = np.diff(t) if last_t is None else np.diff(np.concatenate([[last_t], t]))
        t_of_step = t[:-1] if last_t is None else np.concatenate([[last_t], t[:-1]])
        n_steps += steps.size
        last_t = float(t[-1])
        row0 = info.n_input
        info.n_input += t.size
        if problem is None or problem["kind"] == "nan":
            for name, x in cols.items():
                bad = np.flatnonzero(~np.isfinite(x))
                if not bad.size:
                    continue
                if problem is None:
                    problem = {
                        "kind": "nan",
                        "name": name,
                        "n": 0,
                        "t": t[bad[0]],
                        "row": row0 + bad[0],
                    }
                if problem["name"] == name:
                    problem["n"] += bad.size
        if not opts.resample and (problem is None or problem["kind"] == "step"):
            tol = step_tolerance(step, max(abs(float(t[0])), abs(last_t))) if t.size else 0.0
            off = np.flatnonzero(np.abs(steps - step) > tol)
            if off.size:
                k = off[np.argmax(np.abs(steps[off] - step))]
                # the 1-based row of the sample after the step (the first chunk's steps
                # start at its first row; later ones at the previous chunk's last)
                row = row0 + int(k) + (2 if row0 == 0 else 1)
                if problem is None:
                    problem = {"kind": "step", "n": 0, "big": steps[k], "t": t_of_step[k]}
                    problem["row"] = row
                problem["n"] += off.size
                if abs(steps[k] - step) > abs(problem["big"] - step):
                    problem["big"], problem["t"], problem["row"] = steps[k], t_of_step[k], row
        if problem is not None:
            continue
        if resampler is not None:
            t, cols, valid = resampler.push(t, cols)
        else:
            valid = None
        info.n_samples += t.size
        yield _chunk(t, cols, valid, opts.aux_channels)
    if resampler is not None and problem is None:
        # the grid point just after the last sample (jitter): no last period lost
        t, cols, valid = resampler.finish()
        if t.size:
            info.n_samples += t.size
            yield _chunk(t, cols, valid, opts.aux_channels)
    info.warnings = list(stream.warnings)
    if resampler is not None:
        info.resample = resampler.report.as_dict()
    if problem is not None and problem["kind"] == "nan":
        raise ValidationError(
            f"{problem['name']} has {problem['n']} NaN/inf value(s), first at "
            f"t = {problem['t']:.9g} s (row {int(problem['row']) + 1})"
        )
    if problem is not None:
        raise ValidationError(
            f"irregular sampling: {problem['n']} of {n_steps} steps differ from the nominal "
            f"{step:.9g} s (largest: {problem['big']:.9g} s after t = {problem['t']:.4f} s, "
            f"before row {problem['row']}); use --resample to interpolate onto a uniform grid"
        )
    duration = info.n_samples * step
    if duration < opts.tau * (1 - 1e-9):
        raise ValidationError(
            f"run lasts {duration:.9g} s ({info.n_samples} samples), shorter than one "
            f"modulation period (tau = {opts.tau:g} s)"
        )


def estimate(path: Path, opts: DemodOptions, psd: Any) -> tuple[Any, RunInfo]:
    """Read and demodulate one run file in chunks (two passes, bounded memory).

    Returns
    -------
    (DemodResult, RunInfo)

    Raises
    ------
    AccalError
        Bad file or data (one line).
    """
    from accal.estimators.demod import demodulate_stream
    from accal.io.rawlog import open_rawlog

    stream = open_rawlog(path, rows=int(opts.chunk_rows))
    step = sampling_step(stream, opts)
    info = RunInfo()
    try:
        res = demodulate_stream(
            lambda: validated_chunks(stream, opts, step, info),
            tau=opts.tau,
            mask=opts.mask,
            fs=1.0 / step,
            method=opts.method,
            signal_model=opts.signal_model,
            rest_tol=opts.rest_tol,
            bias_aux=opts.aux_channels,
            psd=psd,
            noise="data" if str(opts.psd).lower() == "auto" else "report",
        )
    except ValidationError as exc:
        # a θ the file declared in another unit and accal converted: the declaration may
        # be what is wrong (QA: radians declared 'deg' said only "never reaches π")
        factor = stream.factors.get("theta")
        if factor is not None and "theta" in str(exc):
            unit = stream.declared_units.get("theta", "?")
            raise ValidationError(
                f"{exc} (theta is declared in {unit!r} and was converted to rad by "
                f"× {factor:.10g}: is that its unit?)"
            ) from None
        raise
    return res, info


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
    data["n_used"] = res.n_used.astype(np.int64)
    data["masked_time"] = res.masked_time
    data["leakage"] = res.leakage
    units.update({k: PERIOD_UNITS[k] for k in ("n_used", "masked_time", "leakage")})
    return data, units


def summarise(
    path: Path, info: RunInfo, res: Any, opts: DemodOptions, *, out_dir: Path | None = None
) -> dict[str, Any]:
    """The run summary (JSON-ready): Rd, σ(T), leakage, masking, drops, sinusoid fit.

    ``source`` is the run's path as given; ``source_path`` the resolved absolute
    path and, with ``out_dir`` (where the summary goes), ``source_relpath`` the
    path relative to it, so that the run is found again from any working
    directory, and after the run and the output directory moved together
    (:func:`find_run`).
    """
    from accal.estimators.demod import fit_sinusoid, sigma_mean

    n = res.a_Y.size
    rd = np.asarray(res.Rd, float)
    n_std = max(1, int(round(opts.integration / res.tau)))
    # σ of the mean of the kept periods at their own lags (no lag that no pair has)
    sigma_run = sigma_mean(rd, n, index=res.period_index)
    sigma_std = sigma_mean(rd, n_std)
    unknown = [k for k in range(1, min(n_std, rd.size)) if not np.isfinite(rd[k])]
    std_note = None
    if unknown:
        std_note = (
            f"not computed: Rd[{unknown[0]}] is unknown because no two kept periods are "
            f"{unknown[0]} period(s) apart ({res.dropped} of {res.n_periods} periods dropped); "
            f"the mean over {opts.integration:g} s of consecutive periods needs it"
        )
    shift = float(getattr(res, "rotation_shift", float("nan")))
    m_periods = int(getattr(res, "pattern_periods", 0))
    # a steady shift of a few samples: the pattern's period is tau + shift; layouts that
    # repeat every m periods: m·tau (QA: --tau 300 on a 600 s pattern was told "give
    # --tau 332" from the shift between its two halves); otherwise it does not repeat
    near = bool(
        np.isfinite(shift)
        and abs(shift) / res.fs < SHIFT_NEAR * res.tau
        and getattr(res, "rotation_shift_steady", True)
    )
    if m_periods >= 1:
        every = m_periods * res.tau
    elif near:
        every = res.tau + shift / res.fs
    else:
        every = None
    dropped = sorted(set(range(res.n_periods)) - set(res.period_index.tolist()))
    mt = res.masked_time
    measured = float(np.median(mt))
    mismatch = abs(measured - opts.mask) > MASK_RTOL * max(opts.mask, 1.0 / res.fs)
    out: dict[str, Any] = {
        "source": str(path),
        "source_path": str(Path(path).resolve()),
        "source_relpath": _relpath(path, out_dir) if out_dir is not None else None,
        "accal_version": __version__,
        "input": {
            "n_rows": info.n_input,
            "n_samples": info.n_samples,
            "fs": res.fs,
            "duration": info.n_samples / res.fs,
            "t_first": info.t_first,
            "resampled": info.resample is not None,
            "resample": info.resample,
            "axes": info.axes,
            "aux_channels": info.aux_channels,
            "chunk_rows": int(opts.chunk_rows),
            "warnings": list(info.warnings),
        },
        "options": {
            "tau": opts.tau,
            "mask": opts.mask,
            "method": opts.method,
            "psd": opts.psd,
            "signal_model": opts.signal_model,
            "bias_model": opts.bias_model,
            "rest_tol": opts.rest_tol,
        },
        "solver": res.solver,
        "n_periods": res.n_periods,
        "n_kept": n,
        "dropped": res.dropped,
        "dropped_periods": dropped,
        "masked_fraction": res.masked_fraction,
        "mask": {
            "nominal": opts.mask,
            "measured_median": measured,
            "measured_min": float(mt.min()),
            "measured_max": float(mt.max()),
            "mismatch": bool(mismatch),
            "tolerance": MASK_RTOL,
        },
        "leakage_max": res.max_leakage,
        "pattern": {
            "rotation_shift": shift / res.fs if np.isfinite(shift) else None,
            "repeats_every": every,
            "pattern_periods": m_periods,
            "units": "s (median shift of the rotations from one period to the next: 0 when "
            "the rotation pattern repeats every tau; the period it repeats with); "
            "pattern_periods: the layout repeats every that many periods (0: not found)",
        },
        "Rd": rd.tolist(),
        "Rd_units": "m^2/s^4 (autocovariance of a_Y per period lag, eq. 23)",
        "sigma_T": {
            "run": {"T": n * res.tau, "n_periods": n, "sigma": sigma_run},
            "standard": {
                "T": n_std * res.tau,
                "n_periods": n_std,
                "sigma": float("nan") if std_note else sigma_std,
                "note": std_note,
            },
            "units": "m/s^2 (1 sigma of the mean over T, full Rd[k]; the run's at the lags "
            "of its kept periods)",
        },
        "mean": {
            "a_Y": float(np.mean(res.a_Y)),
            "a_Z": float(np.mean(res.a_Z)),
            "sigma": sigma_run,
            "units": "m/s^2 (plain mean of the kept periods; sigma at their own lags)",
        },
        "noise": noise_summary(res, opts),
        "consistency": consistency_summary(res),
        "signal_leakage": leakage_summary(res),
    }
    if opts.sinusoid_period is not None:
        fits = {}
        for ax in ("Y", "Z"):
            fit = fit_sinusoid(
                res.t_mid,
                getattr(res, f"a_{ax}"),
                1.0 / opts.sinusoid_period,
                rd=rd,
                index=res.period_index,
                constant=opts.sinusoid_constant,
            )
            fits[ax] = {
                "alpha": fit.alpha,
                "beta": fit.beta,
                "offset": fit.offset if fit.constant else None,
                "cov": fit.cov.tolist(),
                "sigma_alpha": fit.sigma_alpha,
                "sigma_beta": fit.sigma_beta,
                "sigma_offset": fit.sigma_offset if fit.constant else None,
            }
        model = "a(t) = alpha cos(2 pi f* t) + beta sin(2 pi f* t)"
        out["sinusoid"] = {
            "period": opts.sinusoid_period,
            "f_star": 1.0 / opts.sinusoid_period,
            "t_origin": 0.0,
            "constant": opts.sinusoid_constant,
            "model": model + (" + offset" if opts.sinusoid_constant else "") + ", t = t_mid",
            "units": "m/s^2 (alpha, beta, offset), m^2/s^4 (cov, order alpha, beta[, offset])",
            **fits,
        }
    return out


def noise_summary(res: Any, opts: DemodOptions) -> dict[str, Any]:
    """The a-priori and the empirical noise of a run (JSON-ready; issue 20).

    Levels are ``sqrt(S(2/τ))`` [m s⁻² Hz⁻¹ᐟ²], where the per-period estimate takes
    its noise (eq. 26, Fig. 3); ``sigma_ratio`` is the σ the a-priori PSD gives over
    the σ the data's PSD gives, for the same estimator.
    """
    rep = getattr(res, "noise", None)
    if rep is None:
        return {"psd_used": "apriori", "apriori": opts.psd}
    f2 = 2.0 / res.tau
    fit = rep.fit
    apriori = "microstar" if str(opts.psd).lower() == "auto" else opts.psd
    return {
        "psd_used": rep.source,
        "apriori": apriori,
        "reason": rep.reason or None,
        "n_periods": rep.n_periods,
        "f_level": f2,
        "level_apriori": float(np.sqrt(rep.apriori(f2))),
        "level_data": float(np.sqrt(fit.psd(f2))) if fit is not None else None,
        "sigma_ratio": rep.sigma_ratio if fit is not None else None,
        "psd_data": (
            {"f": fit.nodes.tolist(), "S": fit.values.tolist()} if fit is not None else None
        ),
        "units": "levels m/s^2/sqrt(Hz) at f_level [Hz] = 2/tau (two-sided PSD); sigma_ratio: "
        "sigma from the a-priori PSD / sigma from the data's PSD, same estimator; psd_data: "
        "the PSD estimated from the residual, f [Hz], S [m^2/s^4/Hz] (usable as --psd FILE)",
    }


def consistency_summary(res: Any) -> dict[str, Any]:
    """χ² of the run's residual against the PSD behind σ (replaces the old scatter/σ).

    ``ratio`` = observed / expected periodogram of the per-period residual over
    ``1/τ … 4/τ`` (the band that sets σ), expected under the PSD used: 1 within
    ``scatter`` when that PSD describes the noise of the run.
    """
    rep = getattr(res, "noise", None)
    if rep is None or not np.isfinite(rep.check_ratio):
        return {"ratio": None}
    return {
        "test": "residual periodogram / its expectation under the PSD used (chi2/dof), "
        "band 1/tau-4/tau",
        "ratio": rep.check_ratio,
        "scatter": rep.check_scatter,
        "band": list(rep.band),
    }


def leakage_summary(res: Any) -> dict[str, Any]:
    """Signal leakage (:func:`accal.estimators.demod.signal_leakage`) as a JSON-ready dict."""
    from accal.estimators.demod import signal_leakage

    lk = signal_leakage(res)
    out: dict[str, Any] = {"n_periods": lk.n, "signal_model": res.signal_model}
    for j, ax in enumerate(("Y", "Z")):
        out[ax] = {
            "rms": float(lk.rms[j]),
            "ratio": float(lk.ratio[j]),
            "ratio_slope": float(lk.ratio_slope[j]),
            "max": float(lk.max[j]),
        }
    out["units"] = (
        "m/s^2 (rms: RMS over periods of the estimated leakage of the signal's in-period "
        "slope and curvature into a_Y, a_Z, noise removed; ratio: rms / RMS sigma; "
        "ratio_slope: the slope's part (removed by --signal-model affine); max: "
        "largest |estimate|, noise included)"
    )
    return out


def _summary_of_extended(summary: dict[str, Any], rows: Mapping[str, Any], model: str) -> None:
    """Point the summary's mean at the extended model's per-period values.

    The declared model's go to ``summary["declared"]`` (QA: after a closure the
    summary's mean a_Y was still the declared model's, 23σ off, while the periods
    held the corrected values).  ``Rd``, the σ over T and the noise report stay
    those of the declared demodulation.
    """
    summary["declared"] = {"mean": dict(summary["mean"])}
    for ax in ("Y", "Z"):
        a = np.asarray(rows[f"a_{ax}"], dtype=np.float64)
        s = np.asarray(rows[f"sigma_{ax}"], dtype=np.float64)
        ok = np.isfinite(a) & np.isfinite(s)
        summary["mean"][f"a_{ax}"] = float(np.mean(a[ok])) if ok.any() else float("nan")
    summary["mean"]["model"] = model


def _relpath(path: Path, start: Path) -> str | None:
    """``path`` relative to the directory ``start`` (None if there is no such path)."""
    try:
        return os.path.relpath(Path(path).resolve(), Path(start).resolve())
    except ValueError:  # another drive (Windows)
        return None


def find_run(summary: dict[str, Any], summary_path: Path) -> Path:
    """The run file a demod summary names, wherever the current directory is.

    Tried in order: ``source_path`` (absolute), ``source_relpath`` relative to the
    summary's directory, ``source`` as given (relative to the current directory),
    ``source`` relative to the summary's directory (summaries of older versions
    only have ``source``).

    Parameters
    ----------
    summary : dict
        The parsed ``summary.json``.
    summary_path : Path
        Its file.

    Returns
    -------
    Path
        The first candidate that exists.

    Raises
    ------
    ValidationError
        None exists (the message lists the places tried).
    """
    here = Path(summary_path).parent
    source = Path(summary["source"])
    tried: list[Path] = []
    for key, base in (("source_path", None), ("source_relpath", here), ("source", None)):
        value = summary.get(key)
        if isinstance(value, str) and value:
            tried.append(Path(value) if base is None else base / value)
    if not source.is_absolute():
        tried.append(here / source)
    seen: list[Path] = []
    for cand in tried:
        if cand not in seen:
            seen.append(cand)
        if cand.is_file():
            return cand
    raise ValidationError(
        f"{source}: run file of {Path(summary_path).name} not found (moved?); "
        f"looked for {', '.join(map(str, seen))}"
    )


#: Shift of the rotations from one period to the next above which --tau is taken not
#: to match the pattern [samples]: 0 for a pattern that repeats every τ (also with a
#: four-angle pattern, an affine signal model, or jittered and resampled timing), 1
#: for a 600 s pattern demodulated with --tau 599 at 1 Hz.
SHIFT_WARN = 0.5
#: A shift shorter than this fraction of τ gives the pattern's period (τ + shift);
#: a longer one only says that the pattern does not repeat every τ.
SHIFT_NEAR = 1 / 8


def tau_of(summary: dict[str, Any]) -> float:
    """The modulation period ``--tau`` a summary was made with [s]."""
    return float(summary["options"]["tau"])


def summary_warnings(summary: dict[str, Any]) -> tuple[str, ...]:
    """Findings of a summary worth a line on stderr."""
    w = list(summary["input"].get("warnings") or [])
    m = summary["mask"]
    if m["mismatch"]:
        w.append(
            f"measured masked time {m['measured_median']:g} s per period differs from "
            f"--mask {m['nominal']:g} s by more than {100 * m['tolerance']:g} %"
        )
    if summary["dropped"]:
        w.append(f"{summary['dropped']} of {summary['n_periods']} periods dropped")
    # samples after the last whole period are not used (QA: a 900 s run said "1/1
    # periods" with its last 300 s silently left out)
    fs = summary["input"]["fs"]
    tail = int(summary["input"]["n_samples"]) - int(
        round(summary["n_periods"] * tau_of(summary) * fs)
    )
    if tail > 0:
        w.append(
            f"the last {tail / fs:g} s ({tail} samples) are less than one period "
            f"(--tau {tau_of(summary):g} s) and are not used"
        )
    # eq. 16 leakage alone is no fault: the joint fit of eq. 17 (chosen whenever it is not
    # ~0) removes the bias whatever the pattern (four angles, an affine signal model, jitter
    # give some).  What is wrong is a --tau that is not the pattern's period: then the
    # rotations move from one period to the next.
    pat = summary.get("pattern") or {}
    shift, tau = pat.get("rotation_shift"), tau_of(summary)
    m_periods = int(pat.get("pattern_periods") or 0)
    if m_periods > 1:
        w.append(
            f"the rotations differ from one period to the next and repeat every {m_periods} "
            f"periods: the pattern's period is {m_periods * tau:.9g} s, not --tau {tau:g} s; "
            f"give --tau {m_periods * tau:.9g}"
        )
    elif (
        m_periods == 0
        and pat.get("repeats_every") is None
        and "pattern_periods" in pat
        and shift is not None
        and np.isfinite(shift)  # at least two periods to compare
    ):
        from accal.estimators.demod import LAYOUT_LAGS

        w.append(
            f"the rotations differ from one period to the next and do not repeat within "
            f"{LAYOUT_LAGS} periods: the pattern does not repeat every --tau {tau:g} s; give "
            "--tau its period (or fix the time column)"
        )
    elif (
        m_periods != 1 and shift is not None and np.isfinite(shift) and abs(shift) * fs > SHIFT_WARN
    ):
        leak = summary.get("leakage_max")
        leak_text = (
            f"; eq. 16 leakage up to {leak:.2g}, removed by the joint fit of eq. 17"
            if leak is not None and np.isfinite(leak) and leak > 1e-9
            else ""
        )
        every = pat.get("repeats_every")
        if every is not None:
            what = f"the pattern repeats every {every:.9g} s, not --tau {tau:g} s; give --tau {every:.9g}"
        else:
            what = f"the pattern does not repeat every --tau {tau:g} s; give --tau its period"
        w.append(
            f"the rotations move by {shift:+.9g} s from one period to the next: {what} "
            f"(or fix the time column){leak_text}"
        )
    w += _noise_warnings(summary)
    rs = summary["input"].get("resample")
    if rs:
        held = rs.get("n_end_held", 0)
        w.append(
            f"resampled onto a {rs['step']:.9g} s grid: {rs['n_interpolated']} samples "
            f"interpolated, {rs['n_gap']} in {rs['n_gaps']} gap(s) marked invalid "
            f"(largest gap {rs['largest_gap']:.9g} s)"
            + (f", {held} grid point after the last sample took its value" if held else "")
        )
    return tuple(w)


def _noise_warnings(summary: dict[str, Any]) -> list[str]:
    """Warnings on the noise (a-priori vs data, fall-back) and on the signal leakage."""
    w: list[str] = []
    nz = summary.get("noise") or {}
    auto = str(summary["options"].get("psd")).lower() == "auto"
    ratio = nz.get("sigma_ratio")
    if auto and nz.get("psd_used") == "apriori" and nz.get("reason"):
        w.append(
            f"sigma from the a-priori PSD ({nz['apriori']}), not from the data: "
            f"{nz['reason']}; check it against the instrument's noise"
        )
    if ratio is not None and not 1 / NOISE_RATIO_WARN <= ratio <= NOISE_RATIO_WARN:
        what = (
            "sigma, Rd and GLS use the PSD from the data"
            if nz.get("psd_used") == "data"
            else f"sigma uses --psd {nz['apriori']} as asked: it is {ratio:.3g} x what the "
            "run's noise gives (drop --psd to use the data's)"
        )
        w.append(
            f"the noise of this run differs from the a-priori PSD ({nz['apriori']}) by more "
            f"than a factor {NOISE_RATIO_WARN:g}: sigma a-priori / sigma data = {ratio:.3g} "
            f"(noise at 2/tau: {nz['level_apriori']:.3g} a-priori, {nz['level_data']:.3g} "
            f"data, m/s^2/sqrt(Hz)); {what}"
        )
    lk = summary.get("signal_leakage") or {}
    worst = max((lk[ax]["ratio"] for ax in ("Y", "Z") if ax in lk), default=float("nan"))
    if np.isfinite(worst) and worst > LEAKAGE_WARN:
        slope = max(lk[ax].get("ratio_slope", 0.0) for ax in ("Y", "Z") if ax in lk)
        hint = (
            "use --signal-model affine"
            if lk.get("signal_model") == "mean" and slope > 0.5 * worst
            else "it is the signal's curvature: a shorter --tau reduces it"
        )
        w.append(
            f"the signal's variation within a period leaks into a_Y/a_Z at {worst:.2g} sigma "
            f"(RMS over periods, --signal-model {lk.get('signal_model')}), not in sigma; {hint}"
        )
    return w


def summary_markdown(s: dict[str, Any]) -> str:
    """Human-readable version of the summary."""

    def e(x: Any) -> str:
        return "n/a" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.4g}"

    o = s["options"]
    rs = s["input"].get("resample")
    resampled = ""
    if rs:
        resampled = (
            f" (resampled to {rs['step']:.9g} s: {rs['n_interpolated']} interpolated, "
            f"{rs['n_gap']} in {rs['n_gaps']} gap(s) masked)"
        )
    lines = [
        f"# accal demod: {Path(s['source']).name}",
        "",
        f"accal {s['accal_version']}; tau = {o['tau']:g} s, mask = {o['mask']:g} s, "
        f"method = {o['method']} ({s['solver']}), signal model = {o['signal_model']}, "
        f"bias model = {o['bias_model']}, PSD = {o['psd']}.",
        "",
        "| quantity | value |",
        "| --- | --- |",
        f"| samples, fs | {s['input']['n_samples']}, {s['input']['fs']:g} Hz{resampled} |",
        f"| periods kept / whole | {s['n_kept']} / {s['n_periods']} |",
        f"| dropped periods | {_ranges(s['dropped_periods']) or 'none'} |",
        f"| masked fraction | {s['masked_fraction']:.4f} |",
        f"| masked time per period (median, min–max) | {s['mask']['measured_median']:g} s "
        f"({s['mask']['measured_min']:g}–{s['mask']['measured_max']:g}); --mask {o['mask']:g} s"
        f"{' **MISMATCH**' if s['mask']['mismatch'] else ''} |",
        f"| max eq. 16 leakage | {e(s['leakage_max'])} |",
        f"| Rd[0..{len(s['Rd']) - 1}] [m²/s⁴] | {', '.join(e(x) for x in s['Rd'])} |",
        f"| σ of the mean over the run ({s['sigma_T']['run']['T']:g} s) | "
        f"{e(s['sigma_T']['run']['sigma'])} m/s² |",
        f"| σ of the mean over {s['sigma_T']['standard']['T']:g} s | "
        + (
            f"n/a ({s['sigma_T']['standard']['note']}) |"
            if s["sigma_T"]["standard"].get("note")
            else f"{e(s['sigma_T']['standard']['sigma'])} m/s² |"
        ),
        f"| mean a_Y, a_Z{_of_model(s)} | {e(s['mean']['a_Y'])}, {e(s['mean']['a_Z'])} m/s² |",
        *_noise_markdown(s, e),
    ]
    if "declared" in s:
        d = s["declared"]
        lines += [
            f"| mean a_Y, a_Z (declared model) | {e(d['mean']['a_Y'])}, {e(d['mean']['a_Z'])} "
            "m/s² |",
        ]
    if "sinusoid" in s:
        sn = s["sinusoid"]
        for ax in ("Y", "Z"):
            f = sn[ax]
            off = f", c = {e(f['offset'])} ± {e(f['sigma_offset'])}" if sn.get("constant") else ""
            lines.append(
                f"| sinusoid {ax} (P = {sn['period']:g} s): α, β ± σ | "
                f"{e(f['alpha'])} ± {e(f['sigma_alpha'])}, {e(f['beta'])} ± {e(f['sigma_beta'])}"
                f" m/s², cov(α,β) = {e(f['cov'][0][1])}{off} |"
            )
    return "\n".join(lines) + "\n"


def _noise_markdown(s: dict[str, Any], e: Callable[[Any], str]) -> list[str]:
    """Rows of the summary table on the noise, the consistency check and the leakage."""
    nz = s.get("noise") or {}
    rows = []
    if "level_apriori" in nz:
        used = "the run's residual (data)" if nz["psd_used"] == "data" else nz["apriori"]
        why = f" ({nz['reason']})" if nz.get("reason") and nz["psd_used"] != "data" else ""
        rows += [
            f"| σ, Rd, GLS from the PSD of | {used}{why} |",
            f"| noise at 2/τ: a-priori ({nz['apriori']}), data [m/s²/√Hz] | "
            f"{e(nz['level_apriori'])}, {e(nz['level_data'])} |",
            f"| σ a-priori / σ data (same estimator) | {e(nz['sigma_ratio'])} |",
        ]
    c = s.get("consistency") or {}
    if c.get("ratio") is not None:
        rows.append(
            f"| residual power / expected under the PSD used, {e(c['band'][0])}–"
            f"{e(c['band'][1])} Hz (χ²/dof; 1 ± {e(c['scatter'])}) | {e(c['ratio'])} |"
        )
    lk = s.get("signal_leakage") or {}
    if "Y" in lk:
        rows.append(
            f"| in-period signal leakage, RMS/σ (Y, Z; `{lk['signal_model']}` model) | "
            f"{e(lk['Y']['ratio'])}, {e(lk['Z']['ratio'])} |"
        )
    return rows


def _of_model(s: dict[str, Any]) -> str:
    model = s["mean"].get("model")
    return f" (`{model}`)" if model else ""


def _ranges(index: Sequence[int], limit: int = 40) -> str:
    """``[1, 2, 3, 7]`` → ``"1–3, 7"`` (at most ``limit`` ranges shown)."""
    out: list[str] = []
    idx = list(index)
    i = 0
    while i < len(idx):
        j = i
        while j + 1 < len(idx) and idx[j + 1] == idx[j] + 1:
            j += 1
        out.append(str(idx[i]) if i == j else f"{idx[i]}–{idx[j]}")
        i = j + 1
    more = len(out) - limit
    return ", ".join(out[:limit]) + (f", ... ({more} more ranges)" if more > 0 else "")


# ---------------------------------------------------------------------------
# the batch


def check_distinct_runs(paths: Sequence[Path]) -> None:
    """Refuse a run file given more than once (also under another name or via a link).

    Parameters
    ----------
    paths : sequence of Path
        The run files, as given.

    Raises
    ------
    ValidationError
        One line naming the file given twice.
    """
    seen: dict[Path, Path] = {}
    for p in map(Path, paths):
        try:
            key = p.resolve()
        except (RuntimeError, OSError):  # a symlink loop: the reader says so, per run
            key = Path(os.path.abspath(p))
        if key in seen:
            what = f"run {p} is given twice"
            if seen[key] != p:
                what = f"runs {seen[key]} and {p} are the same file"
            raise ValidationError(f"{what}; give each run once")
        seen[key] = p


def output_paths(paths: Sequence[Path], out_dir: Path, fmt: str) -> list[tuple[Path, Path, Path]]:
    """``(periods table, summary.json, summary.md)`` of each input (see the module notes).

    The periods table is the same cumulative ``DIR/periods.<fmt>`` for every input.

    Raises
    ------
    ValidationError
        A run given twice (:func:`check_distinct_runs`), or two inputs that would
        write the same summaries (or the same ``source`` rows).
    """
    from accal.pipeline import output_stem

    check_distinct_runs(paths)
    table = out_dir / f"periods.{fmt}"
    if len(paths) == 1 and not _summaries_of_other_runs(out_dir, Path(paths[0]).name):
        return [(table, out_dir / "summary.json", out_dir / "summary.md")]
    seen: dict[str, Path] = {}
    out = []
    for p in paths:
        stem = output_stem(Path(p))
        other = seen.get(stem) or next((q for q in seen.values() if q.name == Path(p).name), None)
        if other is not None:
            raise ValidationError(
                f"inputs {other} and {p} would both write {stem}.summary.json; rename one"
            )
        seen[stem] = Path(p)
        out.append((table, out_dir / f"{stem}.summary.json", out_dir / f"{stem}.summary.md"))
    return out


def _summaries_of_other_runs(out_dir: Path, name: str) -> bool:
    """Whether ``out_dir`` holds the summary of a run other than ``name``.

    One run per call into the same directory (a cron job) must not overwrite the
    ``summary.json`` of the run before it, whose rows stay in the periods table:
    the new run's summaries are then named after it, as with several inputs.
    """
    return any(
        (src := summary_source(sp)) is not None and src != name
        for sp in Path(out_dir).glob("*summary.json")
    )


def check_output_format(out_dir: Path, fmt: str) -> None:
    """Refuse a ``--format`` other than that of the periods table already in ``out_dir``.

    The periods table is cumulative: a second one in the other format beside it
    would split the directory's rows in two tables (as ``grace-bias`` refuses a
    second ``bias_drift`` table).

    Raises
    ------
    ValidationError
        One line naming the existing table.
    """
    other = "csv" if fmt == "parquet" else "parquet"
    table = Path(out_dir) / f"periods.{other}"
    if table.exists():
        raise ValidationError(
            f"{table}: the periods table of this --out is in --format {other}; use --format "
            f"{other} there, or another --out for --format {fmt}"
        )


def load_summary(path: Path) -> tuple[str, dict[str, Any]] | None:
    """(run file name, content) of a demod ``summary.json``, or None if it is not one."""
    try:
        s = json.loads(Path(path).read_text())
        if isinstance(s, dict) and isinstance(s.get("options"), dict):
            return Path(s["source"]).name, s
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return None


def summary_source(path: Path) -> str | None:
    """File name of the run a ``summary.json`` is about, or None if it is not a demod summary."""
    got = load_summary(path)
    return None if got is None else got[0]


def remove_stale_summaries(out_dir: Path, source: str, keep: Path) -> list[Path]:
    """Remove the summaries of ``source`` in ``out_dir`` other than ``keep`` (and their .md).

    A run that is re-run into the same directory under another summary name
    (``summary.json`` alone, ``<stem>.summary.json`` with others) replaces its
    rows in the periods table; its old summaries describe rows that are gone.

    Returns
    -------
    list of Path
        The files removed.
    """
    gone = []
    for sp in sorted(Path(out_dir).glob("*summary.json")):
        if sp.name == keep.name or summary_source(sp) != source:
            continue
        md = sp.with_name(sp.name[: -len(".json")] + ".md")
        for f in (sp, md):
            with contextlib.suppress(FileNotFoundError):
                f.unlink()
                gone.append(f)
    return gone


def process_run(
    path: Path, targets: tuple[Path, Path, Path], opts: DemodOptions, psd: Any
) -> RunOutcome:
    """read → validate → demodulate → write for one run file (all outputs or none).

    The run's rows are merged into the cumulative periods table (replacing the
    rows of an earlier run of the same source); the table and the run's two
    summaries are renamed into place together.

    Raises
    ------
    AccalError
        On bad input; nothing is written then.
    """
    from accal.io.merge import merge_table
    from accal.io.writers import _json_default, atomic_path

    res, info = estimate(path, opts, psd)
    rows, units = period_rows(res, path.name, info.units)
    summary = summarise(path, info, res, opts, out_dir=targets[1].parent)
    closure: dict[str, Any] | None = None
    plots: list[Path] = []
    if opts.close_loop:
        step = info.step if info.resample is not None else None
        used = res.noise.used if getattr(res, "noise", None) is not None else psd
        closure, extended, plots = close_run(path, opts, targets[0].parent, step=step, psd=used)
        rows, units = apply_closure(rows, units, extended)
        summary["closure"] = {
            k: closure[k] for k in ("effects", "unexplained", "rms_before", "rms_after", "model")
        }
        _summary_of_extended(summary, rows, closure["model"])
    history = []
    if info.resample is not None:
        history.append(
            f"accal {__version__}: resample_uniform(step={info.step:.9g}, "
            f"gap_factor={opts.gap_factor:g})"
        )
    history.append(f"accal {__version__}: demodulate")
    source_meta = {
        "tau": opts.tau,
        "mask": opts.mask,
        "method": opts.method,
        "solver": res.solver,
        "signal_model": opts.signal_model,
        "bias_model": opts.bias_model,
        "psd": opts.psd,
        "Rd": summary["Rd"],
        "n_periods": res.n_periods,
        "n_kept": int(res.a_Y.size),
        "accal_version": __version__,
        "history": history,
        "summary": targets[1].name,  # the source's current summary (accal diagnose)
    }

    def table_meta(old: dict[str, Any]) -> dict[str, Any]:
        sources = dict(old.get("sources") or {})
        sources[path.name] = source_meta
        return {"accal_version": __version__, "sources": dict(sorted(sources.items()))}

    p_path, _, _ = targets
    with contextlib.ExitStack() as stack:
        tmp = [stack.enter_context(atomic_path(p)) for p in targets]
        merge_table(
            p_path,
            rows,
            key=("source",),
            sort=("source", "period"),
            fmt=opts.fmt,
            units=units,
            meta=table_meta,
            out=tmp[0],
        )
        tmp[1].write_text(json.dumps(_nan_to_none(summary), indent=2, default=_json_default) + "\n")
        tmp[2].write_text(summary_markdown(summary))
    remove_stale_summaries(targets[1].parent, path.name, targets[1])
    # without --close-loop an earlier closure of this source no longer applies (QA: its
    # report and plots stayed, and contradicted the periods written now)
    write_demod_closure(targets[0].parent, path.name, closure)
    return RunOutcome(
        path,
        True,
        outputs=(*targets, *plots),
        summary=summary,
        warnings=summary_warnings(summary),
    )


def close_run(
    path: Path, opts: DemodOptions, out_dir: Path, *, step: float | None = None, psd: Any = None
) -> tuple[dict[str, Any], Any, list[Path]]:
    """Close the loop on one run with the demodulation model as base.

    The run is read whole (:func:`accal.io.rawlog.read_rawlog`) and, with
    ``opts.resample``, resampled as the demodulation resampled it
    (:func:`accal.estimators.resample.resample_uniform` onto ``t0 + k·step``, gaps
    longer than ``opts.gap_factor`` steps kept as invalid samples, the grid point
    just after the last sample held); the declared
    model is the per-period signal (``--signal-model``) and affine bias (plus the
    ``--bias-model`` channels, eq. 18); every auxiliary channel (the declared ones
    for lagged couplings) is offered to the ``auxiliary`` candidate, with the platform candidates (angle offset,
    intra-period bias shape) and the generic ones (steps, periodic terms,
    polynomial drift).  Plots go to ``out_dir/<stem>.closure*.png``.

    Parameters
    ----------
    path : Path
        The run file.
    opts : DemodOptions
        Options of the demodulation (``tau``, models, ``resample``, ``gap_factor``, ``alpha``).
    out_dir : Path
        Where the plots go.
    step : float, optional
        With ``opts.resample``: the grid step the demodulation used [s]; default
        :func:`accal.estimators.resample.nominal_step` of the run.
    psd : PSD, optional
        The noise model of the demodulation (with ``--psd auto`` the PSD estimated
        from the run), for the per-period sigmas; made here when not given
        (``--psd auto``: by demodulating the run once).

    Returns
    -------
    closure : dict
        ``closure.json`` entry of the run (:meth:`ClosureResult.to_dict` plus
        ``model`` and per-period change statistics).
    periods : DemodPeriods
        Per-period values before/after.
    plots : list of Path
    """
    from accal.closure.demod import close_loop_demod
    from accal.closure.report import to_markdown
    from accal.io.rawlog import read_rawlog

    if psd is None and str(opts.psd).lower() == "auto":  # the PSD from the data, as demod
        res0, _ = estimate(path, opts, load_psd(opts.psd))
        psd = res0.noise.used if res0.noise is not None else load_psd(opts.psd)
    elif psd is None:
        psd = load_psd(opts.psd)
    series = read_rawlog(path)
    time, valid = series.time, series.valid
    cols = {
        "m_y": series.acc[:, list(series.axes).index("y")],
        "m_z": series.acc[:, list(series.axes).index("z")],
        **{k: np.asarray(v, dtype=np.float64) for k, v in series.aux.items()},
    }
    if opts.resample:  # the grid of the demodulation (validated_chunks' UniformResampler)
        from accal.estimators.resample import nominal_step, resample_uniform

        grid_step = step if step is not None else nominal_step(time, opts.tau)
        time, cols, valid, _ = resample_uniform(
            time, cols, grid_step, gap_factor=opts.gap_factor, hold_end=True
        )
    theta = cols["theta"]
    chans = {k: v for k, v in cols.items() if k not in ("m_y", "m_z", "theta")}
    bias_aux = {c: chans[c] for c in opts.aux_channels if c in chans}
    missing = [c for c in opts.aux_channels if c not in chans]
    if missing:
        raise ValidationError(f"bias-model channel(s) {missing} not in the run")
    # every varying channel, the declared ones too: at lag 0 they are in the base, but a
    # lagged coupling to one is not (QA: with temp2 declared, a 120 s coupling to it
    # went unreported and a_Y was off by up to 76σ)
    aux = {k: v for k, v in chans.items() if np.isfinite(v).any() and np.ptp(v[np.isfinite(v)]) > 0}

    def closure(noise_psd: Any) -> Any:
        return close_loop_demod(
            time,
            (cols["m_y"], cols["m_z"]),
            theta,
            valid,
            tau=opts.tau,
            signal_model=opts.signal_model,
            bias_model="affine",
            bias_aux=bias_aux or None,
            aux=aux or None,
            alpha=opts.alpha,
            rest_tol=opts.rest_tol,
            # sigmas before/after with the demodulation's own noise model (--psd)
            noise_psd=noise_psd,
        )

    res, periods = closure(psd)
    psd_after = psd
    if str(opts.psd).lower() == "auto" and res.effect_columns.shape[1]:
        # the PSD from the data was estimated on the declared model's residual, which
        # holds the effects found: estimate it again without them and redo the closure
        # with it (issue 20; QA: an undeclared 2e-8 temperature coupling made sigma 16x
        # the error)
        psd_after = _psd_without_effects(res, time, cols, theta, valid, bias_aux, opts, psd)
        if psd_after is not psd:
            res, periods = closure(psd_after)
    if opts.method == "gls":  # also with no effect: "before" and "after" are GLS values
        periods = _gls_after(
            res, periods, time, cols, theta, valid, bias_aux, opts, psd, psd_after=psd_after
        )
    entry = res.to_dict()
    entry["method"] = opts.method
    entry["model"] = "+".join(["declared", *periods.effects])
    entry["periods"] = change_statistics(periods.to_table())
    entry["markdown"] = to_markdown(res, title=f"{path.name}: closing the loop")
    stem = path.name.split(".")[0]
    plots = _closure_plots(res, out_dir, stem) if opts.plots else []
    return entry, periods, plots


def change_statistics(table: Mapping[str, Any]) -> dict[str, Any]:
    """RMS and median ``|change|/σ`` of the per-period change of ``a_Y``, ``a_Z``.

    ``table`` has ``period``, ``change_*``, ``sigma_change_*`` and ``sigma_*`` (after)
    columns: the periods rows, or :meth:`DemodPeriods.to_table`.

    Periods the closure left unchanged (change and its σ at rounding level, e.g.
    1e-22 ± 7e-27 m/s² beside a step in another period) count as 0 σ: their
    ratio of two rounding errors is meaningless (QA: "median |change|/σ 2.1e4").
    """
    out: dict[str, Any] = {"n": int(np.asarray(table["period"]).size)}
    for ax in ("Y", "Z"):
        change = np.asarray(table[f"change_{ax}"], dtype=np.float64)
        sig = np.asarray(table[f"sigma_change_{ax}"], dtype=np.float64)
        scale = np.asarray(table[f"sigma_{ax}"], dtype=np.float64)
        ok = np.isfinite(change)
        real = ok & (sig > 1e-6 * np.abs(scale))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(real, np.abs(change) / sig, 0.0)[ok]
        out[f"median_abs_change_{ax}_sigmas"] = float(np.median(ratio)) if ratio.size else None
        out[f"n_changed_{ax}"] = int(np.count_nonzero(real))
        out[f"rms_change_{ax}"] = float(np.sqrt(np.mean(change[ok] ** 2))) if ok.any() else None
    return out


def _effects_model(res: Any) -> tuple[np.ndarray, np.ndarray]:
    """The closure's fitted effects on ``(m_y, m_z)`` [m s⁻²] (0 when none was found)."""
    k = res.effect_columns.shape[1]  # an effect may have a column per axis
    gamma = np.asarray(res.coef[res.coef.size - k :], dtype=np.float64)
    model = np.nan_to_num(res.effect_columns) @ gamma
    return model[0::2], model[1::2]


def _psd_without_effects(
    res: Any,
    time: np.ndarray,
    cols: dict[str, np.ndarray],
    theta: np.ndarray,
    valid: Any,
    bias_aux: dict[str, np.ndarray],
    opts: DemodOptions,
    psd: Any,
) -> Any:
    """The PSD from the data (``--psd auto``) of the run with the closure's effects removed.

    ``psd`` itself when the run is too short for it.
    """
    from accal.estimators.demod import demodulate

    my, mz = _effects_model(res)
    r = demodulate(
        time,
        cols["m_y"] - my,
        cols["m_z"] - mz,
        theta,
        tau=opts.tau,
        mask=opts.mask,
        signal_model=opts.signal_model,
        bias_aux=bias_aux or None,
        psd=load_psd(opts.psd),
        valid=valid,
        rest_tol=opts.rest_tol,
        noise="data",
    )
    return r.noise.used if r.noise is not None and r.noise.source == "data" else psd


def _gls_after(
    res: Any,
    periods: Any,
    time: np.ndarray,
    cols: dict[str, np.ndarray],
    theta: np.ndarray,
    valid: Any,
    bias_aux: dict[str, np.ndarray],
    opts: DemodOptions,
    psd: Any,
    *,
    psd_after: Any = None,
) -> Any:
    """The extended model's per-period values with the declared ``--method gls``.

    The closure fits its effects by least squares together with the declared
    model; with ``--method gls`` the user asked for the GLS estimator (section
    5.3), so the effects found are subtracted from ``m_y``, ``m_z`` and the run is
    demodulated again as declared (as ``grace-bias`` refits the calibrated series).
    The σ after adds to that GLS σ the variance the closure attributes to the
    effects' estimation, ``σ²_after,LS − σ²_before,LS`` (QA: with ``--method gls
    --close-loop`` the LS values were written, ``a_Y_before`` was GLS, and the
    change was an estimator difference).  "Before" is the declared GLS
    demodulation of the same samples, so the change and its statistics are those
    of the GLS values (the same from ``accal diagnose``).
    """
    from dataclasses import replace

    from accal.estimators.demod import demodulate

    k = res.effect_columns.shape[1]  # an effect may have a column per axis
    model_y, model_z = _effects_model(res)

    def gls(m_y: np.ndarray, m_z: np.ndarray, noise_psd: Any = psd) -> Any:
        return demodulate(
            time,
            m_y,
            m_z,
            theta,
            tau=opts.tau,
            mask=opts.mask,
            method="gls",
            signal_model=opts.signal_model,
            bias_aux=bias_aux or None,
            psd=noise_psd if noise_psd is not None else load_psd(opts.psd),
            valid=valid,
            rest_tol=opts.rest_tol,
        )

    # declared (as the periods rows have it) and with the effects subtracted (with
    # --psd auto: under the PSD of the run without the effects)
    before = gls(cols["m_y"], cols["m_z"])
    # nothing found: the declared GLS values (QA: the closure's LS values were written
    # as "after", 0.6σ from "before", with a change of σ 0)
    after = (
        gls(cols["m_y"] - model_y, cols["m_z"] - model_z, psd_after if psd_after else psd)
        if k
        else before
    )
    new: dict[str, np.ndarray] = {}
    for kind, r in (("before", before), ("after", after)):
        where = {int(p): i for i, p in enumerate(r.period_index)}
        pick = np.array([where.get(int(p), -1) for p in periods.period_index], dtype=np.int64)
        have = pick >= 0

        def take(x: np.ndarray, pick: np.ndarray = pick, have: np.ndarray = have) -> np.ndarray:
            out = np.full(pick.size, np.nan)
            out[have] = np.asarray(x)[pick[have]]
            return out

        for ax in ("Y", "Z"):
            new[f"a_{ax}_{kind}"] = take(getattr(r, f"a_{ax}"))
            sg = take(getattr(r, f"sigma_{ax}"))
            if kind == "after":
                extra = np.maximum(
                    getattr(periods, f"sigma_{ax}_after") ** 2
                    - getattr(periods, f"sigma_{ax}_before") ** 2,
                    0.0,
                )
                sg = np.sqrt(sg**2 + extra)
            new[f"sigma_{ax}_{kind}"] = sg
            if opts.signal_model == "affine":
                new[f"slope_{ax}_{kind}"] = take(getattr(r, f"slope_{ax}"))
                if kind == "after":
                    new[f"sigma_slope_{ax}_after"] = take(getattr(r, f"sigma_slope_{ax}"))
    for ax in ("Y", "Z"):
        new[f"change_{ax}"] = new[f"a_{ax}_after"] - new[f"a_{ax}_before"]
    return replace(periods, **new)


def _closure_plots(res: Any, out_dir: Path, stem: str) -> list[Path]:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return []
    from accal.closure.report import plot_closure
    from accal.io.writers import atomic_path

    names = [out_dir / f"{stem}.closure{k}.png" for k in ("", "-psd", "-effects")]
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(atomic_path(p)) for p in names]
        pngs = [t.with_name(t.name + ".png") for t in tmps]
        plot_closure(res, *pngs)
        for png, t in zip(pngs, tmps, strict=True):
            png.replace(t)
    return names


def apply_closure(
    rows: dict[str, Any], units: dict[str, str], periods: Any
) -> tuple[dict[str, Any], dict[str, str]]:
    """Periods rows with the extended model's ``a_Y``/``a_Z`` (declared ones as ``*_before``).

    Periods the closure could not determine keep NaN in the extended columns.
    """
    idx = {int(k): i for i, k in enumerate(periods.period_index)}
    where = np.array([idx.get(int(k), -1) for k in rows["period"]], dtype=np.int64)
    have = where >= 0

    def take(values: np.ndarray) -> np.ndarray:
        out = np.full(where.size, np.nan)
        out[have] = np.asarray(values, dtype=np.float64)[where[have]]
        return out

    rows = dict(rows)
    for ax in ("Y", "Z"):
        rows[f"a_{ax}_before"] = rows[f"a_{ax}"]
        rows[f"sigma_{ax}_before"] = rows[f"sigma_{ax}"]
        rows[f"a_{ax}"] = take(getattr(periods, f"a_{ax}_after"))
        rows[f"sigma_{ax}"] = take(getattr(periods, f"sigma_{ax}_after"))
        rows[f"change_{ax}"] = rows[f"a_{ax}"] - rows[f"a_{ax}_before"]
        sc = take(getattr(periods, f"sigma_change_{ax}"))
        # the closure analysed these periods on fewer samples than the declared fit (a
        # lagged coupling's unknown start is left out): its change σ is not that of
        # this difference (QA: period 0, change_Z -2.6e-11 ± 1.3e-12 on an axis with
        # nothing injected); σ_after ⊕ σ_before bounds it (the two correlate positively)
        other = np.abs(take(getattr(periods, f"a_{ax}_before")) - rows[f"a_{ax}_before"]) > (
            1e-3 * np.abs(rows[f"sigma_{ax}_before"])
        )
        rows[f"sigma_change_{ax}"] = np.where(
            other, np.hypot(rows[f"sigma_{ax}"], rows[f"sigma_{ax}_before"]), sc
        )
    n = where.size
    model = "+".join(["declared", *periods.effects])
    rows["model"] = np.array([model] * n, dtype=object)
    units = dict(units)
    for ax in ("Y", "Z"):
        units[f"a_{ax}"] = f"m/s^2 (mean a_{ax} over the period, extended model of --close-loop)"
        units[f"sigma_{ax}"] = "m/s^2 (1 sigma, extended model, coloured-noise sandwich)"
        units[f"a_{ax}_before"] = "m/s^2 (declared demodulation model, --method)"
        units[f"sigma_{ax}_before"] = "m/s^2 (1 sigma, declared model)"
        units[f"change_{ax}"] = "m/s^2 (extended - declared)"
        units[f"sigma_change_{ax}"] = (
            "m/s^2 (1 sigma of the change, closure's covariance; periods the closure "
            "analysed on fewer samples (a lagged coupling's unknown start): sigma_after "
            "(+) sigma_before, an upper bound)"
        )
    units["model"] = "declared model plus the effects --close-loop added"
    return rows, units


def write_demod_closure(
    out_dir: Path, source: str, entry: dict[str, Any] | None
) -> tuple[Path, Path]:
    """Merge one run's closure into ``OUT/closure.json`` / ``closure.md`` (layout: ``sources``).

    ``entry=None`` (the source redone without ``--close-loop``) removes the source's
    entry and plots; with no source left the two files are removed.
    """
    from accal.io.writers import _json_default, atomic_path

    jpath, mpath = out_dir / "closure.json", out_dir / "closure.md"
    try:
        old = json.loads(jpath.read_text())
        sources = old.get("sources", {}) if isinstance(old, dict) else {}
    except (OSError, ValueError):
        sources = {}
    if entry is None:
        if sources.pop(source, None) is None:
            return jpath, mpath
        stem = source.split(".")[0]
        for k in ("", "-psd", "-effects"):
            (out_dir / f"{stem}.closure{k}.png").unlink(missing_ok=True)
        if not sources:
            for f in (jpath, mpath):
                f.unlink(missing_ok=True)
            return jpath, mpath
    else:
        sources[source] = entry
    sources = dict(sorted(sources.items()))
    with atomic_path(jpath) as tmp:
        tmp.write_text(
            json.dumps(
                _nan_to_none({"accal_version": __version__, "sources": sources}),
                indent=2,
                default=_json_default,
            )
            + "\n"
        )
    lines = ["# accal demod: closing the loop", ""]
    for src, e in sources.items():
        lines.append(e.get("markdown", f"## {src}").rstrip())
        per = e.get("periods") or {}
        lines += [
            "",
            f"Model: `{e.get('model')}`"
            + (f", per-period values by `--method {e['method']}`" if e.get("method") else "")
            + ". Per-period change of a_Y/a_Z (extended - declared): "
            f"RMS {_g(per.get('rms_change_Y'))} / {_g(per.get('rms_change_Z'))} m/s², median "
            f"|change|/σ {_g(per.get('median_abs_change_Y_sigmas'))} / "
            f"{_g(per.get('median_abs_change_Z_sigmas'))} over {per.get('n', 0)} periods"
            + (
                f" ({per['n_changed_Y']} / {per['n_changed_Z']} changed beyond rounding)."
                if "n_changed_Y" in per
                else "."
            ),
            "",
        ]
    with atomic_path(mpath) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return jpath, mpath


def _g(x: Any) -> str:
    return "–" if x is None else f"{x:.3g}"


def _nan_to_none(obj: Any) -> Any:
    from accal.pipeline import _nan_to_none as f

    return f(obj)


def run_demod(
    paths: Iterable[Path],
    out_dir: Path,
    opts: DemodOptions,
    *,
    progress: Callable[[Iterable[Path]], Iterable[Path]] | None = None,
    psd: Any = None,
) -> DemodRunSummary:
    """Demodulate every run file; failures are recorded, not raised.

    Parameters
    ----------
    paths : iterable of Path
        Run files.
    out_dir : Path
        Output directory (created).
    opts : DemodOptions
        Options.
    progress : callable, optional
        Wraps the iterable of paths (e.g. ``tqdm``).
    psd : PSD, optional
        The noise model already loaded from ``opts.psd`` (:func:`load_psd`).

    Returns
    -------
    DemodRunSummary

    Raises
    ------
    AccalError
        Before any input is processed: unreadable ``--psd`` table, colliding output
        names, a periods table of the other ``--format`` in ``out_dir``.
    """
    from accal.batch import OutputLock, RunLog, remove_stale_temporaries

    start = _time.perf_counter()
    paths = [Path(p) for p in paths]
    targets = output_paths(paths, out_dir, opts.fmt)
    check_output_format(out_dir, opts.fmt)
    if psd is None:
        psd = load_psd(opts.psd)
    outcomes: list[RunOutcome] = []
    pairs = list(zip(paths, targets, strict=True))
    if not out_dir.exists() and not any(os.path.lexists(p) for p in paths):
        # nothing to read: fail each without creating the output directory, its lock
        # and log (issue 23: a failed `accal demod run1.parquet` left them behind)
        missing = [RunOutcome(p, False, failure_message(p, ValidationError("no such file")))
                   for p in paths]  # fmt: skip
        return DemodRunSummary(missing, _time.perf_counter() - start)
    out_dir.mkdir(parents=True, exist_ok=True)
    # one writer per output directory (the cumulative periods table); a killed
    # run's temporary files are removed under the lock
    with OutputLock(out_dir, "accal demod"):
        remove_stale_temporaries(out_dir)
        log = RunLog(out_dir)
        try:
            log(f"start accal demod: {len(paths)} runs, options={opts}")
            for path, tgt in progress(pairs, total=len(pairs)) if progress else pairs:
                try:
                    check_input(path)
                    outcomes.append(process_run(path, tgt, opts, psd))
                except AccalError as exc:
                    outcomes.append(RunOutcome(path, False, failure_message(path, exc)))
                except Exception as exc:  # a bug, not bad input: keep the batch going
                    outcomes.append(RunOutcome(path, False, internal_error_message(path, exc)))
                o = outcomes[-1]
                log(f"ok {path}" if o.ok else f"FAILED {o.message}")
            summary = DemodRunSummary(outcomes, _time.perf_counter() - start)
            log(
                f"accal demod: {summary.n_ok} ok, {summary.n_failed} failed in {summary.seconds:.2f} s"
            )
            return summary
        finally:
            log.close()


# ---------------------------------------------------------------------------
# design, budget, simulate


def write_design(
    out: Path, tau: float, mask: float, fs: float, *, kind: str = "fig2", periods: int = 1
) -> tuple[Path, Any]:
    """Design a calibration pattern and write θ(t) for ``periods`` periods.

    Columns ``time`` [s], ``theta`` [rad], ``rest`` (discrete θ̇ = θ̈ = 0 mask, as
    ``accal demod`` will find it) and ``rest_nominal``.  Format by suffix
    (``.csv`` → CSV, else Parquet).

    Returns
    -------
    (Path, CalibrationPattern)
    """
    import pandas as pd

    from accal.estimators.design import design_pattern, tile
    from accal.io.writers import write_table

    if periods < 1:
        raise ValidationError(f"periods must be >= 1, got {periods}")
    pat = design_pattern(tau, mask, fs, kind=kind)
    t, theta = tile(pat, periods)
    df = pd.DataFrame(
        {
            "time": t,
            "theta": theta,
            "rest": np.tile(pat.mask, periods),
            "rest_nominal": np.tile(pat.mask_nominal, periods),
        }
    )
    units = {
        "time": "s (from the start of the first period)",
        "theta": "rad",
        "rest": "True where the discrete dtheta = d2theta = 0 (samples demod uses)",
        "rest_nominal": "True outside the nominal rotation windows",
    }
    meta = {
        "kind": pat.kind,
        "tau": pat.tau,
        "mask": pat.tm,
        "fs": pat.fs,
        "periods": periods,
        "segments": [list(s) for s in pat.segments],
        "residuals": pat.residuals,
        "residuals_nominal": pat.residuals_nominal,
        "accal_version": __version__,
    }
    return write_table(df, out, units=units, meta=meta), pat


def parse_taus(spec: str | None, tm: float, fs: float) -> np.ndarray:
    """``START:STOP:STEP`` [s] → array; default ``TM+40 .. 3600`` in 40 s steps (Fig. 6)."""
    if not spec:
        step = 40.0
        return np.arange(tm + step, 3600.0 + 0.5 / fs, step)
    try:
        a, b, c = (float(x) for x in spec.split(":"))
    except ValueError:
        raise ValidationError(f"--taus must be START:STOP:STEP in seconds, got {spec!r}") from None
    if not (0 < a <= b and c > 0):
        raise ValidationError(f"--taus needs 0 < START <= STOP and STEP > 0, got {spec!r}")
    return np.arange(a, b + 1e-9 * b, c)


def budget_report(
    mask: float,
    *,
    tau: float | None = None,
    fs: float = 1.0,
    method: str = "ls",
    integration: float = 3600.0,
    psd: str = "microstar",
    taus: str | None = None,
) -> dict[str, Any]:
    """Uncertainty budget as a JSON-ready dict (``accal budget``).

    With ``tau``: Rd[k] and σ over ``integration`` for that τ.  Without: the Fig. 6
    scan (``tau``, ``sigma``, ``tau_opt``) and the budget at ``tau_opt``.
    ``sigma_curve`` holds σ of the mean versus the number of periods (Fig. 5).
    """
    from accal.estimators.demod import budget, sigma_mean, tau_scan

    check_option("method", method, ("ls", "gls"))
    p = load_psd(psd)
    out: dict[str, Any] = {"mask": mask, "fs": fs, "method": method, "integration": integration}
    if tau is None:
        ts, ss, t_opt = tau_scan(
            mask, parse_taus(taus, mask, fs), fs, psd=p, method=method, T=integration
        )
        out.update({"tau": ts.tolist(), "sigma": ss.tolist(), "tau_opt": t_opt})
        tau_b = t_opt
    else:
        tau_b = tau
    b = budget(tau_b, mask, fs, psd=p, method=method, T=integration)
    n = max(1, int(round(integration / b.pattern.tau)))
    out.update(
        {
            "tau_budget": b.pattern.tau,
            "kind": b.pattern.kind,
            "Rd": b.Rd.tolist(),
            "sigma_T": b.sigma_T,
            "sigma_T_indep": b.sigma_T_indep,
            "n_periods": n,
            "sigma_curve": {
                "T": [k * b.pattern.tau for k in range(1, n + 1)],
                "sigma": [sigma_mean(b.Rd, k) for k in range(1, n + 1)],
            },
            "units": {
                "Rd": "m^2/s^4",
                "sigma_T": "m/s^2",
                "sigma": "m/s^2",
                "tau": "s",
                "integration": "s",
            },
        }
    )
    return out


def plot_budget(report: dict[str, Any], path: Path) -> Path:
    """PNG of the budget: σ vs τ (Fig. 6) when scanned, else σ of the mean vs T (Fig. 5)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from accal.io.writers import atomic_path

    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    if "tau_opt" in report:
        ax.plot(report["tau"], np.asarray(report["sigma"]) * 1e12, ".-")
        ax.axvline(report["tau_opt"], color="k", ls=":", label=f"τ_opt = {report['tau_opt']:g} s")
        ax.set_xlabel("modulation period τ [s]")
        ax.set_ylabel(f"σ over {report['integration']:g} s [pm s⁻²]")
        ax.set_title(f"TM = {report['mask']:g} s, {report['method'].upper()}")
        ax.legend()
    else:
        c = report["sigma_curve"]
        ax.loglog(c["T"], np.asarray(c["sigma"]) * 1e12, ".-")
        from matplotlib.ticker import FormatStrFormatter

        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.set_xlabel("integration time T [s]")
        ax.set_ylabel("σ of the mean [pm s⁻²]")
        ax.set_title(
            f"τ = {report['tau_budget']:g} s, TM = {report['mask']:g} s, "
            f"{report['method'].upper()}: Rd[0] = {report['Rd'][0]:.3g} m²s⁻⁴"
        )
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def write_simulated_gap(out: Path, **params: Any) -> tuple[Path, Path]:
    """Simulate a run (:func:`accal.simulate.gap.simulate_gap`) and write it with its truth.

    The run goes to ``out`` (``.csv`` → CSV, else Parquet) and the per-period true
    means to ``<stem>.truth.<ext>`` next to it; both or neither are written.  Runs
    longer than ``SIMULATE_CHUNK_DAYS`` are simulated and written in blocks of that
    length (:func:`accal.simulate.gap.simulate_gap_chunks`), so a simulated year
    needs a few hundred MB; shorter ones are one block, identical to
    :func:`~accal.simulate.gap.simulate_gap`'s record.
    """
    from accal.estimators.design import design_pattern
    from accal.io.chunked import chunked_table_writer
    from accal.simulate.gap import simulate_gap_chunks

    out = Path(out)
    if out.name.lower().endswith(".gz"):
        raise ValidationError(f"{out}: compressed output is not supported; use .parquet or .csv")
    # option errors name the options (design_pattern's own messages say tm, tau)
    tau, mask, fs = (float(params.get(k, d)) for k, d in (("tau", 600), ("mask", 200), ("fs", 1)))
    if not 0 < fs < np.inf or not 0 < tau < np.inf:
        raise ValidationError(
            f"--tau and --fs must be positive and finite, got --tau {tau:g} s, --fs {fs:g} Hz"
        )
    if not 0 < mask < tau:
        raise ValidationError(
            f"--mask (masking time TM) must be in (0, --tau) s for a calibration pattern, got "
            f"--mask {mask:g} s for --tau {tau:g} s"
        )
    try:
        design_pattern(tau, mask, fs, kind=params.get("kind", "fig2"))
    except ValidationError as exc:
        raise ValidationError(
            f"no calibration pattern for --tau {tau:g} s, --mask {mask:g} s, --fs {fs:g} Hz: {exc}"
        ) from None
    fmt = "csv" if out.suffix.lower() == ".csv" else "parquet"
    truth_path = out.with_name(f"{out.stem}.truth{out.suffix or '.parquet'}")
    run_units = {
        "time": "s (from the start of the run)",
        "m_y": "m/s^2",
        "m_z": "m/s^2",
        "m_x": "m/s^2",
        "theta": "rad",
        "temperature": "K",
    }
    truth_units = {
        "period": "index of the modulation period",
        "t_start": "s",
        "t_mid": "s",
        "a_Y": "m/s^2 (true period mean)",
        "a_Z": "m/s^2 (true period mean)",
        "bias_y": "m/s^2 (true period-mean bias of m_y)",
        "bias_z": "m/s^2 (true period-mean bias of m_z)",
    }
    meta = {"simulate_gap": params, "accal_version": __version__}
    blocks = simulate_gap_chunks(**params, chunk_days=SIMULATE_CHUNK_DAYS)
    with contextlib.ExitStack() as stack:
        w_run = stack.enter_context(chunked_table_writer(out, fmt=fmt, units=run_units, meta=meta))
        w_truth = stack.enter_context(
            chunked_table_writer(truth_path, fmt=fmt, units=truth_units, meta=meta)
        )
        for data, truth in blocks:
            w_run.write(data)
            w_truth.write(truth)
    return out, truth_path


#: Options of a source that a summary and the periods table metadata must share.
_SOURCE_OPTIONS = ("tau", "mask", "method", "signal_model", "bias_model", "psd")


def current_summaries(
    directory: Path, warnings: list[str] | None = None
) -> list[tuple[Path, dict[str, Any]]]:
    """The summaries of a demod output directory that describe its current periods table.

    The table's metadata (``accal.meta["sources"]``) lists every source whose rows
    it holds, with the name of the summary its last run wrote.  A summary is
    current when it is that one; summaries left by earlier runs (a source re-run
    under another summary name, with other options, or a source whose rows are no
    longer in the table) are ignored.  Tables of older accal versions do not name
    the summary: a summary is then current when its options are the table's for
    its source (the newest one if several are).

    Parameters
    ----------
    directory : Path
        The ``accal demod --out`` directory.
    warnings : list of str, optional
        Appended to: sources of the table left without a current summary.

    Returns
    -------
    list of (Path, dict)
        The summary files and their content, sorted by file name.
    """
    from accal.io.writers import read_table_metadata

    directory = Path(directory)
    tables = sorted(directory.glob("periods.*"), key=lambda q: q.stat().st_mtime)
    sources: dict[str, Any] | None = None
    if tables:
        with contextlib.suppress(Exception):  # unreadable metadata: every summary counts
            meta = read_table_metadata(tables[-1])[1]
            if isinstance(meta.get("sources"), dict):
                sources = meta["sources"]
    found: dict[str, tuple[Path, dict[str, Any]]] = {}
    for sp in sorted(directory.glob("*summary.json")):
        got = load_summary(sp)
        if got is None:
            continue  # not a demod summary
        name, s = got
        o = s["options"]
        if sources is not None:
            meta = sources.get(name)
            if not isinstance(meta, dict):
                continue  # its rows are no longer in the table
            if "summary" in meta:
                if meta["summary"] != sp.name:
                    continue  # an earlier run's summary
            elif any(meta.get(k, o.get(k)) != o.get(k) for k in _SOURCE_OPTIONS):
                continue  # older table: not the options of the rows
        old = found.get(name)
        if old is None or sp.stat().st_mtime > old[0].stat().st_mtime:
            found[name] = (sp, s)
    if warnings is not None and sources is not None:
        for name in sorted(set(sources) - set(found)):
            want = sources[name].get("summary") if isinstance(sources[name], dict) else None
            warnings.append(
                f"{name}: rows in {tables[-1].name} but no current summary"
                + (f" ({want} now belongs to another run)" if want else "")
                + f"; re-run accal demod on it into {directory} to diagnose it"
            )
    return sorted(found.values(), key=lambda x: x[0].name)


def diagnose_demod_dir(
    directory: Path,
    out_dir: Path,
    *,
    alpha: float = 0.01,
    warnings: list[str] | None = None,
    plots: bool = False,
) -> list[tuple[Path, dict[str, Any] | None, str]]:
    """Close the loop on the runs of an earlier ``accal demod`` output directory.

    Each current ``summary.json``/``<stem>.summary.json`` (:func:`current_summaries`:
    the ones that describe the periods table as it is) names its run file and
    options; the run is re-read (it must still exist; found by :func:`find_run`,
    from any working directory), resampled as it was, and analysed with the same
    declared model.  The periods table is not changed (re-run ``demod
    --close-loop`` for that); ``closure.json``/``closure.md`` and plots go to
    ``out_dir``.

    Parameters
    ----------
    directory : Path
        The ``accal demod --out`` directory.
    out_dir : Path
        Where the reports go.
    alpha : float
        False-detection probability per selection step.
    warnings : list of str, optional
        Appended to: sources of the periods table without a current summary.

    Returns
    -------
    list of (Path, dict or None, str)
        Per run: its path, its ``closure.json`` entry (None on failure) and a
        one-line error message (empty on success).
    """
    directory, out_dir = Path(directory), Path(out_dir)
    results: list[tuple[Path, dict[str, Any] | None, str]] = []
    for sp, s in current_summaries(directory, warnings):
        src = Path(s["source"])
        o = s["options"]
        rs = (s.get("input") or {}).get("resample") if isinstance(s.get("input"), dict) else None
        rs = rs if isinstance(rs, dict) and rs else None  # the resampling report, if resampled
        try:
            src = find_run(s, sp)
            opts = DemodOptions(
                tau=float(o["tau"]),
                mask=float(o["mask"]),
                signal_model=o.get("signal_model", "mean"),
                bias_model=o.get("bias_model", "affine"),
                resample=rs is not None,
                gap_factor=float(rs.get("gap_factor", 2.0)) if rs else 2.0,
                psd=str(o.get("psd") or "microstar"),
                close_loop=True,
                alpha=alpha,
                rest_tol=float(o.get("rest_tol", 1e-9)),
                plots=plots,
            )
            step = float(rs["step"]) if rs and "step" in rs else None
            out_dir.mkdir(parents=True, exist_ok=True)  # not before a run is found
            entry, _, _ = close_run(src, opts, out_dir, step=step)
            write_demod_closure(out_dir, src.name, entry)
            results.append((src, entry, ""))
        except AccalError as exc:
            msg = str(exc).replace("\n", " ")
            if getattr(exc, "path", None) is None and not msg.startswith(str(src)):
                msg = f"{src}: {msg}"
            results.append((src, None, msg))
    return results
