"""The library side of ``accal design`` and ``accal budget``: patterns and uncertainty budgets."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.demodjob.reading import load_psd
from accal.errors import ValidationError, check_option
from accal.estimators.demod import budget, sigma_mean, tau_scan
from accal.estimators.design import design_pattern, tile
from accal.io.writers import atomic_path, write_table


def write_design(
    out: Path, tau: float, mask: float, fs: float, *, kind: str = "fig2", periods: int = 1
) -> tuple[Path, Any]:
    """Design a calibration pattern and write θ(t) for ``periods`` periods.

    Columns ``time`` [s], ``theta`` [rad], ``rest`` (discrete θ̇ = θ̈ = 0 mask, as
    ``accal demod`` will find it) and ``rest_nominal``.  Format by suffix
    (``.csv`` → CSV, else Parquet).

    Returns
    -------
    (Path, CalibrationPattern)
    """
    import pandas as pd  # here: ~1.2 s to import (python -X importtime), only design needs it

    if periods < 1:
        raise ValidationError(f"periods must be >= 1, got {periods}")
    pat = design_pattern(tau, mask, fs, kind=kind)
    t, theta = tile(pat, periods)
    df = pd.DataFrame(
        {
            "time": t,
            "theta": theta,
            "rest": np.tile(pat.mask, periods),
            "rest_nominal": np.tile(pat.mask_nominal, periods),
        }
    )
    units = {
        "time": "s (from the start of the first period)",
        "theta": "rad",
        "rest": "True where the discrete dtheta = d2theta = 0 (samples demod uses)",
        "rest_nominal": "True outside the nominal rotation windows",
    }
    meta = {
        "kind": pat.kind,
        "tau": pat.tau,
        "mask": pat.tm,
        "fs": pat.fs,
        "periods": periods,
        "segments": [list(s) for s in pat.segments],
        "residuals": pat.residuals,
        "residuals_nominal": pat.residuals_nominal,
        "accal_version": __version__,
    }
    return write_table(df, out, units=units, meta=meta), pat


def parse_taus(spec: str | None, tm: float, fs: float) -> np.ndarray:
    """``START:STOP:STEP`` [s] → array; default ``TM+40 .. 3600`` in 40 s steps (Fig. 6)."""
    if not spec:
        step = 40.0
        return np.arange(tm + step, 3600.0 + 0.5 / fs, step)
    try:
        a, b, c = (float(x) for x in spec.split(":"))
    except ValueError:
        raise ValidationError(f"--taus must be START:STOP:STEP in seconds, got {spec!r}") from None
    if not (0 < a <= b and c > 0):
        raise ValidationError(f"--taus needs 0 < START <= STOP and STEP > 0, got {spec!r}")
    return np.arange(a, b + 1e-9 * b, c)


def budget_report(
    mask: float,
    *,
    tau: float | None = None,
    fs: float = 1.0,
    method: str = "ls",
    integration: float = 3600.0,
    psd: str = "microstar",
    taus: str | None = None,
) -> dict[str, Any]:
    """Uncertainty budget as a JSON-ready dict (``accal budget``).

    With ``tau``: Rd[k] and σ over ``integration`` for that τ.  Without: the Fig. 6
    scan (``tau``, ``sigma``, ``tau_opt``) and the budget at ``tau_opt``.
    ``sigma_curve`` holds σ of the mean versus the number of periods (Fig. 5).
    """
    check_option("method", method, ("ls", "gls"))
    p = load_psd(psd)
    out: dict[str, Any] = {"mask": mask, "fs": fs, "method": method, "integration": integration}
    if tau is None:
        ts, ss, t_opt = tau_scan(
            mask, parse_taus(taus, mask, fs), fs, psd=p, method=method, T=integration
        )
        out.update({"tau": ts.tolist(), "sigma": ss.tolist(), "tau_opt": t_opt})
        tau_b = t_opt
    else:
        tau_b = tau
    b = budget(tau_b, mask, fs, psd=p, method=method, T=integration)
    n = max(1, int(round(integration / b.pattern.tau)))
    out.update(
        {
            "tau_budget": b.pattern.tau,
            "kind": b.pattern.kind,
            "Rd": b.Rd.tolist(),
            "sigma_T": b.sigma_T,
            "sigma_T_indep": b.sigma_T_indep,
            "n_periods": n,
            "sigma_curve": {
                "T": [k * b.pattern.tau for k in range(1, n + 1)],
                "sigma": [sigma_mean(b.Rd, k) for k in range(1, n + 1)],
            },
            "units": {
                "Rd": "m^2/s^4",
                "sigma_T": "m/s^2",
                "sigma": "m/s^2",
                "tau": "s",
                "integration": "s",
            },
        }
    )
    return out


def plot_budget(report: dict[str, Any], path: Path) -> Path:
    """PNG of the budget: σ vs τ (Fig. 6) when scanned, else σ of the mean vs T (Fig. 5)."""
    import matplotlib  # here: ~0.4 s to import (python -X importtime), only plots need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    if "tau_opt" in report:
        ax.plot(report["tau"], np.asarray(report["sigma"]) * 1e12, ".-")
        ax.axvline(report["tau_opt"], color="k", ls=":", label=f"τ_opt = {report['tau_opt']:g} s")
        ax.set_xlabel("modulation period τ [s]")
        ax.set_ylabel(f"σ over {report['integration']:g} s [pm s⁻²]")
        ax.set_title(f"TM = {report['mask']:g} s, {report['method'].upper()}")
        ax.legend()
    else:
        c = report["sigma_curve"]
        ax.loglog(c["T"], np.asarray(c["sigma"]) * 1e12, ".-")
        from matplotlib.ticker import FormatStrFormatter

        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.set_xlabel("integration time T [s]")
        ax.set_ylabel("σ of the mean [pm s⁻²]")
        ax.set_title(
            f"τ = {report['tau_budget']:g} s, TM = {report['mask']:g} s, "
            f"{report['method'].upper()}: Rd[0] = {report['Rd'][0]:.3g} m²s⁻⁴"
        )
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path
