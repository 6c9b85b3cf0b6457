"""Candidate effects: the search state handed to builders, proposals, drifts and steps.

A *builder* takes the current state of the fit (:class:`Context`) and proposes zero
or more :class:`Proposal` objects: the regressor columns of its best-fitting member
(best epoch, frequency, lag, ...) and the number of members searched, which the
selection uses as a Bonferroni factor so that searching many epochs or frequencies
does not buy false detections.

This module holds the polynomial and exponential drifts and the bias step; the
periodic terms are in :mod:`accal.closure.periodic`, the couplings to channels and
the scale error in :mod:`accal.closure.couplings`, the rotating-platform effects in
:mod:`accal.closure.platform`.  :mod:`accal.closure.kinds` lists them all with
their properties.  A caller with its own effect passes its builder function in
``close_loop(candidates=...)``.

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

from accal.closure.basis import Basis
from accal.closure.edgekernel import END_CLEAR, TRANSITION
from accal.closure.multiplicity import scan_factor, scan_length

if TYPE_CHECKING:
    from accal.closure.residual import Grid

__all__ = [
    "SQUARED",
    "Context",
    "Proposal",
    "bias_step",
    "cubic_drift",
    "exponential_drift",
    "quadratic_drift",
    "scan_multiplicity",
    "step_placebo_sigma",
]


#: Suffix of a channel's square (about its mean) among the couplings.
SQUARED = "^2"


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
        ``lag_scan``, ``aux_taus``, ``fmax``, ``settle_taus``), ``step_transition``
        (the data are low-passed, e.g. Level-1B: a bias step's final fit has the local
        columns of its ramp, :mod:`accal.closure.transition`) and ``platform``
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
    reference : ndarray, shape (N,), optional
        The reference acceleration the data were differenced with (for ``scale``).
    blocked : frozenset
        Members not to propose again (rejected: not identifiable, not confirmed on
        held-out stretches, or implausible), as ``(name, channel)`` or
        ``(name, channel, key)``.
    proxies : ndarray, shape (n, q), optional
        Series carrying the same signal (the other axes) on the used samples: the
        step scan looks for its epoch with them fitted
        (:class:`accal.closure.validation.SignalProxies`).
    coupled : dict of str to (float, float)
        The channels coupled in the model, each with its ``(lag, τ)`` [s]: the square
        of such a channel is proposed on the same path
        (:func:`accal.closure.couplings.auxiliary`).
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
    reference: NDArray[np.float64] | None = None
    blocked: frozenset = frozenset()
    proxies: NDArray[np.float64] | None = None
    coupled: dict[str, tuple[float, float]] = field(default_factory=dict)

    def is_blocked(self, name: str, channel: str | None, key: Any = None) -> bool:
        """Whether the member ``(name, channel[, key])`` was rejected earlier."""
        return (name, channel) in self.blocked or (name, channel, key) in self.blocked

    @property
    def t(self) -> NDArray[np.float64]:
        """Times of the used samples [s]."""
        return self.t_all[self.use]

    @property
    def qx(self) -> NDArray[np.float64]:
        """The orthonormal basis as a dense (n, p) array (small designs only)."""
        return self.basis.dense_q()

    @property
    def scan_level(self) -> float:
        """The level a scan's multiplicity is taken at: alpha over the candidate
        families (the decision boundary of a corrected p-value)."""
        return float(self.options.get("alpha", 0.01)) / float(self.options.get("families", 1))

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
        for the final fit's Jacobian (:func:`accal.closure.final.with_jacobian`).
    """

    name: str
    channel: str | None
    columns: NDArray[np.float64]
    labels: tuple[str, ...]
    multiplicity: float = 1.0
    params: dict[str, Any] = field(default_factory=dict)
    axes: tuple[str, ...] | None = None
    note: str | None = None
    jacobian: Callable[[], list[tuple[str, NDArray[np.float64]]]] | None = field(
        default=None, compare=False
    )

    @property
    def path(self) -> tuple[float, float]:
        """A coupling's ``(lag, τ)`` [s] (0 for either when not set)."""
        return float(self.params.get("lag") or 0.0), float(self.params.get("tau") or 0.0)

    @property
    def squared(self) -> bool:
        """Whether this is a coupling to a channel's square (``NAME^2``)."""
        return str(self.channel).endswith(SQUARED)


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
            {"powers": missing, "scale": ctx.span, "t0": ctx.t0},
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
    power = channel_power(ctx, np.exp(-el[None, :] / taus[:, None]))  # one A per channel
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
            {"tau": tau, "t0": ctx.t0},
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
        return -float(channel_power(ctx, np.exp(-el / np.exp(log_tau))[None, :])[0])

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


#: Least separation of two bias steps [s]: closer, two opposite steps are a box (a burst,
#: a thruster firing's tail), not two changes of the instrument's bias (QA: pairs of
#: ±3e-10 m/s² steps 30-80 s apart on a simulated GRACE-FO day).
STEP_SEPARATION = 600.0


def bias_step(ctx: Context) -> list[Proposal]:
    """A bias step at an unknown epoch: the best single change point of the residual.

    Without a reference the orbit-periodic signal is in the null model
    (:class:`accal.closure.nuisance.OrbitTemplate`): the residual the scan sees has
    no eclipse edges left to snap to.

    The scan evaluates the OLS power of ``1[t ≥ τ]`` (design projected out) for every
    used sample ``τ`` at least ``min_segment`` samples (default 10) from either end, with cumulative sums
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
    # a block base (one bias per demodulation period) scans every block on its own and
    # its multiplicity counts them, so only the record's last samples are left out
    # (QA: a step 10-60 s from a run's end came out as steps of the wrong sign)
    min_seg = int(ctx.options.get("min_segment", 10)) * len(masks)
    if ctx.options.get("step_transition") and n > 1:
        # low-passed data: a step is a ramp of ±TRANSITION s, which must lie inside the
        # record (a "step" at a tests/indep day's 10th sample, 4.2e-9 ± 8e-10 m/s², was
        # removed and moved the bias by 3.7σ: ten samples at the start are no level),
        # and at least END_CLEAR from the ends
        dt = float(np.median(np.diff(t)))
        if dt > 0:
            clear = max(2.0 * TRANSITION, END_CLEAR)
            min_seg = max(min_seg, int(np.ceil(clear / dt)) * len(masks))
    if n < 2 * min_seg + 2:
        return []
    r = ctx.residual
    ok = np.zeros(n, dtype=bool)
    ok[min_seg : n - min_seg + 1] = True  # at least min_seg samples on either side
    ok &= np.r_[True, np.diff(t) > 0]  # epochs at the first sample of a time
    for lab in ctx.labels:  # no second step within STEP_SEPARATION of an existing one
        if lab.startswith("step@"):
            e = float(lab[5:].split(":")[0])
            ok &= np.abs(t - e) >= max(STEP_SEPARATION, min_seg * 1.0)
    near = max(min_seg, n // 200)
    for key in ctx.blocked:  # nor near a rejected one
        if len(key) == 3 and key[0] == "bias_step":
            i = int(np.searchsorted(t, float(key[2])))
            ok[max(0, i - near) : i + near] = False
    extra = None
    if ctx.proxies is not None:
        # the epoch is looked for with the other axes' signal fitted: a storm's onset,
        # which they explain, would otherwise be the best epoch again and again (each
        # rejected by the signal-proxy check) while a real step elsewhere waited
        extra = ctx.basis.complement(ctx.proxies)
        r = r - extra @ (extra.T @ r)
    stat = _scan(ctx.basis, r, masks, ok, extra)
    if not ok.any():
        return []
    i = int(np.argmax(np.where(ok, stat, -1.0)))
    epoch = float(t[i])
    m_tests = float(min(ctx.options.get("step_tests", 200), ok.sum()))
    block = ctx.basis.block
    if ctx.basis.n_blocks > 1:  # a scan in every block holding candidate epochs
        counts = np.bincount(block[masks[0] & (block >= 0)], minlength=ctx.basis.n_blocks)
        scanned = np.unique(block[ok & (block >= 0)])
        fractions = 1.0 / np.maximum(counts[scanned], 1)
    else:  # one scan over the record, epochs at least min_segment from the ends
        fractions = np.array([min_seg / max(n, 1)])
    level = ctx.scan_level
    mult = max(m_tests, scan_multiplicity(fractions, len(masks), level))
    length = scan_length(ctx, ok)  # a nuisance in the model: measured decorrelation
    if length is not None:
        mult = max(mult, scan_factor(2.0 * length, len(masks), level))
    out = [_step_proposal(ctx, [epoch], mult)]
    # the best second epoch given the first: two steps that mask each other (a box of
    # +1e-9/-1e-9 m/s²: alone each had p 1.0, the other inflating the low-frequency
    # noise estimate) are tested together, at the pairs' multiplicity; the selection
    # takes the pair only when no single step is significant
    zt = ctx.basis.complement((t >= epoch).astype(np.float64))
    if zt.shape[1] == 0:
        return out
    if extra is not None and extra.shape[1]:
        zt = np.linalg.qr(np.column_stack([extra, zt]))[0]
    r2 = ctx.residual - zt @ (zt.T @ ctx.residual)
    ok2 = ok & (np.abs(t - epoch) >= STEP_SEPARATION)
    stat2 = _scan(ctx.basis, r2, masks, ok2, zt)
    if ok2.any():
        j = int(np.argmax(np.where(ok2, stat2, -1.0)))
        out.append(_step_proposal(ctx, sorted([epoch, float(t[j])]), 0.5 * mult**2))
    return out


def _step_sums(basis, r, m, extra=None):
    """For a step ``1[t ≥ e]`` on channel mask ``m`` at every used sample ``e``: its inner
    product with ``r`` (``Σ_{t≥e} r``), its norm with the design projected out, and
    where that norm is defined.  ``extra``: orthonormal columns orthogonal to the
    design, projected out too (the design extended without forming it)."""
    rm = r * m
    s_r = np.cumsum(rm[::-1])[::-1]
    cnt = np.cumsum(m[::-1].astype(float))[::-1]
    nrm = cnt - basis.step_norms(m)
    if extra is not None and extra.shape[1]:
        nrm = nrm - np.sum(np.cumsum((extra * m[:, None])[::-1], axis=0)[::-1] ** 2, axis=1)
    good = nrm > 1e-6 * np.maximum(cnt, 1.0)
    return s_r, np.where(good, nrm, 1.0), good


def _scan(basis, r, masks, ok, extra=None) -> NDArray[np.float64]:
    """Explained power of a step at every used sample (``ok`` is cleared where undefined);
    ``extra``: see :func:`_step_sums`."""
    stat = np.zeros(r.size)
    for m in masks:
        s_r, nrm, good = _step_sums(basis, r, m, extra)
        ok &= good
        stat += np.where(good, s_r**2 / nrm, 0.0)
    return stat


#: Fewest placebo epochs (one per other block) for :func:`step_placebo_sigma`.
PLACEBO_MIN = 20


def step_placebo_sigma(ctx: Context, epoch: float) -> NDArray[np.float64] | None:
    """Empirical σ of a step's size per data channel from placebo epochs (block base).

    With a per-block base (one bias per demodulation period) a step's size comes from
    the samples of its own block, where whatever the model lacks within a period adds
    to the noise: the signal's change within a period ("mean" signal model) moved
    platform step sizes by 1-2e-10 m/s² against a σ of 1.5e-11 from the noise model
    (closure-detection: z RMS 24; 0.93 with a constant signal).  The size a step would
    get at the same offset into every other block, where there is none, is a sample of
    that error (a placebo test: the estimator applied where the effect is known to be
    absent, e.g. Abadie, Diamond & Hainmueller 2010, JASA 105, 493); its robust RMS
    about zero (1.4826 × median |size|) is the empirical σ.  The sizes are the exact
    least-squares ones given the model ``ctx`` (``Σ_{t≥e} r / ‖(I − P)1[t≥e]‖²``).
    None for a one-block base or fewer than :data:`PLACEBO_MIN` placebo blocks.
    """
    basis = ctx.basis
    if basis.n_blocks < 2:
        return None
    t = ctx.t
    if t.size < 4:
        return None
    block = np.asarray(basis.block)
    ok = np.r_[True, np.diff(t) > 0] & (block >= 0)
    sizes = []
    for m in ctx.channel_masks():
        s_r, nrm, good = _step_sums(basis, ctx.residual, m)
        ok &= good
        sizes.append(np.where(good, s_r / nrm, np.nan))
    i0 = min(int(np.searchsorted(t, epoch)), t.size - 1)
    b0 = int(block[i0])
    if b0 < 0:
        return None
    valid = block >= 0
    start = np.full(basis.n_blocks, np.inf)
    np.minimum.at(start, block[valid], t[valid])
    idx = np.flatnonzero(ok & (block != b0))
    if idx.size == 0:
        return None
    dist = np.abs(t[idx] - (start[block[idx]] + (epoch - start[b0])))
    order = np.lexsort((dist, block[idx]))  # by block, nearest first
    first = order[np.r_[True, np.diff(block[idx][order]) != 0]]
    step = float(np.median(np.diff(t[ok]))) if ok.sum() > 1 else 1.0
    pick = idx[first][dist[first] <= 2.0 * max(step, 1e-300)]
    if pick.size < PLACEBO_MIN:
        return None
    return np.array([1.4826 * float(np.median(np.abs(s[pick]))) for s in sizes])


def _step_proposal(ctx: Context, epochs: list[float], mult: float) -> Proposal:
    """Steps at ``epochs`` (one, or a pair tested together and split when accepted)."""
    cols = np.column_stack([(ctx.t_all >= e).astype(np.float64) for e in epochs])
    labs = tuple(f"step@{e!r}" for e in epochs)
    cols, labs, axes = ctx.split(cols, labs)
    # the final fit models a ramp in low-passed data (options["step_transition"])
    ramp = {"transition": True} if ctx.options.get("step_transition") else {}
    if len(epochs) == 1:
        params = {"epoch": epochs[0], **ramp}
        return Proposal("bias_step", None, cols, labs, mult, params, axes=axes)
    n_c = max(ctx.n_chan, 1)
    parts = []
    for k, e in enumerate(epochs):  # columns of step k: one per channel
        idx = [k + len(epochs) * c for c in range(n_c)] if axes is not None else [k]
        parts.append((idx, {"epoch": e, **ramp}))
    return Proposal(
        "bias_step",
        None,
        cols,
        labs,
        mult,
        {"epoch": epochs[0], "pair": True, "parts": parts},
        axes=axes,
    )


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
    eps = np.clip(np.asarray(fractions, dtype=np.float64), 1e-12, 0.5)
    return scan_factor(float(np.sum(2.0 * np.log((1.0 - eps) / eps))), k, level)


def channel_power(ctx: Context, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`row_power` of the rows of ``z`` with one coefficient per data channel (summed)."""
    masks = ctx.channel_masks()
    if len(masks) == 1:
        return row_power(ctx, z)
    return sum(row_power(ctx, z * m) for m in masks)


def row_power(ctx: Context, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """:meth:`Context.power` of the rows of ``z`` (m, n) (used samples)."""
    zr, nrm, ok = row_fit(ctx, z)
    return np.where(ok, zr**2 / np.maximum(nrm, 1e-300), 0.0)


def row_fit(ctx: Context, z: NDArray[np.float64]):
    """``z̃ᵀr`` and ``z̃ᵀz̃`` of the rows of ``z`` (m, n) (used samples; ``z̃``: the design
    projected out, so the OLS coefficient is their ratio) and whether a row has anything
    outside the design (over 1e-9 of its power)."""
    z2 = np.einsum("ij,ij->i", z, z)
    nrm = z2 - ctx.basis.captured(z.T)
    return z @ ctx.residual, nrm, nrm > 1e-9 * np.maximum(z2, 1e-300)
