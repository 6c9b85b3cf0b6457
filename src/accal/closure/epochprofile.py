"""Uncertainty of a bias step's epoch: the profile of the step's fit over its epoch.

The step scan (:func:`accal.closure.candidates.bias_step`) gives the explained power
``P(e)`` of a step ``1[t ≥ e]`` at every used sample ``e`` with cumulative sums, so the
profile of the fit over the epoch costs one scan.  With the rest of the final model held
(the step itself left out), the size's Wald statistic at epoch ``e`` is taken as
``W(e) ≈ W(ê)·P(e)/P(ê)`` (``W(ê)`` the size's squared z in the final fit), and the
epoch's interval is the likelihood-ratio one, ``{e : W(ê) − W(e) ≤ c}``.  A change
point is not a regular parameter: its profile decays linearly away from the epoch and
``W(ê) − W(e₀)`` at the true epoch is not χ²₁ (Hinkley 1970, *Biometrika* 57, 1: the
maximum of a two-sided random walk with drift), so ``c = 1`` covers the true epoch far
less than 68 % of the time.  Simulated (one step in white noise, 2000 draws per size):
``c = 1`` covers 89 %, 47 %, 23 % at ``W ≈`` 9000, 1000, 90; the 68 % quantile of
``W(ê) − W(e₀)`` is 0.0, 2.3, 3.1 there (4.2 at ``W ≈`` 10, below detection).
:data:`EPOCH_DELTA_W` ``= 3`` covers 82-95 % of detectable steps with ``W ≳ 1000`` and
~66 % near the detection limit.  The set is scanned over the whole record: samples outside the interval
around ``ê`` that fit as well (two near-equal edges, a step inside a data gap's
neighbourhood) make ``epoch_ambiguous`` true and widen ``epoch_interval`` to the hull.

Reported in the effect's details: ``epoch_interval`` [s, s] (the set widened by one
sample on each side: which of two neighbouring samples starts a sharp step is decided by
their own noise), ``epoch_sigma`` (half its width, at least one sample step),
``epoch_ambiguous``, and ``epoch_interval_local``, the contiguous part of the set around
the epoch (widened likewise).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.closure.candidates import Context, _scan
from accal.closure.lagprofile import _wald
from accal.closure.results import Effect

if TYPE_CHECKING:  # annotations only
    from accal.closure.search import Found, Search

__all__ = ["EPOCH_DELTA_W", "add_epoch_uncertainties", "epoch_uncertainty"]

#: Drop of the Wald statistic from the chosen epoch that bounds the epoch's interval
#: (the ~68 % quantile of the change point's likelihood ratio; see the module notes).
EPOCH_DELTA_W = 3.0


def epoch_uncertainty(ctx: Context, epoch: float, wald: float) -> dict[str, Any]:
    """The epoch's ~68 % profile interval, its σ and whether other epochs fit as well.

    Parameters
    ----------
    ctx : Context
        The final model without this step.
    epoch : float
        The step's epoch [s] (its first sample after the step).
    wald : float
        ``W(ê)``: the size's squared z in the final fit (summed over data channels).

    Returns
    -------
    dict
        ``epoch_interval``, ``epoch_sigma`` [s], ``epoch_ambiguous``; empty when the step
        explains nothing at ``epoch`` or ``wald`` is not finite.
    """
    t = ctx.t
    if t.size < 3 or not np.isfinite(wald):
        return {}
    ok = np.r_[True, np.diff(t) > 0]  # a step starts at the first sample of a time
    ok[0] = False  # a step at the first sample is the bias
    stat = _scan(ctx.basis, ctx.residual, ctx.channel_masks(), ok)
    i0 = min(int(np.searchsorted(t, epoch)), t.size - 1)
    p_hat = float(stat[i0]) if ok[i0] else 0.0
    if not p_hat > 0:
        return {}
    steps = np.diff(t)
    dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    inside = ok & (wald * (1.0 - stat / p_hat) <= EPOCH_DELTA_W)
    inside[i0] = True
    lo = hi = i0
    while lo > 0 and (inside[lo - 1] or not ok[lo - 1]):
        lo -= 1
    while hi + 1 < t.size and (inside[hi + 1] or not ok[hi + 1]):
        hi += 1
    idx = np.flatnonzero(inside)
    ambiguous = bool(np.any((idx < lo) | (idx > hi)))
    # one sample more on each side: which of two neighbouring samples starts the step is
    # decided by their own noise (a 3σ-per-sample step: 4 of 20 epochs one sample off
    # with a one-sample interval, σ = dt/√12 giving z = 3.5)
    t_lo, t_hi = float(t[max(idx[0] - 1, 0)]), float(t[min(idx[-1] + 1, t.size - 1)])
    return {
        "epoch_interval": [t_lo, t_hi],
        "epoch_sigma": max(0.5 * (t_hi - t_lo), dt),
        "epoch_ambiguous": ambiguous,
        # the contiguous part around the epoch, widened the same way
        "epoch_interval_local": [float(t[max(lo - 1, 0)]), float(t[min(hi + 1, t.size - 1)])],
    }


def add_epoch_uncertainties(search: Search, final: Sequence[Found], effects: list[Effect]) -> None:
    """Put each bias step's epoch interval in its effect's details (in place).

    ``final`` and ``effects`` are aligned; the profile is taken with the rest of the
    final model held (:meth:`~accal.closure.search.Search.state` of the others).
    """
    for i, (f, e) in enumerate(zip(final, effects, strict=True)):
        epoch = f.prop.params.get("epoch")
        if f.prop.name != "bias_step" or epoch is None or f.prop.params.get("pair"):
            continue
        others = [g for j, g in enumerate(final) if j != i]
        basis, fit, lev = search.state(others)
        ctx = search.context(others, basis, fit, lev)
        info = epoch_uncertainty(ctx, float(epoch), _wald(e))
        e.details.update(info)
