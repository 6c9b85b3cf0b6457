"""``grace-bias --reference REF --scale fit|fit-matrix --bias-basis ...``: one input.

Sequences the reference calibration of one day (issue 22): the reference on the
data's epochs, thruster firings excluded (THR1B next to the input or
``--thrusters``), :func:`accal.estimators.reference.fit_reference`, and the
``bias_drift`` rows, calibrated series and parameter table of the result.  The
estimation itself is in :mod:`accal.estimators.reference`; this module computes
nothing but table entries from the fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.calibration import parse_scale, tn02_scale
from accal.errors import ValidationError
from accal.estimators.refbasis import parse_bias_basis
from accal.estimators.reference import ReferenceFit, fit_reference
from accal.io.attitude import find_attitude_file, read_attitude, rotate_to_srf
from accal.io.thrusters import find_thruster_file, firing_mask, foreign_day, read_thrusters
from accal.io.writers import atomic_path
from accal.series import AccSeries
from accal.timescale import gps_to_date

__all__ = [
    "PARAMETER_UNITS",
    "ReferenceDay",
    "apriori_scale",
    "fit_arc",
    "fit_day",
    "parameter_table",
    "report_entry",
    "row_fields",
    "write_covariance",
]


@dataclass(frozen=True)
class ReferenceDay:
    """The reference calibration of one input.

    Attributes
    ----------
    fit : ReferenceFit
    use : ndarray of bool
        Samples used (valid, reference present, not in a firing).
    calibrated : AccSeries
        ``S·(a_raw − b(t))``.
    thrusters : dict
        ``file``, ``firings`` in the day and ``n_excluded`` samples.
    warnings : tuple of str
    reference : ndarray, shape (n, 3), or None
        The reference the fit used, in the SRF [m/s²] (rotated with the attitude for
        ``--reference-frame inertial``; NaN where missing): the closure's null model
        (:mod:`accal.gracejob.reference_closure`).
    """

    fit: ReferenceFit
    use: np.ndarray
    calibrated: AccSeries
    thrusters: dict[str, Any]
    warnings: tuple[str, ...]
    reference: np.ndarray | None = None


def apriori_scale(scale: str | None, satellite: str) -> tuple[float, float, float]:
    """Scales used where a scale is fixed.

    ``--scale`` numbers (or ``tn02``) as given; no ``--scale``: 1; ``fit``/``fit-matrix``
    (the a-priori of a scale that is not identifiable): TN-02 for GRACE A/B, else 1.
    """
    if scale not in ("fit", "fit-matrix"):
        return parse_scale(scale, satellite) or (1.0, 1.0, 1.0)
    try:
        return tn02_scale(satellite)
    except ValidationError:
        return (1.0, 1.0, 1.0)


def _thrusters(path: Path, series: AccSeries, opts: Any) -> tuple[np.ndarray, dict, list[str]]:
    """Samples within a firing (``opts.thrusters`` or the THR1B beside ``path``)."""
    thr = opts.thrusters if opts.thrusters is not None else find_thruster_file(path)
    none = np.zeros(len(series), bool)
    if thr is None or opts.thruster_margins is None:
        why = "off" if opts.thruster_margins is None else "no THR1B file found"
        notes = []
        if (
            thr is None
            and opts.thruster_margins is not None
            and series.satellite.startswith("GRACE")
        ):
            # QA: unmasked firing spikes took S_zz to 0.44 ± 0.02 (truth 0.95), silently
            notes.append(
                f"no THR1B file beside {path.name}: thruster firings are not left out of the "
                "reference fit (give --thrusters FILE, or --thruster-margins off)"
            )
        return none, {"file": None, "firings": 0, "n_excluded": 0, "why": why}, notes
    firings = read_thrusters(thr)
    foreign = foreign_day(firings, series.time, thr)
    if foreign is not None:
        return (
            none,
            {"file": Path(thr).name, "firings": 0, "n_excluded": 0, "why": foreign},
            [foreign],
        )
    before, after = opts.thruster_margins
    mask = firing_mask(series.time, firings, before=before, after=after)
    t0, t1 = float(series.time[0]), float(series.time[-1])
    # paired attitude thrusters fire together: count distinct pulses (start epochs)
    start = np.unique(np.asarray(firings.events.start))
    n_day = int(np.count_nonzero((start >= t0 - after) & (start <= t1 + before)))
    info = {
        "file": Path(thr).name,
        "firings": n_day,
        "n_excluded": int(mask.sum()),
        "margins_s": [before, after],
    }
    return mask, info, list(firings.warnings)


def _to_srf(
    path: Path, time: np.ndarray, ref: np.ndarray, attitude: Path | None
) -> tuple[np.ndarray, list[str]]:
    """Rotate an inertial reference into the SRF with the SCA1B attitude (slerp)."""
    att_path = attitude if attitude is not None else find_attitude_file(path)
    if att_path is None:
        raise ValidationError(
            "--reference-frame inertial needs the SCA1B attitude: no SCA1B file beside the "
            "input; give --attitude"
        )
    att = read_attitude(att_path)
    srf = rotate_to_srf(time, ref, att)
    n_out = int(np.count_nonzero(~np.isfinite(srf).all(1) & np.isfinite(ref).all(1)))
    notes = [f"{Path(att_path).name}: {w}" for w in att.warnings]
    if n_out:
        notes.append(
            f"{n_out} samples outside the attitude of {Path(att_path).name} (not covered or in "
            "a gap): left out of the reference fit"
        )
    return srf, notes


def _prepare(path: Path, series: AccSeries, minus_ref: AccSeries, opts: Any):
    """Reference in the SRF, samples to use, thruster info and warnings of one input."""
    if tuple(series.axes) != ("x", "y", "z"):
        raise ValidationError(
            f"the reference calibration needs all three axes x, y, z (the input has "
            f"{', '.join(series.axes)})"
        )
    ref = series.acc - minus_ref.acc
    use = np.ones(len(series), bool) if opts.keep_flagged else minus_ref.valid.copy()
    firing, thr_info, warnings = _thrusters(path, series, opts)
    if opts.reference_frame == "inertial":
        ref, note = _to_srf(path, series.time, ref, opts.attitude)
        warnings.extend(note)
    use &= np.isfinite(ref).all(1)
    use &= ~firing
    return ref, use, thr_info, warnings


def fit_arc(
    paths: list[Path], series: list[AccSeries], minus_ref: list[AccSeries], opts: Any
) -> list[ReferenceDay]:
    """Fit consecutive inputs of one satellite as one arc (:func:`fit_reference`).

    ``minus_ref[k]`` is ``series[k] − reference`` on its epochs (reference holes marked
    invalid, :func:`accal.pipeline.subtract_reference`).  The bias basis spans the
    whole arc (a spline is continuous across the days); the noise model restarts at
    each input's first sample.  One input is an arc of one day.
    """
    parts = [_prepare(p, s, m, opts) for p, s, m in zip(paths, series, minus_ref, strict=True)]
    t = np.concatenate([s.time for s in series])
    if np.any(np.diff(t) <= 0):
        raise ValidationError("the inputs of an arc overlap in time")
    raw = np.concatenate([s.acc for s in series])
    ref = np.concatenate([p[0] for p in parts])
    use = np.concatenate([p[1] for p in parts])
    breaks = np.concatenate([np.arange(len(s)) == 0 for s in series])
    basis = parse_bias_basis(opts.bias_basis or "poly1", float(t[0]), float(t[-1]))
    mode = opts.scale if opts.scale in ("fit", "fit-matrix") else "fixed"
    apriori = apriori_scale(opts.scale, series[0].satellite)
    fit = fit_reference(t, raw, ref, use, basis, scale=mode, apriori=apriori, breaks=breaks)
    unmasked = []
    if opts.thruster_margins is not None:  # inputs with no THR1B file to mask firings by
        unmasked = [p.name for p, part in zip(paths, parts, strict=True) if part[2]["file"] is None]
    _check_scales(fit, mode, opts, unmasked)
    days = []
    edges = np.cumsum([0] + [len(s) for s in series])
    arc = f" over an arc of {len(series)} inputs" if len(series) > 1 else ""
    for k, s in enumerate(series):
        sl = slice(edges[k], edges[k + 1])
        cal = s.replace(
            acc=fit.calibrate(s.time, s.acc),
            history=(
                *s.history,
                f"calibrate(reference fit{arc}: basis {basis.name()}, scale {'/'.join(fit.modes)})",
            ),
        )
        notes = [*parts[k][3], *(f"reference fit: {n}" for n in fit.notes)]
        days.append(ReferenceDay(fit, fit.used[sl], cal, parts[k][2], tuple(notes), parts[k][0]))
    return days


#: Range of a fitted diagonal scale outside which the reference is taken to be in
#: another unit or of another quantity: an electrostatic accelerometer's scale factors
#: are within a few % of 1 (GRACE TN-02: 0.93-0.98; QA: a reference in nm/s² gave
#: scales of 9.6e8 with nothing said).
SCALE_RANGE = (0.5, 2.0)


def _check_scales(fit: ReferenceFit, mode: str, opts: Any, unmasked: list[str]) -> None:
    """Raise when a fitted diagonal scale is outside :data:`SCALE_RANGE` (``unmasked``:
    inputs whose thruster firings were not left out, for the message)."""
    if mode == "fixed":
        return
    lo, hi = SCALE_RANGE
    for i, ax in enumerate("xyz"):
        s = float(fit.scale[i, i])
        if fit.modes[i] != "fixed" and not lo <= s <= hi:
            raise ValidationError(
                f"{opts.reference}: the fitted scale on {ax} is {s:.3g} (an accelerometer's "
                f"is within {lo:g}-{hi:g}): is the reference in m/s² and of the same axes "
                "as the data?"
                + (
                    f" Thruster firings were not left out ({', '.join(unmasked)}: no THR1B "
                    "file; --thrusters FILE): their spikes also pull the scale."
                    if unmasked
                    else ""
                )
            )


def fit_day(path: Path, series: AccSeries, minus_ref: AccSeries, opts: Any) -> ReferenceDay:
    """Fit one input against its reference: :func:`fit_arc` of one day."""
    return fit_arc([path], [series], [minus_ref], opts)[0]


def row_fields(day: ReferenceDay, axis: str, time: np.ndarray, mode_given: str) -> dict[str, Any]:
    """Entries of one ``bias_drift`` row: bias/drift at the first used sample and the scales."""
    i = "xyz".index(axis)
    fit = day.fit
    t_used = time[day.use]
    t0 = float(t_used[0])
    b, sb = fit.bias(np.array([t0]))
    d, sd = fit.bias(np.array([t0]), deriv=1)
    k = fit.basis.size
    cols0, f0 = fit.basis.design(np.array([t0]))
    cols1, f1 = fit.basis.design(np.array([t0]), deriv=1)
    g0 = np.zeros(k)
    g0[f0 : f0 + cols0.shape[1]] = cols0[0]
    g1 = np.zeros(k)
    g1[f1 : f1 + cols1.shape[1]] = cols1[0]
    c = fit.bias_cov[i * k : (i + 1) * k, i * k : (i + 1) * k]
    denom = float(sb[0, i] * sd[0, i])
    s_sig = fit.scale_sigma
    mode = fit.modes[i]
    return {
        "method": "reference",
        "order": fit.basis.degree,
        "bias": float(b[0, i]),
        "drift": float(d[0, i]),
        "quadratic": float("nan"),
        "t0": t0,
        "bias_sigma": float(sb[0, i]),
        "drift_sigma": float(sd[0, i]),
        "quadratic_sigma": float("nan"),
        "bias_drift_corr": float(g0 @ c @ g1 / denom) if denom > 0 else float("nan"),
        "n": int(day.use.sum()),
        "rms": float(fit.rms[i]),
        "scale": float(fit.scale[i, i]),
        "bias_correction": float(-fit.scale[i, i] * b[0, i]),
        "model": fit.basis.name(),
        "bias_includes": "instrument",
        "sigma_model": f"AR({fit.noise[i].order}) of the reference residual",
        **{f"scale_{a}": float(fit.scale[i, j]) for j, a in enumerate("xyz")},
        **{f"scale_{a}_sigma": float(s_sig[i, j]) for j, a in enumerate("xyz")},
        "scale_mode": mode if mode_given in ("fit", "fit-matrix") else "given",
        "bias_basis": fit.basis.name(),
        "n_thruster": int(day.thrusters.get("n_excluded", 0)),
    }


def parameter_table(fit: ReferenceFit) -> dict[str, np.ndarray]:
    """The bias basis coefficients with their σ, one row per axis and coefficient.

    For a spline, ``node_time`` is the Greville abscissa of the coefficient (the
    mean of its interior knots, where it acts most; de Boor 2001, ch. XI).
    """
    k = fit.basis.size
    knots = fit.basis.knots
    deg = fit.basis.degree
    if fit.basis.kind == "spline":
        node = np.array([knots[j + 1 : j + deg + 1].mean() for j in range(k)])
    else:
        node = np.full(k, 0.5 * (fit.basis.t0 + fit.basis.t1))
    sig = np.sqrt(np.clip(np.diag(fit.bias_cov), 0, None)).reshape(3, k)
    return {
        "axis": np.repeat(np.array(["x", "y", "z"]), k),
        "index": np.tile(np.arange(k), 3),
        "node_time": np.tile(node, 3),
        "coef": fit.bias_coef.ravel(),
        "coef_sigma": sig.ravel(),
    }


PARAMETER_UNITS = {
    "axis": "accelerometer axis",
    "index": "coefficient index in the basis",
    "node_time": "s (GPS; Greville abscissa of a spline coefficient, arc centre for poly)",
    "coef": "m/s^2 (bias basis coefficient; Legendre on the arc mapped to [-1, 1] for poly)",
    "coef_sigma": "m/s^2 (1 sigma, scale uncertainty included)",
}


def write_covariance(path: Path, fit: ReferenceFit) -> Path:
    """Write the fit's full covariance and parameters to ``path`` (``.npz``), atomically.

    Arrays: ``scale`` (3, 3), ``bias_coef`` (3, K), ``cov`` (9 + 3K square: the
    covariance of ``scale.ravel()`` then ``bias_coef.ravel()``, SI units squared),
    ``names`` and ``units`` (9 + 3K: each row/column of ``cov``, e.g. ``scale_xy``
    [1] and ``bias_y[4]`` [m/s^2]; the file says its own layout), ``knots`` (spline
    knot vector [s GPS], empty for poly) and ``basis`` (its name).
    """
    names, units = covariance_labels(fit.bias_coef.shape[1])
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(
            fh,
            scale=fit.scale,
            bias_coef=fit.bias_coef,
            cov=fit.cov,
            names=names,
            units=units,
            knots=fit.basis.knots,
            basis=np.array(fit.basis.name()),
        )
    return path


def covariance_labels(k: int) -> tuple[NDArray[np.str_], NDArray[np.str_]]:
    """Names and units of the 9 + 3k rows of :func:`write_covariance`'s ``cov``.

    ``scale_ij`` (row i, column j of S in ``a_cal = S (a_raw − b)``, unit 1), then
    ``bias_<axis>[m]`` (coefficient m of the bias basis of that axis, m/s²), in the
    order of ``scale.ravel()`` and ``bias_coef.ravel()``.
    """
    names = [f"scale_{i}{j}" for i in "xyz" for j in "xyz"]
    names += [f"bias_{ax}[{m}]" for ax in "xyz" for m in range(k)]
    units = ["1"] * 9 + ["m/s^2"] * (3 * k)
    return np.array(names), np.array(units)


def report_entry(day: ReferenceDay) -> dict[str, Any]:
    """The ``reference_fit`` entry of ``<stem>.report.json``."""
    fit = day.fit
    return {
        "basis": fit.basis.name(),
        "knots": fit.basis.knots.tolist(),
        "scale": fit.scale.tolist(),
        "scale_sigma": fit.scale_sigma.tolist(),
        "scale_modes": list(fit.modes),
        "notes": list(fit.notes),
        "crosstalk_test": fit.crosstalk_test,
        "noise_ar_order": [m.order for m in fit.noise],
        "sigma0": fit.sigma0.tolist(),
        "rms": fit.rms.tolist(),
        "n_used": fit.n_used,
        "thrusters": day.thrusters,
        "convention": "a_ref = S (a_raw - b(t)) + e; a_cal = S (a_raw - b(t))",
    }


def parse_arc(spec: str) -> tuple[str, int]:
    """``--arc``: ``day`` → ("days", 1), ``30d`` → ("days", 30), ``month`` → ("month", 0)."""
    s = spec.strip().lower()
    if s == "day":
        return "days", 1
    if s == "month":
        return "month", 0
    if s.endswith("d") and s[:-1].isdigit() and int(s[:-1]) >= 1:
        return "days", int(s[:-1])
    raise ValidationError(f"--arc {spec!r}: expected day, <N>d (e.g. 30d) or month")


def group_arcs(
    inputs: list[tuple[str, float, float]], spec: str
) -> tuple[list[list[int]], list[str]]:
    """Group inputs into arcs.

    Parameters
    ----------
    inputs : list of (satellite, first time, last time)
        One entry per input (GPS seconds).
    spec : str
        ``--arc`` value.

    Returns
    -------
    arcs : list of list of int
        Input indices per arc, in time order: one satellite per arc, at most N
        calendar days (or one month), consecutive: a whole day without data
        between two inputs starts a new arc.
    notes : list of str
        Where an arc was cut short by a missing day.
    """
    kind, n_days = parse_arc(spec)
    order = sorted(range(len(inputs)), key=lambda i: (inputs[i][0], inputs[i][1]))
    arcs: list[list[int]] = []
    notes: list[str] = []
    first_day = 0.0
    for i in order:
        sat, t0, t1 = inputs[i]
        day = np.floor((t0 + 43200.0) / 86400.0)  # GPS day number (GPS epoch is noon)
        if arcs:
            prev = inputs[arcs[-1][-1]]
            same = prev[0] == sat
            if kind == "days":
                fits = day - first_day < n_days
            else:
                fits = gps_to_date(t0)[:7] == gps_to_date(inputs[arcs[-1][0]][1])[:7]
            gap = t0 - prev[2]
            if same and fits and gap > 86400.0:
                notes.append(
                    f"{sat}: {gap / 86400.0:.1f} days without data after "
                    f"{gps_to_date(prev[2])}: a new arc starts on {gps_to_date(t0)}"
                )
            elif same and fits:
                arcs[-1].append(i)
                continue
        arcs.append([i])
        first_day = day
    return arcs, notes
