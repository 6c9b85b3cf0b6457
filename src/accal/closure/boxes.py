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
neighbouring edge, :data:`accal.closure.jumps.RECUR_SHARE`).  Steps with one size per
data channel (a demodulation's two axes) are left to their own checks.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from numpy.typing import NDArray

__all__ = ["BOX_MAX", "BOX_SHARE", "box_reasons", "reject_boxes", "step_sizes"]

#: Longest box [s]: a level that returns within it did not change.
BOX_MAX = 3600.0
#: Least ratio of the smaller to the larger size of a box's two steps.
BOX_SHARE = 0.5


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
        f = search.found.pop(i)
        verdict = dataclasses.replace(f.verdict, ok=False, reason=why[i], coefficient=size[i])
        search.rejected.append(dataclasses.replace(f, verdict=verdict))
