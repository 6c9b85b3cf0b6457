"""``accal grace-bias``: per-day, per-axis bias and drift of GRACE/GRACE-FO L1B files.

The options are declared in :mod:`accal.cli.grace_bias_options`; the work is
:func:`accal.pipeline.run`.  The library is imported when the command runs
(accal.pipeline and accal.batch: ~0.4 s, not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from accal._cliutil import check_files, err, progress
from accal.cli.batch_options import for_scheduler
from accal.cli.grace_bias_options import grace_bias_options, parse_column_map, parse_margins


@click.command(
    "grace-bias", short_help="Estimate per-day, per-axis bias and drift of accelerometer data."
)
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@grace_bias_options
def grace_bias(
    inputs: tuple[Path, ...],
    out: Path,
    method: str,
    fmt: str,
    order: str,
    scale: str | None,
    reference: Path | None,
    bias_basis: str | None,
    reference_frame: str,
    attitude: Path | None,
    arc: str,
    thrusters: Path | None,
    thruster_margins: str,
    columns: tuple[str, ...],
    input_format: str | None,
    keep_flagged: bool,
    recursive: bool,
    include: tuple[str, ...],
    workers: int | None,
    scheduler: str | None,
    force: bool,
    checksum: bool,
    close_loop: bool,
    aux: Path | None,
    plots: bool,
    truth: Path | None,
    alpha: float,
    degraded_days: Path | None,
    pool_days: int,
    keep_going: bool,
    quiet: bool,
) -> None:
    """Estimate per-day, per-axis bias and drift of accelerometer files.

    INPUTS are files, directories (with --recursive) or glob patterns.  Writes
    OUT/bias_drift.<fmt> (cumulative: one row per input, axis and method ever
    processed there), OUT/<stem>.calibrated.<fmt> and OUT/<stem>.report.json per
    input, OUT/manifest.json (re-runs skip inputs whose outputs are current) and
    OUT/accal.log.  With --close-loop also OUT/closure.json and OUT/closure.md (and
    PNG plots with --plots).
    """
    from accal.batch import DEFAULT_INCLUDE, Interrupted, LockedError, default_workers, discover
    from accal.closure_reports import write_closure_reports
    from accal.errors import AccalError
    from accal.pipeline import KEPT_EARLIER, GraceBiasOptions, run

    colmap = parse_column_map(columns)
    try:
        opts = GraceBiasOptions(
            methods=("wavelet", "lsq") if method == "both" else (method,),
            order=int(order),
            fmt=fmt,
            scale=scale,
            keep_flagged=keep_flagged,
            reference=reference,
            columns=colmap,
            input_format=input_format,
            close_loop=close_loop or aux is not None or truth is not None,
            aux=aux,
            truth=truth,
            alpha=alpha,
            plots=plots,
            degraded_days=degraded_days,
            pool_days=pool_days,
            bias_basis=bias_basis,
            reference_frame=reference_frame,
            attitude=attitude,
            arc=arc,
            thrusters=thrusters,
            thruster_margins=parse_margins(thruster_margins),
        )
    except AccalError as exc:
        raise click.UsageError(str(exc)) from None
    check_files(reference=reference, aux=aux, truth=truth, attitude=attitude, thrusters=thrusters)
    files, problems = discover(inputs, recursive=recursive, include=include or DEFAULT_INCLUDE)
    files, out, opts = for_scheduler(scheduler, files, out, opts)
    try:
        summary = run(
            files,
            out,
            opts,
            unmatched=problems,
            fail_fast=not keep_going,
            progress=progress(quiet, "grace-bias"),
            workers=workers or default_workers(),
            scheduler=scheduler,
            force=force,
            checksum=checksum,
        )
    except (LockedError, AccalError) as exc:
        err(str(exc))
        sys.exit(1)
    except Interrupted as exc:
        done = exc.summary
        err(
            f"interrupted: {done.n_ok} ok, {done.n_failed} failed, {done.n_not_run} not run "
            f"(kept in {out}; run the same command again to finish)"
        )
        sys.exit(130)
    except OSError as exc:  # the output directory cannot be made or written
        err(f"{exc.filename or out}: cannot write the output directory: {exc.strerror or exc}")
        sys.exit(2)
    for o in summary.outcomes:
        if not o.ok:
            err(o.message)
            if o.kept_earlier:
                err(f"{o.path}: note: {KEPT_EARLIER}")
        elif o.warnings and not quiet:
            err(f"{o.path}: warning: {'; '.join(o.warnings)}")
    if opts.close_loop or (out / "closure.json").exists():  # also drops stale entries
        write_closure_reports(out, summary.outcomes)
    if not quiet:
        click.echo(summary.line(), err=True)
    if summary.n_failed or summary.n_not_run or problems:
        sys.exit(1)
