"""The candidate library: effects a base model may lack, each a small family of regressors.

A *builder* takes the current state of the fit (:class:`Context`) and proposes zero
or more :class:`Proposal` objects: the regressor columns of its best-fitting member
(best epoch, frequency, lag, ...) and the number of members searched, which the
selection uses as a Bonferroni factor so that searching many epochs or frequencies
does not buy false detections.

Builders are plain functions; :data:`BUILDERS` maps the names accepted by
:func:`accal.closure.close_loop` to them.  A caller with its own effect passes its
builder function in ``candidates`` instead of a name.  The rotating-platform
effects (:func:`angle_offset`, :func:`intra_period_shape`) need the platform angle
and the fitted demodulated signal (:class:`PlatformInfo` in
``options["platform"]``); :func:`accal.closure.demod.close_loop_demod` supplies them.

With several data channels (the y and z axes of the rotating platform, interleaved
in time), every generic effect gets one coefficient per channel (the columns are
split with :meth:`Context.split`) and is tested jointly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import ValidationError

if TYPE_CHECKING:
    from accal.closure.basis import Basis
    from accal.closure.residual import Grid

__all__ = [
    "BUILDERS",
    "EFFECT_NAMES",
    "Context",
    "PlatformInfo",
    "Proposal",
    "angle_offset",
    "auxiliary",
    "bias_step",
    "cubic_drift",
    "exponential_drift",
    "intra_period_shape",
    "periodic",
    "quadratic_drift",
    "scan_multiplicity",
]

#: Names an effect can carry in a result (``closure.json``).
EFFECT_NAMES = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
    "angle_offset",
    "intra_period_shape",
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
    basis : Basis
        Orthonormal basis of the current design on the used samples (block base +
        the effects added so far; :class:`accal.closure.basis.Basis`).
    leverage : ndarray, shape (C, nf)
        Its leverage spectrum ``Σ_j |Q_j(f)|²`` (for PSD estimates).
    labels : frozenset of str
        Labels of the columns already in the design (``"t^2"``, ``"step@<t>"``, ...;
        with several channels suffixed ``":<channel>"``).
    aux : dict of str to ndarray, shape (N,)
        Auxiliary channels on all samples.
    orbit_period : float or None
        Nominal orbit/revolution period [s].
    excluded_freqs : tuple of float
        Frequencies not to propose again [Hz] (already modelled or rejected).
    options : dict
        Search settings (``step_tests``, ``min_segment``, ``max_lag``, ``n_lags``,
        ``aux_taus``, ``fmax``, ``settle_taus``) and ``platform``
        (:class:`PlatformInfo`, for ``angle_offset`` and ``intra_period_shape``).
    channel_all : ndarray of int, shape (N,), optional
        Data channel of every sample (several channels: e.g. the y and z axes of
        the rotating platform, interleaved in time).
    channel_names : tuple of str
        Names of the channels (empty for a single channel).
    orbit_frequency : float or None
        Frequency of the ``periodic``/``orbit`` effect already in the model [Hz]
        (its harmonics are then not searched as separate lines).
    n_lines : int
        Number of ``periodic``/``line`` effects already in the model.
    model_freqs : tuple of float
        Frequencies of the sinusoids in the model [Hz] (lines, orbit harmonics).
    cache : dict
        Shared by the contexts of one selection: what builders compute from the
        data alone (not the residual), e.g. filtered auxiliary channels.
    """

    t_all: NDArray[np.float64]
    use: NDArray[np.bool_]
    t0: float
    span: float
    grid: Grid
    residual: NDArray[np.float64]
    basis: Basis
    leverage: NDArray[np.float64]
    labels: frozenset[str]
    aux: dict[str, NDArray[np.float64]]
    orbit_period: float | None
    excluded_freqs: tuple[float, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)
    channel_all: NDArray[np.int64] | None = None
    channel_names: tuple[str, ...] = ()
    orbit_frequency: float | None = None
    n_lines: int = 0
    model_freqs: tuple[float, ...] = ()
    cache: dict[Any, Any] = field(default_factory=dict)

    @property
    def t(self) -> NDArray[np.float64]:
        """Times of the used samples [s]."""
        return self.t_all[self.use]

    @property
    def qx(self) -> NDArray[np.float64]:
        """The orthonormal basis as a dense (n, p) array (small designs only)."""
        return self.basis.dense_q()

    @property
    def n_chan(self) -> int:
        """Number of data channels."""
        return max(len(self.channel_names), 1)

    def has_label(self, label: str) -> bool:
        """Whether a column labelled ``label`` (any channel) is in the design."""
        return any(lab == label or lab.startswith(label + ":") for lab in self.labels)

    def split(
        self, cols: NDArray[np.float64], labels: tuple[str, ...]
    ) -> tuple[NDArray[np.float64], tuple[str, ...], tuple[str, ...] | None]:
        """One copy of ``cols`` (N, q) per data channel (zero on the others).

        Returns ``(columns (N, q·C), labels, axis of each column)``; with one
        channel, the input unchanged and ``None``.
        """
        cols = np.asarray(cols, dtype=np.float64)
        if cols.ndim == 1:
            cols = cols[:, None]
        if self.n_chan == 1 or self.channel_all is None:
            return cols, labels, None
        out, labs, axes = [], [], []
        for c, name in enumerate(self.channel_names):
            m = (self.channel_all == c)[:, None]
            out.append(cols * m)
            labs += [f"{lab}:{name}" for lab in labels]
            axes += [name] * cols.shape[1]
        return np.column_stack(out), tuple(labs), tuple(axes)

    def channel_masks(self) -> list[NDArray[np.bool_]]:
        """Used-sample mask of every channel (one all-true mask for a single channel)."""
        if self.n_chan == 1 or self.channel_all is None:
            return [np.ones(int(self.use.sum()), dtype=bool)]
        ch = self.channel_all[self.use]
        return [ch == c for c in range(self.n_chan)]

    def power(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """OLS explained power ``(z̃ᵀr)²/z̃ᵀz̃`` of each column of ``z`` (used rows).

        ``z̃`` is ``z`` with the current design projected out; a cheap ranking used
        by the searches (the test itself is the coloured-noise Wald test).
        """
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        # the residual is orthogonal to the design: z̃ᵀr = zᵀr, ‖z̃‖² = ‖z‖² − ‖Qᵀz‖²
        z2 = np.sum(z**2, axis=0)
        nrm = z2 - self.basis.captured(z)
        num = (z.T @ self.residual) ** 2
        return np.where(nrm > 1e-9 * np.maximum(z2, 1e-300), num / np.maximum(nrm, 1e-300), 0.0)

    def joint_power(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`power` summed over the data channels (columns split per channel)."""
        z = np.asarray(z, dtype=np.float64)
        if z.ndim == 1:
            z = z[:, None]
        masks = self.channel_masks()
        if len(masks) == 1:
            return self.power(z)
        return sum(self.power(z * m[:, None]) for m in masks)


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
    axes : tuple of str, optional
        Data channel of each column when the data have several channels.
    note : str, optional
        Set (with no columns) when the effect cannot be estimated from these data
        (e.g. not identifiable): the selection records it in
        :attr:`ClosureResult.notes` instead of testing it.
    jacobian : callable, optional
        For an effect with fitted nonlinear parameters (a coupling's lag and
        low-pass time constant): returns ``[(name, d columns / d parameter), ...]``
        (each the shape of ``columns``; ``"tau"`` is differentiated in ``ln τ``)
        for the final fit's Jacobian (:func:`accal.closure.select._with_tau_jacobian`).
    """

    name: str
    channel: str | None
    columns: NDArray[np.float64]
    labels: tuple[str, ...]
    multiplicity: float = 1.0
    params: dict[str, Any] = field(default_factory=dict)
    check_consistency: bool = False
    axes: tuple[str, ...] | None = None
    note: str | None = None
    jacobian: Callable[[], list[tuple[str, NDArray[np.float64]]]] | None = field(
        default=None, compare=False
    )


Builder = Callable[[Context], list[Proposal]]


def _poly_proposal(ctx: Context, name: str, powers: tuple[int, ...]) -> list[Proposal]:
    if ctx.has_label(f"t^{max(powers)}"):
        return []
    missing = tuple(k for k in powers if not ctx.has_label(f"t^{k}"))
    u = (ctx.t_all - ctx.t0) / ctx.span
    cols, labs, axes = ctx.split(
        np.column_stack([u**k for k in missing]), tuple(f"t^{k}" for k in missing)
    )
    return [
        Proposal(
            name,
            None,
            cols,
            labs,
            1.0,
            {"powers": missing, "scale": ctx.span},
            axes=axes,
        )
    ]


def quadratic_drift(ctx: Context) -> list[Proposal]:
    """A ``(t − t0)²`` term beyond the declared order (one regressor per channel)."""
    return _poly_proposal(ctx, "quadratic_drift", (2,))


def cubic_drift(ctx: Context) -> list[Proposal]:
    """A ``(t − t0)³`` term (one regressor per channel).

    If the model lacks ``(t − t0)²`` and ``quadratic_drift`` is not enabled, the
    square is added too; otherwise the quadratic must enter first (parsimony: the
    nested one-regressor family is preferred).
    """
    if not ctx.has_label("t^2") and "quadratic_drift" in ctx.options.get("enabled", ()):
        return []
    return _poly_proposal(ctx, "cubic_drift", (2, 3))


#: Shortest and longest time constants of :func:`exponential_drift` [s].  The longest
#: is also capped at :data:`EXP_SPAN_FRACTION` of the record's span: a slower decay
#: is a low-order polynomial over the record (a quadratic + an exponential of
#: T = 0.8 span, 1.7e-8 m/s², took the place of a true cubic drift).
EXP_TAU_RANGE = (120.0, 86400.0)
EXP_SPAN_FRACTION = 0.25
#: Longest time constant, as a fraction of the span, of the exponential that may take the
#: place of polynomial drift terms after the search (``select._Search.smooth_swap``).
EXP_LONG_FRACTION = 1.0
#: Ratio between neighbouring time constants searched.
EXP_TAU_STEP = 1.4


def exponential_drift(ctx: Context) -> list[Proposal]:
    """A decaying bias ``A·exp(−(t − t0)/T)`` from the first sample (one ``A`` per channel).

    The settling of an accelerometer after switch-on, a heater or mode change, or
    a calibration manoeuvre at the start of the record: a drift shape no
    polynomial of low order follows (a 5e-9 m/s², 2 h decay went unnamed as
    "unexplained", a 1e-9 m/s², 50 min one was taken for a bias step).  ``T`` is
    searched on a log grid (:data:`EXP_TAU_RANGE`, ratio :data:`EXP_TAU_STEP`,
    capped at :data:`EXP_SPAN_FRACTION` of the span) for the most explained power, then refined between the
    grid's neighbours (:func:`_refine_tau`); the multiplicity is the number of
    grid values.  Only one exponential per model.  ``options["exp_tau_max"]``
    overrides the longest T (the selection's polynomial swap searches up to
    :data:`EXP_LONG_FRACTION` of the span).
    """
    if any(lb.startswith("exp:") for lb in ctx.labels):
        return []
    steps = np.diff(ctx.t)
    steps = steps[steps > 0]
    dt = float(np.median(steps)) if steps.size else 1.0
    lo = max(EXP_TAU_RANGE[0], 10.0 * dt)
    hi = min(EXP_TAU_RANGE[1], EXP_SPAN_FRACTION * ctx.span)
    hi = float(ctx.options.get("exp_tau_max", hi))  # the polynomial swap searches further
    if hi <= lo:
        return []
    n_tau = int(np.ceil(np.log(hi / lo) / np.log(EXP_TAU_STEP))) + 1
    taus = np.geomspace(lo, hi, n_tau)  # both ends, ratio <= EXP_TAU_STEP
    el = ctx.t - ctx.t0
    power = _channel_power(ctx, np.exp(-el[None, :] / taus[:, None]))  # one A per channel
    if not np.any(power > 0):
        return []
    k = int(np.argmax(power))
    tau = _refine_tau(ctx, el, float(taus[max(k - 1, 0)]), float(taus[min(k + 1, taus.size - 1)]))
    if tau > hi / EXP_TAU_STEP**0.1:
        # the power still grows at the cap: a polynomial-like trend, not a decay (on
        # the real Swarm storm day an exponential of T = span/4, 2.4e-6 m/s², took
        # the place of an injected quadratic drift); the polynomial candidates hold it
        return []
    col = np.exp(-(ctx.t_all - ctx.t0) / tau)
    cols, labs, axes = ctx.split(col[:, None], (f"exp:{tau!r}",))
    return [
        Proposal(
            "exponential_drift",
            None,
            cols,
            labs,
            float(taus.size),
            {"tau": tau},
            axes=axes,
        )
    ]


def _refine_tau(ctx: Context, el: NDArray[np.float64], lo: float, hi: float) -> float:
    """The time constant of most explained power in ``[lo, hi]`` (bounded search on ln T).

    The grid's step (40 %) left a 5 % error in T, and the misfit was then taken up
    by a spurious step or polynomial.
    """
    from scipy.optimize import minimize_scalar

    masks = ctx.channel_masks()

    def neg_power(log_tau: float) -> float:
        return -float(_channel_power(ctx, np.exp(-el / np.exp(log_tau))[None, :])[0])

    if hi <= lo:
        return lo
    res = minimize_scalar(
        neg_power, bounds=(np.log(lo), np.log(hi)), method="bounded", options={"xatol": 1e-3}
    )
    tau = float(np.exp(res.x))
    # Gauss-Newton on (A_c, T): the power is flat at its maximum, so the bounded
    # search stops at its tolerance; a noise-free exponential needs T to rounding
    r = ctx.residual
    for _ in range(8):
        e = np.exp(-el / tau)
        per_chan, d_col = [], np.zeros_like(e)
        for m in masks:
            x = e * m
            xt = x - ctx.basis.project(x)
            nrm = float(xt @ xt)
            a = float(xt @ r) / nrm if nrm > 0 else 0.0
            per_chan.append(x)
            d_col += a * (el / tau**2) * e * m  # ∂(A_c e^(−el/T))/∂T
        cols = np.column_stack([*per_chan, d_col])
        ct = cols - ctx.basis.project(cols)
        norms = np.linalg.norm(ct, axis=0)
        if not np.all(norms > 0):
            break
        coef, *_ = np.linalg.lstsq(ct / norms, r, rcond=None)  # columns of ~1 and ~A/T
        step = float(coef[-1] / norms[-1])
        if not np.isfinite(step) or abs(step) > 0.5 * tau:
            break
        tau = min(max(tau + step, lo), hi)
        if abs(step) <= 1e-13 * tau:
            break
    return tau


def _without_orbit_template(ctx: Context, masks: list[NDArray[np.bool_]]) -> NDArray[np.float64]:
    """The residual minus its mean at each orbital phase (one-sample bins), for the epoch scan.

    Orbit-periodic structure the model does not hold (sharp radiation-pressure
    switching at eclipse entry and exit, beyond the harmonics fitted) adds wiggles to
    the cumulative sums, and the best change point snapped to them: a −3e-9 m/s² step
    at 40,000 s came out at 40,960 s, an eclipse edge.  A step is not periodic, so
    the phase-folded mean barely holds it (each phase bin sees the step in the same
    proportion of its orbits); the periodic part goes.  Only with an orbit frequency
    (found, or from ``orbit_period``) and at least two revolutions; the step's
    column and its test are unchanged.

    The bins are one sampling interval wide: a sharp edge is a one-sample jump, and
    30 s bins left a ±2e-8 m/s² dipole about every eclipse edge (QA, simulated
    GRACE-FO C y, 2006-03-11), the same in every orbit; the scan statistic divides
    it by the step's norm, smallest at the record's ends, so the first edge of the
    day won (4.6e-17 vs at most 1.1e-17 mid-day), and the raw test of a step there
    (a box over the partial orbit before it) passed: two opposite steps 86 s apart.
    """
    r = ctx.residual
    f = ctx.orbit_frequency or (1.0 / ctx.orbit_period if ctx.orbit_period else None)
    if not f or f <= 0 or ctx.span * f < 2.0:
        return r
    steps = np.diff(ctx.t)
    steps = steps[steps > 0]
    dt = float(np.median(steps)) if steps.size else 30.0
    nb = max(4, int(round(1.0 / (f * dt))))
    ph = np.floor(np.mod((ctx.t - ctx.t0) * f, 1.0) * nb).astype(np.int64) % nb
    out = r.copy()
    for m in masks:
        cnt = np.bincount(ph[m], minlength=nb)
        mean = np.bincount(ph[m], weights=r[m], minlength=nb) / np.maximum(cnt, 1)
        out[m] -= mean[ph[m]]
    return out


def bias_step(ctx: Context) -> list[Proposal]:
    """A bias step at an unknown epoch: the best single change point of the residual.

    With an orbit the scan runs on the residual minus its orbit-phase template
    (:func:`_without_orbit_template`), so orbit-periodic features do not pull the epoch.

    The scan evaluates the OLS power of ``1[t ≥ τ]`` (design projected out) for every
    used sample ``τ`` at least ``min_segment`` samples (default 0.1 % of them, at least
    10) from either end, with cumulative sums
    (O(n p), block by block for a block base).  Repeated over iterations, this is
    binary segmentation with a multiplicity-corrected threshold as penalty.  The
    multiplicity is ``step_tests`` (default 200: epochs closer than 0.5 % of the span
    are not independent tests), or the scan's own, :func:`scan_multiplicity`, when
    that is larger: with a per-block base (one bias per demodulation period) a step
    is seen only inside its block, and every block is a scan of its own, so a day of
    144 periods is ~10⁴ tests, not 200.  With several data channels the step has one
    size per channel and the scan sums the channels' powers.
    """
    t = ctx.t
    n = t.size
    masks = ctx.channel_masks()
    n_time = n // len(masks)
    # a block base (one bias per demodulation period) scans every block on its own and
    # its multiplicity counts them, so only the record's last samples are left out
    # (QA: a step 10-60 s from a run's end came out as steps of the wrong sign)
    edge = 10 if ctx.basis.n_blocks > 1 else max(10, n_time // 1000)
    min_seg = int(ctx.options.get("min_segment", edge)) * len(masks)
    if n < 2 * min_seg + 2:
        return []
    r = _without_orbit_template(ctx, masks)
    ok = np.zeros(n, dtype=bool)
    ok[min_seg : n - min_seg + 1] = True  # at least min_seg samples on either side
    ok &= np.r_[True, np.diff(t) > 0]  # epochs at the first sample of a time
    for lab in ctx.labels:  # no second step at an existing epoch
        if lab.startswith("step@"):
            e = float(lab[5:].split(":")[0])
            i = int(np.searchsorted(t, e))
            ok[max(0, i - min_seg) : i + min_seg] = False
    stat = np.zeros(n)
    for m in masks:
        rm = r * m
        s_r = np.cumsum(rm[::-1])[::-1]
        cnt = np.cumsum(m[::-1].astype(float))[::-1]
        nrm = cnt - ctx.basis.step_norms(m)
        good = nrm > 1e-6 * np.maximum(cnt, 1.0)
        ok &= good
        stat += np.where(good, s_r**2 / np.where(good, nrm, 1.0), 0.0)
    if not ok.any():
        return []
    stat = np.where(ok, stat, -1.0)
    i = int(np.argmax(stat))
    epoch = float(t[i])
    cols, labs, axes = ctx.split(
        (ctx.t_all >= epoch).astype(np.float64)[:, None], (f"step@{epoch!r}",)
    )
    m_tests = float(min(ctx.options.get("step_tests", 200), ok.sum()))
    block = ctx.basis.block
    if ctx.basis.n_blocks > 1:  # a scan in every block holding candidate epochs
        counts = np.bincount(block[masks[0] & (block >= 0)], minlength=ctx.basis.n_blocks)
        scanned = np.unique(block[ok & (block >= 0)])
        fractions = 1.0 / np.maximum(counts[scanned], 1)
    else:  # one scan over the record, epochs at least min_segment from the ends
        fractions = np.array([min_seg / max(n, 1)])
    level = float(ctx.options.get("alpha", 0.01)) / float(ctx.options.get("families", 1))
    m_scan = scan_multiplicity(fractions, len(masks), level)
    return [
        Proposal(
            "bias_step",
            None,
            cols,
            labs,
            max(m_tests, m_scan),
            {"epoch": epoch},
            axes=axes,
        )
    ]


def scan_multiplicity(fractions: NDArray[np.float64], k: int, level: float) -> float:
    """Bonferroni factor of change-point scans, at the decision boundary.

    The largest standardized step statistic over the epochs of a segment, with
    epochs from a fraction ``ε`` of the segment to ``1 − ε``, exceeds ``x²`` (χ²
    with ``k`` channels) with probability (Siegmund's approximation for the
    standardized CUSUM of a Brownian bridge, James, James & Siegmund 1987, leading
    term)::

        P(max > x²) ≈ xᵏ e^(−x²/2) / (2^(k/2) Γ(k/2)) · ln((1 − ε)² / ε²)

    summed over the segments scanned.  The factor returned is that probability
    divided by the single-epoch ``P(χ²_k > x²)`` at the ``x²`` where the scan's
    probability equals ``level`` (alpha over the candidate families), so a step's
    corrected p-value is right where the decision is taken.

    Checked by simulation (white noise, 390-sample segments with an affine base
    per segment, as a 600 s demodulation period with a 200 s rotation mask): the
    approximation is 1.2-1.7x conservative at x² = 16-25.

    Parameters
    ----------
    fractions : ndarray
        ``ε`` of every segment scanned (``1/L`` for a segment of ``L`` samples).
    k : int
        Channels the step statistic sums (its χ² degrees of freedom).
    level : float
        Corrected significance level of the whole scan.

    Returns
    -------
    float
        The factor (at least 1).
    """
    from scipy import optimize, special, stats

    eps = np.clip(np.asarray(fractions, dtype=np.float64), 1e-12, 0.5)
    logs = float(np.sum(2.0 * np.log((1.0 - eps) / eps)))
    if logs <= 0.0 or not 0.0 < level < 1.0:
        return 1.0
    c = 2.0 ** (k / 2.0) * special.gamma(k / 2.0)

    def excess(x2: float) -> float:  # log P(scan max > x2) - log level
        return k / 2.0 * np.log(x2) - x2 / 2.0 - np.log(c) + np.log(logs) - np.log(level)

    lo = max(float(k), 1.0)  # the tail formula holds beyond the mode
    if excess(lo) <= 0.0:
        return 1.0
    x2 = optimize.brentq(excess, lo, 1e4)
    return float(max(1.0, level / stats.chi2.sf(x2, k)))


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


def _excluded(f: float, ctx: Context, width: float) -> bool:
    return any(abs(f - g) < width for g in ctx.excluded_freqs)


ORBIT_HARMONICS = 6
"""Highest once-per-revolution harmonic the ``orbit`` proposal may include."""

MAX_LINES = 2
"""Most ``line`` effects one selection adds (option ``max_lines``), strongest first."""


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
    from accal.closure.residual import estimate_psd

    tau_all = ctx.t_all - ctx.t0
    tau = ctx.t - ctx.t0
    masks = ctx.channel_masks()
    out: list[Proposal] = []
    df = 1.0 / (ctx.grid.size * ctx.grid.step)
    noise = estimate_psd(ctx.grid, ctx.residual, ctx.leverage)
    freqs = ctx.grid.freqs
    fmax = float(ctx.options.get("fmax", freqs[-1]))
    ratio = noise.pgram / np.maximum(_line_background(noise.pgram), 1e-300)
    band = (np.arange(freqs.size) >= 4) & (freqs <= fmax)
    for g in ctx.excluded_freqs:
        band &= np.abs(freqs - g) > 1.5 * df
    thr = 2.0 * np.log(max(float(band.sum()), 1.0) / 0.01)
    r = ctx.residual

    def clear_at(f: float, rat: NDArray[np.float64], level: float) -> bool:
        k = f / df
        ks = [j for j in (int(np.floor(k)), int(np.ceil(k))) if 0 < j < freqs.size]
        return any(rat[j] > level for j in ks)

    def orbit_harmonics(f: float, n_max: int) -> list[int]:
        # harmonics 1 and 2 always; then, with those fitted out of the residual (their
        # power and its leakage through the gaps raise the background of the others: on
        # a simulated half day the 3rd-6th stand 6-23x above it before, 19-86x after),
        # every harmonic clearly above its background, at twice the Bonferroni level of
        # the harmonics searched
        top = min(fmax, freqs[-1])
        level = 2.0 * np.log(max(n_max, 1) / 0.01)
        x = _harmonic_cols(tau, [f, 2 * f])
        r2 = r.copy()
        for m in masks:
            coef, *_ = np.linalg.lstsq(x[m], r[m], rcond=None)
            r2[m] -= x[m] @ coef
        pg = np.mean(np.abs(ctx.grid.fft(r2)[0]) ** 2, axis=0)
        rat = pg / np.maximum(_line_background(pg), 1e-300)
        return [1, 2] + [
            n for n in range(3, n_max + 1) if n * f <= top and clear_at(n * f, rat, level)
        ]

    n_max = int(ctx.options.get("orbit_harmonics", ORBIT_HARMONICS))
    if ctx.orbit_frequency is not None:
        # the orbit effect is in the model (its harmonic set is revisited when the
        # selection refines it given the other effects): no lines at its harmonics
        for n in range(1, n_max + 1):
            band &= np.abs(freqs - n * ctx.orbit_frequency) > 1.5 * df
    elif ctx.orbit_period and ctx.orbit_period > 0:
        f0 = 1.0 / ctx.orbit_period
        # shorter than a revolution, once/twice-per-revolution terms are a smooth curve
        # the polynomial base already has: a 100 s record "found" a 1e-3 m/s² orbit term
        long_enough = ctx.span >= ctx.orbit_period
        harm: list[int] = []
        if long_enough and not _excluded(f0, ctx, 0.05 * f0) and 2 * f0 < freqs[-1]:
            trial = f0 * (1 + np.linspace(-0.03, 0.03, 41))
            pw = _line_power(tau, r, trial, masks) + _line_power(tau, r, 2 * trial, masks)
            f = float(trial[int(np.argmax(pw))])
            harm = orbit_harmonics(f, n_max)
            # harmonics next to a line of the model stay out (nearly collinear columns)
            harm = [n for n in harm if not any(abs(n * f - g) <= 1.5 * df for g in ctx.model_freqs)]
        if harm:
            # no lines are kept off this trial's harmonics: a line competes with it
            # (QA: a 3e-9 m/s² line at 2500 s pulled this f 2.9 % high, 1.4 bins
            # from the line's 2f, the line was kept off, the orbit term had p = 1,
            # and the line was never proposed); once an orbit effect is in the model
            # its harmonics are kept off (above)
            m = max(1.0, 0.06 * f0 * ctx.span)
            labs = tuple(lab for n in harm for lab in (f"cos@{n * f!r}", f"sin@{n * f!r}"))
            cols, labs, axes = ctx.split(_harmonic_cols(tau_all, [n * f for n in harm]), labs)
            out.append(
                Proposal(
                    "periodic",
                    "orbit",
                    cols,
                    labs,
                    m,
                    {"frequency": f, "harmonics": tuple(harm)},
                    True,
                    axes,
                )
            )
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
        out.insert(
            0,
            Proposal(
                "periodic",
                "line",
                cols,
                labs,
                float(band.sum()),
                {"frequency": f, "harmonics": (1,)},
                True,
                axes,
            ),
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


SQUARED = "^2"
"""Suffix of a channel's square (about its mean) in the ``auxiliary`` proposals."""


def square_about_mean(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(x − mean x)²``, the mean over the finite values (channel ``NAME^2``)."""
    x = np.asarray(x, dtype=np.float64)
    return (x - np.nanmean(x)) ** 2


def squared_column(
    t_all: NDArray[np.float64], x: NDArray[np.float64], lag: float, tau: float
) -> NDArray[np.float64]:
    """``(x − mean x)²`` through the coupling's low-pass ``tau`` and lag ``lag`` (on ``t_all``).

    The regressor of channel ``NAME^2`` as :func:`auxiliary` forms it (holes
    interpolated, filtered and shifted on the distinct sample times).
    """
    tu, first = np.unique(t_all, return_index=True)
    sq = square_about_mean(x)[first]
    good = np.isfinite(sq)
    h = _first_order(np.interp(tu, tu[good], sq[good]), tu, tau)
    return np.interp(t_all - lag, tu, h)


def auxiliary(ctx: Context) -> list[Proposal]:
    """Linear coupling to each auxiliary channel, with a lag search and a first-order response.

    A channel already coupled is offered again as its square about its mean,
    ``(x − mean x)²`` (channel ``NAME^2``, coefficient in m/s² per unit²), searched
    alike: with the linear term, a quadratic dependence on the channel.

    For channel ``x`` the regressor is ``h_τ * x`` evaluated at ``t − lag`` (``h_τ``:
    first-order low-pass with time constant ``τ``; ``τ = 0``: no filter), searched
    over ``n_lags`` lags in ``[0, max_lag]`` (default 31 lags up to min(span/20,
    3600 s)) and ``aux_taus`` (default 0, 300, 1000, 3000 s); the multiplicity is
    the number of (lag, τ) pairs.  The coefficient is in [m/s² per channel unit]
    (one per data channel when there are several).
    """
    out: list[Proposal] = []
    t_all = ctx.t_all
    t_u = ctx.t
    # filter and shift on the distinct sample times (channels share them)
    tu, first = np.unique(t_all, return_index=True)
    dt = float(np.median(np.diff(tu))) if tu.size > 1 else 1.0
    top_lag = max_lag(ctx.options, ctx.span)
    lags = np.linspace(0.0, top_lag, int(ctx.options.get("n_lags", 31)))
    taus = tuple(ctx.options.get("aux_taus", (0.0, 300.0, 1000.0, 3000.0)))
    z = np.empty((lags.size, t_u.size))  # lagged regressors on the used samples, row by row
    channels = []
    for name, x in ctx.aux.items():
        if not ctx.has_label(f"aux:{name}"):
            channels.append((name, x))
        elif not ctx.has_label(f"aux:{name}{SQUARED}"):
            # once coupled linearly, the square of the channel (about its mean): a
            # coupling c1·x + c2·x² (QA: demod with c2 = 2e-6 m/s²/K² on a platform
            # temperature, fitted as c1 plus three steps, a line and a shape; the a_Y
            # error grew from std z 12 to 37).  Before the coupling is in, the square is
            # tested together with it, at its lag and low-pass (select's _with_square):
            # its own lag search for every channel made a run ~9x slower
            channels.append((f"{name}{SQUARED}", square_about_mean(x)))
    for name, x in channels:
        x = np.asarray(x, dtype=np.float64)[first]
        good = np.isfinite(x)
        if good.sum() < 10 or np.ptp(x[good]) == 0:
            continue
        xf = np.interp(tu, tu[good], x[good])
        best = (-1.0, 0.0, 0.0)

        def filtered(tc: float, name: str = name, xf: NDArray[np.float64] = xf):
            key = ("aux", name, tc)  # the same at every step: filter once per selection
            if key not in ctx.cache:
                ctx.cache[key] = _first_order(xf, tu, tc)
            return ctx.cache[key]

        grid_best = []
        for tc in taus:
            h = filtered(tc)
            for j, lag in enumerate(lags):
                z[j] = np.interp(t_u - lag, tu, h)
            pw = _channel_power(ctx, z)
            j = int(np.argmax(pw))
            grid_best.append((float(pw[j]), float(lags[j]), float(tc)))
        top = max(g[0] for g in grid_best)
        lag_step = float(lags[1] - lags[0]) if lags.size > 1 else 0.0
        for p_best, lag, tc in grid_best:
            if p_best < 0.8 * top:
                continue
            if lags.size > 1:
                # between the grid's lags, for every competitive time constant: a 1500 s
                # lag fell between grid lags and 1212 s + a 300 s low-pass won
                lag, p_best = _refine_lag(ctx, tu, filtered(tc), lag, lag_step, top_lag, p_best)
            if p_best > best[0]:
                best = (p_best, lag, tc)
        p_best, lag, tc = best
        grid = sorted(taus)
        if len(grid) > 1:
            # and between the grid's time constants, lag and τ together: a 500 s
            # low-pass came out as 300 s + a 160 s lag, its coefficient 7 % low.  Up to
            # the neighbouring grid values; beyond the largest up to TAU_BEYOND times
            # it, but a result at that bound is noise, not a time constant (a 3000 s
            # low-pass went to 6000 s on the slow noise: the ranking is the OLS power),
            # and the largest grid value stands.  From a pure lag, the search starts
            # half-way to the first low-pass.
            k = grid.index(tc)
            lo_tau = grid[k - 1] if k > 0 else 0.0
            hi_tau = grid[k + 1] if k + 1 < len(grid) else tc * TAU_BEYOND
            start_lag, start_tau = lag, tc
            if tc == 0:
                start_tau = 0.5 * hi_tau
                start_lag = max(lag - start_tau, 0.0)
            lag2, tc2, p2 = _refine_lag_tau(
                ctx, tu, xf, start_lag, start_tau, lag_step, top_lag, (lo_tau, hi_tau), p_best
            )
            at_bound = k + 1 == len(grid) and tc2 > 0.98 * hi_tau
            if p2 > p_best and not at_bound:
                if tc2 >= TAU_MIN_STEPS * dt:
                    best = (p2, lag2, tc2)
                elif tc > 0:  # a low-pass of a few samples is a lag
                    best = (p2, min(lag2 + tc2, top_lag), 0.0)
                # (from a pure lag, a few samples of low-pass: the lag stays as found)
        _, lag, tc = best
        h = filtered(tc) if tc in taus else _first_order(xf, tu, tc)
        period = float(ctx.options.get("lag_period") or 0.0)
        if period > 0 and lag >= 0.5 * period:
            lag = _shortest_lag(ctx, tu, h, lag, period, lag_step, top_lag)
        col = np.interp(t_all - lag, tu, h)
        # not de-meaned: the bias is the one at channel value 0, as the model
        # ``b + c·x`` says.  A de-meaned regressor left c × mean(x) in the bias (a
        # 3e-9 m/s²/K coupling to a 20 °C channel: 6e-8 m/s²), so the day-to-day bias
        # followed the day's mean temperature; the σ of that extrapolation is in the
        # bias σ (σ(c) × mean(x))
        cc, labs, axes = ctx.split(col[:, None], (f"aux:{name}",))

        def jacobian(
            xf=xf, h=h, lag=lag, tc=tc, name=name
        ) -> list[tuple[str, NDArray[np.float64]]]:
            # c·h_τ(x)(t − lag): d/dlnτ by a central difference (the filter is smooth
            # in τ), d/dlag = −h'(t − lag), smooth too behind a low-pass.  Only with a
            # low-pass: for a pure lag the channel's own derivative is the column, and
            # a channel with kicks (a platform's temperature after each rotation) made
            # it spikes: lag 1.4 ± 0.3 s for a true 0, the coefficient 2 % off
            eps = 1e-3
            up, down = (
                _first_order(xf, tu, tc * np.exp(eps)),
                _first_order(xf, tu, tc / np.exp(eps)),
            )
            parts = [
                ("tau", np.interp(t_all - lag, tu, (up - down) / (2 * eps))),
                ("lag", -np.interp(t_all - lag, tu, np.gradient(h, tu))),
            ]
            return [(k, ctx.split(d[:, None], (f"aux:{name}",))[0]) for k, d in parts]

        out.append(
            Proposal(
                "auxiliary",
                name,
                cc,
                labs,
                float(lags.size * len(taus)),
                {"lag": lag, "tau": tc},
                True,
                axes,
                jacobian=jacobian if tc > 0 else None,
            )
        )
    return out


def _lag_power(ctx: Context, tu: NDArray[np.float64], h: NDArray[np.float64], lag: float) -> float:
    """:func:`_channel_power` of the response ``h`` (on times ``tu``) delayed by ``lag``."""
    return float(_channel_power(ctx, np.interp(ctx.t - lag, tu, h)[None, :])[0])


def _shortest_lag(
    ctx: Context,
    tu: NDArray[np.float64],
    h: NDArray[np.float64],
    lag: float,
    period: float,
    step: float,
    top: float,
) -> float:
    """The shortest of ``lag − k·period`` (refined) explaining ≥ 98 % of ``lag``'s power.

    With a per-period base (demodulation) a channel that repeats with the period
    (a platform temperature kicked by every rotation) couples the same at lags a
    period apart: searched up to 1080 s, a 120 s lag came out as 720 s (on the lag
    grid, where 120 s was not), with two spurious lines beside it.  A channel that
    does not repeat (QA: a slow temperature at 1000 s) keeps its lag.
    """
    here = _lag_power(ctx, tu, h, lag)
    for k in range(int(lag // period), 0, -1):  # shortest first
        cand = lag - k * period
        new, p = cand, _lag_power(ctx, tu, h, cand)
        if step > 0:
            new, p = _refine_lag(ctx, tu, h, cand, step, top, p)
        if p >= 0.98 * here:
            return new
    return lag


def _refine_lag(
    ctx: Context,
    tu: NDArray[np.float64],
    h: NDArray[np.float64],
    lag: float,
    step: float,
    top: float,
    power: float,
) -> tuple[float, float]:
    """(lag, power) of most explained power within one grid step of ``lag`` (bounded search).

    ``power``: that of ``lag`` itself.  On the grid alone a 600 s lag (grid points
    576 and 648 s) was fitted as 284 s plus a 300 s low-pass, and the shape left
    over at the start came out as an exponential settling.
    """
    from scipy.optimize import minimize_scalar

    def neg_power(lg: float) -> float:
        return -_lag_power(ctx, tu, h, lg)

    lo, hi = max(0.0, lag - step), min(top, lag + step)
    if hi <= lo:
        return lag, power
    res = minimize_scalar(neg_power, bounds=(lo, hi), method="bounded", options={"xatol": 0.5})
    return (float(res.x), float(-res.fun)) if -res.fun > power else (lag, power)


#: A refined low-pass time constant below this many sample steps is taken as a
#: pure lag (τ = 0, the lag grown by τ): the two cannot be told apart.
TAU_MIN_STEPS = 5.0
#: How far beyond the largest grid time constant (``aux_taus``) the refinement looks.
TAU_BEYOND = 2.0


def _refine_lag_tau(
    ctx: Context,
    tu: NDArray[np.float64],
    x: NDArray[np.float64],
    lag: float,
    tau: float,
    lag_step: float,
    top_lag: float,
    tau_range: tuple[float, float],
    power: float,
) -> tuple[float, float, float]:
    """(lag, τ, power) of most explained power near a grid point, both varied together.

    A low-pass delays the slow part of a channel by about its time constant, so a
    time constant between grid values is fitted by a neighbour plus a lag: lag and
    τ are searched jointly (Nelder-Mead within ``[0, top_lag] × tau_range``, from
    the grid point).  ``x``: the channel on the distinct sample times ``tu``.
    Returns the start unchanged unless the power grows.
    """
    from scipy.optimize import minimize

    t_u = ctx.t

    def neg_power(v: NDArray[np.float64]) -> float:
        lg, tc = float(v[0]), float(v[1])
        z = np.interp(t_u - lg, tu, _first_order(x, tu, tc))
        return -float(_channel_power(ctx, z[None, :])[0])

    lo_tau, hi_tau = tau_range
    d_lag = max(lag_step, 0.1 * tau, 10.0)
    d_tau = 0.5 * tau if tau + 0.5 * tau <= hi_tau else -0.5 * (tau - lo_tau)
    start = np.array([min(lag, top_lag), tau])
    simplex = np.array([start, start + [d_lag, 0.0], start + [0.0, d_tau]])
    simplex[:, 0] = np.clip(simplex[:, 0], 0.0, max(top_lag, 0.0))
    if simplex[1, 0] == start[0]:  # at the upper lag bound: step down instead
        simplex[1, 0] = max(start[0] - d_lag, 0.0)
    res = minimize(
        neg_power,
        start,
        method="Nelder-Mead",
        bounds=[(0.0, max(top_lag, 0.0)), (lo_tau, hi_tau)],
        options={"initial_simplex": simplex, "xatol": 2.0, "fatol": 1e-6 * power, "maxfev": 60},
    )
    if -res.fun > power:
        return float(res.x[0]), float(res.x[1]), float(-res.fun)
    return lag, tau, power


def max_lag(options: dict[str, Any], span: float) -> float:
    """Longest lag :func:`auxiliary` searches [s]: ``options["max_lag"]`` or min(span/20, 1 h)."""
    return float(options.get("max_lag", min(span / 20.0, 3600.0)))


def _channel_power(ctx: Context, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`_row_power` of the rows of ``z`` with one coefficient per data channel (summed)."""
    masks = ctx.channel_masks()
    if len(masks) == 1:
        return _row_power(ctx, z)
    return sum(_row_power(ctx, z * m) for m in masks)


def _row_power(ctx: Context, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """:meth:`Context.power` of the rows of ``z`` (m, n) (used samples)."""
    z2 = np.einsum("ij,ij->i", z, z)
    nrm = z2 - ctx.basis.captured(z.T)
    num = (z @ ctx.residual) ** 2
    return np.where(nrm > 1e-9 * np.maximum(z2, 1e-300), num / np.maximum(nrm, 1e-300), 0.0)


# --------------------------------------------------------------------------------------
# rotating platform


@dataclass(frozen=True)
class PlatformInfo:
    """What the rotating-platform candidates need, on every (stacked) sample.

    Built by :func:`accal.closure.demod.close_loop_demod`; passed to
    :func:`close_loop` as ``options["platform"]``.

    Attributes
    ----------
    theta : ndarray, shape (N,)
        Platform angle θ at each sample [rad].
    signal_y, signal_z : ndarray, shape (N,)
        Fitted demodulated signal ``a_Y(t)``, ``a_Z(t)`` at each sample (base
        model, eqs. 14/17) [m/s²].
    axis_index : ndarray of int, shape (N,)
        0 for an ``m_y`` sample, 1 for an ``m_z`` sample.
    since_rest : ndarray, shape (N,)
        Time since the platform came to rest (end of the last rotation) [s]; NaN
        while rotating.
    direction : ndarray, shape (N,)
        Sign of the last rotation (+1: θ increased, −1: decreased, 0: none yet).
    rest_angle : ndarray, shape (N,)
        Rest angle, rounded to 1e-3 rad (NaN while rotating) [rad].
    """

    theta: NDArray[np.float64]
    signal_y: NDArray[np.float64]
    signal_z: NDArray[np.float64]
    axis_index: NDArray[np.int64]
    since_rest: NDArray[np.float64]
    direction: NDArray[np.float64]
    rest_angle: NDArray[np.float64]

    def dm_dtheta(self) -> NDArray[np.float64]:
        """``∂m/∂θ`` on every sample [m/s² per rad] (eq. 4 with k₂ = 0, δk₁ = 0).

        ``m_y = cos θ a_Y + sin θ a_Z`` → ``−sin θ a_Y + cos θ a_Z``;
        ``m_z = −sin θ a_Y + cos θ a_Z`` → ``−cos θ a_Y − sin θ a_Z``.
        """
        c, s = np.cos(self.theta), np.sin(self.theta)
        ay, az = self.signal_y, self.signal_z
        return np.where(self.axis_index == 0, -s * ay + c * az, -c * ay - s * az)


def _platform(ctx: Context, what: str) -> PlatformInfo:
    info = ctx.options.get("platform")
    if not isinstance(info, PlatformInfo):
        raise ValidationError(
            f"{what} needs the platform angle θ and the fitted demodulated signal: call it "
            "through accal.closure.demod.close_loop_demod (options['platform'])"
        )
    return info


_IDENT_TOL = 1e-6


def _identifiable(ctx: Context, col: NDArray[np.float64]) -> float:
    """Relative norm of the part of ``col`` (used rows) outside the current design."""
    z = col[ctx.use]
    nz = float(np.linalg.norm(z))
    if nz == 0:
        return 0.0
    return float(np.linalg.norm(z - ctx.basis.project(z)) / nz)


def angle_offset(ctx: Context) -> list[Proposal]:
    """An error of the platform angle: ``m = P(θ + δ) a`` ≈ ``P(θ) a + δ ∂m/∂θ``.

    Regressor: ``∂m/∂θ`` from the fitted demodulated signal (eq. 4; the quadrature
    of the demodulated signal), coefficient ``δ`` [rad].  Variants:

    * ``channel="common"``: one offset for every sample (an encoder zero error).
      Since ``P(θ + δ) = P(θ) P(δ)``, it is a rotation of ``(a_Y, a_Z)`` by ``δ``:
      with the signal free in every period (eqs. 18-19) it is *never* identifiable
      from the data, whatever the pattern.  It is not proposed; a note says so.
    * ``channel="rest@<θ_g>"``: the rest angle ``θ_g`` is off by ``δ_g`` relative to
      the others (rests not exactly where the log says, e.g. not exactly π apart).
      With rests at 0 and π only, per period the data hold four numbers (the mean
      of each axis at each angle, as many as ``a_Y, a_Z, b_y, b_z``), so ``δ_g``
      is absorbed into the signal and bias: not identifiable (note).  It becomes
      identifiable when the pattern rests at three or more angles (e.g. 0, π/2, π,
      3π/2) and ``a`` is non-zero.
    * ``channel="scale"``: a scale error of the angle, ``θ_true = (1 + s) θ`` (an
      encoder gain), i.e. an offset ``s θ_g`` at every rest angle ``θ_g`` as logged:
      regressor ``θ ∂m/∂θ`` at rest samples, coefficient ``s`` [rad/rad].  One
      parameter where the per-rest offsets need one per angle (QA: on a four-rest
      pattern a scale error of 1e-3 came out as the π/2 rest's offset alone, plus
      settling shapes and lines, and a_Y got 4.5x worse).  Proposed with three or
      more rest angles (with two it is the other rest's offset).

    Identifiability is decided numerically: the regressor must keep more than
    ``1e-6`` of its norm after projecting out the current design.  Each
    identifiable variant is one proposal; the multiplicity is their number.
    """
    info = _platform(ctx, "angle_offset")
    g = info.dm_dtheta()
    out: list[Proposal] = []
    notes: list[Proposal] = []
    at_rest = np.isfinite(info.rest_angle)
    variants = [("common", np.isfinite(g), None)]
    angles = np.unique(info.rest_angle[ctx.use & at_rest])
    if angles.size > 1:
        ref = angles[int(np.argmin(np.abs(np.angle(np.exp(1j * angles)))))]
        for a in angles:
            if a != ref:
                variants.append((f"rest@{a:.4g}", info.rest_angle == a, float(a)))
    if angles.size > 2:  # with two rest angles a scale is the other rest's offset
        variants.append(("scale", at_rest, None))
    for channel, sel, ang in variants:
        if ctx.has_label(f"angle:{channel}"):
            continue
        col = np.where(sel, g, 0.0)
        if channel == "scale":
            col = np.where(sel, np.nan_to_num(info.theta) * g, 0.0)
        rel = _identifiable(ctx, col)
        if rel <= _IDENT_TOL:
            why = (
                "a common angle offset is a rotation of (a_Y, a_Z): P(θ+δ)a = P(θ)P(δ)a"
                if channel == "common"
                else "absorbed by the per-period signal and bias (rests at two angles only, "
                "or the rest angle's samples carry no independent information)"
            )
            notes.append(
                Proposal(
                    "angle_offset",
                    channel,
                    np.zeros((col.size, 0)),
                    (),
                    params={"relative_norm_outside_base": rel},
                    note=f"not identifiable: {why}",
                )
            )
            continue
        out.append(
            Proposal(
                "angle_offset",
                channel,
                col[:, None],
                (f"angle:{channel}",),
                1.0,
                {
                    "rest_angle": ang,
                    "relative_norm_outside_base": rel,
                    "units": "rad/rad" if channel == "scale" else "rad",
                },
            )
        )
    out = [Proposal(p.name, p.channel, p.columns, p.labels, float(len(out)), p.params) for p in out]
    return out + notes


def intra_period_shape(ctx: Context) -> list[Proposal]:
    """A bias shape repeating after every rotation: a settling transient.

    Family: ``A_axis · exp(−φ/τ_s)`` with ``φ`` the time since the platform came to
    rest, either the same after every rotation (``channel="common"``) or with the
    sign of the rotation (``channel="direction"``: e.g. a proof-mass tilt in the
    sense of rotation), one amplitude ``A`` per axis [m/s²], ``τ_s`` searched over
    ``settle_taus`` (default 5, 10, 20, 50, 100, 200 s); multiplicity: the number
    of (τ_s, sign) pairs.

    Why a parametric shape and not a free basis in phase-within-period: the part of
    any periodic shape that lies in the span of the per-period columns (signal
    ``cos θ`` and bias) cannot be told apart from a constant signal offset, so a
    free basis could not correct ``a_Y``/``a_Z``.  With a fixed shape, the part
    outside that span fixes ``A``, and subtracting ``A·shape`` removes its leak into
    the demodulated signal as well (e.g. a direction-dependent transient, whose
    ``cos θ`` component does not cancel over the symmetric pattern).
    """
    info = _platform(ctx, "intra_period_shape")
    taus = tuple(ctx.options.get("settle_taus", (5.0, 10.0, 20.0, 50.0, 100.0, 200.0)))
    phi = info.since_rest
    rest = np.isfinite(phi)
    shapes, keys = [], []
    for kind, sign in (("common", np.ones_like(phi)), ("direction", info.direction)):
        if ctx.has_label(f"shape:{kind}"):
            continue
        for ts in taus:
            shapes.append(np.where(rest, np.exp(-np.where(rest, phi, 0.0) / ts), 0.0) * sign)
            keys.append((kind, ts))
    if not shapes:
        return []
    z = np.column_stack(shapes)
    zu = z[ctx.use]
    z2 = np.sum(zu**2, axis=0)
    rel2 = 1.0 - ctx.basis.captured(zu) / np.maximum(z2, 1e-300)
    ok = (z2 > 0) & (rel2 > _IDENT_TOL**2)
    if not ok.any():
        return []
    pw = ctx.joint_power(zu)
    j = int(np.argmax(np.where(ok, pw, -1.0)))
    kind, ts = keys[j]
    sign = info.direction if kind == "direction" else np.ones_like(phi)
    ts = _refine_settle(ctx, phi, rest, sign, ts, sorted(taus))
    e = np.where(rest, np.exp(-np.where(rest, phi, 0.0) / ts), 0.0) * sign
    cols, labs, axes = ctx.split(e[:, None], (f"shape:{kind}",))

    def jacobian() -> list[tuple[str, NDArray[np.float64]]]:
        # ∂ exp(−φ/τ_s) / ∂ ln τ_s = (φ/τ_s) exp(−φ/τ_s)
        d = np.where(rest, np.where(rest, phi, 0.0) / ts, 0.0) * e
        return [("tau", ctx.split(d[:, None], (f"shape:{kind}",))[0])]

    return [
        Proposal(
            "intra_period_shape",
            kind,
            cols,
            labs,
            float(ok.sum()),
            {"tau": ts},
            axes=axes,
            jacobian=jacobian,
        )
    ]


def _refine_settle(
    ctx: Context,
    phi: NDArray[np.float64],
    rest: NDArray[np.bool_],
    sign: NDArray[np.float64],
    ts: float,
    grid: list[float],
) -> float:
    """The settling time constant of most explained power between the grid's neighbours.

    Bounded search on ln τ_s (to 1e-4), between the neighbouring grid values (a
    third / three times the end values).  On the grid alone a 60 s transient of
    2e-9 m/s² came out at 50 s with two lines, a step and a second shape, and
    a_Y's error stayed at 1.4e-10 m/s² (noise 4e-12).
    """
    from scipy.optimize import minimize_scalar

    k = grid.index(ts)
    lo = grid[k - 1] if k > 0 else ts / 3.0
    hi = grid[k + 1] if k + 1 < len(grid) else 3.0 * ts
    ph = np.where(rest, phi, 0.0)[ctx.use]
    sg = np.where(rest, sign, 0.0)[ctx.use]

    def neg_power(log_ts: float) -> float:
        col = np.exp(-ph / np.exp(log_ts)) * sg
        return -float(ctx.joint_power(col[:, None])[0])

    res = minimize_scalar(
        neg_power, bounds=(np.log(lo), np.log(hi)), method="bounded", options={"xatol": 1e-4}
    )
    if not res.success or -res.fun < -neg_power(np.log(ts)):
        return ts
    return float(np.exp(res.x))


#: Names accepted in ``close_loop(candidates=...)``.
BUILDERS: dict[str, Builder] = {
    "quadratic_drift": quadratic_drift,
    "cubic_drift": cubic_drift,
    "exponential_drift": exponential_drift,
    "bias_step": bias_step,
    "periodic": periodic,
    "auxiliary": auxiliary,
    "angle_offset": angle_offset,
    "intra_period_shape": intra_period_shape,
}
