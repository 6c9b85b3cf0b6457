"""Bias and drift of an archive over time, one figure (``accal plot DIRECTORY``).

A scientist looking at a mission archive wants the day-by-day bias and drift of each
axis with their error bars, one series per satellite and method, against UTC dates,
in units read at a glance (µm/s² for the bias, nm/s² per day for the drift) and with
a title that names the table.  The values come from the ``bias_drift`` table of an
``accal grace-bias`` output directory as written (SI: m/s², m/s³); only the plot
scales them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from accal.errors import AccalError
from accal.io.writers import atomic_path

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn (~0.4 s)
    from matplotlib.figure import Figure

#: Plot scales: the table's SI value times the factor gives the plotted unit.
BIAS_SCALE = (1e6, "µm/s²")
DRIFT_SCALE = (1e9 * 86400.0, "nm/s² per day")
#: More series than this in one panel are not told apart by colour.
MAX_SERIES = 12


def plot_bias_drift(table: pd.DataFrame, path: str | Path, *, source: str) -> Path:
    """Write :func:`bias_drift_figure` of ``table`` to a PNG, atomically.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of a ``bias_drift`` table (see :func:`bias_drift_figure`).
    path : str or Path
        The PNG to write (a complete file or none).
    source : str
        What the rows are (the table's path), for the title.

    Returns
    -------
    Path
        ``path``.
    """
    import matplotlib.pyplot as plt

    fig = bias_drift_figure(table, source=source)
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)
    return path


def bias_drift_figure(table: pd.DataFrame, *, source: str) -> Figure:
    """Bias and drift per axis against the date, with 1σ error bars.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of a ``bias_drift`` table (columns ``satellite``, ``date``, ``axis``,
        ``method``, ``bias``, ``bias_sigma``, ``drift``, ``drift_sigma``; SI units).
    source : str
        What the rows are (the table's path), for the title.

    Returns
    -------
    matplotlib.figure.Figure
        One row of panels per axis present, bias (µm/s², :data:`BIAS_SCALE`) left and
        drift (nm/s² per day, :data:`DRIFT_SCALE`) right; one series per satellite
        and method.

    Raises
    ------
    accal.errors.AccalError
        No row to plot, or more than :data:`MAX_SERIES` satellite/method series.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = table.dropna(subset=["date"])
    if rows.empty:
        raise AccalError(f"{source}: no row to plot (check the selection options)")
    series = sorted(
        {(str(s), str(m)) for s, m in zip(rows["satellite"], rows["method"], strict=True)}
    )
    if len(series) > MAX_SERIES:
        raise AccalError(
            f"{source}: {len(series)} satellite/method series in one figure (at most "
            f"{MAX_SERIES}); select some with --satellite or --method"
        )
    axes_names = [a for a in ("x", "y", "z") if (rows["axis"] == a).any()]
    fig, panels = plt.subplots(
        len(axes_names), 2, figsize=(11, 2.6 * len(axes_names) + 0.8), sharex=True, squeeze=False
    )
    for i, axis in enumerate(axes_names):
        on_axis = rows[rows["axis"] == axis]
        for j, (col, (factor, unit)) in enumerate((("bias", BIAS_SCALE), ("drift", DRIFT_SCALE))):
            ax = panels[i][j]
            for k, (sat, method) in enumerate(series):
                sel = on_axis[(on_axis["satellite"] == sat) & (on_axis["method"] == method)]
                if sel.empty:
                    continue
                sel = sel.sort_values("date")
                days = pd.to_datetime(sel["date"]).to_numpy()
                value = sel[col].to_numpy(dtype=float) * factor
                sigma = sel[f"{col}_sigma"].to_numpy(dtype=float) * factor
                ax.errorbar(
                    days, value, yerr=np.where(np.isfinite(sigma), sigma, 0.0),
                    fmt="o-", ms=3, lw=0.8, capsize=2, color=f"C{k % 10}",
                    label=f"{sat} {method}",
                )  # fmt: skip
            ax.set_ylabel(f"{col} {axis} [{unit}]")
            ax.grid(alpha=0.3)
            ax.ticklabel_format(axis="y", useOffset=False)
    for ax in panels[-1]:
        ax.set_xlabel("date")
    panels[0][1].legend(fontsize=8, loc="best")
    first, last = str(rows["date"].min()), str(rows["date"].max())
    fig.suptitle(f"bias and drift, {first} to {last}, ± 1σ\n{source}", fontsize=10)
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig
