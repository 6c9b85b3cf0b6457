"""The transition of a bias step: local columns that let the data choose its shape.

A bias step in Level-1B data is not an edge: the processing's CRN filter low-passes
everything the instrument measured, so a step is a ramp over the filter's window
(GRACE: ~±17 s for accal's stand-in of the real filter, :mod:`accal.crn`; ±35 s for
seven 10 s boxcars; :data:`accal.closure.jumps.TRANSITION`).  Fitted as an edge
``1[t ≥ e]``, the ramp leaves a misfit ``m = ramp − edge`` that is odd about the
epoch, whose one-sided area is the ramp's first absolute moment ``A = E[X⁺]`` (≈ 3 s
times the size for seven 10 s boxcars).  The edge's least-squares weights jump at the
epoch, so they take ``A`` for part of the size: with the orbit template in the null
model the step's information comes from a few hundred samples around the epoch
(:mod:`accal.closure.multiplicity`), and 1e-8 m/s² steps came out 1-2 % small, 2-4 σ
(``make closure-detection``, ``tests.indep`` days; seed 7419: −9.820e-9 ± 4.2e-11
for −1e-8).  Leaving the samples within ±40 s out of the fit removes the bias
(−9.974e-9 ± 3.7e-11), but an exclusion changes the model's sample set.

Instead the step's model gets local columns (:func:`transition_columns`), zero far
from the epoch, whose span holds the misfit of the ramps a step may take: Gaussian
ramps ``Φ((t − c)/w) − 1[t ≥ e]`` of :data:`WIDTHS` and the epoch's Jacobian
``φ((t − c)/w)/w`` of :data:`SHIFTS` (``c`` half a sample before ``e``).  A ramp of
``k`` cascaded boxcars is near-Gaussian (central limit theorem), and a mixture of
centred Gaussian ramps of different widths plus the shift columns covers boxcar
cascades of 1 to 7 boxcars of 1-10 s shifted by up to ±4 s: the one-sided area of the
part of their misfit outside the span is at most 0.28 s (RMS 0.09 s) against up to
5.8 s without the columns (one of 90 shapes, computed when the widths were chosen).
The edge's coefficient is the size (the columns vanish away from the epoch) and its σ
includes what the columns cost.  The fitted columns are part of the step's
contribution, so the calibrated series loses the ramp, not only the edge.

Only for low-passed data: :func:`accal.closure.close_loop` adds the columns with
``options={"step_transition": True}``, which ``grace-bias`` sets for Level-1B files.
On a sharp step they take information for nothing: on a 600 s-block design (a step in
one block) its σ grew by 21 % (``tests/closure/test_block_base.py``'s day), and a
demodulation's per-block base never gets them.  Measured on ``tests/indep`` days with
steps through seven 10 s boxcars (40 days per size, library path as ``grace-bias``):
1e-8 m/s² steps' z RMS 1.26 → 0.86 (signed mean −0.28 → +0.04), 3e-9 m/s² 1.31 → 1.23
(those are mostly found by :mod:`accal.closure.jumps`, whose size is its own); on
white-noise days with a 1e-8 m/s² ramp (``tests/closure/test_step_transition.py``)
z −4.7, −2.9, −5.5 → 0.7, 1.7, 0.8: at ~1,400σ the span's approximation shows.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

__all__ = ["SHIFTS", "WIDTHS", "transition_columns"]

#: Widths [s] (Gaussian σ) of the centred ramps whose misfit to an edge is in the span.
WIDTHS = (2.0, 4.0, 7.0, 11.0)
#: Widths [s] of the Gaussian bumps (the Jacobian of a ramp's epoch) in the span.
SHIFTS = (3.0, 6.0)


def transition_columns(
    t: NDArray[np.float64], epoch: float, dt: float
) -> list[tuple[str, NDArray[np.float64]]]:
    """The local columns of a step's transition at ``epoch`` on times ``t``.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times [s].
    epoch : float
        The step's epoch [s]: its first sample after the step (the edge ``1[t ≥ epoch]``).
    dt : float
        Sampling step [s]: widths under half a step are left out (at a coarse sampling
        the narrow ramps are the edge itself).

    Returns
    -------
    list of (str, ndarray of shape (n, 1))
        ``("transition_w<width>", Φ((t − c)/w) − 1[t ≥ epoch])`` and
        ``("transition_shift<width>", φ((t − c)/w)/w)`` with ``c = epoch − dt/2``
        (module notes); values under 1e-12 are set to zero, so each column is local.
    """
    t = np.asarray(t, dtype=np.float64)
    c = float(epoch) - 0.5 * dt
    edge = (t >= epoch).astype(np.float64)
    out = []
    for w in WIDTHS:
        if w >= 0.5 * dt:
            col = ndtr((t - c) / w) - edge
            col[np.abs(col) < 1e-12] = 0.0
            out.append((f"transition_w{w:g}", col[:, None]))
    for w in SHIFTS:
        if w >= 0.5 * dt:
            col = np.exp(-0.5 * ((t - c) / w) ** 2) / (np.sqrt(2.0 * np.pi) * w)
            col[np.abs(col) < 1e-12] = 0.0
            out.append((f"transition_shift{w:g}", col[:, None]))
    return out
