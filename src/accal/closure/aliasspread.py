"""The base coefficients' spread over a coupling's alias lags.

With a per-period base (demodulation) a channel that repeats with the period (a
platform temperature kicked at every rotation) couples alike at lags a whole period
apart, and the lag profile reports those lags as aliases
(:func:`accal.closure.lagprofile.lag_uncertainty`, ``"alias": true``): the lag is known
modulo the period only.  The coefficient hardly moves between aliases (the channel's
periodic part fixes it), but the per-period base coefficients (a_Y, a_Z) do: they take
up the part of the channel's non-periodic variation (its random walk, its daily cycle)
that projects on the signal within each period, and that part differs between lags a
period apart.  The coupling search keeps the shortest alias
(:func:`accal.closure.couplings._shortest_lag`); on 2 of the 7 platform runs where a
3e-8 m/s²/K coupling was found (closure-detection, 2026-11-28) the true lag was another
alias and the a_Y after closure scattered 3.19 and 2.36 times their σ.

The data cannot choose among the aliases, so each base coefficient's covariance gains
the spread of its value over them: the model-averaging variance with equal weights
(Hoeting, Madigan, Raftery & Volinsky 1999, *Stat. Sci.* 14, 382, eq. 2: the total
variance is the within-model variance, already in ``cov_b``, plus the between-model
term), here ``Σ_i d_i d_iᵀ / K`` over the held lag and its ``K − 1`` aliases, with
``d_i = β(L_i) − β(L̂)`` the change of a block's base coefficients when the coupling is
moved to lag ``L_i``, its coefficient re-fitted and the rest of the final model held.
By the partitioned least squares (Frisch-Waugh-Lovell; Seber & Lee 2003, *Linear
Regression Analysis*, sec. 3.7):

.. math:: \\beta(L) = \\beta_R(y) - \\sum_j \\beta_R(z_j(L))\\,\\gamma_j(L),
   \\qquad \\gamma(L) = (\\tilde Z^\\top \\tilde Z)^{-1} \\tilde Z^\\top r,

with ``β_R(v)`` the base part of the least-squares fit of ``v`` on the rest of the model,
``Z̃`` the coupling's columns (one per data channel; with its square when the coupling
is the pair) with that model projected out and ``r`` the rest model's residual.

The coupling's own coefficients get the same between-model term, ``Σ_i (γ_i − γ̂)² / K``:
at an alias the channel's random walk is a regressor error, which attenuates the
coefficient (errors in variables; Fuller 1987, *Measurement Error Models*, §1.1),
and the profile's ``ΔW`` between aliases cannot tell which one is free of it (it is
computed as if the noise were the same at every lag, where the random walk's part sits
at the low frequencies the noise is red at: on seed 7307 the true lag had ``ΔW`` 2627).
On the 7 platform coupling seeds the coefficients' z went from 0.47, −3.13, 2.24, 1.66,
−2.43, 2.20, −1.52 to 0.45, −2.90, 2.24, 1.66, −1.40, 1.31, −0.98 (the 2nd and the 3rd's
lags are off the truth by more than an alias: 329.5 s with τ 10 s for 932.5 s, and
10.6 s with τ 14 s for 23.3 s).  Those two had stopped on the lag/low-pass ridge:
polished to the least-squares optimum (:func:`accal.closure.couplings._polish`) and with
the signal model's spread below (:func:`add_signal_model_spread`) the z are 0.33, −0.77,
0.92, 1.59, −0.86, 1.11, −0.97 (RMS 1.00).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.candidates import Context
from accal.closure.couplings import SQUARED
from accal.closure.couplingscan import column, square_about_mean
from accal.closure.validation import SIGNAL_STEP_REASON
from accal.closure.widen import add_base_covariance, scale_variance

if TYPE_CHECKING:  # annotations only: the search imports the candidates
    from accal.closure.search import Found, Search

__all__ = ["add_alias_spread", "add_signal_model_spread", "add_signal_step_spread", "base_shift"]


def base_shift(
    ctx: Context, name: str, x: NDArray[np.float64], tau: float, lag: float, pair: bool = False
):
    """``(Σ_j β_R(z_j(L)) γ_j(L), γ(L))``: what the coupling at ``lag`` (time constant
    ``tau``), re-fitted on the rest model ``ctx``, takes out of the base coefficients,
    per block (n_blocks, p; NaN on blocks the fit does not identify), and its
    coefficients, one per data channel (NaN for a channel it has no sample on); None
    when it has none.  ``pair``: the channel with its square, at the same lag and
    response (:func:`accal.closure.couplings._proposals`; the square's columns last)."""
    col = [column(ctx, name, x, tau, lag)]
    if pair:
        col.append(column(ctx, name + SQUARED, square_about_mean(x), tau, lag))
    cols, _, _ = ctx.split(np.column_stack(col), (name, name + SQUARED)[: len(col)])
    z = cols[ctx.use]
    keep = np.flatnonzero(np.any(z != 0.0, axis=0))
    fits = [ctx.basis.fit(z[:, j]) for j in keep]
    if not fits:
        return None
    zt = np.column_stack([f.resid for f in fits])
    g, *_ = np.linalg.lstsq(zt, ctx.residual, rcond=None)
    gamma = np.full(z.shape[1], np.nan)
    gamma[keep] = g
    p = ctx.basis.p
    return sum(gj * f.beta.reshape(-1, p) for gj, f in zip(g, fits, strict=True)), gamma


def add_alias_spread(
    search: Search,
    final: Sequence[Found],
    effects: list[Any],
    cov: dict,
    basis: Any,
    n_jumps: int = 0,
) -> None:
    """Add the spread over each coupling's alias lags to the base coefficients'
    covariance (``cov["cov_b"]``, ``cov["cov_d"]``, per segment of the final model's
    ``basis``) and to the coupling's own coefficients (their σ in ``effects``, their rows
    and columns of ``cov["v_ww"]``, whose first ``n_jumps`` columns are the jumps'); in
    place.  The details say which aliases (``base_sigma_aliases``) and the σ before
    (``coefficient_sigma_without_aliases``, per channel ``sigma_without_aliases``)."""
    j0 = n_jumps
    for i, (f, e) in enumerate(zip(final, effects, strict=True)):
        q, start = f.prop.columns.shape[1], j0
        j0 += q
        alts = [float(a["lag"]) for a in e.details.get("lag_alternatives", []) if a.get("alias")]
        name = str(f.prop.channel)
        x = search.aux.get(name)
        lag = f.prop.params.get("lag")
        if f.prop.name != "auxiliary" or not alts or x is None or lag is None:
            continue
        pair = bool(f.prop.params.get("pair"))  # the channel and its square
        if name.endswith(SQUARED) or q < _main_columns(f):
            continue
        others = [g for j, g in enumerate(final) if j != i]
        rb, rfit, rlev = search.state(others)
        ctx = search.context(others, rb, rfit, rlev)
        xa, tau = np.asarray(x, float), float(f.prop.params.get("tau") or 0.0)
        held = base_shift(ctx, name, xa, tau, float(lag), pair)
        if held is None:
            continue
        moved = [base_shift(ctx, name, xa, tau, lg, pair) for lg in alts]
        if any(m is None for m in moved):  # an alias with no used sample: cannot say
            continue
        d = np.stack([m[0] - held[0] for m in moved])
        d = np.where(np.isfinite(d), d, 0.0)  # (K − 1, n_blocks, p)
        add_base_covariance(cov, basis, np.einsum("kbp,kbq->bpq", d, d) / (len(alts) + 1))
        dg = np.stack([m[1] - held[1] for m in moved])
        var_g = np.nansum(dg**2, axis=0) / (len(alts) + 1)  # per column
        effects[i] = _widened_coefficients(e, f, var_g, cov["v_ww"], start)
        effects[i].details["base_sigma_aliases"] = alts


def add_signal_model_spread(
    search: Search,
    final: Sequence[Found],
    effects: list[Any],
    cov: dict,
    basis: Any,
    fit: Any,
    n_jumps: int = 0,
) -> None:
    """Add the spread of each coupling's coefficients between the declared signal model
    and the one a degree beyond it to their σ (in place; demodulation bases only).

    The per-period signal of the "mean" model is constant within a period, while the
    signal changes (a daily term, a once-per-rev term); the change, modulated by θ, is
    left in the residual with the period's rhythm, and a platform temperature kicked at
    every rotation has that rhythm too.  On a platform run with a 3e-8 m/s²/K coupling
    at the true lag (seed 7304, data drawn by ``tests.indep``) the least squares took
    +1.7e-9 (y) and +2.9e-9 m/s²/K (z) from the signal alone, 5-9 times the
    coefficient's σ, and 1.3e-10 and 2.2e-10 with the signal's slope in the model
    (``signal0``, :func:`accal.closure.validation.validate`'s extension).  The data
    do not say which model holds, so each coupling coefficient's variance gains the
    between-model term of the two with equal weights (Hoeting et al. 1999, eq. 2, as
    for the aliases above): ``d²/2``, ``d`` the change of the coefficient when the
    final model (the other effects with it) is fitted with the extension.  Without
    a leak ``E[d²]`` is the extension's extra variance (nested least squares), so the
    σ grows by at most half of that.  The details keep the σ before
    (``coefficient_sigma_without_signal_model``, per channel
    ``sigma_without_signal_model``) and the change (``signal_model_change``).
    """
    if search.signal0 is None or not final:
        return
    ext = search.signal_state(final, basis)
    g_ext = ext.fit(search.y_u).gamma
    if g_ext.size != fit.gamma.size:
        return
    c0 = 0  # the effect's first column in gamma (in v_ww after the jumps' columns)
    for i, (f, e) in enumerate(zip(final, effects, strict=True)):
        q, c_start = f.prop.columns.shape[1], c0
        c0 += q
        main = _main_columns(f)
        if f.prop.name != "auxiliary" or q < main:
            continue
        d = g_ext[c_start : c_start + main] - fit.gamma[c_start : c_start + main]
        if not np.all(np.isfinite(d)):
            continue
        start = n_jumps + c_start
        effects[i] = _widened_coefficients(e, f, d**2 / 2.0, cov["v_ww"], start, "signal_model")
        effects[i].details["signal_model_change"] = d.tolist()


def add_signal_step_spread(search: Search, cov: dict, basis: Any, fit: Any) -> None:
    """Add the spread between a bias step and a step of the signal to the base
    coefficients' covariance (``cov["cov_b"]``, ``cov["cov_d"]``; in place), for each
    significant bias step rejected because a change of the signal at its epoch
    explains it as well (:func:`accal.closure.validation.signal_step_p`).

    The data then say that something changed there, not what: a bias step (which the
    model without it leaves in that period's ``a_Y``, ``a_Z``: 7.8σ on a run with a
    1e-9 m/s² step 60 s into its first period) or a change of the signal (which the
    model without a step averages over the period, as the period's value should be:
    0.35σ on a run with a 1e-9 m/s² step of ``a_Y``).  The values stay those of the
    model without the step; their variance gains the between-model term of the two
    with equal weights, ``d²/2`` (Hoeting et al. 1999, eq. 2, as above), ``d`` the
    change of each base coefficient when the step is fitted with the final model.  A
    note names the step and the largest change.
    """
    p = basis.p
    b0 = fit.beta.reshape(-1, p)
    for f in search.rejected:
        why = f.verdict.reason or ""
        if not (why.startswith(SIGNAL_STEP_REASON) and f.p_adj < search.alpha):
            continue
        ext = basis.extend(f.prop.columns[search.use])
        b1 = ext.fit(search.y_u).beta.reshape(-1, p)
        if b1.shape != b0.shape:
            continue
        d = np.where(np.isfinite(b1 - b0), b1 - b0, 0.0)
        add_base_covariance(cov, basis, np.einsum("bp,bq->bpq", d, d) / 2.0)
        search.note(
            "bias_step",
            None,
            f"the bias step at {float(f.prop.params['epoch']):.1f} s (not removed: a change "
            "of the signal explains it as well) is in the σ of the base coefficients it "
            f"would move (by up to {np.abs(d).max():.3g} m/s²): their variance holds half "
            "the square of that change",
        )


def _main_columns(f: Found) -> int:
    """A coupling's main columns, its first ones: one per data channel, twice with the
    channel's square (the pair); any Jacobian columns follow."""
    return len(set(f.prop.axes or (None,))) * (1 + bool(f.prop.params.get("pair")))


def _widened_coefficients(e: Any, f: Found, var_g, v_ww, start: int, what: str = "aliases") -> Any:
    """The coupling's coefficients' variance plus ``var_g`` (one per main column, the
    first ones of the effect): its rows and columns of ``v_ww`` scaled (correlations
    kept, in place), the effect's σ and per-channel σ updated; returns the effect.
    ``what`` names the σ before in the details (``sigma_without_<what>``)."""
    axes = list(f.prop.axes)[: var_g.size] if f.prop.axes is not None else [None]
    sig: dict = {}
    for k, ax in enumerate(axes):
        old = float(np.sqrt(max(v_ww[start + k, start + k], 0.0)))
        new = float(np.sqrt(old**2 + var_g[k]))
        if old > 0 and new > old:
            scale_variance(v_ww, start + k, new / old)
        sig.setdefault(ax, var_g[k])  # a channel's first column: its coupling (then the square)
    for ax, d in e.details.get("axes", {}).items():
        if ax in sig and sig[ax] > 0:
            d[f"sigma_without_{what}"] = d["sigma"]
            d["sigma"] = float(np.hypot(d["sigma"], np.sqrt(sig[ax])))
    extra = sig.get(e.axis, sig.get(None, 0.0))
    if not extra > 0:
        return e
    e.details[f"coefficient_sigma_without_{what}"] = e.sigma
    return dataclasses.replace(e, sigma=float(np.hypot(e.sigma, np.sqrt(extra))))
