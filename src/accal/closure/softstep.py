"""A bias step whose transition is longer than the Level-1B filter's: a ramp of fitted duration.

The local columns of :mod:`accal.closure.transition` hold the misfit of ramps up to
the CRN filter's ±35 s.  An instrument's bias can also change over minutes (a heater
cycle, a settling after a mode change).  Fitted as an edge with those columns, such a
ramp's misfit is left in the fit, and the edge's least-squares weights, largest near
the epoch, take it for part of the size: a 5e-9 m/s² change over 5 min came out as
3.83e-9 ± 3.2e-10 (z −3.6), over 10 min 4.56e-9 ± 2.7e-10 (z −1.6; QA helper days of
2026-11-29).  Wider Gaussian ramps among the transition's columns (σ 20-160 s) fixed
the size but took the step's identifiability with them where the orbit template and
the smooth curve are in the null model (the 5 min QA step: p 0.055 given them; not
kept).

:func:`with_wide_ramp` instead tries the step as a linear ramp of each duration of
:data:`DURATIONS` centred at its epoch, ``clip((t − e)/D + 1/2, 0, 1)``: the ramp's
misfit to the edge, ``ramp − 1[t ≥ e]``, is tested given the step and its transition
columns by the spectrum-weighted Wald test of the effects
(:func:`accal.closure.residual.wald_test`) for the duration whose ramp (with the
transition's columns) fits best in least squares, at :data:`RAMP_LEVEL` over the
durations (Bonferroni; the most significant duration was the shortest, 60 s for a
300 s ramp, and left the size 3.4σ small).  When the data ask for it, the step's
column becomes that ramp, with the ramp's Jacobian in ``D``, ``−(t − e)/D²`` on the ramp,
as one more shape column: one level change still, its coefficient the size, its σ
holding the duration's (the Gauss-Newton linearisation, as for a coupling's lag).  The
calibrated series loses the ramp.  A filtered sharp step keeps its edge but for the
false ramps the level allows.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from accal.closure.final import independent
from accal.closure.residual import wald_test

if TYPE_CHECKING:  # annotations only
    from accal.closure.basis import Basis
    from accal.closure.candidates import Proposal
    from accal.closure.search import Search

__all__ = ["DURATIONS", "RAMP_LEVEL", "ramp_columns", "with_wide_ramp"]

#: Durations [s] of the linear ramps tried.
DURATIONS = (60.0, 120.0, 240.0, 480.0, 960.0)
#: Family-wise level of the test that the data ask for a ramp (Bonferroni over them).
RAMP_LEVEL = 0.01


def ramp_columns(
    t: NDArray[np.float64], epoch: float, duration: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The linear ramp of ``duration`` [s] centred at ``epoch``, ``clip((t − e)/D + 1/2,
    0, 1)``, and its derivative in ``D``, ``−(t − e)/D²`` on the ramp (zero off it)."""
    t = np.asarray(t, dtype=np.float64)
    x = (t - float(epoch)) / duration
    on = np.abs(x) < 0.5
    return np.clip(x + 0.5, 0.0, 1.0), np.where(on, -x / duration, 0.0)


def with_wide_ramp(aug: Proposal, s: Search, rest: Basis) -> Proposal:
    """``aug`` (a bias step with its transition columns, :func:`accal.closure.final.with_jacobian`)
    as the ramp of the best-fitting duration of :data:`DURATIONS` when its misfit to
    the edge is significant given ``aug`` and the model ``rest`` (module notes); else
    ``aug``."""
    if aug.name != "bias_step" or not aug.params.get("transition") or aug.axes is not None:
        return aug
    if int(aug.params.get("jacobian") or 0) != 1:
        return aug
    epoch = float(aug.params["epoch"])
    model = rest.extend(aug.columns[s.use])  # the step as an edge, with its transition
    fit = model.fit(s.y_u)
    shape = aug.columns[s.use][:, 1:]  # the transition's columns
    # the duration: the ramp (with the transition's columns) that fits best
    rss = {0.0: float(np.sum(fit.resid**2))}
    for d in DURATIONS:
        cols = np.column_stack([ramp_columns(s.t_all, epoch, d)[0][s.use], shape])
        rss[d] = float(np.sum(rest.extend(cols).fit(s.y_u).resid ** 2))
    d = min(rss, key=rss.get)
    if d == 0.0:
        return aug
    # whether the data ask for it: the ramp's misfit to the edge given the step
    ramp, jac = ramp_columns(s.t_all, epoch, d)
    zt = model.complement((ramp - aug.columns[:, 0])[s.use][:, None])
    if zt.shape[1] == 0:
        return aug
    p_ramp = float(wald_test(s.grid, fit.resid, zt, s.leverage(model)).pvalue)
    if not p_ramp * len(DURATIONS) < RAMP_LEVEL:
        return aug
    cand = dataclasses.replace(
        aug,
        columns=np.column_stack([ramp, aug.columns[:, 1:], jac]),
        labels=(*aug.labels, f"d{aug.labels[0]}/dtransition_duration"),
    )
    red = independent(rest, cand, s.use)
    if red.labels[0] != cand.labels[0]:  # the ramp itself is not independent
        return aug
    names = [*aug.params.get("jacobian_params", ()), "transition_duration"]
    kept = [names[cand.labels.index(lb) - 1] for lb in red.labels[1:]]
    params = {
        **aug.params,
        "jacobian_params": kept,
        "ramp_duration": d,
        "ramp_p": min(1.0, p_ramp * len(DURATIONS)),
    }
    return dataclasses.replace(red, params=params)
