"""Checks of the demodulation input: finite values, regular sampling, τ and TM, θ.

The whole-record checks of :func:`demodulate` (:func:`_validate`) and the
per-chunk checks of :func:`demodulate_stream` (:class:`_Checker`), with the
sampling step and θ-convention helpers they share (also used by
:mod:`accal.pipeline_demod` and :mod:`accal.closure.demod`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...errors import ValidationError
from .records import DemodChunk


def _first_bad(name: str, x: NDArray, valid: NDArray | None = None, offset: int = 0) -> None:
    bad = ~np.isfinite(x)
    if valid is not None:
        bad &= valid
    if bad.any():
        raise ValidationError(
            f"{name} contains {int(bad.sum())} NaN/inf value(s) "
            f"(first at index {offset + int(np.argmax(bad))})"
        )


#: Relative tolerance of a sampling step against the nominal step.
STEP_RTOL = 1e-6


def step_tolerance(dt: float, t_abs: float) -> float:
    """Largest ``|step − dt|`` [s] still taken as regular sampling.

    ``STEP_RTOL·dt`` plus the float64 rounding of the times themselves: each time
    is stored to within half its ulp, so a difference of two is off by up to one
    ulp of the larger.  With absolute times that is not negligible: at 1.4e9 s (GPS
    seconds of 2024) the ulp is 2.4e-7 s, 2.4e-6 of a 10 Hz step (QA: a regular
    10 Hz run was refused as irregular once its times were GPS seconds).

    Parameters
    ----------
    dt : float
        Nominal step [s].
    t_abs : float
        Largest ``|t|`` of the times compared [s].

    Returns
    -------
    float
        [s]
    """
    return STEP_RTOL * dt + 2.0 * float(np.spacing(abs(t_abs)))


def sampling_step(t: NDArray[np.float64]) -> tuple[float, float]:
    """The sampling step of increasing times, and its relative uncertainty.

    The median step; when every step is within :func:`step_tolerance` of it, the
    mean step ``(t[-1] − t[0])/(n − 1)`` instead, whose only error is the rounding
    of the two end times (``2 ulp / span``, returned).  The median of steps that
    are each rounded to the ulp of large absolute times is off by up to that ulp,
    enough to make ``τ·fs`` non-integer (QA: ``tau·fs = 6000.0057`` for 10 Hz at
    1.4e9 s).

    Parameters
    ----------
    t : ndarray, shape (n,), n >= 2
        Times [s].

    Returns
    -------
    dt : float
        [s]
    rtol : float
        Relative uncertainty of ``dt`` from the rounding of the times (0 when the
        steps are irregular: the caller reports them).
    """
    steps = np.diff(t)
    dt = float(np.median(steps))
    if not dt > 0:
        return dt, 0.0
    t_abs = max(abs(float(t[0])), abs(float(t[-1])))
    if np.all(np.abs(steps - dt) <= step_tolerance(dt, t_abs)):
        span = float(t[-1] - t[0])
        return span / (t.size - 1), 2.0 * float(np.spacing(t_abs)) / span
    return dt, 0.0


def regular_step(t: NDArray[np.float64]) -> tuple[float, float]:
    """:func:`sampling_step` of times that must be regular.

    Raises
    ------
    ValidationError
        A step further than :func:`step_tolerance` from the nominal one (the worst is
        named, with its index), or times that do not increase.
    """
    dt, rtol = sampling_step(t)
    steps = np.diff(t)
    if dt <= 0 or np.any(np.abs(steps - dt) > step_tolerance(dt, max(abs(t[0]), abs(t[-1])))):
        k = int(np.argmax(np.abs(steps - dt)))
        raise ValidationError(
            f"sampling is irregular: step {steps[k]:.10g} s at index {k} vs nominal "
            f"{dt:.10g} s (resample or split the record at gaps)"
        )
    return dt, rtol


def _check_tau_mask(fs: float, tau: float, tm: float, fs_rtol: float = 0.0) -> int:
    """``q = τ·fs`` (an integer within 1e-6, or within ``fs_rtol`` of ``fs``), after checking τ and TM."""
    q = tau * fs
    if not np.isfinite(q) or q <= 0:
        raise ValidationError(f"tau must be positive, got {tau}")
    if q < 1 - 1e-6:
        raise ValidationError(
            f"tau = {tau:.10g} s is shorter than one sample (fs = {fs:.10g} Hz): tau must be "
            f"a whole number of samples, at least {1 / fs:.10g} s"
        )
    if abs(q - round(q)) > max(1e-6, q * fs_rtol):
        lo, hi = np.floor(q) / fs, np.ceil(q) / fs
        raise ValidationError(
            f"tau·fs = {q:.10g} is not an integer (fs = {fs:.10g} Hz); "
            f"use tau = {lo:.10g} s or {hi:.10g} s"
        )
    if not 0 <= tm < tau:
        raise ValidationError(
            f"mask (masking time TM) must be in [0, tau) s, got {tm} s for tau = {tau} s"
        )
    return int(round(q))


#: A θ value this close to a multiple of π/2 [rad] counts as a rest angle of a pattern.
REST_ANGLE_TOL = 1e-6


def theta_in_range(th: NDArray[np.float64], valid: NDArray | None, tol: float) -> NDArray:
    """θ in ``[0, 2π]``: as given, or wrapped when it is radians in another convention.

    A θ outside ``[−tol, 2π + tol]`` whose rests are at multiples of π/2 (over a tenth
    of the samples away from 0 lie within :data:`REST_ANGLE_TOL` of one) is radians
    in another convention, ``[−π, π)`` (atan2) or unwrapped (always rotating one
    way): it is wrapped into ``[0, 2π)``, with values within ``REST_ANGLE_TOL`` below
    2π taken as 0, so a rest at 0 stays continuous.  Degrees rest at 90, 180, 270,
    which are not multiples of π/2 rad: refused with that diagnosis.  QA: θ of
    ``[−π, π)`` was refused ("must lie in [0, 2π]"), unwrapped radians were taken for
    degrees.

    Parameters
    ----------
    th : ndarray
        θ [rad].
    valid : ndarray of bool or None
        Samples to judge by (others may hold anything).
    tol : float
        Tolerance on the ``[0, 2π]`` range [rad].

    Returns
    -------
    ndarray
        θ in ``[−REST_ANGLE_TOL, 2π + tol]`` [rad].

    Raises
    ------
    ValidationError
        θ outside the range and not radians of another convention.
    """
    x = th if valid is None else th[valid]
    x = x[np.isfinite(x)]
    if not x.size or (x.min() >= -tol and x.max() <= 2 * np.pi + tol):
        # in range; a rest at 0 whose noise dips below it reads just under 2π: those
        # samples are taken as the same rest, not a turn away (QA: θ mod 2π with
        # N(0, 1e-8 rad) at rest masked 352 s per period instead of 208 s, a_Y off 5σ)
        near = th > 2 * np.pi - REST_ANGLE_TOL
        return np.where(near, th - 2 * np.pi, th) if near.any() else th
    away = x[np.abs(x) > REST_ANGLE_TOL]
    r = np.mod(away, 0.5 * np.pi)
    at_rest_angle = np.minimum(r, 0.5 * np.pi - r) < REST_ANGLE_TOL
    if away.size and at_rest_angle.mean() > 0.1:
        w = np.mod(th, 2 * np.pi)
        return np.where(w > 2 * np.pi - REST_ANGLE_TOL, w - 2 * np.pi, w)
    if x.max() > 2 * np.pi + tol:
        raise ValidationError(
            f"theta reaches {x.max():g} > 2π and its rests are not at multiples of π/2 rad: "
            "it looks like degrees; give theta in radians (or declare its unit 'deg')"
        )
    raise ValidationError(
        f"theta must lie in [0, 2π] rad (or be radians resting at multiples of π/2 in "
        f"another convention), got minimum {x.min():g}"
    )


def _validate(time, m_y, m_z, theta, aux, valid, tau, tm, theta_tol):
    arrs = {}
    for name, x in (("time", time), ("m_y", m_y), ("m_z", m_z), ("theta", theta), *aux.items()):
        a = np.asarray(x, dtype=float)
        if a.ndim != 1:
            raise ValidationError(f"{name} must be 1-D, got shape {a.shape}")
        arrs[name] = a
    n = arrs["time"].size
    ok = None if valid is None else np.asarray(valid, dtype=bool)
    if ok is not None and ok.shape != (n,):
        raise ValidationError(f"valid has shape {ok.shape} but time has {n} samples")
    for name, a in arrs.items():
        if a.size != n:
            raise ValidationError(f"{name} has {a.size} samples but time has {n}")
    for name, a in arrs.items():
        _first_bad(name, a, None if name == "time" else ok)
    if n < 3:
        raise ValidationError(f"need at least 3 samples, got {n}")
    dt, dt_rtol = regular_step(arrs["time"])
    fs = 1.0 / dt
    _check_tau_mask(fs, tau, tm, dt_rtol)
    arrs["theta"] = theta_in_range(arrs["theta"], ok, theta_tol)
    return arrs, ok, fs


class _Checker:
    """Per-chunk checks of a stream (the whole-record checks of :func:`_validate`)."""

    def __init__(self, aux_names, tau, tm, fs, theta_tol=1e-6, live=False):
        self.aux_names = tuple(aux_names)
        self.tau, self.tm, self.theta_tol = float(tau), float(tm), theta_tol
        self.fs = None if fs is None else float(fs)
        self.fs_rtol = 0.0  # relative uncertainty of fs from the rounding of the times
        self.q = None  # checked when the first chunk arrives (its own checks come first)
        self.n = 0
        self.last_t = None
        self.th_min, self.th_max = np.inf, -np.inf
        self.reaches_pi = False
        # value range of each channel's valid samples: with the noise estimated from the
        # data (``live``) a channel must vary
        self.live = live
        self.span = {"m_y": [np.inf, -np.inf], "m_z": [np.inf, -np.inf]}

    def __call__(self, ch: DemodChunk) -> dict[str, NDArray]:
        arrs = {}
        aux = dict(ch.aux)
        missing = [k for k in self.aux_names if k not in aux]
        if missing:
            raise ValidationError(f"chunk lacks the auxiliary channel(s) {', '.join(missing)}")
        cols = (("time", ch.time), ("m_y", ch.m_y), ("m_z", ch.m_z), ("theta", ch.theta))
        for name, x in (*cols, *((k, aux[k]) for k in self.aux_names)):
            a = np.asarray(x, dtype=float)
            if a.ndim != 1:
                raise ValidationError(f"{name} must be 1-D, got shape {a.shape}")
            arrs[name] = a
        n = arrs["time"].size
        for name, a in arrs.items():
            if a.size != n:
                raise ValidationError(f"{name} has {a.size} samples but time has {n}")
        ok = np.ones(n, bool) if ch.valid is None else np.asarray(ch.valid, dtype=bool)
        if ok.shape != (n,):
            raise ValidationError(f"valid has shape {ok.shape} but time has {n} samples")
        for name, a in arrs.items():
            _first_bad(name, a, None if name == "time" else ok, self.n)
        t = arrs["time"]
        if self.fs is None:
            if n < 3:
                raise ValidationError(
                    f"need at least 3 samples in the first chunk to find the sampling step, got {n}"
                )
            dt, self.fs_rtol = sampling_step(t)
            self.fs = 1.0 / dt
        if self.q is None:
            self.q = _check_tau_mask(self.fs, self.tau, self.tm, self.fs_rtol)
        dt = 1.0 / self.fs
        steps = np.diff(t) if self.last_t is None else np.diff(np.concatenate([[self.last_t], t]))
        off = (
            np.abs(steps - dt) > step_tolerance(dt, max(abs(t[0]), abs(t[-1]))) if n else steps > 0
        )
        if off.any():
            k = int(np.argmax(np.abs(steps - dt)))
            idx = self.n + k - (0 if self.last_t is None else 1)
            raise ValidationError(
                f"sampling is irregular: step {steps[k]:.10g} s at index {idx} vs nominal "
                f"{dt:.10g} s (resample or split the record at gaps)"
            )
        arrs["theta"] = theta_in_range(arrs["theta"], ok, self.theta_tol)
        th = arrs["theta"][ok]
        if th.size:
            self.th_min = min(self.th_min, float(th.min()))
            self.th_max = max(self.th_max, float(th.max()))
            self.reaches_pi |= bool(np.any(np.abs(np.cos(th) + 1.0) < 1e-3))
        for name, span in self.span.items():
            a = arrs[name][ok]
            if a.size:
                span[0], span[1] = min(span[0], float(a.min())), max(span[1], float(a.max()))
        if n:
            self.last_t = float(t[-1])
        self.n += n
        arrs["valid"] = ok
        return arrs

    def finish(self) -> None:
        if self.n < 3:
            raise ValidationError(f"need at least 3 samples, got {self.n}")
        if not self.reaches_pi:
            raise ValidationError(
                f"theta never reaches π (range {self.th_min:.3g} to {self.th_max:.3g} rad): "
                "the pattern must measure at θ = 0 and θ = π"
            )
        # QA (2026-11-30): an all-zero m_z gave a_Z = 3e-23 ± 2.7e-12 (σ from the other
        # axis' noise), an all-zero run an internal error in the noise fit
        # (a noise-free record with an a-priori PSD may be constant: exact, σ as declared)
        dead = [f"{k} = {v[0]:.6g}" for k, v in self.span.items() if self.live and v[0] == v[1]]
        if dead:
            raise ValidationError(
                f"{' and '.join(dead)} at every valid sample: a dead or zero-filled "
                "channel, nothing to demodulate"
            )
