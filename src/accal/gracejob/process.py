"""One input of ``accal grace-bias``, end to end: read, fit, write its outputs.

:func:`process_file` writes an input's calibrated series and report (raising on
bad input); :func:`process_one` is the task the workers run, every failure
turned into a one-line :class:`~accal.gracejob.outcome.FileOutcome`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.batch import LOCK, check_input, failure_message, file_signature, write_error_message
from accal.batch_summary import reset_peak_rss
from accal.errors import AccalError, ValidationError
from accal.gracejob.fit import fit_input
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import FileOutcome, internal_error, peak_rss_mb
from accal.gracejob.outputs import (
    CALIBRATED_UNITS,
    calibrated_file_columns,
    file_size,
    output_stem,
    write_json,
)
from accal.gracejob.reading import read_input, read_with_reference, with_warnings
from accal.io.writers import run_guard, write_table
from accal.series import AccSeries


def process_file(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    """Run the whole chain on one input and write its calibrated series and report.

    Raises
    ------
    AccalError
        On bad input; nothing is written for this input then.
    """
    series, fit_series, ref_series = read_with_reference(path, opts, read_reference_named(opts))
    stem = output_stem(path)
    if opts.reference_fit:
        # imported here: the reference fit's modules import scipy (~0.3 s of start-up)
        from accal.pipeline_arcs import reference_outputs
        from accal.pipeline_reference import fit_day

        day = fit_day(path, series, ref_series, opts)
        closure = None
        if opts.close_loop:
            # imported here: the closure modules cost ~0.4 s of start-up (scipy.signal)
            from accal.gracejob.reference_closure import close_reference_loop

            day, closure, notes = close_reference_loop(
                path, series, ref_series, day, opts, out_dir / stem
            )
            series = with_warnings(series, *notes)
        return reference_outputs(path, out_dir, opts, series, ref_series, day, closure=closure)
    fitted = fit_input(path, series, fit_series, ref_series, opts, out_dir / stem)
    series, cal, use, rows = fitted.series, fitted.calibrated, fitted.use, fitted.rows
    closure, extra_outputs = fitted.closure, list(fitted.outputs)
    meta = {
        "source": path.name,
        "satellite": series.satellite,
        "frame": series.frame,
        "method": opts.methods[0],
        "order": opts.order,
        "history": list(cal.history),
        "input_meta": series.meta,
    }
    cal_path = write_table(
        calibrated_file_columns(cal, use, opts.fmt),
        out_dir / f"{stem}.calibrated.{opts.fmt}",
        fmt=opts.fmt,
        units=CALIBRATED_UNITS,
        meta=meta,
        sync=False,  # made durable with the batch commit (sync_files)
        required=True,
    )
    report = {
        "source": str(path),
        "accal_version": __version__,
        "satellite": series.satellite,
        "read_report": series.report.as_dict(),
        "fits": rows,
        "history": list(cal.history),
    }
    if closure:
        report["closure"] = {ax: c["summary"] for ax, c in closure.items()}
    rep_path = out_dir / f"{stem}.report.json"
    write_json(rep_path, report, sync=False)
    if opts.pool_days:
        extra_outputs.append(
            _save_spectra(out_dir / stem, fitted.fit_series, opts, fitted.exclude, fitted.fits)
        )
    return FileOutcome(
        path,
        True,
        rows=rows,
        n_samples=len(series),
        outputs=(cal_path, rep_path, *extra_outputs),
        n_bytes=file_size(path),
        closure={ax: c["summary"] for ax, c in closure.items()},
        warnings=tuple(report["read_report"]["warnings"]),
    )


def read_reference_named(opts: GraceBiasOptions) -> AccSeries | None:
    """``--reference`` as read (None without one); its reader's errors without a path.

    A reader's error carries the reference's path, and
    :func:`accal.batch.failure_message` then prints it alone; re-raised as a
    :class:`ValidationError` whose text starts with that path, the line names the
    input too, as the reference's other errors do (``accal: DAY: REF: ...``).
    """
    if opts.reference is None:
        return None
    try:
        return read_input(Path(opts.reference), GraceBiasOptions(columns=opts.columns))
    except AccalError as exc:
        if getattr(exc, "path", None) is None:
            raise
        raise ValidationError(str(exc).replace("\n", " ")) from exc


def _save_spectra(
    stem_path: Path,
    fit_series: AccSeries,
    opts: GraceBiasOptions,
    exclude: dict[str, np.ndarray],
    fits: dict[tuple[str, str], Any],
) -> Path:
    """Write ``<stem>.noise.npz``: the residual spectra of ``fits`` (``--pool-days``)."""
    # imported here: accal.pooling imports scipy (~0.3 s of start-up), for --pool-days only
    from accal.pooling import day_spectra, spectra_path, write_spectra

    base = np.ones(len(fit_series), bool) if opts.keep_flagged else fit_series.valid
    base = base & np.isfinite(fit_series.time)
    masks = {}
    for k, ax in enumerate(fit_series.axes):
        m = base & np.isfinite(fit_series.acc[:, k])
        masks[ax] = m & ~exclude[ax] if ax in exclude else m
    spectra = day_spectra(fit_series.time, fit_series.acc, fit_series.axes, masks, fits)
    return write_spectra(spectra_path(stem_path.parent, stem_path.name), spectra, fits)


def process_one(
    path: Path, out_dir: Path, opts: GraceBiasOptions, run_token: str | None = None
) -> FileOutcome:
    """:func:`process_file` with every failure turned into a one-line :class:`FileOutcome`.

    Module-level and picklable: this is the task the worker processes and the
    dask workers run.  ``run_token``: the lock token of the submitting run; the
    task's outputs are renamed into ``out_dir`` only while that run holds the lock
    (:func:`accal.io.writers.run_guard`), so a task orphaned by a killed run cannot
    overwrite a later run's outputs.
    """
    with run_guard(Path(out_dir) / LOCK if run_token else None, run_token):
        return _process_one(Path(path), out_dir, opts)


def _process_one(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    # the peak memory of a failed input counts too: a hostile file that fails late is
    # exactly the one whose memory the summary must show (issue 23, finding 9); the
    # peak is this input's, not the worker's lifetime one (a Dask worker's)
    reset_peak_rss()
    outcome = _try_one(path, out_dir, opts)
    return dataclasses.replace(outcome, peak_rss=peak_rss_mb())


def _try_one(path: Path, out_dir: Path, opts: GraceBiasOptions) -> FileOutcome:
    try:
        check_input(path)
        if path.is_dir():
            raise ValidationError("is a directory (use --recursive to process the files in it)")
        try:  # before the read: an input replaced while it is processed is redone next run
            before = file_signature(path)
        except OSError:
            before = None
        outcome = process_file(path, Path(out_dir), opts)
        return dataclasses.replace(outcome, signature=before)
    except AccalError as exc:
        return FileOutcome(path, False, failure_message(path, exc))
    except MemoryError:
        return FileOutcome(path, False, f"{path}: out of memory")
    except OSError as exc:  # writing the outputs (disk full, permissions, ...)
        return FileOutcome(path, False, write_error_message(path, exc))
    except Exception as exc:  # a bug, not bad input: still keep the batch going
        return internal_error(path, exc)
