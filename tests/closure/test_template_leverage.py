"""The orbit template's leverage spectrum is exact: ``Σ_j |DFT q_j|²`` of its columns.

The white-noise suppression ``1 − lev(f)/n`` of the residual periodogram corrects the
noise PSD every test uses.  Before 2026-11-29 the template's leverage was an
approximation (three ordinates per orbit harmonic suppressed in full), above ``n`` at
some ordinates and a tenth of the truth between the harmonics: the PSD came out low
there and bias steps were found on 7 of 80 white-noise days at α = 0.01.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.nuisance import OrbitTemplate


def _brute(tmpl: OrbitTemplate, t: np.ndarray, grid_size: int, step: float) -> np.ndarray:
    """``Σ_j |rfft(P e_j)|²`` from the projection of every unit vector: the leverage
    of the template's column space by definition (P = Σ_j q_j q_jᵀ)."""
    n = t.size
    proj = tmpl.project(np.eye(n))  # (n, n): the projector, symmetric
    idx = np.rint((t - t[0]) / step).astype(np.int64)
    # Σ_j |Q_j(k)|² = e_kᴴ P e_k with e_k the DFT vector at the samples' grid positions
    k = np.arange(grid_size // 2 + 1)
    e = np.exp(-2j * np.pi * np.outer(idx, k) / grid_size)  # (n, nf)
    return np.real(np.einsum("ik,ij,jk->k", np.conj(e), proj, e))


@pytest.mark.parametrize("gaps", [False, True])
def test_leverage_matches_the_projector(gaps):
    """A short record (1,200 samples at 2 s, a 200 s period, 12 orbits), with and
    without holes: the leverage at every ordinate equals the projector's quadratic
    form to rounding."""
    rng = np.random.default_rng(3)
    step = 2.0
    t = np.arange(1200) * step
    if gaps:  # two holes and scattered missing samples
        keep = np.ones(t.size, bool)
        keep[300:340] = keep[900:913] = False
        keep[rng.choice(t.size, 25, replace=False)] = False
        t = t[keep]
    tmpl = OrbitTemplate(t, 200.0, order=2, global_degree=1, knot_spacing=400.0, mod_harmonics=1)
    grid_size = int(round((t[-1] - t[0]) / step)) + 1
    got = tmpl.leverage(grid_size, step, np.array([float(t.size)]))[0]
    want = _brute(tmpl, t, grid_size, step)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * t.size)
    # the whole spectrum holds the rank: Σ over the two-sided spectrum / N = rank
    two_sided = got[0] + 2 * got[1:].sum() - (got[-1] if grid_size % 2 == 0 else 0.0)
    assert two_sided / grid_size == pytest.approx(tmpl.rank, rel=1e-9)
    assert np.all(got <= t.size * (1 + 1e-9))
