"""Reports of a :class:`~accal.closure.select.ClosureResult`: dict, Markdown, plots.

The only module of :mod:`accal.closure` that writes files, and only to the paths
its caller gives.  ``result_to_dict`` is the ``closure.json`` layout::

    {"effects": [{"name", "channel", "axis", "coefficient", "sigma", "significance",
                  "epoch", "frequency", "lag", "tau", "details"}, ...],
     "unexplained": [...same keys, name "unexplained"...],
     "notes": [{"name", "channel", "note"}, ...],   # candidates not testable here
     "removed": [{"name", "channel", "p_accept", "epoch"/"frequency"/"lag"/"tau"}, ...],
                                                    # added, then eliminated
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

if TYPE_CHECKING:
    from numpy.typing import NDArray

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
        "removed": [
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
            for e in result.removed
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
    if result.removed:
        names = ", ".join(effect_label(e) for e in result.removed)  # a step: its epoch
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
                f"; instrument effects must stay significant given the other axes "
                f"({', '.join(sm['signal_proxies'])})"
                if sm.get("signal_proxies")
                else ""
            )
        )
    considered = [c["channel"] for c in result.considered if c["status"] == "considered"]
    left = [
        f"{c['channel']} ({c['reason']})" for c in result.considered if c["status"] != "considered"
    ]
    if considered or left:
        lines.append(
            f"- channels tested for couplings: {', '.join(considered) or 'none'}"
            + (f"; left out: {'; '.join(left)}" if left else "")
        )
    if result.unexplained or result.notes or result.removed or result.rejected:
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


def _break_gaps(x, *ys):
    """Insert NaN where ``x`` jumps by more than 1.5 median steps (lines do not bridge gaps)."""
    if x.size < 3:
        return (x, *ys)
    cut = np.flatnonzero(np.diff(x) > 1.5 * np.median(np.diff(x))) + 1
    return tuple(np.insert(np.asarray(a, dtype=float), cut, np.nan) for a in (x, *ys))


def _channels(result: ClosureResult) -> list[tuple[str | None, NDArray[np.bool_]]]:
    if not result.channel_names or result.channel is None:
        return [(None, result.use)]
    return [(nm, result.use & (result.channel == c)) for c, nm in enumerate(result.channel_names)]


def plot_closure(
    result: ClosureResult,
    residual_path: str | Path,
    psd_path: str | Path,
    effects_path: str | Path | None = None,
) -> tuple[Path, ...]:
    """Plot residuals and their PSDs before/after (matplotlib, Agg backend).

    Parameters
    ----------
    result : ClosureResult
    residual_path, psd_path : str or Path
        Output image files (format from the suffix), chosen by the caller.
    effects_path : str or Path, optional
        Also plot every effect's regressor against the residual
        (:func:`plot_effects`).

    Returns
    -------
    tuple of Path
        The files written, in the order given.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    chans = _channels(result)
    t_first = result.time[result.use][0]
    fig = Figure(figsize=(9, 3.2 * len(chans) + 1.0))
    axes = fig.subplots(len(chans), 1, squeeze=False, sharex=True)[:, 0]
    for ax, (nm, m) in zip(axes, chans, strict=True):
        hours = (result.time[m] - t_first) / 3600.0
        rb, ra = result.residual_before[m], result.residual_after[m]
        hb, rb_p, ra_p = _break_gaps(hours, rb, ra)
        ax.plot(hb, rb_p, lw=0.4, label=f"before (RMS {np.sqrt(np.mean(rb**2)):.3g})")
        ax.plot(hb, ra_p, lw=0.4, label=f"after (RMS {np.sqrt(np.mean(ra**2)):.3g})")
        for e in result.effects:
            if e.epoch is not None:
                ax.axvline((e.epoch - t_first) / 3600.0, color="k", ls="--", lw=0.8)
        ax.set_ylabel("residual [m/s²]" if nm is None else f"residual {nm} [m/s²]")
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time since first used sample [h]")
    names = ", ".join(e.name for e in result.effects) or "none"
    axes[0].set_title(f"residual before/after closing the loop (effects: {names})", fontsize=10)
    fig.tight_layout()
    residual_path = Path(residual_path)
    fig.savefig(residual_path, dpi=110)

    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for st, lab in ((result.stats_before, "before"), (result.stats_after, "after")):
        asd = np.sqrt(st.psd[1:]) if st.freq.size > 1 else np.zeros(0)
        ok = asd > 0  # an exact fit (a residual of zeros) has nothing to draw on a log scale
        if ok.any():
            ax.loglog(st.freq[1:][ok], asd[ok], lw=0.8, label=lab)
    for e in result.effects:
        if e.frequency:
            ax.axvline(e.frequency, color="k", ls=":", lw=0.8)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("residual ASD [m/s²/√Hz]")
    ax.set_title("residual amplitude spectral density", fontsize=10)
    if ax.get_lines():
        ax.legend(loc="best")
    fig.tight_layout()
    psd_path = Path(psd_path)
    fig.savefig(psd_path, dpi=110)
    out: tuple[Path, ...] = (residual_path, psd_path)
    if effects_path is not None:
        out = (*out, plot_effects(result, effects_path))
    return out


def plot_effects(result: ClosureResult, path: str | Path, max_points: int = 4000) -> Path:
    """Each effect's fitted contribution against the residual without it.

    One panel per effect (and data channel), an added-variable plot against time:
    the fitted contribution ``regressor × coefficient`` with the base model
    projected out (colour: what only this effect explains) and the *partial
    residual* ``residual_after + contribution`` (grey, decimated to
    ``max_points``).  An effect that explains the residual follows it; one found
    in noise would not.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    chans = _channels(result)
    effects = list(result.effects)
    path = Path(path)
    rows = max(len(effects), 1)
    fig = Figure(figsize=(9, 2.6 * rows + 0.6))
    axes = fig.subplots(rows, len(chans), squeeze=False)
    if not effects:
        axes[0, 0].text(0.5, 0.5, "no effect found", ha="center", va="center")
        axes[0, 0].set_axis_off()
        fig.savefig(path, dpi=110)
        return path
    from accal.closure.basis import Basis

    t_first = result.time[result.use][0]
    use = result.use
    bb = result.base_design
    base = Basis(bb.block[use], bb.columns[use], n_blocks=bb.n_blocks)
    j = result.n_base
    for i, e in enumerate(effects):
        q = _n_columns(result, j, e)
        full = (
            result.effect_columns[:, j - result.n_base : j - result.n_base + q]
            @ (result.coef[j : j + q])
        )
        # what only the effect explains: its contribution with the base projected out
        contrib = np.full(full.shape, np.nan)
        contrib[use] = full[use] - base.project(full[use])
        j += q
        for k, (nm, m) in enumerate(chans):
            ax = axes[i, k]
            idx = np.flatnonzero(m)
            if idx.size > max_points:
                idx = idx[np.linspace(0, idx.size - 1, max_points).astype(int)]
            hours = (result.time[idx] - t_first) / 3600.0
            ax.plot(hours, result.residual_after[idx] + contrib[idx], ".", ms=1, color="0.6")
            ax.plot(hours, contrib[idx], lw=1.0, color="C3")
            lab = e.name if e.channel is None else f"{e.name} ({e.channel})"
            ax.set_title(lab if nm is None else f"{lab} — {nm}", fontsize=9)
            ax.set_ylabel("[m/s²]", fontsize=8)
            if i == rows - 1:
                ax.set_xlabel("time since first used sample [h]", fontsize=8)
    fig.suptitle(
        "partial residual (grey) and fitted effect (red), base model projected out", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _n_columns(result: ClosureResult, start: int, effect: Effect) -> int:
    """Number of design columns of ``effect`` (its columns start at ``start``)."""
    return int(effect.details.get("n_columns", 1))
