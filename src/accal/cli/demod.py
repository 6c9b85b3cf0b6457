"""``accal demod``: unbiased a_Y, a_Z per modulation period of rotating-platform runs.

The options are declared in :mod:`accal.cli.demod_options`; the work is
:func:`accal.pipeline_demod.run_demod`, imported when the command runs
(with accal.run_sampling: ~0.5 s, not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from accal._cliutil import CONTEXT_SETTINGS, err, fail, fmt_number, progress, usage_fail
from accal.cli.batch_options import for_scheduler
from accal.cli.demod_options import demod_options


@click.command(
    "demod",
    context_settings=CONTEXT_SETTINGS,
    short_help="Demodulate rotating-platform runs: unbiased a_Y, a_Z per period.",
)
@click.argument("runs", nargs=-1, required=True, type=click.Path(path_type=Path))
@demod_options
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
    workers: int | None,
    scheduler: str | None,
    force: bool,
    checksum: bool,
    close_loop: bool,
    alpha: float,
    plots: bool,
    quiet: bool,
) -> None:
    """Demodulate rotating-platform runs: unbiased a_Y, a_Z per modulation period.

    Every RUN's periods go into the cumulative OUT/periods.<fmt> (a `source`
    column; a re-run replaces that source's rows).  Summaries: OUT/summary.json
    and OUT/summary.md with one RUN, OUT/<stem>.summary.json/.md with several.
    OUT/manifest.json: re-runs skip RUNs whose file and options did not change;
    OUT/accal.log: the run log.  Runs go to worker processes (-j) or a Dask
    cluster (--scheduler).
    """
    from accal.batch import Interrupted, default_workers
    from accal.errors import AccalError
    from accal.pipeline_demod import (
        DemodOptions,
        check_output_format,
        load_psd,
        output_paths,
        run_demod,
    )
    from accal.run_sampling import too_coarse_for_tau

    try:
        output_paths(runs, out, fmt)  # a run given twice: a usage error
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
        usage_fail(str(exc))
    runs_l, out, opts = for_scheduler(scheduler, runs, out, opts)
    runs = tuple(runs_l)
    coarse = too_coarse_for_tau(runs, opts)
    if coarse:
        path, step = coarse[0]
        usage_fail(
            f"--tau {fmt_number(float(opts.tau))} s is shorter than one sample of {path} (fs = "
            f"{fmt_number(1 / step)} Hz): tau must be a whole number of samples, at least "
            f"{fmt_number(step)} s"
        )
    try:
        summary = run_demod(
            runs,
            out,
            opts,
            progress=progress(quiet, "demod"),
            psd=noise,
            workers=workers or default_workers(),
            scheduler=scheduler,
            force=force,
            checksum=checksum,
        )
    except AccalError as exc:  # the lock of another run, an unreachable scheduler, ...
        fail(str(exc))
    except Interrupted:  # the runs that finished are written; a re-run does the rest
        err("interrupted")
        sys.exit(130)
    for o in summary.outcomes:
        if not o.ok:
            err(o.message)
            continue
        if quiet or o.skipped:  # as grace-bias: -q is errors only; warnings in accal.log
            continue
        for w in o.warnings:
            err(f"{o.path}: warning: {w}")
        for line in _run_lines(o.path, o.summary, o.outputs[0]):
            click.echo(line, err=True)
    if not quiet:
        click.echo(summary.line(), err=True)
    if summary.n_failed:
        sys.exit(1)


def _run_lines(path: Path, s: dict[str, Any], first_output: Path) -> list[str]:
    """The lines said of one demodulated run: its mean, its noise levels, its closure."""
    lines = [
        f"{path}: {s['n_kept']}/{s['n_periods']} periods, "
        f"mean a_Y = {s['mean']['a_Y']:.4g}, a_Z = {s['mean']['a_Z']:.4g} "
        f"± {s['mean']['sigma']:.3g} m/s^2; Rd[0] = {s['Rd'][0]:.4g} m^2/s^4 -> {first_output}"
    ]
    nz = s.get("noise") or {}
    if nz.get("level_apriori") is not None:
        src = "the run's residual" if nz["psd_used"] == "data" else nz["apriori"]
        ratio = nz.get("sigma_ratio")
        lines.append(
            f"{path}: sigma from the PSD of {src}; noise at 2/tau "
            f"{nz['level_apriori']:.3g} a-priori ({nz['apriori']}), "
            + (
                f"{nz['level_data']:.3g} data m/s^2/sqrt(Hz); sigma a-priori/data = {ratio:.3g}"
                if ratio is not None
                else "data: not estimated"
            )
        )
    if "closure" in s:
        c = s["closure"]
        found = [
            e["name"] + (f"({e['channel']})" if e.get("channel") else "") for e in c["effects"]
        ]
        found += ["unexplained"] * len(c["unexplained"])
        after = c.get("noise_after")
        noise = (
            f"; noise at 2/tau without its effects {after['level_data']:.3g} m/s^2/sqrt(Hz) "
            "(the sigma after the closure)"
            if after
            else ""
        )
        lines.append(
            f"{path}: closure: {', '.join(found) or 'nothing found'}; residual RMS "
            f"{c['rms_before']:.3g} -> {c['rms_after']:.3g} m/s^2{noise} (closure.md)"
        )
    return lines
