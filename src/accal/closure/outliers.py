"""Outliers: bursts and spikes no candidate models, left out of the closure's analysis.

The tests assume Gaussian noise; a burst of 50 samples of 5e-8 m/s² in 1e-10 noise
was fitted as two bias steps (their least-squares area), and thruster firings put
spikes of 1e-8–1e-7 m/s² into a raw record, with pulses of the angular
accelerations at the same samples: real acceleration, which a coupling to the
angular channels then "explained" (a 0.5 mm lever arm removed from a simulated
storm day) and a pair of steps boxed.  Samples far from the running median of the
residual around them, or of any candidate channel, are left out of the analysis
(and stay in the data).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter

__all__ = [
    "EDGE_STEP_MAX_SIGMAS",
    "OUTLIER_MAX_FRACTION",
    "OUTLIER_PAD",
    "OUTLIER_SIGMAS",
    "OUTLIER_WINDOW",
    "SPIKE_WINDOW",
    "edge_runs",
    "outliers",
    "spikes",
]

#: Largest offset [robust σ of the first differences] of a run of flagged samples at the
#: record's start or end that is kept as a possible bias step rather than left out: at
#: the record's end a step and a burst fit alike (the burst's other edge is outside the
#: record); instrument bias steps are tens of σ, bursts and spikes hundreds to thousands.
EDGE_STEP_MAX_SIGMAS = 200.0
#: Fewest samples of such a run.
EDGE_STEP_MIN = 10

#: Outliers: samples this many robust σ (1.4826 MAD) from the residual's running median.
OUTLIER_SIGMAS = 10.0
#: Running-median window [samples].
OUTLIER_WINDOW = 241
#: Largest fraction of a channel's samples that may be outliers (more is structure,
#: e.g. a strong high-frequency line).  Attitude-thruster firings take up to ~1 % of a
#: GRACE day (2-6 an hour, 1-5 s each).
OUTLIER_MAX_FRACTION = 0.02
#: Samples on either side of a flagged one also left out (a firing's ramp and tail).
OUTLIER_PAD = 2
#: Centred running-median window of :func:`spikes` [samples]: over twice the longest
#: thruster pulse (1-5 s at 1 Hz), so a pulse never makes the median.
SPIKE_WINDOW = 15
#: Samples on either side of a flagged run whose level tells a burst from a step.
LEVEL_SAMPLES = 60


def outliers(
    r: NDArray[np.float64], chan: NDArray[np.int64] | None, t: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Samples of the base residual ``r`` far from the residual around them (each channel).

    A burst of 50 samples of 5e-8 m/s² in 1e-10 noise was fitted as two bias steps
    of ±2.9e-9 m/s² (the steps' least-squares area); the Wald tests assume Gaussian
    noise.  The level around a sample is the running median of the
    :data:`OUTLIER_WINDOW` samples before it and of those after it; the deviation
    is the smaller of the two (only the one that fits inside the segment at its
    ends), so a step's edge is never an outlier, a burst shorter than the window
    is one anywhere (also at the record's ends, where a centred median followed
    it), and the running medians never reach across a data gap.  Flagged samples
    are left out of the analysis (the caller keeps them in the data).  Nothing is
    flagged when more than :data:`OUTLIER_MAX_FRACTION` of a channel would be.
    """
    w = OUTLIER_WINDOW
    bad = np.zeros(r.size, dtype=bool)
    for idx in _channel_groups(chan, r.size):
        if idx.size < 4 * w:
            continue
        x, tt = r[idx], t[idx]
        steps = np.diff(tt)
        cut = np.flatnonzero(steps > 5.0 * np.median(steps)) + 1  # data gaps
        dev = np.full(x.size, np.inf)  # from each side's median
        dev_line = np.full(x.size, np.inf)  # from each side's line (_side_levels)
        # a segment too short to tell an outlier from structure: none flagged
        segs = [seg for seg in np.split(np.arange(x.size), cut) if seg.size >= 2 * w]
        if segs:
            at = np.concatenate(segs)
            pos = np.concatenate([np.arange(seg.size) for seg in segs])
            back = np.concatenate([np.arange(seg.size)[::-1] for seg in segs])
            levels = _segment_medians(x, segs, w, (w // 2, -(w // 2)))
            lines = _side_levels(x, segs, w, pos, back, levels)
            for out, (lo, hi) in ((dev, levels), (dev_line, lines)):
                left, right = np.abs(x[at] - lo), np.abs(x[at] - hi)
                # near a segment's start the left window is not inside it, near its end
                # the right
                out[at] = np.where(
                    pos < w - 1, right, np.where(back < w - 1, left, np.minimum(left, right))
                )
        finite = np.isfinite(dev)
        if finite.sum() < 2 * w:
            continue
        sig = 1.4826 * float(np.median(dev[finite]))  # dev >= 0: MAD about 0
        if not sig > 0:
            continue
        hit = finite & (dev > OUTLIER_SIGMAS * sig)
        if segs:  # a sloped stretch inside a segment is no outlier (_on_lines)
            hit = _on_lines(hit, dev_line, OUTLIER_SIGMAS * sig, at, pos, back, w)
        hit = _bursts_only(hit, x)
        if 0 < hit.sum() <= OUTLIER_MAX_FRACTION * idx.size:
            pad = np.convolve(hit, np.ones(2 * OUTLIER_PAD + 1), mode="same") > 0
            bad[idx[pad]] = True
    return bad


def _on_lines(hit, dev_line, limit, at, pos, back, w):
    """``hit`` without its runs that lie on a side's robust line (:func:`_side_levels`).

    A run of flagged samples whose every sample is within ``limit`` of the line of one
    side, and which lies inside its segment (at least ``w − 1`` samples from either
    end), is a sloped stretch that a median lags, not a burst: the samples after a
    large step, where the null model's partial fit leaves a slope (a QA helper's
    GRACE-A day: 114 samples after a 1e-8 m/s² step left out with the step's edge,
    and the step was not found).  Runs are judged whole: unflagging part of a run
    changed what :func:`edge_runs` and :func:`_bursts_only` make of the rest (a
    noise-free exponential's start), and at a segment's ends the lines did not make
    the screen more right but changed what it left out (the start of a QA day's drag
    axis, after which a 2.4e-8 ± 4e-9 m/s² "step" on that axis passed the scan).
    """
    inside = np.zeros(hit.size, bool)
    inside[at] = (pos >= w - 1) & (back >= w - 1)
    out = hit.copy()
    edges = np.flatnonzero(np.diff(np.r_[0, hit.astype(np.int8), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if inside[a:b].all() and np.all(dev_line[a:b] <= limit):
            out[a:b] = False
    return out


def _side_levels(x, segs, w, pos, back, levels):
    """The line each side of every sample sets for it, for :func:`outliers`.

    Each side's robust line, carried to the sample: the medians of the two half
    windows (``h = (w + 1) // 2`` samples each) nearest the sample on that side give
    a level and a slope (a two-point Theil-type line; the medians' noise is ~0.1 of
    the samples' σ each, so the line's at the sample ~0.15σ), evaluated at the
    sample.  One median of ``w`` samples, used before, lags a sloped residual by
    ``slope × w/2``: the null model's partial fit of a large step leaves a slope on
    both sides of it, and the samples after a 1e-8 m/s² step on a quiet axis (QA
    helper's GRACE-A day, residual 6e-10 m/s² RMS) were 10σ off the median after
    them: 114 samples left out, the step's edge with them, and the step was not
    found (:func:`_on_lines` gives such runs back).  Where a side's far half window
    is not inside the segment, the line is that side's median of ``w`` samples
    (``levels``, the one-sided medians :func:`outliers` has).  Aligned with the
    segments' concatenation.
    """
    h = (w + 1) // 2
    lo_w, hi_w = levels
    near_l, near_r = _segment_medians(x, segs, h, (h // 2, -(h // 2)))
    k = np.arange(pos.size)
    far_l = np.where(pos >= h, near_l[np.maximum(k - h, 0)], np.nan)
    far_r = np.where(back >= h, near_r[np.minimum(k + h, k.size - 1)], np.nan)
    c = 0.5 * (h - 1)  # a half window's centre, from the sample
    lo = near_l + (near_l - far_l) / h * c
    hi = near_r - (far_r - near_r) / h * c
    lo = np.where(np.isfinite(lo), lo, lo_w)
    hi = np.where(np.isfinite(hi), hi, hi_w)
    return lo, hi


def spikes(
    r: NDArray[np.float64], chan: NDArray[np.int64] | None, t: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Short pulses of ``r`` (each channel), found before any signal model is fitted.

    :func:`outliers` works on the residual of the null model; with the orbit-phase
    template in it, a pulse leaks into the fit of its phase bin, i.e. into the same
    phase of every other orbit (~15 "ghosts" per pulse sample).  On a GRACE-FO day
    without angular accelerations (ACT1B) the 128 thruster pulses and their ghosts were
    5 % of the record: above :data:`OUTLIER_MAX_FRACTION`, nothing was left out, and
    the firings came out as bias steps (QA, closure-detection storm days).  This
    screen needs no model: the deviation from a centred running median of
    :data:`SPIKE_WINDOW` samples, which follows any monotone stretch exactly (steps,
    eclipse ramps, drag) and a smooth extremum to its curvature × window², while a
    pulse shorter than half the window stays out of the median.  Flagged: more than
    :data:`OUTLIER_SIGMAS` robust σ from the centred median and from both sides'
    lines (the median of the window ending at the sample, carried to it along the
    median of that window's first differences; likewise from the window starting
    there): a step's edge is at the level of one side, and a kink (a slope that turns
    at a sample) on the line of both.  The one-sided medians alone lag by slope × 7
    samples: an in-period quadratic bias on a rotating platform turns its slope at every
    period's start, and the 963 samples there were taken for spikes (QA helper's run
    q11; the periods they cut then left the table).  Requiring a sample off one side's
    line only as well as off both medians was tried: it took the kinks again on 5 of 12
    ``tests/indep`` platform runs with an in-period quadratic (the carried lines'
    noise).  In very smooth noise the few samples at a step's edge can still be
    flagged: they are left out, the step is not.  At most
    :data:`OUTLIER_MAX_FRACTION` of a channel, padded by :data:`OUTLIER_PAD`; never
    across a data gap.  The robust σ is 1.4826 × the median of the non-zero centred
    deviations.  Not the MAD of all: L1B data are CRN-filtered, smooth from sample to
    sample, and the median follows every monotone stretch exactly, so most deviations
    are 0 and the MAD is 0 (a GRACE-FO day: 11 % of the samples "more than 10 MADs"
    off); the non-zero ones are the noise's wiggles at its local extrema, the scale a
    pulse must stand out of (a 95th-percentile scale was ~10× smaller on smooth noise
    and flagged 2.6 % of a pulse-free record).
    """
    w = SPIKE_WINDOW
    bad = np.zeros(r.size, dtype=bool)
    for idx in _channel_groups(chan, r.size):
        x, tt = r[idx], t[idx]
        steps = np.diff(tt)
        if steps.size < 4 * w:
            continue
        cut = np.flatnonzero(steps > 5.0 * np.median(steps)) + 1  # data gaps
        dev = np.full(x.size, np.nan)
        side = np.full(x.size, np.nan)
        segs = [seg for seg in np.split(np.arange(x.size), cut) if seg.size >= 2 * w]
        if segs:
            at = np.concatenate(segs)
            mid, lo, hi = _segment_medians(x, segs, w, (0, w // 2, -(w // 2)))
            # each side's level carried to the sample along that side's slope
            dx = np.concatenate(
                [np.diff(x[seg], prepend=2 * x[seg[0]] - x[seg[1]]) for seg in segs]
            )
            ends = np.cumsum([0] + [seg.size for seg in segs])
            dsegs = [np.arange(a, b) for a, b in zip(ends[:-1], ends[1:], strict=True)]
            dlo, dhi = _segment_medians(dx, dsegs, w, (w // 2, -(w // 2)))
            lo = lo + (w // 2) * dlo
            hi = hi - (w // 2) * dhi
            dev[at] = np.abs(x[at] - mid)
            side[at] = np.minimum(np.abs(x[at] - lo), np.abs(x[at] - hi))
        finite = np.isfinite(dev)
        if finite.sum() < 4 * w:
            continue
        moved = dev[finite & (dev > 0)]
        sig = 1.4826 * float(np.median(moved)) if moved.size > 4 * w else 0.0
        if not sig > 0:
            continue
        # off the centred median *and* off both one-sided ones (a step's edge fits one side)
        hit = _pulses_only(finite & (np.minimum(dev, side) > OUTLIER_SIGMAS * sig), x, tt)
        if 0 < hit.sum() <= OUTLIER_MAX_FRACTION * idx.size:
            pad = np.convolve(hit, np.ones(2 * OUTLIER_PAD + 1), mode="same") > 0
            bad[idx[pad]] = True
    return bad


def _channel_groups(chan: NDArray[np.int64] | None, n: int) -> list[NDArray[np.int64]]:
    """Sample indices of each channel (all samples when there is one)."""
    if chan is None:
        return [np.arange(n)]
    return [np.flatnonzero(chan == c) for c in np.unique(chan)]


def _segment_medians(
    x: NDArray[np.float64], segs: list[NDArray[np.int64]], w: int, origins: tuple[int, ...]
) -> list[NDArray[np.float64]]:
    """Running medians of ``w`` samples of ``x`` within each segment, for each origin.

    ``segs``: increasing, contiguous index runs of ``x``; each result is aligned with
    their concatenation.  Origin 0: centred; ``w // 2``: the window ending at the
    sample; ``−(w // 2)``: the one starting there (:func:`scipy.ndimage.median_filter`'s
    convention), ``mode="nearest"`` at each segment's ends.  One filter call per origin:
    the segments laid end to end with ``w`` copies of each one's first and last value
    around it, so no window reaches another segment and every median is the one of
    the segment alone, bit for bit (a rotating platform's residual has a segment per
    period: 3,500 calls took 0.3 s).
    """
    parts, starts = [], []
    pos = 0
    for seg in segs:
        xs = x[seg]
        parts += [np.full(w, xs[0]), xs, np.full(w, xs[-1])]
        starts.append(pos + w)
        pos += xs.size + 2 * w
    laid = np.concatenate(parts)
    take = np.concatenate([np.arange(a, a + seg.size) for a, seg in zip(starts, segs, strict=True)])
    return [median_filter(laid, size=w, origin=o, mode="nearest")[take] for o in origins]


def _bursts_only(hit: NDArray[np.bool_], x: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``hit`` without the runs that are a change of level rather than a burst.

    A burst returns to the level before it; around a step the flagged run sits at the
    level of one side and the two sides differ (QA: a step 300 s before the record's
    end, seen from the one running median that fits there, was left out as 124
    outliers and found 244 s late).  A run whose sides (:data:`LEVEL_SAMPLES` unflagged
    samples each) differ by more than half the run's offset from either side is kept.
    Runs less than :data:`OUTLIER_PAD` × 2 + 1 samples apart (one run once padded) are
    judged as one: a 1e-8 m/s² step on a quiet axis was flagged as two runs 2 samples
    apart (the 130 s before its ramp and the ramp's lower half, on the slope the null
    model's partial fit of the step leaves), each with the other's samples for a side,
    and left out (``tests.indep`` seed 7411: the step placed 11 s late, its size 0.6σ
    small).
    """
    joined = hit.copy()
    idx = np.flatnonzero(hit)
    if idx.size > 1:
        gaps = np.flatnonzero((np.diff(idx) > 1) & (np.diff(idx) <= 2 * OUTLIER_PAD + 1))
        for g in gaps:
            joined[idx[g] : idx[g + 1]] = True
    edges = np.flatnonzero(np.diff(np.r_[0, joined.astype(np.int8), 0]))
    out = hit.copy()
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        before = x[max(0, a - LEVEL_SAMPLES) : a][~joined[max(0, a - LEVEL_SAMPLES) : a]]
        after = x[b : b + LEVEL_SAMPLES][~joined[b : b + LEVEL_SAMPLES]]
        if before.size < 5 or after.size < 5:
            continue  # at a segment's end: edge_runs decides
        mb, ma, mr = np.median(before), np.median(after), np.median(x[a:b])
        if abs(ma - mb) > 0.5 * max(abs(mr - ma), abs(mr - mb)):
            out[a:b] = False
    return out


def _pulses_only(
    hit: NDArray[np.bool_], x: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """``hit`` of :func:`spikes` without the runs that are a step's edge on a slope.

    On the raw signal's slope (the drag changes by ~2.5e-10 m/s² a second in a storm's
    decline), the sample after an upward step is above both one-sided medians (they
    lag by slope × 7 samples): `accal simulate` storm day, a 3e-9 m/s² step on x left
    out with its neighbours, so the step's edge, which tells it from the signal
    (:mod:`accal.closure.jumps`), was gone.  A pulse returns to the line it left; a
    step does not: lines are fitted to :data:`LEVEL_SAMPLES` unflagged samples before
    and after the run and evaluated at the run's samples, and a run is kept for the
    analysis when every one of its samples is nearer one of the lines than half their
    separation (a pulse stands off both; a run that merged a pulse with a ramp's
    corner keeps the pulse's samples off both).
    """
    edges = np.flatnonzero(np.diff(np.r_[0, hit.astype(np.int8), 0]))
    out = hit.copy()
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        sides = []
        for lo, hi in ((max(0, a - LEVEL_SAMPLES), a), (b, min(x.size, b + LEVEL_SAMPLES))):
            keep = ~hit[lo:hi]
            if keep.sum() < 5:
                break
            tt, xx = t[lo:hi][keep], x[lo:hi][keep]
            c = np.polyfit(tt - t[a], xx, 1)
            sides.append(np.polyval(c, t[a:b] - t[a]))
        if len(sides) < 2:
            continue
        # every sample of the run near one of the two lines (within half their
        # separation there): an edge between two levels, not a pulse off both
        off = np.minimum(np.abs(x[a:b] - sides[0]), np.abs(x[a:b] - sides[1]))
        if np.all(off <= 0.5 * np.abs(sides[1] - sides[0])):
            out[a:b] = False
    return out


def edge_runs(bad: NDArray[np.bool_], r: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``bad`` without its runs at the record's start or end that look like a bias step.

    A step a few minutes from either end makes the running medians see the samples
    before (after) it as a burst (QA: a 3e-9 m/s² step 60 s into a day was left out
    as 60 outliers, and the table's bias kept it).  A leading or trailing run of at
    least :data:`EDGE_STEP_MIN` flagged samples that is smooth (its second differences
    within :data:`OUTLIER_SIGMAS` times the noise's: a constant offset, or a fast
    settling) and at most :data:`EDGE_STEP_MAX_SIGMAS` from the samples next to
    it is kept for the analysis (a 1e-8 m/s² decay of T = 120 s had its start screened
    and its amplitude came out 20x low).
    σ is that of the first differences of the unflagged samples (slow structure and
    steps elsewhere do not inflate it).
    """
    n = r.size
    if not bad.any() or bad.all():
        return bad
    k0 = int(np.argmax(~bad))
    k1 = int(np.argmax(~bad[::-1]))
    d = np.diff(r[~bad])
    sig = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2.0)
    if not sig > 0:
        return bad
    out = bad.copy()
    for k, at_start in ((k0, True), (k1, False)):
        if k < EDGE_STEP_MIN:
            continue
        core = max(k - OUTLIER_PAD, 1)  # the padding may reach past the step
        run = r[:core] if at_start else r[n - core :]
        near = r[k : k + OUTLIER_WINDOW] if at_start else r[max(0, n - k - OUTLIER_WINDOW) : n - k]
        # smooth: a constant offset (a step) or a decay (a settling), not spikes: no second
        # difference beyond what the noise gives (σ·√6 for white noise)
        d2 = np.diff(run, 2) if run.size > 2 else np.zeros(0)
        if near.size == 0 or np.max(np.abs(d2), initial=0.0) > OUTLIER_SIGMAS * np.sqrt(6) * sig:
            continue
        if abs(float(np.median(run) - np.median(near))) > EDGE_STEP_MAX_SIGMAS * sig:
            continue
        if at_start:
            out[:k] = False
        else:
            out[n - k :] = False
    return out
