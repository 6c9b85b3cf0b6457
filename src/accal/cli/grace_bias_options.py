"""The options of ``accal grace-bias`` (declarations only; the command is in
:mod:`accal.cli.grace_bias`) and the parsers of its two structured values."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from accal._cliutil import (
    OutPath,
    alpha_option,
    aux_option,
    config_option,
    format_option,
    option_stack,
    plots_option,
    quiet_option,
)
from accal.cli.batch_options import batch_options


def parse_margins(text: str) -> tuple[float, float] | None:
    """``--thruster-margins``: ``BEFORE,AFTER`` seconds, or None for ``off``.

    Parameters
    ----------
    text : str
        The option value.

    Returns
    -------
    tuple of 2 float or None
        Seconds left out before and after each firing; None: no firing left out.

    Raises
    ------
    click.BadParameter
        Not two numbers separated by a comma, nor ``off``.
    """
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


def parse_column_map(items: tuple[str, ...]) -> dict[str, str]:
    """``--column AXIS=COLUMN`` values as ``{axis: column}``.

    Parameters
    ----------
    items : tuple of str
        The repeated option's values.

    Returns
    -------
    dict
        Axis (``x``, ``y``, ``z``), or ``time``, to table column; a later item for an
        axis wins.

    Raises
    ------
    click.BadParameter
        An item that is not ``AXIS=COLUMN`` with AXIS in x|y|z|time.
    """
    colmap = {}
    for item in items:
        ax, sep, col = item.partition("=")
        if not sep or ax not in ("x", "y", "z", "time") or not col:
            raise click.BadParameter(
                f"expected AXIS=COLUMN with AXIS in x|y|z|time, got {item!r}",
                param_hint="--column",
            )
        colmap[ax] = col
    return colmap


_FILE = click.Path(dir_okay=False, path_type=Path)

#: The options in the order ``accal grace-bias --help`` lists them (first = top).
_OPTIONS: list[Callable[[Any], Any]] = [
    click.option(
        "--out",
        "out",
        type=OutPath(file_okay=False, path_type=Path),
        required=True,
        help="Output directory (created).",
    ),
    click.option(
        "--method",
        type=click.Choice(["wavelet", "lsq", "both"]),
        default="wavelet",
        show_default=True,
        help="Estimator; with 'both' the wavelet fit calibrates the series.",
    ),
    format_option("Output format."),
    click.option(
        "--order",
        type=click.Choice(["1", "2"]),
        default="1",
        show_default=True,
        help="Trend order: 1 = bias + drift, 2 = + quadratic term.",
    ),
    click.option(
        "--scale",
        default=None,
        help="Scale applied to the calibrated series: 'tn02' (GRACE TN-02 a-priori) or "
        "'sx,sy,sz'; a_cal = scale*(a_raw - trend).  With --reference also 'fit' (one scale "
        "per axis) or 'fit-matrix' (3x3 scale matrix), estimated with the bias.",
    ),
    click.option(
        "--reference",
        type=_FILE,
        default=None,
        help="Reference accelerations (table or L1B); the fit uses raw - reference.",
    ),
    click.option(
        "--bias-basis",
        default=None,
        metavar="BASIS",
        help="With --reference: fit a_ref = S (a_raw - b(t)) by AR-weighted least squares, "
        "the bias b on poly0|poly1|poly2|spline:STEP (e.g. spline:6h); method 'reference' "
        "(default poly1 when only --scale fit is given).",
    ),
    click.option(
        "--reference-frame",
        type=click.Choice(["srf", "inertial"]),
        default="srf",
        show_default=True,
        help="Frame of --reference; 'inertial' is rotated into the SRF with the SCA1B "
        "attitude (--attitude, or the SCA1B file beside the input).",
    ),
    click.option(
        "--attitude",
        type=_FILE,
        default=None,
        help="SCA1B star-camera file for --reference-frame inertial.",
    ),
    click.option(
        "--arc",
        default="day",
        show_default=True,
        metavar="day|Nd|month",
        help="With the reference fit: fit up to N consecutive days (e.g. 30d) or a calendar "
        "month of one satellite together (one bias spline across the days, one scale); "
        "a missing day starts a new arc.",
    ),
    click.option(
        "--thrusters",
        type=_FILE,
        default=None,
        help="THR1B file whose firings the reference fit leaves out (default: the THR1B "
        "file beside the input, if any).",
    ),
    click.option(
        "--thruster-margins",
        default="0.1,0.7",
        show_default=True,
        metavar="BEFORE,AFTER",
        help="Seconds left out before and after each firing (GROOPS's values), or 'off'.",
    ),
    click.option(
        "--column",
        "columns",
        multiple=True,
        metavar="AXIS=COLUMN",
        help="Map a table column to an axis, e.g. --column x=a_cal_x, or name the time "
        "column, --column time=t (repeatable; for table inputs and a table --reference).",
    ),
    click.option(
        "--input-format",
        type=click.Choice(["grace-l1b", "table"]),
        default=None,
        help="Force the input format (default: sniffed from the content).",
    ),
    click.option(
        "--keep-flagged", is_flag=True, help="Use samples the quality flags mark invalid."
    ),
    click.option(
        "--recursive",
        "-r",
        is_flag=True,
        help="Take the files of directory inputs and their sub-directories.",
    ),
    click.option(
        "--include",
        "include",
        multiple=True,
        metavar="PATTERN",
        help="Names taken from directories (repeatable; default: *ACC1B_* and *ACT1B_*).",
    ),
    batch_options("inputs"),  # -j, --scheduler, --force, --checksum
    click.option(
        "--close-loop",
        is_flag=True,
        help="Analyse the residual, add the effects the model lacks, refit (closure.json/md).",
    ),
    aux_option,
    plots_option,
    click.option(
        "--truth",
        type=_FILE,
        default=None,
        help="Truth JSON of a simulation: --close-loop (implied) reports the true error "
        "before/after.",
    ),
    alpha_option,
    click.option(
        "--degraded-days",
        type=click.Path(dir_okay=False, exists=True, path_type=Path),
        default=None,
        help="TOML/YAML table of degraded/transplant/off periods, ahead of the built-in one.",
    ),
    click.option(
        "--pool-days",
        type=click.IntRange(min=0),
        default=0,
        show_default=True,
        metavar="N",
        help="Sigmas from a noise model fitted to N adjacent days together (archives; noise "
        "correlated over hours needs it; >= 2, 8 recommended; 0: each day's own estimate).",
    ),
    click.option(
        "--keep-going/--fail-fast",
        default=True,
        show_default=True,
        help="Go on with the other inputs after a failure (--fail-fast: stop at the first, "
        "running the inputs one at a time, in order).",
    ),
    quiet_option,
    config_option,
]


#: Decorator attaching the options of ``grace-bias`` (and ``--config``) to its function.
grace_bias_options = option_stack(_OPTIONS)
