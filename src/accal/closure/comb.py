"""Bias jumps that recur at a common period: one periodic effect, not several steps.

A sawtooth (a level that ramps and resets, e.g. a periodically re-centred proof mass
or a heater's switching cycle) has sharp edges of one sign and one size, a period
apart, and between them ramps.  Each edge alone passes every test of a lone bias jump
(:mod:`accal.closure.jumps`): it is persistent and has no second edge nearby.  Taking
the edges out as bias steps leaves the ramps: their sum is a trend over the record,
which the base's drift then takes (``tests/indep`` days with a 1e-9 m/s² sawtooth of
period 6380 s: 5 steps removed, the drift moved by 5.2σ, its error from 0.3σ to 5.4σ).
A bias step happens at one epoch; steps at ``e₀ + kP`` for every ``k`` are a periodic
effect, which closure reports and does not remove.

The test (:func:`find_comb`): for every pair of accepted jumps of one sign whose sizes
agree, and every period ``P = |e_j − e_i| / m`` (``m`` up to :data:`MAX_DIVISOR`, ``P``
at least :data:`MIN_PERIOD` s and at most half the record), the comb ``e_i + kP`` is
laid over the record.  Its teeth that hold no accepted jump are measured (the caller's
``measure``: the jump kernel's z at the best-ranked epoch within ±:data:`WINDOW` s of
each tooth, on the residual the jumps are out of).  Without an edge at a tooth that z
has mean zero and a variance ``v`` near one (the best of a window's epochs is a little
larger than one epoch's, but not signed); ``v`` is measured on the same residual at
:data:`N_CONTROL` epochs spread over the record (at least one).  The comb is the
data's when the teeth's z turned to the jumps' sign have a sum ``Σ s_k / √(n v)``
beyond the one-sided normal quantile of :data:`LEVEL`, with at least
:data:`SIGN_SHARE` of at least :data:`MIN_TEETH` teeth of the jumps' sign.  A t-test,
which estimates ``v`` from the teeth themselves, had no power with three teeth (z 3.3,
4.3 and 3.5: p = 0.003).  Per-tooth thresholds do not work either: a sawtooth whose
period is near the orbit's is mostly followed by the orbit template, and its teeth in
the residual are 0.2-0.45 of the jumps' size, at z 2-5 (``tests/indep`` seed 7201,
period 5112 s: all 14 teeth of the jumps' sign).  Two real, unrelated steps predict
teeth where the residual's edges have either sign.

Only the jump test's jumps are checked: the least-squares step scan of the search did
not take a sawtooth's resets for steps on any of the days tried (``tests/indep``
sawtooth days, 48; ``tests/closure/test_jumps.py``'s red days, 12).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

__all__ = [
    "LEVEL",
    "MAX_DIVISOR",
    "MEMBER",
    "MIN_PERIOD",
    "MIN_TEETH",
    "N_CONTROL",
    "SIGN_SHARE",
    "WINDOW",
    "Comb",
    "find_comb",
]

#: Divisors ``m`` of a pair's spacing tried as the comb's period (teeth skipped between
#: two accepted jumps: a search caps the jumps it accepts, 5 in :mod:`~accal.closure.jumps`).
MAX_DIVISOR = 4
#: Shortest period [s] considered: three jump-test windows (±:data:`~accal.closure.jumps.WIDE` s).
MIN_PERIOD = 720.0
#: Half-width [s] around a tooth within which an edge is looked for (the jumps' own
#: epoch tolerance, as for a recurrence one orbit away in :mod:`~accal.closure.jumps`).
WINDOW = 30.0
#: Half-width [s] around a tooth within which an accepted jump is on it: a jump's epoch
#: is placed within its ±40 s transition, and the teeth far from the pair that laid the
#: comb are predicted to tens of seconds (a reset of a 4100 s sawtooth came out as a
#: jump 60 s after its tooth: ``tests/closure/test_jumps.py``, seed 14).
MEMBER = 90.0
#: One-sided level of the test of the teeth's signed z (per pair and period tried: at
#: most 40 with 5 jumps).
LEVEL = 1e-4
#: Epochs at which the measure's z is taken for its variance without an edge.
N_CONTROL = 64
#: Least number of teeth measured, and least share of them with the jumps' sign.
MIN_TEETH = 3
SIGN_SHARE = 0.75
#: Largest difference of two jumps' sizes, in σ of the difference, for one comb.
SIZE_AGREE = 3.0


@dataclass(frozen=True)
class Comb:
    """Jumps that recur with one period (:func:`find_comb`).

    Attributes
    ----------
    period : float
        Spacing of the teeth [s].
    anchor : float
        Epoch of one of its jumps [s]: the teeth are ``anchor + k·period``.
    members : tuple of int
        Indices of the accepted jumps on the comb.
    size : float
        Their σ-weighted mean size [m/s²].
    n_checked, n_confirmed : int
        Other teeth measured, and those with an edge of the jumps' sign.
    p_value : float
        One-sided p-value of their signed z.
    """

    period: float
    anchor: float
    members: tuple[int, ...]
    size: float
    n_checked: int
    n_confirmed: int
    p_value: float

    def teeth(self, t0: float, t1: float) -> NDArray[np.float64]:
        """Its teeth within ``[t0, t1]`` [s]."""
        return _teeth(self.anchor, self.period, t0, t1)

    def reason(self) -> str:
        """Why its jumps are not removed (the note of each)."""
        return (
            f"one of {len(self.members)} jumps of ~{self.size:.3g} m/s² on a comb of period "
            f"{self.period:.0f} s, whose other teeth hold edges of the same sign ({self.n_confirmed} "
            f"of {self.n_checked}, p = {self.p_value:.2g}): a periodic effect (e.g. a "
            "sawtooth), not bias steps"
        )


def find_comb(
    epochs: NDArray[np.float64],
    sizes: NDArray[np.float64],
    sigmas: NDArray[np.float64],
    span: tuple[float, float],
    measure: Callable[[NDArray[np.float64]], tuple[NDArray, NDArray, NDArray]],
) -> Comb | None:
    """The comb of recurring jumps among accepted ones (None when there is none).

    Parameters
    ----------
    epochs, sizes, sigmas : ndarray, shape (k,)
        The accepted jumps [s, m/s², m/s²].
    span : (float, float)
        Times of the first and last samples [s].
    measure : callable
        ``measure(times) -> (ok, z, size)`` for teeth at ``times`` [s]: whether each
        could be measured (scannable), and the edge's z and size there (the size is
        not used).

    Returns
    -------
    Comb or None
        The comb with the most members (ties: the smallest p).
    """
    epochs = np.asarray(epochs, dtype=np.float64)
    sizes = np.asarray(sizes, dtype=np.float64)
    sigmas = np.asarray(sigmas, dtype=np.float64)
    t0, t1 = span
    ok_c, z_c, _ = measure(t0 + (np.arange(N_CONTROL) + 0.5) * (t1 - t0) / N_CONTROL)
    var = max(float(np.mean(z_c[ok_c] ** 2)), 1.0) if ok_c.any() else 1.0
    best: Comb | None = None
    for i, j in _pairs(sizes, sigmas):
        for m in range(1, MAX_DIVISOR + 1):
            period = abs(epochs[j] - epochs[i]) / m
            if period < MIN_PERIOD:
                break
            if period > 0.5 * (t1 - t0):
                continue
            comb = _laid(epochs, sizes, sigmas, i, period, (t0, t1), measure, var)
            if comb is not None and (best is None or _better(comb, best)):
                best = comb
    return best


def _pairs(sizes: NDArray, sigmas: NDArray) -> list[tuple[int, int]]:
    """Pairs of jumps of one sign whose sizes agree within :data:`SIZE_AGREE` σ."""
    out = []
    for i in range(sizes.size):
        for j in range(i + 1, sizes.size):
            if np.sign(sizes[i]) != np.sign(sizes[j]):
                continue
            if abs(sizes[i] - sizes[j]) <= SIZE_AGREE * np.hypot(sigmas[i], sigmas[j]):
                out.append((i, j))
    return out


def _laid(epochs, sizes, sigmas, i, period, span, measure, var) -> Comb | None:
    """The comb through jump ``i`` with ``period``, when the data confirm it (``var``:
    the measure's z variance without an edge)."""
    teeth = _teeth(float(epochs[i]), period, *span)
    sign = np.sign(sizes[i])
    dist = np.abs(epochs[:, None] - teeth[None, :])
    on = (dist.min(axis=1) <= MEMBER) & (np.sign(sizes) == sign)
    members = np.flatnonzero(on)
    if members.size < 2:
        return None
    w = 1.0 / sigmas[members] ** 2
    mean = float(np.sum(w * sizes[members]) / np.sum(w))
    free = teeth[dist[members].min(axis=0) > MEMBER]
    if free.size == 0:
        return None
    ok, z, _ = measure(free)
    signed = sign * z[ok]
    n_checked = int(signed.size)
    if n_checked < MIN_TEETH:
        return None
    n_conf = int(np.count_nonzero(signed > 0))
    if n_conf < SIGN_SHARE * n_checked:
        return None
    p = float(ndtr(-np.sum(signed) / np.sqrt(n_checked * var)))
    if not p <= LEVEL:
        return None
    members_t = tuple(int(m) for m in members)
    return Comb(float(period), float(epochs[i]), members_t, mean, n_checked, n_conf, p)


def _teeth(anchor: float, period: float, t0: float, t1: float) -> NDArray[np.float64]:
    """``anchor + k·period`` within ``[t0, t1]`` [s]."""
    k0 = np.ceil((t0 - anchor) / period)
    k1 = np.floor((t1 - anchor) / period)
    return anchor + np.arange(k0, k1 + 1) * period


def _better(a: Comb, b: Comb) -> bool:
    """More members, then the smaller p (a comb of half the period holds the true teeth
    and as many between them, at which the data say nothing)."""
    return (len(a.members), -a.p_value) > (len(b.members), -b.p_value)
