"""Uncertainty of a coupling's lag: the profile of the explained power over the lag.

A coupling ``c·(h_τ * x)(t − L)`` is linear in ``c``, not in the lag ``L``.  A pure lag
(``τ = 0``) has no usable Jacobian (the derivative of a kicked channel is spikes), and a
low-passed one's linearised σ is too small on the lag/low-pass ridge of a smooth channel
(closure-detection: lag z up to ~5).  So the lag's uncertainty comes from the profile
of the fit over the lag instead (the likelihood-ratio interval of a nonlinear parameter:
Wilks 1938, *Ann. Math. Stat.* 9, 60; Venzon & Moolgavkar 1988, *Appl. Stat.* 37, 87;
Seber & Wild 1989, *Nonlinear Regression*, sec. 5.9.1).

With the rest of the final model held, the coefficient's Wald statistic at lag ``L`` is
``W(L) = (zᵀr)² / zᵀVz`` (``z`` the regressor with the model projected out, ``r`` the
residual, ``V`` the noise covariance).  A shift of a stationary channel leaves ``zᵀVz``
nearly unchanged, so ``W(L) ≈ W(L̂)·P(L)/P(L̂)`` with ``P`` the explained power
``(zᵀr)²/zᵀz``, and the 68 % profile interval ``{L : W(L̂) − W(L) ≤ 1}`` is

.. math:: P(L) \\ge P(\\hat L)\\,\\bigl(1 - 1/W(\\hat L)\\bigr).

:func:`lag_uncertainty` finds that set: the interval around ``L̂`` (its two crossings,
by bisection at a tenth of a sample step) and, over the whole searched range, other
lags that fit as well.  A channel that repeats (a platform temperature kicked at every
rotation, a heater cycle) can fit almost alike at lags a cycle apart: those within
``ΔW ≤ 4`` are listed as ``lag_alternatives`` and, within ``ΔW ≤ 1``, widen the
reported interval to the hull of all of them (the lag is then not identified better
than that, and ``lag_ambiguous`` says so).  With a per-period base (demodulation) the
lags a whole period apart that explain at least :data:`ALIAS_SHARE` of the power are
aliases (:func:`_is_alias`) and widen the interval too: the lag is known modulo the
period only.

The profile need not be a parabola: a channel with both slow and sample-to-sample
variation (a walking temperature read with white noise) has a broad hill from the slow
part and, at the true lag, a narrow notch from the fast one, a few samples wide.  On a
`tests.indep` day (1e-8 m/s²/K, true lag 797.8 s) the hill peaked at 785.5 s with
``ΔW ≤ 1`` over ±3.6 s, while the notch at the truth had ``ΔW = 2.2``: the 68 % set
was right to leave it out, but a σ of 3.6 s put the truth at 3.4σ where the profile
says ~1.5σ.  So the 95 % set ``{ΔW ≤ 4}`` is found too (:func:`_two_sigma_set`: its
contiguous part by bisection, then a scan at a quarter sample step, at most
:data:`ISLAND_POINTS` lags, of a window as wide again each side for such islands),
and ``lag_sigma`` is at least a quarter of its width (``ΔW = 4`` is 2σ on a
parabola, where both give the same σ).  Reported as ``lag_interval_95``.

With a low-pass in the model (``τ`` fitted), the contiguous parts of both sets are those
of the profile with ``τ`` re-fitted at each lag (``τ`` a nuisance parameter): a one-pole
low-pass delays a slow channel by about ``τ`` (at ``τ = 0``, ``∂/∂τ = ∂/∂L``), so with ``τ``
held the lag's set was too narrow (closure-detection, 24 days per size, 2026-11-28: lag
z RMS 3.5 at 1e-8 m/s²/K; 0.7 with ``τ`` re-fitted and the housekeeping low-passed like
the Level-1B data, :mod:`accal.crn`).

A second σ, the least-squares sandwich of the lag under the residual's coloured noise
(:func:`lag_sandwich_sigma`), is computed beside the profile's; ``lag_sigma`` is the
larger (below a sample step the profile is widened by the channel's linear
interpolation between samples, which no σ from a smooth model sees).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from accal.closure.candidates import Context, row_fit
from accal.closure.couplings import ANGULAR_MAX_LAG, SQUARED
from accal.closure.couplingscan import (
    column,
    lag_powers,
    max_lag,
    power_at,
    powers_at,
    scans_every_lag,
    used_rows,
)
from accal.closure.kinds import channel_class
from accal.closure.peaks import prominent_peaks
from accal.closure.results import Effect
from accal.closure.wald import sandwich_cov

if TYPE_CHECKING:  # annotations only: the search imports the candidates
    from accal.closure.search import Found, Search

__all__ = [
    "ALT_DELTA_W",
    "add_lag_uncertainties",
    "coefficient_interval",
    "lag_sandwich_sigma",
    "lag_uncertainty",
    "profile_intervals",
]

#: Reach of the low-pass time constant re-fitted along the lag profile beyond ``τ̂`` [s]
#: (at least ``2τ̂``): a lag shorter by ``d`` is compensated by ``τ ≈ τ̂ + d``.
TAU_PROFILE_REACH = 120.0
#: ``ΔW`` up to which another lag is listed as an alternative (2σ).
ALT_DELTA_W = 4.0
#: Lags on the profile over the whole searched range (local maxima refined).
PROFILE_POINTS = 121
#: Local maxima of that profile refined and checked at most.
MAX_ALTERNATIVES = 6
#: ``ΔW`` of the 95 % profile set (2σ on a parabola).
TWO_SIGMA_DELTA_W = 4.0
#: Lags scanned at most on each side for islands of the 95 % set beside its contiguous part.
ISLAND_POINTS = 200
#: Lags and time constants of the grid of the coefficient's profile (:func:`coefficient_interval`).
COEF_PROFILE_LAGS = 15
COEF_PROFILE_TAUS = 11
#: Share of the explained power at which a lag a whole period away is an alias
#: (the coupling search's rule, :func:`accal.closure.couplings._shortest_lag`).
ALIAS_SHARE = 0.98


def _crossing(f, inside: float, outside: float, tol: float) -> float:
    """The point between ``inside`` (``f ≥ 0``) and ``outside`` (``f < 0``) where ``f``
    changes sign, by bisection to ``tol``."""
    while abs(outside - inside) > tol:
        mid = 0.5 * (inside + outside)
        if f(mid) >= 0:
            inside = mid
        else:
            outside = mid
    return 0.5 * (inside + outside)


def _side(f, lag: float, bound: float, step: float, tol: float) -> float:
    """The end of ``{f ≥ 0}`` from ``lag`` towards ``bound``: doubling steps, then bisection."""
    sign = 1.0 if bound >= lag else -1.0
    inside, d = lag, step
    while True:
        trial = lag + sign * d
        if sign * (trial - bound) >= 0:
            return bound if f(bound) >= 0 else _crossing(f, inside, bound, tol)
        if f(trial) < 0:
            return _crossing(f, inside, trial, tol)
        inside, d = trial, 2.0 * d


def lag_uncertainty(
    ctx: Context,
    name: str,
    x: NDArray[np.float64],
    tau: float,
    lag: float,
    wald: float,
    top: float,
    *,
    low_pass: bool = True,
    extended: Context | None = None,
) -> dict[str, Any]:
    """The lag's 68 % profile interval, its σ and the other lags that fit as well.

    Parameters
    ----------
    ctx : Context
        The final model without this coupling (its residual and basis).
    name, x : str, ndarray
        The channel and its values on all samples.
    tau, lag : float
        The coupling's low-pass time constant and lag [s] (held τ).
    wald : float
        ``W(L̂)``: the coefficient's squared z in the final fit (summed over data
        channels).
    top : float
        Longest lag searched [s].
    low_pass : bool
        Whether the coupling's model has a low-pass (τ fitted): the contiguous parts
        of the 68 % and 95 % sets are then those of the profile with τ re-fitted at
        each lag (the likelihood-ratio interval of the lag with τ a nuisance
        parameter; Venzon & Moolgavkar 1988): a low-pass of time constant τ delays a
        slow channel by about τ, so lag and τ trade along a ridge (closure-detection,
        24 days per size: with τ held the true lag was inside the 68 % interval for 2
        of 12 found couplings).  Other lags and islands are looked for with τ held.
    extended : Context, optional
        The same model with the signal's extension (demodulation: the per-period
        signal's slope, :meth:`accal.closure.search.Search.signal_state`).  Where the
        lags are scanned at every sample, its best lag, when outside the interval,
        is another lag that fits as well (``"signal_model": True``; an alias when a
        whole period away): the "mean" signal model leaks the signal's change within
        a period, with the rotation's rhythm, into the residual, and a temperature
        kicked at every rotation fits it at lags a period apart (closure-detection
        seed 7322: 3e-8 m/s²/K at 1,646.9 s found at 3,446.5 s, ΔW 3,824 for the true
        lag under the "mean" model; 1,647.0 s with the slope in the model).

    Returns
    -------
    dict
        ``lag_sigma`` (half the width of the interval) [s], ``lag_interval`` [s, s],
        ``lag_alternatives`` (``[{"lag", "delta_w"[, "alias"]}]``, ``ΔW ≤``
        :data:`ALT_DELTA_W` or an alias), ``lag_ambiguous`` (another lag inside
        ``ΔW ≤ 1``, or an alias), ``lag_sigma_method``.
        Empty when the coupling explains nothing at ``lag``.
    """
    step = ctx.grid.step
    top = max(float(top), float(lag))

    def power(lg: float) -> float:
        return power_at(ctx, name, x, tau, float(min(max(lg, 0.0), top)))

    def powers(lgs: NDArray[np.float64]) -> NDArray[np.float64]:
        return powers_at(ctx, name, x, tau, np.clip(lgs, 0.0, top))

    # the per-period base's period only: a channel's own cycle (lag_period) picks the
    # search's lag, but aliases a cycle apart here would widen the interval over lags
    # the data tell apart (ΔW 314 on test_coupling_sigma_ridge's line channel)
    period = float(ctx.options.get("lag_period") or 0.0)
    free = None
    if low_pass:
        tau_hi = max(2.0 * tau, tau + TAU_PROFILE_REACH)

        def free(lg: float) -> float:  # τ profiled out: the lag/low-pass ridge
            lg = float(min(max(lg, 0.0), top))
            res = minimize_scalar(
                lambda tc: -power_at(ctx, name, x, float(tc), lg),
                bounds=(0.0, tau_hi),
                method="bounded",
                options={"xatol": max(step, 0.05 * tau_hi), "maxiter": 12},
            )
            return max(-float(res.fun), power(lg))

    dense = lag_powers(ctx, name, x, tau)
    model_lags = []
    if extended is not None and dense is not None:
        ext = lag_powers(extended, name, x, tau)
        if ext is not None and ext[0].size:
            model_lags.append(float(ext[0][int(np.argmax(ext[1]))]))
    return profile_intervals(
        power, float(lag), float(wald), top, step, period, free, powers, dense, model_lags
    )


def profile_intervals(
    power,
    lag: float,
    wald: float,
    top: float,
    step: float,
    period: float = 0.0,
    free=None,
    powers=None,
    dense=None,
    model_lags: Sequence[float] = (),
) -> dict[str, Any]:
    """The lag's 68 % and 95 % profile sets from the explained power ``power(L)``.

    Parameters
    ----------
    power : callable
        ``P(L)``, the explained power at lag ``L`` (the rest of the model held).
    lag : float
        ``L̂``, the lag maximising ``P`` [s].
    wald : float
        ``W(L̂)`` (see :func:`lag_uncertainty`).
    top : float
        Longest lag searched [s].
    step : float
        Sample step [s]: the interval ends are found to a tenth of it.
    period : float
        Per-period base's period [s] (lags a whole period apart are aliases), 0 if none.
    free : callable, optional
        ``P(L)`` with the other nonlinear parameters re-fitted at each ``L`` (≥
        ``power``): the contiguous parts of both sets come from it.
    powers : callable, optional
        ``power`` at an array of lags at once (the scans of a grid); by default
        ``power`` lag by lag.
    dense : tuple of ndarray, optional
        ``(lags, P)`` at every sample lag over ``[0, top]`` (:func:`lag_powers`): the
        other lags that fit as well are looked for there instead of on
        :data:`PROFILE_POINTS` lags (a kicked platform temperature's peaks are ~35 s
        wide, the profile's grid 30 s apart).
    model_lags : sequence of float
        Lags another plausible model of the data chose (:func:`lag_uncertainty`'s
        ``extended``): each outside the interval is an alternative that fits as well
        (``"signal_model": True``, and ``"alias"`` when a whole period away).

    Returns
    -------
    dict
        As :func:`lag_uncertainty`, plus ``lag_interval_95`` [s, s] and
        ``lag_sigma_68`` (half the 68 % interval's width) [s], ``lag_sigma_local``
        (half the width of the chosen lag's own contiguous 68 % set) [s].
        ``lag_sigma`` is the larger of ``lag_sigma_68`` and a quarter of the 95 %
        interval's width (eq. 1 of the module docstring's profile: ``ΔW = 1`` and
        ``ΔW = 4`` are 1σ and 2σ on a parabola).
    """
    p_hat = power(lag) if free is None else max(power(lag), free(lag))
    if not (p_hat > 0 and np.isfinite(wald)):
        return {}
    if wald <= 1.0:  # nothing known about the lag
        return {
            "lag_sigma": 0.5 * top,
            "lag_interval": [0.0, top],
            "lag_interval_95": [0.0, top],
            "lag_sigma_68": 0.5 * top,
            "lag_sigma_local": 0.5 * top,
            "lag_alternatives": [],
            "lag_ambiguous": True,
            "lag_sigma_method": "profile",
        }

    if powers is None:

        def powers(lgs: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.array([power(g) for g in lgs], dtype=np.float64)

    def delta_w(p):
        return wald * (1.0 - p / p_hat)

    def inside(lg: float, level: float = 1.0) -> float:
        return level - delta_w(power(lg))  # ≥ 0 inside the set

    def inside_free(lg: float, level: float = 1.0) -> float:
        return level - delta_w(free(lg)) if free is not None else inside(lg, level)

    lo, hi = _contiguous(inside, lag, top, step)
    if free is not None:
        lo, hi = _widened(inside_free, lag, top, step, lo, hi)
    alts = _alternatives(power, powers, delta_w, (lag, p_hat, period), lo, hi, top, step, dense)
    for m in model_lags:
        if lo - step <= m <= hi + step or any(abs(a["lag"] - m) <= step for a in alts):
            continue
        k = round(abs(m - lag) / period) if period > 0 else 0
        alias = k >= 1 and abs(abs(m - lag) - k * period) <= 0.25 * period
        alt = {"lag": float(m), "delta_w": max(float(delta_w(power(m))), 0.0)}
        alts.append({**alt, "signal_model": True, **({"alias": True} if alias else {})})
    alike = _alike_lags(alts)
    ambiguous = bool(alike)
    half = 0.5 * (hi - lo)  # each other lag is as uncertain as the chosen one
    lo_all = max(min([lo] + [v - half for v in alike]), 0.0)
    hi_all = min(max([hi] + [v + half for v in alike]), top)
    lo95, hi95 = _two_sigma_set(
        lambda lg: inside(lg, TWO_SIGMA_DELTA_W),
        lag,
        top,
        step,
        None if free is None else lambda lg: inside_free(lg, TWO_SIGMA_DELTA_W),
        lambda lgs: TWO_SIGMA_DELTA_W - delta_w(powers(lgs)),
    )
    lo95, hi95 = min(lo95, lo_all), max(hi95, hi_all)
    sigma68 = 0.5 * (hi_all - lo_all)
    return {
        "lag_sigma": max(sigma68, 0.25 * (hi95 - lo95)),
        "lag_interval": [lo_all, hi_all],
        "lag_interval_95": [lo95, hi95],
        "lag_sigma_68": sigma68,
        "lag_sigma_local": half,
        "lag_alternatives": alts,
        "lag_ambiguous": bool(ambiguous),
        "lag_sigma_method": "profile",
    }


def _contiguous(inside, lag: float, top: float, step: float, tol: float | None = None):
    """``[lo, hi]``, the contiguous part of ``{inside ≥ 0}`` around ``lag`` within
    ``[0, top]`` (:func:`_side`, ends to ``tol``, default a tenth of ``step``)."""
    tol = 0.1 * step if tol is None else tol
    lo = _side(inside, lag, 0.0, step, tol) if lag > 0 else 0.0
    hi = _side(inside, lag, top, step, tol) if lag < top else top
    return lo, hi


def _widened(free, lag: float, top: float, step: float, lo: float, hi: float):
    """``[lo, hi]`` widened to the contiguous part of ``{free ≥ 0}`` (each point a fit of
    the other nonlinear parameters: its ends only to a tenth of ``hi − lo``).

    ``free ≥ 0`` wherever the held profile's ``inside ≥ 0`` (the re-fitted power is at
    least the held one), so ``[lo, hi] ∋ lag`` lies in that set and each end is
    searched for from ``lo`` or ``hi`` outwards (:func:`_side`), not from ``lag``: 1-4
    fits per side instead of ~10 when τ is well determined."""
    tol = max(0.1 * step, 0.1 * (hi - lo))
    first = max(step, tol)
    f_lo = _beyond(free, lo, 0.0, first, tol) if lo > 0 else 0.0
    f_hi = _beyond(free, hi, top, first, tol) if hi < top else top
    return min(lo, f_lo), max(hi, f_hi)


def _beyond(free, end: float, bound: float, first: float, tol: float) -> float:
    """The end of ``{free ≥ 0}`` beyond ``end`` (inside) towards ``bound``
    (:func:`_side`), tried first at ``tol`` from ``end``: when ``free < 0`` there the
    end is within the tolerance of ``end`` and is ``end``, one fit instead of the
    ~5 of doubling and bisection (a τ well determined leaves the held set as it is:
    a platform coupling day's lag profile, 16 of 21 re-fits of τ saved)."""
    probe = end + (tol if bound > end else -tol)
    if (bound - probe) * (bound - end) <= 0:  # the bound is nearer than the tolerance
        return end
    if free(probe) < 0:
        return end
    return _side(free, probe, bound, first, tol)


def _two_sigma_set(
    inside, lag: float, top: float, step: float, contiguous=None, inside_many=None
) -> tuple[float, float]:
    """Hull ``[lo, hi]`` of the 95 % set ``{inside ≥ 0}`` near ``lag``: its contiguous
    part by doubling and bisection (:func:`_side`; widened to that of ``{contiguous ≥
    0}`` when given, :func:`_widened`), then islands of ``inside`` in a window on each
    side as wide as its own contiguous part (at least 10 steps), scanned at a quarter
    step or, for a wide window, at :data:`ISLAND_POINTS` lags (``inside_many``: ``inside``
    at an array of lags at once); the outermost island's outer edge is bisected."""
    tol = 0.1 * step
    lo, hi = _contiguous(inside, lag, top, step)
    ext = max(hi - lo, 10.0 * step)
    if contiguous is not None:  # islands are looked for beside the held set (cost)
        lo, hi = _widened(contiguous, lag, top, step, lo, hi)
    for a, b in ((max(lo - ext, 0.0), lo), (hi, min(hi + ext, top))):
        if b - a <= tol:
            continue
        n = int(min(np.ceil((b - a) / (0.25 * step)), ISLAND_POINTS)) + 1
        grid = np.linspace(a, b, n)
        vals = inside_many(grid) if inside_many is not None else [inside(g) for g in grid]
        ok = np.flatnonzero(np.asarray(vals) >= 0)
        if not ok.size:
            continue
        first, last = ok[0], ok[-1]  # the hull's new ends, to the bisection's tolerance
        if grid[first] < lo:
            edge = (
                grid[first] if first == 0 else _crossing(inside, grid[first], grid[first - 1], tol)
            )
            lo = min(lo, float(edge))
        if grid[last] > hi:
            edge = (
                grid[last] if last == n - 1 else _crossing(inside, grid[last], grid[last + 1], tol)
            )
            hi = max(hi, float(edge))
    return lo, hi


def _is_alias(d_lag: float, p: float, p_hat: float, period: float) -> bool:
    """Whether a lag ``d_lag`` away explaining ``p`` is an alias a whole period apart.

    With a per-period base (demodulation, ``options["lag_period"]``) a channel that
    repeats with the period fits alike at lags a period apart; the coupling search
    takes the shortest lag explaining at least :data:`ALIAS_SHARE` of the power
    (:func:`accal.closure.couplings._shortest_lag`), and the same rule makes the
    others equivalent here: the lag is known modulo the period only.  On the
    closure-detection platform runs the aliases of a 3e-8 m/s²/K coupling differed
    by 3e-4 of the explained power, ΔW ≈ 5 at W ≈ 1.5e4, while the coefficient was
    2-3 % (3σ) low: the model error is larger than that difference.
    """
    if period <= 0 or p < ALIAS_SHARE * p_hat:
        return False
    k = round(d_lag / period)
    return k >= 1 and abs(d_lag - k * period) <= 0.25 * period


def _alike_lags(alternatives: Sequence[dict[str, Any]]) -> list[float]:
    """The lags of ``lag_alternatives`` that fit as well as the chosen one: ``ΔW ≤ 1``,
    an alias a period apart, or the lag of the signal's extended model."""
    return [
        a["lag"]
        for a in alternatives
        if a["delta_w"] <= 1.0 or a.get("alias") or a.get("signal_model")
    ]


def _alternatives(power, powers, delta_w, at, lo, hi, top, step, dense=None):
    """Other local maxima of the profile over ``[0, top]`` with ``ΔW ≤ ALT_DELTA_W``,
    and aliases a period apart (:func:`_is_alias`); ``power`` is ``P(L)``, ``powers``
    ``P`` at an array of lags (the grid), ``at`` is (lag, power, period); ``dense``
    ``(lags, P)`` at every sample lag (used instead of the grid when given)."""
    lag, p_hat, period = at
    if top <= 0:
        return []
    if dense is not None:
        grid, values = np.asarray(dense[0], float), np.asarray(dense[1], float)
        keep = grid <= top + 1e-9
        grid, values = grid[keep], values[keep]
    else:
        grid = np.linspace(0.0, top, PROFILE_POINTS)
    if grid.size < 2:
        return []
    spacing = float(grid[1] - grid[0])
    far = (grid < lo - spacing) | (grid > hi + spacing)
    if not far.any():
        return []
    if dense is not None:
        # at every sample the profile wiggles: a peak is another lag only when the
        # profile dips between it and its neighbours by ΔW ≥ 1 (its prominence)
        # (the ends may be peaks too: padded below every value)
        prof = values
        floor = float(np.min(prof)) - p_hat
        found = prominent_peaks(
            np.r_[floor, prof, floor], prominence=p_hat / max(delta_w(0.0), 1e-300)
        )
        found -= 1
        peaks = found[far[found]]
    else:
        prof = np.full(grid.size, -np.inf)
        prof[far] = powers(grid[far])
        left = np.r_[-np.inf, prof[:-1]]
        right = np.r_[prof[1:], -np.inf]
        peaks = np.flatnonzero(far & (prof >= left) & (prof >= right) & np.isfinite(prof))
    # the grid can sit a fraction of a spacing off a narrow peak: refine the highest
    peaks = peaks[np.argsort(-prof[peaks])][:MAX_ALTERNATIVES]
    out = []
    for k in peaks:
        a, b = max(0.0, grid[k] - spacing), min(top, grid[k] + spacing)
        res = minimize_scalar(
            lambda lg: -power(lg),
            bounds=(a, b),
            method="bounded",
            options={"xatol": 0.25 * step, "maxiter": 30},
        )
        lg, p = (float(res.x), -float(res.fun)) if -res.fun > prof[k] else (grid[k], prof[k])
        dw = float(delta_w(p))
        if lo <= lg <= hi:
            continue
        if _is_alias(abs(lg - lag), p, p_hat, period):
            out.append({"lag": float(lg), "delta_w": max(dw, 0.0), "alias": True})
        elif dw <= ALT_DELTA_W:
            out.append({"lag": float(lg), "delta_w": max(dw, 0.0)})
    return sorted(out, key=lambda a: a["delta_w"])


def lag_sandwich_sigma(
    ctx: Context, name: str, x: NDArray[np.float64], tau: float, lag: float, half: float
) -> float:
    """σ of the lag from the least-squares sandwich under the residual's coloured noise.

    The lag maximising the explained power ``P(L)`` is an M-estimator; linearised at
    ``L̂`` its variance is ``J/H²`` (Huber 1967; White 1982, *Econometrica* 50, 1) with
    ``H = c²‖ż⊥‖²`` and ``J = c²·ż⊥ᵀVż⊥``: ``σ_L = √(q̂ᵀVq̂) / (|c|·‖ż⊥‖)``, ``ż⊥`` the
    regressor's derivative in the lag with the model and the regressor itself
    projected out, ``q̂`` its direction, ``V`` the noise covariance from the residual's
    PSD (:func:`accal.closure.wald.sandwich_cov`).  The derivative is a secant over
    ``±half`` (a pure lag of a kicked channel has spikes for a derivative: the secant
    over the profile's own width is the slope the data resolve).  With several data
    channels each has its coefficient; their informations add.  NaN when undefined.
    """
    use = ctx.use
    z0 = column(ctx, name, x, tau, lag)[use]
    lo, hi = max(lag - half, 0.0), lag + half
    zd = (column(ctx, name, x, tau, hi)[use] - column(ctx, name, x, tau, lo)[use]) / (hi - lo)
    r = ctx.residual
    info = 0.0
    for m in ctx.channel_masks():
        mz = z0 * m - ctx.basis.project(z0 * m)
        md = zd * m - ctx.basis.project(zd * m)
        nz = float(mz @ mz)
        if not nz > 0:
            continue
        c = float(mz @ r) / nz
        d = md - mz * (float(mz @ md) / nz)
        nd = float(np.sqrt(d @ d))
        if not (nd > 0 and c != 0):
            continue
        q = d / nd
        r_full = r - mz * c  # the coupling's own part out of the PSD estimate
        var_q = float(sandwich_cov(ctx.grid, r_full, q[None, :], ctx.leverage)[0, 0])
        if var_q > 0:
            info += (c * nd) ** 2 / var_q
    return float(1.0 / np.sqrt(info)) if info > 0 else float("nan")


def coefficient_interval(
    ctx: Context,
    name: str,
    x: NDArray[np.float64],
    tau: float,
    lag: float,
    wald: float,
    coef: float,
    sigma: float,
    lags: Sequence[float],
    extra_lags: Sequence[float] = (),
    per_axis: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """The coupling coefficient's 68 % profile interval with the lag and τ free.

    The coefficient is linear given ``(L, τ)``: ``ĉ(L, τ) = z̃ᵀr / z̃ᵀz̃`` and, with the
    profile's approximation of the module notes, ``W(L, τ) = W(L̂, τ̂)·P(L, τ)/P̂``, so
    ``χ²(c, L, τ) − χ²_min = ΔW(L, τ) + W(L, τ)·(c/ĉ(L, τ) − 1)²`` and the interval
    ``{c : min over (L, τ) ≤ 1}`` (Venzon & Moolgavkar 1988) is the hull over the
    grid points with ``ΔW ≤ 1`` of ``ĉ ± σ(L, τ)·√(1 − ΔW)``, ``σ = |ĉ|/√W(L, τ)``,
    and of ``coef ± sigma`` (the final fit's).  Grid: :data:`COEF_PROFILE_LAGS` lags
    over ``lags`` (the lag's 95 % set, whose projection holds every lag of the joint
    68 % set) and the ``extra_lags`` (other lags that fit as well: narrow peaks a grid
    misses, e.g. a kicked platform temperature's aliases a period apart) by
    :data:`COEF_PROFILE_TAUS` time constants in ``[0, max(2τ̂, τ̂ +``
    :data:`TAU_PROFILE_REACH` ``)]``.

    With several data channels (the platform's y and z) each has its coefficient
    ``c_k`` and the lag and τ are shared: ``ΔW`` is that of the summed power, and
    channel ``k``'s interval is the hull of ``ĉ_k ± σ_k(L, τ)·√(1 − ΔW)`` with
    ``W_k(L, τ) = W_k·P_k(L, τ)/P̂_k`` (the other channels' terms are zero at their own
    best coefficients).  ``per_axis`` holds each channel's ``coefficient`` and
    ``sigma`` (the final fit's), keyed by channel name.

    Where little of the channel lies outside the signal model (a temperature that is
    mostly orbit-periodic, a heater cycle on top) lag, τ and the coefficient trade
    along a ridge on which the final fit's linearised σ (its Jacobian columns) is too
    small: a 2e-8 m/s²/K coupling came out 2.198e-8 ± 5.2e-10 (3.8σ) at lag 482 s,
    τ 127 s, for a pure lag of 600 s (``docs/closure.md``); a channel that is nearly one
    line gets an interval over both signs (``tests/closure/test_coupling_sigma_ridge.py``).

    Returns ``{"coefficient_interval": [lo, hi], "coefficient_sigma_profile": (hi −
    lo)/2}`` (channel units; with several channels every channel's under
    ``"coefficient_axes"`` instead), empty when nothing is explained.
    """
    masks = ctx.channel_masks()
    names = list(ctx.channel_names) if len(masks) > 1 else [None]
    if len(masks) > 1 and not per_axis:
        return {}
    if not (wald > 0 and np.isfinite(wald)):
        return {}
    tau_hi = max(2.0 * tau, tau + TAU_PROFILE_REACH)
    lag_grid = np.r_[np.linspace(lags[0], lags[1], COEF_PROFILE_LAGS), np.asarray(extra_lags)]

    def fits(tc: float, lg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``ĉ_k`` and ``P_k`` (channels × lags) at one τ."""
        z = used_rows(ctx, name, x, float(tc), lg)
        z -= z.mean(axis=1, keepdims=True)
        c_k, p_k = [], []
        for m in masks:
            zr, nrm, ok = row_fit(ctx, z * m if len(masks) > 1 else z)
            c_k.append(np.where(ok, zr / np.where(ok, nrm, 1.0), np.nan))
            p_k.append(np.where(ok, zr**2 / np.where(ok, nrm, 1.0), 0.0))
        return np.array(c_k), np.array(p_k)

    parts = [fits(tc, lag_grid) for tc in np.linspace(0.0, tau_hi, COEF_PROFILE_TAUS)]
    c = np.concatenate([a for a, _ in parts], axis=1)
    p = np.concatenate([b for _, b in parts], axis=1)
    total = p.sum(axis=0)
    p_hat = max(float(total.max()), power_at(ctx, name, x, tau, lag), 1e-300)
    dw = wald * (1.0 - total / p_hat)
    if len(masks) == 1:
        p_hat_k, w_k, best = np.array([p_hat]), np.array([wald]), [(coef, sigma)]
    else:
        at_hat = fits(tau, [lag])[1][:, 0]
        p_hat_k = at_hat * p_hat / max(float(at_hat.sum()), 1e-300)
        best = [(per_axis[a]["coefficient"], per_axis[a]["sigma"]) for a in names]
        w_k = np.array([(cb / sb) ** 2 if sb > 0 else np.nan for cb, sb in best])
    out: dict[str, list[float]] = {}
    for k, a in enumerate(names):
        inside = (dw <= 1.0) & np.isfinite(c[k]) & (p[k] > 0)
        if not (p_hat_k[k] > 0 and w_k[k] > 0):
            inside[:] = False
        sig = np.abs(c[k][inside]) / np.sqrt(w_k[k] * p[k][inside] / p_hat_k[k])
        half = sig * np.sqrt(np.clip(1.0 - dw[inside], 0.0, 1.0))
        cb, sb = best[k]
        lo = float(min(np.min(c[k][inside] - half, initial=np.inf), cb - sb))
        hi = float(max(np.max(c[k][inside] + half, initial=-np.inf), cb + sb))
        out[a] = [lo, hi]
    per = {
        a: {"coefficient_interval": v, "coefficient_sigma_profile": 0.5 * (v[1] - v[0])}
        for a, v in out.items()
    }
    return per[None] if len(masks) == 1 else {"coefficient_axes": per}


def _wald(e: Effect) -> float:
    """``W`` of an effect's coefficient: its squared z, summed over data channels."""
    per = e.details.get("axes")
    if per:
        return float(
            sum((v["coefficient"] / v["sigma"]) ** 2 for v in per.values() if v["sigma"] > 0)
        )
    return float((e.coefficient / e.sigma) ** 2) if e.sigma > 0 else float("nan")


def _cover_sigma(
    info: dict[str, Any],
    lag: float,
    top: float,
    alike: Sequence[float] = (),
    local: float = 0.0,
) -> None:
    """Widen the reported intervals to at least ``L̂ ± σ`` and ``L̂ ± 2σ``, and to each of
    the ``alike`` lags ± ``local`` and ± 2 ``local`` (in place).

    The profile's sets come from the explained power alone; ``lag_sigma`` can be
    larger (the sandwich σ under the residual's coloured noise, the Jacobian's, a
    quarter of the 95 % set's width where the profile is not a parabola), and an
    interval narrower than ``±σ`` said less than σ does: on the closure-detection
    ``tests/indep`` couplings (11 found, 12 days per size) the true lag was inside the
    profile's 68 % set on 5 of 11, inside ``L̂ ± σ`` on 8 of 11.  The profile's own
    sets stay in ``lag_interval_profile`` and ``lag_interval_95_profile``.

    An alias or other lag that fits as well (``alike``) is located to a quarter step
    by its refinement and scatters like the chosen lag (``local``: its profile or
    sandwich σ); the profile put only its own half-width around them: on the
    closure-detection platform runs (3e-8 m/s²/K, 24 days) the true lag fell 0.1 s
    beyond an alias ± 0.06 s on 3 of 21.
    """
    sigma = float(info["lag_sigma"])
    for key, k in (("lag_interval", 1.0), ("lag_interval_95", 2.0)):
        if key not in info:
            continue
        lo, hi = info[key]
        info[key + "_profile"] = [lo, hi]
        lo, hi = min(lo, lag - k * sigma), max(hi, lag + k * sigma)
        for v in alike:
            lo, hi = min(lo, v - k * local), max(hi, v + k * local)
        info[key] = [max(lo, 0.0), min(hi, top)]


def _extended_context(search: Search, others: Sequence[Found], basis, lev) -> Context | None:
    """The context of ``others`` with the signal's extension (None without one)."""
    if search.signal0 is None:
        return None
    ext = search.signal_state(others, basis)
    return search.context(others, ext, ext.fit(search.y_u), lev)


def add_lag_uncertainties(search: Search, final: Sequence[Found], effects: list[Effect]) -> None:
    """Put each coupling's lag interval in its effect's details (in place).

    ``final`` and ``effects`` are aligned (one effect per entry of the final model).
    The profile is taken with the rest of the final model held
    (:meth:`~accal.closure.search.Search.state` of the others, already computed for
    their p-values).  A low-pass coupling's linearised σ (its Jacobian) is kept as
    ``lag_sigma_linearised`` and the larger of the two is ``lag_sigma``; the reported
    intervals hold ``L̂ ± σ`` and ``L̂ ± 2σ``, and every other lag that fits as well
    ± its local σ and twice that (:func:`_cover_sigma`).  The square of a
    channel shares its channel's lag and gets none of its own.

    The coefficient's profile interval with lag and τ free
    (:func:`coefficient_interval`, every coupling but angular ones; over the lag's 95 %
    set and the other lags that fit as well) goes in the details too, and its
    half-width replaces the effect's σ when larger (the linearised σ kept as
    ``coefficient_sigma_linearised``; ``effects`` is updated); with several data
    channels each channel's σ in ``details["axes"]`` likewise (``sigma_linearised``).
    """
    for i, (f, e) in enumerate(zip(final, effects, strict=True)):
        lag = f.prop.params.get("lag")
        name = str(f.prop.channel)
        x = search.aux.get(name)
        if f.prop.name != "auxiliary" or lag is None or name.endswith(SQUARED) or x is None:
            continue
        others = [g for j, g in enumerate(final) if j != i]
        basis, fit, lev = search.state(others)
        ctx = search.context(others, basis, fit, lev)
        top = max_lag(search.options, search.span)
        # an angular acceleration: τ = 0 and short lags, no low-pass to re-fit
        angular = channel_class(search.options, name) == "angular"
        if angular:
            top = min(top, ANGULAR_MAX_LAG)
        tau = float(f.prop.params.get("tau") or 0.0)
        xa, lag = np.asarray(x, float), float(lag)
        extended = _extended_context(search, others, basis, lev) if scans_every_lag(ctx) else None
        info = lag_uncertainty(
            ctx, name, xa, tau, lag, _wald(e), top, low_pass=not angular, extended=extended
        )
        if not info:
            continue
        local = info.pop("lag_sigma_local")  # the chosen lag's own set, not the hull
        sand = lag_sandwich_sigma(ctx, name, xa, tau, lag, max(local, ctx.grid.step))
        info["lag_sigma_profile"] = info["lag_sigma"]
        if np.isfinite(sand):
            info["lag_sigma_sandwich"] = sand
            if sand > info["lag_sigma"] and not info["lag_ambiguous"]:
                info["lag_sigma"] = sand
                info["lag_sigma_method"] = "sandwich"
        lin = e.details.get("lag_sigma")
        if lin:
            info["lag_sigma_linearised"] = float(lin)
            if lin > info["lag_sigma"]:
                info["lag_sigma"] = float(lin)
                info["lag_sigma_method"] = "linearised"
        # the other lags that fit as well are as uncertain as the chosen one is locally
        # (its profile or sandwich σ, not the hull over them), to the refinement's
        # quarter step at least
        local = max(local, sand if np.isfinite(sand) else 0.0)
        alike = _alike_lags(info.get("lag_alternatives", []))
        _cover_sigma(info, lag, top, alike, max(local, 0.25 * ctx.grid.step))
        if not angular:
            lags = info.get("lag_interval_95", [lag, lag])
            info.update(
                coefficient_interval(
                    ctx,
                    name,
                    xa,
                    tau,
                    lag,
                    _wald(e),
                    e.coefficient,
                    e.sigma,
                    lags,
                    alike,
                    e.details.get("axes"),
                )
            )
        per = info.pop("coefficient_axes", {})
        for ax, v in per.items():
            d = e.details["axes"][ax]
            d["coefficient_interval"] = v["coefficient_interval"]
            if v["coefficient_sigma_profile"] > 1.001 * d["sigma"]:
                d["sigma_linearised"] = d["sigma"]
                d["sigma"] = float(v["coefficient_sigma_profile"])
        info.update(per.get(e.axis, {}))  # the reported coefficient's channel
        e.details.update(info)
        prof = info.get("coefficient_sigma_profile", 0.0)
        if prof > 1.001 * e.sigma:  # the ridge of lag, τ and coefficient: the profile's σ
            e.details["coefficient_sigma_linearised"] = e.sigma
            effects[i] = dataclasses.replace(e, sigma=float(prof))
