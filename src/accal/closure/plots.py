"""Figures of a closure result: residual before/after, its spectrum, each effect.

Written for a reader who opens the PNG without the report: the title names the input
and axis, time is UTC, accelerations are in the SI prefix that fits them (nm/s², µm/s²,
:func:`accal.plot_style.accel_scale`), a day of samples is drawn as a binned mean inside
its min-max envelope (:func:`accal.plot_style.envelope`), and every effect's epoch or
frequency is marked and labelled where it falls inside the plotted range.
matplotlib's object API (``Figure``, no pyplot state), Agg backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.closure.kinds import effect_label
from accal.plot_style import accel_scale, envelope
from accal.timescale import gps_to_utc

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from accal.closure.select import ClosureResult

__all__ = ["plot_closure", "plot_effects"]

#: Intervals a panel's time axis is binned into (:func:`accal.plot_style.envelope`).
TIME_BINS = 1500
DPI = 110


def _figure(size: tuple[float, float]) -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    return Figure(figsize=size)


def _channels(result: ClosureResult) -> list[tuple[str | None, NDArray[np.bool_]]]:
    if not result.channel_names or result.channel is None:
        return [(None, result.use)]
    return [(nm, result.use & (result.channel == c)) for c, nm in enumerate(result.channel_names)]


def _time_axis(seconds: NDArray[np.float64], gps: bool) -> tuple[Any, str]:
    """Abscissae for ``seconds`` and the axis label: UTC instants (GPS seconds in), or
    hours since the first sample."""
    if gps:
        return gps_to_utc(seconds), "time (UTC)"
    return seconds / 3600.0, "time [h]"


def _dates(axes: Any) -> None:
    """Concise UTC date ticks (the date once, then hours) on time axes."""
    import matplotlib.dates as mdates

    for ax in np.ravel(axes):
        loc = mdates.AutoDateLocator()
        ax.xaxis.set_major_locator(loc)
        ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(loc))


def _heading(title: str | None, what: str) -> str:
    return what if not title else f"{title}\n{what}"


def _short(e: Any) -> str:
    """An effect's name for a mark on an axis that already says where it is."""
    return e.name if e.channel is None else f"{e.name}({e.channel})"


def _rms(x: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def plot_closure(
    result: ClosureResult,
    residual_path: str | Path,
    psd_path: str | Path,
    effects_path: str | Path | None = None,
    *,
    title: str | None = None,
    gps: bool = True,
) -> tuple[Path, ...]:
    """Plot the residual and its amplitude spectrum before/after closing the loop.

    Parameters
    ----------
    result : ClosureResult
    residual_path, psd_path : str or Path
        Output image files (format from the suffix), chosen by the caller.
    effects_path : str or Path, optional
        Also plot every effect against the residual (:func:`plot_effects`).
    title : str, optional
        What the data are (e.g. the input file and axis), first line of every title.
    gps : bool
        ``result.time`` is GPS seconds: the time axis is UTC (else hours).

    Returns
    -------
    tuple of Path
        The files written, in the order given.
    """
    chans = _channels(result)
    fig = _figure((10, 3.0 * len(chans) + 1.2))
    axes = fig.subplots(len(chans), 1, squeeze=False, sharex=True)[:, 0]
    factor, unit = accel_scale(result.residual_before[result.use])
    label = "time"
    for ax, (nm, m) in zip(axes, chans, strict=True):
        t = result.time[m]
        for res, colour, name in (
            (result.residual_before[m], "C0", "before"),
            (result.residual_after[m], "C1", "after"),
        ):
            centre, mean, lo, hi = envelope(t, res * factor, TIME_BINS)
            x, label = _time_axis(centre, gps)
            ax.fill_between(x, lo, hi, color=colour, alpha=0.25, lw=0)
            ax.plot(
                x, mean, color=colour, lw=0.8, label=f"{name}: RMS {_rms(res) * factor:.3g} {unit}"
            )
        _mark_epochs(ax, result, gps)
        ax.set_ylabel(f"residual{'' if nm is None else ' ' + nm} [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel(f"{label}; line: mean per interval, band: its min-max")
    names = ", ".join(effect_label(e) for e in result.effects) or "none"
    axes[0].set_title(
        _heading(title, f"residual before/after closing the loop; effects: {names}"), fontsize=10
    )
    if gps:
        _dates(axes)
    fig.tight_layout()
    residual_path = Path(residual_path)
    fig.savefig(residual_path, dpi=DPI)
    psd_path = _plot_psd(result, psd_path, title)
    out: tuple[Path, ...] = (residual_path, psd_path)
    if effects_path is not None:
        out = (*out, plot_effects(result, effects_path, title=title, gps=gps))
    return out


def _mark_epochs(ax: Any, result: ClosureResult, gps: bool) -> None:
    """A dashed line and the effect's name at each effect's epoch."""
    for e in result.effects:
        if e.epoch is None:
            continue
        x, _ = _time_axis(np.array([float(e.epoch)]), gps)
        ax.axvline(x[0], color="k", ls="--", lw=0.8)
        ax.annotate(
            _short(e), (x[0], 1.0), xycoords=("data", "axes fraction"),
            xytext=(2, -10), textcoords="offset points", fontsize=7, rotation=90, va="top",
        )  # fmt: skip


def _plot_psd(result: ClosureResult, path: str | Path, title: str | None) -> Path:
    """Amplitude spectral density of the residual before/after, effects' frequencies
    marked and labelled inside the plotted band (listed in the title otherwise)."""
    fig = _figure((8, 4.8))
    ax = fig.subplots()
    curves = []
    for st, lab in ((result.stats_before, "before"), (result.stats_after, "after")):
        asd = np.sqrt(st.psd[1:]) if st.freq.size > 1 else np.zeros(0)
        ok = asd > 0  # an exact fit (a residual of zeros) has nothing to draw on a log scale
        curves.append((st.freq[1:][ok], asd[ok], lab))
    factor, unit = accel_scale(np.concatenate([c[1] for c in curves]))
    band = [np.inf, 0.0]
    for f, asd, lab in curves:
        if f.size:
            ax.loglog(f, asd * factor, lw=0.8, label=lab)
            band = [min(band[0], f.min()), max(band[1], f.max())]
    outside, marked = [], []
    for e in result.effects:
        if not e.frequency:
            continue
        text = f"{_short(e)}, period {1.0 / e.frequency:.5g} s"
        if band[0] <= e.frequency <= band[1]:
            marked.append(text)
            ax.axvline(e.frequency, color="k", ls=":", lw=0.8)
            ax.annotate(
                str(len(marked)), (e.frequency, 1.0), xycoords=("data", "axes fraction"),
                xytext=(2, -10 - 9 * ((len(marked) - 1) % 3)), textcoords="offset points",
                fontsize=7,
            )  # fmt: skip
        else:
            outside.append(text)
    if marked:  # numbered marks, named in a box: close lines do not overwrite each other
        ax.text(
            0.99, 0.98, "\n".join(f"{k}: {m}" for k, m in enumerate(marked, 1)),
            transform=ax.transAxes, ha="right", va="top", fontsize=7,
            bbox={"boxstyle": "round", "fc": "white", "alpha": 0.8, "lw": 0.5},
        )  # fmt: skip
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(f"residual ASD [{unit}/√Hz]")
    ax.grid(alpha=0.3, which="both")
    what = "residual amplitude spectral density"
    if outside:
        what += f" (outside the band: {'; '.join(outside)})"
    ax.set_title(_heading(title, what), fontsize=10)
    if ax.get_lines():
        ax.legend(loc="lower left")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    return path


def plot_effects(
    result: ClosureResult,
    path: str | Path,
    max_points: int = 4000,
    *,
    title: str | None = None,
    gps: bool = True,
) -> Path:
    """Each effect's fitted contribution against the residual without it.

    One panel per effect (and data channel), an added-variable plot against time:
    the fitted contribution ``regressor × coefficient`` with the base model
    projected out (red: what only this effect explains) and the *partial residual*
    ``residual_after + contribution`` (grey, decimated to ``max_points``).  An effect
    that explains the residual follows it; one found in noise would not.  ``title``
    and ``gps`` as :func:`plot_closure`.
    """
    from accal.closure.basis import Basis

    chans = _channels(result)
    effects = list(result.effects)
    path = Path(path)
    rows = max(len(effects), 1)
    fig = _figure((10, 2.6 * rows + 0.9))
    axes = fig.subplots(rows, len(chans), squeeze=False)
    if not effects:
        axes[0, 0].text(0.5, 0.5, "no effect found", ha="center", va="center")
        axes[0, 0].set_axis_off()
        if title:
            fig.suptitle(title, fontsize=10)
        fig.savefig(path, dpi=DPI)
        return path
    use = result.use
    bb = result.base_design
    base = Basis(bb.block[use], bb.columns[use], n_blocks=bb.n_blocks)
    j = result.n_base
    label = "time"
    for i, e in enumerate(effects):
        q = int(e.details.get("n_columns", 1))
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
            partial = result.residual_after[idx] + contrib[idx]
            factor, unit = accel_scale(partial)
            x, label = _time_axis(result.time[idx], gps)
            ax.plot(x, partial * factor, ".", ms=1, color="0.6")
            ax.plot(x, contrib[idx] * factor, lw=1.0, color="C3")
            lab = effect_label(e)
            if e.channel is not None and e.channel not in lab:
                lab += f" ({e.channel})"
            ax.set_title(lab if nm is None else f"{lab}, {nm}", fontsize=9)
            ax.set_ylabel(f"[{unit}]", fontsize=8)
            ax.grid(alpha=0.3)
            if i == rows - 1:
                ax.set_xlabel(label, fontsize=8)
    fig.suptitle(
        _heading(
            title, "partial residual (grey) and fitted effect (red), base model projected out"
        ),
        fontsize=10,
    )
    if gps:
        _dates(axes)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path
