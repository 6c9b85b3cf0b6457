"""Reports of a :class:`~accal.closure.select.ClosureResult`: dict, Markdown (and the
plots of :mod:`accal.closure.plots`, re-exported here).

With :mod:`accal.closure.plots`, the only modules of :mod:`accal.closure` that write
files, and only to the paths their caller gives.  ``result_to_dict`` is the ``closure.json`` layout::

    {"effects": [{"name", "channel", "axis", "coefficient", "sigma", "significance",
                  "epoch", "frequency", "lag", "tau", "details"}, ...],
     "unexplained": [...same keys, name "unexplained"...],
     "notes": [{"name", "channel", "note"}, ...],   # candidates not testable here
     "eliminated": [{"name", "channel", "p_accept", "epoch"/"frequency"/"lag"/"tau"}, ...],
                        # added to the model, then eliminated (not removed from the data;
                        # the caller's "removed_from_calibrated" lists what was)
     "rejected": [{...effect keys...; details.reason}, ...],  # significant, not added:
                        # not identifiable, not confirmed on held-out stretches, implausible
     "considered": [{"channel", "status", "reason"}, ...],  # channels offered / left out
     "signal_model": {...},                         # the orbit template (no reference)
     "base": [{"name", "before", "sigma_before", "after", "sigma_after", "sigma_plain",
               "change", "sigma_change", "change_significant"}, ...],
     "channels": [...] (several data channels, e.g. ["y", "z"]),
     "rms_before", "rms_after", "t0", "n_used", "iterations",
     "residual_before": {"kurtosis", "lowfreq_fraction", "psd": {"freq", "psd"}},
     "residual_after": {...}, "true_error": {...} (only with truth)}

``effects`` is an empty list when nothing was found.  With several data channels
``axis`` names the channel whose coefficient is given and ``details.axes`` holds
every channel's.  Units: SI (see :class:`~accal.closure.select.Effect`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.closure.kinds import effect_label
from accal.closure.plots import plot_closure, plot_effects

if TYPE_CHECKING:
    from accal.closure.residual import ResidualStats
    from accal.closure.select import ClosureResult, Effect

__all__ = ["plot_closure", "plot_effects", "result_to_dict", "to_markdown", "write_json"]


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
        "axis": e.axis,
        "coefficient": e.coefficient,
        "unit": e.unit,
        "instrument": e.instrument,
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
        "notes": list(result.notes),
        "eliminated": [
            {
                "name": e.name,
                "channel": e.channel,
                "p_accept": e.significance,  # of the test that admitted it
                **{
                    k: float(v)
                    for k, v in (
                        ("epoch", e.epoch),
                        ("frequency", e.frequency),
                        ("lag", e.lag),
                        ("tau", e.tau),
                    )
                    if v is not None
                },
            }
            for e in result.eliminated
        ],
        "rejected": [_effect_dict(e) for e in result.rejected],
        "considered": list(result.considered),
        "signal_model": dict(result.signal_model),
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
                "sigma_plain": b.sigma_plain,
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
    if result.channel_names:
        d["channels"] = list(result.channel_names)
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


def _fmt(x: float | str | None, unit: str = "") -> str:
    if isinstance(x, str):
        return x
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.3g}{(' ' + unit) if unit else ''}"


def to_markdown(
    result: ClosureResult,
    title: str = "Closing the loop",
    truth: dict[str, float] | None = None,
    max_base_rows: int = 30,
) -> str:
    """A short Markdown report of ``result``.

    With a block base (e.g. one block per modulation period) only the first
    ``max_base_rows`` base coefficients are tabulated; ``closure.json`` has them all.
    """
    lines = [f"## {title}", ""]
    lines.append(
        f"Residual RMS {_fmt(result.rms_before, 'm/s²')} → {_fmt(result.rms_after, 'm/s²')} "
        f"({int(result.use.sum())} samples, {result.iterations} selection step(s))."
    )
    lines.append("")
    multi = bool(result.channel_names)
    if result.effects:
        head = "| effect | channel | " + ("axis | " if multi else "")
        lines += [
            head + "coefficient | σ | p (corrected) | epoch / frequency / lag / τ |",
            "|---" * (7 if multi else 6) + "|",
        ]
        for e in result.effects:
            where = next(
                (
                    f"{lab} {_fmt(v)}"
                    for lab, v in (
                        ("epoch", None if e.epoch is None else f"{e.epoch:.10g} s"),
                        ("f", e.frequency),
                        ("lag", e.lag),
                        ("τ", e.tau),
                    )
                    if v is not None
                ),
                "",
            )
            if e.name == "bias_step" and e.details.get("epoch_sigma"):
                where += f" ± {_fmt(e.details['epoch_sigma'])} s"
                if e.details.get("epoch_ambiguous"):
                    lo, hi = e.details["epoch_interval"]
                    where += f" (other epochs fit as well: {lo:.10g}-{hi:.10g} s)"
            elif e.tau is not None and e.details.get("tau_sigma") and where.startswith("τ"):
                where += f" ± {_fmt(e.details['tau_sigma'])}"
            elif e.name == "periodic" and e.details.get("amplitude_rate") is not None:
                # amplitude at mid-record, changing linearly (see _Search._modulated)
                where += (
                    f" (period {1.0 / e.frequency:.6g} s), amplitude changing by "
                    f"{_fmt(e.details['amplitude_rate'])} ± "
                    f"{_fmt(e.details['amplitude_rate_sigma'])} m/s² per s"
                )
            elif e.name == "auxiliary":  # the coupling's lag and low-pass, with their σ
                if e.details.get("lag_sigma"):
                    where += f" ± {_fmt(e.details['lag_sigma'])}"
                if e.details.get("lag_ambiguous"):  # other lags fit as well
                    lo, hi = e.details["lag_interval"]
                    where += f" (lag not identified within {_fmt(lo)}-{_fmt(hi)} s)"
                if e.tau:
                    where += f", τ {e.tau:.4g}"
                    if e.details.get("tau_sigma"):
                        where += f" ± {_fmt(e.details['tau_sigma'])}"
                    where += " s"
            ax = f"{e.axis or ''} | " if multi else ""
            lines.append(
                f"| {e.name} | {e.channel or ''} | {ax}{_fmt(e.coefficient)} | {_fmt(e.sigma)} "
                f"| {_fmt(e.significance)} | {where} |"
            )
            for a, v in e.details.get("axes", {}).items():
                if a != e.axis:
                    lines.append(f"| | | {a} | {_fmt(v['coefficient'])} | {_fmt(v['sigma'])} | | |")
    else:
        lines.append("No effect found.")
    lines.append("")
    for u in result.unexplained:
        lines.append(
            f"- **unexplained** ({u.channel}): RMS {_fmt(u.coefficient, 'm/s²')}, dominant frequency "
            f"{_fmt(u.frequency, 'Hz')} — {u.details.get('reason', '')}"
        )
    for n in result.notes:
        ch = f" ({n['channel']})" if n.get("channel") is not None else ""
        lines.append(f"- {n['name']}{ch}: {n['note']}")
    if result.eliminated:
        names = ", ".join(effect_label(e) for e in result.eliminated)  # a step: its epoch
        lines.append(f"- added and later eliminated (stood in for another effect): {names}")
    for e in result.rejected:
        ch = f" ({e.channel})" if e.channel is not None else ""
        lines.append(
            f"- significant but **not removed**: {e.name}{ch}, coefficient "
            f"{_fmt(e.coefficient)} {e.unit}, p {_fmt(e.significance)}: {e.details.get('reason', '')}"
        )
    if result.signal_model:
        sm = result.signal_model
        lines.append(
            f"- signal model (no reference): orbit-phase template, period {sm['period']:.6g} s, "
            f"{sm['bins']} bins × degree-{sm['amplitude_degree']} amplitude, a smooth curve "
            f"(knots {sm.get('knot_spacing', 0):.0f} s) and {sm.get('modulated_harmonics', 0)} "
            "orbit harmonics with slowly changing amplitude"
            + (
                f"; the unexplained signal of {', '.join(sm['proxies_in_model'])} in the model"
                if sm.get("proxies_in_model")
                else ""
            )
            + (
                f"; instrument effects must stay significant given the other axes "
                f"({', '.join(sm['signal_proxies'])})"
                if sm.get("signal_proxies")
                else ""
            )
        )
    considered = [
        c["channel"] + (f" ({c['reason']})" if c.get("reason") else "")
        for c in result.considered
        if c["status"] == "considered"
    ]
    left = [
        f"{c['channel']} ({c['reason']})" for c in result.considered if c["status"] != "considered"
    ]
    if considered or left:
        lines.append(
            f"- channels tested for couplings: {', '.join(considered) or 'none'}"
            + (f"; left out: {'; '.join(left)}" if left else "")
        )
    if result.unexplained or result.notes or result.eliminated or result.rejected:
        lines.append("")
    lines += [
        "| base | before ± σ | after ± σ | change ± σ | significant |",
        "|---|---|---|---|---|",
    ]
    for b in result.base[:max_base_rows]:
        lines.append(
            f"| {b.name} | {_fmt(b.before)} ± {_fmt(b.sigma_before)} | {_fmt(b.after)} ± {_fmt(b.sigma_after)} "
            f"| {_fmt(b.change)} ± {_fmt(b.sigma_change)} | {'yes' if b.change_significant else 'no'} |"
        )
    if len(result.base) > max_base_rows:
        n_sig = sum(b.change_significant for b in result.base)
        lines.append(
            f"| … {len(result.base) - max_base_rows} more (closure.json); "
            f"{n_sig} of {len(result.base)} changed significantly | | | | |"
        )
    if truth is not None:
        lines += ["", "| base | true error before | true error after |", "|---|---|---|"]
        for k, v in result.true_error(truth).items():
            lines.append(f"| {k} | {_fmt(v['before'])} | {_fmt(v['after'])} |")
    return "\n".join(lines) + "\n"
