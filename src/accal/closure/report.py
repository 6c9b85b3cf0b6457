"""Reports of a :class:`~accal.closure.select.ClosureResult`: dict, Markdown, plots.

The only module of :mod:`accal.closure` that writes files, and only to the paths
its caller gives.  ``result_to_dict`` is the ``closure.json`` layout::

    {"effects": [{"name", "channel", "coefficient", "sigma", "significance",
                  "epoch", "frequency", "lag", "tau", "details"}, ...],
     "unexplained": [...same keys, name "unexplained"...],
     "base": [{"name", "before", "sigma_before", "after", "sigma_after",
               "change", "sigma_change", "change_significant"}, ...],
     "rms_before", "rms_after", "t0", "n_used", "iterations",
     "residual_before": {"kurtosis", "lowfreq_fraction", "psd": {"freq", "psd"}},
     "residual_after": {...}, "true_error": {...} (only with truth)}

``effects`` is an empty list when nothing was found.  Units: SI (see
:class:`~accal.closure.select.Effect`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from accal.closure.residual import ResidualStats
    from accal.closure.select import ClosureResult, Effect

__all__ = ["plot_closure", "result_to_dict", "to_markdown", "write_json"]


def _clean(obj: Any) -> Any:
    """Make ``obj`` JSON-able: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _effect_dict(e: Effect) -> dict[str, Any]:
    return {
        "name": e.name,
        "channel": e.channel,
        "coefficient": e.coefficient,
        "sigma": e.sigma,
        "significance": e.significance,
        "epoch": e.epoch,
        "frequency": e.frequency,
        "lag": e.lag,
        "tau": e.tau,
        "details": e.details,
    }


def _stats_dict(s: ResidualStats, max_points: int = 200) -> dict[str, Any]:
    f, p = s.freq, s.psd
    if f.size > max_points:  # log-spaced subsample keeps the JSON small
        idx = np.unique(np.geomspace(1, f.size - 1, max_points).astype(int))
        f, p = f[idx], p[idx]
    return {
        "rms": s.rms,
        "kurtosis": s.kurtosis,
        "lowfreq_fraction": s.lowfreq_fraction,
        "segment_means": s.segment_means,
        "psd": {"freq": f, "psd": p, "units": {"freq": "Hz", "psd": "(m/s^2)^2/Hz"}},
    }


def result_to_dict(result: ClosureResult, truth: dict[str, float] | None = None) -> dict[str, Any]:
    """The JSON-able summary of ``result`` (NaN becomes None).

    Parameters
    ----------
    result : ClosureResult
    truth : dict, optional
        True base coefficients (simulation), e.g. ``{"bias": ..., "drift": ...}``;
        adds ``true_error``.
    """
    d: dict[str, Any] = {
        "effects": [_effect_dict(e) for e in result.effects],
        "unexplained": [_effect_dict(e) for e in result.unexplained],
        "base": [
            {
                "name": b.name,
                "before": b.before,
                "sigma_before": b.sigma_before,
                "after": b.after,
                "sigma_after": b.sigma_after,
                "change": b.change,
                "sigma_change": b.sigma_change,
                "change_significant": b.change_significant,
            }
            for b in result.base
        ],
        "rms_before": result.rms_before,
        "rms_after": result.rms_after,
        "t0": result.t0,
        "n_used": int(result.use.sum()),
        "iterations": result.iterations,
        "residual_before": _stats_dict(result.stats_before),
        "residual_after": _stats_dict(result.stats_after),
        "units": {"coefficient": "SI (see docs/closure.md)", "time": "s"},
    }
    if truth is not None:
        d["true_error"] = result.true_error(truth)
    return _clean(d)


def write_json(
    result: ClosureResult, path: str | Path, truth: dict[str, float] | None = None
) -> Path:
    """Write :func:`result_to_dict` to ``path`` (the caller chooses the path)."""
    path = Path(path)
    path.write_text(json.dumps(result_to_dict(result, truth), indent=2) + "\n")
    return path


def _fmt(x: float | None, unit: str = "") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.3g}{(' ' + unit) if unit else ''}"


def to_markdown(
    result: ClosureResult, title: str = "Closing the loop", truth: dict[str, float] | None = None
) -> str:
    """A short Markdown report of ``result``."""
    lines = [f"## {title}", ""]
    lines.append(
        f"Residual RMS {_fmt(result.rms_before, 'm/s²')} → {_fmt(result.rms_after, 'm/s²')} "
        f"({int(result.use.sum())} samples, {result.iterations} selection step(s))."
    )
    lines.append("")
    if result.effects:
        lines += [
            "| effect | channel | coefficient | σ | p (corrected) | epoch / frequency / lag |",
            "|---|---|---|---|---|---|",
        ]
        for e in result.effects:
            where = (
                e.epoch
                if e.epoch is not None
                else e.frequency
                if e.frequency is not None
                else e.lag
            )
            lines.append(
                f"| {e.name} | {e.channel or ''} | {_fmt(e.coefficient)} | {_fmt(e.sigma)} | {_fmt(e.significance)} | {_fmt(where)} |"
            )
    else:
        lines.append("No effect found.")
    lines.append("")
    for u in result.unexplained:
        lines.append(
            f"- **unexplained** ({u.channel}): RMS {_fmt(u.coefficient, 'm/s²')}, dominant frequency "
            f"{_fmt(u.frequency, 'Hz')} — {u.details.get('reason', '')}"
        )
    if result.unexplained:
        lines.append("")
    lines += [
        "| base | before ± σ | after ± σ | change ± σ | significant |",
        "|---|---|---|---|---|",
    ]
    for b in result.base:
        lines.append(
            f"| {b.name} | {_fmt(b.before)} ± {_fmt(b.sigma_before)} | {_fmt(b.after)} ± {_fmt(b.sigma_after)} "
            f"| {_fmt(b.change)} ± {_fmt(b.sigma_change)} | {'yes' if b.change_significant else 'no'} |"
        )
    if truth is not None:
        lines += ["", "| base | true error before | true error after |", "|---|---|---|"]
        for k, v in result.true_error(truth).items():
            lines.append(f"| {k} | {_fmt(v['before'])} | {_fmt(v['after'])} |")
    return "\n".join(lines) + "\n"


def plot_closure(
    result: ClosureResult, residual_path: str | Path, psd_path: str | Path
) -> tuple[Path, Path]:
    """Plot residuals and their PSDs before/after (matplotlib, Agg backend).

    Parameters
    ----------
    result : ClosureResult
    residual_path, psd_path : str or Path
        Output image files (format from the suffix), chosen by the caller.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    t = result.time[result.use]
    hours = (t - t[0]) / 3600.0
    fig = Figure(figsize=(9, 4.5))
    ax = fig.subplots()
    ax.plot(
        hours,
        result.residual_before[result.use],
        lw=0.4,
        label=f"before (RMS {result.rms_before:.3g})",
    )
    ax.plot(
        hours,
        result.residual_after[result.use],
        lw=0.4,
        label=f"after (RMS {result.rms_after:.3g})",
    )
    for e in result.effects:
        if e.epoch is not None:
            ax.axvline((e.epoch - t[0]) / 3600.0, color="k", ls="--", lw=0.8)
    ax.set_xlabel("time since first used sample [h]")
    ax.set_ylabel("residual [m/s²]")
    ax.legend(loc="best")
    fig.tight_layout()
    residual_path = Path(residual_path)
    fig.savefig(residual_path, dpi=110)

    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for s, lab in ((result.stats_before, "before"), (result.stats_after, "after")):
        if s.freq.size > 1:
            ax.loglog(s.freq[1:], np.sqrt(s.psd[1:]), lw=0.8, label=lab)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("residual ASD [m/s²/√Hz]")
    ax.legend(loc="best")
    fig.tight_layout()
    psd_path = Path(psd_path)
    fig.savefig(psd_path, dpi=110)
    return residual_path, psd_path
