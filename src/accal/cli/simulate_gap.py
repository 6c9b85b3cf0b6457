"""``accal simulate gap``: a synthetic rotating-platform run and its truth table.

The run is :func:`accal.pipeline_demod.write_simulated_gap`, imported when the
command runs (~0.3 s, not for ``accal --help``).
"""

from __future__ import annotations

from pathlib import Path

import click

from accal._cliutil import (
    CONTEXT_SETTINGS,
    OutPath,
    check_number,
    check_seed,
    config_option,
    fail,
    fs_option,
)
from accal.cli.limits import check_period_samples, check_run_size
from accal.errors import AccalError, ValidationError


@click.command(
    "gap",
    context_settings=CONTEXT_SETTINGS,
    short_help="Write a synthetic rotating-platform run and its truth table.",
)
@click.option("--days", type=float, default=1.0, show_default=True, help="Duration [day].")
@click.option("--tau", type=float, default=600.0, show_default=True, help="Modulation period [s].")
@click.option("--mask", type=float, default=200.0, show_default=True, help="Masking time [s].")
@fs_option
@click.option(
    "--out",
    type=OutPath(dir_okay=False, path_type=Path),
    required=True,
    help="Run file (.parquet or .csv); truth goes to <stem>.truth.<ext> next to it.",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--temperature-coupling",
    type=float,
    default=0.0,
    show_default=True,
    help="Bias sensitivity to temperature [m s^-2 K^-1].",
)
@click.option(
    "--quadratic", type=float, default=0.0, show_default=True, help="Quadratic factor k2 [s^2/m]."
)
@click.option(
    "--signal-amplitude",
    type=float,
    default=0.0,
    show_default=True,
    help="Amplitude of a sinusoid on a_Y (sin) and a_Z (cos) [m/s^2].",
)
@click.option(
    "--signal-period", type=float, default=86400.0, show_default=True, help="Its period [s]."
)
@click.option("--with-x", is_flag=True, help="Also write an m_x column.")
@config_option
def simulate_gap(
    days: float,
    tau: float,
    mask: float,
    fs: float,
    out: Path,
    seed: int,
    temperature_coupling: float,
    quadratic: float,
    signal_amplitude: float,
    signal_period: float,
    with_x: bool,
) -> None:
    """Write a synthetic rotating-platform run (MicroSTAR noise) and its truth table."""
    from accal.pipeline_demod import write_simulated_gap

    check_seed("--seed", seed)
    check_number("--days", days, low=0, low_open=True, unit=" days", what="duration")
    check_number("--tau", tau, low=0, low_open=True, unit=" s", what="modulation period")
    check_number("--fs", fs, low=0, low_open=True, unit=" Hz", what="sampling frequency")
    for name, value in (
        ("--temperature-coupling", temperature_coupling),
        ("--quadratic", quadratic),
        ("--signal-amplitude", signal_amplitude),
    ):
        check_number(name, value)
    check_number("--signal-period", signal_period, low=0, low_open=True, unit=" s")
    check_period_samples(tau, fs)
    check_run_size(days, fs)
    try:
        run, truth = write_simulated_gap(
            out,
            days=days,
            tau=tau,
            mask=mask,
            fs=fs,
            seed=seed,
            temperature_coupling=temperature_coupling,
            quadratic=quadratic,
            signal_amplitude=signal_amplitude,
            signal_period=signal_period,
            with_x=with_x,
        )
    except ValidationError as exc:  # option values (the message names the option)
        raise click.UsageError(str(exc)) from None
    except AccalError as exc:
        fail(str(exc))
    click.echo(f"wrote {run} and {truth}", err=True)
