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
``Z̃`` the coupling's columns (one per data channel) with that model projected out and
``r`` the rest model's residual.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.candidates import Context
from accal.closure.couplings import SQUARED, _column
from accal.closure.widen import add_base_covariance

if TYPE_CHECKING:  # annotations only: the search imports the candidates
    from accal.closure.search import Found, Search

__all__ = ["add_alias_spread", "base_shift"]


def base_shift(ctx: Context, name: str, x: NDArray[np.float64], tau: float, lag: float):
    """``Σ_j β_R(z_j(L)) γ_j(L)`` per block (n_blocks, p): what the coupling at ``lag``
    (time constant ``tau``), re-fitted on the rest model ``ctx``, takes out of the base
    coefficients (NaN on blocks the fit does not identify)."""
    cols, _, _ = ctx.split(_column(ctx, name, x, tau, lag)[:, None], (name,))
    z = cols[ctx.use]
    keep = np.flatnonzero(np.any(z != 0.0, axis=0))
    fits = [ctx.basis.fit(z[:, j]) for j in keep]
    if not fits:
        return None
    zt = np.column_stack([f.resid for f in fits])
    gamma, *_ = np.linalg.lstsq(zt, ctx.residual, rcond=None)
    p = ctx.basis.p
    return sum(g * f.beta.reshape(-1, p) for g, f in zip(gamma, fits, strict=True))


def add_alias_spread(
    search: Search, final: Sequence[Found], effects: list[Any], cov: dict, basis: Any
) -> None:
    """Add the spread of the base coefficients over each coupling's alias lags to
    ``cov["cov_b"]`` and ``cov["cov_d"]`` (in place; ``basis`` the final model's, whose
    segments ``cov`` is indexed by) and say so in the effect's details
    (``base_sigma_aliases``: the aliases averaged over)."""
    for i, (f, e) in enumerate(zip(final, effects, strict=True)):
        alts = [float(a["lag"]) for a in e.details.get("lag_alternatives", []) if a.get("alias")]
        name = str(f.prop.channel)
        x = search.aux.get(name)
        lag = f.prop.params.get("lag")
        if f.prop.name != "auxiliary" or not alts or x is None or lag is None:
            continue
        if name.endswith(SQUARED) or len(f.prop.labels) != len(f.prop.axes or (0,)):
            continue  # a channel with its square: both would move together (not done)
        others = [g for j, g in enumerate(final) if j != i]
        rb, rfit, rlev = search.state(others)
        ctx = search.context(others, rb, rfit, rlev)
        xa, tau = np.asarray(x, float), float(f.prop.params.get("tau") or 0.0)
        held = base_shift(ctx, name, xa, tau, float(lag))
        if held is None:
            continue
        d = np.stack([base_shift(ctx, name, xa, tau, lg) - held for lg in alts])
        d = np.where(np.isfinite(d), d, 0.0)  # (K − 1, n_blocks, p)
        spread = np.einsum("kbp,kbq->bpq", d, d) / (len(alts) + 1)
        add_base_covariance(cov, basis, spread)
        e.details["base_sigma_aliases"] = alts
