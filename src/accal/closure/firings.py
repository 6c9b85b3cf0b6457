"""Couplings to an angular acceleration and thruster firings.

A thruster firing moves the linear and the angular accelerations at once (its force
and its torque), through the same Level-1B filter: a coupling fitted to an angular
acceleration can rest on the firings and be no lever arm at all.
:func:`firing_test` asks it to hold away from them (the channel's bursts, and the
firings of a THR1B file when ``grace-bias`` found one) and with a σ that does not
take the residual as stationary (:func:`accal.closure.hac.hac_wald`);
:func:`accal.closure.validation.validate` reports, and never removes, a coupling that
fails.  Split from :mod:`accal.closure.validation` (2026-11-29).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter

from accal.closure.candidates import Context, Proposal
from accal.closure.hac import hac_wald
from accal.closure.kinds import channel_class
from accal.closure.residual import WaldResult, wald_test

__all__ = [
    "BURST_MARGIN",
    "BURST_MAX_SHARE",
    "BURST_SIGMAS",
    "BURST_WINDOW",
    "FIRING_MAX_SHARE",
    "firing_test",
    "is_angular",
]

#: Bursts of an angular acceleration: samples more than :data:`BURST_SIGMAS` robust σ off
#: its running median over :data:`BURST_WINDOW` samples, and :data:`BURST_MARGIN` s either
#: side of them (the Level-1B filter's spread of a firing).
BURST_SIGMAS = 5.0
BURST_WINDOW = 241
BURST_MARGIN = 40.0
#: Largest share of the samples that may be bursts for :func:`firing_test` to be made.
BURST_MAX_SHARE = 0.2
#: The same with the firings of a THR1B file (``options["firings"]``): the real
#: 2003 and 2023 samples fire 26-39 times an hour, ±40 s of each is 32-45 % of a day.
FIRING_MAX_SHARE = 0.7


def is_angular(prop: Proposal, ctx: Context) -> bool:
    """Whether ``prop`` couples to an angular acceleration (by the channel's unit)."""
    return channel_class(ctx.options, str(prop.channel or "")) == "angular"


def _bursts(x: NDArray[np.float64], median: NDArray[np.float64], step: float) -> NDArray[np.bool_]:
    """Samples of ``x`` :data:`BURST_SIGMAS` robust σ off ``median``, its centred running
    median of :data:`BURST_WINDOW` samples (σ: 1.4826 × the median absolute deviation
    from it), grown by :data:`BURST_MARGIN` s."""
    if x.size < 2 * BURST_WINDOW:
        return np.zeros(x.size, dtype=bool)
    dev = np.abs(x - median)
    sig = 1.4826 * float(np.median(dev))
    if not sig > 0:
        return np.zeros(x.size, dtype=bool)
    m = max(int(round(BURST_MARGIN / step)), 0)
    return np.convolve(dev > BURST_SIGMAS * sig, np.ones(2 * m + 1), mode="same") > 0


def _bridged(z: NDArray[np.float64], ev: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``z`` (columns) with the samples ``ev`` interpolated linearly from the others
    (by sample index; held beyond the first and last kept samples)."""
    if not ev.any() or ev.all():
        return z
    idx = np.arange(ev.size)
    out = z.copy()
    for j in range(z.shape[1]):
        out[ev, j] = np.interp(idx[ev], idx[~ev], z[~ev, j])
    return out


def firing_test(prop: Proposal, ctx: Context, wald: WaldResult, factor: float) -> dict[str, Any]:
    """A coupling to an angular acceleration tested with the channel's bursts left out.

    The angular accelerations of a GRACE day are dominated by attitude-thruster
    firings, and a firing also moves the linear accelerations directly (a thruster
    pair's residual force), at the same samples; through the Level-1B filter both are
    ±35 s bumps, wider than the spike screen's window.  A lever-arm coupling fitted to
    them rests on a few coincident bumps, and the Wald test's stationary PSD makes its
    σ far too small: a coupling of y to ``ang_accl_z``, 4.9e-4 ± 2.8e-5 m/s² per
    rad/s², was removed on a `tests.indep` storm day with thrusters (seed 4010) and
    moved the y bias 17σ; a heteroskedasticity- and autocorrelation-consistent σ
    (Newey & West 1987, Econometrica 55, 703; Bartlett weights, 300 lags) gave 2.2σ.
    A lever arm acts between firings too.  So the columns are bridged over the bursts
    (:func:`_bursts`) by straight lines (:func:`_bridged`), orthogonalised against the model and
    tested on the same
    residual with the admitting test's PSD and degrees of freedom
    (:func:`accal.closure.residual.wald_test`); ``p_adj`` is its p-value times
    ``factor``.  Not made (``applicable`` False) without bursts or when they cover
    over :data:`BURST_MAX_SHARE` of the samples.

    With ``ctx.options["firings"]`` (the samples a THR1B file's firings reach,
    :func:`accal.gracejob.firings.closure_firings`) those are bursts too, up to
    :data:`FIRING_MAX_SHARE` of the samples.

    Firings too small to stand out of the channel stay in, and so do their linear
    bumps under the spike screen: on a QA thruster day (2026-11-29, ~150 firings with
    independent linear and angular sizes) couplings of z to ``ang_accl_y`` and
    ``ang_accl_z`` at 7-8 s lags passed this test at p 4e-17 and 1e-7 and one moved
    the z bias 5.5σ.  So the coupling, on every sample, is also referred to the
    Newey-West covariance (:func:`accal.closure.hac.hac_wald`): ``hac_p_adj``, its
    p-value times ``factor`` (there t = −2.0 and −2.3; a 5 cm lever arm: t ≫ 100).
    """
    z = np.asarray(prop.columns[ctx.use], dtype=np.float64)
    # the channel's running median: the burst threshold's centre
    smooth = median_filter(z, size=(BURST_WINDOW, 1), mode="nearest")
    ev = _bursts(z[:, 0], smooth[:, 0], ctx.grid.step)
    share = BURST_MAX_SHARE
    firings = ctx.options.get("firings")
    if firings is not None:  # the THR1B file's firings, spread by the filter
        ev |= np.asarray(firings, dtype=bool)[ctx.use]
        share = FIRING_MAX_SHARE
    n_ev = int(ev.sum())
    # every sample, with a σ that does not take the residual as stationary
    zt = np.linalg.svd(ctx.basis.complement(z), False)[0]
    hac_stat, hac_p = hac_wald(zt, ctx.residual)
    out: dict[str, Any] = {
        "samples": n_ev,
        "applicable": False,
        "hac_stat": hac_stat,
        "hac_p_adj": float(min(1.0, hac_p * factor)),
    }
    if firings is not None and n_ev > share * ev.size:
        # the known firings leave too little: nothing tells a lever arm from them
        return {**out, "applicable": True, "stat": 0.0, "p_adj": 1.0, "too_many": True}
    if n_ev == 0 or n_ev > share * ev.size or wald.psd is None:
        return out
    # the bursts bridged by straight lines between their neighbours: the column's slow
    # part stays whole (a column with holes in its orbital cycle would be tested on the
    # holes' pattern); the running median, which these used to be replaced by, holds the
    # bumps' level where firings fill half the window (THR1B days: p 1e-20 without them)
    u, sv, _ = np.linalg.svd(ctx.basis.complement(_bridged(z, ev)), False)
    keep = sv > 1e-8 * max(float(sv[0]) if sv.size else 0.0, 1e-300)
    if not keep.any():
        return {**out, "applicable": True, "stat": 0.0, "p_adj": 1.0}
    w = wald_test(ctx.grid, ctx.residual, u[:, keep], ctx.leverage, psd=wald.psd, psd_dof=wald.dof)
    p_adj = float(min(1.0, w.pvalue * factor))
    return {**out, "applicable": True, "stat": float(w.stat), "p_adj": p_adj}
