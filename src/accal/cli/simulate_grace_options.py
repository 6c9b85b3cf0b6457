"""The options of ``accal simulate grace`` (declarations only; the command is in
:mod:`accal.cli.simulate_grace`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from accal._cliutil import OutPath, config_option, option_stack

#: The options in the order ``accal simulate grace --help`` lists them (first = top).
_OPTIONS: list[Callable[[Any], Any]] = [
    click.option(
        "--date", "date", default="2005-01-01", show_default=True, help="UTC day (YYYY-MM-DD)."
    ),
    click.option(
        "--satellite", type=click.Choice(["A", "B", "C", "D"]), default="A", show_default=True
    ),
    click.option(
        "--out",
        "out",
        type=OutPath(dir_okay=False, path_type=Path),
        required=True,
        help="Output ACC1B file (.asc/.txt, .gz to compress); truth goes to <out>.truth.json.",
    ),
    click.option(
        "--seed",
        type=int,
        default=None,
        help="Random seed (default: derived from --date and --satellite, so every day "
        "differs and a day is the same on every machine).",
    ),
    click.option("--duration", type=float, default=86400.0, show_default=True, help="Seconds."),
    click.option("--gaps", type=int, default=0, show_default=True, help="Number of data gaps."),
    click.option(
        "--flagged",
        type=float,
        default=0.0,
        show_default=True,
        help="Fraction of samples flagged invalid.",
    ),
    click.option(
        "--noise",
        type=float,
        default=1e-10,
        show_default=True,
        help="Noise level [m/s^2/sqrt(Hz)] in the measurement band.",
    ),
    click.option(
        "--storm",
        is_flag=True,
        help="Add a geomagnetic storm (density x2-4 within hours, decaying).",
    ),
    click.option(
        "--thrusters",
        is_flag=True,
        help="Add thruster pulses (1e-8-1e-7 m/s^2, a few s, a few per hour) to the true "
        "signal and write them as a THR1B file beside --out.",
    ),
    click.option(
        "--effect",
        "effects",
        multiple=True,
        metavar="SPEC",
        help="Inject an instrument effect NAME:key=value,... into the raw reading "
        "(repeatable; the effects are listed above).",
    ),
    click.option(
        "--reference-out",
        "reference_out",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="Also write the reference: the true non-gravitational acceleration s*a_true "
        "plus the reference noise, as a table (for grace-bias --reference; .csv or Parquet).",
    ),
    click.option(
        "--reference-noise",
        "reference_noise",
        type=float,
        default=1e-9,
        show_default=True,
        metavar="LEVEL",
        help="Noise of the --reference-out table [m/s^2]: its RMS at orbit scales (periods "
        "over 1000 s); it rises at high frequency like a POD-derived acceleration (at 1e-9: "
        "ASD 3.2e-8 m/s^2/sqrt(Hz) up to 0.1 Hz, 1.4e-7 at 0.5 Hz). 0: a noise-free "
        "reference.",
    ),
    click.option(
        "--days",
        type=int,
        default=1,
        show_default=True,
        help="Simulate N consecutive days from --date as one arc (--out must contain the "
        "date, replaced by each day's; --seed S gives day k the seed S+k); the bias continues "
        "across the days and --reference-out gets one table covering all of them (for "
        "grace-bias --arc).",
    ),
    config_option,
]


#: Decorator attaching the options of ``simulate grace`` (and ``--config``) to its function.
simulate_grace_options = option_stack(_OPTIONS)
