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

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize, minimize_scalar

from accal.closure.candidates import SQUARED, Context, Proposal
from accal.closure.couplingscan import (
    AUX_TAUS,
    N_LAGS,
    column,
    first_order,
    lag_multiplicity,
    lag_powers,
    max_lag,
    on_grid,
    power_at,
    raw_multiplicity,
    response,
    scan_direct,
    scan_fft,
    scan_fine,
    scans_every_lag,
    square_about_mean,
    used_rows,
)
from accal.closure.kinds import channel_class
from accal.closure.lagscan import channel_period
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
        pre, values = on_grid(ctx, name, x, 0)
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
    here = power_at(ctx, name, x, tc, lag)
    for k in range(int(lag // period), 0, -1):  # shortest first
        cand = lag - k * period
        lo, hi = max(0.0, cand - 0.25 * period), min(top, cand + 0.25 * period)
        best, power = _best_lag_in(ctx, name, x, tc, lo, hi)
        if power >= 0.98 * here:
            return best
    return lag


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
    p0 = power_at(ctx, name, x, tc, lag)
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
        lambda v: -power_at(ctx, name, x, float(v[1]), float(v[0])),
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
    p0 = power_at(ctx, name, x, tc, lag)
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
            p1 = power_at(ctx, name, x, tc1, lag1)
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
        lambda lg: -power_at(ctx, name, x, tc, lg),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 0.25 * step, "maxiter": 25},
    )
    lag, power = float(res.x), float(-res.fun)
    if dense is not None and inside.size and pw[k] > power:
        return float(lags[k]), float(pw[k])
    return lag, power


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
    rows = used_rows(ctx, name, x, tc, (lag, lag + dl, lo))
    up = used_rows(ctx, name, x, tc * np.exp(eps), (lag,))[0]
    down = used_rows(ctx, name, x, tc / np.exp(eps), (lag,))[0]
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
        up = column(ctx, name, x, tc * np.exp(eps), lag)
        down = column(ctx, name, x, tc / np.exp(eps), lag)
        dl = 0.5 * ctx.grid.step
        dlag = column(ctx, name, x, tc, lag + dl) - column(ctx, name, x, tc, max(lag - dl, 0))
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
            hp = response(ctx, name, x, big, tc)
            if fine:
                pw, m = scan_fine(ctx, name, tc, hp, big, top)
            else:
                pw = (
                    scan_fft(ctx, hp, lags, ("den", name, tc, big))
                    if fft_path
                    else scan_direct(ctx, hp, lags)
                )
                m = raw_multiplicity(ctx, name, tc, hp, big, top)
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
    col = column(ctx, name, x, tc, lag)
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
        sq = column(ctx, name + SQUARED, square_about_mean(x), tc, lag)
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
