"""The candidate library: effects a base model may lack, each a small family of regressors.

A *builder* takes the current state of the fit (:class:`Context`) and proposes zero
or more :class:`Proposal` objects: the regressor columns of its best-fitting member
(best epoch, frequency, lag, ...) and the number of members searched, which the
selection uses as a Bonferroni factor so that searching many epochs or frequencies
does not buy false detections.

Builders are plain functions; :data:`BUILDERS` maps the names accepted by
:func:`accal.closure.close_loop` to them.  A caller with its own effect (the
rotating-platform demodulation: ``angle_offset``, intra-period bias shape) passes
its builder function in ``candidates`` instead of a name; :func:`angle_offset` and
:func:`intra_period_shape` are the documented hooks, not implemented yet.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.residual import Grid, estimate_psd

__all__ = [
    "BUILDERS",
    "EFFECT_NAMES",
    "Context",
    "Proposal",
    "angle_offset",
    "auxiliary",
    "bias_step",
    "cubic_drift",
    "intra_period_shape",
    "periodic",
    "quadratic_drift",
]

#: Names an effect can carry in a result (``closure.json``).
EFFECT_NAMES = (
    "quadratic_drift",
    "cubic_drift",
    "bias_step",
    "periodic",
    "auxiliary",
    "angle_offset",
    "unexplained",
)


@dataclass(frozen=True)
class Context:
    """State of the fit handed to every builder.

    Attributes
    ----------
    t_all : ndarray, shape (N,)
        All sample times [s] (regressors are built on all samples).
    use : ndarray of bool, shape (N,)
        Samples used in the fit.
    t0 : float
        Reference epoch: first used sample [s].
    span : float
        Time span of the used samples [s].
    grid : Grid
        Used samples on their nominal grid.
    residual : ndarray, shape (n,)
        Residual of the current model on the used samples [m/s²].
    qx : ndarray, shape (n, p)
        Orthonormal basis of the current design on the used samples.
    qx_fft : ndarray, shape (p, nf)
        Its rfft on the grid.
    labels : frozenset of str
        Labels of the columns already in the design (``"t^2"``, ``"step@<t>"``, ...).
    aux : dict of str to ndarray, shape (N,)
        Auxiliary channels on all samples.
    orbit_period : float or None
        Nominal orbit/revolution period [s].
    excluded_freqs : tuple of float
        Frequencies not to propose again [Hz] (already modelled or rejected).
    options : dict
        Search settings (``step_tests``, ``min_segment``, ``max_lag``, ``n_lags``,
        ``aux_taus``, ``fmax``).
    """

    t_all: NDArray[np.float64]
    use: NDArray[np.bool_]
    t0: float
    span: float
    grid: Grid
    residual: NDArray[np.float64]
    qx: NDArray[np.float64]
    qx_fft: NDArray[np.complex128]
    labels: frozenset[str]
    aux: dict[str, NDArray[np.float64]]
    orbit_period: float | None
    excluded_freqs: tuple[float, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def t(self) -> NDArray[np.float64]:
        """Times of the used samples [s]."""
        return self.t_all[self.use]

    def power(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """OLS explained power ``(z̃ᵀr)²/z̃ᵀz̃`` of each column of ``z`` (used rows).

        ``z̃`` is ``z`` with the current design projected out; a cheap ranking used
        by the searches (the test itself is the coloured-noise Wald test).
        """
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        zt = z - self.qx @ (self.qx.T @ z)
        nrm = np.sum(zt**2, axis=0)
        num = (zt.T @ self.residual) ** 2
        return np.where(nrm > 1e-12 * np.maximum(np.sum(z**2, axis=0), 1e-300), num / nrm, 0.0)


@dataclass(frozen=True)
class Proposal:
    """One candidate effect, ready to be tested.

    Attributes
    ----------
    name : str
        Effect kind (one of :data:`EFFECT_NAMES`).
    channel : str or None
        Auxiliary channel or sub-kind (``"orbit"`` for once/twice per revolution).
    columns : ndarray, shape (N, q)
        Regressors on all samples.
    labels : tuple of str
        One label per column (kept in the design to avoid proposing it twice).
    multiplicity : float
        Number of family members searched (Bonferroni factor).
    params : dict
        ``epoch`` [s], ``frequency`` [Hz], ``harmonics``, ``lag`` [s], ``tau`` [s], ...
    check_consistency : bool
        Whether the selection must check that the coefficient is the same in
        every third of the record (periodic and auxiliary effects).
    """

    name: str
    channel: str | None
    columns: NDArray[np.float64]
    labels: tuple[str, ...]
    multiplicity: float = 1.0
    params: dict[str, Any] = field(default_factory=dict)
    check_consistency: bool = False


Builder = Callable[[Context], list[Proposal]]


def _poly_proposal(ctx: Context, name: str, powers: tuple[int, ...]) -> list[Proposal]:
    if f"t^{max(powers)}" in ctx.labels:
        return []
    missing = tuple(k for k in powers if f"t^{k}" not in ctx.labels)
    u = (ctx.t_all - ctx.t0) / ctx.span
    cols = np.column_stack([u**k for k in missing])
    return [
        Proposal(
            name,
            None,
            cols,
            tuple(f"t^{k}" for k in missing),
            1.0,
            {"powers": missing, "scale": ctx.span},
        )
    ]


def quadratic_drift(ctx: Context) -> list[Proposal]:
    """A ``(t − t0)²`` term beyond the declared order (one regressor)."""
    return _poly_proposal(ctx, "quadratic_drift", (2,))


def cubic_drift(ctx: Context) -> list[Proposal]:
    """A ``(t − t0)³`` term (one regressor).

    If the model lacks ``(t − t0)²`` and ``quadratic_drift`` is not enabled, the
    square is added too; otherwise the quadratic must enter first (parsimony: the
    nested one-regressor family is preferred).
    """
    if "t^2" not in ctx.labels and "quadratic_drift" in ctx.options.get("enabled", ()):
        return []
    return _poly_proposal(ctx, "cubic_drift", (2, 3))


def bias_step(ctx: Context) -> list[Proposal]:
    """A bias step at an unknown epoch: the best single change point of the residual.

    The scan evaluates the OLS power of ``1[t ≥ τ]`` (design projected out) for every
    used sample ``τ`` at least ``min_segment`` from either end, with cumulative sums
    (O(n p)).  Repeated over iterations, this is binary segmentation with a
    multiplicity-corrected threshold as penalty.  The multiplicity is
    ``step_tests`` (default 200: epochs closer than 0.5 % of the span are not
    independent tests).
    """
    t = ctx.t
    n = t.size
    min_seg = int(ctx.options.get("min_segment", max(10, n // 50)))
    if n < 2 * min_seg + 2:
        return []
    r = ctx.residual
    # reverse cumulative sums: S[i] = Σ_{j ≥ i}
    s_r = np.cumsum(r[::-1])[::-1]
    s_q = np.cumsum(ctx.qx[::-1], axis=0)[::-1]
    cnt = n - np.arange(n)
    nrm = cnt - np.sum(s_q**2, axis=1)
    lo, hi = min_seg, n - min_seg
    ok = np.zeros(n, dtype=bool)
    ok[lo:hi] = True
    ok &= nrm > 1e-6 * cnt
    for lab in ctx.labels:  # no second step at an existing epoch
        if lab.startswith("step@"):
            e = float(lab[5:])
            i = int(np.searchsorted(t, e))
            ok[max(0, i - min_seg) : i + min_seg] = False
    if not ok.any():
        return []
    stat = np.where(ok, s_r**2 / np.where(ok, nrm, 1.0), -1.0)
    i = int(np.argmax(stat))
    epoch = float(t[i])
    col = (ctx.t_all >= epoch).astype(np.float64)[:, None]
    m = float(min(ctx.options.get("step_tests", 200), ok.sum()))
    return [Proposal("bias_step", None, col, (f"step@{epoch!r}",), m, {"epoch": epoch})]


def _harmonic_cols(tau: NDArray[np.float64], freqs: list[float]) -> NDArray[np.float64]:
    cols = []
    for f in freqs:
        ph = 2 * np.pi * f * tau
        cols += [np.cos(ph), np.sin(ph)]
    return np.column_stack(cols)


def _line_power(
    tau: NDArray[np.float64], r: NDArray[np.float64], freqs: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Periodogram ``|Σ r e^{−2πifτ}|²`` of the residual at arbitrary frequencies.

    A ranking for the frequency searches (the residual is already orthogonal to
    the design, and sinusoids well inside the band are nearly orthogonal to it).
    """
    out = np.empty(freqs.size)
    for j, f in enumerate(freqs):
        out[j] = np.abs(np.dot(r, np.exp(-2j * np.pi * f * tau))) ** 2
    return out


def _excluded(f: float, ctx: Context, width: float) -> bool:
    return any(abs(f - g) < width for g in ctx.excluded_freqs)


def periodic(ctx: Context) -> list[Proposal]:
    """Sinusoids: the strongest residual spectral line, and once/twice per revolution.

    * ``channel="line"``: the DFT frequency (≥ 4/T) with the largest ratio of the
      residual periodogram to the binned PSD, refined on a grid of ±1 DFT bin; the
      multiplicity is the number of DFT frequencies searched.
    * ``channel="orbit"`` (only with ``orbit_period``): cos/sin at ``f`` and ``2f``,
      with ``f`` estimated from the data within ±3 % of ``1/orbit_period``
      (multiplicity: resolvable frequencies in that band).
    """
    t = ctx.t
    tau_all = ctx.t_all - ctx.t0
    tau = t - ctx.t0
    out: list[Proposal] = []
    df = 1.0 / (ctx.grid.size * ctx.grid.step)
    noise = estimate_psd(ctx.grid, ctx.residual, ctx.qx_fft)
    freqs = ctx.grid.freqs
    fmax = float(ctx.options.get("fmax", freqs[-1]))
    ratio = noise.pgram / np.maximum(noise.psd, 1e-300)
    band = (np.arange(freqs.size) >= 4) & (freqs <= fmax)
    for g in ctx.excluded_freqs:
        band &= np.abs(freqs - g) > 1.5 * df
    if band.any():
        k = int(np.argmax(np.where(band, ratio, -1.0)))
        trial = freqs[k] + df * np.linspace(-1, 1, 21)
        trial = trial[trial > 0]
        f = float(trial[int(np.argmax(_line_power(tau, ctx.residual, trial)))])
        out.append(
            Proposal(
                "periodic",
                "line",
                _harmonic_cols(tau_all, [f]),
                (f"cos@{f!r}", f"sin@{f!r}"),
                float(band.sum()),
                {"frequency": f, "harmonics": (1,)},
                True,
            )
        )
    if ctx.orbit_period and ctx.orbit_period > 0:
        f0 = 1.0 / ctx.orbit_period
        if not _excluded(f0, ctx, 0.05 * f0) and 2 * f0 < freqs[-1]:
            trial = f0 * (1 + np.linspace(-0.03, 0.03, 41))
            r = ctx.residual
            pw = _line_power(tau, r, trial) + _line_power(tau, r, 2 * trial)
            f = float(trial[int(np.argmax(pw))])
            m = max(1.0, 0.06 * f0 * ctx.span)
            out.append(
                Proposal(
                    "periodic",
                    "orbit",
                    _harmonic_cols(tau_all, [f, 2 * f]),
                    (f"cos@{f!r}", f"sin@{f!r}", f"cos@{2 * f!r}", f"sin@{2 * f!r}"),
                    m,
                    {"frequency": f, "harmonics": (1, 2)},
                    True,
                )
            )
    return out


def _first_order(x: NDArray[np.float64], t: NDArray[np.float64], tau: float) -> NDArray[np.float64]:
    """First-order low-pass response ``τ ẏ + y = x`` (exact for piecewise-constant x)."""
    if tau <= 0:
        return x
    from scipy.signal import lfilter

    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    a = np.exp(-dt / tau)
    y = lfilter([1 - a], [1, -a], x - x[0]) + x[0]
    return y


def auxiliary(ctx: Context) -> list[Proposal]:
    """Linear coupling to each auxiliary channel, with a lag search and a first-order response.

    For channel ``x`` the regressor is ``h_τ * x`` evaluated at ``t − lag`` (``h_τ``:
    first-order low-pass with time constant ``τ``; ``τ = 0``: no filter), searched
    over ``n_lags`` lags in ``[0, max_lag]`` (default 31 lags up to min(span/20,
    3600 s)) and ``aux_taus`` (default 0, 300, 1000, 3000 s); the multiplicity is
    the number of (lag, τ) pairs.  The coefficient is in [m/s² per channel unit].
    """
    out: list[Proposal] = []
    t_all = ctx.t_all
    max_lag = float(ctx.options.get("max_lag", min(ctx.span / 20.0, 3600.0)))
    lags = np.linspace(0.0, max_lag, int(ctx.options.get("n_lags", 31)))
    taus = tuple(ctx.options.get("aux_taus", (0.0, 300.0, 1000.0, 3000.0)))
    for name, x in ctx.aux.items():
        if f"aux:{name}" in ctx.labels:
            continue
        x = np.asarray(x, dtype=np.float64)
        good = np.isfinite(x)
        if good.sum() < 10 or np.ptp(x[good]) == 0:
            continue
        xf = np.interp(t_all, t_all[good], x[good])
        best = (-1.0, 0.0, 0.0)
        cols = {}
        for tc in taus:
            h = _first_order(xf, t_all, tc)
            zs = np.column_stack([np.interp(t_all - lag, t_all, h) for lag in lags])
            pw = ctx.power(zs[ctx.use])
            j = int(np.argmax(pw))
            if pw[j] > best[0]:
                best = (float(pw[j]), float(lags[j]), float(tc))
                cols[(best[1], best[2])] = zs[:, j]
        _, lag, tc = best
        col = cols[(lag, tc)]
        col = col - col[ctx.use].mean()
        out.append(
            Proposal(
                "auxiliary",
                name,
                col[:, None],
                (f"aux:{name}",),
                float(lags.size * len(taus)),
                {"lag": lag, "tau": tc},
                True,
            )
        )
    return out


def angle_offset(ctx: Context) -> list[Proposal]:
    """Hook for the rotating platform: an offset of the turntable angle θ.

    Not implemented: the demodulation caller will build it from its θ series
    (the regressor is ∂model/∂θ, i.e. the quadrature of the demodulated signal)
    and pass the builder in ``candidates``.
    """
    raise NotImplementedError(
        "angle_offset needs the platform angle; pass a builder function from the demod caller"
    )


def intra_period_shape(ctx: Context) -> list[Proposal]:
    """Hook for the rotating platform: bias shape within a rotation period (not implemented)."""
    raise NotImplementedError(
        "intra_period_shape needs the platform angle; pass a builder from the demod caller"
    )


#: Names accepted in ``close_loop(candidates=...)``.
BUILDERS: dict[str, Builder] = {
    "quadratic_drift": quadratic_drift,
    "cubic_drift": cubic_drift,
    "bias_step": bias_step,
    "periodic": periodic,
    "auxiliary": auxiliary,
    "angle_offset": angle_offset,
    "intra_period_shape": intra_period_shape,
}
