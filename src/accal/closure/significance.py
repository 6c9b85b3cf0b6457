"""Tests of significance: is a candidate's part of the residual more than its noise?

Three tests, all under the residual's own coloured noise
(:func:`accal.closure.residual.wald_test`, the sandwich Wald/F test with a
Satterthwaite number of degrees of freedom):

* :func:`test_proposal`: a candidate's columns, orthogonalised against the current
  model.  The p-value is multiplied by the members the candidate's search tried
  and by the number of candidate families (Bonferroni), so the family-wise false
  detection probability per selection step is at most ``alpha``.  A sinusoid is
  judged against the residual's *local* spectrum around its frequency (the mean of
  the periodogram ordinates within ±:data:`LOCAL_HALF` of it, the ±2 next to it
  left out): a binned PSD whose bin is wider than a bump of the noise at the orbit
  frequency made the σ of orbit terms ~6x too small on band-limited noise.
* :func:`p_given_others`: an effect given all the others (backward elimination and
  the p-values reported).
* :func:`unexplained_test`: a generic smooth basis (piecewise linear, ``knots``
  knots) against the white + 1/f model fitted above twice its frequencies and
  extrapolated down (:func:`accal.closure.residual.white_plus_flicker`): structure
  no candidate explains is reported, never removed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from accal.closure.basis import Basis
from accal.closure.candidates import Proposal
from accal.closure.distributions import chi2_logsf, f_logsf, f_sf
from accal.closure.residual import (
    Grid,
    WaldResult,
    _quad,
    _two_sided,
    as_leverage,
    estimate_psd,
    wald_test,
    white_plus_flicker,
)
from accal.closure.results import Effect

__all__ = [
    "LOCAL_HALF",
    "Tested",
    "p_given_others",
    "test_proposal",
    "unexplained_test",
]

#: Least share of a catch-all hat column's energy outside the design for the column to
#: be tested (:func:`unexplained_test`).
CATCHALL_MIN_OUTSIDE = 0.01
#: Half-width [DFT ordinates] of the local spectrum a sinusoid is tested against.
LOCAL_HALF = 12
#: Ordinates next to a sinusoid's frequency left out of its local spectrum.
LOCAL_GUARD = 2


@dataclass(frozen=True)
class Tested:
    """A proposal with its test.

    Attributes
    ----------
    prop : Proposal
    wald : WaldResult
        The test of its orthogonalised columns against the current model.
    p_adj : float
        p-value times multiplicity times families (at most 1).
    log_p : float
        Natural log of the same (not capped; far below the smallest float's log when
        the candidate is overwhelming): the selection's ranking.
    power : float
        Residual power it explains [(m/s²)² summed over samples].
    zt : ndarray, shape (n, q)
        Its orthonormalised columns (current model projected out).
    """

    prop: Proposal
    wald: WaldResult
    p_adj: float
    power: float
    zt: NDArray[np.float64]
    log_p: float = 0.0


def _local_test(grid: Grid, residual, zt, freqs: list[float], lev=None) -> WaldResult:
    """Wald test of sinusoid columns ``zt`` against the local spectrum at ``freqs``.

    The local level is the ratio estimator of :func:`accal.closure.residual.estimate_psd`
    over the window's ordinates: ``Σ P_k / Σ (1 − lev_k/n)``, with ``lev`` the model's
    leverage spectrum (``basis_leverage``, shape (C, nf)) plus the sinusoid's own, and
    ``2 Σ (1 − lev_k/n)`` degrees of freedom.  Without the correction the mean
    periodogram counted the noise the model had taken as absent: with the orbit template
    in the model (a fifth of the noise on a day, most of it near the harmonics) lines of
    1-3e-12 m/s² on white noise of 1e-10 m/s² per sample, 2.5-4.4 times their σ, were
    significant on 1 of 40 days at α = 0.01 (QA's generator, 24 CLI runs: 4 of 72 axes;
    docs/closure.md).  ``lev`` None: the mean periodogram and the sinusoid's own
    leverage, as before 2026-11-29 (:func:`test_proposal` passes the model's leverage
    with the orbit template only: with a per-period block base, whose leverage takes
    nearly all the noise at a slow line, a 1e-8 m/s² line at 5400 s on a platform run
    was no longer found; open).
    """
    gamma = zt.T @ residual
    r1 = residual - zt @ gamma
    nc = np.maximum(grid.counts, 1.0)[:, None]
    raw = np.abs(grid.fft(r1)[0]) ** 2 / nc  # (C, nf)
    nf = raw.shape[-1]
    z_fft = grid.fft(zt)
    lev_z = np.sum(np.abs(z_fft) ** 2, axis=0)
    lev_all = lev_z if lev is None else as_leverage(lev, grid.n_chan) + lev_z
    supp = np.clip(1.0 - lev_all / nc, 0.0, 1.0)  # (C, nf)
    df = 1.0 / (grid.size * grid.step)
    psd = np.zeros(nf)
    n_eff = 0.0
    for f in freqs:
        k = int(round(f / df))
        idx = np.r_[k - LOCAL_HALF : k - LOCAL_GUARD, k + LOCAL_GUARD + 1 : k + LOCAL_HALF + 1]
        idx = idx[(idx > 0) & (idx < nf)]
        eff = float(np.sum(supp[:, idx])) if idx.size else 0.0
        if eff <= 0.5:  # nothing of the noise left there to compare with
            continue
        lo, hi = max(1, k - LOCAL_HALF), min(nf, k + LOCAL_HALF + 1)
        level = float(np.sum(raw[:, idx])) / eff
        psd[lo:hi] = np.maximum(psd[lo:hi], level)
        n_eff += eff
    # outside the local windows: the binned estimate (the columns hold little there)
    rest = estimate_psd(grid, r1, lev_all).psd
    psd = np.where(psd > 0, psd, rest)
    w = _two_sided(grid.size, nf) * psd
    cov = _quad(z_fft, w, grid.size)
    cov = 0.5 * (cov + cov.T)
    q = zt.shape[1]
    cinv = np.linalg.pinv(cov, rcond=1e-12)
    stat = float(gamma @ cinv @ gamma) / q
    dof = max(2.0 * n_eff, 2.0)
    return WaldResult(gamma, cov, stat, dof, float(f_sf(stat, q, dof)), r1, psd)


def sinusoid_freqs(prop: Proposal) -> list[float]:
    """The frequencies of a periodic proposal's sinusoids [Hz] (empty for other kinds)."""
    f = prop.params.get("frequency")
    if f is None or not prop.params.get("local_psd"):
        return []
    return [n * float(f) for n in prop.params.get("harmonics", (1,))]


def test_proposal(
    grid: Grid,
    basis: Basis,
    resid: NDArray[np.float64],
    lev: NDArray[np.float64],
    prop: Proposal,
    use: NDArray[np.bool_],
    n_families: int,
) -> Tested | None:
    """Test ``prop`` on top of the model ``basis`` (None when it adds nothing)."""
    zt = basis.complement(prop.columns[use])
    if zt.shape[1] == 0:
        return None
    freqs = sinusoid_freqs(prop)
    if freqs:  # the model's leverage corrects the local spectrum with the template only
        w = _local_test(grid, resid, zt, freqs, lev if basis.nuisance is not None else None)
    else:
        w = wald_test(grid, resid, zt, lev)
    factor = max(prop.multiplicity, 1.0) * max(n_families, 1)
    p_adj = float(min(1.0, w.pvalue * factor))
    q = max(w.q, 1)
    if np.isfinite(w.dof):
        logsf = float(f_logsf(w.stat, q, w.dof))
    else:
        logsf = float(chi2_logsf(w.stat * q, q))
    return Tested(prop, w, p_adj, float(np.sum(w.gamma**2)), zt, logsf + float(np.log(factor)))


def p_given_others(
    grid: Grid,
    basis_without: Basis,
    lev_without: NDArray[np.float64],
    y: NDArray[np.float64],
    prop: Proposal,
    use: NDArray[np.bool_],
    n_families: int,
) -> float:
    """Corrected p-value of ``prop`` given the model without it (``basis_without``)."""
    fit = basis_without.fit(y)
    t = test_proposal(grid, basis_without, fit.resid, lev_without, prop, use, n_families)
    return 1.0 if t is None else t.p_adj


def catchall_columns(t: NDArray[np.float64], knots: int) -> NDArray[np.float64]:
    """Piecewise-linear hat functions on ``knots`` equally spaced nodes."""
    nodes = np.linspace(t[0], t[-1], knots)
    h = nodes[1] - nodes[0]
    return np.clip(1.0 - np.abs(t[:, None] - nodes[None, :]) / h, 0.0, None)


def unexplained_test(
    grid: Grid,
    basis: Basis,
    resid: NDArray[np.float64],
    lev: NDArray[np.float64],
    t_u: NDArray[np.float64],
    knots: int,
    split,
) -> tuple[WaldResult | None, NDArray[np.float64] | None]:
    """The catch-all test of the model ``basis`` (None when disabled or nothing is left).

    ``split`` turns the hat columns into one copy per data channel.  A hat column of
    which the design already holds all but :data:`CATCHALL_MIN_OUTSIDE` of the energy
    is left out: the rotating platform's per-period affine bias spans the hats to
    3e-5-1.5e-4 of their energy (knots an hour apart, periods of 600 s), and the test
    of those remnants, kinks at the knots inside a period, reported "unexplained
    smooth structure" on 4 of 32 platform runs of an outside generator, one of them
    clean (QA 2026-11-28, α = 0.01), for 0.5 s of a 5 s run.
    """
    if not knots or knots < 3:
        return None, None
    cols = split(catchall_columns(t_u, knots))
    norm2 = np.einsum("ij,ij->j", cols, cols)
    outside = 1.0 - basis.captured(cols) / np.maximum(norm2, 1e-300)
    cols = cols[:, (norm2 > 0) & (outside >= CATCHALL_MIN_OUTSIDE)]
    if cols.shape[1] == 0:
        return None, None
    zt = basis.complement(cols)
    if zt.shape[1] == 0:
        return None, None
    nz = estimate_psd(grid, resid, lev)
    f_lo = 2.0 * knots / (grid.size * grid.step)
    model, _, nu = white_plus_flicker(grid, nz, f_lo, return_dof=True)
    model = np.where(grid.freqs >= f_lo, nz.psd, model)  # the extrapolation only below f_lo
    return wald_test(grid, resid, zt, lev, psd=model, psd_dof=nu), zt


def describe_smooth(grid: Grid, t: NDArray[np.float64], comp, w: WaldResult) -> Effect:
    """An ``unexplained`` effect from the catch-all component ``comp`` (used samples)."""
    spec = np.sum(np.abs(grid.fft(comp)[0]) ** 2, axis=0)
    spec[0] = 0.0
    k = int(np.argmax(spec))
    f = float(grid.freqs[k])
    ch = grid.channel
    rms_c = [np.sqrt(np.mean(comp[ch == c] ** 2)) for c in range(grid.n_chan)]
    sel = ch == int(np.argmax(rms_c))
    tc, cc = t[sel], comp[sel]
    idx = np.linspace(0, tc.size - 1, min(100, tc.size)).astype(int)
    return Effect(
        "unexplained",
        "smooth",
        float(np.sqrt(np.mean(comp**2))),
        float("nan"),
        float(w.pvalue),
        frequency=f,
        details={
            "reason": "smooth structure left after the selected effects",
            "period": 1.0 / f if f > 0 else None,
            "stat": w.stat,
            "dof": w.dof,
            "shape_t": tc[idx].tolist(),
            "shape": cc[idx].tolist(),
        },
        unit="m/s^2",
    )
