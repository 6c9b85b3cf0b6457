"""``accal design``: a θ(t) calibration pattern for the rotating platform.

The pattern is made and written by :func:`accal.pipeline_demod.write_design`,
imported when the command runs (~0.3 s, not for ``accal --help``).
"""

from __future__ import annotations

from pathlib import Path

import click

from accal._cliutil import (
    CONTEXT_SETTINGS,
    OutPath,
    check_number,
    config_option,
    fs_option,
    usage_fail,
)
from accal.cli.limits import check_design_size, check_period_samples
from accal.errors import AccalError


@click.command(
    "design",
    context_settings=CONTEXT_SETTINGS,
    short_help="Design a calibration pattern θ(t); print the eq. 16 residuals.",
)
@click.option("--tau", type=float, required=True, help="Modulation period τ [s].")
@click.option("--mask", type=float, required=True, help="Total rotation time per period TM [s].")
@fs_option
@click.option(
    "--signal-model",
    type=click.Choice(["mean", "affine"]),
    default="mean",
    show_default=True,
    help="Conditions that must vanish: Σc, Σct (mean); also Σct² (affine).",
)
@click.option(
    "--kind",
    type=click.Choice(["fig2", "fig1"]),
    default="fig2",
    show_default=True,
    help="Pattern: four rotations (Fig. 2) or two (Fig. 1a).",
)
@click.option("--periods", type=click.IntRange(min=1), default=1, show_default=True)
@click.option(
    "--out",
    type=OutPath(dir_okay=False, path_type=Path),
    required=True,
    help="θ(t) table; .csv → CSV, else Parquet.",
)
@config_option
def design(
    tau: float, mask: float, fs: float, signal_model: str, kind: str, periods: int, out: Path
) -> None:
    """Design a calibration pattern θ(t) and print the eq. 16 residuals.

    Prints Σc, Σct, Σct² (normalised, c = cos θ on the samples used) for the
    discrete rest mask (what demod uses) and for the nominal one.  The sin
    conditions vanish identically: at rest θ is 0 or π.
    """
    from accal.pipeline_demod import write_design

    check_number("--tau", tau, low=0, low_open=True, unit=" s", what="modulation period")
    check_number("--fs", fs, low=0, low_open=True, unit=" Hz", what="sampling frequency")
    check_number(
        "--mask", mask, low=0, high=tau, low_open=True, high_open=True, unit=" s",
        what="total rotation time TM", why="shorter than --tau",
    )  # fmt: skip
    check_period_samples(tau, fs)
    check_design_size(periods, tau, fs)
    try:
        path, pat = write_design(out, tau, mask, fs, kind=kind, periods=periods)
    except AccalError as exc:
        usage_fail(str(exc))
    need = ("sum_c", "sum_ct") + (("sum_ct2",) if signal_model == "affine" else ())
    click.echo(
        f"pattern {pat.kind}: segments [s] "
        + " | ".join(
            f"{'R' if a is None else ('+' if a == 0 else '-')}{n / fs:g}" for n, a in pat.segments
        )
    )
    click.echo(f"{'condition':<10} {'discrete':>12} {'nominal':>12}  required ({signal_model})")
    for k in ("sum_c", "sum_ct", "sum_ct2"):
        r, rn = pat.residuals[k], pat.residuals_nominal[k]
        flag = ("ok" if abs(r) < 1e-9 else "NOT ZERO") if k in need else "-"
        click.echo(f"{k:<10} {r:>12.3e} {rn:>12.3e}  {flag}")
    click.echo(f"wrote {path} ({periods} period(s), {pat.q * periods} samples)", err=True)
