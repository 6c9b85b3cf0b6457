"""``grace-bias --close-loop`` and ``accal diagnose``: the closure's side of the pipeline.

For each axis, :func:`close_the_loop` hands the residual of the declared trend to
:func:`accal.closure.close_loop` with everything the data offer as candidate
channels (the L1B file's own channels, a table's numeric columns, ``--aux``
housekeeping; never the target itself or a copy of it), removes the instrument
effects it accepts from the series to refit, and reports what it found, what it
rejected and why, and how much the closure moved each estimate (do no harm).

Imported by :mod:`accal.gracejob.fit` only when closure is asked for (the closure
modules pull in scipy's signal processing, ~0.4 s at start-up).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.batch import Manifest, failure_message, write_error_message
from accal.calibration import parse_scale
from accal.closure import DEFAULT_CANDIDATES, close_loop, effect_label, kind_of
from accal.closure.period import estimate_period
from accal.closure.report import plot_closure, to_markdown
from accal.crn import is_level1b, smooth_channel
from accal.errors import AccalError, ValidationError
from accal.gracejob.firings import closure_firings
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import FileOutcome, internal_error
from accal.gracejob.outputs import CALIBRATED_SUFFIXES, output_stem
from accal.gracejob.reading import read_input, subtract_reference
from accal.io.housekeeping import read_housekeeping
from accal.io.tables import read_table_series
from accal.io.units import si_factor
from accal.io.writers import atomic_path, read_table_metadata
from accal.series import AccSeries
from accal.timescale import gps_to_date

#: How the closure report describes an ``--aux`` channel of Level-1B data.
LOWPASSED = "low-passed like the Level-1B data (CRN-like, zero phase)"

#: Effects removed from the calibrated series (instrument effects).  Periodic
#: terms and unexplained structure are reported but kept: at orbit frequencies
#: they are as likely to be real non-gravitational signal as instrument error.
#: Longest hole inside an ``--aux`` channel that is bridged linearly [s].  A longer
#: one stays uncovered: a temperature interpolated over 1000–4000 s (most of an
#: orbit) had hidden a coupling and put false steps at the hole's edges.
AUX_MAX_BRIDGE = 600.0


def load_aux(
    path: Path, t: np.ndarray, satellite: str = ""
) -> tuple[dict[str, np.ndarray], list[str]]:
    """Housekeeping channels of ``path`` on ``t`` and what was left out (see
    :func:`load_aux_channels`, which also gives their units)."""
    channels, _, notes = load_aux_channels(path, t, satellite)
    return channels, notes


def load_aux_channels(
    path: Path, t: np.ndarray, satellite: str = ""
) -> tuple[dict[str, np.ndarray], dict[str, str], list[str]]:
    """Housekeeping channels of ``path`` interpolated onto ``t``, and what was left out.

    Holes inside a channel's span of up to :data:`AUX_MAX_BRIDGE` are bridged
    linearly; within one housekeeping step of its ends a channel holds its value;
    longer holes, and the time further before its first and after its last value,
    are NaN (not covered: the closure leaves those samples out).  Channels covering
    under 90 % of ``t``, or constant, are left out (named in the returned notes).
    A file that covers none of the data (another day's housekeeping) is an error;
    one that covers part of it but no channel 90 % gives a note and no channel.
    Housekeeping of another satellite than ``satellite`` (the data's) is used, with
    a note (QA: GRACE-A temperatures were applied to GRACE-B data without a word).
    """
    hk = read_housekeeping(path)
    notes = []
    if hk.satellite and satellite and hk.satellite != satellite:
        notes.append(
            f"--aux {path.name} is housekeeping of {hk.satellite}, the data are {satellite}: "
            "its channels are tested all the same"
        )
    out = {}
    coverage = 0.0
    constant, short = [], []
    step = float(np.median(np.diff(hk.time))) if hk.time.size > 1 else 0.0
    for k, v in hk.on(t).items():
        v = np.asarray(v, dtype=np.float64)
        ok = np.isfinite(v)
        if ok.any():
            _bridge_short_holes(t, v, ok)
            _hold_ends(t, v, np.isfinite(v), step)
            ok = np.isfinite(v)
        coverage = max(coverage, float(ok.mean()))
        # a channel must cover the day and vary to be a candidate regressor
        if ok.mean() < 0.9:
            short.append(f"{k} ({ok.mean():.0%})")
            continue
        if np.ptp(v[ok]) == 0:
            constant.append(k)
            continue
        out[k] = v
    if coverage == 0.0:
        raise ValidationError(
            f"{path}: --aux covers none of the data "
            f"({gps_to_date(float(t[0]))} ... {gps_to_date(float(t[-1]))}, GPS days); "
            "give the housekeeping of the same day(s)"
        )
    if not out and short:
        notes.append(
            f"--aux covers at most {coverage:.0%} of the data (holes over "
            f"{AUX_MAX_BRIDGE:g} s are not bridged): no coupling is tested"
        )
        short = []
    if constant:
        notes.append(f"--aux channel(s) constant over the data, not tested: {', '.join(constant)}")
    if short:
        notes.append(f"--aux channel(s) covering under 90 %, not tested: {', '.join(short)}")
    units = dict(getattr(hk, "units", {}) or {})
    return out, {k: str(units.get(k, "") or "") for k in out}, notes


def _hold_ends(t: np.ndarray, v: np.ndarray, ok: np.ndarray, step: float) -> None:
    """Hold, in place, a channel's first and last values over the samples less than one
    housekeeping ``step`` before its first (after its last) value.

    QA (2026-11-30): the real GRACE-FO AHK1B starts 0.091 s after the ACT1B's first
    record; that one sample was "outside --aux" and every such day warned that no
    coupling was removed (also on days where one was).
    """
    idx = np.flatnonzero(ok)
    if idx.size == 0 or not step > 0:
        return
    a, b = idx[0], idx[-1]
    head = t[:a] >= t[a] - step
    v[:a][head] = v[a]
    tail = t[b + 1 :] <= t[b] + step
    v[b + 1 :][tail] = v[b]


def _bridge_short_holes(t: np.ndarray, v: np.ndarray, ok: np.ndarray) -> None:
    """Fill, in place, the NaN runs of ``v`` inside its span that last <= AUX_MAX_BRIDGE."""
    idx = np.flatnonzero(ok)
    for g in np.flatnonzero(np.diff(idx) > 1):  # holes: not-ok runs between ok samples
        a, b = idx[g], idx[g + 1]  # the ok samples around the hole
        if t[b] - t[a] <= AUX_MAX_BRIDGE:
            v[a + 1 : b] = np.interp(t[a + 1 : b], (t[a], t[b]), (v[a], v[b]))


def load_truth(path: Path, series: AccSeries, reference: bool) -> dict[str, dict[str, float]]:
    """Per-axis true bias and drift of the fitted series from a simulation truth file.

    The trend a perfect estimator returns is the instrument's (``bias``,
    ``drift``) plus, without a reference, the trend of the true signal.
    """
    try:
        truth = json.loads(Path(path).read_text())
        sat = str(truth.get("satellite", ""))
        if sat and series.satellite and series.satellite[-1:] != sat[-1:]:
            raise ValidationError(
                f"{path}: truth of satellite {sat}, the data are {series.satellite}"
            )
        t0 = float(truth["t0"])
        if len(series) and not series.time[0] - 86400 <= t0 <= series.time[-1]:
            raise ValidationError(
                f"{path}: truth of {truth.get('date', t0)} does not describe data starting "
                f"at {series.time[0]:.9g} s"
            )
        out = {}
        for i, ax in enumerate("xyz"):
            if ax not in series.axes:
                continue
            b = float(truth["bias"][i])
            d = float(truth["drift"][i])
            if not reference and "signal_trend" in truth:
                b += float(truth["signal_trend"]["bias"][i])
                d += float(truth["signal_trend"]["drift"][i])
            # the truth refers to its own t0; move the bias to the series' first used sample
            out[ax] = {"bias": b, "drift": d, "t0": float(truth["t0"])}
        return out
    except ValidationError:
        raise
    except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:
        raise ValidationError(f"{path}: not a readable truth file ({exc})") from None


def closure_candidates(
    opts: GraceBiasOptions, span: float | None = None
) -> tuple[tuple[str, ...], str]:
    """Candidate kinds for a ``grace-bias`` closure, and a note on what is left out.

    Without ``--reference`` the fitted series is the raw acceleration, whose
    non-gravitational signal varies slowly over the day: kinds that need a
    reference (:attr:`accal.closure.kinds.Kind.needs_reference`: polynomial and
    exponential drifts, the scale) are not tested.  On a record shorter than two
    revolutions (``span`` below twice ``orbit_period``) there is no orbit-signal
    model, and a step cannot be told from the signal's own jumps (radiation
    pressure switching at eclipse entry and exit): steps are left out too.
    """
    if opts.reference is not None:
        return tuple(DEFAULT_CANDIDATES), ""
    drop = {c for c in DEFAULT_CANDIDATES if kind_of(c).needs_reference}
    note = (
        f"no --reference: {', '.join(sorted(drop))} not tested (not separable from the slow "
        "variation of the non-gravitational signal); the orbit-periodic and slow signal is "
        "part of the null model, and periodic and unexplained structure include real signal"
    )
    if span is not None and opts.orbit_period and span < 2 * opts.orbit_period:
        drop.add("bias_step")
        note += (
            f"; record shorter than two revolutions ({span:.0f} s): bias steps not tested "
            "either (eclipse transitions of the radiation pressure look like steps)"
        )
    return tuple(c for c in DEFAULT_CANDIDATES if c not in drop), note


#: Integer channels with at most this many distinct values are flags or counters.
FLAG_LEVELS = 8


def _axis_stem(name: str) -> str | None:
    """``"a_cal_"`` for ``"a_cal_x"`` (a name ending in an axis letter after ``_``), else None."""
    if len(name) > 2 and name[-1].lower() in "xyz" and name[-2] == "_":
        return name[:-1].lower()
    return None


def candidate_channels(
    series: AccSeries, opts: GraceBiasOptions
) -> tuple[dict[str, np.ndarray], dict[str, str], list[dict[str, Any]], list[str]]:
    """Every channel of the data a coupling may be tested to, with units and verdicts.

    All numeric channels of the input besides its axes (an L1B file's angular
    accelerations, a table's other columns) and the ``--aux`` housekeeping.  Left
    out, with the reason, are channels of the target's own quantity (an
    acceleration: the L1B fit residuals, other columns of a table such as
    ``a_cal``/``a_raw``; derived from the target or the reference) and flags or
    counters (integer, at most :data:`FLAG_LEVELS` distinct values).  The closure
    then screens what is left (:func:`accal.closure.inputs.screen_channels`).

    Returns ``(channels, units, report, warnings)``.
    """
    aux: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    report: list[dict[str, Any]] = []
    # stems of the axis-like names (a_cal_x, a_cal_y -> "a_cal_") that occur for more
    # than one axis letter: without units, those columns are one vector quantity
    letters: dict[str, set[str]] = {}
    for name in series.aux:
        if _axis_stem(name) is not None:
            letters.setdefault(_axis_stem(name), set()).add(name[-1].lower())
    stems = {k for k, v in letters.items() if len(v) > 1}
    for name, v in series.aux.items():
        unit = str(series.units.get(name, "") or "")
        x = np.asarray(v)
        declared = unit.strip().lower() not in ("", "unknown")
        if declared and si_factor(unit, "acceleration") is not None:
            why = f"an acceleration ({unit}): the target's own quantity, derived from it"
        elif not declared and _axis_stem(name) in stems:
            why = "no unit, named like another axis of the same quantity (the target's own)"
        elif np.unique(x[np.isfinite(x)]).size <= 1:
            why = "constant"
        elif np.issubdtype(x.dtype, np.integer) or np.all(np.mod(x[np.isfinite(x)], 1) == 0):
            levels = np.unique(x[np.isfinite(x)]).size
            why = (
                f"a flag or counter ({levels} distinct integer values)"
                if levels <= FLAG_LEVELS
                else ""
            )
        else:
            why = ""
        cover = float(np.mean(np.isfinite(np.asarray(v, dtype=np.float64))))
        if not why and cover < 0.9:
            why = f"covers {cover:.0%} of the record"
        if why:
            report.append({"channel": name, "status": "left out", "reason": why})
            continue
        aux[name] = np.asarray(v, dtype=np.float64)
        units[name] = unit
    warnings: list[str] = []
    if opts.aux is not None:
        channels, hk_units, warnings = load_aux_channels(opts.aux, series.time, series.satellite)
        # Level-1B accelerations went through the processing's CRN filter, housekeeping
        # did not: an effect of a temperature is seen through the filter (accal.crn)
        crn = is_level1b(series.meta)
        for k, v in channels.items():
            aux[k] = smooth_channel(series.time, v) if crn else v
            units[k] = hk_units.get(k, "")
            if crn:
                report.append({"channel": k, "status": "considered", "reason": LOWPASSED})
    return aux, units, report, warnings


def close_the_loop(
    path: Path,
    series: AccSeries,
    fit_series: AccSeries,
    use: np.ndarray,
    opts: GraceBiasOptions,
    prefix: Path,
) -> tuple[AccSeries, dict[str, Any], list[Path], list[str]]:
    """Close the loop on every axis and return the series to refit.

    For each axis, :func:`accal.closure.close_loop` analyses the residual of the
    declared ``poly<order>`` trend with every channel of the data as a candidate
    (:func:`candidate_channels`), with the reference (``--reference``: the ``scale``
    candidate) or else with the orbit-periodic and slow signal in the null model
    (the orbit period is estimated once, on all axes).  The instrument effects it
    accepts (:attr:`accal.closure.Effect.instrument`) are subtracted from the fitted
    series, so the estimators then fit bias and drift with the extended model.  With
    ``opts.plots``, writes ``<prefix>.closure.<axis>.png``,
    ``<prefix>.closure-psd.<axis>.png`` and ``<prefix>.closure-effects.<axis>.png``.

    Returns
    -------
    fit_series : AccSeries
        The series minus the instrument effects (to refit).
    closure : dict
        ``{axis: {"summary": closure.json entry, "instrument": model array,
        "model": model label}}``.
    outputs : list of Path
        Plots written.
    warnings : list of str
        What the user should know (e.g. ``--aux`` not covering every used sample:
        the closure then uses the samples it covers).
    """
    aux, units, left_out, warnings = candidate_channels(series, opts)
    # a coupling is only known where its channel is: the closure uses those samples
    covered = np.ones(len(series), bool)
    for v in aux.values():
        covered &= np.isfinite(v)
    n_out = int(np.count_nonzero(use & ~covered))
    use_cl = use & covered
    t_used = fit_series.time[use_cl]
    span = float(t_used[-1] - t_used[0]) if t_used.size else 0.0
    candidates, note = closure_candidates(opts, span)
    firings, firing_note = closure_firings(path, series, opts)
    settings: dict[str, Any] = {
        "orbit_period_fixed": True,
        # a step in CRN-filtered data is a ramp (accal.closure.transition)
        "step_transition": is_level1b(series.meta),
    }
    if firings is not None:
        settings["firings"] = firings
    elif firing_note:
        settings["firings_unknown"] = True
    reference = opts.reference is not None
    period = opts.orbit_period
    if not reference and period and t_used.size > 2 and span >= 2 * period:
        res = np.column_stack(
            [_detrended(t_used, fit_series.axis(ax)[use_cl]) for ax in series.axes]
        )
        period = estimate_period(t_used, res, float(period))
    out: dict[str, Any] = {}
    plots: list[Path] = []
    cols = []
    for ax in series.axes:
        y = fit_series.axis(ax)
        res = close_loop(
            fit_series.time,
            y,
            valid=use_cl,
            base=f"poly{opts.order}",
            aux=aux or None,
            alpha=opts.alpha,
            orbit_period=period,
            candidates=candidates,
            resolution=_resolution(series, fit_series, ax),
            reference=series.axis(ax) - y if reference else None,
            channel_units=units,
            screened=left_out,
            options=settings,
            signal_proxies=None
            if reference
            else {o: fit_series.axis(o) for o in series.axes if o != ax},
        )
        inst = np.zeros(len(series))
        labels = [f"poly{opts.order}"]
        for e, m in res.effect_models():
            if e.instrument:
                inst += np.where(covered, m, 0.0)
                labels.append(effect_label(e))
        summary = res.to_dict()
        summary["model"] = "+".join(labels)
        summary["candidates"] = list(candidates)
        if note:
            summary["note"] = note
        if firing_note:
            summary["thrusters"] = firing_note
        summary["removed_from_calibrated"] = labels[1:]
        summary["markdown"] = to_markdown(res, title=f"{path.name} axis {ax}")
        if firing_note:
            summary["markdown"] = (
                summary["markdown"].rstrip("\n") + f"\n\nThrusters: {firing_note}.\n"
            )
        out[ax] = {"summary": summary, "instrument": inst, "model": "+".join(labels)}
        cols.append(y - inst)
        if opts.plots:
            plots += _plot_closure(res, prefix, ax, title=f"{path.name}, axis {ax}")
    fit_series = fit_series.replace(acc=np.column_stack(cols)).with_history(
        f"accal {__version__}: close_loop(alpha={opts.alpha}) removed "
        + "; ".join(f"{ax}: {out[ax]['model']}" for ax in series.axes)
    )
    coupled = [ax for ax in series.axes if "auxiliary(" in out[ax]["model"]]
    covered_note = (
        f"{'--aux' if opts.aux is not None else 'the closure channels'} covers "
        f"{1 - n_out / max(int(use.sum()), 1):.1%} of the used samples: the closure analyses "
        "those only"
    )
    if coupled and n_out:
        # a removed coupling is not removed where its channel is missing: those samples
        # leave the refit of the coupled axes only; the calibrated file's valid column,
        # shared by the axes, marks them invalid
        for ax in coupled:
            out[ax]["exclude"] = ~covered
        warnings.append(
            f"{covered_note}; a coupling was removed on axis {', '.join(coupled)}, which "
            f"cannot be removed at the {n_out} samples outside it: they are left out of "
            f"the refit of axis {', '.join(coupled)} (the other axes keep them) and marked "
            "invalid in the calibrated file (its valid column is shared by the axes)"
        )
    elif n_out:
        warnings.append(
            f"{covered_note} (the {n_out} samples outside it keep the plain fit's treatment: "
            "no coupling was removed)"
        )
    return fit_series, out, plots, warnings


def _detrended(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``y`` minus its least-squares line (for the orbit-period estimate)."""
    a = np.column_stack([np.ones_like(t), t - t[0]])
    return y - a @ np.linalg.lstsq(a, y, rcond=None)[0]


def write_closure_plots(res: Any, prefix: Path, ax: str, title: str | None = None) -> list[Path]:
    """Write ``<prefix>.closure{,-psd,-effects}.<ax>.png`` of a closure result (none
    without matplotlib; ``title``: the input and axis, on every figure); returns the
    paths written."""
    return _plot_closure(res, prefix, ax, title)


def _plot_closure(res: Any, prefix: Path, ax: str, title: str | None = None) -> list[Path]:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return []

    names = [
        prefix.with_name(f"{prefix.name}.closure{k}.{ax}.png") for k in ("", "-psd", "-effects")
    ]
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(atomic_path(p, sync=False)) for p in names]
        pngs = [t.with_name(t.name + ".png") for t in tmps]  # matplotlib wants the suffix
        plot_closure(res, *pngs, title=title)
        for png, t in zip(pngs, tmps, strict=True):
            png.replace(t)
    return names


def change_entry(before: float, sigma_before: float, after: float, sigma_after: float) -> dict:
    """One quantity before and after closing the loop, with ``change_sigmas``:
    ``|after − before| / σ_after`` (infinite for σ_after = 0)."""
    return {
        "before": before,
        "sigma_before": sigma_before,
        "after": after,
        "sigma_after": sigma_after,
        "change_sigmas": abs(after - before) / sigma_after if sigma_after > 0 else float("inf"),
    }


def before_after(
    before: dict[tuple[str, str], Any],
    after: dict[tuple[str, str], Any],
    ax: str,
    truth: dict[str, float] | None,
) -> dict[str, Any]:
    """Bias and drift of each method before/after closing the loop (and their true errors).

    ``change_sigmas`` is ``|after − before| / σ_after``: how many of the final
    uncertainties the extended model moved the estimate.
    """
    out: dict[str, Any] = {}
    for (a, m), fb in before.items():
        if a != ax:
            continue
        fa = after[(a, m)]
        entry: dict[str, Any] = {}
        for k, name in enumerate(("bias", "drift")):
            b, s_b = float(fb.coef[k]), float(fb.sigma[k])
            v, s_v = float(fa.coef[k]), float(fa.sigma[k])
            e = change_entry(b, s_b, v, s_v)
            if truth is not None:
                tb = truth["bias"] + truth["drift"] * (fb.t0 - truth["t0"])
                tv = tb if name == "bias" else truth["drift"]
                e["true_error_before"] = b - tv
                e["true_error_after"] = v - tv
            entry[name] = e
        out[m] = entry
    return out


def with_effect_uncertainty(
    fits: dict[tuple[str, str], Any], closure: dict[str, Any]
) -> dict[tuple[str, str], Any]:
    """The refitted trends with the uncertainty of the removed effects added.

    The refit subtracts the effects the closure estimated as if they were known,
    so its σ leaves out their uncertainty (QA: a quadratic drift found on raw −
    reference left a drift σ of 9.0e-17 m/s³ in the table for a true error of
    6.2e-16).  The closure measures what estimating them adds to each base
    coefficient's variance under the final noise (``sigma_after² −
    sigma_plain²``); that is added to the refit's variance of the same
    coefficient, for every method.
    """
    out = dict(fits)
    for (ax, m), fit in fits.items():
        entry = closure.get(ax)
        if not entry or not entry["summary"].get("removed_from_calibrated"):
            continue  # nothing subtracted before the refit
        base = entry["summary"].get("base") or []
        cov = np.array(fit.cov, dtype=np.float64, copy=True)
        for k in range(min(cov.shape[0], len(base))):
            after, plain = base[k].get("sigma_after"), base[k].get("sigma_plain")
            if after is None or plain is None or not np.isfinite(after * plain):
                continue
            cov[k, k] += max(0.0, after**2 - plain**2)
        out[(ax, m)] = dataclasses.replace(fit, cov=cov)
    return out


def with_effects_removed(series: AccSeries, closure: dict[str, Any]) -> AccSeries:
    cols = [series.axis(ax) - closure[ax]["instrument"] for ax in series.axes]
    removed = "; ".join(
        f"{ax}: {', '.join(closure[ax]['summary'].get('removed_from_calibrated') or []) or 'nothing'}"
        for ax in series.axes
        if ax in closure
    )
    return series.replace(acc=np.column_stack(cols)).with_history(
        f"accal {__version__}: instrument effects found by close_loop removed ({removed})"
    )


def _resolution(series: AccSeries, fit_series: AccSeries, ax: str) -> float:
    """Numerical resolution of the closure's data on axis ``ax`` [m/s²].

    float64 epsilon times the largest magnitude of the raw axis (and of raw −
    reference): a text file's 16-17 significant digits resolve no better.
    """
    big = 0.0
    for s in (series, fit_series):
        a = np.abs(s.axis(ax))
        a = a[np.isfinite(a)]
        if a.size:
            big = max(big, float(a.max()))
    return float(np.finfo(np.float64).eps * big)


def _as_diagnosis(summary: dict[str, Any]) -> dict[str, Any]:
    """A closure entry of ``accal diagnose``: nothing was removed, ``would_remove`` says what."""
    out = dict(summary)
    out["would_remove"] = out.pop("removed_from_calibrated", [])
    return out


def _diagnosis_input(
    series: AccSeries, run: dict[str, Any]
) -> tuple[AccSeries, Path | None, list[str]]:
    """The series ``accal diagnose`` analyses: calibrated / scale (− reference).

    The calibrated series is ``scale · (raw − trend)``: divided by the run's scale
    it is the residual ``--close-loop`` analyses, so both report effects in the
    raw data's units (QA: after ``--scale tn02`` diagnose gave a 3e-9 m/s² step as
    2.84e-9, the z scale 0.9485 times it, 4.5σ off).  A run with ``--reference``
    fitted ``raw − reference``, so its residual is ``calibrated / scale −
    reference`` (the reference named in the manifest, read again).  Returns the
    series, the reference path (None without one) and warnings.
    """
    scale = parse_scale(run.get("scale"), series.satellite)
    raw = series
    if scale is not None:
        s = np.asarray(scale, dtype=np.float64)[: len(series.axes)]
        raw = series.replace(acc=series.acc / s[None, :])
    ref = run.get("reference")
    path = ref.get("path") if isinstance(ref, dict) else ref
    if not path:
        return raw, None, []
    ref_path = Path(str(path))
    if not ref_path.is_file():
        return (
            raw,
            None,
            [
                f"the run used --reference {ref_path}, which is gone: analysed without it "
                "(polynomial drifts not tested)"
            ],
        )
    ref_series = read_input(ref_path, GraceBiasOptions(columns=run.get("columns") or {}))
    out = subtract_reference(raw, ref_series, ref_path)
    return out, ref_path, list(out.report.warnings[len(raw.report.warnings) :])


def diagnose_dir(
    directory: Path,
    out_dir: Path,
    *,
    aux: Path | None = None,
    alpha: float = 0.01,
    plots: bool = False,
    progress: Callable[..., Iterable[Any]] | None = None,
) -> list[FileOutcome]:
    """Close the loop on every ``*.calibrated.<fmt>`` of an earlier ``grace-bias`` run.

    The calibrated series is ``scale · (raw − trend)``: its used samples are the
    residual of the declared model (times the scale), so the closure runs on it
    with the same polynomial base (order from the file's metadata).  Plots go to
    ``out_dir``; the caller writes ``closure.json``/``closure.md``
    (:func:`accal.closure_reports.write_closure_reports`).
    """
    directory, out_dir = Path(directory), Path(out_dir)
    files = sorted(p for p in directory.iterdir() if p.name.endswith(CALIBRATED_SUFFIXES))
    if not files:  # not a grace-bias directory: nothing created in it (QA)
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    runs = {  # the options each calibrated file was made with (grace-bias's manifest)
        out: e.get("options") or {}
        for e in Manifest.load(directory).entries.values()
        for out in e.get("outputs", ())
    }
    outcomes = []
    for p in progress(files, total=len(files)) if progress else files:
        try:
            _, meta = read_table_metadata(p)
            series = read_table_series(p)
            order = int(meta.get("order", 1))
            name = str(meta.get("source") or p.name.split(".calibrated.")[0])
            fit_series, ref_path, extra = _diagnosis_input(series, runs.get(p.name) or {})
            opts = GraceBiasOptions(
                order=order,
                close_loop=True,
                aux=aux,
                alpha=alpha,
                reference=ref_path,
                plots=plots,
            )
            _, closure, plots, notes = close_the_loop(
                Path(name),
                series,
                fit_series,
                fit_series.valid,
                opts,
                out_dir / output_stem(Path(name)),
            )
            notes = [*extra, *notes]
            outcomes.append(
                FileOutcome(
                    Path(name),
                    True,
                    n_samples=len(series),
                    outputs=tuple(plots),
                    closure={ax: _as_diagnosis(c["summary"]) for ax, c in closure.items()},
                    warnings=tuple(notes),
                )
            )
        except AccalError as exc:
            outcomes.append(FileOutcome(p, False, failure_message(p, exc)))
        except OSError as exc:  # writing the plots (read-only or full output directory)
            outcomes.append(FileOutcome(p, False, write_error_message(p, exc)))
        except Exception as exc:
            outcomes.append(internal_error(p, exc))
    return outcomes
