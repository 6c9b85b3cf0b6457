"""``accal plot``: an output directory's table over time, as a PNG.

An ``accal grace-bias`` directory: bias and drift per axis and day; an ``accal demod``
directory: a_Y and a_Z per period.

The library imports (pandas, matplotlib, accal.pipeline) happen when the command
runs, as for ``accal table`` (not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from accal._cliutil import OutPath, err, usage_fail
from accal.cli.table import ROW_OPTIONS, periods_filter_message, selected_rows
from accal.errors import AccalError


@click.command(
    "plot", short_help="Plot an output directory's bias and drift (or periods) over time."
)
@click.argument("directory", type=click.Path(exists=True, file_okay=False, path_type=Path))
@ROW_OPTIONS
@click.option(
    "--out", "out", type=OutPath(dir_okay=False, path_type=Path), default=None,
    help="PNG to write [DIRECTORY/bias_drift.png; demod: DIRECTORY/periods.png].",
)  # fmt: skip
def plot_cmd(
    directory: Path,
    satellites: tuple[str, ...],
    start: str | None,
    end: str | None,
    methods: tuple[str, ...],
    axes: tuple[str, ...],
    statuses: tuple[str, ...],
    out: Path | None,
) -> None:
    """Plot bias and drift per axis against the day (UTC), ± 1σ, one series per
    satellite and method, from the cumulative table of an output DIRECTORY.

    In an ``accal demod`` output directory: a_Y and a_Z of every period against its
    mid-time (UTC), ± 1σ, one series per run.
    """
    from accal.products import table_view
    from accal.products.archive_plot import plot_bias_drift, plot_periods

    if out is not None:  # QA: a user's notes.txt replaced by a PNG, /nonexist created
        if out.suffix.lower() != ".png":
            usage_fail(f"--out {out}: the plot is a PNG; give a file name ending in .png")
        if not out.parent.is_dir():
            usage_fail(f"--out {out}: directory {out.parent} does not exist")
    try:
        path, df = table_view.load(directory, periods=True)
        if table_view.is_periods(path):
            if satellites or start or end or methods or axes or statuses:
                usage_fail(periods_filter_message(path))
            target = out if out is not None else directory / "periods.png"
            plot_periods(df, target, source=str(path))
            click.echo(f"wrote {target} ({len(df)} periods)", err=True)
            return
        df = selected_rows(
            path, df, satellites=satellites, start=start, end=end, methods=methods, axes=axes,
            statuses=statuses,
        )  # fmt: skip
        target = out if out is not None else directory / "bias_drift.png"
        plot_bias_drift(df, target, source=str(path))
        click.echo(f"wrote {target} ({len(df)} rows)", err=True)
    except AccalError as exc:
        err(str(exc))
        sys.exit(1)
