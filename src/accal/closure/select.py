"""Close the loop: find what a linear base model lacks, add it, refit — and do no harm.

:func:`close_loop` sets the problem up, runs the search (:mod:`accal.closure.search`)
and makes the final fit (:mod:`accal.closure.final`):

1. the *null model*: the declared base (polynomial, or the per-period demodulation
   model as a block base) plus, without a reference and with an orbit period, the
   orbit-periodic signal (:class:`accal.closure.nuisance.OrbitTemplate`, orbit
   period refined on the data): candidates are tested, validated and estimated with
   the signal already fitted, so a candidate that can mimic the signal finds nothing
   to fit;
2. the channels offered for couplings are screened
   (:func:`accal.closure.inputs.screen_channels`): never the target itself or a copy
   of it (a channel collinear with the data), nor a constant or too short one;
   ``result.considered`` says which were tried and why the others were not;
3. outliers (bursts, spikes) are left out of the analysis
   (:func:`accal.closure.outliers.outliers`);
4. forward selection (:func:`accal.closure.search.run`): test of significance with
   multiplicity, then validation (identifiable, confirmed on held-out stretches,
   plausible) before anything is added; significant candidates that fail are
   reported in ``result.rejected`` with the reason; at the first coupling whose
   lagged or filtered channel is unknown at used samples (before the record, after
   its holes) the search is made again without those samples
   (:func:`~accal.closure.unknownhistory.without_unknown_history`), and a later
   coupling it does not find again is rejected;
5. the final fit with the Jacobians of searched time constants and lags, the
   coloured-noise covariances (coupling coefficients also with their spread over
   alias lags and over the signal model, :mod:`accal.closure.aliasspread`), and a
   catch-all test of what is left (``unexplained``, reported, never removed).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.closure.aliasspread import (
    add_alias_spread,
    add_signal_model_spread,
    add_signal_step_spread,
)
from accal.closure.basis import Basis
from accal.closure.blockbase import BlockBase
from accal.closure.boxes import give_back, reject_boxes
from accal.closure.channelfault import fault_notes, faulted
from accal.closure.epochprofile import add_epoch_uncertainties
from accal.closure.final import covariances, describe, refer_exponentials
from accal.closure.inputs import (
    MIN_SAMPLES,
    prepared_inputs,
    screen_channels,
    usable_proxies,
)
from accal.closure.jumpfit import add_jump_covariance, jump_columns, jump_effects
from accal.closure.jumps import jumps_first
from accal.closure.kinds import EFFECT_NAMES, kind_of, unit_of
from accal.closure.lagprofile import add_lag_uncertainties
from accal.closure.nullsetup import NullSetup
from accal.closure.outliers import OUTLIER_SIGMAS, edge_runs, outliers, spikes
from accal.closure.proxybasis import leak_cov
from accal.closure.residual import characterise
from accal.closure.results import BaseCoefficient, ClosureResult, Effect
from accal.closure.search import Found, Search, run, swap_smooth
from accal.closure.significance import describe_smooth, unexplained_test
from accal.closure.unknownhistory import (
    UNKNOWN_DEPTH,
    fired,
    new_unknown,
    pause_at,
    reject_unconfirmed,
    without_unknown_history,
)
from accal.closure.validation import SignalProxies
from accal.closure.widen import placebo_step_sigmas, widened_couplings
from accal.errors import ValidationError, check_option

__all__ = [
    "DEFAULT_CANDIDATES",
    "MIN_SAMPLES",
    "BaseCoefficient",
    "ClosureResult",
    "Effect",
    "close_loop",
    "screen_channels",
]

#: A residual within this factor of the data's numerical resolution is rounding.
RESOLUTION_FACTOR = 1000.0

DEFAULT_CANDIDATES = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
    "scale",
)


def _resolve(candidates: Sequence[str | Callable]) -> list[tuple[str, Callable]]:
    out = []
    for c in candidates:
        if callable(c):
            out.append((getattr(c, "__name__", "custom"), c))
        else:
            check_option("candidates", c, tuple(n for n in EFFECT_NAMES if n != "unexplained"))
            out.append((c, kind_of(c).builder))
    return out


def _families(builders, orbit_period, template: bool) -> int:
    n = 0
    for name, _ in builders:
        n += 2 if name == "periodic" and orbit_period and not template else 1
    return max(n, 1)


def _signal_model(template, proxies: SignalProxies | None, in_model=()) -> dict[str, Any]:
    """``ClosureResult.signal_model``: the template's description, the proxies used and
    those whose unexplained signal is in the model (``in_model``)."""
    if template is None:
        return {}
    out = dict(template.describe())
    if proxies is not None:
        out["signal_proxies"] = list(proxies.names)
        out["proxies_in_model"] = list(in_model)
    return out


def _spikes_out(t_all, y_all, chan_all, use):
    """``use`` without the data's short pulses (:func:`~accal.closure.outliers.spikes`),
    before the null model is fitted: (use, number left out)."""
    hit = spikes(y_all[use], None if chan_all is None else chan_all[use], t_all[use])
    if not hit.any():
        return use, 0
    use = use.copy()
    use[np.flatnonzero(use)[hit]] = False
    return use, int(hit.sum())


def _leave_out_outliers(setup, st, use, aux_all, n_spikes=0):
    """Outliers of the base fit's residual and of the channels left out: (st, use, notes)."""
    notes: dict[tuple, dict[str, Any]] = {}
    resid = st["fit0"].resid
    bad = outliers(resid, st["chan_u"], st["t_u"])
    if st["chan_u"] is None:
        bad = edge_runs(bad, resid)
    n_data = int(bad.sum()) + n_spikes
    n_steep, steep = 0, np.zeros_like(bad)
    if st["template"] is not None:  # profile steeper than one-sample bins resolve
        sigma = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
        steep = st["template"].unresolved(setup.y_all[use], sigma) & ~bad
        n_steep = int(steep.sum())
        bad |= steep
    for x in aux_all.values():  # a firing shows in the angular channels too
        xu = x[use]
        ok = np.isfinite(xu)
        if ok.all():
            bad |= outliers(xu - np.median(xu), st["chan_u"], st["t_u"])
    n_out = int(bad.sum()) - n_steep + n_spikes
    first = None
    if bad.any():
        if n_steep < int(bad.sum()):
            first = float(st["t_u"][bad & ~steep][0])
        use = use.copy()
        use[np.flatnonzero(use)[bad]] = False
        st = setup.build(use)
    if n_out:
        notes[("outliers",)] = {
            "name": "outliers",
            "channel": None,
            "note": f"{n_out} samples left out of the analysis: more than "
            f"{OUTLIER_SIGMAS:g} robust σ from the running median of the residual ({n_data}) or "
            "of a candidate channel, and their neighbours (bursts, spikes, thruster firings: "
            "no candidate models them; they stay in the data)",
            "details": {"n": n_out, "first": first},
        }
    if n_steep:
        notes[("unresolved",)] = {
            "name": "unresolved",
            "channel": None,
            "note": f"{n_steep} samples left out of the analysis where the orbit profile "
            "changes faster than one-sample phase bins follow (eclipse edges; they stay "
            "in the data)",
            "details": {"n": n_steep},
        }
    return st, use, notes


def close_loop(
    t: ArrayLike,
    y: ArrayLike,
    *,
    base: str | ArrayLike | BlockBase = "poly1",
    aux: dict[str, ArrayLike] | None = None,
    valid: ArrayLike | None = None,
    candidates: Sequence[str | Callable] = DEFAULT_CANDIDATES,
    alpha: float = 0.01,
    max_effects: int = 5,
    orbit_period: float | None = None,
    catchall_knots: int = 24,
    options: dict[str, Any] | None = None,
    channel: ArrayLike | None = None,
    channel_names: Sequence[str] | None = None,
    noise_psd: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    resolution: float | None = None,
    reference: ArrayLike | None = None,
    signal_model: str = "auto",
    channel_units: dict[str, str] | None = None,
    screened: Sequence[dict[str, Any]] = (),
    signal_proxies: dict[str, ArrayLike] | None = None,
    psd_update: Callable[[NDArray[np.float64]], Any] | None = None,
) -> ClosureResult:
    """Find the effects a linear base model lacks, add them and refit.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, strictly increasing (within each channel, non-decreasing
        overall when ``channel`` is given) [s].
    y : array_like, shape (N,)
        Data [m/s²]: one accelerometer axis, or raw − reference (then give the
        reference as ``reference``).
    base : {"poly0", "poly1", "poly2", "poly3"}, array_like (N, p0) or BlockBase
        The declared model: a polynomial in ``t − t0`` (``t0``: first used sample;
        one per channel), a dense design, or a block-diagonal design
        (:class:`~accal.closure.blockbase.BlockBase`, e.g. the per-period demodulation
        model; its ``signal`` columns are the signal part of the null model).
    aux : dict of str to array_like, shape (N,), optional
        Channels offered to the coupling search (temperatures, angular
        accelerations, any numeric column of a table); screened first
        (:func:`screen_channels`).
    valid : array_like of bool, shape (N,), optional
        Samples to use (non-finite ``y`` are always excluded).
    candidates : sequence of str or callable
        Kind names (:mod:`accal.closure.kinds`) or builder functions
        ``f(Context) -> list[Proposal]``.
    alpha : float
        Family-wise false-detection probability per selection step, and the level
        of the final ``unexplained`` test.
    max_effects : int
        Upper bound on the number of effects added.
    orbit_period : float, optional
        Nominal orbit period [s]: the orbit-phase signal model (without a
        reference; the period is refined on the data unless
        ``options["orbit_period_fixed"]``), orbit harmonics (with one), per-orbit
        residual means.
    catchall_knots : int
        Knots of the piecewise-linear basis of the ``unexplained`` test; 0 disables it.
    options : dict, optional
        Search settings passed to the builders (see :class:`Context`);
        ``{"step_transition": True}`` for low-passed data (``grace-bias`` sets it for
        Level-1B files): bias steps fitted as ramps (:mod:`accal.closure.transition`);
        ``{"firings": mask}`` (bool, the shape of ``t``: samples a thruster firing
        reaches) for the firing test of couplings to an angular acceleration, or
        ``{"firings_unknown": True}`` to report such couplings and never remove them
        (:func:`accal.closure.firings.firing_test`).
    channel, channel_names : optional
        Several data channels on one time grid (e.g. the platform's y and z axes,
        interleaved in time); noises independent with a common PSD; every generic
        effect gets one coefficient per channel.
    noise_psd : callable, optional
        The instrument's two-sided noise PSD ``S(f)`` [(m/s²)²/Hz]: the reported
        covariances use it (as the declared estimator does); tests use the estimate.
    resolution : float, optional
        Numerical resolution of ``y`` [m/s²]: a residual within
        :data:`RESOLUTION_FACTOR` of it is rounding, and the search stops.
    reference : array_like, shape (N,), optional
        The reference acceleration ``y`` was differenced with: enables the ``scale``
        candidate and, as the signal is then removed, no signal model is used.
    signal_model : {"auto", "orbit", "none"}
        The signal part of the null model: ``"auto"`` is ``"orbit"`` when there is no
        reference and an ``orbit_period`` (the raw signal is then in ``y``), else
        ``"none"``.
    channel_units : dict of str to str, optional
        Unit of each ``aux`` channel (plausibility bounds, reported units).
    screened : sequence of dict, optional
        Channels the caller left out before (``{"channel", "status", "reason"}``),
        reported with this screening's in ``result.considered``; an entry with status
        ``"considered"`` is the caller's note on a channel it offers (e.g. how it was
        filtered), kept as the reason of that channel's own entry.
    signal_proxies : dict of str to array_like, shape (N,), optional
        Series carrying the same signal but not this channel's instrument: the other
        axes of the same accelerometer [m/s²].  Never candidates.  With the
        orbit-phase signal model (no reference), an instrument effect is removed only
        when it stays significant with them in the model
        (:func:`accal.closure.validation.signal_proxy_test`: a storm's onset on every
        axis is not a bias step).  A series not finite on every used sample is left
        out (noted).
    psd_update : callable, optional
        For a noise model that depends on the effects found (``accal demod --psd auto``
        estimates it again without them): when the search found any, called with
        their fitted sum on every sample (N,) [m/s², as subtracted from ``y``; NaN
        at the samples the search left out because a coupled channel is made up
        there (the first lag of the record), whose misfit is not noise]; a PSD it
        returns replaces ``noise_psd`` in the final fit (None keeps it).  The search does not use ``noise_psd`` (its tests estimate the noise from
        the residual), so the caller need not search twice.

    Returns
    -------
    ClosureResult

    Raises
    ------
    ValidationError
        Bad shapes, fewer than :data:`MIN_SAMPLES` usable samples, an unknown
        candidate, base or signal model.
    """
    check_option("signal_model", signal_model, ("auto", "orbit", "none"))
    if not 0 < alpha < 1:
        raise ValidationError(f"alpha must be in (0, 1), got {alpha}")
    opts = {**(options or {}), "channel_units": dict(channel_units or {})}
    inp = prepared_inputs(
        t, y, valid, reference, aux, channel, channel_names, signal_proxies, screened, opts
    )
    t_all, y_all, chan_all, names, use, ref_all, aux_all, proxies_all, considered = inp
    if signal_model == "auto":
        signal_model = "orbit" if ref_all is None and orbit_period else "none"
    builders = _resolve(candidates)
    fixed = bool(opts.get("orbit_period_fixed", False))
    setup = NullSetup(t_all, y_all, base, chan_all, names, signal_model, orbit_period, fixed)
    st, use, notes, families, jumps, proxies = _null_model(
        setup, use, aux_all, builders, alpha, proxies_all
    )
    opts.update(_search_settings(st, builders, families, alpha))

    make = _search_maker(setup, builders, alpha, opts, aux_all, ref_all, proxies, notes)
    stop = _floor_stop(resolution)
    search, st = _select(make, st, use, setup, max_effects, stop)
    st, jumps = _given_back(search, setup, st, jumps)
    reject_boxes(search, *_final_fit(search, setup, st)[::2])
    st = _proxies_off_effects(search, setup, st)
    noise_psd = _updated_psd(search, setup, st, jumps.jumps, use, noise_psd, psd_update)
    floored = stop is not None and stop(search)
    args = (catchall_knots, noise_psd, floored, considered, opts, jumps.jumps)
    return _determined_result(search, setup, st, args)


def _determined_result(search: Search, setup: NullSetup, st, args: tuple) -> ClosureResult:
    """:func:`_finish`'s result, refitted without the effects the data do not determine
    (:func:`reject_undetermined`) when there are any."""
    res = _finish(search, setup, st, *args)
    if not reject_undetermined(search, res, len(args[-1])):
        return res
    setup.proxy_exclude = None
    st = _installed(search, setup.build(search.use))
    return _finish(search, setup, _proxies_off_effects(search, setup, st), *args)


#: An instrument effect whose final coefficient is within this many of its σ of zero
#: (its sign not determined) is not removed (:func:`reject_undetermined`).
DETERMINED_SIGMAS = 1.0


def reject_undetermined(search: Search, res: ClosureResult, n_jumps: int) -> bool:
    """Move the instrument effects of ``res`` that are not determined (``|c| <``
    :data:`DETERMINED_SIGMAS` ``σ``, the final σ: lag and τ profiled, the proxies'
    share) from ``search.found`` to its rejected ones; whether any was.

    The selection's test holds a coupling's lag and time constant at their best values;
    with them free its coefficient can be anything: QA (2026-11-30, a GRACE-FO day with
    a thermostat heater and a storm), a coupling of y removed with −8.1e-8 ± 1.7e-6
    m/s²/K, lag 424 ± 1,784 s, made the calibrated y 3.2× further from the truth than
    no closure, and its bias σ 30,000× larger.  At 2σ the rule also held back four
    couplings of the same QA set whose removal brought the series closer to the truth
    (1.1-1.9σ from zero, e.g. −3.7e-9 ± 2.2e-9 for −5.1e-9); at 1σ one (−3.0e-9 ± 4.8e-9
    for −6.0e-9).
    """
    effects = list(res.effects[n_jumps:])
    if len(effects) != len(search.found):
        return False
    bad = [
        k
        for k, e in enumerate(effects)
        if e.instrument
        and e.sigma is not None
        and np.isfinite(e.sigma)
        and e.sigma > 0
        and abs(e.coefficient) < DETERMINED_SIGMAS * e.sigma
    ]
    for k in reversed(bad):
        f, e = search.found.pop(k), effects[k]
        reason = (
            f"not determined: {e.coefficient:.3g} ± {e.sigma:.2g} {e.unit} once its "
            f"free parameters are profiled (within {DETERMINED_SIGMAS:g}σ of zero, its sign "
            "not fixed by the data): removing it would change the series by an amount the "
            "data do not determine"
        )
        verdict = dataclasses.replace(f.verdict, ok=False, reason=reason)
        search.rejected.append(dataclasses.replace(f, verdict=verdict))
    return bool(bad)


def _given_back(search: Search, setup: NullSetup, st, scan):
    """Edge-scan jumps a least-squares step gives back put back into the data
    (:func:`~accal.closure.boxes.give_back`), the null fit rebuilt: ``(st, scan)``."""
    kept = give_back(search, *_final_fit(search, setup, st)[::2], scan.jumps)
    if len(kept) == len(scan.jumps):
        return st, scan
    sizes = np.array([j.size for j in kept])
    setup.y_all = setup.y_all_given - jump_columns(setup.t_all, kept) @ sizes
    st = setup.build(search.use)
    search.y_u = setup.y_all[search.use]
    search.drop_caches()
    return st, dataclasses.replace(scan, jumps=kept)


def _proxies_off_effects(search: Search, setup: NullSetup, st):
    """The null fit rebuilt with the proxies orthogonal to the effects found
    (:func:`~accal.closure.proxybasis.add_proxies`' ``exclude``), for the final fit."""
    if not setup.proxies_in_model or not search.found:
        return st
    setup.proxy_exclude = np.column_stack([f.model_prop.columns for f in search.found])
    return _installed(search, setup.build(search.use))


def _installed(search: Search, st: dict[str, Any]) -> dict[str, Any]:
    """``st``, a null fit rebuilt on ``search.use``, made the search's null model (its
    caches dropped, as :func:`_search_maker` sets them up); returned."""
    search.basis0, search.beta = st["basis0"], st["beta"]
    search.drop_caches()
    search.cache["template"], search.cache["null_basis"] = st["template"], st["basis0"]
    return st


def _updated_psd(search: Search, setup: NullSetup, st, jumps, use, noise_psd, psd_update):
    """``noise_psd``, or what ``psd_update`` (:func:`close_loop`) returns for the fitted
    sum of the effects found (NaN where the search left samples out: a channel made
    up there) when the search found any."""
    if psd_update is None or not (search.found or jumps):
        return noise_psd
    model = _effects_sum(search, setup, st, jumps)
    model[use & ~search.use] = np.nan
    new_psd = psd_update(model)
    return noise_psd if new_psd is None else new_psd


def _search_settings(st, builders, families: int, alpha: float) -> dict[str, Any]:
    """The options the builders get from the null fit ``st`` (:class:`Context`)."""
    return {
        "families": families,
        "enabled": tuple(name for name, _ in builders),
        "alpha": alpha,
        "residual_ptp": float(np.ptp(st["fit0"].resid)),
        "signal_template": st["template"].period if st["template"] is not None else None,
    }


def _null_model(setup: NullSetup, use, aux_all, builders, alpha: float, proxies_all):
    """The null fit on the samples left after spikes and outliers, with the bias jumps
    told by their edge taken out: ``(st, use, notes, families, jumps, proxies)``
    (``proxies``: the usable signal proxies, with an orbit template only)."""
    use, n_spikes = _spikes_out(setup.t_all, setup.y_all, setup.chan_all, use)
    proxy_notes: dict[tuple, dict[str, Any]] = {}
    setup.proxies = usable_proxies(proxies_all, use, proxy_notes)
    st = setup.build(use)
    st, use, notes = _leave_out_outliers(setup, st, use, aux_all, n_spikes)
    families = _families(builders, setup.orbit_period, st["template"] is not None)
    proxies = setup.proxies if st["template"] else None
    if proxies is not None:
        notes.update(proxy_notes)
    level = alpha / (2.0 * families)
    st, jumps = _take_out_jumps(setup, st, use, builders, level, notes, proxies)
    return st, use, notes, families, jumps, proxies


def _select(make, st, use, setup: NullSetup, max_effects: int, stop) -> tuple[Search, dict]:
    """The search on the null fit ``st`` and its ``(search, st)``.

    Paused at the first coupling whose channel's history is unknown at used samples:
    the search without those samples replaces it when it finds the coupling again
    (:func:`~accal.closure.unknownhistory.without_unknown_history`; the rest of this
    one would be wasted); else this one goes on with it, pausing again at the next
    such coupling, which is rejected unless found again without every coupling's
    made-up samples (at most :data:`~accal.closure.unknownhistory.UNKNOWN_DEPTH`
    times).  A coupling whose channel the data do not follow over a stretch
    (:mod:`accal.closure.channelfault`) is rejected when not found again without it,
    first or not: on a QA thruster day (2026-11-29) a z coupling to a 50 s low-pass of
    ``ang_accl_y`` whose coefficient reversed over 5.5 h was not significant on the
    other 77 % of the record, was kept unconfirmed, and moved the z bias 1.4σ.  So is a
    coupling to an angular acceleration not found again without the known thruster
    firings (:func:`~accal.closure.unknownhistory.fired`).
    """
    search = make(st, use)
    kept: set = set()  # couplings kept unconfirmed (the first search's first ones)

    def pause(s: Search) -> bool:
        return pause_at(s, frozenset(kept))

    run(search, max_effects, stop, until=pause)
    for _ in range(UNKNOWN_DEPTH):
        if not search.paused:
            break
        skip = frozenset(kept)
        again = without_unknown_history(search, use, setup, make, max_effects, stop, skip=skip)
        if again is not None:
            return again
        # not found without the made-up samples: the first coupling stays (unconfirmed),
        # a later one is rejected; the selection goes on, pausing at the next one.  A
        # coupling whose channel the data do not follow over a stretch is rejected even
        # when first: the stretch is its own misfit, not a history nobody could know
        if kept:
            reject_unconfirmed(search, skip)
        else:
            first = new_unknown(search, skip)
            fault = [
                f for f in first if faulted(search.options, f.prop.channel) or fired(search, f)
            ]
            if fault:
                reject_unconfirmed(search, skip | {f for f in first if f not in fault})
            kept.update(f for f in first if f not in fault)
        run(search, max_effects, stop, until=pause)
    if search.paused:
        run(search, max_effects, stop)
    swap_smooth(search)
    return search, st


def _final_fit(search: Search, setup: NullSetup, st) -> tuple[list[Found], Basis, Any]:
    """The final model's effects, its basis (the null model plus their columns) and fit."""
    final = _final_effects(search)
    basis = st["basis0"]
    if final:
        basis = basis.extend(np.column_stack([f.prop.columns[search.use] for f in final]))
    return final, basis, basis.fit(setup.y_all[search.use])


def _effects_sum(search: Search, setup: NullSetup, st, jumps) -> NDArray[np.float64]:
    """The effects found, fitted as in :func:`_finish`, summed on every sample (NaN as 0)."""
    final, _, fit = _final_fit(search, setup, st)
    cols = [f.prop.columns for f in final]
    out = np.nan_to_num(np.column_stack(cols)) @ fit.gamma if cols else np.zeros(search.t_all.size)
    if jumps:
        out = out + jump_columns(search.t_all, tuple(jumps)) @ np.array([j.size for j in jumps])
    return out


def _take_out_jumps(setup: NullSetup, st, use, builders, level: float, notes: dict, proxies):
    """Bias jumps told by their edge (:func:`~accal.closure.jumps.jumps_first`), taken
    out of ``setup.y_all`` (the rest of the search runs on that) with the null fit
    rebuilt: ``(st, scan)``."""
    given = None if proxies is None else (proxies.columns[use], proxies.names)
    scan = jumps_first(st, {name for name, _ in builders}, level, notes, given)
    if scan.jumps:
        sizes = np.array([j.size for j in scan.jumps])
        setup.y_all = setup.y_all_given - jump_columns(setup.t_all, scan.jumps) @ sizes
        st = setup.build(use)
    return st, scan


def _search_maker(
    setup: NullSetup, builders, alpha: float, opts, aux_all, ref_all, proxies, notes
) -> Callable[[dict[str, Any], NDArray[np.bool_]], Search]:
    """``make(st, use)``: a fresh :class:`Search` of the null fit ``st`` on the samples ``use``."""
    t_all, y_all, orbit_period = setup.t_all, setup.y_all, setup.orbit_period
    chan_all, names = setup.chan_all, setup.names

    def make(st: dict[str, Any], use: NDArray[np.bool_]) -> Search:
        search = Search(
            grid=st["grid"],
            t_all=t_all,
            use=use,
            t0=st["t0"],
            span=st["span"],
            y_u=y_all[use],
            basis0=st["basis0"],
            bias0=st["bias0"],
            signal0=st["signal0"],
            builders=builders,
            n_families=_families(builders, orbit_period, st["template"] is not None),
            alpha=alpha,
            options=opts,
            aux=aux_all,
            orbit_period=orbit_period,
            base_labels=frozenset(st["bbase"].column_labels()),
            chan_all=chan_all,
            names=names,
            reference=ref_all,
            beta=st["beta"],
            proxies=proxies,
        )
        search.notes.update(notes)
        for d in fault_notes(opts):  # channel faults a search before this one found
            search.note(d["name"], d["channel"], d["note"], d["details"])
        search.cache["template"] = st["template"]
        search.cache["null_basis"] = st["basis0"]
        return search

    return make


def _floor_stop(resolution: float | None) -> Callable[[Search], bool] | None:
    """The search's stop at the data's numerical resolution (None without one): a
    residual within :data:`RESOLUTION_FACTOR` of it is rounding (noted)."""
    if not resolution or resolution <= 0:
        return None
    floor = RESOLUTION_FACTOR * float(resolution)

    def at_floor(s: Search) -> bool:
        rms = float(np.sqrt(np.mean(s.state(s.found)[1].resid ** 2)))
        if rms > floor:
            return False
        s.note(
            "closure",
            None,
            f"residual RMS {rms:.2g} m/s² is at the data's numerical resolution "
            f"({float(resolution):.2g} m/s²): nothing left to test",
        )
        return True

    return at_floor


def _split(cols, chan_u, names):
    if not names:
        return cols
    return np.column_stack([cols * (chan_u == c)[:, None] for c in range(len(names))])


def _final_effects(search: Search) -> list[Found]:
    """The effects found as they enter the final fit (with their Jacobian columns); drop
    the least significant while one is no longer significant given the others' augmented
    columns (an effect that had only taken up a held time constant's misfit), and a
    bias step that is not significant given its own ramp's columns
    (:meth:`~accal.closure.search.Search.p_final`), also when it is the only effect."""
    final = [Found(f.model_prop, f.p_adj, f.verdict, f.stat) for f in search.found]
    while final:
        if len(final) == 1 and not final[0].prop.params.get("transition"):
            break  # a lone effect stays (the selection's), unless a step with its ramp
        ps = [search.p_final(i, final) for i in range(len(final))]
        worst = int(np.argmax(ps))
        if ps[worst] < search.alpha:
            break
        search.removed.append(search.found.pop(worst))
        final.pop(worst)
    return final


def _rejected_effect(f: Found, channel_units: dict[str, str]) -> Effect:
    v = f.verdict
    return Effect(
        f.prop.name,
        f.prop.channel,
        v.coefficient,
        float("nan"),
        f.p_adj,
        epoch=f.prop.params.get("epoch"),
        frequency=f.prop.params.get("frequency"),
        lag=f.prop.params.get("lag"),
        tau=f.prop.params.get("tau"),
        details={"reason": v.reason, **v.details()},
        instrument=kind_of(f.prop.name).instrument if f.prop.name in EFFECT_NAMES else False,
        unit=unit_of(f.prop, channel_units),
    )


def _finish(
    search: Search, setup: NullSetup, st, knots, noise_psd, floored, considered, opts, jumps=()
):
    """The final fit and the :class:`ClosureResult`.

    ``jumps`` (taken out of the data before the search,
    :func:`~accal.closure.jumps.jumps_first`) come first among the effects; the
    "before" values are the null fit of the data as given.
    """
    grid, use, t_all, y_all = search.grid, search.use, search.t_all, setup.y_all
    t_u, chan_u, names = st["t_u"], st["chan_u"], search.names
    bbase, basis0 = st["bbase"], st["basis0"]
    fit0 = basis0.fit(setup.y_all_given[use]) if jumps else st["fit0"]
    final, basis, fit = _final_fit(search, setup, st)
    ps = [search.p_final(i, final) for i in range(len(final))] if final else []
    lev = search.leverage(basis)
    cov = covariances(grid, basis, fit, lev, basis0, fit0, st["lev0"], noise_psd)
    if setup.proxy_exclude is not None and fit.k_kept:
        cov["v_ww"] = cov["v_ww"] + leak_cov(grid, st["template"], fit.w_gamma, search.y_u)
    jcols = jump_columns(t_all, tuple(jumps))
    add_jump_covariance(cov, basis, jcols[use], tuple(jumps))
    units = dict(opts.get("channel_units", {}))
    found = [
        (f.prop, p, {"p_accept": f.p_adj, **f.verdict.details()})
        for f, p in zip(final, ps, strict=True)
    ]
    if basis.n_blocks > 1 and any(f.prop.name == "bias_step" for f in final):
        placebo_step_sigmas(search.context(final, basis, fit, lev), final, found, cov, fit)
    # v_ww holds the jumps' sizes first (add_jump_covariance); the effects' block follows
    nj = len(jumps)
    effects = describe(found, fit.gamma, cov["v_ww"][nj:, nj:], st["span"], st["t0"], units)
    if setup.t_first is not None and setup.t_first < st["t0"]:
        # a search that left out the record's start fitted its exponentials from its own
        # first sample: their amplitudes are referred to the record's (QA: 4.9e-10 m/s²
        # reported for a 3e-9 decay 5400 s earlier)
        effects = refer_exponentials(effects, setup.t_first)
    add_lag_uncertainties(search, final, effects)
    widened_couplings(final, effects, cov, fit, nj)
    add_alias_spread(search, final, effects, cov, basis, nj)
    add_signal_model_spread(search, final, effects, cov, basis, fit, nj)
    add_signal_step_spread(search, cov, basis, fit)
    add_epoch_uncertainties(search, final, effects)
    unexplained = []
    if not floored:
        w, zt = unexplained_test(
            grid, basis, fit.resid, lev, t_u, knots, lambda c: _split(c, chan_u, names)
        )
        if w is not None and w.pvalue < search.alpha:
            unexplained.append(describe_smooth(grid, t_u, zt @ w.gamma, w))
    effects = jump_effects(tuple(jumps)) + list(effects)
    base_out = _base_coefficients(basis, bbase, fit0, fit, cov)
    k = fit.k_kept + len(jumps)
    nb, p = bbase.n_blocks, bbase.p
    seg_of = basis.seg_of_block()
    has = seg_of >= 0
    base_cov = np.full((nb, p, p), np.nan)
    cross = np.full((nb, p, k), np.nan)
    base_cov[has] = cov["cov_b"][seg_of[has]]
    cross[has] = cov["cov_bg"][seg_of[has]]
    eff_cols = np.column_stack([jcols] + [f.prop.columns for f in final])
    gamma = np.concatenate([[j.size for j in jumps], fit.gamma])
    res_before = setup.y_all_given - bbase.matvec(fit0.beta)
    res_after = y_all - bbase.matvec(fit.beta) - eff_cols[:, len(jumps) :] @ fit.gamma
    if st["template"] is not None:
        # the signal model is part of both fits and known on the used samples only
        res_before = np.full(t_all.size, np.nan)
        res_before[use] = fit0.resid
        res_after = np.full(t_all.size, np.nan)
        res_after[use] = fit.resid
    seg = search.orbit_period or None
    return ClosureResult(
        effects=tuple(effects),
        unexplained=tuple(unexplained),
        base=base_out,
        t0=st["t0"],
        rms_before=float(np.sqrt(np.mean(fit0.resid**2))),
        rms_after=float(np.sqrt(np.mean(fit.resid**2))),
        time=t_all,
        use=use,
        residual_before=res_before,
        residual_after=res_after,
        base_design=bbase,
        effect_columns=eff_cols,
        labels=bbase.column_labels()
        + tuple(f"step@{j.epoch!r}" for j in jumps)
        + tuple(lb for f in final for lb in f.prop.labels),
        coef=np.concatenate([fit.beta, gamma]),
        base_cov=base_cov,
        cross_cov=cross.reshape(nb * p, k),
        effects_cov=cov["v_ww"],
        n_base=bbase.n_columns,
        stats_before=characterise(t_u, fit0.resid, segment=seg, chan=chan_u),
        stats_after=characterise(t_u, fit.resid, segment=seg, chan=chan_u),
        iterations=search.iterations,
        notes=tuple(search.notes.values()),
        channel=search.chan_all,
        channel_names=names,
        eliminated=tuple(_rejected_effect(f, units) for f in search.removed),
        rejected=tuple(_rejected_effect(f, units) for f in search.rejected),
        considered=tuple(considered),
        signal_model=_signal_model(st["template"], search.proxies, setup.proxies_in_model),
    )


def _base_coefficients(basis, bbase, fit0, fit, cov) -> tuple[BaseCoefficient, ...]:
    """Before/after of every base coefficient with its σ (block by block)."""
    seg_of = basis.seg_of_block()
    nb, p = bbase.n_blocks, bbase.p
    has = seg_of >= 0
    sg = seg_of[has]
    var = {k: np.full((nb, p), np.nan) for k in ("0", "1", "d", "p")}
    var["0"][has] = np.einsum("sii->si", cov["v_ll0"][sg])
    var["1"][has] = np.einsum("sii->si", cov["cov_b"][sg])
    var["d"][has] = np.einsum("sii->si", cov["cov_d"][sg])
    var["p"][has] = np.einsum("sii->si", cov["v_ll"][sg])
    ident = np.isfinite(fit0.beta.reshape(nb, p))
    for arr in var.values():
        arr[~ident] = np.nan
    scale = bbase.column_scale()
    sd = {k: np.sqrt(np.maximum(v.ravel(), 0.0)) * scale for k, v in var.items()}
    b0, b1 = fit0.beta, fit.beta
    return tuple(
        BaseCoefficient(
            nm,
            float(b0[j] * scale[j]),
            float(sd["0"][j]),
            float(b1[j] * scale[j]),
            float(sd["1"][j]),
            float((b1[j] - b0[j]) * scale[j]),
            float(sd["d"][j]),
            float(sd["p"][j]),
        )
        for j, nm in enumerate(bbase.column_names())
    )
