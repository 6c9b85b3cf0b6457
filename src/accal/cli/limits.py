"""Size caps of the commands that build arrays from option values alone, and their checks.

A value over a cap is a usage error saying the cap (exit status 2), not a
MemoryError or a run that never ends.
"""

from __future__ import annotations

from accal._cliutil import fmt_number, usage_fail
from accal.errors import AccalError

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


def check_period_samples(tau: float, fs: float, option: str = "--tau") -> None:
    """Usage error unless ``tau·fs <= MAX_PERIOD_SAMPLES`` (τ [s], fs [Hz] both finite).

    Parameters
    ----------
    tau, fs : float
        Modulation period [s] and sampling frequency [Hz].
    option : str
        The option named by the message.
    """
    if tau * fs > MAX_PERIOD_SAMPLES:
        usage_fail(
            f"{option} {fmt_number(tau)} s at --fs {fmt_number(fs)} Hz is "
            f"{fmt_number(tau * fs)} samples per modulation period; at most "
            f"{MAX_PERIOD_SAMPLES} (tau·fs) are allowed"
        )


def check_design_size(periods: int, tau: float, fs: float) -> None:
    """Usage error unless a ``design`` table fits :data:`MAX_DESIGN_SAMPLES` rows.

    Parameters
    ----------
    periods : int
        ``--periods``.
    tau, fs : float
        Modulation period [s] and sampling frequency [Hz].
    """
    if periods * tau * fs > MAX_DESIGN_SAMPLES:
        usage_fail(
            f"--periods {periods} of --tau {fmt_number(tau)} s at --fs {fmt_number(fs)} Hz is "
            f"{fmt_number(periods * tau * fs)} samples; at most {MAX_DESIGN_SAMPLES} are written"
        )


def check_run_size(days: float, fs: float) -> None:
    """Usage error unless a ``simulate gap`` run fits :data:`MAX_RUN_SAMPLES` samples.

    Parameters
    ----------
    days : float
        ``--days``.
    fs : float
        Sampling frequency [Hz].
    """
    if days * 86400.0 * fs > MAX_RUN_SAMPLES:
        usage_fail(
            f"--days {fmt_number(days)} at --fs {fmt_number(fs)} Hz is "
            f"{fmt_number(days * 86400.0 * fs)} samples; at most {fmt_number(MAX_RUN_SAMPLES)} "
            f"are simulated (--days up to {fmt_number(MAX_RUN_SAMPLES / (86400.0 * fs))} at "
            "this --fs)"
        )


def check_budget_size(
    mask: float, tau: float | None, fs: float, method: str, integration: float, taus: str | None
) -> None:
    """Usage errors for a ``budget`` too large to compute (see the ``MAX_*`` caps).

    Parameters
    ----------
    mask, tau, fs, method, integration, taus
        The (finite, positive) options of ``budget``: TM [s], τ [s] or None (scan),
        fs [Hz], ``"ls"``/``"gls"``, T [s] and the ``--taus`` spec.
    """
    import numpy as np  # ~0.2 s: not for `accal --help`

    from accal.pipeline_demod import parse_taus

    g = fmt_number
    if tau is not None:
        grid = np.array([tau])
    else:
        if taus:
            try:
                start, stop, step = (float(x) for x in taus.split(":"))
            except ValueError:
                start = stop = step = float("nan")
            if not all(np.isfinite((start, stop, step))):
                usage_fail(f"--taus must be START:STOP:STEP in finite seconds, got {taus!r}")
            if 0 < start <= stop and step > 0 and (stop - start) / step + 1 > MAX_SCAN_TAUS:
                usage_fail(
                    f"--taus {taus} is {g(np.floor((stop - start) / step) + 1)} tau values; "
                    f"at most {MAX_SCAN_TAUS} are scanned (use a larger STEP)"
                )
        try:
            grid = parse_taus(taus, mask, fs)
        except AccalError as exc:
            usage_fail(str(exc))
        if not grid.size:
            return  # budget_report says that no tau is left
    check_period_samples(float(grid.max()), fs, "--tau" if tau is not None else "--taus up to")
    # the budget is computed at one tau of the grid (tau_opt when scanning): the largest need
    n = np.maximum(1, np.round(integration / grid))  # periods in T
    q = grid * fs
    if method == "ls":
        need = float(np.max((n + 1) * q))
        if need > MAX_BUDGET_SAMPLES:
            usage_fail(
                f"--integration {g(integration)} s at --fs {g(fs)} Hz needs {g(need)} noise "
                f"samples for --method ls ((T/tau + 1)·tau·fs); at most {MAX_BUDGET_SAMPLES} "
                "are allowed (use a shorter --integration)"
            )
    else:
        need = float(np.max(np.maximum(16, 2 * n + 4) ** 2 * q))
        if need > MAX_GLS_ENTRIES:
            usage_fail(
                f"--integration {g(integration)} s at --fs {g(fs)} Hz needs a {g(need)}-entry "
                "matrix for --method gls ((2·T/tau + 4)²·tau·fs); at most "
                f"{g(MAX_GLS_ENTRIES)} are allowed (use a shorter --integration or --method ls)"
            )
