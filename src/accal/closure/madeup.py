"""Where a coupling's regressor is made up: its channel unknown at the lag it needs.

A coupling to channel ``x`` with lag ``L`` and a first-order low-pass ``τ`` needs, at a
sample ``t``, the channel over ``[t − L − 5τ, t − L]`` (5τ: the response's memory to
e⁻⁵ < 1 %).  Where that reaches a stretch the channel is unknown over (before its
first value, a hole, after its last), the regressor holds interpolated or held values:
such samples are made up (:mod:`accal.closure.unknownhistory` searches again without
them; :mod:`accal.closure.channelfault` marks a faulty stretch unknown).

A coupling to an angular acceleration with the firings of a THR1B file known
(``options["firings"]``) counts the firings as such stretches too
(:func:`firing_samples`): there each thruster moves the linear and the angular
accelerations at its own fixed ratio (its force and its torque), which is no lever
arm, and a coefficient fitted on them takes that ratio's share.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from accal.closure.candidates import SQUARED
from accal.closure.firings import FIRING_MAX_SHARE
from accal.closure.kinds import channel_class

if TYPE_CHECKING:  # annotations only
    from accal.closure.search import Found, Search

__all__ = ["coupling_firings", "firing_samples", "made_up", "unknown_stretches"]

#: A hole of more than this many steps between finite values is unknown (shorter
#: ones are interpolated).
HOLE_STEPS = 5


def unknown_stretches(
    t_all: NDArray[np.float64], x: NDArray[np.float64], step: float
) -> list[tuple[float, float]]:
    """The channel's unknown stretches ``(a, b)`` in its own time [s]: before its first
    finite value (``a = -inf``), each hole of more than :data:`HOLE_STEPS` steps
    between finite values (NaN, or a data gap), after its last (``b = +inf``); empty
    for a channel with no finite value."""
    known = np.isfinite(x) & np.isfinite(t_all)
    tk = np.unique(t_all[known])
    if tk.size == 0:
        return []
    gaps = np.flatnonzero(np.diff(tk) > HOLE_STEPS * step)
    return (
        [(-np.inf, float(tk[0]))]
        + [(float(tk[i]), float(tk[i + 1])) for i in gaps]
        + [(float(tk[-1]), np.inf)]
    )


def made_up(
    search: Search, f: Found, t_all: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], float] | None:
    """``(mask, lead)`` of the samples where coupling ``f``'s regressor is made up
    (module notes), None when there are none or ``f`` is not a coupling to an
    offered channel.

    A sample at ``t`` is made up where ``[t − L − 5τ, t − L]`` reaches an unknown
    stretch ``(a, b)`` (:func:`unknown_stretches`): ``a + L < t < b + L + 5τ``.  The
    record's start counts a lag of at most :data:`HOLE_STEPS` steps as none (``lead =
    L + 5τ``, or ``5τ``): the first ``lead`` seconds of the channel and the samples
    before its first value; after a hole the ``lead`` seconds from its end too.
    Within the record a hole's interior is made up whatever the lag (a stretch marked
    unknown by :mod:`accal.closure.channelfault`, a data gap: before 2026-11-29 only
    the ``lead`` seconds after a hole were left out, and a hole longer than the lag
    was interpolated).
    """
    if f.prop.name != "auxiliary":
        return None
    step = search.grid.step
    lag, tc = f.prop.path
    lead = (lag if lag > HOLE_STEPS * step else 0.0) + 5.0 * tc
    name = str(f.prop.channel).removesuffix(SQUARED)
    x = search.aux.get(name)
    if x is None:
        return None
    stretches = unknown_stretches(t_all, x, step)
    if not stretches:
        return None
    firing = firing_samples(search.options, name, t_all, lag, tc)
    eps = 1e-9
    mask = t_all < stretches[0][1] + lead - eps  # before the first value, the first lead s
    for a, b in stretches[1:-1]:
        mask |= (t_all > a + lag + eps) & (t_all < b + lag + 5.0 * tc - eps)
        mask |= (t_all >= b - eps) & (t_all < b + lead - eps)
    mask |= t_all > stretches[-1][0] + lag + eps
    if firing is not None:
        mask |= firing
    return (mask, lead) if mask.any() else None


def firing_samples(
    options: dict, channel: str, t_all: NDArray[np.float64], lag: float, tc: float
) -> NDArray[np.bool_] | None:
    """The samples whose regressor ``channel`` (lag ``lag``, low-pass ``tc`` [s]) takes
    from a known thruster firing (``options["firings"]``, the samples the firings
    reach), when ``channel`` is an angular acceleration and the firings take at most
    :data:`~accal.closure.firings.FIRING_MAX_SHARE` of the samples (beyond,
    :func:`accal.closure.firings.firing_test` reports the coupling); None otherwise.

    The firings themselves and every ``t`` with a firing in ``[t − lag − 5 tc, t −
    lag]``.  A 5 cm lever arm fitted on every sample of a day with 30 firings an hour
    of 4 thrusters came out 0.6-5 % off at 14-82σ, and a 2 mm one as 1.0-4.5 mm
    (``tests/closure/test_firing_coupling.py``).
    """
    firings = options.get("firings")
    if firings is None or channel_class(options, channel) != "angular":
        return None
    fm = np.asarray(firings, dtype=bool)
    if not fm.any() or fm.sum() > FIRING_MAX_SHARE * fm.size:
        return None
    tf = np.sort(t_all[fm])
    hi = np.searchsorted(tf, t_all - lag, side="right")
    lo = np.searchsorted(tf, t_all - lag - 5.0 * tc, side="left")
    return fm | (hi > lo)


def coupling_firings(search: Search, f: Found) -> NDArray[np.bool_] | None:
    """:func:`firing_samples` of coupling ``f`` (its channel, lag and low-pass); None for
    an effect that is not a coupling."""
    if f.prop.name != "auxiliary":
        return None
    lag, tc = f.prop.path
    name = str(f.prop.channel).removesuffix(SQUARED)
    return firing_samples(search.options, name, search.t_all, lag, tc)
