"""Command-line interface (click).  Thin: parse options, call the pipeline, map errors.

Exit status: 0 when every input was processed, 1 when some failed (the others are
still processed and written), 2 for usage errors.  Every failure is one line on
stderr: ``accal: FILE[:LINE]: what is wrong``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from accal import __version__
from accal._cliutil import config_option
from accal._cliutil import err as _err
from accal._cliutil import progress as _progress

CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(context_settings=CONTEXT_SETTINGS)
@click.version_option(__version__, prog_name="accal")
def main() -> None:
    """accal: calibrate spacecraft electrostatic-accelerometer data.

    \b
    grace-bias  per-day, per-axis bias and drift of GRACE / GRACE-FO ACC1B/ACT1B
    demod       unbiased acceleration from a rotating-platform accelerometer
    design      a theta(t) calibration pattern for the rotating platform
    budget      uncertainty budget of the rotating-platform measurement
    simulate    synthetic inputs with a truth file
    """


@main.command("grace-bias")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "--out",
    "out",
    type=click.Path(file_okay=False, path_type=Path),
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
    "'sx,sy,sz'; a_cal = scale*(a_raw - trend).",
)
@click.option(
    "--reference",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Reference accelerations (table or L1B); the fit uses raw - reference.",
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
    "--keep-going/--fail-fast",
    default=True,
    show_default=True,
    help="Go on with the other inputs after a failure.",
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
    columns: tuple[str, ...],
    input_format: str | None,
    keep_flagged: bool,
    keep_going: bool,
    quiet: bool,
) -> None:
    """Estimate per-day, per-axis bias and drift of accelerometer files.

    Writes OUT/bias_drift.<fmt> (one row per input, axis and method),
    OUT/<stem>.calibrated.<fmt> and OUT/<stem>.report.json for each input.
    """
    from accal.errors import AccalError
    from accal.pipeline import GraceBiasOptions, run

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
        )
    except AccalError as exc:
        raise click.UsageError(str(exc)) from None
    summary = run(
        inputs, out, opts, fail_fast=not keep_going, progress=_progress(quiet, "grace-bias")
    )
    for o in summary.outcomes:
        if not o.ok:
            _err(o.message)
    if not quiet:
        n = sum(o.n_samples for o in summary.outcomes)
        click.echo(
            f"accal grace-bias: {summary.n_ok} ok, {summary.n_failed} failed, "
            f"{len(inputs) - len(summary.outcomes)} not run; {n} samples in "
            f"{summary.seconds:.2f} s; table: {summary.table_path}",
            err=True,
        )
    if summary.n_failed or len(summary.outcomes) < len(inputs):
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
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Output ACC1B file (.asc/.txt, .gz to compress); truth goes to <out>.truth.json.",
)
@click.option("--seed", type=int, default=0, show_default=True)
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
@config_option
def simulate_grace(
    date: str,
    satellite: str,
    out: Path,
    seed: int,
    duration: float,
    gaps: int,
    flagged: float,
    noise: float,
) -> None:
    """Write a realistic synthetic GRACE/GRACE-FO ACC1B day file and its truth JSON."""
    from accal.errors import AccalError
    from accal.simulate.grace import write_simulated_grace

    try:
        truth_path = write_simulated_grace(
            out,
            date=date,
            satellite=satellite,
            seed=seed,
            duration=duration,
            n_gaps=gaps,
            flagged_fraction=flagged,
            noise=noise,
        )
    except AccalError as exc:
        _err(str(exc))
        sys.exit(1)
    click.echo(f"wrote {out} and {truth_path}", err=True)


from accal.cli_demod import budget, demod, design, simulate_gap  # noqa: E402

main.add_command(demod)
main.add_command(design)
main.add_command(budget)
simulate.add_command(simulate_gap, name="gap")

if __name__ == "__main__":  # pragma: no cover
    main()
