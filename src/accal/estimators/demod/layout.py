"""Rotation layout of the periods: does the pattern repeat every τ?

The shift of each period's masked samples against the periods before it gives
``rotation_shift``, ``pattern_periods`` and ``rotation_shift_steady`` of
:class:`DemodResult` (a ``--tau`` that does not match the pattern).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: Period lags at which rotation layouts are compared (a pattern of up to this many τ).
LAYOUT_LAGS = 4
#: Fraction of period pairs that must agree for a layout to count as repeating.
LAYOUT_AGREE = 0.9


def _layout_shifts(rest: NDArray, prev: NDArray | None) -> tuple[dict[int, NDArray], NDArray]:
    """Shift of each period's rotation layout against the periods before it [samples].

    The circular cross-correlation of the masked samples (``~rest``) of two
    periods peaks at the shift ``d`` by which the rotations moved: at lag 1, 0
    when the pattern repeats every τ, ``d`` when it repeats every ``τ + d/fs``.
    Circular, so a rotation that leaves the end of a period and comes back at
    its start does not break the estimate.  Lags up to :data:`LAYOUT_LAGS` tell a
    ``--tau`` that is a fraction of the pattern's period (layouts that differ
    from one period to the next but repeat every m periods).

    Parameters
    ----------
    rest : ndarray of bool, shape (P, q)
        Rest masks of consecutive periods.
    prev : ndarray of complex or None
        Spectra of the masks of the (up to :data:`LAYOUT_LAGS`) periods before the
        first one (from the previous block).

    Returns
    -------
    shifts : dict of int to ndarray of int
        Per lag ``m``: one shift per pair (period, period − m) whose later period
        is in ``rest``, in ``(-q/2, q/2]``.
    last : ndarray of complex
        Spectra of the last periods' masks (``prev`` of the next block).
    """
    q = rest.shape[1]
    spec = np.fft.rfft((~rest).astype(np.float64), axis=1)
    n_prev = 0 if prev is None else prev.shape[0]
    if prev is not None:
        spec = np.concatenate([prev, spec])
    out: dict[int, NDArray] = {}
    for lag in range(1, LAYOUT_LAGS + 1):
        i = np.arange(max(n_prev, lag), spec.shape[0])
        if not i.size:
            out[lag] = np.empty(0, np.int64)
            continue
        xc = np.fft.irfft(spec[i] * np.conj(spec[i - lag]), n=q, axis=1)
        shift = np.argmax(np.round(xc, 6), axis=1)  # rounding: ties (no rotation) go to 0
        out[lag] = np.where(shift > q // 2, shift - q, shift).astype(np.int64)
    return out, spec[-LAYOUT_LAGS:]


def _pattern_of_shifts(shifts: dict[int, list[NDArray]]) -> tuple[float, int, bool]:
    """(median lag-1 shift [samples], pattern_periods, steady) of :class:`DemodResult`."""
    lag1 = np.concatenate(shifts[1]) if shifts[1] else np.empty(0, np.int64)
    if not lag1.size:
        return float("nan"), 0, False
    med = float(np.median(lag1))
    steady = bool(np.mean(np.abs(lag1 - med) <= 1) >= LAYOUT_AGREE)
    for lag in range(1, LAYOUT_LAGS + 1):
        d = np.concatenate(shifts[lag]) if shifts[lag] else np.empty(0, np.int64)
        if d.size and np.mean(d == 0) >= LAYOUT_AGREE:
            return med, lag, steady
    return med, 0, steady
