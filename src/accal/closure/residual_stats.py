"""Residual characterisation: what is left in a residual.

:func:`characterise`: gap-tolerant Welch PSD on the continuous segments
(:func:`continuous_segments`, :func:`welch_segments`), per-segment means,
low-frequency share, kurtosis (:class:`ResidualStats`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from accal.closure.distributions import excess_kurtosis
from accal.closure.noise_psd import estimate_psd, make_grid


@dataclass(frozen=True)
class ResidualStats:
    """What is left in a residual.

    Attributes
    ----------
    rms : float
        Root mean square [m/s²].
    kurtosis : float
        Excess kurtosis (0 for Gaussian; large values mean outliers/steps).
    freq : ndarray
        Frequencies of the Welch PSD [Hz].
    psd : ndarray
        One-sided Welch PSD averaged over continuous segments [(m/s²)²/Hz]; when
        no gap-free segment reaches ``nperseg``, Welch with the longest power-of-two
        window that fits one (≥ 256 samples), else the binned periodogram of the
        gapped residual on its nominal grid (first entry: frequency 0, PSD 0).
    segment_edges : ndarray
        Start times of the segments used for ``segment_means`` [s].
    segment_means : ndarray
        Mean residual per segment (per orbit when the orbit period is known) [m/s²].
    lowfreq_fraction : float
        Share of the residual variance below 1/(segment length) (slow structure).
    """

    rms: float
    kurtosis: float
    freq: NDArray[np.float64]
    psd: NDArray[np.float64]
    segment_edges: NDArray[np.float64]
    segment_means: NDArray[np.float64]
    lowfreq_fraction: float


def continuous_segments(t: NDArray[np.float64], step: float) -> list[slice]:
    """Slices of runs of samples without a gap (> 1.5 nominal steps)."""
    if t.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(t) > 1.5 * step) + 1
    starts = np.r_[0, breaks]
    stops = np.r_[breaks, t.size]
    return [slice(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def welch_segments(
    t: NDArray[np.float64], r: NDArray[np.float64], nperseg: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Welch PSD averaged over the continuous segments of at least ``nperseg`` samples.

    Returns ``(freq [Hz], psd [(m/s²)²/Hz])``, weighted by each segment's number of
    Welch windows; empty arrays when no segment is long enough.
    """
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    acc = None
    total = 0.0
    freq = np.zeros(0)
    for sl in continuous_segments(t, step):
        seg = r[sl]
        if seg.size < nperseg:
            continue
        # imported here: scipy.signal costs ~0.6 s, and a platform run's residual
        # (rests every period) has no segment long enough for Welch
        from scipy.signal import welch

        freq, p = welch(seg, fs=1.0 / step, nperseg=nperseg, detrend="constant")
        nwin = 1 + (seg.size - nperseg) // (nperseg // 2)
        acc = p * nwin if acc is None else acc + p * nwin
        total += nwin
    if acc is None:
        return np.zeros(0), np.zeros(0)
    return freq, acc / total


def characterise(
    t: NDArray[np.float64],
    r: NDArray[np.float64],
    *,
    segment: float | None = None,
    nperseg: int | None = None,
    chan: NDArray[np.int64] | None = None,
) -> ResidualStats:
    """Characterise a residual (used samples only).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times of the used samples [s].
    r : ndarray, shape (n,)
        Residual [m/s²].
    segment : float, optional
        Length of the segments for the segment means [s], e.g. the orbit period;
        default span/16.
    nperseg : int, optional
        Welch window length [samples]; default the largest power of two ≤ span/8
        (at least 64).
    chan : ndarray of int, shape (n,), optional
        Channel of each sample: the Welch PSD is averaged over the channels;
        segment means, RMS and kurtosis pool them.
    """

    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    span = float(t[-1] - t[0]) if t.size > 1 else 1.0
    t1 = t if chan is None else t[np.asarray(chan) == chan[0]]
    step = float(np.median(np.diff(t1))) if t1.size > 1 else 1.0
    if segment is None or not segment > 0:
        segment = span / 16.0
    if nperseg is None:
        nperseg = int(2 ** np.floor(np.log2(max(span / step / 8.0, 64))))
    if chan is None or int(np.max(chan, initial=0)) == 0:
        freq, psd = welch_segments(t, r, nperseg)
    else:
        freq, psd, tot = np.zeros(0), np.zeros(0), 0
        for c in np.unique(chan):
            m = chan == c
            f_c, p_c = welch_segments(t[m], r[m], nperseg)
            if f_c.size:
                freq = f_c
                psd = p_c if tot == 0 else psd + p_c
                tot += 1
        if tot:
            psd = psd / tot
    if freq.size == 0 and t.size > 16 and (chan is None or int(np.max(chan, initial=0)) == 0):
        # no gap-free stretch of span/8: Welch with the longest window that fits
        segs = continuous_segments(t, step)
        longest = max((sl.stop - sl.start for sl in segs), default=0)
        if longest >= 256:
            freq, psd = welch_segments(t, r, int(2 ** np.floor(np.log2(longest))))
    if freq.size == 0 and t.size > 16:
        # no gap-free stretch long enough for Welch (e.g. the rests of a rotating
        # platform): the gap-tolerant binned periodogram on the nominal grid
        grid = make_grid(t, None if chan is None else np.asarray(chan, dtype=np.int64))
        noise = estimate_psd(grid, r, np.zeros((grid.n_chan, grid.size // 2 + 1)), tilt=False)
        f = grid.freqs
        nb = noise.level.size
        cnt = np.bincount(noise.which[1:], minlength=nb)
        fc = np.bincount(noise.which[1:], weights=f[1:], minlength=nb) / np.maximum(cnt, 1)
        keep = cnt > 0
        freq = np.r_[0.0, fc[keep]]
        psd = np.r_[0.0, 2.0 * noise.level[keep] * grid.step]  # one-sided [(m/s²)²/Hz]
    edges = np.arange(t[0], t[-1] + segment, segment)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 1)
    counts = np.bincount(which, minlength=edges.size)
    sums = np.bincount(which, weights=r, minlength=edges.size)
    means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    var = float(np.mean(r**2)) if r.size else np.nan
    seg_var = float(np.nansum(counts * np.nan_to_num(means) ** 2) / max(r.size, 1))
    return ResidualStats(
        rms=float(np.sqrt(var)),
        kurtosis=excess_kurtosis(r) if r.size > 3 else np.nan,
        freq=freq,
        psd=psd,
        segment_edges=edges,
        segment_means=means,
        lowfreq_fraction=seg_var / var if var > 0 else 0.0,
    )
