"""The spectrum-weighted step kernel of :mod:`accal.closure.jumps`: weights, scores, sizes.

A step at grid index ``e`` is tested with the GLS weights of a unit step under the
residual's PSD, the samples within ±:data:`TRANSITION` s of the epoch left out
(:func:`gapped_weights`; the derivation is in :mod:`accal.closure.jumps`).  Here: the
kernel at index 0 (:func:`step_kernel`), its cross-correlation with a residual for every
epoch (:func:`edge_scores`), the best epochs of a ranking (:func:`top_epochs`), and the
exact size, σ and z of a step at given epochs with the kernel as weights
(:func:`edge_sizes`, the sandwich variance on the same PSD).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from accal.closure.noise_psd import Grid, estimate_psd, two_sided_weights

__all__ = [
    "END_CLEAR",
    "ENERGY",
    "EdgeMeasure",
    "EXACT_CHUNK",
    "TRANSITION",
    "edge_measure",
    "edge_scores",
    "edge_sizes",
    "edge_weights",
    "gapped_weights",
    "grid_time",
    "kernel_norm",
    "kernels_at",
    "step_kernel",
    "top_epochs",
]

#: Half-width [s] of the transition a step may take in the data, left out of its test:
#: Level-1B data are low-passed by the CRN filter of the processing, so an instrument's
#: step is a ramp over the filter's window (ACC1B ``qualflg`` bits 5-7 count from the
#: "center of CRN filter window" beyond 15 s; seven 10 s boxcars, the tests' stand-in,
#: span ±35 s).  A test of the step's *edge* found the unfiltered steps of the earlier
#: generators and not one filtered like the data (1e-8 m/s², x axis).
TRANSITION = 40.0
#: Least time [s] between a least-squares step of low-passed data and the record's
#: ends (:func:`accal.closure.candidates.bias_step`), as the edge scan needs its widest
#: kernel's half-width (:data:`accal.closure.jumps.HALF_MAX`) of data on either side.
#: The signal model is extrapolated at the ends, and a firing's bump screened next to
#: the start leaves slivers of samples whose level is no bias: a QA thruster day
#: (2026-11-29) had "steps" of −3.2e-8 and −1.7e-8 m/s² removed 82 s and 133 s into
#: the record, between firings at 0, 120 and 162 s (the z bias moved 9σ and 5σ).
END_CLEAR = 600.0
#: Energy share that defines the kernel's half-width.
ENERGY = 0.999
#: Candidate epochs per chunk in :func:`edge_sizes`.
EXACT_CHUNK = 8


def step_kernel(grid: Grid, r: NDArray[np.float64], lev: NDArray) -> tuple:
    """The step kernels at grid index 0 and the PSD.

    Returns ``kf`` (the rfft of ``k0``), ``k0`` (transition ±:data:`TRANSITION` s left
    out, :func:`gapped_weights`), the PSD, the half-width of ``k0`` [samples] (99.9 % of its
    energy) and ``k2`` (twice the transition left out, for the persistence check).
    """
    n = grid.size
    psd = estimate_psd(grid, r, lev).psd
    w = max(1, min(int(round(TRANSITION / grid.step)), n // 8))
    k0, k2 = gapped_weights(psd, n, grid.step, (w, 2 * w))
    c = n // 2
    cs = np.cumsum(np.roll(k0, c) ** 2)  # lag 0 at index c
    tot = float(cs[-1])
    if not tot > 0:
        return np.fft.rfft(k0), k0, psd, n, k2
    m = np.arange(min(c, n - c - 1))
    inner = cs[c + m] - np.r_[0.0, cs][c - m]  # energy within lags -m .. m
    half = int(np.searchsorted(inner, ENERGY * tot))
    return np.fft.rfft(k0), k0, psd, max(half, w), k2


def gapped_weights(
    psd: NDArray[np.float64], n: int, step: float, widths: tuple[int, ...]
) -> list[NDArray[np.float64]]:
    """GLS weights of a step at grid index 0 with the samples ``−w .. w−1`` left out,
    for each ``w`` of ``widths`` (one PSD, so ``Q`` and the step's weights are shared).

    With ``Q = C⁻¹`` the Whittle inverse of the noise covariance (circulant, ``1/S(f)``;
    zero at f = 0: constants are the base's), the GLS weights of a unit step ``u``
    given only the samples ``O`` outside the transition ``Γ`` are ``(C_OO)⁻¹ u_O``, and
    by the partitioned inverse ``(C_OO)⁻¹ = Q_OO − Q_OΓ (Q_ΓΓ)⁻¹ Q_ΓO``:
    ``g = a − Q (Q_ΓΓ)⁻¹ a_Γ`` with ``a = Q (u with Γ zeroed)``, which vanishes on Γ
    (e.g. Golub & Van Loan 2013, Matrix Computations, §3.2.10 for the block inverse).
    Per width two FFTs and one ``2w × 2w`` solve.  Any transition of the step inside Γ
    (the Level-1B filter's ramp) leaves the weights' response ``Σ_{k≥0} g_k`` unchanged.
    """
    f = np.fft.rfftfreq(n, step)
    inv = np.zeros(f.size)
    good = (psd > 0) & np.isfinite(psd)
    good[0] = False
    inv[good] = 1.0 / psd[good]
    d = 1.0 - np.exp(-2j * np.pi * f[good] * step)
    kf = np.zeros(f.size, dtype=complex)
    kf[good] = inv[good] / d  # Q u: the step's GLS weights, all samples used
    q = np.fft.irfft(inv, n=n)
    out = []
    for w in widths:
        gap = np.arange(-w, w) % n
        u_gap = np.zeros(n)
        u_gap[:w] = 1.0  # the step's samples inside Γ (indices 0 .. w−1)
        a = np.fft.irfft(kf - np.fft.rfft(u_gap) * inv, n=n)
        j = np.arange(2 * w)
        b = linalg.solve(q[np.abs(j[:, None] - j[None, :])], a[gap], assume_a="pos")
        b_full = np.zeros(n)
        b_full[gap] = b
        g = a - np.fft.irfft(np.fft.rfft(b_full) * inv, n=n)
        g[gap] = 0.0  # zero there to rounding (the construction)
        out.append(g)
    return out


def edge_scores(grid: Grid, r: NDArray[np.float64], kf: NDArray[np.complex128]) -> NDArray:
    """``|⟨G_e, r⟩|`` for every grid epoch (one cross-correlation): the ranking."""
    rg = grid.place(r)[0, 0]
    return np.abs(np.fft.irfft(np.fft.rfft(rg) * np.conj(kf), n=grid.size))


def grid_time(t: NDArray[np.float64], grid: Grid, e: int) -> float:
    """Time of the used sample at grid index ``e``."""
    return float(t[int(np.searchsorted(grid.idx, e))])


def top_epochs(score: NDArray[np.float64], k: int, sep: int) -> NDArray[np.int64]:
    """The ``k`` best indices of ``score`` at least ``sep`` apart (positive scores only)."""
    order = np.argsort(-score)
    out: list[int] = []
    blocked = np.zeros(score.size, dtype=bool)
    for i in order:
        if score[i] < 0 or len(out) >= k:
            break
        if blocked[i]:
            continue
        out.append(int(i))
        blocked[max(0, i - sep) : i + sep + 1] = True
    return np.array(out, dtype=np.int64)


def kernels_at(k0: NDArray[np.float64], grid: Grid, epochs: NDArray[np.int64]) -> NDArray:
    """The kernel at each grid epoch, on the used samples: (n, k)."""
    n = grid.size
    rows = (grid.idx[:, None] - epochs[None, :]) % n
    return k0[rows]


def kernel_norm(g: NDArray[np.float64], grid: Grid, e: int) -> float:
    """``gᵀ 1[t ≥ t_e]`` (the weights' response to a unit step at grid index ``e``)."""
    return float(g[int(np.searchsorted(grid.idx, e)) :].sum())


def edge_sizes(grid, r, basis, k0, psd, cand, pos, project=True):
    """Size, σ and z of a step at each candidate grid epoch with the kernel as weights
    (null design projected out of them).

    ``project=False``: the edge of the residual ``r`` itself, the weights as they are
    (the neighbour and recurrence checks of :mod:`accal.closure.jumps`: whether the
    residual has another edge there, not whether a step there could be told from the
    orbit template; where the template follows an eclipse edge, a projected kernel's σ
    is 10-20× larger and the box the template leaves had an edge at only 3σ).  The
    candidates are worked through :data:`EXACT_CHUNK` at a time
    (:data:`accal.closure.jumps.TOP` weight columns at once, their projections, sums
    and spectra, held 290 MB on a 1 Hz day).
    """
    cand = np.asarray(cand, dtype=np.int64)
    size, sd = np.zeros(cand.size), np.zeros(cand.size)
    w = two_sided_weights(grid.size, psd.size) * psd
    for c0 in range(0, cand.size, EXACT_CHUNK):
        part = slice(c0, c0 + EXACT_CHUNK)
        gm = edge_weights(k0, grid, basis, cand[part], project)
        first = pos[cand[part]]  # used-sample position of each epoch
        # response to the unit step: the sum of the weights from the epoch on
        csum = np.cumsum(gm[::-1], axis=0)[::-1]
        a = csum[first, np.arange(first.size)]
        del csum
        size[part] = (gm.T @ r) / a
        f = grid.fft(gm)  # (k, C, nf)
        # the quadratic form's diagonal (accal.closure.wald.quad_form): Σ |G|² w / N
        var = np.einsum("kcf,f->k", f.real**2 + f.imag**2, w) / grid.size / a**2
        sd[part] = np.sqrt(np.maximum(var, 0.0))
    z = np.where(sd > 0, size / np.where(sd > 0, sd, 1.0), 0.0)
    return z, size, sd


def edge_weights(k0, grid, basis, epochs, project=True) -> NDArray[np.float64]:
    """The kernel at grid ``epochs`` on the used samples, the null design projected
    out (``project``): (n, k)."""
    g = kernels_at(k0, grid, np.asarray(epochs, dtype=np.int64))
    return g - basis.project(g) if project else g


#: ``times -> (ok, z, size)``: :func:`edge_measure`'s measure.
EdgeMeasure = Callable[[NDArray[np.float64]], tuple[NDArray, NDArray, NDArray]]


def edge_measure(
    grid: Grid,
    t: NDArray[np.float64],
    r: NDArray[np.float64],
    lev: NDArray,
    window: float,
    ok: NDArray[np.bool_] | None = None,
) -> EdgeMeasure:
    """A measure of the residual's edges near given times (for
    :func:`accal.closure.comb.find_comb`).

    For each time, the epoch of the best score (:func:`edge_scores`) among the grid
    epochs ``ok`` (default: the used ones) within ±``window`` s, and the z and size of
    the residual ``r``'s own edge there (:func:`edge_sizes` with ``project=False``;
    the kernel from ``r``'s PSD, ``lev`` its null model's leverage spectrum).  ``ok``
    of the returned triple is False where no such epoch exists.

    Parameters
    ----------
    grid : Grid
        Placement of the used samples (one channel).
    t, r : ndarray, shape (n,)
        Times [s] and residual [m/s²] of the used samples.
    lev : ndarray
        Leverage spectrum of the model ``r`` is the residual of.
    window : float
        Half-width of the search around each time [s].
    ok : ndarray of bool, shape (grid.size,), optional
        Grid epochs that may be measured.

    Returns
    -------
    callable
        ``measure(times) -> (ok, z, size)``, arrays of ``times``' shape.
    """
    kf, k0, psd, _, _ = step_kernel(grid, r, lev)
    score = edge_scores(grid, r, kf)
    pos = np.full(grid.size, -1)
    pos[grid.idx] = np.arange(grid.idx.size)
    if ok is None:
        ok = pos >= 0
    w = max(int(round(window / grid.step)), 1)

    def measure(times: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
        c = grid.idx[0] + np.round((np.asarray(times) - t[0]) / grid.step).astype(np.int64)
        good, picks = np.zeros(c.size, dtype=bool), np.zeros(c.size, dtype=np.int64)
        for q, ci in enumerate(c):
            a, b = max(int(ci) - w, 0), min(int(ci) + w + 1, grid.size)
            if b > a:
                s = np.where(ok[a:b], score[a:b], -1.0)
                good[q], picks[q] = s.max() >= 0, a + int(np.argmax(s))
        z, size = np.zeros(c.size), np.zeros(c.size)
        if good.any():
            z[good], size[good], _ = edge_sizes(
                grid, r, None, k0, psd, picks[good], pos, project=False
            )
        return good, z, size

    return measure
