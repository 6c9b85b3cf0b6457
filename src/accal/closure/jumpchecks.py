"""The checks of a significant edge that say it is not a lone bias jump.

:func:`accal.closure.jumps.scan_jumps` finds edges by the spectrum-weighted step test;
before it takes one for a bias jump it asks these (module notes of
:mod:`accal.closure.jumps`): is it an image of an accepted jump (:func:`image`) or of a
larger edge left in the data (:func:`image_of_rejected`) through the orbit template,
does the same edge recur an orbit away (:func:`recurrence`), does a second edge close
by make it a box (:func:`neighbour`).  The other edges are judged on the residual with
the jump's transition bridged (:func:`bridged`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from accal.closure.edgekernel import TRANSITION, edge_sizes, top_epochs

if TYPE_CHECKING:
    from accal.closure.jumps import Jump

__all__ = [
    "BRIDGE",
    "IMAGE_WINDOW",
    "NEIGHBOURS",
    "RECUR_ORBITS",
    "RECUR_SHARE",
    "RECUR_WINDOW",
    "RECUR_Z",
    "bridged",
    "image",
    "image_of_rejected",
    "neighbour",
    "recurrence",
]


#: Orbits either side where a jump is looked for again, and the search window there [s].
RECUR_ORBITS = (-2, -1, 1, 2)
RECUR_WINDOW = 30.0
#: Half-width [s] of the window at the same orbital phase in which a jump no larger than
#: an accepted one is its image in the orbit template (:func:`image`): three times
#: the transition left out.
IMAGE_WINDOW = 3.0 * TRANSITION
#: A jump there of this share of the size (same sign) at :data:`RECUR_Z` σ is a recurrence.
RECUR_SHARE = 0.5
RECUR_Z = 4.0


def image(jumps: list[Jump], epoch: float, size: float, period: float | None) -> str | None:
    """Why a jump at ``epoch`` is an image of an accepted one (None when it is not).

    A jump of the same sign, no larger, within ±:data:`IMAGE_WINDOW` s of the same
    orbital phase one or two orbits from an accepted jump: the orbit template fitted with that step in
    the data holds part of its edge at that phase in every orbit, and the scan, which
    takes the accepted jumps out one at a time, can see it there (a red test day with
    steps of 3e-9 m/s² at 7000, 16500 and 27100 s: "jumps" of 2.8e-9 and 2.2e-9 at
    10898 and 5298 s, one and two orbits before the largest, were removed as well,
    ``tests/closure/test_jumps.py``).  :func:`recurrence` looks for the other edge in
    the residual, from which an accepted jump is gone.  The image is a weak edge, and
    the scan places it less well than a step: with numpy 2.4.6 / scipy 1.17.1 the same
    day's image one orbit before the 16,500 s step came out at 10,819 s (1.68e-9 m/s²,
    its epoch interval 10,819-10,865 s), 80 s from that orbital phase.
    """
    if not period or period <= 0:
        return None
    for j in jumps:
        if np.sign(j.size) != np.sign(size):
            continue
        if abs(size) > abs(j.size):
            continue
        for k in RECUR_ORBITS:
            if abs(epoch - (j.epoch + k * period)) <= IMAGE_WINDOW:
                return (
                    f"the jump at {j.epoch:.0f} s ({j.size:.3g} m/s²) is {k:+d} orbit(s) "
                    "away at the same orbital phase: its image in the orbit signal's "
                    "model, or an edge of that signal, not a second bias step"
                )
    return None


def image_of_rejected(grid, t, basis, k0, psd, pos, e, size, rejected) -> str | None:
    """Why the jump at grid epoch ``e`` is the image of a larger edge left in the data
    (None when it is not).

    A significant edge that was not taken out (``rejected``: not a lone or persistent
    step) stays in the residual, and the orbit template fitted with it in holds part
    of it at the same phase in other orbits: the kernel at ``e``, with the template
    projected out of it, responds to that edge ``j`` by ``s_j`` times its response to
    a unit step at ``e_j`` (exact, the edge's own column through the same weights).
    When that response carries :data:`RECUR_SHARE` of the jump's size or more, with
    its sign, the jump is the other edge's image.  QA (2026-11-29, boxcar-filtered
    data, AR(1) and random-walk noise): a real 3.2e-9 m/s² step beside an eclipse
    edge failed the persistence test, and a −9.8e-10 m/s² "step" three orbits later,
    at its phase, was removed; on the same day without the step there is nothing.
    """
    for j in rejected:
        sj = float(j.get("size", 0.0))
        if not np.isfinite(sj) or abs(sj) <= abs(size):
            continue
        col = sj * (t >= float(j["epoch"])).astype(np.float64)
        _, img, _ = edge_sizes(grid, col, basis, k0, psd, np.array([e], dtype=np.int64), pos)
        if img[0] * size > 0 and abs(img[0]) >= RECUR_SHARE * abs(size):
            return (
                f"the edge of {sj:.3g} m/s² at {float(j['epoch']):.0f} s, not taken out, "
                f"puts {img[0]:.3g} m/s² here through the orbit template: its image, not "
                "a bias step"
            )
    return None


def neighbour(grid, t, r, basis, k0, psd, pos, score, ok, e, size, m) -> str | None:
    """Why the jump at grid epoch ``e`` is not a lone edge (None when it is).

    A bias step is one level change.  A box or a burst of the residual longer than the
    transition left out comes with a second one nearby (boxes an eclipse penumbra
    leaves where the orbit template does not follow it: `tests.indep` day seed 31,
    cross-track, 1.0e-9 m/s² edges 40 s apart).  Within ±``m`` samples (the neighbour
    window), beyond twice the transition (kernels there see the same change), there
    must be no other (the :data:`NEIGHBOURS` best ranked, at least two samples apart)
    of :data:`RECUR_SHARE` of its size or more at :data:`RECUR_Z` σ.
    """
    a, b = max(e - m, 0), min(e + m + 1, grid.size)
    s = np.where(ok[a:b], score[a:b], -1.0)
    # kernels whose left-out transition is near this one see the same step
    near = 2 * max(1, int(round(TRANSITION / grid.step))) + 2
    s[max(e - near - a, 0) : e + near + 1 - a] = -1.0
    picks = a + top_epochs(s, NEIGHBOURS, 2)
    if picks.size == 0:
        return None
    z, sz, _ = edge_sizes(grid, r, basis, k0, psd, picks, pos, project=False)
    for zk, sk, ek in zip(z, sz, picks, strict=True):
        if abs(sk) >= RECUR_SHARE * abs(size) and abs(zk) >= RECUR_Z:
            return (
                f"another edge of {sk:.3g} m/s² ({abs(zk):.0f}σ) {(ek - e) * grid.step:+.0f} s "
                "away: a box, burst or ramp of the residual, not a bias step"
            )
    return None


#: Edges looked at around a jump by :func:`neighbour` (4 missed the other edge of a 52 s
#: box of ±1.6e-10 m/s², cross-track, C/D day seed 2003).
NEIGHBOURS = 16


def recurrence(grid, t, r, basis, k0, psd, pos, score, ok, e, size, period) -> str | None:
    """Why the jump at grid epoch ``e`` is the signal's (None when it is not).

    An eclipse edge that the orbit template does not follow exactly leaves a sharp
    edge at nearly the same orbital phase in every orbit (a 40 s penumbra on the
    cross-track axis: edges of ±5e-10 m/s² with a kernel σ of 2e-11 on `tests.indep`
    days, one per orbit).  A bias jump happens once: within ±:data:`RECUR_WINDOW` s
    of the same phase one and two orbits away there must be no jump of the same sign
    and at least :data:`RECUR_SHARE` of its size at :data:`RECUR_Z` σ.
    """
    if not period or period <= 0:
        return None
    w = max(int(round(RECUR_WINDOW / grid.step)), 1)
    picks = []
    for k in RECUR_ORBITS:
        c = e + int(round(k * period / grid.step))
        a, b = max(c - w, 0), min(c + w + 1, grid.size)
        if b <= a:
            continue
        s = np.where(ok[a:b], score[a:b], -1.0)
        if s.max() < 0:
            continue
        picks.append(a + int(np.argmax(s)))
    if not picks:
        return None
    z, sz, _ = edge_sizes(
        grid, r, basis, k0, psd, np.array(picks, dtype=np.int64), pos, project=False
    )
    for zk, sk, ek in zip(z, sz, picks, strict=True):
        if (
            np.sign(sk) == np.sign(size)
            and abs(sk) >= RECUR_SHARE * abs(size)
            and abs(zk) >= RECUR_Z
        ):
            dt = (ek - e) * grid.step
            return (
                f"a jump of {sk:.3g} m/s² ({abs(zk):.0f}σ) {dt:+.0f} s away, at the same "
                "orbital phase: an edge of the orbit signal, not a bias step"
            )
    return None


#: Width [s] of the stretches either side of a jump's transition whose means bridge it
#: (:func:`bridged`).
BRIDGE = 10.0


def bridged(t: NDArray[np.float64], r: NDArray[np.float64], epoch: float) -> NDArray[np.float64]:
    """``r`` with the samples within ±:data:`TRANSITION` s of ``epoch`` replaced by the
    line between the means of the :data:`BRIDGE` s either side (unchanged when a side
    has none).

    A jump is taken out as a sharp step; in low-passed data it is a ramp, and what is
    left of it within its transition (left out of its own test) is a lump of up to half
    its size.  The kernels of a red residual respond to that lump from beyond the
    transition: on a QA day (boxcar-filtered data, AR(1) and random-walk noise) a real
    3e-9 m/s² step left −1.55e-9 m/s² right after its midpoint, and an "edge" of
    −1.63e-9 m/s² (7σ) 83 s away made it a box; on the same day without the step
    nothing is there.  The other edges are judged on the residual without that lump.
    """
    before = (t >= epoch - TRANSITION - BRIDGE) & (t < epoch - TRANSITION)
    after = (t > epoch + TRANSITION) & (t <= epoch + TRANSITION + BRIDGE)
    inside = np.abs(t - epoch) <= TRANSITION
    if not before.any() or not after.any() or not inside.any():
        return r
    t0, t1 = epoch - TRANSITION - 0.5 * BRIDGE, epoch + TRANSITION + 0.5 * BRIDGE
    r0, r1 = float(np.mean(r[before])), float(np.mean(r[after]))
    out = r.copy()
    out[inside] = r0 + (r1 - r0) * (t[inside] - t0) / (t1 - t0)
    return out
