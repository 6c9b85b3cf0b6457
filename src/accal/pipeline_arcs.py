"""``grace-bias`` with the reference fit: the outputs of one input, and arcs of inputs.

Sequencing only (issue 22): :func:`reference_outputs` writes what one input's
reference fit produced (table rows, calibrated series, parameter table, covariance,
report); :func:`arc_outcomes` reads a batch's inputs, groups them into arcs
(:func:`accal.pipeline_reference.group_arcs`), fits each arc once
(:func:`accal.pipeline_reference.fit_arc`) and yields one outcome per input for
:func:`accal.pipeline.run` to commit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import check_input, failure_message, file_signature, write_error_message
from accal.degraded import classify_day, load_periods
from accal.errors import AccalError, ValidationError
from accal.gracejob.fit import row_source, signal_share
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import FileOutcome, peak_rss_mb
from accal.gracejob.outputs import (
    CALIBRATED_UNITS,
    calibrated_file_columns,
    file_size,
    output_stem,
    write_json,
)
from accal.gracejob.reading import read_input, read_with_reference, with_warnings
from accal.io.writers import write_table
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
    "arc_outcomes",
    "parameter_file_columns",
    "redo_all",
    "reference_outputs",
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


def arc_outcomes(
    paths: list[Path], out_dir: Path, opts: GraceBiasOptions
) -> Iterable[tuple[int, FileOutcome]]:
    """Fit the inputs in arcs (``--arc``), in this process; yield ``(index, outcome)``.

    Every input is read (a bad one fails alone), the good ones are grouped by
    :func:`accal.pipeline_reference.group_arcs` and each arc is fitted at once
    (:func:`accal.pipeline_reference.fit_arc`); a failed fit fails the inputs of its
    arc with one message.  The arc's coefficients go to
    ``arc_<satellite>_<first date>_<last date>.bias_basis.<fmt>``.
    """

    reference = None
    try:
        reference = read_input(opts.reference, GraceBiasOptions(columns=opts.columns))
    except AccalError as exc:
        for j, p in enumerate(paths):
            yield j, FileOutcome(p, False, failure_message(p, exc))
        return
    loaded: dict[int, tuple[AccSeries, AccSeries, Any]] = {}
    for j, p in enumerate(paths):
        try:
            check_input(p)
            before = file_signature(p)
            series, _, minus_ref = read_with_reference(p, opts, reference)
            loaded[j] = (series, minus_ref, before)
        except AccalError as exc:
            yield j, FileOutcome(p, False, failure_message(p, exc))
        except OSError as exc:
            yield j, FileOutcome(p, False, write_error_message(p, exc))
    good = sorted(loaded)
    keys = [(loaded[j][0].satellite, float(loaded[j][0].time[0]), float(loaded[j][0].time[-1]))
            for j in good]  # fmt: skip
    arcs, notes = group_arcs(keys, opts.arc)
    for arc in arcs:
        js = [good[k] for k in arc]
        names = [paths[j].name for j in js]
        try:
            days = fit_arc(
                [paths[j] for j in js],
                [loaded[j][0] for j in js],
                [loaded[j][1] for j in js],
                opts,
            )
            first, last = (
                gps_to_date(float(loaded[j][0].time[k])) for j, k in ((js[0], 0), (js[-1], -1))
            )
            who = loaded[js[0]][0].satellite or output_stem(paths[js[0]])
            par_name = f"arc_{who}_{first}_{last}.bias_basis.{opts.fmt}"
            info = {"sources": names, "parameters": par_name, "first": first, "last": last}
            write_table(
                parameter_file_columns(days[0].fit, opts.fmt),
                out_dir / par_name,
                fmt=opts.fmt,
                units=PARAMETER_FILE_UNITS,
                meta={"sources": names, **report_entry(days[0])},
            )
            write_covariance(out_dir / f"arc_{who}_{first}_{last}.reference_cov.npz", days[0].fit)
            for j, day in zip(js, days, strict=True):
                series, minus_ref, before = loaded[j]
                series = with_warnings(series, *(n for n in notes if first in n))
                out = reference_outputs(paths[j], out_dir, opts, series, minus_ref, day, info)
                yield j, dataclasses.replace(out, peak_rss=peak_rss_mb(), signature=before)
        except AccalError as exc:
            for j in js:
                msg = f"arc of {len(js)} inputs ({names[0]} .. {names[-1]}): {exc}"
                yield (
                    j,
                    FileOutcome(paths[j], False, failure_message(paths[j], ValidationError(msg))),
                )
        except OSError as exc:
            for j in js:
                yield j, FileOutcome(paths[j], False, write_error_message(paths[j], exc))
