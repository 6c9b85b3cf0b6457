"""Periodic candidates: the orbit harmonics as one effect, and spectral lines.

Periodic terms are reported, never removed from a calibrated series (at orbit
frequencies they are as likely real non-gravitational signal as instrument error;
:mod:`accal.closure.kinds`).  Without a reference the orbit-periodic signal is in
the null model (:class:`accal.closure.nuisance.OrbitTemplate`) and no orbit term
is proposed.  On the rotating platform a line must lie mostly outside the span of
the per-period signal, its slope within the period included: a line near the
modulation frequency is the modulated signal itself (its sidebands), not a
candidate (the ``periodic`` kind's ``ident_min``, checked by
:func:`accal.closure.validation.identifiability`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from accal.closure.candidates import Context, Proposal
from accal.closure.multiplicity import frequency_search_factor
from accal.closure.residual import estimate_psd

__all__ = ["MAX_LINES", "ORBIT_HARMONICS", "periodic"]


def _refine_frequency(
    tau: NDArray[np.float64],
    r: NDArray[np.float64],
    f: float,
    half_width: float,
    masks: list[NDArray[np.bool_]],
) -> float:
    """The frequency within ``f ± half_width`` whose least-squares sinusoid explains most.

    A sinusoid fitted at a frequency ``δf`` off leaves ``~2π δf (t − t̄)`` times its
    amplitude in the residual, all of it in the line's own PSD bin: 0.036 of a DFT
    bin off (the 1/10-bin grid), a 3e-9 m/s² line at 2200 s on half a day left
    ~2e-10 m/s², 3x the noise, the test's noise estimate at the line rose with it,
    and the line was not significant (corrected p 0.1); lines that were found had
    σ 20-90x too large.  Bounded scalar search (scipy), to 1e-4 of the width.
    """
    from scipy.optimize import minimize_scalar

    def neg_power(fr: float) -> float:
        x = _harmonic_cols(tau, [fr])
        tot = 0.0
        for m in masks:
            coef, *_ = np.linalg.lstsq(x[m], r[m], rcond=None)
            tot += float(np.sum((x[m] @ coef) ** 2))
        return -tot

    lo, hi = max(f - half_width, 1e-12), f + half_width
    res = minimize_scalar(neg_power, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-4 * half_width})  # fmt: skip
    return float(res.x) if res.success and -res.fun >= -neg_power(f) else f


def _block_period(ctx: Context) -> float | None:
    """The common spacing of the base's blocks [s] (the demodulation period τ), or None.

    Only for a base of at least 8 blocks, at least half of them starting one
    spacing after the previous one (gaps make some spacings multiples).
    """
    b = ctx.basis
    starts = b.seg_start[b.seg_block >= 0]
    if starts.size < 8:
        return None
    d = np.diff(ctx.t[starts])
    period = float(np.median(d))
    if period <= 0 or np.mean(np.abs(d - period) <= 1e-3 * period) < 0.5:
        return None
    return period


def _projected_power(ctx: Context, z: NDArray[np.float64]) -> float:
    """Residual power the columns ``z`` (used rows) explain jointly, design projected out.

    ``rᵀz̃ (z̃ᵀz̃)⁻¹ z̃ᵀr`` with ``z̃ = (I − QQᵀ) z``: the RSS reduction of adding ``z``
    to the fit (``rᵀz̃ = rᵀz``, the residual being orthogonal to the design).
    """
    zr = z.T @ ctx.residual
    gram = z.T @ z
    c = ctx.basis.block_coef(z)
    gram -= np.einsum("spm,spk->mk", c, c)
    if ctx.basis.qe.shape[1]:
        e = ctx.basis.qe.T @ z
        gram -= e.T @ e
    x, *_ = np.linalg.lstsq(gram, zr, rcond=1e-10)
    return float(zr @ x)


_ALIAS_ORDERS = 4


def _unalias(
    ctx: Context, tau: NDArray[np.float64], f: float, period: float, df: float, fmax: float
) -> float:
    """The line frequency that explains most once the block base is projected out.

    A per-block base (the demodulation's per-period bias and signal, eq. 17) takes
    most of a slow sinusoid out of the residual: what it leaves is the sinusoid's
    curvature within each block, whose periodogram peaks at the sidebands
    ``k/τ ± f`` and not at ``f``.  QA: a 1e-8 m/s² bias term of period 5400 s on
    ``m_y`` came out as lines at 675 and 540 s (``1/600 ∓ 1/5400``) of 1.5e-10 m/s²,
    and removing those, which are modulated-signal frequencies, made ``a_Y`` worse
    (std z 1.12 → 9.9).  The true frequency is the one among ``|f + k/τ|``
    (``|k| ≤`` :data:`_ALIAS_ORDERS`) whose sinusoid, with the design projected out,
    explains most of the residual (Cauchy-Schwarz: the true sinusoid's projection
    explains all of its own part); it is refined on that same projected power.
    """
    from scipy.optimize import minimize_scalar

    masks = ctx.channel_masks()

    def power(fr: float) -> float:
        x = _harmonic_cols(tau, [fr])
        return _projected_power(ctx, np.column_stack([x * m[:, None] for m in masks]))

    cands = [f] + [abs(f + k / period) for k in range(-_ALIAS_ORDERS, _ALIAS_ORDERS + 1) if k != 0]
    cands = [
        g for g in cands if 4 * df <= g <= fmax and (g == f or not _excluded(g, ctx, 1.5 * df))
    ]
    pw = [power(g) for g in cands]
    best = int(np.argmax(pw))
    g = cands[best]
    # the search's refinement maximised the plain least-squares fit, which the
    # projection distorts: a 1000 s line came out at 999.85 s, and its phase drift
    # over the day (0.08 rad) left 2e-11 m/s² that was flagged "unexplained"
    half = 0.5 * df if best else 0.1 * df
    res = minimize_scalar(lambda fr: -power(fr), bounds=(max(g - half, 1e-12), g + half),
                          method="bounded", options={"xatol": 1e-4 * df})  # fmt: skip
    return float(res.x) if res.success and -res.fun >= pw[best] else g


def _modulated_twin(ctx: Context, tau_all, f: float, period: float | None) -> float | None:
    """Most power a sinusoid modulated like the platform's signal explains near ``f``.

    Modulated by θ (period τ), a signal term at ``g`` appears at ``g ± k/τ``: the
    candidates are ``g = |f − k/τ|``, ``|k| ≤`` :data:`_ALIAS_ORDERS`.  A signal term
    ``a_Y = α cos + β sin`` (``a_Z`` alike) enters ``m_y`` as ``cos θ a_Y + sin θ a_Z`` and
    ``m_z`` as ``−sin θ a_Y + cos θ a_Z`` (eq. 4): four columns.  None off the platform.
    """
    info = ctx.options.get("platform")
    if info is None or ctx.channel_all is None or not period:
        return None
    th = np.nan_to_num(info.theta)
    c, s = np.cos(th), np.sin(th)
    y = info.axis_index == 0
    cy = np.where(y, c, -s)[ctx.use]
    cz = np.where(y, s, c)[ctx.use]
    tau_u = tau_all[ctx.use]
    best = 0.0
    for k in range(-_ALIAS_ORDERS, _ALIAS_ORDERS + 1):
        g = abs(f - k / period)
        h = _harmonic_cols(tau_u, [g])
        best = max(best, _projected_power(ctx, np.column_stack([h * cy[:, None], h * cz[:, None]])))
    return best


def _harmonic_cols(tau: NDArray[np.float64], freqs: list[float]) -> NDArray[np.float64]:
    cols = []
    for f in freqs:
        ph = 2 * np.pi * f * tau
        cols += [np.cos(ph), np.sin(ph)]
    return np.column_stack(cols)


def _line_power(
    tau: NDArray[np.float64],
    r: NDArray[np.float64],
    freqs: NDArray[np.float64],
    masks: list[NDArray[np.bool_]] | None = None,
) -> NDArray[np.float64]:
    """Periodogram ``Σ_c |Σ r e^{−2πifτ}|²`` of the residual at evenly spaced frequencies.

    A ranking for the frequency searches (the residual is already orthogonal to
    the design, and sinusoids well inside the band are nearly orthogonal to it);
    with several channels the channels' periodograms are summed.  The phasors are
    advanced by one complex multiplication per frequency (``freqs`` must be evenly
    spaced).
    """
    masks = masks or [np.ones(r.size, dtype=bool)]
    out = np.zeros(freqs.size)
    if freqs.size == 0:
        return out
    step = float(freqs[1] - freqs[0]) if freqs.size > 1 else 0.0
    for m in masks:
        tm, rm = tau[m], r[m]
        ph = rm * np.exp(-2j * np.pi * freqs[0] * tm)
        rot = np.exp(-2j * np.pi * step * tm)
        for j in range(freqs.size):
            out[j] += np.abs(np.sum(ph)) ** 2
            ph *= rot
    return out


_BG_HALF_MAX = 50


def _line_background(pgram: NDArray[np.float64]) -> NDArray[np.float64]:
    """Local background of a periodogram for the line search: a running median.

    The binned PSD cannot serve here: a line contributes to its own bin, so its
    ratio to the bin level is capped by the bin's width (3 ordinates at 7000 s
    periods on a day, 21 at 1000 s) and a strong low-frequency line ranked below
    the largest pure-noise ordinate of a wide high-frequency bin (≈ ln N).  The
    median of the neighbours within ±25 % of the frequency (±4 to ±50 ordinates,
    the ordinate and its two neighbours left out, so leakage of a line between
    two DFT frequencies does not count) is insensitive to the line; for
    periodogram ordinates of noise (χ²₂/2) it is ``ln 2`` times the local mean.
    """
    from scipy.ndimage import median_filter

    n = pgram.size
    out = median_filter(pgram, size=2 * _BG_HALF_MAX + 1, mode="nearest")
    for k in range(min(n, 4 * _BG_HALF_MAX)):
        h = min(max(4, k // 4), _BG_HALF_MAX)
        lo, hi = max(1, k - h), min(n, k + h + 1)
        idx = np.r_[lo : max(lo, k - 1), min(hi, k + 2) : hi]
        if idx.size:
            out[k] = np.median(pgram[idx])
    return out / np.log(2.0)


def line_threshold(n: float) -> float:
    """Least ratio of a periodogram ordinate to :func:`_line_background` that is a line.

    Twice the 1 % Bonferroni level over ``n`` ordinates (a noise ordinate over its
    background is exp(1)-distributed: ``P(ratio > x) = e^(−x)``, so ``ln(n/0.01)`` is
    the 1 % level; doubled, a line stands far above it).
    """
    return 2.0 * np.log(max(float(n), 1.0) / 0.01)


def _excluded(f: float, ctx: Context, width: float) -> bool:
    return any(abs(f - g) < width for g in ctx.excluded_freqs)


ORBIT_HARMONICS = 6
"""Highest once-per-revolution harmonic the ``orbit`` proposal may include."""

ORBIT_BAND = 0.06
"""Relative width of the orbit frequency's search band (±3 % of ``1/orbit_period``)."""

MAX_LINES = 2
"""Most ``line`` effects one selection adds (option ``max_lines``), strongest first."""


def _line_band(ctx: Context, freqs, df: float, fmax: float) -> NDArray[np.bool_]:
    """DFT frequencies searched for a line: ≥ 4/T, ≤ fmax, off excluded/rejected/modulated ones."""
    band = (np.arange(freqs.size) >= 4) & (freqs <= fmax)
    for g in ctx.excluded_freqs:
        band &= np.abs(freqs - g) > 1.5 * df
    for key in ctx.blocked:  # rejected lines: not proposed again
        if len(key) == 3 and key[0] == "periodic" and key[1] == "line":
            band &= np.abs(freqs - float(key[2])) > 1.5 * df
    for g in ctx.cache.get("modulated_freqs", ()):  # the signal's own variation (periodic)
        band &= np.abs(freqs - g) > 1.5 * df
    return band


def _clear_at(f: float, rat: NDArray[np.float64], level: float, df: float, n_freqs: int) -> bool:
    """Whether a DFT ordinate next to ``f`` has its ratio to the background above ``level``."""
    k = f / df
    ks = [j for j in (int(np.floor(k)), int(np.ceil(k))) if 0 < j < n_freqs]
    return any(rat[j] > level for j in ks)


def _orbit_harmonics(ctx: Context, tau, masks, f, n_max: int, fmax, df: float) -> list[int]:
    """The orbit harmonics ``n`` (of ``f``) taken in the orbit effect."""
    # harmonics 1 and 2 always; then, with those fitted out of the residual (their
    # power and its leakage through the gaps raise the background of the others: on
    # a simulated half day the 3rd-6th stand 6-23x above it before, 19-86x after),
    # every harmonic clearly above its background, at twice the Bonferroni level of
    # the harmonics searched
    freqs = ctx.grid.freqs
    r = ctx.residual
    top = min(fmax, freqs[-1])
    level = line_threshold(n_max)
    x = _harmonic_cols(tau, [f, 2 * f])
    r2 = r.copy()
    for m in masks:
        coef, *_ = np.linalg.lstsq(x[m], r[m], rcond=None)
        r2[m] -= x[m] @ coef
    pg = np.mean(np.abs(ctx.grid.fft(r2)[0]) ** 2, axis=0)
    rat = pg / np.maximum(_line_background(pg), 1e-300)
    return [1, 2] + [
        n
        for n in range(3, n_max + 1)
        if n * f <= top and _clear_at(n * f, rat, level, df, freqs.size)
    ]


def _orbit_proposal(
    ctx: Context, tau, tau_all, masks, df: float, fmax: float, n_max: int
) -> Proposal | None:
    """The orbit effect: cos/sin at ``f``, ``2f`` and the clear higher harmonics, if any."""
    freqs = ctx.grid.freqs
    r = ctx.residual
    f0 = 1.0 / ctx.orbit_period
    # shorter than a revolution, once/twice-per-revolution terms are a smooth curve
    # the polynomial base already has: a 100 s record "found" a 1e-3 m/s² orbit term
    long_enough = ctx.span >= ctx.orbit_period
    harm: list[int] = []
    if long_enough and not _excluded(f0, ctx, 0.05 * f0) and 2 * f0 < freqs[-1]:
        trial = f0 * (1 + np.linspace(-0.5 * ORBIT_BAND, 0.5 * ORBIT_BAND, 41))
        pw = _line_power(tau, r, trial, masks) + _line_power(tau, r, 2 * trial, masks)
        f = float(trial[int(np.argmax(pw))])
        harm = _orbit_harmonics(ctx, tau, masks, f, n_max, fmax, df)
        # harmonics next to a line of the model stay out (nearly collinear columns)
        harm = [n for n in harm if not any(abs(n * f - g) <= 1.5 * df for g in ctx.model_freqs)]
    if not harm:
        return None
    # no lines are kept off this trial's harmonics: a line competes with it
    # (QA: a 3e-9 m/s² line at 2500 s pulled this f 2.9 % high, 1.4 bins
    # from the line's 2f, the line was kept off, the orbit term had p = 1,
    # and the line was never proposed); once an orbit effect is in the model
    # its harmonics are kept off (in periodic)
    m = frequency_search_factor(ctx.t, ORBIT_BAND * f0, harm, len(masks), ctx.scan_level)
    labs = tuple(lab for n in harm for lab in (f"cos@{n * f!r}", f"sin@{n * f!r}"))
    cols, labs, axes = ctx.split(_harmonic_cols(tau_all, [n * f for n in harm]), labs)
    return Proposal(
        "periodic",
        "orbit",
        cols,
        labs,
        m,
        {"frequency": f, "harmonics": tuple(harm), "local_psd": True, "t0": ctx.t0},
        axes,
    )


def periodic(ctx: Context) -> list[Proposal]:
    """Sinusoids: the strongest residual spectral line, and the orbit harmonics.

    * ``channel="orbit"`` (only with ``orbit_period``, on records spanning at least
      one revolution): cos/sin at ``f`` and ``2f``,
      with ``f`` estimated from the data within ±3 % of ``1/orbit_period``
      (multiplicity: resolvable frequencies in that band), plus every higher
      harmonic ``n f`` (``n ≤`` :data:`ORBIT_HARMONICS`, option ``orbit_harmonics``)
      that stands clearly out of the residual spectrum (see below).  Harmonics of
      the orbit are everywhere in accelerometer data (drag, radiation pressure,
      thermal cycles); as one effect they do not use up the selection's budget
      one line at a time, and lines found elsewhere are not at the orbit.
    * ``channel="line"``: among the DFT frequencies (≥ 4/T, away from the orbit
      harmonics) whose residual periodogram exceeds its local median background
      (:func:`_line_background`) by twice the Bonferroni level ``2 ln(M/0.01)``,
      the one with the largest excess power (if none does, the largest ratio),
      refined on a grid of ±1 DFT bin; the multiplicity ``M`` is the number of
      DFT frequencies searched.  Ranking by power and not by ratio: the sharpest
      line is often a tiny one where the noise floor is low (1e-10 m/s² at
      0.02 Hz over white noise), and the budget would go to those first.  At most
      :data:`MAX_LINES` lines are added (option ``max_lines``): real signal has
      lines everywhere (the eclipse switching of radiation pressure puts orbit
      harmonics up to the 40th above 3e-10 m/s²), and each costs a selection step.

    With several data channels the search uses their summed periodograms and the
    amplitudes are per channel.
    """
    tau_all = ctx.t_all - ctx.t0
    tau = ctx.t - ctx.t0
    masks = ctx.channel_masks()
    out: list[Proposal] = []
    df = 1.0 / (ctx.grid.size * ctx.grid.step)
    noise = estimate_psd(ctx.grid, ctx.residual, ctx.leverage)
    freqs = ctx.grid.freqs
    fmax = float(ctx.options.get("fmax", freqs[-1]))
    ratio = noise.pgram / np.maximum(_line_background(noise.pgram), 1e-300)
    band = _line_band(ctx, freqs, df, fmax)
    thr = line_threshold(band.sum())
    r = ctx.residual

    n_max = int(ctx.options.get("orbit_harmonics", ORBIT_HARMONICS))
    if ctx.orbit_frequency is not None:
        # the orbit effect is in the model (its harmonic set is revisited when the
        # selection refines it given the other effects): no lines at its harmonics
        for n in range(1, n_max + 1):
            band &= np.abs(freqs - n * ctx.orbit_frequency) > 1.5 * df
    elif ctx.options.get("signal_template") is not None:
        # the orbit-periodic signal is in the null model: no orbit term, and no line
        # at its harmonics (nothing is left there)
        f_t = 1.0 / float(ctx.options["signal_template"])
        n_top = int(freqs[-1] / f_t)
        if n_top >= 1:  # the nearest harmonic 1 .. n_top of every frequency, at once
            nearest = np.clip(np.rint(freqs / f_t), 1, n_top) * f_t
            band &= np.abs(freqs - nearest) > 1.5 * df
    elif ctx.orbit_period and ctx.orbit_period > 0 and not ctx.is_blocked("periodic", "orbit"):
        orbit = _orbit_proposal(ctx, tau, tau_all, masks, df, fmax, n_max)
        if orbit is not None:
            out.append(orbit)
    if band.any() and ctx.n_lines < int(ctx.options.get("max_lines", MAX_LINES)):
        clear = band & (ratio > thr)
        if clear.any():
            excess = np.maximum(noise.pgram - noise.pgram / np.maximum(ratio, 1e-300), 0.0)
            # a line between two DFT frequencies shares its power with its neighbours
            # (0.57 + 0.25 + ... halfway): rank by the three ordinates around it
            excess3 = excess + np.r_[0.0, excess[:-1]] + np.r_[excess[1:], 0.0]
            k = int(np.argmax(np.where(clear, excess3, -np.inf)))
        else:
            k = int(np.argmax(np.where(band, ratio, -1.0)))
        trial = freqs[k] + df * np.linspace(-1, 1, 21)
        trial = trial[trial > 0]
        f = float(trial[int(np.argmax(_line_power(tau, r, trial, masks)))])
        f = _refine_frequency(tau, r, f, 0.1 * df, masks)
        period = _block_period(ctx)
        if period is not None:
            f = _unalias(ctx, tau, f, period, df, fmax)
        taken = list(ctx.model_freqs)
        if ctx.orbit_frequency is not None:
            taken += [n * ctx.orbit_frequency for n in range(1, n_max + 1)]
        if any(abs(f - g) <= 1.5 * df for g in taken):
            # refined back next to a sinusoid of the model: the two columns would be
            # nearly collinear, and their fit two huge cancelling amplitudes (QA: a line
            # 0.0007 bins from the orbit term, 9e-7 m/s² each, for a 4e-9 m/s² term
            # whose amplitude grew over the day)
            return out
        cols, labs, axes = ctx.split(_harmonic_cols(tau_all, [f]), (f"cos@{f!r}", f"sin@{f!r}"))
        twin = _modulated_twin(ctx, tau_all, f, period)
        if twin is not None and twin >= _projected_power(ctx, cols[ctx.use]):
            # the structure changes sign with θ: it is the signal varying within its
            # modulation periods (their sidebands k/τ ± f), not a bias term (QA: lines at
            # 585 and 615 s on a τ = 600 s run removed the signal's own variation)
            ctx.cache.setdefault("modulated_freqs", []).append(f)
            out.append(
                Proposal(
                    "periodic",
                    "line",
                    np.zeros((tau_all.size, 0)),
                    (),
                    params={"frequency": f, "t0": ctx.t0},
                    note=f"structure at {f:.6g} Hz ({1.0 / f:.6g} s) is modulated like the "
                    "signal (it explains more modulated by θ than as a bias term): the "
                    "signal's own variation within its periods, not a candidate",
                )
            )
            return out
        out.insert(
            0,
            Proposal(
                "periodic",
                "line",
                cols,
                labs,
                float(band.sum()),
                {"frequency": f, "harmonics": (1,), "local_psd": True, "t0": ctx.t0},
                axes,
            ),
        )
    return out
