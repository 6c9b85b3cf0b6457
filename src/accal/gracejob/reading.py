"""Reading one input of ``accal grace-bias``, and subtracting a reference from it.

:func:`read_input` reads with the format registry, :func:`subtract_reference`
removes an interpolated reference (marking its holes), and
:func:`read_with_reference` does both, with the plausibility screen and the
file-name checks (:func:`name_mismatch`) of every input.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline

from accal import __version__
from accal.batch_discovery import L1B_NAME
from accal.errors import AccalError, ValidationError
from accal.gracejob.options import GraceBiasOptions
from accal.io import FORMATS, detect_format, read
from accal.plausibility import flag_wild_samples
from accal.series import ACC_UNIT_FACTORS, AccSeries, acceleration_factor
from accal.timescale import gps_to_date, gps_to_utc


def read_input(path: Path, opts: GraceBiasOptions) -> AccSeries:
    """Read one input with the registry (format sniffed unless forced)."""
    kwargs: dict[str, Any] = {}
    fmt = opts.input_format or detect_format(path)  # detect_format also checks the path
    if opts.columns and fmt == "table":  # --column maps table columns; L1B files have fixed ones
        kwargs["columns"] = dict(opts.columns)
    if opts.input_format is None:  # sniffed and checked above: call the reader directly
        series = FORMATS[fmt][1](path, **kwargs)
    else:
        series = read(path, format=fmt, **kwargs)
    if opts.columns and fmt != "table" and not _reference_is_table(opts):
        # QA (issue 23): silently ignored; a table --reference uses the mapping (QA, 22)
        cols = ", ".join(f"{a}={c}" for a, c in sorted(opts.columns.items()))
        series = with_warnings(
            series, f"--column {cols} is for table inputs; this {fmt} file's columns are fixed"
        )
    return series


def _reference_is_table(opts: GraceBiasOptions) -> bool:
    """Whether ``--reference`` is a table (``--column`` maps its columns too)."""
    return opts.reference is not None and _is_table(str(opts.reference))


@functools.lru_cache(maxsize=4)
def _is_table(path: str) -> bool:
    """Whether ``path`` is sniffed as a table (once per process: every input asks)."""
    try:
        return detect_format(Path(path)) == "table"
    except (AccalError, OSError):  # its reader says what is wrong with it
        return False


#: Longest spacing of two reference samples that :func:`subtract_reference` interpolates
#: across, in nominal reference steps: one missing sample is bridged, a longer hole is not.
REFERENCE_MAX_BRIDGE = 2.5


def _utc_span(t: np.ndarray) -> str:
    """``2005-01-15 00:00:00 to 11:59:59 UTC`` for GPS seconds ``t`` (first and last)."""
    try:
        a, b = (str(x).replace("T", " ") for x in gps_to_utc(t[[0, -1]]).astype("datetime64[s]"))
    except ValueError:  # non-finite or before 1972: the seconds as they are
        return f"GPS seconds {t[0]:.1f} to {t[-1]:.1f}"
    return f"{a} to {b[11:] if b[:10] == a[:10] else b} UTC"


def _not_covered(ref_path: Path, tr: np.ndarray, t: np.ndarray) -> str:
    """One line: the reference ``ref_path`` (times ``tr``) does not cover the data's ``t``."""
    have = f"covers {_utc_span(tr)}" if tr.size >= 2 else f"has {tr.size} sample(s)"
    return (
        f"{ref_path}: the reference {have}, the data {_utc_span(t)}: the reference must "
        "cover the data (give a reference for the whole day)"
    )


#: Reference samples kept beyond each end of the data for the interpolating spline.
SPLINE_MARGIN = 8


def interpolate_reference(reference: AccSeries, axes: tuple[str, ...], t: np.ndarray) -> np.ndarray:
    """``reference``'s ``axes`` at the epochs ``t``: a cubic spline through its valid samples.

    A not-a-knot cubic spline (de Boor, *A Practical Guide to Splines*, 1978, ch. IV;
    :class:`scipy.interpolate.CubicSpline`) through the reference's valid, finite
    samples within :data:`SPLINE_MARGIN` samples of ``t``'s span, one per stretch
    between holes longer than :data:`REFERENCE_MAX_BRIDGE` steps; epochs outside them
    (and inside a hole) are NaN (their samples are left out by
    :func:`subtract_reference`).  Linear
    interpolation, used before, attenuates what varies between two reference
    samples: measured on a drag-like signal with eclipses, a 10 s reference gave
    scale errors of −1.1e-5 to −3.4e-5 linearly and 8e-10 to 4e-6 with the spline
    (30 s: −1e-4 to −3e-4 against 1e-7 to 7e-5).  At the reference's own epochs
    both are exact.
    """
    tr = reference.time
    acc = np.column_stack([reference.axis(ax) for ax in axes])
    keep = reference.valid & np.isfinite(acc).all(1) & np.isfinite(tr)
    lo, hi = np.searchsorted(tr, [t[0], t[-1]])
    window = np.zeros(tr.size, bool)
    window[max(lo - SPLINE_MARGIN, 0) : hi + SPLINE_MARGIN] = True
    keep &= window
    xs, ys = tr[keep], acc[keep]
    out = np.full((t.size, len(axes)), np.nan)
    if xs.size < 2:
        return out
    if np.any(np.diff(xs) <= 0):  # repeated epochs: no spline (linear, as the reader keeps)
        inside = (t >= xs[0]) & (t <= xs[-1])
        for i in range(len(axes)):
            out[inside, i] = np.interp(t[inside], xs, ys[:, i])
        return out
    # one spline per stretch without a hole (a hole's cubic would ring into its edges;
    # the data inside a hole are left out by subtract_reference)
    gaps = np.diff(xs) > REFERENCE_MAX_BRIDGE * float(np.median(np.diff(xs)))
    edges = np.r_[0, np.flatnonzero(gaps) + 1, xs.size]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        inside = (t >= xs[a]) & (t <= xs[b - 1])
        if b - a >= 4:
            out[inside] = CubicSpline(xs[a:b], ys[a:b], axis=0)(t[inside])
        elif b - a >= 2:  # too few for a cubic
            for i in range(len(axes)):
                out[inside, i] = np.interp(t[inside], xs[a:b], ys[a:b, i])
    return out


def subtract_reference(series: AccSeries, reference: AccSeries, ref_path: Path) -> AccSeries:
    """Return ``series`` minus ``reference`` interpolated onto its epochs.

    Samples that fall in a hole of the reference (two reference samples more than
    :data:`REFERENCE_MAX_BRIDGE` nominal steps apart) are not bridged: they are
    marked invalid (left out of the fit) and a warning in the returned series'
    report says how many.  A reference sampled more sparsely than that relative to
    the data (or so holed that its median step is a hole) is interpolated, with a
    warning that gives both steps.  A reference that ends less than a hole's length
    before the data (or starts after them) leaves the samples outside it out, with a
    warning; further, it is an error.  QA: 96 missing samples of a 1 Hz reference were bridged
    by a straight line and moved the bias by 8.7e-10 m/s² (2.5σ), silently.

    Raises
    ------
    ValidationError
        If the reference does not cover the series' time span or lacks an axis.
    """
    t = series.time
    tr = reference.time
    if tr.size < 2:
        raise ValidationError(_not_covered(ref_path, tr, t))
    # an end short of the data by less than a hole (e.g. a 10 s reference whose last
    # sample is 9 s before the day's: QA lost the whole day) leaves those samples out
    slack = REFERENCE_MAX_BRIDGE * float(np.median(np.diff(tr)))
    if tr[0] > t[0] + slack or tr[-1] < t[-1] - slack:
        raise ValidationError(_not_covered(ref_path, tr, t))
    outside = (t < tr[0]) | (t > tr[-1])
    unit = reference.units.get("acc")
    factor = acceleration_factor(unit)
    if factor is None:
        raise ValidationError(
            f"{ref_path}: reference unit {unit!r} is not an acceleration unit accal knows "
            f"({', '.join(sorted({k for k in ACC_UNIT_FACTORS if k.isascii()}))})"
        )
    for ax in series.axes:
        if ax not in reference.axes:
            raise ValidationError(f"{ref_path}: reference has no axis {ax!r}")
    ref_ok = np.interp(t, tr, reference.valid.astype(float)) > 0.999
    if not np.any(ref_ok & ~outside):  # QA: "0 usable samples", the reference not named
        raise ValidationError(
            f"{ref_path}: the reference has no valid (finite) sample over the data's span "
            f"({_utc_span(t)})"
        )
    ref_on_t = interpolate_reference(reference, series.axes, t)
    cols = [series.axis(ax) - factor * ref_on_t[:, i] for i, ax in enumerate(series.axes)]
    n_ref_bad = int(np.count_nonzero(series.valid & ~ref_ok & ~outside))
    valid = series.valid & ref_ok
    n_out = int(np.count_nonzero(outside & valid))
    valid &= ~outside
    step = float(np.median(np.diff(tr)))
    j = np.clip(np.searchsorted(tr, t, side="right"), 1, tr.size - 1)
    lo, hi = tr[j - 1], tr[j]
    hole = (hi - lo > REFERENCE_MAX_BRIDGE * step) & (t != lo) & (t != hi)
    warnings = []
    if factor != 1.0:
        warnings.append(f"--reference {ref_path.name} is in {unit}: converted to m/s^2")
    step_data = float(np.median(np.diff(t))) if t.size > 1 else step
    if step > REFERENCE_MAX_BRIDGE * step_data:
        # too few reference samples to tell a hole from its sampling: say how it is used
        warnings.append(
            f"--reference {ref_path.name} is sampled every {step:g} s (median), the data "
            f"every {step_data:g} s: it is interpolated by a cubic spline through its samples"
        )
    if n_out:
        warnings.append(
            f"--reference {ref_path.name} ends within {slack:g} s of the data's "
            f"{'start' if tr[0] > t[0] else 'end'}: {n_out} sample(s) of the data outside it "
            "are left out of the fit"
        )
    if n_ref_bad:
        warnings.append(
            f"--reference {ref_path.name} has missing or non-finite samples: {n_ref_bad} "
            "sample(s) of the data next to them are left out of the fit"
        )
    n_hole = int(np.count_nonzero(hole & valid))
    if n_hole:
        valid &= ~hole
        warnings.append(
            f"--reference {ref_path.name} has holes longer than "
            f"{REFERENCE_MAX_BRIDGE * step:g} s: {n_hole} sample(s) of the data "
            f"({n_hole / t.size:.1%}) fall in them and are left out of the fit"
        )
    valid &= np.isfinite(ref_on_t).all(1)  # the spline's holes are those above, or none
    out = series.replace(acc=np.column_stack(cols), valid=valid).with_history(
        f"accal {__version__}: subtract_reference({ref_path.name})"
    )
    return with_warnings(out, *warnings)


def read_with_reference(
    path: Path, opts: GraceBiasOptions, reference: AccSeries | None = None
) -> tuple[AccSeries, AccSeries, AccSeries | None]:
    """Read one input: (series, series to fit, ``series − reference`` or None).

    ``reference``: the reference already read (an arc reads it once for all inputs).
    """
    series = read_input(path, opts)
    if len(series) == 0:
        raise ValidationError("no data records")
    series, wild = flag_wild_samples(series)
    _check_live_axes(series)
    series = with_warnings(series, *name_mismatch(path, series), *wild)
    if opts.reference is None:
        return series, series, None
    if reference is None:
        reference = read_input(opts.reference, GraceBiasOptions(columns=opts.columns))
    minus_ref = subtract_reference(series, reference, opts.reference)
    return series.replace(report=minus_ref.report), minus_ref, minus_ref


def _check_live_axes(series: AccSeries) -> None:
    """Refuse an axis whose valid samples all hold one value (a dead or zero-filled channel).

    QA (2026-11-30): an all-zero day gave bias 0 ± 0 (and an internal error with
    ``--close-loop``), a stuck x axis a bias σ of 1e-22 m/s²: numbers, not data.

    Raises
    ------
    ValidationError
        Naming the axes and their value.
    """
    dead = []
    for k, ax in enumerate(series.axes):
        a = series.acc[series.valid, k]
        a = a[np.isfinite(a)]
        if a.size >= 2 and a.min() == a.max():
            dead.append(f"{ax} = {a[0]:.6g}")
    if dead:
        raise ValidationError(
            f"axis {' and '.join(dead)} at every valid sample ({int(series.valid.sum())}): "
            "a dead or zero-filled channel, nothing to calibrate"
        )


def with_warnings(series: AccSeries, *warnings: str) -> AccSeries:
    """``series`` with ``warnings`` appended to its read report (itself if none)."""
    if not warnings:
        return series
    rep = series.report
    return series.replace(report=dataclasses.replace(rep, warnings=(*rep.warnings, *warnings)))


def name_mismatch(path: Path, series: AccSeries) -> list[str]:
    """Disagreements between an L1B file name and its content (satellite, day).

    ``ACC1B_2005-01-01_A_02.asc`` names GRACE-A data of GPS day 2005-01-01; a
    file that holds another satellite or day was probably renamed or mixed up.
    Names that do not follow the L1B pattern are not checked.
    """
    m = L1B_NAME.search(path.name)
    if m is None or len(series) == 0:
        return []
    out = []
    letter = series.satellite[-1:] if series.satellite.startswith("GRACE") else ""
    if letter and m["sat"] != letter:
        out.append(f"file name says satellite {m['sat']}, the data are {series.satellite}")
    t = series.time
    days = {gps_to_date(float(t[0])), gps_to_date(float(t[len(t) // 2]))}
    if m["date"] not in days:
        out.append(f"file name says {m['date']}, the data are of {min(days)}")
    return out
