"""Reading a run for ``accal demod``: the PSD, the sampling step, checked chunks.

A run is read in chunks of ``chunk_rows`` rows (two passes: checks, then
estimates; see :func:`accal.estimators.demod.demodulate_stream`), so memory is
bounded by the chunk, not by the run: a year of 1 Hz data fits in a few hundred
MB.  The results equal those of a whole-file run to rounding.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from accal.demodjob.options import DemodOptions, RunInfo
from accal.errors import ValidationError
from accal.estimators.demod import DemodChunk, demodulate_stream, step_tolerance
from accal.estimators.demod import sampling_step as regular_step
from accal.estimators.noise import as_psd
from accal.estimators.resample import UniformResampler, nominal_step
from accal.io.rawlog import open_rawlog, read_psd


def load_psd(spec: str | None):
    """The a-priori PSD: ``"microstar"``/``"auto"``/None → eq. 1; else a table file (``f``, ``S``).

    With ``"auto"`` eq. 1 is the fall-back of a run too short for the PSD from the
    data, and the reference the data's noise is compared with.

    Raises
    ------
    AccalError
        Unreadable table or invalid values (the message names the file).
    """
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
