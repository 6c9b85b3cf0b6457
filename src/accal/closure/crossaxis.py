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

from accal.closure.edgekernel import TRANSITION, edge_scores, edge_sizes, step_kernel
from accal.closure.noise_psd import Grid

__all__ = ["LEVEL", "NEAR", "OWN_JUMPS", "OWN_LEVEL", "RATIO_MIN", "WINDOW", "OtherAxes"]

#: Half-width [s] of the search for another axis' edge around a jump's epoch (the
#: Level-1B filter's transition, within which the jump's own epoch is placed).
WINDOW = TRANSITION
#: Family-wise level of that search (each axis, each epoch of the window).
LEVEL = 1e-2
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
        self._axes: list[dict[str, Any]] | None = None

    def _prepared(self) -> list[dict[str, Any]]:
        """Per other axis: its residual of the null model with its own jumps out
        (:func:`_own_jumps`), those jumps, and the step kernel of that residual's PSD."""
        if self._axes is None:
            self._axes = []
            for p in self.proxies.T:
                res = p - self.basis.project(p)
                clean, jumps = _own_jumps(self.grid, self.t, res, self.basis, self.lev)
                kf, k0, psd, _, _ = step_kernel(self.grid, clean, self.lev)
                self._axes.append({"clean": clean, "jumps": jumps, "kf": kf, "k0": k0, "psd": psd})
        return self._axes

    def seen(self, epoch: float, size: float, names: tuple[str, ...] = ()) -> str | None:
        """Why a jump of ``size`` at ``epoch`` [s] is seen on the other axes (None when
        it is not).

        Each other axis' residual of the same null model, its own jumps farther than
        :data:`NEAR` s from ``epoch`` taken out (a real step an hour from a storm's
        onset raised that axis' PSD so that its onset edge was not significant: the
        onset was removed as a bias step of the along-track axis, QA: 3 of 18 storm
        days), is measured at its best edge within ±:data:`WINDOW` s by the kernel of
        that PSD (the edge of the residual as it is); an edge significant at
        :data:`LEVEL` (two-sided, Bonferroni over the window's epochs and the axes)
        of :data:`RATIO_MIN` of ``size`` or more is the signal's.
        """
        axes = self._prepared()
        grid, t = self.grid, self.t
        w = max(int(round(WINDOW / grid.step)), 1)
        n_look = (2 * w + 1) * len(axes)
        pos = np.full(grid.size, -1)
        pos[grid.idx] = np.arange(grid.idx.size)
        c = grid.idx[0] + int(round((epoch - t[0]) / grid.step))
        a, b = max(c - w, 0), min(c + w + 1, grid.size)
        if b <= a:
            return None
        for k, ax in enumerate(axes):
            r = ax["clean"].copy()
            for e_j, s_j in ax["jumps"]:
                if abs(e_j - epoch) <= NEAR:  # an edge here stays: it is what is asked
                    col = (t >= e_j).astype(np.float64)
                    r += s_j * (col - self.basis.project(col))
            score = np.where(pos[a:b] >= 0, edge_scores(grid, r, ax["kf"])[a:b], -1.0)
            if score.max() < 0:
                continue
            e = np.array([a + int(np.argmax(score))])
            z, s, _ = edge_sizes(grid, r, None, ax["k0"], ax["psd"], e, pos, project=False)
            z0, s0 = float(z[0]), float(s[0])
            log_p = np.log(2.0) + log_ndtr(-abs(z0)) + np.log(n_look)
            if log_p < np.log(LEVEL) and abs(s0) >= RATIO_MIN * abs(size):
                name = names[k] if k < len(names) else f"axis {k + 1}"
                return (
                    f"not identifiable: the other axis {name} has an edge of {s0:.3g} m/s² "
                    f"({abs(z0):.0f}σ) at the same time: a change of the signal seen on more "
                    "than one axis (or an instrument event common to the axes), not told "
                    "from a bias step of this one"
                )
        return None


#: Other-axis jumps within this many seconds of the epoch asked about stay in its
#: residual when it is measured (:meth:`OtherAxes.seen`).
NEAR = 2.0 * WINDOW
#: Most of an other axis' own jumps taken out (:func:`_own_jumps`), and their least
#: significance (Bonferroni over the record's epochs at this level).
OWN_JUMPS = 3
OWN_LEVEL = 1e-3


def _own_jumps(grid: Grid, t, res, basis, lev) -> tuple[NDArray, list[tuple[float, float]]]:
    """``res`` without its largest edges and those edges ``[(epoch, size), ...]``.

    Up to :data:`OWN_JUMPS` times: the best-ranked edge of the residual by the step
    kernel of its current PSD (:mod:`accal.closure.edgekernel`), taken out as a step
    when significant at :data:`OWN_LEVEL` over all epochs.  A step is what raises an
    axis' low-frequency PSD the most and makes every other edge look insignificant.
    """
    jumps: list[tuple[float, float]] = []
    pos = np.full(grid.size, -1)
    pos[grid.idx] = np.arange(grid.idx.size)
    log_level = np.log(OWN_LEVEL) - np.log(max(t.size, 1))
    for _ in range(OWN_JUMPS):
        kf, k0, psd, half, _ = step_kernel(grid, res, lev)
        # epochs whose kernel and transition have used samples all round: at the
        # record's ends or beside a hole an unprojected kernel sees the level itself
        # (a "jump" of 5.9e-5 m/s² at the sixth sample of an along-track day)
        m = max(half, int(round(2 * TRANSITION / grid.step)), 1)
        used = (pos >= 0).astype(np.float64)
        full = np.convolve(used, np.ones(2 * m + 1), mode="same") >= 2 * m + 1
        score = np.where(full, edge_scores(grid, res, kf), -1.0)
        if score.max() < 0:
            break
        e = np.array([int(np.argmax(score))])
        z, s, _ = edge_sizes(grid, res, None, k0, psd, e, pos, project=False)
        if not np.log(2.0) + log_ndtr(-abs(float(z[0]))) < log_level:
            break
        epoch = float(t[int(pos[e[0]])])
        col = (t >= epoch).astype(np.float64)
        res = res - float(s[0]) * (col - basis.project(col))
        jumps.append((epoch, float(s[0])))
    return res, jumps
