"""Bias/drift covariance from a low-frequency noise model pooled over adjacent days.

One day cannot tell how noise correlated over hours continues below 1/day, and that
is where the bias and drift estimators have their weight: the day's own binned
periodogram (:func:`accal.estimators.trend.linear_estimator_covariance`) gives
σ that scatter 25–45 % from day to day and are 1.4–3× too small under red noise
(``make mc-sigma``).  This module fits a parametric noise model to the residual's
low-frequency spectrum of several adjacent days together (the same instrument, the
same noise process) and evaluates the estimators' covariance under it.

Noise model (per grid step, lags ``h`` in samples)::

    e = white (variance W per sample) + A · red_θ

``red_θ`` is one of

* a power law: the intrinsic random function of order 1 (Matheron 1973) with
  generalized covariance ``K_β(h) = −(|h|^β − 1)/β`` (``β → 0``: ``−log|h|``) for
  ``h ≥ 1`` and ``K_β(0) = K_β(1) + ν_β`` (``ν_β`` the smallest nugget that makes
  ``K_β`` conditionally positive definite, :func:`_nugget`).  Its spectrum is
  ``c_β |f|^−(1+β)`` at low frequency (:func:`spectral_const`; the variogram of a
  power-law process, Mandelbrot & Van Ness 1968): ``β = 0`` is 1/f noise, ``β = 1``
  a random walk (``K = 1 − |h|``);
* a stationary AR(1), ``C(h) = φ^|h|``, ``φ = exp(−1/τ)`` (a Lorentzian spectrum).

**Exact expectations** of the tapered residual's Fourier coefficients.  The residual
is ``r = (I − V G) e`` (``V`` the Vandermonde matrix in ``t − t0``, ``G`` the
estimator's weights, ``G V = I``), so with a taper ``u`` (the first sine taper,
Riedel & Sidorenko 1995) ``R_k = Σ_t u_t r_t e^{−2πi k m_t/N} = c_kᴴ e`` with
``c_k = (I − V G)ᵀ (u z_k)``.  ``c_k`` annihilates polynomials of the fitted order,
so for any (generalized) covariance ``C``::

    E|R_k|² = c_kᴴ C c_k = z̃_kᴴ C z̃_k − 2 Re[(z̃_kᴴ C Gᵀ) a_k] + a_kᴴ (G C Gᵀ) a_k

(``z̃_k = u z_k``, ``a_k = Vᵀ z̃_k``), evaluated with FFTs of length ``2N``
(circulant embedding; ``N`` the grid of the day, gaps as zeros).  Hence
``E|R_k|² = W w_k + A h_k(θ)`` with ``w``, ``h`` fixed by the sample layout: the
projection of the fitted trend, the gaps and the taper's leakage are all in it.

**Fit**: Whittle's likelihood (Whittle 1953) ``l = −Σ_k [log E_k + P̄_k/E_k]`` of the
mean periodogram ``P̄`` of the ``D`` pooled days over bins ``k = 1 … K``
(:data:`K_BAND`), times ``D``; for every shape of a grid (:data:`BETAS`,
:data:`TAUS_PER_N`) ``W, A ≥ 0`` by iteratively reweighted least squares (the score
of the Gamma GLM with identity link, McCullagh & Nelder 1989, §8.3).  A coloured
model must gain :data:`COLOURED_MARGIN` in ``l`` over white noise; a Lorentzian must
beat the best power law by :data:`LORENTZ_MARGIN`.  Ordinates far above their
expectation (a line, a band) are left out with their neighbours and the fit
repeated.  A goodness-of-fit test (Gamma deviance of log-spaced groups, Wilson &
Hilferty 1931) flags a spectrum the model does not describe; then the day's own
estimate is kept (``info["misfit"]``).

**Covariance** of the estimators under the fitted model: ``W G Gᵀ + A G C_θ Gᵀ``.
The drift (``Σ g_d = 0``) is a contrast, defined for the generalized covariance.
The bias is not (``Σ g_b = 1``); for the power laws two conventions bound it and
the smaller is used:

* *pinned*: the red part's value at ``t0`` belongs to the instrument, the error is
  ``(g_b − δ_t0)ᵀ red``: exact for a random walk started at ``t0``;
* *stationary, flat below 1/(2T)*: ``Σ_j |G_b(f_j)|² S(f_j)/N`` at the half-integer
  frequencies ``f_j = (j + ½)/N`` with ``S`` held at its value at ``1/(2N)`` below.

Between the grid's shapes the covariance is interpolated at the vertex of the
profile likelihood's parabola.  No variance is below that of white noise at the mean
level of the fitted band (``mean(P̄/w)·(G Gᵀ)_jj``; not the residual's variance, which
content above the band, e.g. real L1B noise at 10–100 mHz, inflates without reaching
the estimates).

Measured (``make mc-sigma``, 1 Hz days, 8-day pools): scatter/σ 0.76–1.10 for white,
white + 1/f, random walk, AR(1) of 1–6 h, except the drift under AR(1) of 3–6 h
(0.55–0.62: σ too large); |z| > 3 in ≤ 3 % (random-walk drift, AR(1) 6 h bias 2–4 %);
a 1/rev band is a misfit and keeps the day's estimate.  Limits: the days pooled must
share the noise process (a storm day or a changed instrument mode breaks it), and a
spectrum steeper than ``f^−2.95`` or flatter than ``f^−0.5`` is at the grid's edge.

References
----------
.. [1] G. Matheron, "The intrinsic random functions and their applications",
   Adv. Appl. Probab. 5, 439–468 (1973).
.. [2] B. B. Mandelbrot & J. W. Van Ness, "Fractional Brownian motions, fractional
   noises and applications", SIAM Rev. 10, 422–437 (1968).
.. [3] P. Whittle, "Estimation and information in stationary time series",
   Ark. Mat. 2, 423–434 (1953).
.. [4] K. S. Riedel & A. Sidorenko, "Minimum bias multiple taper spectral
   estimation", IEEE Trans. Signal Process. 43, 188–195 (1995).
.. [5] P. McCullagh & J. A. Nelder, *Generalized Linear Models*, 2nd ed. (1989).
.. [6] E. B. Wilson & M. M. Hilferty, "The distribution of chi-square", PNAS 17,
   684–688 (1931).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import gamma as _gamma

from accal.estimators.trend import METHODS, _grid_index, _on_grid

__all__ = [
    "NoiseSpectrum",
    "noise_spectra",
    "noise_spectrum",
    "pooled_covariance",
    "spectral_const",
]

#: Power-law exponents β of the grid (spectrum ∝ f^−(1+β)).
BETAS = np.round(np.arange(-0.5, 1.951, 0.1), 2)
#: AR(1) time constants of the grid, as fractions of the day's grid length.
TAUS_PER_N = np.geomspace(1 / 400, 1 / 2, 16)
#: Whittle band: Fourier bins 1 … K_BAND of the day.
K_BAND = 400
#: Narrower bands tried, widest first, when the model does not fit the wider one: the
#: estimators' weights are at the lowest bins (|G(f)|² ∝ f⁻² for the bias), and a
#: spectrum that rises again above ~1 mHz (QA: the tests' realistic L1B noise, 3× from
#: bin 40 to 100) is no misfit of the part that matters.
NARROWER_BANDS = (200, 100, 50)
#: Fewer samples or bins: no model (the day's own estimate stays).
MIN_N = 400
MIN_BINS = 32
#: A Lorentzian must raise the log-likelihood this much over the best power law.
LORENTZ_MARGIN = 2.0
#: A coloured model is kept only if it raises the Whittle log-likelihood this much
#: over white noise (BIC-like for 2 extra parameters, ×2 for the correlation of
#: neighbouring tapered ordinates).
COLOURED_MARGIN = 10.0
#: An ordinate above this many times its fitted expectation (one day) is a line or
#: a band: left out with ±LINE_NEIGHBOURS bins and the fit repeated.
LINE_FACTOR = 12.0
LINE_NEIGHBOURS = 2
#: Log-spaced groups of the goodness-of-fit test, and its flag level.
GOF_GROUPS = 10
GOF_P_FLAG = 1e-4
#: Weight of one day's deviance in the test of the day against its pool (:func:`_day_misfit`):
#: ½ for the correlation of neighbouring tapered ordinates (each is worth about half an
#: independent one; at weight 1 stationary days were flagged on 1-4 % of the pools).
DAY_GOF_WEIGHT = 0.5


# --------------------------------------------------------------------- the models


def _taper(n_grid: int) -> NDArray[np.float64]:
    """The first sine taper ``sin(π(t + ½)/N)`` (sidelobes ∝ k⁻⁴ in power)."""
    return np.sin(np.pi * (np.arange(n_grid) + 0.5) / n_grid)


def _red_lags(beta: float, h: NDArray[np.float64], nugget: float | None = None):
    """``K_β(h) = −(h^β − 1)/β`` (``β = 0``: ``−log h``) for ``h ≥ 1``; ``K(0) = ν_β``."""
    hh = np.maximum(h, 1.0)
    k = -np.log(hh) if abs(beta) < 1e-9 else -(hh**beta - 1.0) / beta
    if nugget is None:
        nugget = _nugget_cached(round(float(beta), 6))
    return np.where(h == 0, k + nugget, k)  # K(1) = 0


def _nugget(beta: float, n: int) -> float:
    """Smallest ``K(0) − K(1)`` that makes ``K_β`` CPD of order 1 on the integers.

    The second difference ``y_t = x_t − 2x_{t−1} + x_{t−2}`` of the process is
    stationary with covariance ``Σ_ij a_i a_j K(h + i − j)``, ``a = (1, −2, 1)``; a
    nugget ``ν`` adds ``16 ν sin⁴(πf)`` to its spectrum, so ``ν_min = max_f
    [−S_y(f)/(16 sin⁴ πf)]`` (lags below ``n``), times 1.05.
    """
    h = np.arange(0, n + 3, dtype=float)
    k = _red_lags(beta, h, nugget=0.0)
    kk = np.concatenate([k[::-1][:-1], k])
    c = kk[:-4] - 4 * kk[1:-3] + 6 * kk[2:-2] - 4 * kk[3:-1] + kk[4:]
    spec = np.real(np.fft.fft(np.fft.ifftshift(c)))
    s4 = 16 * np.sin(np.pi * np.fft.fftfreq(c.size)) ** 4
    ok = s4 > 1e-3
    return float(max(0.0, np.max(-spec[ok] / s4[ok])) * 1.05 + 1e-12)


@functools.lru_cache(maxsize=64)
def _nugget_cached(beta: float) -> float:
    return _nugget(beta, 4096)


def spectral_const(beta: float) -> float:
    """``c_β`` of the low-frequency spectrum ``c_β |f|^−(1+β)`` of ``K_β`` (two-sided,
    per grid step): ``Γ(1+β) sin(πβ/2) / (βπ(2π)^β)``, ``½`` at ``β = 0``."""
    if abs(beta) < 1e-9:
        return 0.5
    return (
        _gamma(1 + beta) * math.sin(math.pi * beta / 2) / (beta * math.pi * (2 * math.pi) ** beta)
    )


# --------------------------------------------------------------------- one layout


@dataclass(frozen=True)
class _Layout:
    """What depends on the sample layout and the weights only (module notes).

    ``w`` (K,), ``h`` (S, K): expectations of the tapered periodogram per unit white
    variance and per unit red amplitude of each shape; ``white_cov`` (p, p) and
    ``covs`` (S, p, p): ``G Gᵀ`` and ``G C_θ Gᵀ`` (bias row by the rule of the notes).
    """

    idx: NDArray[np.int64] | None
    n_grid: int
    taper: NDArray[np.float64]
    w: NDArray[np.float64]
    h: NDArray[np.float64]
    white_cov: NDArray[np.float64]
    covs: NDArray[np.float64]
    shapes: tuple[str, ...]


def _layout(t: NDArray[np.float64], g: NDArray[np.float64], order: int) -> _Layout:
    n = t.size
    idx, n_grid = _grid_index(t)
    kmax = int(min(K_BAND, (n_grid - 1) // 2))
    k = np.arange(1, kmax + 1)
    mask = _on_grid(np.ones((1, n)), idx, n_grid)[0]
    taper = _taper(n_grid) * mask
    gg = _on_grid(g, idx, n_grid)
    v = np.vander(t - t[0], order + 1, increasing=True)
    vg = _on_grid(np.ascontiguousarray(v.T), idx, n_grid) * taper[None, :]
    a = np.conj(np.fft.fft(vg, axis=1)[:, k])  # a_k = Vᵀ(u z_k)
    fm = np.fft.rfft(taper, 2 * n_grid)
    m_lag = np.fft.irfft(fm * np.conj(fm), 2 * n_grid)[:n_grid]  # Σ_t u_t u_{t+h}
    fg2 = np.fft.rfft(gg, 2 * n_grid, axis=1)

    def expect(lags: NDArray[np.float64]):
        """E|R_k|² (k = 1 … K), G C Gᵀ and C g_j at t0 for the covariance ``lags``."""
        x = lags * m_lag
        t1 = 2 * np.real(np.fft.fft(x)[k]) - x[0]
        circ = np.concatenate([lags, [0.0], lags[:0:-1]])
        y = np.fft.irfft(fg2 * np.fft.rfft(circ)[None, :], 2 * n_grid, axis=1)[:, :n_grid]
        y *= mask[None, :]
        zy = np.fft.fft(y * taper[None, :], axis=1)[:, k]
        gcg = gg @ y.T
        gcg = 0.5 * (gcg + gcg.T)
        cross = np.sum(zy * a, axis=0)
        quad = np.einsum("ik,ij,jk->k", np.conj(a), gcg, a).real
        return t1 - 2 * cross.real + quad, gcg, y[:, 0].copy()

    white = np.zeros(n_grid)
    white[0] = 1.0
    w, white_cov, _ = expect(white)
    # the bias row of the power laws under "stationary, flat below 1/(2T)"
    tt = np.arange(n_grid)
    gf = np.fft.fft(gg * np.exp(-1j * np.pi * tt / n_grid)[None, :], axis=1)
    f = np.maximum(np.minimum((tt + 0.5) / n_grid, 1 - (tt + 0.5) / n_grid), 0.5 / n_grid)
    pair = np.real(gf[:, None, :] * np.conj(gf[None, :, :]))
    hs, covs, shapes = [], [], []
    for beta in BETAS:
        lags = _red_lags(float(beta), np.arange(n_grid, dtype=float))
        h, cov, y0 = expect(lags)
        pinned = cov.copy()  # error (g_b − δ_t0)ᵀ red
        pinned[0, 0] = cov[0, 0] - 2 * y0[0] + lags[0]
        pinned[0, 1:] = pinned[1:, 0] = cov[0, 1:] - y0[1:]
        stat = cov.copy()
        v_stat = pair @ (spectral_const(float(beta)) * f ** -(1.0 + beta)) / n_grid
        stat[0, :], stat[:, 0] = v_stat[0, :], v_stat[:, 0]
        hs.append(h)
        covs.append(pinned if pinned[0, 0] < stat[0, 0] else stat)
        shapes.append(f"power law beta={beta:.2f}")
    for frac in TAUS_PER_N:
        tau = frac * n_grid
        h, cov, _ = expect(np.exp(-np.arange(n_grid) / tau))
        hs.append(h)
        covs.append(cov)
        shapes.append(f"AR(1) tau={tau:.4g} steps")
    return _Layout(idx, n_grid, taper, w, np.array(hs), white_cov, np.array(covs), tuple(shapes))


@functools.lru_cache(maxsize=4)
def _uniform_layout(n: int, step: float, method: str, order: int) -> _Layout:
    t = np.arange(n) * step
    return _layout(t, METHODS[method](t, order), order)


# --------------------------------------------------------------------- per day


@dataclass(frozen=True)
class NoiseSpectrum:
    """One day's low-frequency residual spectrum and its model expectations.

    Attributes
    ----------
    periodogram : ndarray, shape (K,)
        ``|R_k|²`` of the tapered residual, bins 1 … K [(m/s²)²].
    white : ndarray, shape (K,)
        Its expectation per unit white variance.
    shapes : ndarray, shape (S, K)
        Its expectation per unit amplitude of each red shape (:attr:`names`).
    white_cov, covs : ndarray, shapes (p, p) and (S, p, p)
        ``G Gᵀ`` and ``G C_θ Gᵀ`` of the estimators (weights ``G``).
    names : tuple of str
        The red shapes.
    """

    periodogram: NDArray[np.float64]
    white: NDArray[np.float64]
    shapes: NDArray[np.float64]
    white_cov: NDArray[np.float64]
    covs: NDArray[np.float64]
    names: tuple[str, ...]

    def to_arrays(self, prefix: str = "") -> dict[str, NDArray]:
        """The fields as arrays (``numpy.savez``); :meth:`from_arrays` reads them."""
        out = {f: getattr(self, f) for f in ("periodogram", "white", "white_cov", "covs")}
        out["shapes"] = self.shapes.astype(np.float32)  # ~7 digits: far below the fit's
        out["names"] = np.array(self.names)
        return {prefix + k: v for k, v in out.items()}

    @classmethod
    def from_arrays(cls, arrays: Any, prefix: str = "") -> NoiseSpectrum:
        """Inverse of :meth:`to_arrays` (a mapping such as a ``numpy.load`` result)."""
        get = lambda k: np.asarray(arrays[prefix + k])  # noqa: E731
        return cls(
            get("periodogram").astype(float),
            get("white").astype(float),
            get("shapes").astype(float),
            get("white_cov").astype(float),
            get("covs").astype(float),
            tuple(str(s) for s in get("names")),
        )


def noise_spectrum(
    t: ArrayLike, residual: ArrayLike, weights: ArrayLike, *, order: int = 1, method: str = ""
) -> NoiseSpectrum | None:
    """The :class:`NoiseSpectrum` of one day's trend residual.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times of the used samples, increasing [s].
    residual : array_like, shape (n,)
        Data − fitted trend on those samples [m/s²].
    weights : array_like, shape (order + 1, n)
        The estimator's weights (:func:`~accal.estimators.trend.wavelet_weights` or
        :func:`~accal.estimators.trend.lsq_weights`).
    order : int
        Order of the fitted polynomial.
    method : str, optional
        The weights' method name; with it, a uniform layout's expectations are
        computed once per (n, step) and shared (they cost ~1.5 s for a 1 Hz day).

    Returns
    -------
    NoiseSpectrum or None
        None when the record is too short for the model (fewer than
        :data:`MIN_N` samples or :data:`MIN_BINS` bins).
    """
    r = np.asarray(residual, dtype=np.float64)
    return noise_spectra(t, r[None, :], weights, order=order, method=method)[0]


def noise_spectra(
    t: ArrayLike, residuals: ArrayLike, weights: ArrayLike, *, order: int = 1, method: str = ""
) -> list[NoiseSpectrum | None]:
    """:func:`noise_spectrum` of each row of ``residuals`` (shape (k, n)) on the same
    samples: the layout's expectations are computed once."""
    t = np.asarray(t, dtype=np.float64)
    res = np.atleast_2d(np.asarray(residuals, dtype=np.float64))
    g = np.atleast_2d(np.asarray(weights, dtype=np.float64))
    n = t.size
    if n < MIN_N or g.shape != (order + 1, n) or res.shape[1] != n:
        return [None] * res.shape[0]
    d = np.diff(t)
    if method in METHODS and d.min() == d.max():
        lay = _uniform_layout(n, float(d[0]), method, order)
    elif (_grid_index(t)[1] - 1) // 2 < MIN_BINS:
        return [None] * res.shape[0]
    else:
        lay = _layout(t, g, order)
    if lay.w.size < MIN_BINS:
        return [None] * res.shape[0]
    grid = _on_grid(res, lay.idx, lay.n_grid) * lay.taper[None, :]
    spec = np.fft.fft(grid, axis=1)[:, 1 : lay.w.size + 1]
    power = spec.real**2 + spec.imag**2
    return [
        NoiseSpectrum(power[j], lay.w, lay.h, lay.white_cov, lay.covs, lay.shapes)
        for j in range(res.shape[0])
    ]


# --------------------------------------------------------------------- the fit


def _whittle(p: NDArray, w: NDArray, h: NDArray, iters: int = 30):
    """``W, A ≥ 0`` maximising ``−Σ[log E + P/E]``, ``E = W w + A h``, for every row of
    ``h`` (IRLS: the Gamma GLM score ``Σ (P − E)/E² x = 0``, McCullagh & Nelder 1989).
    Returns ``W``, ``A``, the log-likelihoods."""
    k_low = max(3, p.size // 50)
    scale = float(np.mean(p / w))
    big_w = np.full(h.shape[0], scale)
    amp = np.maximum(np.mean(p[:k_low]) - scale * np.mean(w[:k_low]), 0.0)
    big_a = 0.5 * amp / np.maximum(np.mean(h[:, :k_low], axis=1), 1e-300)
    for _ in range(iters):
        e = np.maximum(big_w[:, None] * w[None, :] + big_a[:, None] * h, 1e-30 * scale)
        q = 1.0 / e**2
        a11, a12, a22 = q @ (w * w), np.sum(q * w * h, axis=1), np.sum(q * h * h, axis=1)
        b1, b2 = q @ (w * p), np.sum(q * h * p, axis=1)
        det = a11 * a22 - a12**2
        w_new = (a22 * b1 - a12 * b2) / det
        a_new = (a11 * b2 - a12 * b1) / det
        neg_a = a_new < 0  # a bound active: the other parameter alone
        w_new, a_new = np.where(neg_a, b1 / a11, w_new), np.where(neg_a, 0.0, a_new)
        neg_w = w_new < 0
        a_new, w_new = np.where(neg_w, b2 / a22, a_new), np.where(neg_w, 0.0, w_new)
        big_w, big_a = w_new, np.maximum(a_new, 0.0)
    e = np.maximum(big_w[:, None] * w[None, :] + big_a[:, None] * h, 1e-30 * scale)
    return big_w, big_a, -np.sum(np.log(e) + p[None, :] / e, axis=1)


def _select(p, w, h, kinds, use, weight):
    """The model of the bins ``use``: white unless a coloured shape gains
    :data:`COLOURED_MARGIN`; a Lorentzian only if it beats the best power law by
    :data:`LORENTZ_MARGIN`.  ``weight``: days pooled (``D ×`` the mean's likelihood)."""
    pu, wu = p[use], w[use]
    w0 = float(np.mean(pu / wu))
    ll0 = -weight * float(np.sum(np.log(w0 * wu) + pu / (w0 * wu)))
    big_w, big_a, ll = _whittle(pu, wu, h[:, use])
    ll = weight * ll
    power = kinds == "pow"
    s_pow = np.flatnonzero(power)[np.argmax(ll[power])]
    s_ar = np.flatnonzero(~power)[np.argmax(ll[~power])]
    s = s_ar if ll[s_ar] > ll[s_pow] + LORENTZ_MARGIN else s_pow
    if ll[s] - ll0 < COLOURED_MARGIN or big_a[s] <= 0:
        return {"W": w0, "A": 0.0, "s": -1, "E": w0 * w}
    e = np.maximum(big_w[s] * w + big_a[s] * h[s], 1e-300)
    return {"W": big_w[s], "A": big_a[s], "s": int(s), "E": e, "Ws": big_w, "As": big_a, "ll": ll}


def _gof(p, e, weight):
    """Gamma deviance of log-spaced groups of ``P/E`` and its upper tail (χ² with
    groups − 3 degrees of freedom, Wilson & Hilferty 1931)."""
    edges = np.unique(np.geomspace(1, p.size + 1, GOF_GROUPS + 1).astype(int) - 1)
    dev, groups = 0.0, 0
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b > a:
            rho = p[a:b].sum() / e[a:b].sum()
            dev += 2 * weight * (b - a) * ((rho - 1) - math.log(rho))
            groups += 1
    dof = max(groups - 3, 1)
    c = 2.0 / (9.0 * dof)
    z = ((dev / dof) ** (1 / 3) - (1 - c)) / math.sqrt(c)
    return 0.5 * math.erfc(z / math.sqrt(2))


def _refined(target: NoiseSpectrum, fit: dict, kinds: NDArray) -> NDArray[np.float64]:
    """The covariance at the vertex of the profile likelihood's parabola through the
    best shape and its neighbours of the same family (the grid step, 0.1 in β, moves
    σ by up to ~25 % for 1/f noise): variances interpolated geometrically,
    covariances linearly."""
    s = fit["s"]

    def cov_at(j):
        return fit["Ws"][j] * target.white_cov + fit["As"][j] * target.covs[j]

    cov = cov_at(s)
    if not (0 < s < kinds.size - 1 and kinds[s - 1] == kinds[s] == kinds[s + 1]):
        return cov
    y0, y1, y2 = fit["ll"][s - 1 : s + 2]
    curv = y0 - 2 * y1 + y2
    if not curv < 0:
        return cov
    delta = float(np.clip(0.5 * (y0 - y2) / curv, -0.5, 0.5))
    other = cov_at(s + 1 if delta > 0 else s - 1)
    wgt = abs(delta)
    out = (1 - wgt) * cov + wgt * other
    diag = np.exp((1 - wgt) * np.log(np.diag(cov)) + wgt * np.log(np.diag(other)))
    out[np.diag_indices_from(out)] = diag
    return out


def _fit_band(p, w, h, kinds, weight):
    """The model of bins ``1 … len(p)``, lines left out: ``(fit, p_misfit, n_lines)``.

    Ordinates above ``1 + (LINE_FACTOR − 1)/√D`` times the fitted expectation (the
    mean of ``D`` days' ordinates) are left out with their neighbours and the fit is
    repeated (at most 4 times).
    """
    use = np.ones(p.size, bool)
    factor = 1.0 + (LINE_FACTOR - 1.0) / math.sqrt(weight)
    for _ in range(4):
        fit = _select(p, w, h, kinds, use, weight)
        lines = p / fit["E"] > factor
        if not np.any(lines & use):
            break
        grow = lines.copy()
        for d in range(1, LINE_NEIGHBOURS + 1):
            grow[d:] |= lines[:-d]
            grow[:-d] |= lines[d:]
        use &= ~grow
        if use.sum() < MIN_BINS:
            break
    return fit, _gof(p[use], fit["E"][use], weight), int(np.sum(~use))


def _day_misfit(target: NoiseSpectrum, fit: dict, band: int) -> float:
    """The goodness-of-fit tail (:func:`_gof`, one day) of ``target``'s own periodogram
    over bins ``1 … band`` against the pooled model's expectation on its layout.

    The pool assumes one stationary process over its days.  A QA pass found what that
    costs when it is not so: a day with a large slow bump got its neighbours' σ (2.1e-11
    against its own 6.0e-11 m/s², |z| 7.8), and days whose white level differed 3× were
    pooled as one (the noisy days' σ 1.1–1.2× too small).  Such a day keeps its own σ.
    """
    s = fit["s"]
    e = fit["W"] * target.white[:band]
    if s >= 0:
        e = e + fit["A"] * target.shapes[s, :band]
    return _gof(target.periodogram[:band], np.maximum(e, 1e-300), DAY_GOF_WEIGHT)


def pooled_covariance(
    target: NoiseSpectrum, others: Sequence[NoiseSpectrum] = ()
) -> tuple[NDArray[np.float64] | None, dict[str, Any]]:
    """Covariance of ``target``'s estimators under the noise model fitted to it and
    ``others`` (adjacent days, the same process; module notes).

    Parameters
    ----------
    target : NoiseSpectrum
        The day whose covariance is wanted.
    others : sequence of NoiseSpectrum
        Other days pooled into the fit (same number of bins; others are left out).

    Returns
    -------
    cov : ndarray, shape (p, p), or None
        None when the spectrum is a misfit to the model (keep the day's own
        estimate then).
    info : dict
        ``days`` pooled, ``model`` (a description), ``misfit`` (bool), ``p_misfit``
        (the goodness-of-fit tail), ``lines`` (bins left out), ``bins`` (the band
        fitted: the widest of ``K_BAND`` and :data:`NARROWER_BANDS` the model fits).
    """
    days = [target, *[o for o in others if o.periodogram.size == target.periodogram.size]]
    weight = float(len(days))
    p = np.mean([d.periodogram for d in days], axis=0)
    w = np.mean([d.white for d in days], axis=0)
    h = np.mean([d.shapes for d in days], axis=0)
    kinds = np.array(["pow" if n.startswith("power") else "ar" for n in target.names])
    info: dict[str, Any] = {"days": len(days)}
    for band in (p.size, *[b for b in NARROWER_BANDS if MIN_BINS <= b < p.size]):
        fit, p_misfit, n_lines = _fit_band(p[:band], w[:band], h[:, :band], kinds, weight)
        info.update(p_misfit=p_misfit, lines=n_lines, bins=band)
        info["model"] = "white" if fit["s"] < 0 else f"white + {target.names[fit['s']]}"
        info["misfit"] = bool(p_misfit < GOF_P_FLAG or n_lines > 0)
        if not info["misfit"]:
            break
    if info["misfit"]:
        return None, info
    if len(days) > 1:  # the pool's model must describe this day too (QA, 2026-11-30)
        day_p = _day_misfit(target, fit, band)
        info["p_day"] = day_p
        if day_p < GOF_P_FLAG:
            info.update(misfit=True, day_differs=True)
            return None, info
    cov = _refined(target, fit, kinds) if fit["s"] >= 0 else fit["W"] * target.white_cov
    cov = 0.5 * (cov + cov.T)  # exactly symmetric (the products above are to rounding)
    # floor: white noise at the band's mean level (not the residual's variance: content
    # above the band, e.g. real L1B noise at 10-100 mHz, does not reach the estimates)
    var = np.diag(cov)
    floor = float(np.mean(p[:band] / w[:band])) * np.diag(target.white_cov)
    scale = np.sqrt(np.maximum(1.0, floor / np.maximum(var, 1e-300)))
    return cov * (scale[:, None] * scale[None, :]), info
