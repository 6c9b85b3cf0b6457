"""A jump of one axis that is a change of the signal on the other axes too.

An instrument's bias step is on its own axis.  A change of the signal faster than the
orbit template can follow (a storm's onset: the density jumps and the cross-track and
radial drag, a few per cent of the along-track, jump with it) is on every axis.  So a
bias step, found by the jump test of :mod:`accal.closure.jumps` or by the search's
least-squares scan, is reported and not removed when another axis (the *signal
proxies* of :func:`accal.closure.select.close_loop`) has an edge of its own within
±:data:`WINDOW` s of its epoch, significant at :data:`LEVEL` over the epochs and axes
looked at, and at least :data:`RATIO_MIN` of the step's size
(:meth:`OtherAxes.seen`).

The search's test with the other axes' series in the model
(:func:`accal.closure.validation.signal_proxy_test`, one free coefficient each for
the whole record) misses such a change when those series are noisy: the coefficient
is attenuated by their own noise (errors in variables).  At an abrupt onset a 1.8e-8
m/s² along-track "step" kept 6.2σ of its 66σ given the other axes
(``tests/closure/test_signal_proxies.py``), while those axes had edges there of 7e-10
and 2.4e-10 m/s², many σ of their own noise.  Counting the proxies' noise in that
test (the PSD of the residual with them fitted) made real 1e-8 m/s² along-track
steps insignificant on 2 of 4 ``tests/indep`` days without explaining them: their
size given the proxies was unchanged.

:data:`RATIO_MIN` keeps an instrument's step from being taken for the signal through
its cross-talk into a quieter axis (GRACE's cross-track axis is ten times quieter
than the along-track one; cross-talk and misalignment are ~1e-3 of the step).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from accal.closure.edgekernel import TRANSITION, edge_measure
from accal.closure.noise_psd import Grid

__all__ = ["LEVEL", "RATIO_MIN", "WINDOW", "OtherAxes"]

#: Half-width [s] of the search for another axis' edge around a jump's epoch (the
#: Level-1B filter's transition, within which the jump's own epoch is placed).
WINDOW = TRANSITION
#: Family-wise level of that search (each axis, each epoch of the window).
LEVEL = 1e-3
#: Least size of another axis' edge, as a share of the jump's (1-3 % for drag; a
#: quarter of the smallest).
RATIO_MIN = 3e-3


class OtherAxes:
    """The other axes of a null model, measured for edges.

    Parameters
    ----------
    grid : Grid
        Placement of the used samples.
    t : ndarray, shape (n,)
        Times of the used samples [s].
    basis : Basis
        The null model (its residual of each other axis is measured).
    lev : ndarray
        Its leverage spectrum.
    proxies : ndarray, shape (n, q)
        The other axes on the used samples [m/s²].
    """

    def __init__(self, grid: Grid, t, basis: Any, lev: NDArray, proxies: NDArray) -> None:
        self.grid, self.t, self.basis, self.lev = grid, t, basis, lev
        self.proxies = np.asarray(proxies, dtype=np.float64).reshape(t.size, -1)
        self._measures: list | None = None

    def seen(self, epoch: float, size: float, names: tuple[str, ...] = ()) -> str | None:
        """Why a jump of ``size`` at ``epoch`` [s] is seen on the other axes (None when
        it is not).

        Each other axis' residual of the same null model is measured at its best edge
        within ±:data:`WINDOW` s by the kernel of its own PSD
        (:func:`accal.closure.edgekernel.edge_measure`: the edge of the residual as it
        is); an edge significant at :data:`LEVEL` (two-sided, Bonferroni over the
        window's epochs and the axes) of :data:`RATIO_MIN` of ``size`` or more is the
        signal's.
        """
        if self._measures is None:
            self._measures = []
            for p in self.proxies.T:
                res = p - self.basis.project(p)
                self._measures.append(edge_measure(self.grid, self.t, res, self.lev, WINDOW))
        n_look = (2 * int(round(WINDOW / self.grid.step)) + 1) * len(self._measures)
        for k, measure in enumerate(self._measures):
            ok, z, s = measure(np.array([epoch]))
            if not ok[0]:
                continue
            log_p = np.log(2.0) + log_ndtr(-abs(float(z[0]))) + np.log(n_look)
            if log_p < np.log(LEVEL) and abs(float(s[0])) >= RATIO_MIN * abs(size):
                name = names[k] if k < len(names) else f"axis {k + 1}"
                return (
                    f"not identifiable: the other axis {name} has an edge of "
                    f"{float(s[0]):.3g} m/s² ({abs(float(z[0])):.0f}σ) at the same time: a "
                    "change of the signal on every axis, not a bias step of this one"
                )
        return None
