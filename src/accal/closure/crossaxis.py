"""A jump of one axis that is a change of the signal on the other axes too.

An instrument's bias step is on its own axis.  A change of the signal faster than the
orbit template can follow (a storm's onset: the density jumps and the cross-track and
radial drag, a few per cent of the along-track, jump with it) is on every axis.  The
jump test of :mod:`accal.closure.jumps` asks the other axes (the *signal proxies* of
:func:`accal.closure.select.close_loop`) in two ways, and a jump that fails either is
reported, not removed:

1. **Explained by them** (:meth:`OtherAxes.explains`): measured again with the other
   axes' series in the null model (one free coefficient each, pinned by the whole
   record), as :func:`accal.closure.validation.signal_proxy_test` does for the
   search's candidates, it is no longer significant at the scan's level.
2. **Seen on them** (:meth:`OtherAxes.seen`): another axis has an edge of its own
   within ±:data:`WINDOW` s of the epoch, significant at :data:`LEVEL` over the epochs
   and axes looked at, and at least :data:`RATIO_MIN` of the jump's size.  The first
   check alone misses a change whose proxies are noisy: one coefficient for the whole
   day is attenuated by the proxy's own noise (errors in variables), and a 1.8e-8 m/s²
   along-track "step" at an abrupt onset kept 6.2σ of its 66σ given the other axes
   (``tests/closure/test_signal_proxies.py``), while those axes had edges at the onset
   of 7e-10 and 2.4e-10 m/s², many σ of their own noise.

:data:`RATIO_MIN` keeps an instrument's step from being taken for the signal through
its cross-talk into a quieter axis (GRACE's cross-track axis is ten times quieter
than the along-track one; cross-talk and misalignment are ~1e-3 of the step).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from accal.closure.edgekernel import TRANSITION, edge_measure, edge_sizes, gapped_weights
from accal.closure.noise_psd import Grid, held_or_more

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
    """The other axes of one scan of :func:`accal.closure.jumps.scan_jumps`.

    Parameters
    ----------
    grid : Grid
        Placement of the used samples.
    t : ndarray, shape (n,)
        Times of the used samples [s].
    basis : Basis
        The scan's null model.
    lev : ndarray
        Its leverage spectrum.
    proxies : ndarray, shape (n, q)
        The other axes on the used samples [m/s²].
    """

    def __init__(self, grid: Grid, t, basis: Any, lev: NDArray, proxies: NDArray) -> None:
        self.grid, self.t, self.basis, self.lev = grid, t, basis, lev
        self.proxies = np.asarray(proxies, dtype=np.float64).reshape(t.size, -1)
        self._given: Any = None
        self._measures: list | None = None

    def explains(self, r, psd, e: int, pos, n_tests: int, log_level: float) -> str | None:
        """Why the jump at grid epoch ``e`` of the residual ``r`` is explained by the
        other axes (check 1 of the module notes; None when it is not).

        The kernel's weights are made orthogonal to the other axes' series and the
        residual has them fitted; the PSD is no lower than ``psd`` (the scan's) and than
        the residual's with them and the jump fitted (their noise, times their
        coefficients, is in it: :func:`accal.closure.noise_psd.held_or_more`), and the
        kernel is the GLS one for it (:func:`accal.closure.edgekernel.gapped_weights`).
        The jump must still pass the scan's Bonferroni level (``n_tests`` epochs,
        ``log_level``).
        """
        if self._given is None:
            self._given = self.basis.extend(self.proxies)
        given, grid = self._given, self.grid
        r_p = r - given.project(r)
        col = (grid.idx >= e).astype(np.float64)  # the jump, for the PSD without it
        col -= given.project(col)
        r_pe = r_p - col * (col @ r_p) / max(float(col @ col), 1e-300)
        psd = held_or_more(grid, r_pe, self.lev, psd)
        w = max(1, min(int(round(TRANSITION / grid.step)), grid.size // 8))
        (k0,) = gapped_weights(psd, grid.size, grid.step, (w,))
        z, size, sd = edge_sizes(grid, r_p, given, k0, psd, np.array([e]), pos)
        log_p = np.log(2.0) + log_ndtr(-abs(float(z[0]))) + np.log(max(n_tests, 1))
        if log_p < log_level:
            return None
        return (
            "not identifiable: a change of the signal on the other axes explains it "
            f"(given them its size is {size[0]:.3g} ± {sd[0]:.2g} m/s², corrected p "
            f"{min(1.0, float(np.exp(log_p))):.2g}, needs < {np.exp(log_level):.2g})"
        )

    def seen(self, epoch: float, size: float, names: tuple[str, ...] = ()) -> str | None:
        """Why a jump of ``size`` at ``epoch`` [s] is seen on the other axes (check 2 of
        the module notes; None when it is not).

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
