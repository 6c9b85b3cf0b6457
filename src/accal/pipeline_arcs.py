"""``grace-bias`` with the reference fit: the outputs of one input, and arcs of inputs.

Sequencing only (issue 22): :func:`reference_outputs` writes what one input's
reference fit produced (table rows, calibrated series, parameter table, covariance,
report); :func:`arc_outcomes` runs an ``--arc`` batch on the batch's workers
(:func:`accal.batch.execute`): the inputs are read (:func:`scan_input`, a task per
input), grouped into arcs here (:func:`accal.pipeline_reference.group_arcs`), and
each arc is fitted once (:func:`accal.pipeline_reference.fit_arc`) and written by
one task (:func:`fit_arc_task`); it yields one outcome per input for the batch
runner to commit.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import (
    LOCK,
    check_input,
    execute,
    failure_message,
    file_signature,
    write_error_message,
)
from accal.batch_summary import peak_rss_mb, reset_peak_rss
from accal.degraded import classify_day, load_periods
from accal.errors import AccalError, ValidationError
from accal.gracejob.fit import row_source, signal_share
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import FileOutcome, internal_error
from accal.gracejob.outputs import (
    CALIBRATED_UNITS,
    calibrated_file_columns,
    file_size,
    output_stem,
    write_json,
)
from accal.gracejob.reading import read_input, read_with_reference, with_warnings
from accal.io.writers import run_guard, write_table
from accal.pipeline_reference import (
    PARAMETER_UNITS,
    fit_arc,
    group_arcs,
    parameter_table,
    report_entry,
    row_fields,
    write_covariance,
)
from accal.products.utc import utc_units, with_utc_columns
from accal.series import AccSeries
from accal.timescale import gps_to_date

__all__ = [
    "PARAMETER_FILE_UNITS",
    "Arc",
    "ArcInput",
    "arc_outcomes",
    "fit_arc_task",
    "parameter_file_columns",
    "redo_all",
    "read_reference",
    "reference_outputs",
    "scan_input",
]


#: Units of the columns of ``<stem>.bias_basis.<fmt>``: :data:`PARAMETER_UNITS` with
#: ``node_time_utc`` after ``node_time``.
PARAMETER_FILE_UNITS = utc_units(PARAMETER_UNITS, ("node_time",))


def parameter_file_columns(fit: Any, fmt: str) -> dict[str, Any]:
    """The columns of ``<stem>.bias_basis.<fmt>``: :func:`parameter_table` with
    ``node_time_utc`` (the node epochs in UTC, :mod:`accal.products.utc`)."""
    return with_utc_columns(parameter_table(fit), ("node_time",), fmt)


def reference_outputs(
    path: Path,
    out_dir: Path,
    opts: GraceBiasOptions,
    series: AccSeries,
    minus_ref: AccSeries,
    day: Any,
    arc: dict[str, Any] | None = None,
    closure: Any = None,
) -> FileOutcome:
    """Write the outputs of one input's reference fit (``--bias-basis``, ``--scale fit``).

    ``day`` is its :class:`accal.pipeline_reference.ReferenceDay`; ``arc`` describes the
    arc it was fitted in (sources, parameter table), None for a day fitted alone;
    ``closure`` the :class:`accal.gracejob.reference_closure.ReferenceClosure` of
    ``--close-loop`` (``day`` is then the refit): the rows' ``model``, the report's
    ``closure`` entry and the outcome's closure (for ``closure.json``/``closure.md``).
    """
    stem = output_stem(path)
    series = with_warnings(series, *day.warnings)
    t = series.time
    date = gps_to_date(0.5 * (float(t[0]) + float(t[-1])))
    periods = load_periods(opts.degraded_days) if opts.degraded_days else None
    status = classify_day(series.satellite, date, series.meta, periods=periods)
    rows = []
    for ax in series.axes:
        row = {**row_source(path, series, opts, date, ax), **row_fields(day, ax, t, opts.scale)}
        row.update(signal_share(series, minus_ref, ax, day.use))
        row["day_status"], row["day_status_reason"] = status
        if closure is not None:
            row["model"] = closure.models[ax]
        rows.append(row)
    meta = {
        "source": path.name,
        "satellite": series.satellite,
        "frame": series.frame,
        "method": "reference",
        "bias_basis": day.fit.basis.name(),
        "history": list(day.calibrated.history),
        "input_meta": series.meta,
    }
    cal_path = write_table(
        calibrated_file_columns(day.calibrated, day.use, opts.fmt),
        out_dir / f"{stem}.calibrated.{opts.fmt}",
        fmt=opts.fmt,
        units=CALIBRATED_UNITS,
        meta=meta,
        sync=False,
        required=True,
    )
    if arc is None:
        par_path = write_table(
            parameter_file_columns(day.fit, opts.fmt),
            out_dir / f"{stem}.bias_basis.{opts.fmt}",
            fmt=opts.fmt,
            units=PARAMETER_FILE_UNITS,
            meta={"source": path.name, **report_entry(day)},
            sync=False,
            required=True,
        )
        cov_path = write_covariance(out_dir / f"{stem}.reference_cov.npz", day.fit)
    else:
        par_path = cov_path = None
    report = {
        "source": str(path),
        "accal_version": __version__,
        "satellite": series.satellite,
        "read_report": series.report.as_dict(),
        "fits": rows,
        "reference_fit": report_entry(day),
        "history": list(day.calibrated.history),
    }
    if arc is not None:
        report["reference_fit"]["arc"] = arc
    if closure is not None:
        report["closure"] = closure.summaries
    rep_path = out_dir / f"{stem}.report.json"
    write_json(rep_path, report, sync=False)
    return FileOutcome(
        path,
        True,
        rows=rows,
        n_samples=len(series),
        # an arc's parameter table is shared by its days: not one input's output
        outputs=(
            (cal_path, rep_path) if arc is not None else (cal_path, par_path, cov_path, rep_path)
        )
        + (closure.outputs if closure is not None else ()),
        n_bytes=file_size(path),
        closure=closure.summaries if closure is not None else {},
        warnings=tuple(report["read_report"]["warnings"]),
    )


def redo_all(todo: list[int], results: dict[int, FileOutcome], paths: list[Path]) -> list[int]:
    """``todo`` plus the inputs skipped as current (an arc is refitted whole)."""
    for i, out in list(results.items()):
        if i >= 0 and out.skipped:
            del results[i]
    return sorted(set(todo) | {i for i in range(len(paths)) if i not in results})


@dataclass(frozen=True)
class ArcInput:
    """What reading one input found for the arcs (:func:`scan_input`).

    Attributes
    ----------
    path : Path
        The input.
    key : tuple of (str, float, float) or None
        ``(satellite, first time, last time)`` [GPS s] of its data, as
        :func:`accal.pipeline_reference.group_arcs` takes it; None when it failed.
    signature : dict or None
        Its size and mtime before it was read (:meth:`accal.batch.Manifest.record`).
    failure : FileOutcome or None
        Its outcome when it could not be read (it fails alone).
    """

    path: Path
    key: tuple[str, float, float] | None = None
    signature: dict[str, Any] | None = None
    failure: FileOutcome | None = None


@dataclass(frozen=True)
class Arc:
    """One arc to fit (:func:`fit_arc_task`): its inputs in time order.

    Attributes
    ----------
    inputs : tuple of ArcInput
        The inputs (read once already, by :func:`scan_input`).
    notes : tuple of str
        Every note of :func:`accal.pipeline_reference.group_arcs` (a missing day
        that started a new arc); the arc's own ones go to its inputs' reports.
    """

    inputs: tuple[ArcInput, ...]
    notes: tuple[str, ...] = ()


@functools.lru_cache(maxsize=1)
def _read_reference(path: str, signature: tuple[int, int], columns: tuple) -> AccSeries:
    """The reference, read once per process while its file is unchanged."""
    return read_input(Path(path), GraceBiasOptions(columns=dict(columns)))


def read_reference(opts: GraceBiasOptions) -> AccSeries:
    """``--reference``, read once per process and batch (its tasks share it).

    The scan and the arcs of a batch run in the same worker processes (or in this
    one, ``-j 1``): each reads the reference once, not once per input.  The file's
    size and mtime are part of the key: a changed file is read again.

    Raises
    ------
    AccalError
        If it cannot be read.
    """
    ref = Path(opts.reference)
    try:
        sig = file_signature(ref)
        key = (int(sig["size"]), int(sig["mtime_ns"]))
    except (OSError, KeyError, TypeError):
        key = (-1, -1)  # the reader says what is wrong with it
    return _read_reference(str(ref), key, tuple(sorted(opts.columns.items())))


def scan_input(path: Path, opts: GraceBiasOptions) -> ArcInput:
    """Read one input against the reference: its arc key, or its failure.

    Module-level and picklable: the first task of an ``--arc`` batch, one per
    input, on the batch's workers.  Nothing is written.
    """
    path = Path(path)
    try:
        reference = read_reference(opts)
    except AccalError as exc:  # every input fails with the reference's message, after its name
        named = ValidationError(str(exc)) if getattr(exc, "path", None) else exc
        return ArcInput(path, failure=FileOutcome(path, False, failure_message(path, named)))
    try:
        check_input(path)
        before = file_signature(path)
        series, _, _ = read_with_reference(path, opts, reference)
    except AccalError as exc:
        return ArcInput(path, failure=FileOutcome(path, False, failure_message(path, exc)))
    except OSError as exc:
        return ArcInput(path, failure=FileOutcome(path, False, write_error_message(path, exc)))
    key = (series.satellite, float(series.time[0]), float(series.time[-1]))
    return ArcInput(path, key, before)


def fit_arc_task(
    arc: Arc, out_dir: Path, opts: GraceBiasOptions, run_token: str | None = None
) -> list[FileOutcome]:
    """Read, fit and write one arc: one outcome per input, in the arc's order.

    Module-level and picklable: the second task of an ``--arc`` batch, one per
    arc, on the batch's workers (an arc is fitted whole, so it is the unit of
    work).  ``run_token``: the lock token of the submitting run
    (:func:`accal.io.writers.run_guard`, as :func:`accal.gracejob.process.process_one`).
    """
    reset_peak_rss()  # the arc's peak, not the worker's lifetime one (a Dask worker's)
    with run_guard(Path(out_dir) / LOCK if run_token else None, run_token):
        return _fit_arc_inputs(arc, Path(out_dir), opts)


def _fit_arc_inputs(arc: Arc, out_dir: Path, opts: GraceBiasOptions) -> list[FileOutcome]:
    """:func:`fit_arc_task` without the guard: outcomes of the arc's inputs, in order.

    An input that cannot be read again (replaced since the scan) fails alone; the
    arc is fitted without it.  A failed fit fails every input of the arc with one
    message.  The arc's coefficients go to
    ``arc_<satellite>_<first date>_<last date>.bias_basis.<fmt>``.
    """
    paths = [a.path for a in arc.inputs]
    outcomes: dict[int, FileOutcome] = {}
    try:
        reference = read_reference(opts)
    except AccalError as exc:  # as in scan_input: the input's name first
        named = ValidationError(str(exc)) if getattr(exc, "path", None) else exc
        return [FileOutcome(p, False, failure_message(p, named)) for p in paths]
    loaded: dict[int, tuple[AccSeries, AccSeries]] = {}
    for k, p in enumerate(paths):
        try:
            series, _, minus_ref = read_with_reference(p, opts, reference)
            loaded[k] = (series, minus_ref)
        except AccalError as exc:
            outcomes[k] = FileOutcome(p, False, failure_message(p, exc))
        except OSError as exc:
            outcomes[k] = FileOutcome(p, False, write_error_message(p, exc))
    ks = sorted(loaded)
    if not ks:
        return [outcomes[k] for k in range(len(paths))]
    names = [paths[k].name for k in ks]
    try:
        days = fit_arc([paths[k] for k in ks], [loaded[k][0] for k in ks],
                       [loaded[k][1] for k in ks], opts)  # fmt: skip
        first, last = (
            gps_to_date(float(loaded[k][0].time[i])) for k, i in ((ks[0], 0), (ks[-1], -1))
        )
        who = loaded[ks[0]][0].satellite or output_stem(paths[ks[0]])
        par_name = f"arc_{who}_{first}_{last}.bias_basis.{opts.fmt}"
        info = {"sources": names, "parameters": par_name, "first": first, "last": last}
        closures: list[Any] = [None] * len(ks)
        notes: list[list[str]] = [[] for _ in ks]
        if opts.close_loop:
            # imported here: the closure modules cost ~0.4 s of start-up (scipy.signal)
            from accal.gracejob.reference_closure import close_arc_loop

            days, closures, notes = close_arc_loop(
                [paths[k] for k in ks], [loaded[k][0] for k in ks], [loaded[k][1] for k in ks],
                days, opts, [out_dir / output_stem(paths[k]) for k in ks],
            )  # fmt: skip
        write_table(
            parameter_file_columns(days[0].fit, opts.fmt),
            out_dir / par_name,
            fmt=opts.fmt,
            units=PARAMETER_FILE_UNITS,
            meta={"sources": names, **report_entry(days[0])},
        )
        write_covariance(out_dir / f"arc_{who}_{first}_{last}.reference_cov.npz", days[0].fit)
        for j, (k, day) in enumerate(zip(ks, days, strict=True)):
            series, minus_ref = loaded[k]
            series = with_warnings(series, *(n for n in arc.notes if first in n), *notes[j])
            out = reference_outputs(
                paths[k], out_dir, opts, series, minus_ref, day, info, closure=closures[j]
            )
            outcomes[k] = dataclasses.replace(
                out, peak_rss=peak_rss_mb(), signature=arc.inputs[k].signature
            )
    except AccalError as exc:
        msg = f"arc of {len(ks)} inputs ({names[0]} .. {names[-1]}): {exc}"
        for k in ks:
            outcomes[k] = FileOutcome(
                paths[k], False, failure_message(paths[k], ValidationError(msg))
            )
    except OSError as exc:
        for k in ks:
            outcomes[k] = FileOutcome(paths[k], False, write_error_message(paths[k], exc))
    return [outcomes[k] for k in range(len(paths))]


def arc_outcomes(
    paths: list[Path],
    out_dir: Path,
    opts: GraceBiasOptions,
    *,
    workers: int = 1,
    scheduler: Any = None,
    on_note: Callable[[str], Any] | None = None,
    run_token: str | None = None,
) -> Iterator[tuple[int, FileOutcome]]:
    """Fit the inputs in arcs (``--arc``) on the batch's workers; yield ``(index, outcome)``.

    Two rounds of tasks (:func:`accal.batch.execute`: this process, local worker
    processes or a dask.distributed cluster): every input is read
    (:func:`scan_input`; a bad one fails alone), the good ones are grouped here by
    :func:`accal.pipeline_reference.group_arcs`, then each arc is read again,
    fitted and written by one task (:func:`fit_arc_task`), the arcs in parallel.
    The outputs do not depend on where the tasks run.

    Parameters
    ----------
    paths : list of Path
        The inputs to run.
    out_dir : Path
        Output directory.
    opts : GraceBiasOptions
        Options (``arc`` other than ``day``).
    workers : int
        Local worker processes.
    scheduler : str or distributed.Client, optional
        A dask.distributed scheduler to run on instead.
    on_note : callable, optional
        Lines for the run's log (where the tasks run).
    run_token : str, optional
        The lock token of this run (:func:`accal.io.writers.run_guard`).

    Yields
    ------
    (int, FileOutcome)
        Index into ``paths`` and the input's outcome: the failed reads first,
        then the inputs of each arc as it completes.
    """
    say = on_note or (lambda _msg: None)
    scans: dict[int, ArcInput] = {}
    for j, scan in execute(
        functools.partial(scan_input, opts=opts),
        paths,
        workers=workers,
        scheduler=scheduler,
        on_error=lambda p, exc: ArcInput(p, failure=internal_error(p, exc)),
        on_note=lambda msg: say(msg.replace("inputs run", "inputs read for the arcs", 1)),
    ):
        if scan.failure is not None:
            yield j, scan.failure
        else:
            scans[j] = scan
    good = sorted(scans)
    keys = [scans[j].key for j in good]
    groups, notes = group_arcs(keys, opts.arc)  # type: ignore[arg-type]
    members = [[good[k] for k in g] for g in groups]
    arcs = [Arc(tuple(scans[j] for j in js), tuple(notes)) for js in members]
    try:
        for a, outs in execute(
            functools.partial(fit_arc_task, out_dir=out_dir, opts=opts, run_token=run_token),
            arcs,
            workers=workers,
            scheduler=scheduler,
            on_error=lambda arc, exc: [internal_error(x.path, exc) for x in arc.inputs],
            on_note=lambda msg: say(msg.replace("inputs run", f"{len(arcs)} arcs run", 1)),
        ):
            yield from zip(members[a], outs, strict=True)
    finally:  # this process's copy (-j 1, the tasks run here): not kept after the batch
        _read_reference.cache_clear()
