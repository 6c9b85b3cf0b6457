"""Command-line interface (click).  Thin: parse options, call the pipeline, map errors.

Exit status: 0 when every input was processed, 1 when some failed (the others are
still processed and written), 2 for usage errors.  Every failure is one line on
stderr: ``accal: FILE[:LINE]: what is wrong``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click
import numpy as np

from accal import __version__
from accal._cliutil import (
    Group,
    OutPath,
    alpha_option,
    aux_option,
    check_files,
    check_number,
    check_seed,
    config_option,
    fmt_number,
    plots_option,
    usage_fail,
)
from accal._cliutil import err as _err
from accal._cliutil import progress as _progress

CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(cls=Group, context_settings=CONTEXT_SETTINGS)
@click.version_option(__version__, prog_name="accal")
@click.option("--debug", is_flag=True, help="Show tracebacks of internal errors (for bug reports).")
def main(debug: bool) -> None:
    """accal: calibrate spacecraft electrostatic-accelerometer data.

    \b
    grace-bias  per-day, per-axis bias and drift of GRACE / GRACE-FO ACC1B/ACT1B
    table       print or export the cumulative bias/drift table of an output dir
    diagnose    close the loop on the outputs of an earlier grace-bias run
    demod       unbiased acceleration from a rotating-platform accelerometer
    design      a theta(t) calibration pattern for the rotating platform
    budget      uncertainty budget of the rotating-platform measurement
    simulate    synthetic inputs with a truth file
    """
    import os

    from accal._runtime import tune_allocator

    tune_allocator()
    if debug:
        os.environ["ACCAL_DEBUG"] = "1"  # inherited by worker processes
    from accal.batch import forced_start_method
    from accal.errors import AccalError

    try:
        forced_start_method()  # a bad value is a usage error now, not at the first pool
    except AccalError as exc:
        usage_fail(str(exc))


def _margins(text: str) -> tuple[float, float] | None:
    """``--thruster-margins``: ``BEFORE,AFTER`` seconds or ``off``."""
    if text.strip().lower() == "off":
        return None
    try:
        before, after = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(
            f"expected BEFORE,AFTER in seconds or 'off', got {text!r}",
            param_hint="--thruster-margins",
        ) from None
    return before, after


@main.command("grace-bias")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "--out",
    "out",
    type=OutPath(file_okay=False, path_type=Path),
    required=True,
    help="Output directory (created).",
)
@click.option(
    "--method",
    type=click.Choice(["wavelet", "lsq", "both"]),
    default="wavelet",
    show_default=True,
    help="Estimator; with 'both' the wavelet fit calibrates the series.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["parquet", "csv"]),
    default="parquet",
    show_default=True,
    help="Output format.",
)
@click.option(
    "--order",
    type=click.Choice(["1", "2"]),
    default="1",
    show_default=True,
    help="Trend order: 1 = bias + drift, 2 = + quadratic term.",
)
@click.option(
    "--scale",
    default=None,
    help="Scale applied to the calibrated series: 'tn02' (GRACE TN-02 a-priori) or "
    "'sx,sy,sz'; a_cal = scale*(a_raw - trend).  With --reference also 'fit' (one scale "
    "per axis) or 'fit-matrix' (3x3 scale matrix), estimated with the bias.",
)
@click.option(
    "--reference",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Reference accelerations (table or L1B); the fit uses raw - reference.",
)
@click.option(
    "--bias-basis",
    default=None,
    metavar="BASIS",
    help="With --reference: fit a_ref = S (a_raw - b(t)) by AR-weighted least squares, "
    "the bias b on poly0|poly1|poly2|spline:STEP (e.g. spline:6h); method 'reference' "
    "(default poly1 when only --scale fit is given).",
)
@click.option(
    "--reference-frame",
    type=click.Choice(["srf", "inertial"]),
    default="srf",
    show_default=True,
    help="Frame of --reference; 'inertial' is rotated into the SRF with the SCA1B "
    "attitude (--attitude, or the SCA1B file beside the input).",
)
@click.option(
    "--attitude",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="SCA1B star-camera file for --reference-frame inertial.",
)
@click.option(
    "--arc",
    default="day",
    show_default=True,
    metavar="day|Nd|month",
    help="With the reference fit: fit up to N consecutive days (e.g. 30d) or a calendar "
    "month of one satellite together (one bias spline across the days, one scale); "
    "a missing day starts a new arc.",
)
@click.option(
    "--thrusters",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="THR1B file whose firings the reference fit leaves out (default: the THR1B "
    "file beside the input, if any).",
)
@click.option(
    "--thruster-margins",
    default="0.1,0.7",
    show_default=True,
    metavar="BEFORE,AFTER",
    help="Seconds left out before and after each firing (GROOPS's values), or 'off'.",
)
@click.option(
    "--column",
    "columns",
    multiple=True,
    metavar="AXIS=COLUMN",
    help="Map a table column to an axis, e.g. --column x=a_cal_x (repeatable).",
)
@click.option(
    "--input-format",
    type=click.Choice(["grace-l1b", "table"]),
    default=None,
    help="Force the input format (default: sniffed from the content).",
)
@click.option("--keep-flagged", is_flag=True, help="Use samples the quality flags mark invalid.")
@click.option(
    "--recursive",
    "-r",
    is_flag=True,
    help="Take the files of directory inputs and their sub-directories.",
)
@click.option(
    "--include",
    "include",
    multiple=True,
    metavar="PATTERN",
    help="Names taken from directories (repeatable; default: *ACC1B_* and *ACT1B_*).",
)
@click.option(
    "--workers",
    "-j",
    type=click.IntRange(min=1),
    default=None,
    help="Worker processes on this machine [default: all cores].",
)
@click.option(
    "--scheduler",
    default=None,
    metavar="ADDRESS",
    help="Run on a dask.distributed cluster (e.g. tcp://host:8786); workers must see "
    "the same file system.",
)
@click.option("--force", is_flag=True, help="Redo inputs whose outputs are current.")
@click.option(
    "--checksum",
    is_flag=True,
    help="Decide 'current' by SHA-256 of the inputs instead of size and mtime.",
)
@click.option(
    "--close-loop",
    is_flag=True,
    help="Analyse the residual, add the effects the model lacks, refit (closure.json/md).",
)
@aux_option
@plots_option
@click.option(
    "--truth",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Truth JSON of a simulation: --close-loop (implied) reports the true error before/after.",
)
@alpha_option
@click.option(
    "--degraded-days",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="TOML/YAML table of degraded/transplant/off periods, ahead of the built-in one.",
)
@click.option(
    "--pool-days",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    metavar="N",
    help="Sigmas from a noise model fitted to N adjacent days together (archives; noise "
    "correlated over hours needs it; >= 2, 8 recommended; 0: each day's own estimate).",
)
@click.option(
    "--keep-going/--fail-fast",
    default=True,
    show_default=True,
    help="Go on with the other inputs after a failure (--fail-fast: stop at the first, "
    "running the inputs one at a time, in order).",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
@config_option
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
    from accal.errors import AccalError
    from accal.pipeline import KEPT_EARLIER, GraceBiasOptions, run
    from accal.pipeline_closure import write_closure_reports

    colmap = {}
    for item in columns:
        ax, sep, col = item.partition("=")
        if not sep or ax not in ("x", "y", "z") or not col:
            raise click.BadParameter(
                f"expected AXIS=COLUMN with AXIS in x|y|z, got {item!r}", param_hint="--column"
            )
        colmap[ax] = col
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
            thruster_margins=_margins(thruster_margins),
        )
    except AccalError as exc:
        raise click.UsageError(str(exc)) from None
    check_files(reference=reference, aux=aux, truth=truth, attitude=attitude, thrusters=thrusters)
    files, problems = discover(inputs, recursive=recursive, include=include or DEFAULT_INCLUDE)
    try:
        summary = run(
            files,
            out,
            opts,
            unmatched=problems,
            fail_fast=not keep_going,
            progress=_progress(quiet, "grace-bias"),
            workers=workers or default_workers(),
            scheduler=scheduler,
            force=force,
            checksum=checksum,
        )
    except (LockedError, AccalError) as exc:
        _err(str(exc))
        sys.exit(1)
    except Interrupted as exc:
        done = exc.summary
        _err(
            f"interrupted: {done.n_ok} ok, {done.n_failed} failed, {done.n_not_run} not run "
            f"(kept in {out}; run the same command again to finish)"
        )
        sys.exit(130)
    except OSError as exc:  # the output directory cannot be made or written
        _err(f"{exc.filename or out}: cannot write the output directory: {exc.strerror or exc}")
        sys.exit(2)
    for o in summary.outcomes:
        if not o.ok:
            _err(o.message)
            if o.kept_earlier:
                _err(f"{o.path}: note: {KEPT_EARLIER}")
        elif o.warnings and not quiet:
            _err(f"{o.path}: warning: {'; '.join(o.warnings)}")
    if opts.close_loop or (out / "closure.json").exists():  # also drops stale entries
        write_closure_reports(out, summary.outcomes)
    if not quiet:
        click.echo(summary.line(), err=True)
    if summary.n_failed or summary.n_not_run or problems:
        sys.exit(1)


@main.command("table")
@click.argument("directory", type=click.Path(file_okay=False, exists=True, path_type=Path))
@click.option(
    "--satellite", "satellites", multiple=True, help="Keep these satellites (repeatable)."
)
@click.option("--start", default=None, metavar="YYYY-MM-DD", help="First date kept.")
@click.option("--end", default=None, metavar="YYYY-MM-DD", help="Last date kept.")
@click.option(
    "--method",
    "methods",
    multiple=True,
    type=click.Choice(["wavelet", "lsq"], case_sensitive=False),
    help="Keep these methods (repeatable).",
)
@click.option(
    "--axis",
    "axes",
    multiple=True,
    type=click.Choice(["x", "y", "z"], case_sensitive=False),
    help="Keep these axes (repeatable).",
)
@click.option(
    "--status",
    "statuses",
    multiple=True,
    type=click.Choice(["nominal", "degraded", "transplant", "off"]),
    help="Keep days of these statuses (repeatable), e.g. --status nominal.",
)
@click.option(
    "--columns",
    default=None,
    help="Comma-separated columns to show/export (default: all when exporting, a "
    "readable subset when printing).",
)
@click.option(
    "--export",
    "export",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the rows to FILE (.csv or .parquet, atomic) instead of printing them.",
)
def table_cmd(
    directory: Path,
    satellites: tuple[str, ...],
    start: str | None,
    end: str | None,
    methods: tuple[str, ...],
    axes: tuple[str, ...],
    statuses: tuple[str, ...],
    columns: str | None,
    export: Path | None,
) -> None:
    """Print or export the cumulative bias/drift table of an output DIRECTORY."""
    from accal.errors import AccalError
    from accal.pipeline import BIAS_DRIFT_UNITS, find_bias_drift, read_bias_drift

    try:
        path = find_bias_drift(directory)
        df = read_bias_drift(path)
        for d in (start, end):
            if d is not None and not _is_date(d):
                raise click.BadParameter(f"expected YYYY-MM-DD, got {d!r}")
        if start and end and start > end:
            raise click.BadParameter(f"--start {start} is after --end {end}")
        keep = np.ones(len(df), dtype=bool)
        if satellites:
            want = {_short_satellite(s) for s in satellites}
            short = df["satellite"].astype(str).str.upper().str.split("-").str[-1]
            held = sorted(set(df["satellite"].astype(str)))
            known = set(short) | set(held)
            unknown = [s for s in satellites if _short_satellite(s) not in known and s not in known]
            if unknown:  # a typo would otherwise match nothing, silently
                usage_fail(
                    f"--satellite {unknown[0]!r} is not in {path} (it holds "
                    f"{', '.join(held) or 'no rows'})"
                )
            keep &= short.isin(want).to_numpy() | df["satellite"].isin(satellites).to_numpy()
        if start:
            keep &= (df["date"] >= start).to_numpy()
        if end:
            keep &= (df["date"] <= end).to_numpy()
        if methods:
            keep &= df["method"].isin([m.lower() for m in methods]).to_numpy()
        if axes:
            keep &= df["axis"].isin([a.lower() for a in axes]).to_numpy()
        if statuses:
            keep &= df["day_status"].isin(statuses).to_numpy()
        df = df[keep]
        if columns:
            cols = [c.strip() for c in columns.split(",") if c.strip()]
            if not cols:
                usage_fail(
                    f"--columns names no column, got {columns!r}; give a comma-separated "
                    f"list of {', '.join(map(str, df.columns))}"
                )
            unknown = [c for c in cols if c not in df.columns]
            if unknown:
                raise click.BadParameter(f"unknown columns {unknown}; known: {list(df.columns)}")
            df = df[cols]
        if export is not None:
            from accal.io.writers import write_table

            fmt = "parquet" if export.suffix.lower() == ".parquet" else "csv"
            if export.suffix.lower() not in (".csv", ".parquet"):
                raise click.BadParameter("--export FILE must end in .csv or .parquet")
            _check_export_target(export)
            write_table(
                {c: df[c].to_numpy() for c in df.columns},
                export,
                fmt=fmt,
                units={c: BIAS_DRIFT_UNITS.get(c, "") for c in df.columns},
                meta={"exported_from": str(path)},
            )
            click.echo(f"wrote {len(df)} rows to {export}", err=True)
            return
        if not columns:
            shown = ["source", "satellite", "date", "axis", "method", "bias", "bias_sigma"]
            shown += ["drift", "drift_sigma", "n", "rms"]
            shown += [c for c in ("day_status", "model") if c in df.columns]
            df = df[shown]
        import pandas as pd

        with pd.option_context("display.width", 250, "display.max_rows", None):
            text = df.to_string(index=False, float_format=lambda v: f"{v:.6g}")
            click.echo(text if len(df) else "(no rows)")
    except AccalError as exc:
        _err(str(exc))
        sys.exit(1)


def _short_satellite(name: str) -> str:
    """``GRACE-A``, ``grace-a``, ``a`` → ``A``; ``GRACE-FO-C`` → ``C`` (others: upper case)."""
    return name.upper().removeprefix("GRACE-FO-").removeprefix("GRACE-")


def _check_export_target(export: Path) -> None:
    """Usage error for an export that would replace an output directory's own table.

    QA: ``accal table OUT --export OUT/bias_drift.parquet --satellite B`` replaced
    the cumulative table with B's rows; the next runs skipped A's inputs as current,
    so their rows were lost until ``--force``.  A ``bias_drift.csv`` beside a
    Parquet table made every later run refuse the directory.  A missing directory
    is an error too, not created (a typo in the path would go unnoticed).
    """
    from accal.batch import MANIFEST

    parent = export.parent
    if not parent.is_dir():
        usage_fail(f"--export {export}: directory {parent} does not exist")
    stem = export.name.lower().rsplit(".", 1)[0]
    if stem == "bias_drift" and ((parent / MANIFEST).exists() or any(parent.glob("bias_drift.*"))):
        usage_fail(
            f"--export {export} is the name of the cumulative table of the output "
            f"directory {parent}; export to another name or directory"
        )


def _is_date(s: str) -> bool:
    import datetime as dt

    try:
        dt.date.fromisoformat(s)
    except ValueError:
        return False
    return len(s) == 10


@main.command("diagnose")
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
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
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

    # a grace-bias or demod run writing DIRECTORY now: its files are half-written (QA:
    # diagnose ran beside a live run and wrote into DIR/diagnose)
    lock = OutputLock(directory, "accal diagnose")
    try:
        if directory.is_dir():
            lock.acquire()
    except LockedError as exc:
        _err(str(exc))
        sys.exit(1)
    except OSError:  # a read-only results directory (--out elsewhere): nothing to guard
        pass
    try:
        _diagnose(directory, out, aux, alpha, quiet, plots)
    finally:
        lock.release()


def _diagnose(
    directory: Path, out: Path | None, aux: Path | None, alpha: float, quiet: bool, plots: bool
) -> None:
    from accal.pipeline_closure import diagnose_dir, write_closure_reports

    out = out or directory / "diagnose"
    if any(directory.glob("periods.*")):  # an accal demod output directory
        from accal.pipeline_demod import diagnose_demod_dir

        stale: list[str] = []
        results = diagnose_demod_dir(directory, out, alpha=alpha, warnings=stale, plots=plots)
        for w in stale:
            _err(f"{directory}: warning: {w}")
        if not results:
            _err(
                f"{directory}: no accal demod summary (summary.json or <stem>.summary.json) "
                "naming a run of its periods table to diagnose"
            )
            sys.exit(1)
        for src, entry, msg in results:
            if entry is None:
                _err(msg)
            elif not quiet:
                found = [e["name"] for e in entry["effects"]]
                found += ["unexplained"] * len(entry["unexplained"])
                click.echo(
                    f"{src.name}: {', '.join(found) or 'nothing found'}; RMS "
                    f"{entry['rms_before']:.3g} -> {entry['rms_after']:.3g} m/s^2"
                )
        if not quiet and any(e is not None for _, e, _ in results):
            click.echo(f"reports: {out / 'closure.json'}, {out / 'closure.md'}", err=True)
        sys.exit(1 if any(e is None for _, e, _ in results) else 0)
    outcomes = diagnose_dir(
        directory, out, aux=aux, alpha=alpha, plots=plots, progress=_progress(quiet, "diagnose")
    )
    if not outcomes:
        _err(
            f"{directory}: no *.calibrated.parquet or *.calibrated.csv file (accal grace-bias "
            "output) and no periods.parquet or periods.csv with summary.json or "
            "<stem>.summary.json (accal demod output) to diagnose"
        )
        sys.exit(1)
    for o in outcomes:
        if not o.ok:
            _err(o.message)
        elif o.warnings and not quiet:
            _err(f"{o.path}: warning: {'; '.join(o.warnings)}")
    good = [o for o in outcomes if o.ok]
    if good:
        jpath, mpath = write_closure_reports(out, good, diagnose=True)
        if not quiet:
            for o in good:
                for ax, entry in o.closure.items():
                    names = [e["name"] for e in entry["effects"]]
                    names += ["unexplained"] * len(entry["unexplained"])
                    click.echo(
                        f"{o.path.name} {ax}: {', '.join(names) or 'nothing found'}; RMS "
                        f"{entry['rms_before']:.3g} -> {entry['rms_after']:.3g} m/s^2"
                    )
            click.echo(f"reports: {jpath}, {mpath}", err=True)
    if len(good) < len(outcomes):
        sys.exit(1)


@main.group()
def simulate() -> None:
    """Write synthetic input files with a truth file."""


@simulate.command("grace")
@click.option(
    "--date", "date", default="2005-01-01", show_default=True, help="UTC day (YYYY-MM-DD)."
)
@click.option(
    "--satellite", type=click.Choice(["A", "B", "C", "D"]), default="A", show_default=True
)
@click.option(
    "--out",
    "out",
    type=OutPath(dir_okay=False, path_type=Path),
    required=True,
    help="Output ACC1B file (.asc/.txt, .gz to compress); truth goes to <out>.truth.json.",
)
@click.option(
    "--seed",
    type=int,
    default=None,
    help="Random seed (default: derived from --date and --satellite, so every day differs "
    "and a day is the same on every machine).",
)
@click.option("--duration", type=float, default=86400.0, show_default=True, help="Seconds.")
@click.option("--gaps", type=int, default=0, show_default=True, help="Number of data gaps.")
@click.option(
    "--flagged",
    type=float,
    default=0.0,
    show_default=True,
    help="Fraction of samples flagged invalid.",
)
@click.option(
    "--noise",
    type=float,
    default=1e-10,
    show_default=True,
    help="Noise level [m/s^2/sqrt(Hz)] in the measurement band.",
)
@click.option(
    "--storm", is_flag=True, help="Add a geomagnetic storm (density x2-4 within hours, decaying)."
)
@click.option(
    "--thrusters",
    is_flag=True,
    help="Add thruster pulses (1e-8-1e-7 m/s^2, a few s, a few per hour) to the true signal "
    "and write them as a THR1B file beside --out.",
)
@click.option(
    "--effect",
    "effects",
    multiple=True,
    metavar="SPEC",
    help="Inject an instrument effect NAME:key=value,... into the raw reading (repeatable; "
    "the effects are listed above).",
)
@click.option(
    "--reference-out",
    "reference_out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the reference: the true non-gravitational acceleration s*a_true plus "
    "the reference noise, as a table (for grace-bias --reference; .csv or Parquet).",
)
@click.option(
    "--reference-noise",
    "reference_noise",
    type=float,
    default=1e-9,
    show_default=True,
    metavar="LEVEL",
    help="Noise of the --reference-out table [m/s^2]: its RMS at orbit scales (periods over "
    "1000 s); it rises at high frequency like a POD-derived acceleration (at 1e-9: ASD "
    "3.2e-8 m/s^2/sqrt(Hz) up to 0.1 Hz, 1.4e-7 at 0.5 Hz). 0: a noise-free reference.",
)
@click.option(
    "--days",
    type=int,
    default=1,
    show_default=True,
    help="Simulate N consecutive days from --date as one arc (--out must contain the date, "
    "replaced by each day's; --seed S gives day k the seed S+k); the bias continues across "
    "the days and --reference-out gets one table covering all of them (for grace-bias --arc).",
)
@config_option
def simulate_grace(
    date: str,
    satellite: str,
    out: Path,
    seed: int | None,
    duration: float,
    gaps: int,
    flagged: float,
    noise: float,
    storm: bool,
    thrusters: bool,
    effects: tuple[str, ...],
    reference_out: Path | None,
    reference_noise: float,
    days: int,
) -> None:
    """Write a real-like synthetic GRACE/GRACE-FO ACC1B day file and its truth JSON.

    All 12 ACC1B columns are filled at the magnitudes of the real files; the truth
    (<out>.truth.json) has the bias, drift and scale, the orbit period, eclipses,
    storm, thruster pulses and every injected effect with its parameters.

    \b
    --effect NAME:key=value,... (times in s, epochs from the start of the day):
      step:axis=x,epoch=43200,size=3e-9
      coupling:axis=y,channel=temperature,coef=3e-9[,lag=600][,tau=300][,tau2=100]
      quadratic:axis=z,coef=1e-18               (m/s^4, about the start)
      scale:axis=x,factor=1.02                  (raw = s*factor*a_true + ...)
      scalematrix:xx=0.98,xy=1e-3,zx=-2e-3      (S of a_ref = S (a_raw - b); others of I)
      splinebias:axis=x,step=21600,amp=1e-9[,seed=0]   (cubic B-spline, nodes k*step GPS s)
      splinebias:axis=x,step=21600,coefs=1e-9;0;-2e-9;...   (nodes t0-step, t0, ...)
      sawtooth:axis=y,period=3000,amp=1e-9[,phase=0]
      growing:axis=y,period=2000,amp0=1e-9,amp1=3e-9[,phase=0]
      exponential:axis=x,amp=3e-9,tau=3000
    A coupling's channel (K) goes to <out>.aux.parquet, for grace-bias --aux.
    --thrusters also writes the pulses as a THR1B file beside <out>
    (THR1B_<date>_<sat>_<rel>.asc/.txt for an ACC1B/ACT1B name), which grace-bias
    finds and uses to leave the firings out.  With --reference-out the truth has
    "reference": "scale" (the 3x3 S that grace-bias --scale fit-matrix should find;
    row i = scale_x, scale_y, scale_z of axis i) and "noise" (model and level).
    """
    from accal.errors import AccalError
    from accal.simulate.effects import parse_effect
    from accal.simulate.grace import write_simulated_arc

    if not _is_date(date) or not "1980-01-06" <= date < "2100-01-01":
        raise click.BadParameter(
            f"expected a day YYYY-MM-DD in 1980-01-06 ... 2099-12-31, got {date!r}",
            param_hint="--date",
        )
    from accal.simulate.grace import MAX_SAMPLES

    check_seed("--seed", seed)
    check_number(
        "--duration",
        duration,
        low=0,
        high=MAX_SAMPLES,  # 1 s sampling
        low_open=True,
        unit=" s",
        why=f"at most {fmt_number(MAX_SAMPLES)} samples of 1 s",
    )
    check_number("--gaps", gaps, low=0, high=MAX_SAMPLES)
    check_number("--flagged", flagged, low=0, high=1, high_open=True, what="fraction")
    check_number("--noise", noise, low=0, unit=" m/s^2/sqrt(Hz)")
    check_number("--reference-noise", reference_noise, low=0, unit=" m/s^2")
    check_number("--days", days, low=1, high=366, what="number of days")
    if days > 1 and date not in out.name:
        usage_fail(
            f"--days {days}: the --out name must contain the date {date} (replaced by each "
            f"day's date), got {out.name!r}"
        )
    parsed = []
    for spec in effects:
        try:
            parsed.append(parse_effect(spec, duration=round(duration) * 1.0))
        except AccalError as exc:
            usage_fail(f"--effect {spec!r}: {exc}")

    try:
        truth_paths = write_simulated_arc(
            out,
            days=days,
            reference_out=reference_out,
            reference_noise=reference_noise,
            date=date,
            satellite=satellite,
            seed=seed,
            duration=duration,
            n_gaps=gaps,
            flagged_fraction=flagged,
            noise=noise,
            storm=storm,
            thrusters=thrusters,
            effects=parsed,
        )
    except AccalError as exc:
        _err(str(exc))
        sys.exit(1)
    from accal.simulate.grace import arc_paths, aux_path
    from accal.simulate.thr1b import thruster_path

    written = []
    for path in arc_paths(out, date, days):
        written.append(str(path))
        if aux_path(path).exists() and any(e.name == "coupling" for e in parsed):
            written.append(str(aux_path(path)))
        if thrusters:
            written.append(str(thruster_path(path, satellite)))
    if reference_out is not None:
        written.append(str(reference_out))
    truths = ", ".join(str(p) for p in truth_paths)
    click.echo(f"wrote {', '.join(written)} and {truths}", err=True)


from accal.cli_demod import budget, demod, design, simulate_gap  # noqa: E402

main.add_command(demod)
main.add_command(design)
main.add_command(budget)
simulate.add_command(simulate_gap, name="gap")

if __name__ == "__main__":  # pragma: no cover
    main()
