"""Commands of the rotating-platform side: ``demod``, ``design``, ``budget``, ``simulate gap``.

Thin, like :mod:`accal.cli`: parse options, call :mod:`accal.pipeline_demod`, map
errors to exit codes (0 all inputs processed, 1 bad input, 2 usage) and one-line
messages ``accal: FILE[:LINE]: what is wrong``.  This module does not import
:mod:`accal.cli` at import time (``cli.py`` registers these commands), so either
module can be imported first.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from accal._cliutil import (
    OutPath,
    alpha_option,
    check_number,
    check_seed,
    config_option,
    plots_option,
)
from accal._cliutil import err as _err
from accal._cliutil import fail as _fail
from accal._cliutil import fmt_number as _g
from accal._cliutil import progress as _progress
from accal._cliutil import usage_fail as _usage_fail

CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"], "max_content_width": 100}

# Size caps of the commands that build arrays from option values alone (a bad value
# is a usage error saying the cap, not a MemoryError or a run that never ends).
#: Samples per modulation period (τ·fs) for design, budget and simulate gap:
#: designing a pattern costs ~(τ·fs)² (24,000 samples: ~10 s; 60,000: ~25 s).
MAX_PERIOD_SAMPLES = 50_000
#: Rows of a ``design`` table (periods·τ·fs): 1e7 rows take ~2 s and ~0.5 GB.
MAX_DESIGN_SAMPLES = 10_000_000
#: τ values of a ``budget --taus`` scan (each designs a pattern: ~5 ms at 1 Hz).
MAX_SCAN_TAUS = 10_000
#: LS budget: noise samples of the lag structure function, ~(T + τ)·fs
#: (1e6: ~1.5 min, ~1 GB).
MAX_BUDGET_SAMPLES = 1_000_000
#: GLS budget: entries of the (P·τ·fs) x P design matrix, P = 2·T/τ + 4 periods
#: (~32 bytes of memory each: 5e7 is ~1.6 GB).
MAX_GLS_ENTRIES = 50_000_000
#: Samples of a ``simulate gap`` run (1e8: about 3 years at 1 Hz, a few GB of file).
MAX_RUN_SAMPLES = 100_000_000


def _check_period_samples(tau: float, fs: float, option: str = "--tau") -> None:
    """Usage error unless ``tau·fs <= MAX_PERIOD_SAMPLES`` (τ [s], fs [Hz] both finite)."""
    if tau * fs > MAX_PERIOD_SAMPLES:
        _usage_fail(
            f"{option} {_g(tau)} s at --fs {_g(fs)} Hz is {_g(tau * fs)} samples per "
            f"modulation period; at most {MAX_PERIOD_SAMPLES} (tau·fs) are allowed"
        )


PSD_HELP = "Noise PSD: 'microstar' (eq. 1 of Lenoir et al. 2013) or a CSV/Parquet table with columns f [Hz], S [m^2 s^-4 Hz^-1] (two-sided)."
DEMOD_PSD_HELP = (
    "Noise PSD behind sigma, Rd[k] and GLS: 'auto' estimates it from the run's own residual "
    "(runs of at least 24 usable periods; shorter ones use eq. 1, with a warning); "
    "'microstar' (eq. 1 of Lenoir et al. 2013) or a CSV/Parquet table with columns f [Hz], "
    "S [m^2 s^-4 Hz^-1] (two-sided) give the a-priori budget.  Both levels are reported; "
    "a factor > 2 between them is a warning."
)


@click.command("demod", context_settings=CONTEXT_SETTINGS)
@click.argument("runs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--tau", type=float, required=True, help="Modulation period τ [s].")
@click.option("--mask", type=float, required=True, help="Nominal masking time TM per period [s].")
@click.option(
    "--out",
    type=OutPath(file_okay=False, path_type=Path),
    required=True,
    help="Output directory (created).",
)
@click.option("--method", type=click.Choice(["ls", "gls"]), default="ls", show_default=True)
@click.option(
    "--psd", default="auto", show_default=True, metavar="auto|microstar|FILE", help=DEMOD_PSD_HELP
)
@click.option(
    "--signal-model", type=click.Choice(["mean", "affine"]), default="mean", show_default=True
)
@click.option(
    "--bias-model",
    default="affine",
    show_default=True,
    metavar="affine|affine+CHANNEL",
    help="Bias basis: affine, optionally plus auxiliary channels of the run file (affine+temperature).",
)
@click.option(
    "--format", "fmt", type=click.Choice(["parquet", "csv"]), default="parquet", show_default=True
)
@click.option(
    "--sinusoid-period",
    type=float,
    default=None,
    help="Fit α cos + β sin of this period [s] to the per-period values (eq. 24).",
)
@click.option(
    "--integration",
    type=float,
    default=10800.0,
    show_default=True,
    help="Integration time of the standard σ(T) in the summary [s].",
)
@click.option(
    "--sinusoid-constant",
    is_flag=True,
    help="Add a constant term to the sinusoid fit (α cos + β sin + c), so a non-zero mean "
    "does not leak into α, β.",
)
@click.option(
    "--resample",
    is_flag=True,
    help="Resample irregular sampling onto a uniform grid: linear interpolation within "
    "continuous stretches; gaps longer than --gap-factor steps stay gaps (masked).",
)
@click.option(
    "--gap-factor",
    type=float,
    default=2.0,
    show_default=True,
    help="With --resample: a step longer than this many grid steps is a gap.",
)
@click.option(
    "--rest-tol",
    type=float,
    default=1e-9,
    show_default=True,
    metavar="RAD",
    help="θ is at rest where its first and second differences are within this [rad]; "
    "raise it for an angle readout that is noisy at rest.",
)
@click.option(
    "--chunk-size",
    "chunk_rows",
    type=click.IntRange(min=16),
    default=1 << 18,  # accal.pipeline_demod.CHUNK_ROWS (not imported here: start-up time)
    show_default=True,
    metavar="ROWS",
    help="Rows read at a time (bounds the memory; results do not depend on it).",
)
@click.option(
    "--close-loop",
    is_flag=True,
    help="Trace the residual to effects the model lacks (steps, auxiliary channels, angle "
    "offset, intra-period shape, ...), add them, refit: OUT/closure.json/.md; "
    "periods then hold the extended model (reads each run whole).",
)
@alpha_option
@plots_option
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary lines.")
@config_option
def demod(
    runs: tuple[Path, ...],
    tau: float,
    mask: float,
    out: Path,
    method: str,
    psd: str,
    signal_model: str,
    bias_model: str,
    fmt: str,
    sinusoid_period: float | None,
    integration: float,
    sinusoid_constant: bool,
    resample: bool,
    gap_factor: float,
    rest_tol: float,
    chunk_rows: int,
    close_loop: bool,
    alpha: float,
    plots: bool,
    quiet: bool,
) -> None:
    """Demodulate rotating-platform runs: unbiased a_Y, a_Z per modulation period.

    Every RUN's periods go into the cumulative OUT/periods.<fmt> (a `source`
    column; a re-run replaces that source's rows).  Summaries: OUT/summary.json
    and OUT/summary.md with one RUN, OUT/<stem>.summary.json/.md with several.
    """
    from accal.errors import AccalError
    from accal.pipeline_demod import (
        DemodOptions,
        check_output_format,
        load_psd,
        output_paths,
        run_demod,
    )

    try:
        output_paths(runs, out, fmt)  # a run given twice, colliding stems: usage errors
        opts = DemodOptions(
            tau=tau,
            mask=mask,
            method=method,
            psd=psd,
            signal_model=signal_model,
            bias_model=bias_model,
            fmt=fmt,
            sinusoid_period=sinusoid_period,
            sinusoid_constant=sinusoid_constant,
            resample=resample,
            gap_factor=gap_factor,
            rest_tol=rest_tol,
            integration=integration,
            chunk_rows=chunk_rows,
            close_loop=close_loop,
            alpha=alpha,
            plots=plots,
        )
    except AccalError as exc:
        raise click.UsageError(str(exc)) from None
    try:  # files named by the options: bad ones are usage errors too, one line naming the file
        check_output_format(out, fmt)
        noise = load_psd(psd)
    except AccalError as exc:
        _usage_fail(str(exc))
    _check_tau_vs_sampling(runs, opts)
    try:
        summary = run_demod(runs, out, opts, progress=_progress(quiet, "demod"), psd=noise)
    except AccalError as exc:
        _fail(str(exc))
    for o in summary.outcomes:
        if not o.ok:
            _err(o.message)
            continue
        for w in o.warnings:
            _err(f"{o.path}: warning: {w}")
        if not quiet:
            s = o.summary
            click.echo(
                f"{o.path}: {s['n_kept']}/{s['n_periods']} periods, "
                f"mean a_Y = {s['mean']['a_Y']:.4g}, a_Z = {s['mean']['a_Z']:.4g} "
                f"± {s['mean']['sigma']:.3g} m/s^2; Rd[0] = {s['Rd'][0]:.4g} m^2/s^4 -> "
                f"{o.outputs[0]}",
                err=True,
            )
            nz = s.get("noise") or {}
            if nz.get("level_apriori") is not None:
                src = "the run's residual" if nz["psd_used"] == "data" else nz["apriori"]
                ratio = nz.get("sigma_ratio")
                click.echo(
                    f"{o.path}: sigma from the PSD of {src}; noise at 2/tau "
                    f"{nz['level_apriori']:.3g} a-priori ({nz['apriori']}), "
                    + (
                        f"{nz['level_data']:.3g} data m/s^2/sqrt(Hz); sigma a-priori/data "
                        f"= {ratio:.3g}"
                        if ratio is not None
                        else "data: not estimated"
                    ),
                    err=True,
                )
            if "closure" in s:
                c = s["closure"]
                found = [
                    e["name"] + (f"({e['channel']})" if e.get("channel") else "")
                    for e in c["effects"]
                ]
                found += ["unexplained"] * len(c["unexplained"])
                click.echo(
                    f"{o.path}: closure: {', '.join(found) or 'nothing found'}; residual RMS "
                    f"{c['rms_before']:.3g} -> {c['rms_after']:.3g} m/s^2 (closure.md)",
                    err=True,
                )
    if not quiet:
        click.echo(
            f"accal demod: {summary.n_ok} ok, {summary.n_failed} failed in {summary.seconds:.2f} s",
            err=True,
        )
    if summary.n_failed:
        sys.exit(1)


def _check_tau_vs_sampling(runs: tuple[Path, ...], opts: object) -> None:
    """Usage error when ``--tau`` is shorter than one sample of every run (τ·fs < 1).

    The sampling step is found as :func:`accal.pipeline_demod.estimate` finds it
    (first chunk of the run).  A run that cannot be read is left to
    :func:`accal.pipeline_demod.run_demod`, which reports it as a failed run; so is
    a run too coarse for ``--tau`` beside others it suits (QA: one run in ms
    stopped a whole batch with exit 2): the option is wrong only when it suits none.

    Parameters
    ----------
    runs : tuple of Path
        The run files.
    opts : accal.pipeline_demod.DemodOptions
        The validated options (``tau`` [s], ``chunk_rows``, ``resample``).
    """
    import math

    from accal.io.rawlog import open_rawlog
    from accal.pipeline_demod import sampling_step

    tau = float(opts.tau)  # type: ignore[attr-defined]
    coarse = []
    for path in runs:
        try:
            stream = open_rawlog(path, rows=int(opts.chunk_rows))  # type: ignore[attr-defined]
            step = sampling_step(stream, opts)  # type: ignore[arg-type]
        except Exception:  # noqa: BLE001 (a bad run fails in run_demod, with its message)
            continue
        if not 0 < step < math.inf:
            continue
        if tau / step >= 1 - 1e-6:
            return  # --tau suits this run: the others fail on their own
        coarse.append((path, step))  # 0 samples per period; its "nearest" whole tau is 0
    if coarse:
        path, step = coarse[0]
        _usage_fail(
            f"--tau {_g(tau)} s is shorter than one sample of {path} (fs = {_g(1 / step)} "
            f"Hz): tau must be a whole number of samples, at least {_g(step)} s"
        )


@click.command("design", context_settings=CONTEXT_SETTINGS)
@click.option("--tau", type=float, required=True, help="Modulation period τ [s].")
@click.option("--mask", type=float, required=True, help="Total rotation time per period TM [s].")
@click.option("--fs", type=float, default=1.0, show_default=True, help="Sampling frequency [Hz].")
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
    from accal.errors import AccalError
    from accal.pipeline_demod import write_design

    check_number("--tau", tau, low=0, low_open=True, unit=" s", what="modulation period")
    check_number("--fs", fs, low=0, low_open=True, unit=" Hz", what="sampling frequency")
    check_number(
        "--mask", mask, low=0, high=tau, low_open=True, high_open=True, unit=" s",
        what="total rotation time TM", why="shorter than --tau",
    )  # fmt: skip
    _check_period_samples(tau, fs)
    if periods * tau * fs > MAX_DESIGN_SAMPLES:
        _usage_fail(
            f"--periods {periods} of --tau {_g(tau)} s at --fs {_g(fs)} Hz is "
            f"{_g(periods * tau * fs)} samples; at most {MAX_DESIGN_SAMPLES} are written"
        )
    try:
        path, pat = write_design(out, tau, mask, fs, kind=kind, periods=periods)
    except AccalError as exc:
        _usage_fail(str(exc))
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


@click.command("budget", context_settings=CONTEXT_SETTINGS)
@click.option("--mask", type=float, required=True, help="Masking time TM per period [s].")
@click.option("--tau", type=float, default=None, help="Modulation period [s]; scan τ if omitted.")
@click.option("--fs", type=float, default=1.0, show_default=True, help="Sampling frequency [Hz].")
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
    from accal.errors import AccalError
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
        _usage_fail(str(exc))
    _check_budget_size(mask, tau, fs, method, integration, taus)
    try:  # every value is an option's (the --psd table is read): errors are usage errors
        rep = budget_report(
            mask, tau=tau, fs=fs, method=method, integration=integration, psd=psd, taus=taus
        )
    except AccalError as exc:
        _usage_fail(str(exc))
    if plot is not None:
        plot_budget(rep, plot)
    if as_json:
        click.echo(json.dumps(rep))
        return
    if "tau_opt" in rep:
        click.echo(f"{'tau [s]':>9} {'sigma [m/s^2]':>14}")
        for t, s in zip(rep["tau"], rep["sigma"], strict=True):
            mark = "  <- tau_opt" if t == rep["tau_opt"] else ""
            click.echo(f"{t:>9g} {s:>14.4e}{mark}")
        click.echo(f"tau_opt = {rep['tau_opt']:g} s (TM = {mask:g} s, T = {integration:g} s)")
    click.echo(
        f"tau = {rep['tau_budget']:g} s, TM = {mask:g} s, {method.upper()}, pattern {rep['kind']}"
    )
    for k, r in enumerate(rep["Rd"][:6]):
        click.echo(f"Rd[{k}] = {r:.4e} m^2/s^4")
    # σ is of whole periods: say how many and how long they are (QA: T = 100 s with
    # tau 600 s printed "(1 periods)", the σ of one 600 s period under T = 100 s)
    n_per, tau_b = int(rep["n_periods"]), float(rep["tau_budget"])
    span = f"{n_per} period{'' if n_per == 1 else 's'} of {tau_b:g} s"
    if abs(n_per * tau_b - integration) > 1e-9 * integration:
        span += f" = {n_per * tau_b:g} s, the whole periods nearest T"
    click.echo(
        f"sigma over T = {integration:g} s ({span}): {rep['sigma_T']:.4e} m/s^2 "
        f"(independent periods: {rep['sigma_T_indep']:.4e})"
    )
    if plot is not None:
        click.echo(f"wrote {plot}", err=True)


def _check_budget_size(
    mask: float, tau: float | None, fs: float, method: str, integration: float, taus: str | None
) -> None:
    """Usage errors for a ``budget`` too large to compute (see the ``MAX_*`` caps).

    Parameters
    ----------
    mask, tau, fs, method, integration, taus
        The (finite, positive) options of ``budget``: TM [s], τ [s] or None (scan),
        fs [Hz], ``"ls"``/``"gls"``, T [s] and the ``--taus`` spec.
    """
    import numpy as np

    from accal.errors import AccalError
    from accal.pipeline_demod import parse_taus

    if tau is not None:
        grid = np.array([tau])
    else:
        if taus:
            try:
                start, stop, step = (float(x) for x in taus.split(":"))
            except ValueError:
                start = stop = step = float("nan")
            if not all(np.isfinite((start, stop, step))):
                _usage_fail(f"--taus must be START:STOP:STEP in finite seconds, got {taus!r}")
            if 0 < start <= stop and step > 0 and (stop - start) / step + 1 > MAX_SCAN_TAUS:
                _usage_fail(
                    f"--taus {taus} is {_g(np.floor((stop - start) / step) + 1)} tau values; "
                    f"at most {MAX_SCAN_TAUS} are scanned (use a larger STEP)"
                )
        try:
            grid = parse_taus(taus, mask, fs)
        except AccalError as exc:
            _usage_fail(str(exc))
        if not grid.size:
            return  # budget_report says that no tau is left
    _check_period_samples(float(grid.max()), fs, "--tau" if tau is not None else "--taus up to")
    # the budget is computed at one tau of the grid (tau_opt when scanning): the largest need
    n = np.maximum(1, np.round(integration / grid))  # periods in T
    q = grid * fs
    if method == "ls":
        need = float(np.max((n + 1) * q))
        if need > MAX_BUDGET_SAMPLES:
            _usage_fail(
                f"--integration {_g(integration)} s at --fs {_g(fs)} Hz needs {_g(need)} noise "
                f"samples for --method ls ((T/tau + 1)·tau·fs); at most {MAX_BUDGET_SAMPLES} "
                "are allowed (use a shorter --integration)"
            )
    else:
        need = float(np.max(np.maximum(16, 2 * n + 4) ** 2 * q))
        if need > MAX_GLS_ENTRIES:
            _usage_fail(
                f"--integration {_g(integration)} s at --fs {_g(fs)} Hz needs a {_g(need)}-entry "
                "matrix for --method gls ((2·T/tau + 4)²·tau·fs); at most "
                f"{_g(MAX_GLS_ENTRIES)} are allowed (use a shorter --integration or --method ls)"
            )


@click.command("gap", context_settings=CONTEXT_SETTINGS)
@click.option("--days", type=float, default=1.0, show_default=True, help="Duration [day].")
@click.option("--tau", type=float, default=600.0, show_default=True, help="Modulation period [s].")
@click.option("--mask", type=float, default=200.0, show_default=True, help="Masking time [s].")
@click.option("--fs", type=float, default=1.0, show_default=True, help="Sampling frequency [Hz].")
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
    from accal.errors import AccalError, ValidationError
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
    _check_period_samples(tau, fs)
    if days * 86400.0 * fs > MAX_RUN_SAMPLES:
        _usage_fail(
            f"--days {_g(days)} at --fs {_g(fs)} Hz is {_g(days * 86400.0 * fs)} samples; at "
            f"most {_g(MAX_RUN_SAMPLES)} are simulated (--days up to "
            f"{_g(MAX_RUN_SAMPLES / (86400.0 * fs))} at this --fs)"
        )
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
        _fail(str(exc))
    click.echo(f"wrote {run} and {truth}", err=True)
