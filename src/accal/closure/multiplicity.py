"""How many independent tests a scan makes: step epochs beside a nuisance, a frequency band.

:func:`scan_length` and :func:`scan_factor`: the step scan with the orbit template in
the model (below).  :func:`frequency_search_factor`: sinusoids whose frequency is
searched over a band (the orbit term), by Davies' bound.

The corrected p of a bias step found by scanning every epoch is its single-epoch p
times the scan's multiplicity (:func:`accal.closure.candidates.scan_multiplicity`):
Siegmund's approximation for the standardized CUSUM, whose neighbouring epochs are
nearly the same test (correlation ``1 − δ/θ(e)`` at ``δ`` samples, ``θ(e)`` of the
order of the distance to the record's nearer end).  With the orbit template in the
null model (no reference: per orbit-phase bin a polynomial in time,
:class:`accal.closure.nuisance.OrbitTemplate`) the projected step loses that: moving
the epoch by one orbit changes every bin's indicator, and the correlation falls to 1/2
within ~100-400 s (measured on a 1 Hz day).  The scan then makes ~10 times more
independent tests than Siegmund's count, and on white-noise days bias steps were
"found" on 5 of 80 at α = 0.01 (2026-11-29).

Here the local decorrelation ``1/θ(e) = (1 − ρ(e, e + δ))/δ`` is measured on the
projected step columns themselves at a few dozen epochs and integrated over the epochs
scanned; the same tail approximation (a χ²_k field whose correlation has a cusp,
``P(max > x²) ≈ x^k e^{−x²/2} / (2^{k/2} Γ(k/2)) · 2 Σ_e 1/θ(e)``; Siegmund 1988,
*Ann. Statist.* 16, 487, and James, James & Siegmund 1987, *Biometrika* 74, 71, whose
``2 ln((1 − ε)/ε)`` is that sum for the CUSUM) gives the multiplicity.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, special

from accal.closure.distributions import chi2_sf

if TYPE_CHECKING:  # annotations only
    from accal.closure.candidates import Context

__all__ = ["WIDTH_EPOCHS", "WIDTH_LAG", "frequency_search_factor", "scan_factor", "scan_length"]

#: Epochs, evenly spread over those scanned, at which the decorrelation is measured
#: (plus eight each side geometrically closer to the ends).
WIDTH_EPOCHS = 48
#: Epoch offset [scanned epochs] of the correlation measured.
WIDTH_LAG = 4
#: Epochs whose step columns are projected together (bounds the memory: 16 columns of
#: a 1 Hz day are 11 MB).
WIDTH_CHUNK = 8


def scan_factor(logs: float, k: int, level: float) -> float:
    """Bonferroni factor of a scan whose summed local decorrelation is ``logs``/2.

    ``logs = 2 Σ_e 1/θ(e)``: the tail ``P(max > x²)`` of the module notes divided by
    the single-epoch ``P(χ²_k > x²)``, at the ``x²`` where the former is ``level``.
    At least 1.
    """
    if logs <= 0.0 or not 0.0 < level < 1.0:
        return 1.0
    c = 2.0 ** (k / 2.0) * special.gamma(k / 2.0)

    def excess(x2: float) -> float:  # log P(scan max > x2) - log level
        return k / 2.0 * np.log(x2) - x2 / 2.0 - np.log(c) + np.log(logs) - np.log(level)

    lo = max(float(k), 1.0)  # the tail formula holds beyond the mode
    if excess(lo) <= 0.0:
        return 1.0
    x2 = optimize.brentq(excess, lo, 1e4)
    return float(max(1.0, level / chi2_sf(x2, k)))


def scan_length(ctx: Context, ok: NDArray[np.bool_]) -> float | None:
    """``Σ_e 1/θ(e)`` over the epochs ``ok`` of a one-channel scan whose model holds a
    nuisance (the orbit template); None otherwise.

    ``ρ(e, e')`` is the correlation of the steps at ``e`` and ``e'`` (the ``WIDTH_LAG``-th
    scanned epoch after ``e``) with the design projected out; ``1/θ = (1 − ρ)/WIDTH_LAG``
    per scanned epoch, interpolated linearly between the epochs measured and held at
    the ends.  Kept in the context's cache for its nuisance and epochs (the effects
    added later change the design by a few columns).
    """
    basis = ctx.basis
    if basis.nuisance is None or len(ctx.channel_masks()) != 1:
        return None
    idx = np.flatnonzero(ok)
    m = idx.size - WIDTH_LAG
    if m < 2:
        return None
    nz = basis.nuisance
    key = ("step scan length", id(nz), getattr(nz, "period", None), int(idx.size),
           int(idx[0]), int(idx[-1]))  # fmt: skip
    hit = ctx.cache.get(key)
    if hit is not None:
        return hit
    near = np.geomspace(1e-4, 0.05, 8)
    q = np.r_[np.linspace(0.0, 1.0, WIDTH_EPOCHS), near, 1.0 - near]
    pick = np.unique(np.round(q * (m - 1)).astype(np.int64))
    t = ctx.t
    one_minus_rho = np.empty(pick.size)
    for a in range(0, pick.size, WIDTH_CHUNK):  # ~10 MB of columns at a time on a day
        part = pick[a : a + WIDTH_CHUNK]
        k = part.size
        cols = np.column_stack([t >= t[i] for i in np.r_[idx[part], idx[part + WIDTH_LAG]]])
        cols = cols.astype(np.float64)
        zt = cols - basis.project(cols)
        nrm = np.sqrt(np.sum(zt**2, axis=0))
        if not np.all(nrm > 1e-6 * np.sqrt(np.sum(cols**2, axis=0))):
            return None
        zt /= nrm
        one_minus_rho[a : a + k] = 0.5 * np.sum((zt[:, :k] - zt[:, k:]) ** 2, axis=0)
    inv = one_minus_rho / WIDTH_LAG
    pos = pick.astype(np.float64)
    inner = float(np.sum(0.5 * (inv[1:] + inv[:-1]) * np.diff(pos)))  # trapezoid rule
    total = inner + float(inv[0] * pos[0] + inv[-1] * (idx.size - 1 - pos[-1]))
    ctx.cache[key] = total
    return total


def frequency_search_factor(
    t: NDArray[np.float64], band: float, harmonics, n_chan: int, level: float
) -> float:
    """Bonferroni factor of sinusoids at ``h·f`` (``h`` in ``harmonics``) whose ``f`` is
    searched over a band ``band`` wide [Hz], at the decision boundary.

    Davies' bound for the supremum of a χ²_k process over a parameter (Davies 1987,
    *Biometrika* 74, 33, eq. 3.4): ``P(sup > u) ≤ P(χ²_k > u) + V u^{(k−1)/2} e^{−u/2}
    2^{−k/2} / Γ(k/2)``, with ``V = band · √λ`` the path length of the normalised
    process; a sinusoid's derivative with respect to ``f`` is ``2π h (t − t̄)`` times its
    quadrature, so ``λ = (2π)² Var(t) · mean(h²)`` (harmonics weighted alike).  ``k =
    2 · len(harmonics) · n_chan``.  The factor is the bound over ``P(χ²_k > u)`` at the
    ``u`` where the bound equals ``level``; at least 1.  On a 1 Hz day the orbit term
    (``f`` and ``2f`` within ±3 %) gets ~6; the count of resolvable frequencies in the
    fundamental's band alone (1 on a day) had such terms significant on 3 of 40
    white-noise days at α = 0.01.
    """
    h = np.asarray(list(harmonics), dtype=np.float64)
    k = 2 * h.size * max(int(n_chan), 1)
    if k == 0 or band <= 0 or t.size < 2 or not 0.0 < level < 1.0:
        return 1.0
    v = float(band * 2.0 * np.pi * np.std(t) * np.sqrt(np.mean(h**2)))
    lg = special.gammaln(k / 2.0)

    def log_tail(u: float) -> float:  # log of Davies' second term
        return np.log(v) + 0.5 * (k - 1) * np.log(u) - 0.5 * u - 0.5 * k * np.log(2.0) - lg

    def excess(u: float) -> float:  # log(bound) − log(level)
        return float(np.logaddexp(np.log(max(chi2_sf(u, k), 1e-300)), log_tail(u)) - np.log(level))

    lo = float(k)
    if excess(lo) <= 0.0:
        return 1.0
    u = optimize.brentq(excess, lo, 1e4)
    return float(max(1.0, level / chi2_sf(u, k)))
