"""Calibration patterns θ(t) for the rotating platform (section 4.1, Figs. 1-2).

A pattern is one modulation period of ``q = τ·fs`` samples.  The platform rests
at θ = 0 or θ = π only (so sin θ = 0 and cos²θ = 1 while measuring: scale and
quadratic factors then behave as a bias, section 4.1), stays within [0, 2π]
(no slip ring), and moves between rests with a smooth quintic profile whose
angular velocity and acceleration vanish at both ends.

Bias rejection (eq. 16, ``Va' Λc V̂b = 0``) becomes, per period, with
``c = cos θ · mask`` and ``t`` centred on the period (``t_k = (k - q/2) δt``):

* signal mean, bias affine:        ``Σ c = 0`` and ``Σ c t = 0``;
* signal affine, bias affine (eq. 19): additionally ``Σ c t² = 0``.

The symmetric four-rotation layout of Fig. 2,
``+a | R | -b | R | +c | R | -b | R | +a`` with ``R = TM/4``, ``b = (τ - TM)/4``
and ``c = 2b - 2a`` meets the first two conditions exactly on the sample grid,
both with the nominal mask and with the discrete θ̇ = θ̈ = 0 mask (which drops one
more sample at each end of every rotation).  ``a`` is searched over integer
sample counts to minimise ``|Σ c t²|``; the residual of every condition is
returned.  For τ = 600 s, TM = 200 s, fs = 1 Hz the search gives
``+34 | 50 | -100 | 50 | +132 | 50 | -100 | 50 | +34`` s.

References
----------
B. Lenoir, B. Christophe, S. Reynaud, Adv. Space Res. 51 (2013) 188-197,
doi:10.1016/j.asr.2012.08.001.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import ValidationError, check_option

__all__ = ["CalibrationPattern", "design_pattern", "rest_mask", "condition_residuals", "tile"]


@dataclass(frozen=True)
class CalibrationPattern:
    """One period of a calibration signal.

    Attributes
    ----------
    kind : str
        ``"fig1"`` (two rotations, Fig. 1(a) type) or ``"fig2"`` (four rotations, Fig. 2).
    tau : float
        Modulation period τ [s].
    tm : float
        Nominal masking (rotation) time per period TM [s].
    fs : float
        Sampling frequency [Hz].
    segments : tuple of (int, float or None)
        Layout as (number of samples, rest angle [rad]) or (samples, None) for a rotation.
    theta : ndarray, shape (q,)
        Rotation angle on the sample grid of one period, first sample at t = 0 [rad].
    mask_nominal : ndarray of bool, shape (q,)
        True on the samples at rest (the rotation samples excluded).
    mask : ndarray of bool, shape (q,)
        True where the discrete θ̇ = 0 and θ̈ = 0 (periodic continuation): the
        mask :func:`accal.estimators.demod.rest_mask` finds on a log of this pattern.
    residuals : dict of str to float
        Normalised residuals of the eq. 16 conditions with ``mask``:
        ``sum_c = Σc/Σ|c|``, ``sum_ct = Σct/Σ|c||t|``, ``sum_ct2 = Σct²/Σ|c|t²``.
    residuals_nominal : dict of str to float
        The same with ``mask_nominal``.
    """

    kind: str
    tau: float
    tm: float
    fs: float
    segments: tuple[tuple[int, float | None], ...]
    theta: NDArray[np.float64]
    mask_nominal: NDArray[np.bool_]
    mask: NDArray[np.bool_]
    residuals: dict[str, float]
    residuals_nominal: dict[str, float]

    @property
    def q(self) -> int:
        """Samples per period ``τ·fs``."""
        return int(self.theta.size)

    @property
    def time(self) -> NDArray[np.float64]:
        """Sample times within the period, from 0 [s]."""
        return np.arange(self.q) / self.fs


def _smoothstep(u: NDArray[np.float64]) -> NDArray[np.float64]:
    # quintic: s(0)=0, s(1)=1, s' = s'' = 0 at both ends
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def rest_mask(
    theta: NDArray[np.float64], *, tol: float = 1e-9, settle: int = 0, periodic: bool = False
) -> NDArray[np.bool_]:
    """Samples at rest: discrete θ̇ = 0 and θ̈ = 0 within ``tol`` (section 4.2).

    ``θ̇_k = θ_k - θ_{k-1}`` and ``θ̈_k = θ_{k+1} - 2θ_k + θ_{k-1}``; a sample is
    at rest when both are within ``tol``.  Because θ̈ uses both neighbours, one
    sample next to each end of a rotation is masked in addition to the samples
    whose angle differs from the rest angle.

    Parameters
    ----------
    theta : ndarray, shape (n,)
        Rotation angle [rad].
    tol : float
        Tolerance on the first and second differences [rad].
    settle : int
        Extra samples masked after (and before) every rotation (settling margin).
    periodic : bool
        Treat ``theta`` as one period of a periodic signal (wrap the ends);
        otherwise the first and last samples use one-sided differences.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    th = np.asarray(theta, dtype=float)
    if periodic:
        prev, nxt = np.roll(th, 1), np.roll(th, -1)
    else:
        prev = np.concatenate([th[:1], th[:-1]])
        nxt = np.concatenate([th[1:], th[-1:]])
    d1 = th - prev
    d1n = nxt - th
    d2 = nxt - 2.0 * th + prev
    rest = (np.abs(d1) <= tol) & (np.abs(d2) <= tol) & (np.abs(d1n) <= tol)
    if settle > 0:
        moving = ~rest
        grown = moving.copy()
        for s in range(1, settle + 1):
            if periodic:
                grown |= np.roll(moving, s) | np.roll(moving, -s)
            else:
                grown[s:] |= moving[:-s]
                grown[:-s] |= moving[s:]
        rest = ~grown
    return rest


def condition_residuals(
    theta: NDArray[np.float64], mask: NDArray[np.bool_], fs: float = 1.0
) -> dict[str, float]:
    """Normalised residuals of the eq. 16 conditions on one period.

    Parameters
    ----------
    theta : ndarray, shape (q,)
        Angle over one period [rad].
    mask : ndarray of bool, shape (q,)
        Samples used.
    fs : float
        Sampling frequency [Hz].

    Returns
    -------
    dict
        ``sum_c``, ``sum_ct``, ``sum_ct2``: ``Σ c tʲ / Σ |c| |t|ʲ`` with
        ``c = cos θ · mask`` and ``t_k = (k - q/2)/fs``.
    """
    q = len(theta)
    c = np.cos(theta) * mask
    t = (np.arange(q) - q / 2) / fs
    out = {}
    for name, p in (("sum_c", 0), ("sum_ct", 1), ("sum_ct2", 2)):
        tp = t**p
        den = np.sum(np.abs(c * tp))
        out[name] = float(np.sum(c * tp) / den) if den > 0 else float("nan")
    return out


def _build(segments, q):
    theta = np.empty(q)
    nominal = np.zeros(q, bool)
    i = 0
    for n, ang in segments:
        if ang is not None:
            theta[i : i + n] = ang
            nominal[i : i + n] = True
        i += n
    i = 0
    for j, (n, ang) in enumerate(segments):
        if ang is None:
            a = segments[j - 1][1]
            b = segments[(j + 1) % len(segments)][1]
            u = np.arange(1, n + 1) / (n + 1)
            theta[i : i + n] = a + (b - a) * _smoothstep(u)
        i += n
    return theta, nominal


def _as_samples(x: float, fs: float, what: str) -> int:
    n = x * fs
    if abs(n - round(n)) > 1e-9 * max(1.0, abs(n)):
        raise ValidationError(f"{what}·fs = {n:g} samples is not an integer")
    return int(round(n))


def design_pattern(
    tau: float,
    tm: float,
    fs: float = 1.0,
    *,
    kind: str = "fig2",
    a: float | None = None,
) -> CalibrationPattern:
    """Design one period of a calibration pattern that rejects an affine bias.

    Parameters
    ----------
    tau : float
        Modulation period τ [s]; ``τ·fs`` must be an integer.
    tm : float
        Total rotation (masking) time per period TM [s]; split evenly between the
        rotations (four for ``"fig2"``, two for ``"fig1"``).
    fs : float
        Sampling frequency [Hz].
    kind : {"fig2", "fig1"}
        ``"fig2"``: ``+a | R | -b | R | +c | R | -b | R | +a`` (Fig. 2, rejects an affine
        bias with an affine signal model up to the reported ``Σct²`` residual).
        ``"fig1"``: ``+b/2 | R | -b | R | +b/2`` (Fig. 1(a) type, mean signal model).
    a : float, optional
        Length of the first rest at θ = 0 for ``"fig2"`` [s]; searched over integer
        sample counts to minimise ``|Σ c t²|`` (with the discrete mask) when omitted.

    Returns
    -------
    CalibrationPattern

    Raises
    ------
    ValidationError
        If the lengths are not whole, even splits on the sample grid.
    """
    check_option("kind", kind, ("fig2", "fig1"))
    q = _as_samples(tau, fs, "tau")
    m = _as_samples(tm, fs, "tm")
    if not 0 < m < q:
        raise ValidationError(f"tm must be in (0, tau), got tm = {tm} s for tau = {tau} s")
    nrot = 4 if kind == "fig2" else 2
    u = q - m
    if m % nrot or u % 4:
        raise ValidationError(
            f"{kind} needs tm·fs divisible by {nrot} and (tau - tm)·fs divisible by 4, got "
            f"tm·fs = {m} and (tau - tm)·fs = {u}"
        )
    r = m // nrot
    b = u // 4 if kind == "fig2" else u // 2
    if kind == "fig1":
        segs = ((b // 2, 0.0), (r, None), (b, np.pi), (r, None), (b // 2, 0.0))
        return _finish(kind, tau, tm, fs, segs, q)

    def segs_for(ai: int):
        return (
            (ai, 0.0),
            (r, None),
            (b, np.pi),
            (r, None),
            (2 * b - 2 * ai, 0.0),
            (r, None),
            (b, np.pi),
            (r, None),
            (ai, 0.0),
        )

    if a is not None:
        ai = _as_samples(a, fs, "a")
        if not 2 <= ai < b:
            raise ValidationError(f"a must be in [2/fs, (tau - tm)/4) s, got {a}")
        return _finish(kind, tau, tm, fs, segs_for(ai), q)
    best = None
    for ai in range(2, b):
        pat = _finish(kind, tau, tm, fs, segs_for(ai), q)
        score = abs(pat.residuals["sum_ct2"])
        if best is None or score < best[0]:
            best = (score, pat)
    if best is None:
        raise ValidationError(f"tau - tm = {tau - tm} s is too short for a fig2 pattern")
    return best[1]


def _finish(kind, tau, tm, fs, segs, q) -> CalibrationPattern:
    theta, nominal = _build(segs, q)
    mask = rest_mask(theta, periodic=True)
    return CalibrationPattern(
        kind=kind,
        tau=float(tau),
        tm=float(tm),
        fs=float(fs),
        segments=tuple((int(n), None if x is None else float(x)) for n, x in segs),
        theta=theta,
        mask_nominal=nominal,
        mask=mask,
        residuals=condition_residuals(theta, mask, fs),
        residuals_nominal=condition_residuals(theta, nominal, fs),
    )


def tile(pattern: CalibrationPattern, n_periods: int) -> tuple[NDArray, NDArray]:
    """Repeat a pattern: ``(time [s], theta [rad])`` for ``n_periods`` periods from t = 0."""
    theta = np.tile(pattern.theta, int(n_periods))
    return np.arange(theta.size) / pattern.fs, theta
