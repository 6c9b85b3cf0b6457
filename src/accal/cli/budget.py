"""``accal budget``: uncertainty budget of the rotating-platform measurement.

The budget is :func:`accal.pipeline_demod.budget_report`, imported when the
command runs (~0.3 s, not for ``accal --help``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from accal._cliutil import CONTEXT_SETTINGS, check_number, config_option, fs_option, usage_fail
from accal.cli.limits import check_budget_size
from accal.errors import AccalError

PSD_HELP = "Noise PSD: 'microstar' (eq. 1 of Lenoir et al. 2013) or a CSV/Parquet table with columns f [Hz], S [m^2 s^-4 Hz^-1] (two-sided)."


@click.command(
    "budget",
    context_settings=CONTEXT_SETTINGS,
    short_help="Uncertainty budget: Rd[k] and σ over T for τ, or the optimal τ.",
)
@click.option("--mask", type=float, required=True, help="Masking time TM per period [s].")
@click.option("--tau", type=float, default=None, help="Modulation period [s]; scan τ if omitted.")
@fs_option
@click.option("--method", type=click.Choice(["ls", "gls"]), default="ls", show_default=True)
@click.option(
    "--integration", type=float, default=3600.0, show_default=True, help="Integration time T [s]."
)
@click.option(
    "--psd", default="microstar", show_default=True, metavar="microstar|FILE", help=PSD_HELP
)
@click.option(
    "--taus",
    default=None,
    metavar="START:STOP:STEP",
    help="τ values to scan [s] (default TM+40 to 3600 by 40).",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@click.option(
    "--plot", type=click.Path(dir_okay=False, path_type=Path), default=None, help="Write a PNG."
)
@config_option
def budget(
    mask: float,
    tau: float | None,
    fs: float,
    method: str,
    integration: float,
    psd: str,
    taus: str | None,
    as_json: bool,
    plot: Path | None,
) -> None:
    """Uncertainty budget: Rd[k] and σ over T for τ, or the optimal τ (Fig. 6)."""
    from accal.pipeline_demod import budget_report, load_psd, plot_budget

    check_number("--mask", mask, low=0, low_open=True, unit=" s", what="masking time TM")
    check_number(
        "--tau", tau, low=mask, low_open=True, unit=" s", what="modulation period",
        why="longer than --mask",
    )  # fmt: skip
    check_number("--fs", fs, low=0, low_open=True, unit=" Hz", what="sampling frequency")
    check_number(
        "--integration", integration, low=0, low_open=True, unit=" s", what="integration time T"
    )
    try:  # a missing or bad --psd table is a usage error (exit 2), one line naming the file
        load_psd(psd)
    except AccalError as exc:
        usage_fail(str(exc))
    check_budget_size(mask, tau, fs, method, integration, taus)
    try:  # every value is an option's (the --psd table is read): errors are usage errors
        rep = budget_report(
            mask, tau=tau, fs=fs, method=method, integration=integration, psd=psd, taus=taus
        )
    except AccalError as exc:
        usage_fail(str(exc))
    if plot is not None:
        plot_budget(rep, plot)
    if as_json:
        click.echo(json.dumps(rep))
        return
    for line in _report_lines(rep, mask, method, integration):
        click.echo(line)
    if plot is not None:
        click.echo(f"wrote {plot}", err=True)


def _report_lines(rep: dict[str, Any], mask: float, method: str, integration: float) -> list[str]:
    """The printed budget: the τ scan (if any), Rd[0..5] and σ over T."""
    lines = []
    if "tau_opt" in rep:
        lines.append(f"{'tau [s]':>9} {'sigma [m/s^2]':>14}")
        for t, s in zip(rep["tau"], rep["sigma"], strict=True):
            mark = "  <- tau_opt" if t == rep["tau_opt"] else ""
            lines.append(f"{t:>9g} {s:>14.4e}{mark}")
        lines.append(f"tau_opt = {rep['tau_opt']:g} s (TM = {mask:g} s, T = {integration:g} s)")
    lines.append(
        f"tau = {rep['tau_budget']:g} s, TM = {mask:g} s, {method.upper()}, pattern {rep['kind']}"
    )
    lines += [f"Rd[{k}] = {r:.4e} m^2/s^4" for k, r in enumerate(rep["Rd"][:6])]
    # σ is of whole periods: say how many and how long they are (QA: T = 100 s with
    # tau 600 s printed "(1 periods)", the σ of one 600 s period under T = 100 s)
    n_per, tau_b = int(rep["n_periods"]), float(rep["tau_budget"])
    span = f"{n_per} period{'' if n_per == 1 else 's'} of {tau_b:g} s"
    if abs(n_per * tau_b - integration) > 1e-9 * integration:
        span += f" = {n_per * tau_b:g} s, the whole periods nearest T"
    lines.append(
        f"sigma over T = {integration:g} s ({span}): {rep['sigma_T']:.4e} m/s^2 "
        f"(independent periods: {rep['sigma_T_indep']:.4e})"
    )
    return lines
