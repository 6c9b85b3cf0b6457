"""An output directory's table over time, one figure (``accal plot DIRECTORY``).

A scientist looking at a mission archive wants the day-by-day bias and drift of each
axis with their error bars, one series per satellite and method, against UTC dates,
in units read at a glance (µm/s² for the bias, nm/s² per day for the drift) and with
a title that names the table.  The values come from the ``bias_drift`` table of an
``accal grace-bias`` output directory as written (SI: m/s², m/s³); only the plot
scales them.  In an ``accal demod`` directory the ``periods`` table is plotted
instead: the unbiased accelerations a_Y, a_Z of every period with their σ, one series
per run, against the period's mid-time (UTC), in the SI prefix that suits them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from accal.errors import AccalError
from accal.io.writers import atomic_path
from accal.plot_style import accel_scale

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
    return _save(bias_drift_figure(table, source=source), path)


def plot_periods(table: pd.DataFrame, path: str | Path, *, source: str) -> Path:
    """Write :func:`periods_figure` of ``table`` to a PNG, atomically (as
    :func:`plot_bias_drift`)."""
    return _save(periods_figure(table, source=source), path)


def _save(fig: Figure, path: str | Path) -> Path:
    """``fig`` as a PNG at ``path`` (a complete file or none), then closed."""
    import matplotlib.pyplot as plt

    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)
    return path


def periods_figure(table: pd.DataFrame, *, source: str) -> Figure:
    """a_Y and a_Z of every demodulation period against its mid-time, with 1σ bars.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of an ``accal demod`` ``periods`` table (columns ``source``,
        ``t_mid_utc``, ``a_Y``, ``a_Z``, ``sigma_Y``, ``sigma_Z``; SI units).
    source : str
        What the rows are (the table's path), for the title.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels (a_Y, a_Z) sharing the time axis; one series per run.

    Raises
    ------
    accal.errors.AccalError
        No period to plot, or more than :data:`MAX_SERIES` runs.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = table.dropna(subset=["t_mid_utc"])
    if rows.empty:
        raise AccalError(f"{source}: no period to plot")
    runs = sorted({str(s) for s in rows["source"]})
    if len(runs) > MAX_SERIES:
        raise AccalError(
            f"{source}: {len(runs)} runs in one figure (at most {MAX_SERIES}); plot a "
            "directory with fewer runs, or use accal table --export and your own plot"
        )
    values = rows[["a_Y", "a_Z"]].to_numpy(dtype=float)
    factor, unit = accel_scale(values)
    fig, panels = plt.subplots(2, 1, figsize=(11, 6.0), sharex=True, squeeze=False)
    for i, comp in enumerate(("Y", "Z")):
        ax = panels[i][0]
        for k, run in enumerate(runs):
            sel = rows[rows["source"].astype(str) == run].sort_values("t_mid_utc")
            when = pd.to_datetime(sel["t_mid_utc"]).dt.tz_localize(None).to_numpy()
            value = sel[f"a_{comp}"].to_numpy(dtype=float) * factor
            sigma = sel[f"sigma_{comp}"].to_numpy(dtype=float) * factor
            ax.errorbar(
                when, value, yerr=np.where(np.isfinite(sigma), sigma, 0.0),
                fmt="o-", ms=2, lw=0.6, capsize=1.5, color=f"C{k % 10}", label=run,
            )  # fmt: skip
        ax.set_ylabel(f"a_{comp} [{unit}]")
        ax.grid(alpha=0.3)
        ax.ticklabel_format(axis="y", useOffset=False)
    panels[-1][0].set_xlabel("period mid-time (UTC)")
    panels[0][0].legend(fontsize=8, loc="best")
    first, last = rows["t_mid_utc"].min(), rows["t_mid_utc"].max()
    fig.suptitle(
        f"unbiased accelerations per period, {first:%Y-%m-%d %H:%M} to {last:%Y-%m-%d %H:%M} "
        f"UTC, ± 1σ\n{source}",
        fontsize=10,
    )
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig


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
    dates = pd.to_datetime(rows["date"])
    if dates.nunique() == 1:  # one day: a week around it, not matplotlib's years
        one = dates.iloc[0]
        panels[-1][0].set_xlim(one - pd.Timedelta(days=3), one + pd.Timedelta(days=3))
    panels[0][1].legend(fontsize=8, loc="best")
    first, last = str(rows["date"].min()), str(rows["date"].max())
    fig.suptitle(f"bias and drift, {first} to {last}, ± 1σ\n{source}", fontsize=10)
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig
