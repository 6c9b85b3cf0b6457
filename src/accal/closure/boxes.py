"""Two bias steps that make a box: a transient of the data, not two bias changes.

A bias step is one lasting level change of the instrument.  A level that goes up and
comes back down within the hour is something else: a manoeuvre's constant thrust, a
transient of the spacecraft, a burst of the noise.  The least-squares step search
takes it as two steps (binary segmentation), and each is significant; removing them
removes the transient from the calibrated series.  QA (2026-11-29): a 10-minute,
3e-7 m/s² along-track manoeuvre on one axis was removed as steps of +3.15e-7 and
−3.02e-7 m/s² 608 s apart, the calibrated x series' error RMS 1.1e-9 → 2.6e-8 m/s²
(the edge scan of :mod:`accal.closure.jumps` had rejected both edges as a box).

:func:`box_reasons`: among the bias steps of the final model, two of opposite signs
within :data:`BOX_MAX` s whose smaller size is at least :data:`BOX_SHARE` of the
larger are a box; both are reported, not removed (the same rule as the edge scan's
neighbouring edge, :data:`accal.closure.jumpchecks.RECUR_SHARE`).  Steps with one size per
data channel (a demodulation's two axes) are left to their own checks.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BOX_MAX",
    "BOX_SHARE",
    "UNDO_WINDOW",
    "box_reasons",
    "give_back",
    "reject_boxes",
    "step_sizes",
    "undone_jumps",
]

#: Longest box [s]: a level that returns within it did not change.
BOX_MAX = 3600.0
#: Least ratio of the smaller to the larger size of a box's two steps.
BOX_SHARE = 0.5
#: Largest distance [s] between an edge-scan jump and a least-squares step of the
#: opposite sign that gives it back (twice the transition left out of the jump's test).
UNDO_WINDOW = 80.0


def step_sizes(props, gamma: NDArray[np.float64]) -> list[tuple[float, float, int]]:
    """``(epoch, size, i)`` of every single-channel bias step among ``props`` (the
    final model's proposals in order, ``gamma`` their fitted coefficients, column by
    column); ``i`` indexes ``props``."""
    out = []
    k = 0
    for i, p in enumerate(props):
        cols = [j for j, lab in enumerate(p.labels) if lab.startswith("step@")]
        if p.name == "bias_step" and len(cols) == 1 and np.isfinite(gamma[k + cols[0]]):
            out.append((float(p.params["epoch"]), float(gamma[k + cols[0]]), i))
        k += p.columns.shape[1]
    return out


def box_reasons(steps: list[tuple[float, float, int]]) -> dict[int, str]:
    """``{i: reason}`` for the steps (:func:`step_sizes`) that make boxes (module notes)."""
    out: dict[int, str] = {}
    for (ea, sa, ia), (eb, sb, ib) in itertools.combinations(sorted(steps), 2):
        if eb - ea > BOX_MAX or sa * sb >= 0:
            continue
        if min(abs(sa), abs(sb)) < BOX_SHARE * max(abs(sa), abs(sb)):
            continue
        for i, other, size in ((ia, eb, sb), (ib, ea, sa)):
            out.setdefault(
                i,
                f"not a bias step: with the step of {size:.3g} m/s² {other - (ea if i == ia else eb):+.0f} s "
                "away the level comes back (a box: a transient of the data, e.g. a "
                "manoeuvre, not a lasting change of the instrument)",
            )
    return out


def reject_boxes(search, final, fit) -> None:
    """Move the bias steps of ``search``'s final model (``final``: its effects in
    order, ``fit``: their fit, as :func:`accal.closure.select` makes them) that make
    boxes (:func:`box_reasons`) from ``search.found`` to ``search.rejected``."""
    steps = step_sizes([f.prop for f in final], fit.gamma)
    why = box_reasons(steps)
    size = {i: s for _, s, i in steps}
    for i in sorted(why, reverse=True):
        _reject(search, i, why[i], coefficient=size[i])


def _reject(search, i: int, reason: str, **verdict) -> None:
    """Move ``search.found[i]`` to ``search.rejected`` with ``reason``."""
    f = search.found.pop(i)
    v = dataclasses.replace(f.verdict, ok=False, reason=reason, **verdict)
    search.rejected.append(dataclasses.replace(f, verdict=v))


def undone_jumps(final, fit, jumps) -> dict[int, tuple[int, str]]:
    """``{i: (k, reason)}``: the bias steps ``i`` of the final model (``final``, ``fit``
    as for :func:`reject_boxes`) that give back the edge-scan jump ``k`` of ``jumps``
    (:class:`accal.closure.jumps.Jump`, taken out of the data before the search).

    A least-squares step within :data:`UNDO_WINDOW` s of a jump, of the opposite sign
    and at least :data:`BOX_SHARE` of its size, puts the level the jump took out back:
    together they are a box of no width, and neither is a bias change.  A QA day
    (2026-11-29, an outside generator): a −4.19e-9 m/s² jump and a +3.90e-9 step at the
    same epoch, two orbits after a real 2e-8 step, were both removed (net −2.8e-10).
    """
    out: dict[int, tuple[int, str]] = {}
    taken: set[int] = set()
    for epoch, size, i in step_sizes([f.prop for f in final], fit.gamma):
        for k, j in enumerate(jumps):
            if k in taken or abs(epoch - j.epoch) > UNDO_WINDOW or size * j.size >= 0:
                continue
            if min(abs(size), abs(j.size)) < BOX_SHARE * max(abs(size), abs(j.size)):
                continue
            taken.add(k)
            out[i] = (
                k,
                f"not a bias step: it gives back the edge-scan jump of {j.size:.3g} m/s² "
                f"{j.epoch - epoch:+.0f} s away (a box of no width: neither is a bias change)",
            )
            break
    return out


def give_back(search, final, fit, jumps) -> tuple:
    """The jumps ``jumps`` less those a bias step of the final model gives back
    (:func:`undone_jumps`); those steps are moved from ``search.found`` to
    ``search.rejected``, and each jump dropped gets a note (it goes back into the data,
    the caller's)."""
    undo = undone_jumps(final, fit, jumps)
    drop = {k for k, _ in undo.values()}
    for i in sorted(undo, reverse=True):
        _reject(search, i, undo[i][1])
    for k in sorted(drop):
        j = jumps[k]
        search.note(
            "bias_step",
            None,
            f"a jump of {j.size:.3g} ± {j.sigma:.2g} m/s² at {j.epoch:.1f} s was not "
            "removed: a least-squares step of the search at its epoch gave it back",
        )
    return tuple(j for k, j in enumerate(jumps) if k not in drop)
