"""``accal plot``: bias and drift of an output directory's table over time, as a PNG.

The library imports (pandas, matplotlib, accal.pipeline) happen when the command
runs, as for ``accal table`` (not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from accal._cliutil import OutPath, err, is_date, usage_fail


@click.command("plot", short_help="Plot the bias and drift of an output directory over time.")
@click.argument("directory", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--satellite", "satellites", multiple=True, help="Keep these satellites (repeatable)."
)
@click.option("--start", default=None, metavar="YYYY-MM-DD", help="First date kept.")
@click.option("--end", default=None, metavar="YYYY-MM-DD", help="Last date kept.")
@click.option(
    "--method", "methods", multiple=True, type=click.Choice(["wavelet", "lsq"]),
    help="Keep these methods (repeatable).",
)  # fmt: skip
@click.option(
    "--axis", "axes", multiple=True, type=click.Choice(["x", "y", "z"]),
    help="Keep these axes (repeatable).",
)  # fmt: skip
@click.option(
    "--status", "statuses", multiple=True,
    type=click.Choice(["nominal", "degraded", "transplant", "off"]),
    help="Keep days of these statuses (repeatable), e.g. --status nominal.",
)  # fmt: skip
@click.option(
    "--out", "out", type=OutPath(dir_okay=False, path_type=Path), default=None,
    help="PNG to write [DIRECTORY/bias_drift.png].",
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
    satellite and method, from the cumulative table of an output DIRECTORY."""
    from accal.errors import AccalError
    from accal.products import table_view
    from accal.products.archive_plot import plot_bias_drift

    try:
        path, df = table_view.load(directory)
        for d in (start, end):
            if d is not None and not is_date(d):
                raise click.BadParameter(f"expected YYYY-MM-DD, got {d!r}")
        unknown = table_view.unknown_satellites(df, satellites)
        if unknown:
            usage_fail(
                f"--satellite {unknown[0]!r} is not in {path} (it holds "
                f"{', '.join(table_view.held_satellites(df)) or 'no rows'})"
            )
        df = table_view.select_rows(
            df, satellites=satellites, start=start, end=end, methods=methods, axes=axes,
            statuses=statuses,
        )  # fmt: skip
        target = out if out is not None else directory / "bias_drift.png"
        plot_bias_drift(df, target, source=str(path))
        click.echo(f"wrote {target} ({len(df)} rows)", err=True)
    except AccalError as exc:
        err(str(exc))
        sys.exit(1)
