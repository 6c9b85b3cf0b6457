"""The CRN-like low-pass of Level-1B accelerometer data, for other channels too.

The GRACE / GRACE-FO Level-1B processing low-passes the 10 Hz accelerometer data with
a CRN filter (cascaded rectangular windows) before decimating them to the 1 Hz
ACC1B / ACT1B products [1]_: all that the instrument measured is filtered, the signal
and any instrument effect alike (a bias step becomes a ramp over the filter's
window).  Housekeeping (AHK1B temperatures, ``--aux`` tables) is not.  An effect of a
temperature on the acceleration is therefore seen through the filter: fitted to the
unfiltered channel, the channel's read-out noise and sharp corners are a mismatch that
a one-pole low-pass in the coupling model "explains" by a time constant τ while it
shifts the lag by −τ (the lag z-scores of `make closure-detection`, 24 days per size:
RMS 3.5 with the channel as read, 1.3 with it through :func:`smooth_channel`).

The stand-in used here, ``CRN_ORDER`` boxcars of ``CRN_BOXCAR`` s (amplitude response
``(sin(πfLΔ)/(L sin(πfΔ)))^CRN_ORDER``, ``L`` samples per boxcar at step ``Δ``; −3 dB
at 35 mHz, first zero at 0.2 Hz), was fitted to the first and second differences of
the real samples (:mod:`accal.simulate.grace_noise`), not taken from the processing;
applied with zero phase, as the processing's symmetric filter is.

.. [1] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product User
   Handbook, JPL D-22027 (ACC1B columns; the CRN filter of the Level-1B processing).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft

__all__ = ["CRN_BOXCAR", "CRN_ORDER", "crn_smooth", "is_level1b", "smooth_channel"]

#: CRN-like low-pass: ``CRN_ORDER`` cascaded boxcars of ``CRN_BOXCAR`` seconds.
CRN_BOXCAR, CRN_ORDER = 5.0, 7


def crn_smooth(x: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
    """The CRN-like low-pass along axis 0, zero phase, same length.

    The cascade's frequency response ``(sin(πfLΔ) / (L sin(πfΔ)))^CRN_ORDER`` (``L``
    boxcar samples, ``Δ = dt``) is applied by FFT to the record extended at both ends
    by its odd reflection about the end samples (``2 x[0] − x[k]``: constants and
    linear trends pass unchanged).  With ``L < 2`` ``x`` is returned unchanged.

    Parameters
    ----------
    x : ndarray, shape (n, ...)
        Uniformly sampled values.
    dt : float
        Sampling step [s].

    Returns
    -------
    ndarray
        The filtered values, the shape of ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    length = int(round(CRN_BOXCAR / dt))
    n = x.shape[0]
    if length < 2 or n < 3:
        return x
    m = min(n - 1, 2 * CRN_ORDER * length)
    xp = np.concatenate([2 * x[:1] - x[m:0:-1], x, 2 * x[-1:] - x[-2 : -m - 2 : -1]], axis=0)
    size = sfft.next_fast_len(xp.shape[0], real=True)
    f = sfft.rfftfreq(size)  # cycles per sample
    h = np.ones_like(f)
    nz = f > 0
    h[nz] = np.sin(np.pi * f[nz] * length) / (length * np.sin(np.pi * f[nz]))
    h = h**CRN_ORDER
    y = sfft.irfft(sfft.rfft(xp, n=size, axis=0) * h.reshape((-1,) + (1,) * (x.ndim - 1)),
                   n=size, axis=0)  # fmt: skip
    return y[m : m + n]


def smooth_channel(t: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """A channel on the data's times through :func:`crn_smooth`, gaps and NaN allowed.

    The values are placed on a uniform grid of the median step (linear interpolation
    over missing samples and NaN, the ends held), filtered, and read back at ``t``;
    samples that were NaN stay NaN.  A channel with fewer than 3 finite values, or
    times that are not increasing, is returned as given.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Increasing sample times [s].
    x : ndarray, shape (n,)
        The channel's values there.

    Returns
    -------
    ndarray, shape (n,)
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x) & np.isfinite(t)
    if ok.sum() < 3 or t.size < 3 or not np.all(np.diff(t) > 0):
        return x
    dt = float(np.median(np.diff(t)))
    n_grid = int(round((t[-1] - t[0]) / dt)) + 1
    if n_grid > 4 * t.size:  # a few samples spread over a long span: nothing to smooth
        return x
    grid = t[0] + dt * np.arange(n_grid)
    y = crn_smooth(np.interp(grid, t[ok], x[ok]), dt)
    out = np.interp(t, grid, y)
    out[~np.isfinite(x)] = np.nan
    return out


def is_level1b(meta: dict[str, Any]) -> bool:
    """Whether a series' metadata (:attr:`accal.series.AccSeries.meta`) says it was read
    from a GRACE or GRACE-FO Level-1B accelerometer file (CRN-filtered data)."""
    return "grace" in meta or "gracefo" in meta
