"""The columns of a coupling and the residual power they explain, at every lag.

A coupling to a channel ``x`` is the column ``c · (h_τ * x)(t − lag)``
(:func:`response`: ``h_τ`` a first-order low-pass, :func:`first_order`), placed on
the nominal grid (:func:`on_grid`) and read at the used samples (:func:`column`).
Its explained power ``(rᵀ z)² / ‖z − P z‖²`` (``P`` the null model's projection) is
scanned over the lag grid by FFT correlation with one data channel
(:func:`scan_fft`), row by row for other designs (:func:`scan_direct`), or at every
sample lag of a per-period block base (:func:`scan_fine`,
:mod:`accal.closure.lagscan`); :func:`power_at` and :func:`powers_at` evaluate it
exactly off the grid.  :func:`lag_multiplicity` counts the independent members the
scan searched.  The search that uses them is :mod:`accal.closure.couplings`.  Split
from it (2026-11-30).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack

from accal.closure.candidates import Context, channel_power
from accal.closure.lagscan import (
    block_scan,
    block_spectra,
    correlate_valid,
    projected_width,
    scan_power,
)

__all__ = [
    "AUX_TAUS",
    "N_LAGS",
    "column",
    "first_order",
    "lag_multiplicity",
    "lag_powers",
    "max_lag",
    "on_grid",
    "power_at",
    "powers_at",
    "raw_multiplicity",
    "response",
    "scan_direct",
    "scan_fft",
    "scan_fine",
    "scans_every_lag",
    "square_about_mean",
    "used_rows",
]

#: Time constants of the first-order response searched [s] (0: none).
AUX_TAUS = (0.0, 300.0, 1000.0, 3000.0)

#: Lags on the search grid.
N_LAGS = 31

#: Responses at time constants off the grid kept per channel (:func:`response`;
#: ~0.7 MB each on a 1 Hz day).
OFF_GRID_RESPONSES = 8

#: Columns evaluated together by :func:`powers_at` (memory: 8·N bytes each).
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


def response(
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
    pre, xg = on_grid(ctx, name, x, lead)
    h = first_order(xg, ctx.grid.step, tc)[pre - lead :]
    if cache:
        ctx.cache[key] = h
    else:
        if len(recent) >= OFF_GRID_RESPONSES:
            del recent[next(iter(recent))]  # the least recently used
        recent[tc] = h
    return h


def on_grid(ctx: Context, name: str, x: NDArray[np.float64], lead: int):
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


def scan_fft(
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


def raw_multiplicity(ctx: Context, name: str, tc: float, hp, big: int, top: float) -> float:
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


def scan_fine(ctx: Context, name: str, tc: float, hp, big: int, top: float):
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
        m = min(max(top / width + 1.0, raw_multiplicity(ctx, name, tc, hp, big, top)), big + 1.0)
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


def scan_direct(ctx: Context, hp: NDArray[np.float64], lags: NDArray[np.int64]):
    """The same as :func:`scan_fft`, exactly, lag by lag (block bases, several channels).

    The channel's mean is taken out first, as in :func:`scan_fft`: each channel's
    bias holds the constant, and a 293 K temperature's norm with the base projected
    out is its 0.1 K variation, 1e-8 of its own norm, lost to cancellation (QA: every
    platform coupling scanned as zero power, 0/16 found).
    """
    big = int(lags.max()) if lags.size else 0
    idx = ctx.grid.idx
    hp = hp - float(np.mean(hp))
    z = np.stack([hp[idx + big - lag] for lag in lags])
    return channel_power(ctx, z)


def column(ctx: Context, name: str, x, tc: float, lag: float) -> NDArray[np.float64]:
    """The coupling's regressor on *all* samples: ``(h_τ * x)(t − lag)``."""
    return _columns(ctx, name, x, tc, (lag,))[:, 0]


def _columns(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
    """:func:`column` at each of ``lags`` (N, len(lags)), the response computed once."""
    tg, h = _grid_response(ctx, name, x, tc, lags)
    return np.column_stack([np.interp(ctx.t_all - lag, tg, h) for lag in lags])


def _grid_response(ctx: Context, name: str, x, tc: float, lags):
    """``(times, response)``: the channel's response on the grid from early enough for
    the longest of ``lags`` (and of the search) to the record's end."""
    step = ctx.grid.step
    lead = int(np.ceil(max(max(lags), max_lag(ctx.options, ctx.span)) / step)) + 2
    h = response(ctx, name, x, lead, tc, cache=tc in AUX_TAUS)
    return ctx.t0 + step * np.arange(-lead, ctx.grid.size), h


def power_at(ctx: Context, name: str, x, tc: float, lag: float) -> float:
    """Explained power of the coupling at (``lag``, ``τ``), the column's mean taken out
    (the base holds the constant; see :func:`scan_direct`)."""
    return float(powers_at(ctx, name, x, tc, (lag,))[0])


def powers_at(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
    """:func:`power_at` at each of ``lags`` (one τ), :data:`POWER_BATCH` columns at a
    time (a profile's grid: one pass over the design per batch, not per lag)."""
    lags = np.atleast_1d(np.asarray(lags, dtype=np.float64))
    out = np.empty(lags.size)
    for k in range(0, lags.size, POWER_BATCH):
        rows = used_rows(ctx, name, x, tc, lags[k : k + POWER_BATCH])
        rows -= np.mean(rows, axis=1, keepdims=True)
        out[k : k + POWER_BATCH] = channel_power(ctx, rows)
    return out


def used_rows(ctx: Context, name: str, x, tc: float, lags) -> NDArray[np.float64]:
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


def lag_powers(ctx: Context, name: str, x, tc: float):
    """``(lags [s], explained power)`` at every sample lag ``0 .. max_lag`` at time
    constant ``tc`` (:mod:`accal.closure.lagscan`, the current model and residual), or
    None where the lags are not scanned so (:func:`scans_every_lag`)."""
    if not scans_every_lag(ctx):
        return None
    step = ctx.grid.step
    big = int(np.rint(max_lag(ctx.options, ctx.span) / step))
    hp = response(ctx, name, np.asarray(x, dtype=np.float64), big, tc, cache=tc in AUX_TAUS)
    pw, _ = scan_fine(ctx, name, tc, hp, big, big * step)
    return step * np.arange(big + 1), pw
