"""Samples too far from their day to be accelerometer data (issue 23, finding 7).

The readers refuse a value beyond 1000 m/s² (:data:`accal.io.common.MAX_ABS_ACCELERATION`),
but a single damaged value below that limit passed: one ``lin_accl_z`` of 999 m/s² in a
GRACE day moved the z bias to 0.416 m/s², with exit status 0.  Here a sample is
*wild* when it is farther from its axis' median than both :data:`WILD_SIGMAS` robust
standard deviations (1.4826 × the median absolute deviation, Rousseeuw & Croux 1993) of
the day and :data:`WILD_FLOOR` (an electrostatic accelerometer's range is ~1e-4 to
1e-3 m/s²; thruster spikes and storms stay far below it).  Wild samples are flagged
invalid with a warning that counts them: their record (every axis: the validity mask is
per record) is left out of the fit and has ``valid = False`` in the calibrated series;
the data are not changed.

References
----------
.. [1] P. J. Rousseeuw & C. Croux, "Alternatives to the median absolute deviation",
   J. Am. Stat. Assoc. 88, 1273–1283 (1993).
"""

from __future__ import annotations

import numpy as np

from accal.series import AccSeries

__all__ = ["WILD_FLOOR", "WILD_SIGMAS", "flag_wild_samples"]

#: Robust standard deviations from the median beyond which a sample is wild.
WILD_SIGMAS = 1e4
#: ... and at least this far from the median [m/s²].
WILD_FLOOR = 1e-3


def flag_wild_samples(series: AccSeries) -> tuple[AccSeries, list[str]]:
    """``series`` with its wild samples flagged invalid, and one warning per axis that
    has any (module notes).

    Parameters
    ----------
    series : AccSeries
        A read day.

    Returns
    -------
    series : AccSeries
        The same data; ``valid`` False also at the wild samples.
    warnings : list of str
    """
    valid = series.valid.copy()
    warnings = []
    for k, ax in enumerate(series.axes):
        a = series.acc[:, k]
        ok = valid & np.isfinite(a)
        if ok.sum() < 3:
            continue
        med = float(np.median(a[ok]))
        mad = 1.4826 * float(np.median(np.abs(a[ok] - med)))
        limit = max(WILD_SIGMAS * mad, WILD_FLOOR)
        wild = ok & (np.abs(a - med) > limit)
        n = int(wild.sum())
        if n:
            i = int(np.flatnonzero(wild)[0])
            warnings.append(
                f"{n} sample(s) of {ax} more than {limit:.3g} m/s² from the day's median "
                f"({WILD_SIGMAS:g} robust sigma, at least {WILD_FLOOR:g} m/s²; the first "
                f"{a[i]:.6g} m/s² at gps_time {series.time[i]:.9g} s): flagged invalid"
            )
            valid &= ~wild
    if not warnings:
        return series, []
    return series.replace(valid=valid), warnings
