"""Local maxima of a sampled curve and their topographic prominence.

The definitions are those of :func:`scipy.signal.find_peaks` and
:func:`scipy.signal.peak_prominences` (without a window), and the tests check the
result against them on random curves with plateaus.  Importing ``scipy.signal`` on the
closure path costs 0.34 s of start-up (it brings ``scipy.stats``; ``python -X
importtime``), 7 % of a platform day's 5 s budget, for one call on a few thousand
points; the same reason keeps :func:`accal.closure.couplings.first_order` and
:mod:`accal.closure.distributions` off ``scipy.signal`` and ``scipy.stats``.

* A peak is a sample, or the middle (rounded down) of a run of equal samples, with
  a lower neighbour on each side; the first and last samples are never peaks.
* Its prominence is its height above the higher of its two bases, each the lowest
  sample between the peak and the nearest strictly higher sample on that side (or
  the curve's end): ``p = x[k] − max(min x(j_L..k), min x(k..j_R))`` (Llobera,
  *Building past landscape perception with GIS*, Internet Archaeology 10, 2001; the
  definition SciPy documents).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["local_maxima", "prominences", "prominent_peaks"]


def local_maxima(x: NDArray[np.float64]) -> NDArray[np.int64]:
    """Indices of the local maxima of ``x`` (plateaus at their middle, rounded down)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, x[1:] != x[:-1]])  # runs of equal samples
    ends = np.r_[starts[1:] - 1, x.size - 1]
    v = x[starts]
    peak = np.zeros(starts.size, dtype=bool)
    peak[1:-1] = (v[1:-1] > v[:-2]) & (v[1:-1] > v[2:])
    return ((starts[peak] + ends[peak]) // 2).astype(np.int64)


def _nearest_higher(x: NDArray[np.float64]) -> NDArray[np.int64]:
    """For each sample, the index of the nearest strictly higher sample before it (−1:
    none), by a monotonic stack (each index pushed and popped once)."""
    out = np.full(x.size, -1, dtype=np.int64)
    stack: list[int] = []
    for i, v in enumerate(x.tolist()):
        while stack and x[stack[-1]] <= v:
            stack.pop()
        if stack:
            out[i] = stack[-1]
        stack.append(i)
    return out


def prominences(x: NDArray[np.float64], peaks: NDArray[np.int64]) -> NDArray[np.float64]:
    """The prominence of each of ``peaks`` in ``x`` (module notes)."""
    x = np.asarray(x, dtype=np.float64)
    peaks = np.asarray(peaks, dtype=np.int64)
    if not peaks.size:
        return np.zeros(0)
    left = _nearest_higher(x)[peaks] + 1
    right = x.size - 2 - _nearest_higher(x[::-1])[x.size - 1 - peaks]
    base = [
        max(x[a : k + 1].min(), x[k : b + 1].min())
        for a, k, b in zip(left, peaks, right, strict=True)
    ]
    return x[peaks] - np.asarray(base, dtype=np.float64)


def prominent_peaks(x: NDArray[np.float64], prominence: float) -> NDArray[np.int64]:
    """Indices of the local maxima of ``x`` whose prominence is at least ``prominence``
    (``scipy.signal.find_peaks(x, prominence=prominence)[0]``)."""
    peaks = local_maxima(x)
    return peaks[prominences(x, peaks) >= prominence]
