"""Low-frequency noise model of a fit residual: Whittle fit of ``W + A·L(f)``.

The uncertainty of a bias or drift estimated over one record is set by the noise
at the record's lowest Fourier frequencies (``f ≲ 2/T``), a handful of
periodogram ordinates that scatter like χ²₂.  Averaging them (three per bin)
gave σ that scattered by 25–32 % from day to day, and the periodogram of a
detrended red process is distorted at exactly those frequencies (the fit removes
power, the record's ends leak it).  This module fits a parametric spectrum to the
lowest few hundred ordinates instead, so that the lowest ones borrow strength
from the rest.

Model (two-sided PSD per grid step, ``f`` in cycles per step)::

    S(f) = W + A·L_θ(f),   L_θ ∈ {(f/f_ref)^(−α), α ∈ [0, 2.5]}  (power law)
                               ∪ {AR(1) with corner f_L ≥ 2/T}  (Lorentzian)

the AR(1) shape being ``(1 − φ)²/((1 − φ)² + 4φ sin²(πf))``, ``φ = e^{−2π f_L}``
(the spectrum of a sampled AR(1) process, ≈ ``1/(1 + (f/f_L)²)`` below Nyquist/10)

``W`` is white noise, ``A`` the coloured part's level at ``f_ref`` (the geometric
centre of the band, power law) or at ``f = 0`` (Lorentzian).  A Lorentzian corner
below ``2/T`` is not in the grid: the record cannot show it.

Ordinates.  ``k = 1 … 4`` (:data:`LOW_BINS`): the plain periodogram of the
residual, ``|Σ_t r_t z_k^t|²/n``, whose expectation ``∫ |C_k(f)|² S(f) df / n``
(``c_k = (I − VG)ᵀ z_k``: the fit's projection and the record's leakage included)
the caller computes exactly and passes to :meth:`LowFreqSpectrum.add_low`.
``k = 7 … K`` (``K = 400``): prewhitened and tapered (Percival & Walden 1993,
§6.5–6.7): the first differences ``d_t = r_{t+1} − r_t`` of the residual on the
nominal grid, only where both samples are used, times a Hann taper ``h``; with
``a = h·mask``, ``I_k = |Σ_t a_t d_t e^{−2πi k t/N}|² / Σ a_t²``.  Differencing
turns ``S`` into ``S_d(f) = 4 sin²(πf)·S(f)``, flat for a random walk and at most
``f^(−0.5)`` steep for ``α ≤ 2.5``, so the taper's sidelobes (decaying as
``Δ⁻⁶``) leak nothing that matters; and it removes the fitted polynomial's
constant, which the Hann taper confines to ``k ≤ 1``.  Their expectation is
``E[I_k] = W·w_k + A·b_k(θ)`` with

* ``w_k = 2 − 2ρ cos(2π f_k)``, ``ρ = Σ a_t a_{t+1} / Σ a_t²``, exact for white
  noise and any mask (``E|Σ c_s e_s|² = W Σ |c_s|²``); a gap's edges put a floor
  ``2W(1 − ρ)`` under the differenced white spectrum, which this term carries;
* ``b_k(θ) = ∫ K_H(f − f_k) S_d,θ(f) df`` with ``K_H`` the Hann spectral window
  (unit area; evaluated on 1/8-bin steps over ±6 bins below bin 64, where
  ``S_d`` bends within a few bins; above it ``S_d(f_k)`` itself, < 1e-3 off).

Fit: Whittle's (1953) likelihood ``ℓ = −Σ_k [log E_k + I_k/E_k]`` (the "local"
Whittle band of Robinson 1995), maximised over ``W, A ≥ 0`` for every shape of
the grid (iteratively reweighted least squares, the Gamma-GLM form of the
Whittle score).  White noise alone is kept unless a coloured shape raises ``ℓ``
by more than :data:`COLOURED_MARGIN`; otherwise the best shape is taken, a
Lorentzian only if better than the best power law by :data:`LORENTZ_MARGIN`
(a corner must be seen to be believed), refined by a parabola through the
profile likelihood at its grid neighbours.  Bayesian model averaging of the
covariance (weights ``∝ exp(ℓ_θ)``, uniform priors) was tried and not kept: over
both families it was biased high by 30 % in variance for an AR(1) with its
corner at 25/T (a power law and an AR(1) that fit alike can differ by 4× in
σ²), within the chosen family by 22 %, against 14 % for the best shape; it did
lower the share of random-walk days with ``|z| > 3`` (2.5–4 % against 6–7 %).

What limits σ's day-to-day scatter: the extrapolation from the band's centre
(``~30/T``) to ``~0.7/T``, where the drift weights have their power, multiplies
the error of ``α̂`` by ``ln 40 ≈ 3.7`` (in ``ln S``).  With ``α̂`` uncertain by
≈ 0.1 over 400 ordinates, σ scatters by 30–45 % for red noise (3–7 % for white
noise, whose model has no slope).  A model with fixed exponents (white +
flicker + random walk + Markov, the noise terms of IEEE Std 952-1997, Annex C)
was tried and not kept: its terms trade against each other inside the band and
σ scattered as much, with 10 % of random-walk days at ``|z| > 3``.

Goodness of fit: the tapered band is cut into :data:`GOF_GROUPS` log-spaced
groups of at least 8 ordinates; ``X = Σ_g 2(m_g/c)[(ρ_g − 1) − ln ρ_g]``, the
Gamma deviance of the ratio ``ρ_g = ΣI/ΣE`` of each group (``m_g`` ordinates,
``c = 1 + 2·(2/3)² + 2·(1/6)²`` the variance inflation of neighbouring
Hann-tapered ordinates), is referred to χ² with ``groups − 3`` degrees of
freedom (tail by Wilson & Hilferty 1931).

References
----------
.. [1] P. Whittle, "Estimation and information in stationary time series",
   Ark. Mat. 2, 423–434 (1953).
.. [2] P. M. Robinson, "Gaussian semiparametric estimation of long range
   dependence", Ann. Statist. 23, 1630–1661 (1995).
.. [3] D. B. Percival & A. T. Walden, *Spectral Analysis for Physical
   Applications*, Cambridge University Press (1993), ch. 6 (tapering,
   prewhitening by differencing).
.. [4] E. B. Wilson & M. M. Hilferty, "The distribution of chi-square",
   PNAS 17, 684–688 (1931).
.. [5] P. McCullagh & J. A. Nelder, *Generalized Linear Models*, 2nd ed.,
   Chapman & Hall (1989).
.. [6] IEEE Std 952-1997, *IEEE Standard Specification Format Guide and Test
   Procedure for Single-Axis Interferometric Fiber Optic Gyros*, Annex C.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ALPHAS",
    "GOF_P_FLAG",
    "LOW_BINS",
    "MAX_BIN",
    "LowFreqModel",
    "LowFreqSpectrum",
    "shape_values",
]

#: Power-law exponents of the shape grid (refined by a parabola between nodes).
ALPHAS = np.round(np.arange(0.0, 2.5001, 0.1), 2)
#: Lorentzian corners of the shape grid, in units of 1/T (T: the record's span).
CORNERS_PER_RECORD = np.geomspace(2.0, 200.0, 25)
#: Upper end of the Whittle band [Fourier bins of the record].
MAX_BIN = 400
#: Lowest ordinate of the tapered periodogram (k = 0, 1 hold the trend fit's
#: constant through the taper) when no exact low bins are given.
MIN_BIN = 2
#: Bins 1 … LOW_BINS are taken from the plain periodogram of the residual, with
#: their exact expectation (see :class:`LowFreqSpectrum`); the tapered one then
#: starts at LOW_BINS + 3 (clear of their main lobes).
LOW_BINS = 4
#: The coloured part is kept only if it raises the log-likelihood by more than this
#: over white noise alone: 6 (BIC-like for two more parameters over ~400
#: ordinates) times ~2, as neighbouring Hann-tapered ordinates are correlated and
#: the Whittle ℓ, which takes them as independent, overstates the evidence about
#: twofold (:data:`HANN_INFLATION`).  With 6, white days with gaps took a coloured
#: model ~1 time in 8, and σ doubled on them.
COLOURED_MARGIN = 12.0
#: A Lorentzian is chosen over the best power law only above this log-likelihood gain.
LORENTZ_MARGIN = 2.0
#: Groups of the goodness-of-fit statistic.
GOF_GROUPS = 12
#: A tapered ordinate above this many times its expectation is a line: left out
#: of the fit, its excess power added to the covariance at its own frequency.
LINE_FACTOR = 12.0
#: Lines at or below this bin take the low ordinates out of the fit.
LINE_NEAR = 60
#: Length of the taper's ramps at gap edges [grid steps].
GAP_RAMP = 64
#: Fewest ordinates in a goodness-of-fit group.
GOF_MIN_GROUP = 8
#: Flag threshold: the misfit note is raised below this χ² tail probability.
GOF_P_FLAG = 1e-4
#: Variance inflation of a sum of neighbouring Hann-tapered ordinates.
HANN_INFLATION = 1.0 + 2.0 * (2.0 / 3.0) ** 2 + 2.0 * (1.0 / 6.0) ** 2


@dataclass(frozen=True)
class LowFreqModel:
    """The fitted low-frequency noise model of one residual.

    Attributes
    ----------
    kind : str
        ``"white"``, ``"power"`` or ``"lorentzian"``.
    white : float
        ``W``, the white level, two-sided PSD per grid step [m²/s⁴ per cycle/step].
    amplitude : float
        ``A``, the coloured part's level at ``f_ref`` (power law) or at 0 (Lorentzian).
    alpha : float
        Power-law exponent (NaN for a Lorentzian).
    corner : float
        Lorentzian corner [cycles/step] (NaN for a power law).
    f_ref : float
        Reference frequency of the power law [cycles/step].
    step : float
        Grid step [s].
    chi2, dof, p_misfit : float, int, float
        Goodness of fit of the binned periodogram (see the module notes).
    """

    kind: str
    white: float
    amplitude: float
    alpha: float
    corner: float
    f_ref: float
    step: float
    chi2: float
    dof: int
    p_misfit: float

    def psd(self, f: ArrayLike) -> NDArray[np.float64]:
        """Two-sided PSD at frequencies ``f`` [Hz] -> [m²/s⁴/Hz]."""
        nu = np.abs(np.asarray(f, dtype=np.float64)) * self.step
        with np.errstate(divide="ignore"):
            if self.kind == "white":
                shape = np.zeros_like(nu)
            elif self.kind == "power":
                shape = (nu / self.f_ref) ** -self.alpha
            else:
                phi = np.exp(-2.0 * np.pi * self.corner)
                shape = (1.0 - phi) ** 2 / ((1.0 - phi) ** 2 + 4.0 * phi * np.sin(np.pi * nu) ** 2)
        return (self.white + self.amplitude * shape) * self.step


def hann_window_kernel(radius: int = 6, sub: int = 8) -> tuple[NDArray, NDArray]:
    """Offsets [bins] and weights of the Hann taper's spectral window.

    ``|H(δ)|² ∝ [sinc(δ)/(1 − δ²)]²`` (the DTFT of ``sin²(πt/L)`` for large ``L``,
    Percival & Walden 1993, §6.6), sampled at the midpoints of ``1/sub``-bin
    steps over ``±radius`` bins and normalised to unit sum (the power beyond 6
    bins is below 1e-5 of the total).
    """
    step = 1.0 / sub
    d = -radius + (np.arange(2 * radius * sub) + 0.5) * step
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.sinc(d) / (1.0 - d**2)
    h[np.isclose(np.abs(d), 1.0)] = 0.5  # the limit at |δ| = 1
    k = h**2
    return d, k / k.sum()


@functools.lru_cache(maxsize=8)
def _shape_table(ngrid: int, kmax: int) -> tuple[NDArray, NDArray, NDArray, float]:
    """``(kinds, params, b, f_ref)`` of the shape grid for a grid of ``ngrid`` points.

    ``kinds``: 0 power law, 1 Lorentzian; ``params``: α or ``f_L`` [cycles/step];
    ``b``: shape (n_shapes, kmax − 1), the expectations ``b_k(θ)`` of the module
    notes for ``k = 2 … kmax``.  Read-only (cached).
    """
    k = np.arange(MIN_BIN, kmax + 1, dtype=np.float64)
    f_ref = math.sqrt(MIN_BIN * kmax) / ngrid
    kinds = np.concatenate([np.zeros(ALPHAS.size), np.ones(CORNERS_PER_RECORD.size)])
    params = np.concatenate([ALPHAS, CORNERS_PER_RECORD / ngrid])
    offs, wts = hann_window_kernel()
    # the window's convolution matters where S_d bends within a few bins (low k);
    # above bin 64 it changes S_d(f_k) by < 1e-3 and S_d(f_k) is used as it is
    near = k < 64
    f = np.abs(k[near, None] + offs[None, :]) / ngrid  # (nk, noffs), never 0
    sd = 4.0 * np.sin(np.pi * f) ** 2
    b = np.empty((kinds.size, k.size))
    b[:, near] = np.einsum("skj,j->sk", shape_values(kinds, params, f_ref, f) * sd[None], wts)
    f = k[~near] / ngrid
    b[:, ~near] = shape_values(kinds, params, f_ref, f) * (4.0 * np.sin(np.pi * f) ** 2)
    for arr in (kinds, params, b):
        arr.setflags(write=False)
    return kinds, params, b, f_ref


def shape_values(
    kinds: NDArray, params: NDArray, f_ref: float, f: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``L_θ(f)`` for every shape (leading axis) at frequencies ``f`` [cycles/step] (> 0)."""
    out = np.empty((kinds.size, *f.shape))
    power = kinds == 0
    logf = np.log(f / f_ref)
    out[power] = np.exp(-params[power].reshape(-1, *([1] * f.ndim)) * logf)
    fl = params[~power].reshape(-1, *([1] * f.ndim))
    # the sampled AR(1) spectrum with φ = exp(−2π f_L): (1 − φ)² / ((1 − φ)² + 4φ sin²πf),
    # the Lorentzian 1/(1 + (f/f_L)²) for f, f_L ≪ 1 and exact up to the Nyquist frequency
    phi = np.exp(-2.0 * np.pi * fl)
    out[~power] = (1.0 - phi) ** 2 / ((1.0 - phi) ** 2 + 4.0 * phi * np.sin(np.pi * f) ** 2)
    return out


def _chi2_sf(x: float, dof: int) -> float:
    """Upper tail of χ² with ``dof`` degrees of freedom (Wilson & Hilferty 1931)."""
    if dof <= 0:
        return float("nan")
    c = 2.0 / (9.0 * dof)
    z = ((max(x, 0.0) / dof) ** (1.0 / 3.0) - (1.0 - c)) / math.sqrt(c)
    return 0.5 * math.erfc(z / math.sqrt(2.0))


def _refine(ll: NDArray, j: int, lo: int, hi: int) -> tuple[int, int, float]:
    """Vertex of the parabola through ``ll[j−1 : j+2]`` (within ``lo … hi−1``).

    Returns ``(j, neighbour, weight)`` for a linear interpolation towards the vertex.
    """
    if lo < j < hi - 1:
        y0, y1, y2 = ll[j - 1], ll[j], ll[j + 1]
        curv = y0 - 2.0 * y1 + y2
        if curv < 0:
            delta = float(np.clip(0.5 * (y0 - y2) / curv, -0.5, 0.5))
            return j, j + (1 if delta > 0 else -1), abs(delta)
    return j, j, 0.0


def _gap_ramps(mask: NDArray[np.bool_], length: int = GAP_RAMP) -> NDArray[np.float64]:
    """``mask`` as 0/1 with ``sin²`` ramps of ``length`` samples inside each gap edge.

    A taper that drops abruptly to 0 at a gap puts a broadband floor
    ``2W·Σ(Δa)²/Σa²`` under the differenced white spectrum (the ``1 − ρ`` of the
    module notes), carried by the few samples at the edges: the ordinates below
    it then share a few degrees of freedom.  Ramps make ``Σ(Δa)²`` ~``π²/(8·length)``
    per edge instead of 1 (the record's own ends are left to the Hann taper).
    """
    if mask.all():
        return mask.astype(np.float64)
    n = mask.size
    idx = np.arange(n)
    prev = np.concatenate(([True], mask[:-1]))  # the record's start is no gap edge
    nxt = np.concatenate((mask[1:], [True]))
    start = np.maximum.accumulate(np.where(mask & ~prev, idx, 0))
    end = np.minimum.accumulate(np.where(mask & ~nxt, idx, n + length)[::-1])[::-1]
    d = np.minimum(idx - start + (start == 0) * length, end - idx)
    ramp = np.sin(0.5 * np.pi * np.clip((d + 0.5) / length, 0.0, 1.0)) ** 2
    return np.where(mask, ramp, 0.0)


class LowFreqSpectrum:
    """Tapered periodogram of residual increments and the Whittle fit of ``W + A·L_θ``.

    Parameters
    ----------
    used : ndarray of bool, shape (ngrid,)
        Which points of the nominal grid hold a used sample.
    step : float
        Grid step [s].
    max_bin : int
        Upper end of the Whittle band (bins ``2 … max_bin``).
    """

    def __init__(
        self, used: NDArray[np.bool_], step: float, max_bin: int = MAX_BIN, exact_low: bool = False
    ) -> None:
        ngrid = used.size
        self.ngrid = ngrid
        self.step = float(step)
        self.kmax = int(min(max_bin, (ngrid - 1) // 2))
        self.kmin = LOW_BINS + 3 if exact_low else MIN_BIN
        self.n_low = 0
        self.ok = self.kmax - self.kmin + 1 >= 16
        if not self.ok:
            return
        m = ngrid - 1
        h = np.sin(np.pi * (np.arange(m) + 0.5) / m) ** 2
        self.taper = h * _gap_ramps(used[1:] & used[:-1])
        self.norm = float(np.dot(self.taper, self.taper))
        rho = float(np.dot(self.taper[1:], self.taper[:-1])) / self.norm
        k = np.arange(self.kmin, self.kmax + 1)
        self.white = 2.0 - 2.0 * rho * np.cos(2.0 * np.pi * k / ngrid)
        self.kinds, self.params, b, self.f_ref = _shape_table(ngrid, self.kmax)
        self.b = b[:, self.kmin - MIN_BIN :]
        self.n_power = int(np.count_nonzero(self.kinds == 0))
        edges = [self.kmin]
        for e in np.geomspace(self.kmin, self.kmax + 1, GOF_GROUPS + 1)[1:].astype(int):
            if e - edges[-1] >= GOF_MIN_GROUP:
                edges.append(int(e))
        edges[-1] = self.kmax + 1
        edges = np.asarray(edges)
        self.groups = edges[:-1] - self.kmin
        self.group_size = np.diff(edges)

    def add_low(self, white: NDArray[np.float64], shapes: NDArray[np.float64]) -> None:
        """Put exact expectations of low ordinates first: ``E = W·white + A·shapes``.

        ``white`` (shape (n_low,)) and ``shapes`` (shape (n_shapes, n_low)); the
        ordinates themselves are passed to :meth:`periodograms` as ``low``.
        """
        self.n_low = white.size
        self.white = np.concatenate([white, self.white])
        self.b = np.concatenate([shapes, self.b], axis=1)
        self.groups = self.groups + white.size

    def periodograms(
        self, grid_rows: NDArray[np.float64], low: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Ordinates of residual rows on the grid (shape (r, ngrid)) -> (r, nk).

        ``low`` (shape (r, n_low)): the exact low-bin ordinates, put first.
        """
        d = np.diff(grid_rows, axis=1)
        d *= self.taper
        spec = np.fft.rfft(d, n=self.ngrid, axis=1)[:, self.kmin : self.kmax + 1]
        tapered = (spec.real**2 + spec.imag**2) / self.norm
        return tapered if low is None else np.concatenate([low, tapered], axis=1)

    def line_mask(self, pgram: NDArray[np.float64], expected: NDArray | None = None) -> NDArray:
        """``True`` for the ordinates kept in the fit, ``False`` for lines (shape of ``pgram``).

        A tapered ordinate above :data:`LINE_FACTOR` times its expectation is a
        line: ``expected``, a fitted model's, or before any fit the running median
        of 41 neighbours over ln 2 (an exponential's median).  The low ordinates
        are left out of a row with a line below bin :data:`LINE_NEAR`: a line
        leaks into them through the trend fit's projection (the weights'
        sidelobes), which their expectation does not hold (the lines' own share of
        the covariance is added at their frequency).
        """
        keep = np.ones(pgram.shape, dtype=bool)
        tap = pgram[:, self.n_low :]
        if expected is None:
            half = 20
            padded = np.pad(tap, ((0, 0), (half, half)), mode="reflect")
            win = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=1)
            line = tap > LINE_FACTOR * np.median(win, axis=2) / math.log(2.0)
        else:
            line = tap > LINE_FACTOR * expected[:, self.n_low :]
        keep[:, self.n_low :] = ~line
        near = np.arange(self.kmin, self.kmax + 1) <= LINE_NEAR
        keep[:, : self.n_low] = ~(line & near).any(axis=1, keepdims=True)
        return keep

    def fit(
        self,
        pgram: NDArray[np.float64],
        keep: NDArray[np.bool_] | None = None,
        iters: int = 15,
        start: dict[str, NDArray] | None = None,
    ) -> dict[str, NDArray]:
        """Whittle fit of every shape to every row of ``pgram`` (shape (r, nk)).

        ``keep`` (shape of ``pgram``): ordinates in the likelihood (default all);
        ``start``: a previous fit to start from.  Returns arrays ``W``, ``A``
        (shape (r, n_shapes)), ``loglik``, ``E`` (expected ordinates, (r, n_shapes,
        nk)), the white-only fit ``W_white``, ``ll_white`` (shape (r,)), ``keep``.
        """
        w, b = self.white, self.b
        if keep is None:
            keep = np.ones(pgram.shape, dtype=bool)
        mk = keep.astype(np.float64)
        ik = pgram * mk  # (r, nk)
        i = ik[:, None, :]
        count = mk.sum(axis=1)
        w_only = np.sum(ik / w, axis=1) / count  # white noise alone: closed form
        tiny = 1e-12 * np.maximum(w_only, np.finfo(float).tiny)
        if start is not None:
            wv, av = start["W"].copy(), start["A"].copy()
        else:
            half = w.size // 2
            w0 = np.sum(ik[:, half:] / w[half:], axis=1) / np.maximum(mk[:, half:].sum(axis=1), 1)
            lo = slice(0, 8)
            excess = np.mean(pgram[:, lo], axis=1) - w0 * np.mean(w[lo])
            wv = np.repeat(w0[:, None], b.shape[0], axis=1)
            av = np.maximum(excess[:, None], 0.0) / np.mean(b[:, lo], axis=1)[None, :]
            av = np.maximum(av, 1e-3 * w0[:, None] * np.mean(w) / np.mean(b, axis=1)[None, :])
        for _ in range(iters):
            e = wv[..., None] * w + av[..., None] * b  # (r, s, nk)
            v = mk[:, None, :] / (e * e)
            bv = b * v
            sww = np.einsum("k,rsk->rs", w * w, v)
            swb = np.einsum("k,rsk->rs", w, bv)
            sbb = np.einsum("sk,rsk->rs", b, bv)
            swi = np.einsum("k,rsk->rs", w, v * i)
            sbi = np.einsum("rsk,rk->rs", bv, ik)
            det = sww * sbb - swb * swb
            with np.errstate(divide="ignore", invalid="ignore"):
                wn = (sbb * swi - swb * sbi) / det
                an = (sww * sbi - swb * swi) / det
            only_w = ~(an > 0) | ~np.isfinite(det) | (det <= 0)
            wn = np.where(only_w, swi / sww, wn)
            an = np.where(only_w, 0.0, an)
            only_a = wn <= 0
            an = np.where(only_a, sbi / sbb, an)
            wn = np.where(only_a, 0.0, wn)
            wv = np.maximum(wn, tiny[:, None])
            av = np.maximum(an, 0.0)
        e = wv[..., None] * w + av[..., None] * b
        loglik = -np.sum((np.log(e) + i / e) * mk[:, None, :], axis=2)
        ll_white = -np.sum(np.log(w_only[:, None] * w) * mk, axis=1) - count
        return {
            "W": wv,
            "A": av,
            "loglik": loglik,
            "E": e,
            "W_white": w_only,
            "ll_white": ll_white,
            "keep": keep,
        }

    def fit_robust(self, pgram: NDArray[np.float64], passes: int = 3) -> dict[str, NDArray]:
        """:meth:`fit` with lines left out: by the running median, then by the model.

        Up to ``passes`` refits, each leaving out (in addition) the ordinates above
        :data:`LINE_FACTOR` times the previous fit's expectation.
        """
        fitted = self.fit(pgram, self.line_mask(pgram))
        for _ in range(passes):
            expected = np.stack([self.expected(fitted, r) for r in range(pgram.shape[0])])
            keep = fitted["keep"] & self.line_mask(pgram, expected)
            if np.array_equal(keep, fitted["keep"]):
                break
            fitted = self.fit(pgram, keep, iters=8, start=fitted)
        return fitted

    def expected(self, fitted: dict[str, NDArray], row: int) -> NDArray[np.float64]:
        """Expected ordinates of ``row`` under its chosen model (:meth:`select`)."""
        s, _, _ = self.select(fitted, row)
        return fitted["W_white"][row] * self.white if s < 0 else fitted["E"][row, s]

    def select(self, fitted: dict[str, NDArray], row: int) -> tuple[int, int, float]:
        """``(shape, neighbour, weight)``: the chosen shape of ``row``.

        The best shape is refined by a parabola through the profile
        log-likelihood at its grid neighbours (in α, or in log corner); the
        covariance is interpolated linearly between ``shape`` and ``neighbour``
        with ``weight`` in [0, 0.5].
        A Lorentzian replaces it if better by more than :data:`LORENTZ_MARGIN`;
        white noise alone (``shape = -1``) is kept unless the best coloured model
        is better by more than :data:`COLOURED_MARGIN`.
        """
        ll = fitted["loglik"][row]
        if ll.max() < fitted["ll_white"][row] + COLOURED_MARGIN:
            return -1, -1, 0.0
        npow = self.n_power
        j = int(np.argmax(ll[:npow]))
        best_l = int(np.argmax(ll[npow:])) + npow
        if ll[best_l] > ll[j] + LORENTZ_MARGIN:
            return _refine(ll, best_l, npow, ll.size)
        return _refine(ll, j, 0, npow)

    def goodness(self, pgram_row: NDArray, expected_row: NDArray) -> tuple[float, int, float]:
        """``(X, dof, p)`` of the binned tapered periodogram against its expectation.

        Each group's sum of ``m`` ordinates is taken as Gamma-distributed with
        shape ``m/c`` (``c``: :data:`HANN_INFLATION`); ``X`` is the sum of the
        groups' Gamma deviances ``2(m/c)[(o/e − 1) − ln(o/e)]`` (McCullagh &
        Nelder 1989, §8.3), nearly χ²₁ each even for few ordinates.
        """
        obs = np.add.reduceat(pgram_row, self.groups)[: self.group_size.size]
        exp = np.add.reduceat(expected_row, self.groups)[: self.group_size.size]
        ratio = obs / exp
        x = float(np.sum(2.0 * self.group_size / HANN_INFLATION * (ratio - 1.0 - np.log(ratio))))
        dof = int(self.groups.size - 3)
        return x, dof, _chi2_sf(x, dof)

    def model(self, fitted: dict[str, NDArray], row: int, pgram_row: NDArray) -> LowFreqModel:
        """The :class:`LowFreqModel` of ``row`` (chosen shape, goodness of fit)."""
        s, nb, wt = self.select(fitted, row)
        if s < 0:
            w = fitted["W_white"][row]
            x, dof, p = self.goodness(pgram_row, w * self.white)
            nan = float("nan")
            return LowFreqModel("white", float(w), 0.0, nan, nan, self.f_ref, self.step, x, dof, p)
        x, dof, p = self.goodness(pgram_row, fitted["E"][row, s])
        kind = "power" if self.kinds[s] == 0 else "lorentzian"
        if kind == "power":
            par = (1.0 - wt) * self.params[s] + wt * self.params[nb]
        else:
            par = self.params[s] ** (1.0 - wt) * self.params[nb] ** wt
        return LowFreqModel(
            kind=kind,
            white=float((1.0 - wt) * fitted["W"][row, s] + wt * fitted["W"][row, nb]),
            amplitude=float((1.0 - wt) * fitted["A"][row, s] + wt * fitted["A"][row, nb]),
            alpha=float(par) if kind == "power" else float("nan"),
            corner=float(par) if kind == "lorentzian" else float("nan"),
            f_ref=self.f_ref,
            step=self.step,
            chi2=x,
            dof=dof,
            p_misfit=p,
        )
