"""What every accal plot shares: acceleration units a reader takes in at a glance, and
long series drawn as a binned mean inside its envelope.

Used by :mod:`accal.products.archive_plot` (``accal plot``) and
:mod:`accal.closure.report` (the ``--close-loop --plots`` figures).  numpy only:
matplotlib is imported by the modules that draw.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ACCEL_SCALES", "accel_scale", "envelope"]

#: SI prefixes of an acceleration axis: (factor, unit); :func:`accel_scale` takes the
#: first in which the largest value reaches 1.
ACCEL_SCALES = ((1.0, "m/s²"), (1e3, "mm/s²"), (1e6, "µm/s²"), (1e9, "nm/s²"), (1e12, "pm/s²"))


def accel_scale(values: ArrayLike) -> tuple[float, str]:
    """The :data:`ACCEL_SCALES` entry in which the largest finite ``|values|`` is ≥ 1.

    Parameters
    ----------
    values : array_like
        Accelerations [m/s²] (NaN ignored).

    Returns
    -------
    factor : float
        Multiply the values [m/s²] by it to plot them in ``unit``.
    unit : str
        E.g. ``"nm/s²"``; the smallest (``pm/s²``) when all values are below 1 pm/s².
    """
    v = np.asarray(values, dtype=float).ravel()
    finite = np.abs(v[np.isfinite(v)])
    top = float(finite.max()) if finite.size else 0.0
    for factor, unit in ACCEL_SCALES:
        if top * factor >= 1.0:
            return factor, unit
    return ACCEL_SCALES[-1]


def envelope(x: ArrayLike, y: ArrayLike, bins: int = 1500) -> tuple[NDArray[np.float64], ...]:
    """A long series as ``bins`` equal intervals of ``x``: mean, minimum and maximum.

    An 86,400-point day drawn sample by sample is a solid block at print size; its mean
    per interval with the band between the interval's extremes shows the same
    excursions (none is lost to decimation) and the level the eye should read.  Empty
    intervals (gaps) are NaN, so lines and bands break there.

    Parameters
    ----------
    x : array_like
        Increasing abscissae (e.g. seconds).
    y : array_like
        Values at ``x`` (NaN ignored).
    bins : int
        Number of intervals; a series with at most ``2·bins`` points is returned as it
        is (``lo = hi = mean = y``).

    Returns
    -------
    centre, mean, lo, hi : ndarray
        Interval centres (in ``x``'s unit) and the statistics of ``y`` per interval.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size <= 2 * bins or x[-1] <= x[0]:
        return x, y, y, y
    edges = np.linspace(x[0], x[-1], bins + 1)
    k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
    n = np.bincount(k, minlength=bins).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(k, weights=y, minlength=bins) / n
    lo = np.full(bins, np.inf)
    hi = np.full(bins, -np.inf)
    np.minimum.at(lo, k, y)
    np.maximum.at(hi, k, y)
    empty = n == 0
    mean[empty] = lo[empty] = hi[empty] = np.nan
    return 0.5 * (edges[:-1] + edges[1:]), mean, lo, hi
