"""``grace-bias --reference REF --bias-basis ... | --scale fit ... --close-loop``.

Issue 22: the closure runs on the calibrated residual of the reference fit, in
the raw data's units, with the fit's scales held at their estimates (eq. 1 of
:mod:`accal.estimators.reference` solved for the raw acceleration)::

    a_raw = S⁻¹ a_ref + b(t) + n,   y_i = a_raw,i − (S⁻¹ a_ref)_i = Σ_k b_ik φ_k(t) + ...

so the declared base of :func:`accal.closure.close_loop` is the bias basis
``φ_k(t)`` alone (a :class:`~accal.closure.blockbase.BlockBase`), and every candidate
(steps, couplings to the data's channels, polynomial and exponential drifts,
and the scale where the fit held it fixed) is tested, validated and estimated
against it, with the closure's own machinery deciding what is an instrument
effect.  The reference is not a free regressor of the closure (a noisy one would
be attenuated: :func:`null_design`).  The effects it accepts are subtracted from
the raw data and the reference fit is made again
(:func:`accal.pipeline_reference.fit_day`); the covariance of the refit gets
what estimating the effects adds (as :func:`accal.pipeline_closure.with_effect_uncertainty`
does for the wavelet/lsq fits).

An arc of several days (``--arc 30d``, ``month``) is one fit: each day's closure
runs on that day's share of it, and the arc is fitted again without the effects
found (:func:`close_arc_loop`).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.closure import close_loop, effect_label
from accal.closure.blockbase import BlockBase
from accal.closure.report import to_markdown
from accal.closure.select import MIN_SAMPLES
from accal.gracejob.options import GraceBiasOptions
from accal.pipeline_closure import (
    candidate_channels,
    change_entry,
    closure_candidates,
    load_truth,
    write_closure_plots,
)
from accal.pipeline_reference import fit_arc, row_fields
from accal.series import AccSeries

__all__ = ["ReferenceClosure", "close_arc_loop", "close_reference_loop", "null_design"]

AXES = "xyz"


@dataclass(frozen=True)
class ReferenceClosure:
    """What the closure of one day's reference fit found and did.

    Attributes
    ----------
    summaries : dict
        ``{axis: closure.json entry}`` (:meth:`accal.closure.ClosureResult.to_dict`
        plus ``model``, ``removed_from_calibrated``, ``estimates``, ``markdown``).
    models : dict
        ``{axis: model label}`` for the ``bias_drift`` table's ``model`` column, e.g.
        ``poly1+bias_step@2005-01-01T09:36:00GPS``.
    outputs : tuple of Path
        Plots written (``--plots``).
    """

    summaries: dict[str, dict[str, Any]]
    models: dict[str, str]
    outputs: tuple[Path, ...] = ()


def null_design(
    fit: Any, axis: int, time: np.ndarray, raw: np.ndarray, reference: np.ndarray
) -> tuple[np.ndarray, Any, np.ndarray]:
    """The data and base of the closure of one axis of a reference fit (eq. 1).

    The closure runs on the calibrated residual in raw units, with the reference
    fit's scales held at their estimates::

        y_i = a_raw,i − (S⁻¹ a_ref)_i = Σ_k b_ik φ_k(t) + n_i − (S⁻¹ e)_i       (3)

    so its null model is the bias basis alone, and the reference enters only through
    the fitted model subtracted from the data.  Not as free regressors: a reference
    noisy at high frequency (a POD-derived one: 5.6e-8 m/s² RMS at 1 Hz for ~2e-8 of
    cross-track signal) regressed on by least squares is attenuated towards −1 (its
    noise is in the regressor and, with the opposite sign, in ``y``: errors in
    variables, Fuller, *Measurement Error Models*, 1987, §1.1), which left ~90 % of
    the signal in the closure's residual (issue 22, QA).  The fit's own scales are
    estimated with the reference as the observation and are not attenuated
    (:mod:`accal.estimators.reference`).

    Parameters
    ----------
    fit : ReferenceFit
        The day's fit (:func:`accal.estimators.reference.fit_reference`).
    axis : int
        0, 1, 2 for x, y, z.
    time : ndarray, shape (n,)
        GPS seconds.
    raw, reference : ndarray, shape (n, 3)
        Raw accelerometer data and the reference in the SRF [m/s²].

    Returns
    -------
    y : ndarray, shape (n,)
        ``a_raw,i − (S⁻¹ a_ref)_i`` (eq. 3) [m/s²].
    base : BlockBase
        The bias basis columns (``bias[k]``, labelled with the powers of ``t`` they
        span: a Legendre ``polyN`` spans ``t^0..t^N``, a clamped cubic B-spline every
        cubic, de Boor 2001, ch. IX); no signal part.
    signal : ndarray, shape (n,)
        ``a_raw,i − b_i(t)``: the signal in raw units with the accelerometer's noise,
        not the reference's (the closure's ``reference``: regressor of the ``scale``
        candidate, offered on axes whose scale the fit held fixed, and screen of the
        coupling channels).  Its coefficient is ``1 − s/s₀`` for a raw gain ``1/s``
        and a fixed scale ``s₀`` (``s₀/s − 1`` to first order).
    """
    ref = np.nan_to_num(np.asarray(reference, dtype=np.float64))
    phi, first = fit.basis.design(time)
    keep = ~fit.unsupported[first : first + phi.shape[1]] if fit.unsupported.size else None
    k_idx = np.arange(first, first + phi.shape[1])
    if keep is not None:
        phi, k_idx = phi[:, keep], k_idx[keep]
    if fit.basis.kind == "poly":
        labels = [f"t^{k}" for k in k_idx]
    else:  # the clamped cubic spline reproduces every cubic over the arc
        labels = [f"t^{j}" if j < 4 else f"bspline[{k}]" for j, k in enumerate(k_idx)]
    names = [f"bias[{k}]" for k in k_idx]
    expected = ref @ np.linalg.inv(fit.scale).T  # S⁻¹ a_ref of every axis
    y = raw[:, axis] - expected[:, axis]
    bias, _ = fit.bias(time)
    signal = raw[:, axis] - np.nan_to_num(bias[:, axis])
    base = BlockBase(
        np.zeros(phi.shape[0], dtype=np.int64),
        np.ascontiguousarray(phi),
        tuple(names),
        tuple(labels),
        np.ones(phi.shape[1]),
    )
    return y, base, signal


def _resolution(raw: np.ndarray, y: np.ndarray) -> float:
    """float64 epsilon times the largest magnitude of the raw axis and of ``y`` [m/s²]
    (as :mod:`accal.pipeline_closure`: a text file resolves no better)."""
    big = max((float(np.nanmax(np.abs(a))) for a in (raw, y) if np.isfinite(a).any()), default=0)
    return float(np.finfo(np.float64).eps * big)


def _row_estimates(day: Any, axis: str, time: np.ndarray, scale_given: str | None) -> dict:
    """Bias and drift at the first used sample and the diagonal scale, with their σ."""
    r = row_fields(day, axis, time, scale_given or "")
    return {
        "t0": r["t0"],
        "bias": (r["bias"], r["bias_sigma"]),
        "drift": (r["drift"], r["drift_sigma"]),
        "scale": (r["scale"], r[f"scale_{axis}_sigma"]),
    }


def _truth_scale(path: Path) -> np.ndarray | None:
    """``S`` of a simulation's truth (``truth["reference"]["scale"]``, 3×3), or None."""
    try:
        s = np.asarray(json.loads(Path(path).read_text())["reference"]["scale"], dtype=float)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return s if s.shape == (3, 3) else None


def before_after(
    before: Any, after: Any, axis: str, time: np.ndarray, opts: GraceBiasOptions, truth: Any
) -> dict[str, Any]:
    """``estimates`` of a closure.json entry: the reference fit's bias, drift and scale
    before and after closing the loop, ``change_sigmas = |after − before| / σ_after``
    (as :func:`accal.pipeline_closure.before_after`), and with ``truth`` the true errors
    of bias and drift (the truth's bias moved to the fit's ``t0`` with its drift) and,
    when the truth has the reference's ``S`` (``accal simulate grace --reference-out``),
    of the scale; a truth without it leaves the scale out (every row of the report's
    table then has its true errors)."""
    b = _row_estimates(before, axis, time, opts.scale)
    a = _row_estimates(after, axis, time, opts.scale)
    true_s = _truth_scale(opts.truth) if truth is not None and opts.truth else None
    out: dict[str, Any] = {}
    for q in ("bias", "drift", "scale"):
        if q == "scale" and truth is not None and true_s is None:
            continue
        (vb, sb), (va, sa) = b[q], a[q]
        e = change_entry(vb, sb, va, sa)
        if truth is not None and q == "scale":
            i = AXES.index(axis)
            e["true_error_before"] = vb - float(true_s[i, i])
            e["true_error_after"] = va - float(true_s[i, i])
        elif truth is not None:
            true_b = truth["bias"] + truth["drift"] * (b["t0"] - truth["t0"])
            e["true_error_before"] = vb - (true_b if q == "bias" else truth["drift"])
            true_a = truth["bias"] + truth["drift"] * (a["t0"] - truth["t0"])
            e["true_error_after"] = va - (true_a if q == "bias" else truth["drift"])
        out[q] = e
    return {"reference": out}


def with_effect_uncertainty(fit: Any, summaries: dict[str, dict[str, Any]]) -> Any:
    """The refitted :class:`ReferenceFit` with the uncertainty of the removed effects.

    The refit subtracts the effects as if known; the closure gives, per base
    coefficient, what estimating them adds to its variance (``sigma_after² −
    sigma_plain²``, :class:`accal.closure.BaseCoefficient`).  That is added to the
    diagonal of the refit's covariance for ``bias[k]`` to ``bias_coef[i, k]`` (same
    quantity; the closure's base is the bias basis alone, eq. 3).
    """
    k = fit.basis.size
    bias_cov = np.array(fit.bias_cov, dtype=np.float64, copy=True)
    cov = np.array(fit.cov, dtype=np.float64, copy=True)
    for ax, entry in summaries.items():
        if not entry.get("removed_from_calibrated"):
            continue
        i = AXES.index(ax)
        for b in entry.get("base") or []:
            after, plain = b.get("sigma_after"), b.get("sigma_plain")
            name = str(b.get("name", ""))
            if after is None or plain is None or not np.isfinite(after * plain):
                continue
            if name.startswith("bias["):
                idx = i * k + int(name[5:-1])
                dv = max(0.0, after**2 - plain**2)
                bias_cov[idx, idx] += dv
                if cov.size:
                    cov[9 + idx, 9 + idx] += dv
    return dataclasses.replace(fit, bias_cov=bias_cov, cov=cov)


def _close_axes(
    path: Path, series: AccSeries, day: Any, opts: GraceBiasOptions, prefix: Path
) -> tuple[dict[str, Any], list[Path], list[str], np.ndarray]:
    """Run :func:`accal.closure.close_loop` on each axis' residual of the reference fit.

    Returns ``({axis: {"summary", "instrument", "model", "coupled"}}, plots, warnings,
    covered)``; ``covered``: the samples every candidate channel covers.
    """
    aux, units, left_out, warnings = candidate_channels(series, opts)
    covered = np.ones(len(series), bool)
    for v in aux.values():
        covered &= np.isfinite(v)
    use_cl = day.use & covered
    candidates, note = closure_candidates(opts)
    # the scale is a candidate only where the user fixed it: with --scale fit|fit-matrix
    # eq. 3 holds the fit's estimate, and an axis the fit had to fix (not identifiable,
    # e.g. with a step in the residual) gets its scale from the refit without the effects
    refit_scale = opts.scale in ("fit", "fit-matrix")
    base_name = day.fit.basis.name()
    out: dict[str, Any] = {}
    plots: list[Path] = []
    for i, ax in enumerate(AXES):
        y, base, signal = null_design(day.fit, i, series.time, series.acc, day.reference)
        mode = day.fit.modes[i]
        cands = tuple(c for c in candidates if c != "scale" or not refit_scale)
        res = close_loop(
            series.time,
            y,
            valid=use_cl,
            base=base,
            aux=aux or None,
            alpha=opts.alpha,
            orbit_period=opts.orbit_period,
            candidates=cands,
            resolution=_resolution(series.acc[:, i], y),
            reference=signal,
            signal_model="none",
            channel_units=units,
            screened=left_out,
            options={"orbit_period_fixed": True},
        )
        inst = np.zeros(len(series))
        labels = [base_name]
        for e, m in res.effect_models():
            if e.instrument:
                inst += np.where(covered, m, 0.0)
                labels.append(effect_label(e))
        summary = res.to_dict()
        summary.update(
            model="+".join(labels),
            candidates=list(cands),
            null_model=f"reference fit's calibrated residual a_raw − S⁻¹a_ref (scale {mode}"
            f"{', held' if mode != 'fixed' else ''} at {day.fit.scale[i, i]:.6g}): bias "
            f"{base_name} ({', '.join(base.names)})",
            removed_from_calibrated=labels[1:],
            markdown=to_markdown(res, title=f"{path.name} axis {ax} (reference fit)"),
        )
        if note:
            summary["note"] = note
        coupled = any(lb.startswith("auxiliary(") for lb in labels[1:])
        out[ax] = {"summary": summary, "instrument": inst, "model": summary["model"]}
        out[ax]["coupled"] = coupled
        if opts.plots:
            plots += write_closure_plots(res, prefix, ax, f"{path.name}, axis {ax} (reference fit)")
    return out, plots, warnings, covered


def close_reference_loop(
    path: Path,
    series: AccSeries,
    minus_ref: AccSeries,
    day: Any,
    opts: GraceBiasOptions,
    prefix: Path,
) -> tuple[Any, ReferenceClosure | None, list[str]]:
    """Close the loop on one day's reference fit; refit when instrument effects are removed.

    Parameters
    ----------
    path : Path
        The input (names it in the reports).
    series, minus_ref : AccSeries
        The input as read and ``series − reference`` (reference holes invalid).
    day : ReferenceDay
        Its reference fit (:func:`accal.pipeline_reference.fit_day`).
    opts : GraceBiasOptions
    prefix : Path
        Where the plots go (``<prefix>.closure.<axis>.png``).

    Returns
    -------
    day : ReferenceDay
        The refit without the instrument effects (``day`` itself when none was removed).
    closure : ReferenceClosure or None
        None when the day is too short for the residual analysis (said in the warnings).
    warnings : list of str
    """
    days, closures, warnings = close_arc_loop([path], [series], [minus_ref], [day], opts, [prefix])
    return days[0], closures[0], warnings[0]


def close_arc_loop(
    paths: list[Path],
    series: list[AccSeries],
    minus_ref: list[AccSeries],
    days: list[Any],
    opts: GraceBiasOptions,
    prefixes: list[Path],
) -> tuple[list[Any], list[ReferenceClosure | None], list[list[str]]]:
    """Close the loop on each day of an arc's reference fit; refit the arc when
    instrument effects are removed.

    ``days[k]`` is input ``k``'s share of one fit over the arc
    (:func:`accal.pipeline_reference.fit_arc`; one input: a day fitted alone).  Each
    day's closure runs on its own calibrated residual (eq. 3) with the arc's bias
    basis on that day as its null model (the columns that are not zero there: a
    spline's local ones, a polynomial's all), which frees the day's bias from the
    continuity across days for the search (a looser null, so nothing of the day's bias
    is taken for an effect).  The instrument effects accepted on any day are taken out
    of that day's data and the whole arc is fitted again: one fit, as without
    ``--close-loop``; what estimating the effects adds to the variance of the bias
    coefficients is added to the refit's covariance (:func:`with_effect_uncertainty`,
    summed over the days that share a coefficient).

    Returns the days of the refit (``days`` when nothing was removed), each day's
    :class:`ReferenceClosure` (None when too short for the residual analysis) and
    each day's warnings.
    """
    n = len(paths)
    warnings: list[list[str]] = [[] for _ in range(n)]
    found: list[dict[str, Any] | None] = [None] * n
    covered: list[np.ndarray | None] = [None] * n
    plots: list[list[Path]] = [[] for _ in range(n)]
    for k in range(n):
        n_use = int(np.count_nonzero(days[k].use))
        if n_use < MIN_SAMPLES:  # the reference fit stands; say why there is no closure
            warnings[k].append(
                f"too short to close the loop ({n_use} usable samples, the residual "
                f"analysis needs {MIN_SAMPLES}): reference fit {days[k].fit.basis.name()} only"
            )
            continue
        found[k], plots[k], notes, covered[k] = _close_axes(
            paths[k], series[k], days[k], opts, prefixes[k]
        )
        warnings[k].extend(notes)
    removed = [
        {ax: c for ax, c in f.items() if c["summary"]["removed_from_calibrated"]} if f else {}
        for f in found
    ]
    after = days
    if any(removed):
        new_series, new_minus = list(series), list(minus_ref)
        for k in range(n):
            if not removed[k]:
                continue
            f, cov_k = found[k], covered[k]
            inst = np.column_stack([f[ax]["instrument"] for ax in AXES])
            valid = minus_ref[k].valid
            n_out = int(np.count_nonzero(days[k].use & ~cov_k))
            if any(c["coupled"] for c in removed[k].values()) and n_out:
                # a coupling is not removed where its channel is missing: out of the refit
                valid = valid & cov_k
                warnings[k].append(
                    f"a coupling was removed and its channel misses {n_out} used samples: "
                    "they are left out of the refit and marked invalid in the calibrated file"
                )
            history = (
                f"accal {__version__}: close_loop(alpha={opts.alpha}) on the reference fit's "
                "residual removed " + "; ".join(f"{ax}: {f[ax]['model']}" for ax in AXES)
            )
            new_series[k] = series[k].replace(acc=series[k].acc - inst).with_history(history)
            new_minus[k] = minus_ref[k].replace(acc=minus_ref[k].acc - inst, valid=valid)
        after = fit_arc(paths, new_series, new_minus, opts)
        fit = after[0].fit
        for k in range(n):
            if removed[k]:
                fit = with_effect_uncertainty(fit, {a: c["summary"] for a, c in removed[k].items()})
        after = [dataclasses.replace(d, fit=fit) for d in after]
    truth = load_truth(opts.truth, series[0], True) if opts.truth and n == 1 else {}
    closures: list[ReferenceClosure | None] = []
    for k in range(n):
        f = found[k]
        if f is None:
            closures.append(None)
            continue
        for ax in AXES:
            f[ax]["summary"]["estimates"] = before_after(
                days[k], after[k], ax, series[k].time, opts, truth.get(ax)
            )
        closures.append(
            ReferenceClosure(
                summaries={ax: c["summary"] for ax, c in f.items()},
                models={ax: c["model"] for ax, c in f.items()},
                outputs=tuple(plots[k]),
            )
        )
    return after, closures, warnings
