"""``accal diagnose``: close the loop on the outputs of an earlier grace-bias or demod run.

The analysis is :func:`accal.pipeline_closure.diagnose_dir` (grace-bias outputs)
or :func:`accal.pipeline_demod.diagnose_demod_dir` (demod outputs), imported when
the command runs (~0.3 s, ~0.6 s more for accal.closure; not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from accal._cliutil import (
    OutPath,
    alpha_option,
    aux_option,
    err,
    plots_option,
    progress,
    quiet_option,
)


@click.command("diagnose", short_help="Close the loop on the outputs of a grace-bias or demod run.")
@click.argument("directory", type=click.Path(file_okay=False, exists=True, path_type=Path))
@click.option(
    "--out",
    "out",
    type=OutPath(file_okay=False, path_type=Path),
    default=None,
    help="Where closure.json/closure.md/plots go [default: DIRECTORY/diagnose, so a "
    "--close-loop run's own reports are kept].",
)
@aux_option
@alpha_option
@plots_option
@quiet_option
def diagnose(
    directory: Path, out: Path | None, aux: Path | None, alpha: float, plots: bool, quiet: bool
) -> None:
    """Close the loop on the outputs of an earlier grace-bias or demod run.

    For an accal demod directory (periods.<fmt>), every run named by its summaries
    is re-read and analysed with the same declared model (closure.json/.md, plots);
    the periods table is not changed.

    Reads every DIRECTORY/*.calibrated.{parquet,csv}, analyses each axis' residual
    of the model that run fitted (the calibrated series is scale*(raw - trend)),
    and reports the effects that model lacks in OUT/closure.json and closure.md,
    with plots.  The calibrated files themselves are not changed: re-run
    grace-bias with --close-loop to calibrate with the extended model.
    """
    from accal.batch import LockedError, OutputLock
    from accal.gracejob.outputs import CALIBRATED_SUFFIXES

    if not any(
        p.name.endswith(CALIBRATED_SUFFIXES) or p.name.startswith("periods.")
        for p in directory.iterdir()
    ):  # QA: a directory of someone else's got .accal.lock and an empty diagnose/
        err(_NOTHING.format(directory=directory))
        sys.exit(1)
    # a grace-bias or demod run writing DIRECTORY now: its files are half-written (QA:
    # diagnose ran beside a live run and wrote into DIR/diagnose)
    lock = OutputLock(directory, "accal diagnose")
    try:
        if directory.is_dir():
            lock.acquire()
    except LockedError as exc:
        err(str(exc))
        sys.exit(1)
    except OSError:  # a read-only results directory (--out elsewhere): nothing to guard
        pass
    try:
        out = out or directory / "diagnose"
        if any(directory.glob("periods.*")):  # an accal demod output directory
            _diagnose_demod(directory, out, alpha, quiet, plots)  # exits
        else:
            _diagnose_grace(directory, out, aux, alpha, quiet, plots)
    finally:
        lock.release()


_NOTHING = (
    "{directory}: no *.calibrated.parquet or *.calibrated.csv file (accal grace-bias output) "
    "and no periods.parquet or periods.csv with summary.json or <stem>.summary.json (accal "
    "demod output) to diagnose"
)


def _effect_line(name: str, entry: dict[str, Any]) -> str:
    """``NAME: effects found; RMS before -> after m/s^2`` of one closure entry."""
    found = [e["name"] for e in entry["effects"]] + ["unexplained"] * len(entry["unexplained"])
    return (
        f"{name}: {', '.join(found) or 'nothing found'}; RMS "
        f"{entry['rms_before']:.3g} -> {entry['rms_after']:.3g} m/s^2"
    )


def _diagnose_demod(directory: Path, out: Path, alpha: float, quiet: bool, plots: bool) -> None:
    """An accal demod output directory; exits with 1 if a run failed, else 0."""
    from accal.pipeline_demod import diagnose_demod_dir

    stale: list[str] = []
    results = diagnose_demod_dir(directory, out, alpha=alpha, warnings=stale, plots=plots)
    for w in stale:
        err(f"{directory}: warning: {w}")
    if not results:
        err(
            f"{directory}: no accal demod summary (summary.json or <stem>.summary.json) "
            "naming a run of its periods table to diagnose"
        )
        sys.exit(1)
    for src, entry, msg in results:
        if entry is None:
            err(msg)
        elif not quiet:
            click.echo(_effect_line(src.name, entry))
    if not quiet and any(e is not None for _, e, _ in results):
        click.echo(f"reports: {out / 'closure.json'}, {out / 'closure.md'}", err=True)
    sys.exit(1 if any(e is None for _, e, _ in results) else 0)


def _diagnose_grace(
    directory: Path, out: Path, aux: Path | None, alpha: float, quiet: bool, plots: bool
) -> None:
    """An accal grace-bias output directory; exits with 1 if an input failed."""
    from accal.closure_reports import write_closure_reports
    from accal.pipeline_closure import diagnose_dir

    outcomes = diagnose_dir(
        directory, out, aux=aux, alpha=alpha, plots=plots, progress=progress(quiet, "diagnose")
    )
    if not outcomes:
        err(_NOTHING.format(directory=directory))
        sys.exit(1)
    for o in outcomes:
        if not o.ok:
            err(o.message)
        elif o.warnings and not quiet:
            err(f"{o.path}: warning: {'; '.join(o.warnings)}")
    good = [o for o in outcomes if o.ok]
    if good:
        jpath, mpath = write_closure_reports(out, good, diagnose=True)
        if not quiet:
            for o in good:
                for ax, entry in o.closure.items():
                    click.echo(_effect_line(f"{o.path.name} {ax}", entry))
            click.echo(f"reports: {jpath}, {mpath}", err=True)
    if len(good) < len(outcomes):
        sys.exit(1)
