"""Resampling of an irregular record onto a uniform grid, leaving gaps as gaps.

Used by ``accal demod --resample``.  Linear interpolation within continuous
stretches of the record; a grid point that falls in a step longer than
``gap_factor`` nominal steps (a gap) is not interpolated but marked invalid
(value NaN), so a demodulation masks it like a rotation sample.  Grid points
that coincide with a sample (within 1e-9 step) take the sample's value exactly.

The resampler works chunk by chunk (:class:`UniformResampler`), carrying the
last sample of a chunk over to the next, and gives the same grid and values
whatever the chunking: a grid point is always interpolated between the same two
samples with the same arithmetic.

At the end of the record a grid point at most half a step after the last
sample takes its value (:meth:`UniformResampler.finish`), so that jitter does
not cut the last sample off.

Linear interpolation does not low-pass: it suits timing jitter and a few lost
samples, not decimation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ValidationError

__all__ = ["ResampleReport", "UniformResampler", "nominal_step", "resample_uniform"]

#: A step longer than this many nominal steps is a gap (not interpolated across).
GAP_FACTOR = 2.0
#: Relative distance below which a grid point counts as on a sample.
SNAP = 1e-9
#: A median step within this relative distance of τ/n (n integer) is taken as τ/n.
STEP_SNAP_RTOL = 1e-4
#: Steps averaged per window when estimating the nominal step.
WINDOW = 64
#: A grid point at most this many steps after the last sample takes its value
#: (:meth:`UniformResampler.finish`): jitter must not cost the record's last sample.
END_HOLD = 0.5


@dataclass(frozen=True)
class ResampleReport:
    """What resampling did.

    Attributes
    ----------
    step : float
        Grid step [s].
    n_input : int
        Input samples.
    n_grid : int
        Grid points (from the first input sample to the last).
    n_exact : int
        Grid points on an input sample (value copied).
    n_interpolated : int
        Grid points interpolated between two samples at most ``gap_factor`` steps apart.
    n_gap : int
        Grid points inside gaps: marked invalid (NaN), never interpolated.
    n_end_held : int
        Grid points after the last input sample (by at most ``END_HOLD`` step,
        0 or 1) that took its value, so that timing jitter does not shorten the
        record by a sample (and its last period).
    n_gaps : int
        Input steps longer than ``gap_factor`` grid steps.
    largest_gap : float
        Longest input step [s].
    gap_factor : float
        The gap threshold [grid steps].
    """

    step: float
    n_input: int
    n_grid: int
    n_exact: int
    n_interpolated: int
    n_gap: int
    n_gaps: int
    largest_gap: float
    gap_factor: float
    n_end_held: int = 0

    def as_dict(self) -> dict[str, float | int]:
        """The report as a plain dict (JSON-ready)."""
        return dict(self.__dict__)


def nominal_step(time: ArrayLike, tau: float | None = None) -> float:
    """Nominal sampling step, snapped to ``τ/n`` when within 1e-4 of it.

    The median of the mean step over windows of 64 steps (windows holding a gap
    left out; the plain median step for short records).  Timing jitter still
    moves it by a few ppm, enough to make ``τ·fs`` non-integer; snapping puts a
    whole number of grid steps in a modulation period.  A step further than
    1e-4 (relative) from every ``τ/n`` is kept.

    Parameters
    ----------
    time : array_like
        Sample times [s] (at least 2).
    tau : float, optional
        Modulation period [s].

    Returns
    -------
    float
        [s]
    """
    t = np.asarray(time, float)
    if t.size < 2:
        raise ValidationError(f"need at least 2 samples to find the sampling step, got {t.size}")
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise ValidationError(f"median sampling step must be positive, got {dt} s")
    m = WINDOW
    if t.size > 2 * m:
        # jitter averages down over m steps; windows holding a gap are left out
        r = (t[m:] - t[:-m]) / m
        ok = np.abs(r - dt) < 0.5 * dt / m
        if ok.any():
            dt = float(np.median(r[ok]))
    if tau is not None and tau > 0:
        n = round(tau / dt)
        if n >= 1 and abs(tau / dt - n) <= STEP_SNAP_RTOL * n:
            dt = tau / n
    return dt


class UniformResampler:
    """Chunk-by-chunk linear resampling onto ``t0 + k·step`` (see the module notes).

    Parameters
    ----------
    step : float
        Grid step [s].
    gap_factor : float
        Input steps longer than ``gap_factor·step`` are gaps.

    Notes
    -----
    Call :meth:`push` with consecutive chunks (times strictly increasing across
    chunks); the grid starts at the first sample and ends at the last grid point
    not after the last sample pushed so far; :meth:`finish` then adds the grid
    point just after the last sample when it is within ``END_HOLD`` step of it.
    """

    def __init__(self, step: float, *, gap_factor: float = GAP_FACTOR) -> None:
        if not step > 0:
            raise ValidationError(f"resampling step must be positive, got {step}")
        self.step = float(step)
        self.gap_factor = float(gap_factor)
        self._t0: float | None = None
        self._k = 0  # next grid index
        self._last_t: float | None = None
        self._last_v: dict[str, float] = {}
        self._n_in = self._n_exact = self._n_interp = self._n_gap = self._n_gaps = 0
        self._n_held = 0
        self._largest = 0.0

    def push(
        self, time: ArrayLike, columns: Mapping[str, ArrayLike]
    ) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]], NDArray[np.bool_]]:
        """Resample one chunk.

        Parameters
        ----------
        time : array_like, shape (n,)
            Sample times [s], strictly increasing, after those of the previous chunk.
        columns : mapping of str to array_like
            Channels to resample (same set for every chunk).

        Returns
        -------
        grid : ndarray
            The grid times covered by this chunk [s].
        values : dict of str to ndarray
            Channels on ``grid`` (NaN inside gaps).
        valid : ndarray of bool
            False inside gaps.
        """
        t = np.asarray(time, float)
        cols = {k: np.asarray(v, float) for k, v in columns.items()}
        if t.size == 0:
            return np.empty(0), {k: np.empty(0) for k in cols}, np.empty(0, bool)
        self._n_in += t.size
        if self._t0 is None:
            self._t0 = float(t[0])
        if self._last_t is not None:
            t = np.concatenate([[self._last_t], t])
            cols = {k: np.concatenate([[self._last_v[k]], v]) for k, v in cols.items()}
        dt, t0 = self.step, self._t0
        steps = np.diff(t)
        if steps.size:
            self._n_gaps += int(np.count_nonzero(steps > self.gap_factor * dt))
            self._largest = max(self._largest, float(steps.max()))
        # grid points t0 + k dt <= t[-1] not emitted yet
        k_hi = int(np.floor((t[-1] - t0) / dt)) + 1
        while k_hi > self._k and t0 + (k_hi - 1) * dt > t[-1]:
            k_hi -= 1
        while t0 + k_hi * dt <= t[-1]:
            k_hi += 1
        k = np.arange(self._k, k_hi)
        self._k = k_hi
        self._last_t = float(t[-1])
        self._last_v = {n: float(v[-1]) for n, v in cols.items()}
        g = t0 + k * dt
        if g.size == 0:
            return g, {n: np.empty(0) for n in cols}, np.empty(0, bool)
        i = np.clip(np.searchsorted(t, g, side="right") - 1, 0, max(t.size - 2, 0))
        j = np.minimum(i + 1, t.size - 1)
        span = t[j] - t[i]
        on_i = np.abs(g - t[i]) <= SNAP * dt
        on_j = ~on_i & (np.abs(g - t[j]) <= SNAP * dt)
        exact = on_i | on_j
        gap = ~exact & (span > self.gap_factor * dt)
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where(span > 0, (g - t[i]) / span, 0.0)
        out = {}
        for n, v in cols.items():
            y = v[i] + (v[j] - v[i]) * frac
            y = np.where(on_i, v[i], np.where(on_j, v[j], y))
            y[gap] = np.nan
            out[n] = y
        self._n_exact += int(exact.sum())
        self._n_gap += int(gap.sum())
        self._n_interp += int(g.size - exact.sum() - gap.sum())
        return g, out, ~gap

    def finish(
        self,
    ) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]], NDArray[np.bool_]]:
        """End of the record: the grid point just after the last sample, if close enough.

        A grid point at most ``END_HOLD`` step after the last sample takes the
        last sample's values (its nearest sample): with timing jitter the last
        sample falls before its grid point about every other record, and the
        grid would otherwise end one point short (a whole period lost for a
        record of whole periods).  Counted in ``n_end_held``.  Call once, after
        the last :meth:`push`.

        Returns
        -------
        grid, values, valid
            As :meth:`push` (empty or one point).
        """
        names = list(self._last_v)
        if self._t0 is None or self._last_t is None:
            return np.empty(0), {n: np.empty(0) for n in names}, np.empty(0, bool)
        g = self._t0 + self._k * self.step
        if g - self._last_t > END_HOLD * self.step:
            return np.empty(0), {n: np.empty(0) for n in names}, np.empty(0, bool)
        self._k += 1
        self._n_held += 1
        return (
            np.array([g]),
            {n: np.array([self._last_v[n]]) for n in names},
            np.ones(1, bool),
        )

    @property
    def report(self) -> ResampleReport:
        """Counts so far."""
        return ResampleReport(
            step=self.step,
            n_input=self._n_in,
            n_grid=self._k,
            n_exact=self._n_exact,
            n_interpolated=self._n_interp,
            n_gap=self._n_gap,
            n_gaps=self._n_gaps,
            largest_gap=self._largest,
            gap_factor=self.gap_factor,
            n_end_held=self._n_held,
        )


def resample_uniform(
    time: ArrayLike,
    columns: Mapping[str, ArrayLike],
    step: float,
    *,
    gap_factor: float = GAP_FACTOR,
    hold_end: bool = False,
) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]], NDArray[np.bool_], ResampleReport]:
    """Resample a whole record onto ``t[0] + k·step`` (see the module notes).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s], strictly increasing.
    columns : mapping of str to array_like
        Channels to resample.
    step : float
        Grid step [s] (e.g. :func:`nominal_step`).
    gap_factor : float
        Input steps longer than ``gap_factor·step`` are gaps: their grid points
        are marked invalid (NaN), never interpolated.
    hold_end : bool
        Add the grid point just after the last sample when it is within
        ``END_HOLD`` step (:meth:`UniformResampler.finish`), as ``accal demod
        --resample`` does.

    Returns
    -------
    grid : ndarray
        Grid times [s].
    values : dict of str to ndarray
        Channels on the grid.
    valid : ndarray of bool
        False inside gaps.
    report : ResampleReport
    """
    r = UniformResampler(step, gap_factor=gap_factor)
    g, v, ok = r.push(time, columns)
    g1, v1, ok1 = r.finish() if hold_end else (np.empty(0), {}, np.empty(0, bool))
    if g1.size:
        g, ok = np.concatenate([g, g1]), np.concatenate([ok, ok1])
        v = {n: np.concatenate([x, v1[n]]) for n, x in v.items()}
    return g, v, ok, r.report
