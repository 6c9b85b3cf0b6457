"""``accal table``: print or export the cumulative bias/drift table of an output directory.

The rows are selected, written and formatted by :mod:`accal.products.table_view`,
imported when the command runs (pandas and accal.pipeline: ~0.8 s, not for
``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from accal._cliutil import err, is_date, option_stack, usage_fail
from accal.errors import AccalError

#: The row selection of ``accal table`` and ``accal plot``.
ROW_OPTIONS = option_stack(
    [
        click.option(
            "--satellite", "satellites", multiple=True, help="Keep these satellites (repeatable)."
        ),
        click.option("--start", default=None, metavar="YYYY-MM-DD", help="First date kept."),
        click.option("--end", default=None, metavar="YYYY-MM-DD", help="Last date kept."),
        click.option(
            "--method",
            "methods",
            multiple=True,
            type=click.Choice(["wavelet", "lsq"], case_sensitive=False),
            help="Keep these methods (repeatable).",
        ),
        click.option(
            "--axis",
            "axes",
            multiple=True,
            type=click.Choice(["x", "y", "z"], case_sensitive=False),
            help="Keep these axes (repeatable).",
        ),
        click.option(
            "--status",
            "statuses",
            multiple=True,
            type=click.Choice(["nominal", "degraded", "transplant", "off"]),
            help="Keep days of these statuses (repeatable), e.g. --status nominal.",
        ),
    ]
)


def selected_rows(path: Path, df: Any, **selection: Any) -> Any:
    """The rows of a bias_drift table ``df`` (read from ``path``) that :data:`ROW_OPTIONS`
    keep; a malformed date or an unknown satellite is a usage error."""
    from accal.products import table_view

    start, end, satellites = selection["start"], selection["end"], selection["satellites"]
    for d in (start, end):
        if d is not None and not is_date(d):
            raise click.BadParameter(f"expected YYYY-MM-DD, got {d!r}")
    if start and end and start > end:
        raise click.BadParameter(f"--start {start} is after --end {end}")
    unknown = table_view.unknown_satellites(df, satellites) if satellites else []
    if unknown:  # a typo would otherwise match nothing, silently
        held = table_view.held_satellites(df)
        usage_fail(
            f"--satellite {unknown[0]!r} is not in {path} (it holds {', '.join(held) or 'no rows'})"
        )
    return table_view.select_rows(df, **selection)


def periods_filter_message(path: Path) -> str:
    """The usage error of a row option given for an ``accal demod`` periods table."""
    return (
        f"{path} is the periods table of accal demod: --satellite, --start, --end, "
        "--method, --axis and --status select rows of a bias_drift table"
    )


@click.command("table", short_help="Print or export the bias/drift table of an output directory.")
@click.argument("directory", type=click.Path(file_okay=False, exists=True, path_type=Path))
@ROW_OPTIONS
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
    help="Write the rows to FILE (.csv, .parquet or .nc: CF netCDF 3; atomic) instead of "
    "printing them.",
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
    """Print or export the cumulative bias/drift table of an output DIRECTORY.

    In an ``accal demod`` output directory: its periods table, whole.
    """
    from accal.products import table_view

    try:
        path, df = table_view.load(directory, periods=True)
        units = df.attrs.get("units")
        filters = satellites or start or end or methods or axes or statuses
        if table_view.is_periods(path) and filters:
            usage_fail(periods_filter_message(path))
        df = selected_rows(
            path, df, satellites=satellites, start=start, end=end, methods=methods, axes=axes,
            statuses=statuses,
        )  # fmt: skip
        known = table_view.column_names(df)
        cols = [c.strip() for c in columns.split(",") if c.strip()] if columns else []
        if columns and not cols:
            usage_fail(
                f"--columns names no column, got {columns!r}; give a comma-separated "
                f"list of {', '.join(known)}"
            )
        unknown = [c for c in cols if c not in known]
        if unknown:
            raise click.BadParameter(f"unknown columns {unknown}; known: {known}")
        if export is not None:
            if export.suffix.lower() not in table_view.EXPORT_FORMATS:
                raise click.BadParameter("--export FILE must end in .csv, .parquet or .nc")
            problem = table_view.export_conflict(export)
            if problem:
                usage_fail(problem)
            table_view.export_rows(df, export, path, cols, units)
            click.echo(f"wrote {len(df)} rows to {export}", err=True)
            return
        click.echo(table_view.table_text(df, cols))
    except AccalError as exc:
        err(str(exc))
        sys.exit(1)
