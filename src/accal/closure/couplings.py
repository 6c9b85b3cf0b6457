"""Candidates tied to other channels: couplings (with lag and response) and the scale error.

``auxiliary``: a linear coupling ``c · (h_τ * x)(t − lag)`` to a channel ``x`` of the
data (a temperature, a voltage, an angular acceleration), ``h_τ`` a first-order
low-pass of time constant ``τ`` (``τ = 0``: none).  Every channel the caller offers
is searched together, one family: the best (channel, τ, lag) is proposed and its
multiplicity is the number of independent members searched over all channels
(:func:`lag_multiplicity`), so offering more channels costs sensitivity, never
false detections.

``scale``: with a reference acceleration, ``raw − reference`` holds ``δs ·
reference`` when the scale factor is off by ``δs`` (the wavelet paper's eq. 9,
``a_raw = s·a + b + d·t``); one regressor, the reference itself.

The lag scan is fast: with one data channel, the numerator of the explained power
of every lag of the grid comes from one FFT cross-correlation
(:func:`accal.closure.lagscan.correlate_valid`) of the residual with the channel, and the
channel-only denominator (its norm with the null model projected out, at every
lag) is computed once per channel and reused at every selection step.  The
effects already in the model are left out of the scan's ranking (second order);
the proposal's own test uses the exact projection.  A base of many blocks (the
rotating platform's per-period base) is scanned at every sample lag, exactly, by
block-wise FFT correlations (:mod:`accal.closure.lagscan`); other designs evaluate
the lag grid directly.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack
from scipy.optimize import minimize, minimize_scalar

from accal.closure.candidates import SQUARED, Context, Proposal, channel_power
from accal.closure.kinds import channel_class
from accal.closure.lagscan import (
    block_scan,
    block_spectra,
    channel_period,
    correlate_valid,
    projected_width,
    scan_power,
)
from accal.closure.scaleband import band_limited
from accal.closure.significance import test_proposal

__all__ = [
    "AUX_TAUS",
    "SQUARED",
    "auxiliary",
    "first_order",
    "lag_multiplicity",
    "max_lag",
    "scale",
    "square_about_mean",
]

#: Time constants of the first-order response searched [s] (0: none).
AUX_TAUS = (0.0, 300.0, 1000.0, 3000.0)
#: Lags on the search grid.
N_LAGS = 31
#: Longest lag searched for a coupling to an angular acceleration [s]: a lever-arm
#: coupling is instantaneous (the linear and angular channels share their filters).
ANGULAR_MAX_LAG = 10.0
#: A refined low-pass time constant below this many sample steps is a pure lag.
TAU_MIN_STEPS = 5.0
#: How far beyond the largest grid time constant the refinement looks.
TAU_BEYOND = 2.0
#: The grid's best coupling is refined only when its corrected p-value is below this
#: (:func:`_worth_refining`).
REFINE_GATE = 0.5
#: Responses at time constants off the grid kept per channel (:func:`_response`;
#: ~0.7 MB each on a 1 Hz day).
OFF_GRID_RESPONSES = 8
#: Columns evaluated together by :func:`_powers_at` (memory: 8·N bytes each).
POWER_BATCH = 32


def first_order(x: NDArray[np.float64], dt: float, tau: float) -> NDArray[np.float64]:
    """First-order low-pass ``τ ẏ + y = x`` on a uniform grid (exact for piecewise-constant x).

    The difference equation ``y[k] − a·y[k − 1] = (1 − a)·x[k]``, ``a = exp(−dt/τ)``
    (zero-order hold), is solved as the lower-bidiagonal triangular system it is, by
    LAPACK's banded triangular solve ``dtbtrs`` (forward substitution: the same
    operations as :func:`scipy.signal.lfilter`, bit for bit; importing
    ``scipy.signal`` costs ~0.6 s, an eighth of a demod day's closure budget).
    The filter starts settled on ``x[0]`` (its state before the record is unknown;
    the first few ``τ`` of the response carry that assumption).
    """
    x = np.asarray(x, dtype=np.float64)
    if tau <= 0 or x.size == 0:
        return x
    a = np.exp(-dt / tau)
    band = np.empty((2, x.size))
    band[0] = 1.0
    band[1] = -a
    y, info = lapack.dtbtrs(band, ((1 - a) * (x - x[0]))[:, None], uplo="L")
    if info != 0:  # pragma: no cover - a unit diagonal is never singular
        raise RuntimeError(f"dtbtrs failed (info {info})")
    return y[:, 0] + x[0]


def square_about_mean(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(x − mean x)²``, the mean over the finite values (channel ``NAME^2``)."""
    x = np.asarray(x, dtype=np.float64)
    return (x - np.nanmean(x)) ** 2


def max_lag(options: dict[str, Any], span: float) -> float:
    """Longest lag searched [s]: ``options["max_lag"]`` or min(span/20, 1 h)."""
    return float(options.get("max_lag", min(span / 20.0, 3600.0)))


def lag_multiplicity(h: NDArray[np.float64], step: float, top_lag: float) -> float:
    """Independent lags in ``[0, top_lag]`` for a response ``h`` on a grid of ``step`` [s].

    A continuous lag search over a channel that decorrelates after ``τ_c`` (the lag
    where its autocorrelation, mean removed, first falls below 1/2) tests about
    ``top_lag/τ_c + 1`` independent members; at least the :data:`N_LAGS` of the grid
    (a white channel is independent at every lag), at most one per sample.
    """
    if top_lag <= 0:
        return 1.0
    x = h - np.mean(h)
    n = x.size
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.abs(np.fft.rfft(x, nfft)) ** 2
    acf = np.fft.irfft(spec, nfft)[:n]
    if not acf[0] > 0:
        return 1.0
    below = np.flatnonzero(acf / acf[0] < 0.5)
    tau_c = (below[0] if below.size else n) * step
    m = top_lag / max(tau_c, step) + 1.0
    return float(min(max(m, min(N_LAGS, top_lag / step + 1.0)), top_lag / step + 1.0))


def _response(
    ctx: Context, name: str, x: NDArray[np.float64], lead: int, tc: float, cache: bool = True
) -> NDArray[np.float64]:
    """The channel's first-order response on the used samples' grid, from ``lead`` steps early.

    The channel is put on the nominal grid from its own first value on (holes
    interpolated; before its first and after its last value held constant) and
    filtered from there, so the filter's state at the record's start carries the
    channel's history (a filter started on the record's first value left a decay of
    its time constant, which an exponential drift then "explained").  Returns the
    response at grid points ``−lead .. N−1``.  Cached per selection: with ``cache``
    the grid's time constants; otherwise the :data:`OFF_GRID_RESPONSES` most recently
    used other ones (a profile evaluates many lags at one refined τ, and the lag
    profile with τ re-fitted the same first τs of its bounded search at every lag:
    a platform coupling run's responses filtered 235 → 72 times with 8 kept by
    recent use instead of 4 by age); the channel on the grid, which does not depend
    on τ, always.
    """
    key = ("response", name, lead, tc)
    if key in ctx.cache:
        return ctx.cache[key]
    recent = ctx.cache.setdefault(("recent responses", name, lead), {})
    if tc in recent:
        recent[tc] = recent.pop(tc)  # the most recently used last
        return recent[tc]
    pre, xg = _on_grid(ctx, name, x, lead)
    h = first_order(xg, ctx.grid.step, tc)[pre - lead :]
    if cache:
        ctx.cache[key] = h
    else:
        if len(recent) >= OFF_GRID_RESPONSES:
            del recent[next(iter(recent))]  # the least recently used
        recent[tc] = h
    return h


def _on_grid(ctx: Context, name: str, x: NDArray[np.float64], lead: int):
    """``(pre, values)``: the channel interpolated on the nominal grid from ``pre ≥ lead``
    steps before the record's start (from its own first value on), cached per
    selection."""
    key = ("on grid", name, lead)
    if key not in ctx.cache:
        step = ctx.grid.step
        ok = np.isfinite(x) & np.isfinite(ctx.t_all)
        tu, first = np.unique(ctx.t_all[ok], return_index=True)
        xv = x[ok][first]
        pre = max(lead, int(np.ceil((ctx.t0 - tu[0]) / step)))
        tg = ctx.t0 + step * np.arange(-pre, ctx.grid.size)
        ctx.cache[key] = (pre, np.interp(tg, tu, xv))
    return ctx.cache[key]


def _channels(ctx: Context) -> list[tuple[str, NDArray[np.float64]]]:
    """The channels to scan: every offered one not yet coupled, and the square about its
    mean (``NAME^2``: a quadratic dependence ``c1·x + c2·x²``) of one already coupled
    (before that, the square is tested together with the channel: :func:`auxiliary`)."""
    out = []
    for name, x in ctx.aux.items():
        if not ctx.has_label(f"aux:{name}"):
            if not ctx.is_blocked("auxiliary", name):
                out.append((name, x))
            continue
        sq = name + SQUARED
        angular = channel_class(ctx.options, name) == "angular"
        if not angular and not ctx.has_label(f"aux:{sq}") and not ctx.is_blocked("auxiliary", sq):
            out.append((sq, square_about_mean(x)))
    return out


def lag_period(ctx: Context, name: str, x) -> float:
    """The period [s] a channel's couplings repeat with, or 0: the per-period base's
    (``options["lag_period"]``, demodulation), else the channel's own when it repeats
    (:func:`accal.closure.lagscan.channel_period`; QA, 2026-11-30: on days whose
    temperature was heater square waves of 1,500 s the lag came out 1,798 s for 300 s,
    one cycle long)."""
    period = float(ctx.options.get("lag_period") or 0.0)
    if period > 0:
        return period
    key = ("channel period", name)
    if key not in ctx.cache:
        pre, values = _on_grid(ctx, name, x, 0)
        ctx.cache[key] = channel_period(_seen_part(ctx, values[pre:]), ctx.grid.step) or (
            channel_period(values, ctx.grid.step)
        )
    return float(ctx.cache[key])


def _seen_part(ctx: Context, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """The part of a channel (on the grid, from its first point) the coupling test sees:
    the channel at the used samples less its projection on the model (NaN in gaps).

    A heater's cycles of 0.04 K under a 0.5 K daily drift and 0.05-0.25 K of
    orbit-periodic temperature do not make the whole channel repeat (autocorrelation
    0.05 at the cycle), but the orbit template and smooth curve of the model take
    those out and the coupling's power is the heater's (QA, 2026-11-30: a 300 s lag
    came out 2,610 s, one 2,335 s cycle long, on a day whose temperature repeats only
    once its orbit and slow parts are removed).
    """
    if ctx.n_chan != 1:
        return np.full(0, np.nan)
    x_u = values[ctx.grid.idx]
    out = np.full(ctx.grid.size, np.nan)
    out[ctx.grid.idx] = x_u - ctx.basis.project(x_u)
    return out


def _shortest_lag(ctx: Context, name: str, x, lag: float, tc: float, top: float) -> float:
    """The shortest of ``lag − k·period`` explaining ≥ 98 % of ``lag``'s power.

    With a per-period base (demodulation) a channel that repeats with the period (a
    platform temperature kicked by every rotation) couples the same at lags a period
    apart: a 120 s lag came out as 720 s, with a line and a step beside it.  Without
    one, the period is the channel's own when it repeats
    (:func:`accal.closure.lagscan.channel_period`).  A channel that does not repeat
    keeps its lag.

    Tried and not kept (docs/closure.md): the alias explaining the most, each refined
    (on a QA platform day 930.7 s for a 933 s lag where this rule gives 329.5 s, but
    the coefficient 3.3 % low instead of 2.4 % and a_Y's error 1.8× the plain run's
    instead of 0.3×: a_Y takes up the coupling's in-period part and moves with its
    coefficient, which is biased low at every alias); reporting the aliases with the
    coefficient's spread over them in its σ (the spread, 0.6 %, does not explain the
    bias, and with the refined low-pass the aliases fell below 98 % of the power).
    Those lags carried the refinement's low-pass of 10 s: polished (:func:`_polish`)
    the lag is 332.5 s without one and the coefficient 2.985e-8 for 3e-8.
    """
    period = lag_period(ctx, name, x)
    if period <= 0 or lag < 0.5 * period:
        return lag
    here = _power_at(ctx, name, x, tc, lag)
    for k in range(int(lag // period), 0, -1):  # shortest first
        cand = lag - k * period
        lo, hi = max(0.0, cand - 0.25 * period), min(top, cand + 0.25 * period)
        best, power = _best_lag_in(ctx, name, x, tc, lo, hi)
        if power >= 0.98 * here:
            return best
    return lag


def _scan_fft(
    ctx: Context, hp: NDArray[np.float64], lags: NDArray[np.int64], key: tuple
) -> NDArray[np.float64]:
    """Explained power of every lag (in samples) of ``hp`` (grid from ``L`` steps early).

    ``hp[k + L]`` is the response at grid point ``k``; the column of lag ``l`` on
    used sample ``i`` is ``hp[idx_i + L − l]``.  The numerator by FFT correlation with
    the residual (on the first scan of a channel, from the columns the denominator
    needs anyway); the denominator (the column's norm with the null model projected
    out) depends on the channel only and is computed once per channel and response,
    exactly, for every lag of the grid.  The channel's mean is taken out first (the
    base holds the constant; a 293 K channel otherwise loses its variation to
    cancellation).
    """
    grid = ctx.grid
    big = int(lags.max()) if lags.size else 0
    hp = hp - float(np.mean(hp))
    if key not in ctx.cache:
        null = ctx.cache["null_basis"]
        z = hp[grid.idx[:, None] + (big - lags)[None, :]]
        ctx.cache[key] = np.einsum("ij,ij->j", z, z) - null.captured(z)
        num = (ctx.residual @ z) ** 2  # the columns are at hand: no correlation needed
    else:
        rg = np.zeros(grid.size)
        rg[grid.idx] = ctx.residual
        num = correlate_valid(hp, rg)[big - lags] ** 2
    den = ctx.cache[key]
    z2 = np.maximum(den, 0.0)
    return np.where(z2 > 1e-9 * np.max(z2, initial=0.0), num / np.maximum(z2, 1e-300), 0.0)


def _raw_multiplicity(ctx: Context, name: str, tc: float, hp, big: int, top: float) -> float:
    """:func:`lag_multiplicity` of the channel's response as read, cached per selection."""
    key = ("m", name, tc, big)
    if key not in ctx.cache:
        ctx.cache[key] = lag_multiplicity(hp[big:], ctx.grid.step, top)
    return ctx.cache[key]


def scans_every_lag(ctx: Context) -> bool:
    """Whether the lags are scanned at every sample (:mod:`accal.closure.lagscan`): a
    base of several blocks without a nuisance projection, unless ``options["lag_scan"]``
    is ``"grid"``."""
    if ctx.options.get("lag_scan", "fine") != "fine":
        return False
    basis = ctx.basis
    return basis.nuisance is None and basis.n_blocks > 1 and ctx.grid.idx.size > 0


def _scan_fine(ctx: Context, name: str, tc: float, hp, big: int, top: float):
    """``(power at every lag 0 .. big samples, multiplicity)`` for a block base.

    The power is exact (:func:`accal.closure.lagscan.scan_power`).  Multiplicity:
    ``top/w + 1`` independent lags with ``w`` the projected columns' decorrelation
    width (:func:`accal.closure.lagscan.projected_width`), at least the channel's
    as read (:func:`lag_multiplicity`) and at most one per sample; both measured
    once per channel and time constant, with the design of the first step.
    """
    # contexts sharing a cache may differ in their used samples (the search without a
    # coupled channel's unknown start) or block base: both are part of the key
    key = ("fine scan", name, tc, big, np.packbits(ctx.use).tobytes())
    hit = ctx.cache.get(key)
    if hit is None or hit[0] is not ctx.basis.q:
        scan = block_scan(ctx.grid, ctx.basis, hp, big, _block_spectra(ctx, big, key[-1]))
        width = projected_width(ctx.grid, ctx.basis, scan, big) * ctx.grid.step
        m = min(max(top / width + 1.0, _raw_multiplicity(ctx, name, tc, hp, big, top)), big + 1.0)
        hit = ctx.cache[key] = (ctx.basis.q, scan, float(m))
    _, scan, m = hit
    return scan_power(ctx.grid, ctx.basis, ctx.residual, scan, big), m


def _block_spectra(ctx: Context, big: int, use_key: bytes):
    """:func:`accal.closure.lagscan.block_spectra` of the context's blocks, shared by
    its channels and time constants; only the latest used-sample set is kept (~10 MB a
    base column on a day)."""
    hit = ctx.cache.get("block spectra")
    if hit is None or hit[0] is not ctx.basis.q or hit[1] != (big, use_key):
        hit = None
        ctx.cache.pop("block spectra", None)  # freed before the new one is made
        hit = (ctx.basis.q, (big, use_key), block_spectra(ctx.grid, ctx.basis, big))
        ctx.cache["block spectra"] = hit
    return hit[2]


def _scan_direct(ctx: Context, hp: NDArray[np.float64], lags: NDArray[np.int64]):
    """The same as :func:`_scan_fft`, exactly, lag by lag (block bases, several channels).

    The channel's mean is taken out first, as in :func:`_scan_fft`: each channel's
    bias holds the constant, and a 293 K temperature's norm with the base projected
    out is its 0.1 K variation, 1e-8 of its own norm, lost to cancellation (QA: every
    platform coupling scanned as zero power, 0/16 found).
    """
    big = int(lags.max()) if lags.size else 0
    idx = ctx.grid.idx
    hp = hp - float(np.mean(hp))
    z = np.stack([hp[idx + big - lag] for lag in lags])
    return channel_power(ctx, z)


def _column(ctx: Context, name: str, x, tc: float, lag: float) -> NDArray[np.float64]:
    """The coupling's regressor on *all* samples: ``(h_τ * x)(t − lag)``."""
    return _columns(ctx, name, x, tc, (lag,))[:, 0]


def _columns(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
    """:func:`_column` at each of ``lags`` (N, len(lags)), the response computed once."""
    tg, h = _grid_response(ctx, name, x, tc, lags)
    return np.column_stack([np.interp(ctx.t_all - lag, tg, h) for lag in lags])


def _grid_response(ctx: Context, name: str, x, tc: float, lags):
    """``(times, response)``: the channel's response on the grid from early enough for
    the longest of ``lags`` (and of the search) to the record's end."""
    step = ctx.grid.step
    lead = int(np.ceil(max(max(lags), max_lag(ctx.options, ctx.span)) / step)) + 2
    h = _response(ctx, name, x, lead, tc, cache=tc in AUX_TAUS)
    return ctx.t0 + step * np.arange(-lead, ctx.grid.size), h


def _power_at(ctx: Context, name: str, x, tc: float, lag: float) -> float:
    """Explained power of the coupling at (``lag``, ``τ``), the column's mean taken out
    (the base holds the constant; see :func:`_scan_direct`)."""
    return float(_powers_at(ctx, name, x, tc, (lag,))[0])


def _powers_at(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
    """:func:`_power_at` at each of ``lags`` (one τ), :data:`POWER_BATCH` columns at a
    time (a profile's grid: one pass over the design per batch, not per lag)."""
    lags = np.atleast_1d(np.asarray(lags, dtype=np.float64))
    out = np.empty(lags.size)
    for k in range(0, lags.size, POWER_BATCH):
        rows = _used_rows(ctx, name, x, tc, lags[k : k + POWER_BATCH])
        rows -= np.mean(rows, axis=1, keepdims=True)
        out[k : k + POWER_BATCH] = channel_power(ctx, rows)
    return out


def _used_rows(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
    """:func:`_columns` on the used samples only, one row per lag (len(lags), n): the
    regressor interpolated at the used samples' distinct times (the platform's two
    axes share each time) and spread to the samples (profile of a platform coupling
    day: 3.2 of 25 s in building all-sample columns, then selecting and transposing)."""
    tg, h = _grid_response(ctx, name, x, tc, lags)
    key = ("used times", np.packbits(ctx.use).tobytes())  # contexts of one cache may differ
    if key not in ctx.cache:
        tu, inv = np.unique(ctx.t_all[ctx.use], return_inverse=True)
        ctx.cache[key] = (tu, None if tu.size == inv.size else inv)
    tu, inv = ctx.cache[key]
    rows = np.empty((len(lags), int(ctx.use.sum())))
    for j, lag in enumerate(lags):
        v = np.interp(tu - lag, tg, h)
        rows[j] = v if inv is None else v[inv]
    return rows


def _taus(ctx: Context, name: str) -> tuple[float, ...]:
    """The first-order time constants searched for ``name`` [s]: :data:`AUX_TAUS` (or
    ``options["aux_taus"]``); none for an angular acceleration, whose lever-arm coupling
    is instantaneous (the linear and angular channels share their filters)."""
    if channel_class(ctx.options, name) == "angular":
        return (0.0,)
    return tuple(ctx.options.get("aux_taus", AUX_TAUS))


def _refine(ctx: Context, name: str, x, lag: float, tc: float, lag_step: float, top: float):
    """(lag, τ, power) refined: lag continuous near the grid's best, then lag and τ
    together within the channel's time constants (:func:`_taus`)."""
    p0 = _power_at(ctx, name, x, tc, lag)
    lo, hi = max(0.0, lag - lag_step), min(top, lag + lag_step)
    if hi > lo:
        best, power = _best_lag_in(ctx, name, x, tc, lo, hi)
        if power > p0:
            lag, p0 = best, power
    grid = sorted(_taus(ctx, name))
    if tc not in grid or len(grid) < 2:
        return lag, tc, p0
    k = grid.index(tc)
    lo_tau = grid[k - 1] if k > 0 else 0.0
    hi_tau = grid[k + 1] if k + 1 < len(grid) else tc * TAU_BEYOND
    start_tau = 0.5 * hi_tau if tc == 0 else tc
    start_lag = max(lag - start_tau, 0.0) if tc == 0 else lag
    d_lag = max(lag_step, 0.1 * start_tau, 10.0)
    d_tau = 0.5 * start_tau if 1.5 * start_tau <= hi_tau else -0.5 * (start_tau - lo_tau)
    start = np.array([min(start_lag, top), start_tau])
    simplex = np.array([start, start + [d_lag, 0.0], start + [0.0, d_tau]])
    simplex[:, 0] = np.clip(simplex[:, 0], 0.0, max(top, 0.0))
    if simplex[1, 0] == start[0]:
        simplex[1, 0] = max(start[0] - d_lag, 0.0)
    res = minimize(
        lambda v: -_power_at(ctx, name, x, float(v[1]), float(v[0])),
        start,
        method="Nelder-Mead",
        bounds=[(0.0, max(top, 0.0)), (lo_tau, hi_tau)],
        options={"initial_simplex": simplex, "xatol": 2.0, "fatol": 1e-6 * p0, "maxfev": 40},
    )
    lag2, tc2, p2 = float(res.x[0]), float(res.x[1]), float(-res.fun)
    at_bound = k + 1 == len(grid) and tc2 > 0.98 * hi_tau
    if p2 > p0 and not at_bound:
        if tc2 >= TAU_MIN_STEPS * ctx.grid.step:
            return lag2, tc2, p2
        if tc > 0:  # a low-pass of a few samples is a lag
            return min(lag2 + tc2, top), 0.0, p2
    return lag, tc, p0


#: Most Gauss-Newton steps of :func:`_polish`.
POLISH_STEPS = 20


def _polish(ctx: Context, name: str, x, lag: float, tc: float, top: float) -> tuple[float, float]:
    """(lag, τ) at the least-squares optimum: Gauss-Newton steps in (lag, ln τ) from
    the refinement's point, each kept only when it explains more power.

    The refinement (:func:`_refine`) is a Nelder-Mead search of at most 40
    evaluations: along the ridge on which the lag and the low-pass trade against each
    other (``lag + τ`` fixed for a slow channel) it can stop far from the optimum,
    and the final fit's Jacobian columns (:func:`accal.closure.final.with_jacobian`)
    linearise the model there.  A platform run's 3e-8 m/s²/K coupling to a kicked
    temperature at 932.5 s came out at lag 322.9 s with τ 10.4 s; the linearised step
    to 329.5 s and 3.4 s is far outside the region where the model is linear in
    ln τ, and the coefficients were 2.93e-8 (y) and 2.82e-8 (z), 2.9σ and 6.6σ low,
    where the least squares at the true lag give 2.99e-8.  Each step here solves
    the linearised problem (Gauss-Newton; Nocedal & Wright 2006, *Numerical
    Optimization*, sec. 10.3) with one coefficient per data channel and the
    channels' steps combined by their coefficients' weight, then halves it until
    the explained power grows (a damped step).  A low-pass shorter than
    :data:`TAU_MIN_STEPS` samples becomes a lag (as in :func:`_refine`), after which
    only the lag is refined.  The ridge's end (no low-pass, the lag at ``lag + τ``) is
    tried first: on the platform seed whose true coupling has no low-pass the steps
    from lag 0 s, τ 26 s crept along the ridge (8 steps to lag 19 s, τ 5.2 s; truth
    23.3 s, no low-pass).
    """
    if tc <= 0:
        return lag, tc
    step, top = ctx.grid.step, max(top, 0.0)
    p0 = _power_at(ctx, name, x, tc, lag)
    # the ridge's end first: no low-pass, the lag taking up τ
    lag_end, p_end = _lag_near(ctx, name, x, min(lag + tc, top), top, p0)
    if p_end > p0:
        return lag_end, 0.0
    for _ in range(POLISH_STEPS):
        d = _gauss_newton_step(ctx, name, x, lag, tc)
        if d is None:
            break
        moved = False
        for shrink in (1.0, 0.5, 0.25):
            lag1 = float(np.clip(lag + shrink * d[0], 0.0, top))
            tc1 = tc * float(np.exp(np.clip(shrink * d[1], -3.0, 3.0)))
            if tc1 < TAU_MIN_STEPS * step:  # a low-pass of a few samples is a lag
                lag1, tc1 = min(lag1 + tc1, top), 0.0
            p1 = _power_at(ctx, name, x, tc1, lag1)
            if p1 > p0:
                lag, tc, p0, moved = lag1, tc1, p1, True
                break
        if not moved or tc == 0 or (abs(d[0]) < 0.05 * step and abs(d[1]) < 1e-3):
            break
    if tc == 0:
        lag, _ = _lag_near(ctx, name, x, lag, top, p0)
    return lag, tc


def _lag_near(ctx: Context, name: str, x, lag: float, top: float, p0: float):
    """The best lag without a low-pass within a few samples of ``lag`` and its power
    (``lag`` and ``p0`` when none explains more than ``p0``)."""
    step = ctx.grid.step
    lo, hi = max(0.0, lag - TAU_MIN_STEPS * step), min(top, lag + TAU_MIN_STEPS * step)
    if not hi > lo:
        return lag, p0
    best, power = _best_lag_in(ctx, name, x, 0.0, lo, hi)
    return (best, power) if power > p0 else (lag, p0)


def _best_lag_in(ctx: Context, name: str, x, tc: float, lo: float, hi: float):
    """``(lag, power)``: the lag in ``[lo, hi]`` explaining the most at time constant
    ``tc`` (bounded Brent search to a quarter sample).

    With the lags scanned at every sample (:func:`lag_powers`) the search starts from
    the best sample lag of the window and refines within a sample of it: a window of
    a few hundred seconds holds several peaks of a kicked platform temperature, and
    Brent's search over all of it converged to another one (closure-detection seeds
    7321 and 7322: couplings found at lags 3,000 s and 1,800 s beyond the truth, their
    aliases not seen).
    """
    step = ctx.grid.step
    dense = lag_powers(ctx, name, x, tc)
    if dense is not None:
        lags, pw = dense
        inside = np.flatnonzero((lags >= lo - 1e-9) & (lags <= hi + 1e-9))
        if inside.size:
            k = inside[int(np.argmax(pw[inside]))]
            lo, hi = max(lo, lags[k] - step), min(hi, lags[k] + step)
            if not hi > lo:
                return float(lags[k]), float(pw[k])
    res = minimize_scalar(
        lambda lg: -_power_at(ctx, name, x, tc, lg),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 0.25 * step, "maxiter": 25},
    )
    lag, power = float(res.x), float(-res.fun)
    if dense is not None and inside.size and pw[k] > power:
        return float(lags[k]), float(pw[k])
    return lag, power


def lag_powers(ctx: Context, name: str, x, tc: float):
    """``(lags [s], explained power)`` at every sample lag ``0 .. max_lag`` at time
    constant ``tc`` (:mod:`accal.closure.lagscan`, the current model and residual), or
    None where the lags are not scanned so (:func:`scans_every_lag`)."""
    if not scans_every_lag(ctx):
        return None
    step = ctx.grid.step
    big = int(np.rint(max_lag(ctx.options, ctx.span) / step))
    hp = _response(ctx, name, np.asarray(x, dtype=np.float64), big, tc, cache=tc in AUX_TAUS)
    pw, _ = _scan_fine(ctx, name, tc, hp, big, big * step)
    return step * np.arange(big + 1), pw


def _gauss_newton_step(ctx: Context, name: str, x, lag: float, tc: float):
    """``(δlag, δln τ)`` of one Gauss-Newton step of the coupling at (``lag``, ``τ``),
    None when it is not defined (a channel without samples, a singular system).

    Per data channel ``c``: ``r ≈ a_c z_c + b_c ∂z_c/∂lag + e_c ∂z_c/∂ln τ`` with the
    model projected out of the columns; the step is ``(b_c, e_c)/a_c`` combined over the
    channels with weights ``a_c²`` (the least-squares combination of the channels'
    steps when their Jacobians are alike).
    """
    step = ctx.grid.step
    eps, dl = 1e-3, 0.5 * step
    lo = max(lag - dl, 0.0)
    rows = _used_rows(ctx, name, x, tc, (lag, lag + dl, lo))
    up = _used_rows(ctx, name, x, tc * np.exp(eps), (lag,))[0]
    down = _used_rows(ctx, name, x, tc / np.exp(eps), (lag,))[0]
    base = np.column_stack(
        [rows[0], (rows[1] - rows[2]) / (lag + dl - lo), (up - down) / (2 * eps)]
    )
    z = np.column_stack([base * m[:, None] for m in ctx.channel_masks()])
    zt = z - ctx.basis.project(z)
    coef, *_ = np.linalg.lstsq(zt, ctx.residual, rcond=None)
    a, b, e = coef[0::3], coef[1::3], coef[2::3]
    w = a**2
    if not (np.all(np.isfinite(coef)) and w.sum() > 0):
        return None
    return float(np.sum(a * b) / w.sum()), float(np.sum(a * e) / w.sum())


def _jacobian(ctx: Context, name: str, x, lag: float, tc: float):
    """Columns of d/dlnτ (central difference) and d/dlag of a coupling's regressor.

    d/dlag = −h'(t − lag) only with a low-pass: a pure lag's derivative is the
    channel's own, spikes for a kicked channel.
    """

    def jac() -> list[tuple[str, NDArray[np.float64]]]:
        eps = 1e-3
        up = _column(ctx, name, x, tc * np.exp(eps), lag)
        down = _column(ctx, name, x, tc / np.exp(eps), lag)
        dl = 0.5 * ctx.grid.step
        dlag = _column(ctx, name, x, tc, lag + dl) - _column(ctx, name, x, tc, max(lag - dl, 0))
        dlag /= lag + dl - max(lag - dl, 0.0)
        parts = [("tau", (up - down) / (2 * eps)), ("lag", dlag)]
        return [(k, ctx.split(d[:, None], (f"aux:{name}",))[0]) for k, d in parts]

    return jac if tc > 0 else None


def auxiliary(ctx: Context) -> list[Proposal]:
    """The best coupling to any offered channel: channel, first-order τ and lag searched.

    Grid: :data:`AUX_TAUS` × :data:`N_LAGS` lags in ``[0, max_lag]`` (angular
    accelerations: τ = 0 and lags up to :data:`ANGULAR_MAX_LAG`); the best grid
    point is refined (lag continuous, then lag and τ together).  Multiplicity: the
    independent members searched, summed over the channels and time constants
    (:func:`lag_multiplicity`).  The coefficient is in m/s² per channel unit, at channel value 0 (the regressor is
    not de-meaned: the bias is the one at channel value 0, as ``b + c·x`` says).

    The square of a channel already coupled is not searched: it is proposed at its
    channel's lag and τ (``ctx.coupled``), one member, beside the search's best, each
    proposal's multiplicity times the number of proposals (Bonferroni within the
    family).  A nonlinear sensitivity to a temperature acts on the temperature the
    linear term sees, and the final model gives the square its channel's lag
    (:func:`accal.closure.lagprofile.add_lag_uncertainties`); searched on its own
    it took a platform day's second selection step 0.5 s for four block scans, and
    once a 3,173 s lag made up over its first 3,173 s (2026-11-28).
    """
    step = ctx.grid.step
    top_all = max_lag(ctx.options, ctx.span)
    fine = scans_every_lag(ctx)
    fft_path = not fine and ctx.n_chan == 1 and "null_basis" in ctx.cache
    bests: dict[str, tuple] = {}  # per channel: (power, name, x, tc, lag, lag_step, top)
    mult = 0.0
    shared = []  # squares of coupled channels: on their channel's path, not searched
    for name, x in _channels(ctx):
        x = np.asarray(x, dtype=np.float64)
        base = name.removesuffix(SQUARED)
        if name != base and base in ctx.coupled:
            shared.append((name, x, *ctx.coupled[base]))
            continue
        ok = np.isfinite(x)
        if ok.sum() < 10 or np.ptp(x[ok]) == 0:
            continue
        angular = channel_class(ctx.options, name) == "angular"
        top = min(top_all, ANGULAR_MAX_LAG) if angular else top_all
        taus = _taus(ctx, name)
        n_l = int(ctx.options.get("n_lags", N_LAGS))
        lags = np.unique(np.rint(np.linspace(0.0, top, n_l) / step).astype(np.int64))
        big = int(lags.max())
        if fine:
            lags = np.arange(big + 1)
        lag_step = float((lags[1] - lags[0]) * step) if lags.size > 1 else 0.0
        for tc in taus:
            hp = _response(ctx, name, x, big, tc)
            if fine:
                pw, m = _scan_fine(ctx, name, tc, hp, big, top)
            else:
                pw = (
                    _scan_fft(ctx, hp, lags, ("den", name, tc, big))
                    if fft_path
                    else _scan_direct(ctx, hp, lags)
                )
                m = _raw_multiplicity(ctx, name, tc, hp, big, top)
            mult += m
            j = int(np.argmax(pw))
            if name not in bests or pw[j] > bests[name][0]:
                bests[name] = (float(pw[j]), name, x, tc, float(lags[j] * step), lag_step, top)
    best = _best_channel(ctx, bests, max(mult, 1.0))
    # a coupled channel's square on the same lag and low-pass (one thermal path: a
    # nonlinear sensitivity to the temperature the linear term sees), one member each;
    # the family then holds the search's best and these (Bonferroni over them)
    n_props = len(shared) + (best is not None and best[0] > 0)
    sq_props = [
        p
        for name, x, lag, tc in shared
        for p in _proposals(ctx, name, x, tc, lag, float(max(n_props, 1)))
    ]
    if best is None or not best[0] > 0:
        return sq_props
    mult = max(mult, 1.0) * max(n_props, 1)
    _, name, x, tc, lag, lag_step, top = best
    props = _proposals(ctx, name, x, tc, lag, mult)
    if not _worth_refining(ctx, props):
        return props + sq_props
    lag, tc, _ = _refine(ctx, name, x, lag, tc, lag_step, top)
    lag = _shortest_lag(ctx, name, x, lag, tc, top)
    lag, tc = _polish(ctx, name, x, lag, tc, top)
    return _proposals(ctx, name, x, tc, lag, mult) + sq_props


def _best_channel(ctx: Context, bests: dict[str, tuple], mult: float) -> tuple | None:
    """The channel whose best grid coupling is the most significant, with its entry.

    Each channel's best (τ, lag) is the one explaining the most residual power; across
    channels that favours slow, heavily low-passed columns under a red residual, whose
    power is mostly noise: on a QA storm day the voltage ``Vp`` at a 2,760 s lag and τ
    1,000 s (Wald statistic 5.3) was proposed at every step, and the temperature's
    1e-8 m/s²/K coupling at 282 s (statistic 43 when offered alone) never was.  So the
    channels' bests are compared by their Wald test
    (:func:`~accal.closure.significance.test_proposal`, the single column), the larger
    power breaking ties.
    """
    live = [b for b in bests.values() if b[0] > 0]
    if len(live) < 2:
        return live[0] if live else None
    n_fam = int(ctx.options.get("families", 1))

    def score(b: tuple) -> tuple[float, float]:
        prop = _proposals(ctx, b[1], b[2], b[3], b[4], mult)[0]
        tested = test_proposal(
            ctx.grid, ctx.basis, ctx.residual, ctx.leverage, prop, ctx.use, n_fam
        )
        return (tested.log_p if tested is not None else 0.0, -b[0])

    return min(live, key=score)


def _worth_refining(ctx: Context, props: list[Proposal]) -> bool:
    """Whether the grid's best coupling comes near significance (:data:`REFINE_GATE`).

    The refinement (lag continuous, then lag and τ together: ~60 evaluations of the
    exact explained power) moves the lag by less than a grid step and τ by less than
    the factor between grid time constants, which changes the explained power by a
    few per cent for a channel that varies on the scale of the grid (a white
    channel's power between grid lags is not found by refining either).  A coupling
    whose grid value has a corrected p-value above the gate would need about twice
    its power to become significant at α ≤ 0.01, so it is not refined: that saves
    most of the search's time on a day without one and can only make the test
    more conservative.  Same test as the selection
    (:func:`~accal.closure.significance.test_proposal`).
    """
    n_fam = int(ctx.options.get("families", 1))
    for prop in props:
        tested = test_proposal(
            ctx.grid, ctx.basis, ctx.residual, ctx.leverage, prop, ctx.use, n_fam
        )
        if tested is not None and tested.p_adj < REFINE_GATE:
            return True
    return False


def _proposals(ctx: Context, name: str, x, tc: float, lag: float, mult: float) -> list[Proposal]:
    """The coupling to ``name`` at (``lag``, ``τ``) and, for a channel that is not an
    angular acceleration or a square, the pair with the channel's square."""
    col = _column(ctx, name, x, tc, lag)
    cols, labs, axes = ctx.split(col[:, None], (f"aux:{name}",))
    out = [
        Proposal(
            "auxiliary",
            name,
            cols,
            labs,
            mult,
            {"lag": lag, "tau": tc},
            axes,
            jacobian=_jacobian(ctx, name, x, lag, tc),
        )
    ]
    if not name.endswith(SQUARED) and channel_class(ctx.options, name) != "angular":
        # the channel and its square together, at the same lag and response: a strong
        # quadratic dependence masks the linear one (QA: c1·T + 2e-9·(T − 20 K)² gave
        # "unexplained" structure only); the selection takes the pair only when no
        # single coupling is significant, and at twice the multiplicity
        sq = _column(ctx, name + SQUARED, square_about_mean(x), tc, lag)
        c2, l2, a2 = ctx.split(np.column_stack([col, sq]), (f"aux:{name}", f"aux:{name}{SQUARED}"))
        n_c = max(ctx.n_chan, 1)
        parts = [
            ([2 * c for c in range(n_c)], {"lag": lag, "tau": tc, "channel": name}),
            ([2 * c + 1 for c in range(n_c)], {"lag": lag, "tau": tc, "channel": name + SQUARED}),
        ]
        params = {"lag": lag, "tau": tc, "pair": True, "parts": parts}
        out.append(Proposal("auxiliary", name, c2, l2, 2.0 * mult, params, a2))
    return out


def scale(ctx: Context) -> list[Proposal]:
    """A scale error: the residual proportional to the reference (one coefficient ``δs``).

    With ``raw = s·a + b + d·t`` and the reference ``a_ref ≈ a``, ``raw − a_ref =
    (s − 1)·a_ref + b + d·t``: the coefficient of ``a_ref`` is ``δs = s − 1``
    (dimensionless).  Only with a reference, one proposal, no search.  The regressor
    is the reference low-passed to where the data's and the reference's filters agree
    (:func:`accal.closure.scaleband.band_limited`, one data channel): a Level-1B
    filter the reference does not share made scale errors of up to 3 % out of nothing.
    """
    ref = ctx.reference
    if ref is None or ctx.has_label("scale") or ctx.is_blocked("scale", None):
        return []
    col = np.asarray(ref, dtype=np.float64)
    if not np.all(np.isfinite(col[ctx.use])) or np.ptp(col[ctx.use]) == 0:
        return []
    if ctx.channel_all is None:
        col = np.where(ctx.use, col, np.nan)
        col = band_limited(ctx.t_all, col, ctx.grid.step)
    cols, labs, axes = ctx.split(np.nan_to_num(col)[:, None], ("scale",))
    return [Proposal("scale", None, cols, labs, 1.0, {}, axes)]
