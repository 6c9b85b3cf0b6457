"""The options of ``accal demod`` (declarations only; the command is in :mod:`accal.cli.demod`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from accal._cliutil import (
    OutPath,
    alpha_option,
    config_option,
    format_option,
    option_stack,
    plots_option,
)
from accal.cli.batch_options import batch_options

DEMOD_PSD_HELP = (
    "Noise PSD behind sigma, Rd[k] and GLS: 'auto' estimates it from the run's own residual "
    "(runs of at least 24 usable periods; shorter ones use eq. 1, with a warning); "
    "'microstar' (eq. 1 of Lenoir et al. 2013) or a CSV/Parquet table with columns f [Hz], "
    "S [m^2 s^-4 Hz^-1] (two-sided) give the a-priori budget.  Both levels are reported; "
    "a factor > 2 between them is a warning."
)

#: The options in the order ``accal demod --help`` lists them (first = top).
_OPTIONS: list[Callable[[Any], Any]] = [
    click.option("--tau", type=float, required=True, help="Modulation period τ [s]."),
    click.option(
        "--mask", type=float, required=True, help="Nominal masking time TM per period [s]."
    ),
    click.option(
        "--out",
        type=OutPath(file_okay=False, path_type=Path),
        required=True,
        help="Output directory (created).",
    ),
    click.option("--method", type=click.Choice(["ls", "gls"]), default="ls", show_default=True),
    click.option(
        "--psd",
        default="auto",
        show_default=True,
        metavar="auto|microstar|FILE",
        help=DEMOD_PSD_HELP,
    ),
    click.option(
        "--signal-model", type=click.Choice(["mean", "affine"]), default="mean", show_default=True
    ),
    click.option(
        "--bias-model",
        default="affine",
        show_default=True,
        metavar="affine|affine+CHANNEL",
        help="Bias basis: affine, optionally plus auxiliary channels of the run file "
        "(affine+temperature).",
    ),
    format_option(),
    click.option(
        "--sinusoid-period",
        type=float,
        default=None,
        help="Fit α cos + β sin of this period [s] to the per-period values (eq. 24).",
    ),
    click.option(
        "--integration",
        type=float,
        default=10800.0,
        show_default=True,
        help="Integration time of the standard σ(T) in the summary [s].",
    ),
    click.option(
        "--sinusoid-constant",
        is_flag=True,
        help="Add a constant term to the sinusoid fit (α cos + β sin + c), so a non-zero mean "
        "does not leak into α, β.",
    ),
    click.option(
        "--resample",
        is_flag=True,
        help="Resample irregular sampling onto a uniform grid: linear interpolation within "
        "continuous stretches; gaps longer than --gap-factor steps stay gaps (masked).",
    ),
    click.option(
        "--gap-factor",
        type=float,
        default=2.0,
        show_default=True,
        help="With --resample: a step longer than this many grid steps is a gap.",
    ),
    click.option(
        "--rest-tol",
        type=float,
        default=1e-9,
        show_default=True,
        metavar="RAD",
        help="θ is at rest where its first and second differences are within this [rad]; "
        "raise it for an angle readout that is noisy at rest.",
    ),
    click.option(
        "--chunk-size",
        "chunk_rows",
        type=click.IntRange(min=16),
        default=1 << 18,  # accal.pipeline_demod.CHUNK_ROWS (not imported here: start-up time)
        show_default=True,
        metavar="ROWS",
        help="Rows read at a time (bounds the memory; results do not depend on it).",
    ),
    batch_options("runs"),  # -j, --scheduler, --force, --checksum
    click.option(
        "--close-loop",
        is_flag=True,
        help="Trace the residual to effects the model lacks (steps, auxiliary channels, angle "
        "offset, intra-period shape, ...), add them, refit: OUT/closure.json/.md; "
        "periods then hold the extended model (reads each run whole).",
    ),
    alpha_option,
    plots_option,
    click.option(
        "--quiet",
        "-q",
        is_flag=True,
        help="No progress bar, summary lines or warnings (in accal.log).",
    ),
    config_option,
]


#: Decorator attaching the options of ``demod`` (and ``--config``) to its function.
demod_options = option_stack(_OPTIONS)
