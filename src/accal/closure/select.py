"""Close the loop: find what a linear base model lacks, add it, refit, repeat.

:func:`close_loop` is forward selection over the candidate library
(:mod:`accal.closure.candidates`) with the coloured-noise sandwich F-test of
:mod:`accal.closure.residual`:

1. fit the current design by least squares on the used samples;
2. ask every builder for its best proposal; test each proposal's regressors
   (orthogonalised against the design) with the sandwich Wald/F test, and multiply
   its p-value by the proposal's multiplicity (epochs, frequencies or lags searched)
   and by the number of candidate families (Bonferroni): the family-wise false
   detection probability per iteration is then ≤ ``alpha``.  Among the significant
   proposals the one that explains the most residual power is taken (p-values of
   very significant effects say little about which one is *the* cause);
3. periodic and auxiliary effects must also be *consistent*: their coefficients in
   the three thirds of the record may not differ significantly (p < 1e-3) and by more
   than 30 %, otherwise the structure is reported as ``unexplained`` (a chirp is not
   a sinusoid) and the next proposal is tried;
4. add the best significant proposal; then re-test every effect added before it
   given all the others (backward elimination): one that is no longer significant
   was standing in for the new one (e.g. the once-per-orbit part of a temperature
   coupling taken as ``periodic``) and is removed, and its search family may propose
   again; go back to 1, at most ``max_effects`` additions;
4b. compare the drift terms found (quadratic, cubic, exponential) with one slow
   exponential settling of T up to the span, by Wald statistic less a χ²₁ quantile
   per parameter; the exponential replaces them when its score is larger by more than
   :data:`SWAP_MIN_GAIN` (:meth:`_Search.smooth_swap`); the final fit carries the
   Jacobian of every exponential's T, so σ(T) and its cost to the other
   coefficients are in the covariances (:func:`_with_tau_jacobian`);
5. finally test a generic smooth basis (piecewise-linear, ``catchall_knots`` knots) on
   top of the final model against the white + 1/f noise model fitted above twice the
   basis' frequencies and extrapolated down (the residual itself cannot tell slow
   structure from slow noise).  If it is significant, several effects may be
   masking one another: the best member of every family is added at once, refined
   and backward-eliminated (:meth:`_Search.backward`); what is still left is
   reported as ``unexplained`` with its dominant frequency, never as a named effect.

The base may be block-diagonal (:class:`~accal.closure.basis.BlockBase`, e.g. the
per-period demodulation model); every projection and covariance is then computed
block by block (:class:`~accal.closure.basis.Basis`).  Several data channels sharing
a time grid (``channel``) are fitted jointly, with independent noises of a common
PSD.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.closure.basis import Basis, BlockBase, FitResult
from accal.closure.candidates import BUILDERS, TAU_MIN_STEPS, Context, Proposal, max_lag
from accal.closure.residual import (
    Grid,
    ResidualStats,
    _quad,
    _two_sided,
    characterise,
    estimate_psd,
    make_grid,
    projection_bias,
    wald_test,
    white_plus_flicker,
)
from accal.errors import ValidationError, check_option

#: Fewest usable samples :func:`close_loop` analyses.
MIN_SAMPLES = 50

__all__ = ["DEFAULT_CANDIDATES", "BaseCoefficient", "ClosureResult", "Effect", "close_loop"]

DEFAULT_CANDIDATES = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
)
_POLY_BASES = ("poly0", "poly1", "poly2", "poly3")
_POLY_NAMES = ("bias", "drift", "quadratic", "cubic")
_CONSISTENCY_P = 1e-3
_CONSISTENCY_REL = 0.3


@dataclass(frozen=True)
class Effect:
    """One effect found (or one piece of structure left unexplained).

    Attributes
    ----------
    name : str
        ``quadratic_drift``, ``cubic_drift``, ``exponential_drift``, ``bias_step``, ``periodic``,
        ``auxiliary``, ``angle_offset``, ``intra_period_shape`` or ``unexplained``.
    channel : str or None
        Auxiliary channel name; ``"orbit"``/``"line"`` for periodic effects;
        ``"common"``/``"rest@<θ>"`` for angle offsets; ``"common"``/``"direction"``
        for intra-period shapes; for ``unexplained``: ``"smooth"`` (catch-all) or
        the rejected kind.
    coefficient : float
        Step size [m/s²]; coefficient of the highest power of ``(t − t0)``
        [m/s⁴ or m/s⁵]; coupling [m/s² per channel unit]; amplitude of the
        fundamental [m/s²]; angle offset [rad]; settling amplitude [m/s²]; RMS of
        the unexplained component [m/s²].
    sigma : float
        1σ uncertainty of ``coefficient`` under the coloured-noise model.
    significance : float
        Multiplicity-corrected p-value of the effect given all the other effects of
        the final model (``details["p_accept"]``: of the test that admitted it).
    epoch : float or None
        Step epoch (first sample after the step) [s].
    frequency : float or None
        Fundamental frequency (periodic) or dominant frequency (unexplained) [Hz].
    lag : float or None
        Lag of the auxiliary response [s].
    tau : float or None
        Time constant of the first-order auxiliary response, or of the settling
        transient [s] (0: none).
    details : dict
        Everything else (all coefficients of the family, phases, shape, ...); with
        several data channels ``details["axes"]`` holds the coefficient and sigma
        of every channel.
    axis : str or None
        With several data channels: the channel whose coefficient is reported in
        ``coefficient`` (the most significant one).
    """

    name: str
    channel: str | None
    coefficient: float
    sigma: float
    significance: float
    epoch: float | None = None
    frequency: float | None = None
    lag: float | None = None
    tau: float | None = None
    details: dict[str, Any] = field(default_factory=dict)
    axis: str | None = None


@dataclass(frozen=True)
class BaseCoefficient:
    """A base-model coefficient before and after closing the loop.

    ``sigma_change`` is the uncertainty of the difference of the two (correlated)
    linear estimators, evaluated under the final residual's noise.  NaN for a
    coefficient the data do not determine (a block without used samples).
    ``sigma_plain`` is the base-only fit's σ under that same noise: ``sigma_after² −
    sigma_plain²`` is what estimating the effects adds (a refit that subtracts the
    effects as if known adds it back; see ``accal.pipeline``).
    """

    name: str
    before: float
    sigma_before: float
    after: float
    sigma_after: float
    change: float
    sigma_change: float
    sigma_plain: float = float("nan")

    @property
    def change_significant(self) -> bool:
        """Whether the change exceeds twice its uncertainty."""
        return bool(abs(self.change) > 2.0 * self.sigma_change)


@dataclass(frozen=True)
class ClosureResult:
    """Outcome of :func:`close_loop`.

    Attributes
    ----------
    effects : tuple of Effect
        Effects added to the model, in the order found.
    unexplained : tuple of Effect
        Structure that no candidate explains (name ``"unexplained"``).
    base : tuple of BaseCoefficient
        Base coefficients before/after; for polynomial bases ``bias`` [m/s²] at
        ``t0``, ``drift`` [m/s³], ... in powers of ``t − t0``; for a block base
        ``f"{name}[{block}]"``.
    t0 : float
        Reference epoch, the first used sample [s].
    rms_before, rms_after : float
        Residual RMS over the used samples [m/s²].
    time : ndarray, shape (N,)
        Sample times [s].
    use : ndarray of bool, shape (N,)
        Samples used.
    residual_before, residual_after : ndarray, shape (N,)
        ``y − model`` on all samples [m/s²] (NaN where the base is undetermined).
    base_design : BlockBase
        The base design on all samples.
    effect_columns : ndarray, shape (N, e)
        Regressors of the effects found, on all samples.
    labels : tuple of str
        Labels of the design's columns (base first).
    coef : ndarray, shape (k,)
        Coefficients of the design (internal scaling: powers of ``(t−t0)/span``).
    base_cov : ndarray, shape (n_blocks, p, p)
        Coloured-noise covariance of each block's base coefficients (internal scaling).
    cross_cov : ndarray, shape (n_base, e)
        Covariance of base and effect coefficients.
    effects_cov : ndarray, shape (e, e)
        Covariance of the effect coefficients.
    n_base : int
        Number of base columns.
    stats_before, stats_after : ResidualStats
        Residual characterisation before/after.
    iterations : int
        Selection iterations run.
    notes : tuple of dict
        Candidates that could not be tested on these data (``name``, ``channel``,
        ``note``), e.g. an angle offset that is not identifiable.
    channel : ndarray of int, shape (N,), optional
        Data channel of every sample (several channels).
    channel_names : tuple of str
        Their names (empty for one channel).
    removed : tuple of Effect
        Effects added and later removed by backward elimination.
    alternatives : tuple of str
        Channels whose significant coupling the search passed over for another
        effect (:func:`_best_branch` tries them first).
    """

    effects: tuple[Effect, ...]
    unexplained: tuple[Effect, ...]
    base: tuple[BaseCoefficient, ...]
    t0: float
    rms_before: float
    rms_after: float
    time: NDArray[np.float64]
    use: NDArray[np.bool_]
    residual_before: NDArray[np.float64]
    residual_after: NDArray[np.float64]
    base_design: BlockBase
    effect_columns: NDArray[np.float64]
    labels: tuple[str, ...]
    coef: NDArray[np.float64]
    base_cov: NDArray[np.float64]
    cross_cov: NDArray[np.float64]
    effects_cov: NDArray[np.float64]
    n_base: int
    stats_before: ResidualStats
    stats_after: ResidualStats
    iterations: int
    notes: tuple[dict[str, Any], ...] = ()
    channel: NDArray[np.int64] | None = None
    channel_names: tuple[str, ...] = ()
    removed: tuple[Effect, ...] = ()
    alternatives: tuple[str, ...] = ()

    @property
    def found(self) -> bool:
        """True when any effect or unexplained structure was reported."""
        return bool(self.effects or self.unexplained)

    @property
    def design(self) -> NDArray[np.float64]:
        """The final design as a dense (N, k) matrix (base columns first).

        Formed on demand: for a block base with many blocks prefer
        :meth:`model` and :meth:`effects_model`.
        """
        return np.column_stack([self.base_design.dense(), self.effect_columns])

    @property
    def cov(self) -> NDArray[np.float64]:
        """Coloured-noise covariance (k, k) of :attr:`coef`.

        For a base with several blocks the covariances between base coefficients
        of *different* blocks are not computed (NaN).
        """
        nb, p = self.base_design.n_blocks, self.base_design.p
        k = self.n_base + self.effects_cov.shape[0]
        out = np.full((k, k), np.nan)
        for b in range(nb):
            out[b * p : (b + 1) * p, b * p : (b + 1) * p] = self.base_cov[b]
        out[: self.n_base, self.n_base :] = self.cross_cov
        out[self.n_base :, : self.n_base] = self.cross_cov.T
        out[self.n_base :, self.n_base :] = self.effects_cov
        return out

    def model(self) -> NDArray[np.float64]:
        """The final model (base + effects) on all samples [m/s²]."""
        return self.base_design.matvec(self.coef[: self.n_base]) + self.effects_model()

    def effects_model(self) -> NDArray[np.float64]:
        """The effects alone (what to subtract to correct the data) on all samples [m/s²]."""
        return self.effect_columns @ self.coef[self.n_base :]

    def effect_models(self) -> list[tuple[Effect, NDArray[np.float64]]]:
        """Each effect with its fitted contribution on all samples [m/s²] (sums to
        :meth:`effects_model`)."""
        out = []
        j = 0
        for e in self.effects:
            q = int(e.details.get("n_columns", 1))
            out.append(
                (
                    e,
                    self.effect_columns[:, j : j + q]
                    @ self.coef[self.n_base + j : self.n_base + j + q],
                )
            )
            j += q
        return out

    def base_coefficient(self, name: str) -> BaseCoefficient:
        """The :class:`BaseCoefficient` called ``name``."""
        for b in self.base:
            if b.name == name:
                return b
        names = [b.name for b in self.base]
        shown = names if len(names) <= 12 else names[:12] + ["..."]
        raise KeyError(f"no base coefficient {name!r} (have {shown})")

    def true_error(self, truth: dict[str, float]) -> dict[str, dict[str, float]]:
        """Errors of the base coefficients against known true values (simulations).

        Returns ``{name: {"before": before − truth, "after": after − truth}}`` for
        every name in both ``truth`` and ``base``.
        """
        out = {}
        for b in self.base:
            if b.name in truth:
                out[b.name] = {
                    "before": b.before - float(truth[b.name]),
                    "after": b.after - float(truth[b.name]),
                }
        return out

    def to_dict(self, truth: dict[str, float] | None = None) -> dict[str, Any]:
        """JSON-able summary (the ``closure.json`` layout, see :mod:`accal.closure.report`)."""
        from accal.closure.report import result_to_dict

        return result_to_dict(self, truth=truth)


# --------------------------------------------------------------------------------------
# base designs


def _poly_base(order: int, t: NDArray[np.float64], t0: float, span: float, chan, names):
    u = (t - t0) / span
    cols = np.column_stack([u**k for k in range(order + 1)])
    scale = np.array([span**-k for k in range(order + 1)])
    nm = _POLY_NAMES[: order + 1]
    lb = tuple(f"t^{k}" for k in range(order + 1))
    if not names:
        return BlockBase.from_dense(cols, nm, lb, scale)
    split = np.column_stack([cols * (chan == c)[:, None] for c in range(len(names))])
    return BlockBase.from_dense(
        split,
        tuple(f"{x}:{c}" for c in names for x in nm),
        tuple(f"{x}:{c}" for c in names for x in lb),
        np.tile(scale, len(names)),
    )


def _base_design(
    base: str | ArrayLike | BlockBase,
    t: NDArray[np.float64],
    t0: float,
    span: float,
    chan: NDArray[np.int64] | None,
    names: tuple[str, ...],
) -> BlockBase:
    """The base as a :class:`BlockBase` on all samples."""
    if isinstance(base, BlockBase):
        if base.block.size != t.size:
            raise ValidationError(f"base must cover {t.size} samples, got {base.block.size}")
        return base
    if isinstance(base, str):
        check_option("base", base, _POLY_BASES)
        return _poly_base(int(base[-1]), t, t0, span, chan, names)
    x = np.asarray(base, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != t.size:
        raise ValidationError(f"base design must have shape ({t.size}, p), got {x.shape}")
    p = x.shape[1]
    return BlockBase.from_dense(
        x, tuple(f"b{j}" for j in range(p)), tuple(f"base{j}" for j in range(p))
    )


# --------------------------------------------------------------------------------------
# helpers


def _segment_masks(t: NDArray[np.float64], k: int = 3) -> list[NDArray[np.bool_]]:
    edges = np.linspace(t[0], t[-1], k + 1)
    seg = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, k - 1)
    return [seg == j for j in range(k)]


def _consistency(
    grid: Grid, basis: Basis, z: NDArray[np.float64], y: NDArray[np.float64], t, lev_fn
) -> tuple[bool, dict[str, Any]]:
    """Is the effect's coefficient the same in each third of the record?"""
    masks = _segment_masks(t)
    q = z.shape[1]
    bxz = basis.extend(z)
    fit = bxz.fit(y)
    extra = np.column_stack([z * m[:, None] for m in masks[:-1]])
    zt = bxz.complement(extra)
    if zt.shape[1] == 0:
        return True, {}
    w = wald_test(grid, fit.resid, zt, lev_fn(bxz))
    full = fit.gamma[-q:]
    seg_coefs = []
    for m in masks:
        if m.sum() < 10 * (int(basis.rank.sum()) + basis.n_extra + q):
            continue
        c = bxz.restrict(m).fit(y[m]).gamma[-q:]
        if np.all(np.isfinite(c)):
            seg_coefs.append(c)
    scale = float(np.linalg.norm(full)) or 1.0
    rel = max((float(np.linalg.norm(c - full)) / scale for c in seg_coefs), default=0.0)
    ok = not (w.pvalue < _CONSISTENCY_P and rel > _CONSISTENCY_REL)
    return ok, {"consistency_p": w.pvalue, "segment_deviation": rel}


def _catchall(t: NDArray[np.float64], knots: int) -> NDArray[np.float64]:
    nodes = np.linspace(t[0], t[-1], knots)
    h = nodes[1] - nodes[0]
    return np.clip(1.0 - np.abs(t[:, None] - nodes[None, :]) / h, 0.0, None)


def _resolve(candidates: Sequence[str | Callable]) -> list[tuple[str, Callable]]:
    out = []
    for c in candidates:
        if callable(c):
            out.append((getattr(c, "__name__", "custom"), c))
        else:
            check_option("candidates", c, tuple(BUILDERS))
            out.append((c, BUILDERS[c]))
    return out


def _with_tau_jacobian(
    f: _Found,
    t_all: NDArray[np.float64],
    t0: float,
    use: NDArray[np.bool_],
    rest: Callable[[], Basis],
) -> _Found:
    """An effect with a fitted time constant, with its Jacobian as extra columns.

    The selection searches ``T`` (:func:`accal.closure.candidates.exponential_drift`)
    and fits ``A`` with ``T`` held.  Linearised at the fitted ``T``,
    ``A·exp(−(t−t0)/(T+δ)) ≈ A·e + β·((t−t0)/T)·e`` with ``e = exp(−(t−t0)/T)`` and
    ``β = A·δ/T``: one more column per channel.  Fitting it with the others is the
    Gauss-Newton covariance of the nonlinear least-squares problem, so σ(T) =
    σ(β)·T/|A| and the base coefficients' σ include what not knowing ``T`` costs
    (a decay of T = 60,000 s over a day had a bias σ 12x too small without it).
    A coupling through a first-order low-pass (:func:`accal.closure.candidates.auxiliary`)
    is treated alike: ``c·h_{τ+δ}(x) ≈ c·h_τ(x) + β·∂h_τ(x)/∂lnτ`` (the derivative by
    a central difference, :attr:`~accal.closure.candidates.Proposal.jacobian`, with the lag's too), so
    σ(τ) = σ(β)·τ/|c| and the bias σ includes it (a 500 s low-pass to a 293 K channel:
    bias z 6 without it).  Other effects, and a Jacobian that is not independent of
    the rest of the design (``rest()``: the base and the other effects, formed only
    when needed), are returned unchanged.
    """
    prop = f.prop
    cols = prop.columns
    if prop.name == "exponential_drift" and prop.params.get("tau"):
        parts = [("tau", cols * ((t_all - t0) / float(prop.params["tau"]))[:, None])]
    elif prop.jacobian is not None:  # a coupling: lag and low-pass, numerically
        parts = prop.jacobian()
    else:
        return f
    jac = np.column_stack([d for _, d in parts])
    names = [k for k, _ in parts]
    aug = Proposal(
        prop.name,
        prop.channel,
        np.column_stack([cols, jac]),
        (*prop.labels, *(f"d{lb}/d{k}" for k in names for lb in prop.labels)),
        prop.multiplicity,
        {**prop.params, "jacobian": cols.shape[1], "jacobian_params": names},
        prop.check_consistency,
        None if prop.axes is None else tuple(prop.axes) * (1 + len(names)),
    )
    if _independent(rest(), aug, use).columns.shape[1] != aug.columns.shape[1]:
        return f
    return _Found(aug, f.p_adj, f.info, f.builder)


def _independent(basis: Basis, prop: Proposal, use: NDArray[np.bool_], tol: float = 1e-8):
    """``prop`` reduced to columns that are independent of the design and of each other."""
    z = prop.columns[use]
    zt = z - basis.project(z)
    norms0 = np.linalg.norm(z, axis=0)
    from scipy.linalg import qr

    _, r, piv = qr(zt, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    keep = np.sort(piv[: int(np.sum(d > tol * max(float(norms0.max()), 1e-300)))])
    if keep.size == z.shape[1]:
        return prop
    return Proposal(
        prop.name,
        prop.channel,
        prop.columns[:, keep],
        tuple(prop.labels[i] for i in keep),
        prop.multiplicity,
        prop.params,
        prop.check_consistency,
        None if prop.axes is None else tuple(prop.axes[i] for i in keep),
    )


def _families(builders, aux, orbit_period) -> int:
    n = 0
    for name, _ in builders:
        if name == "auxiliary":
            n += len(aux)
        elif name == "periodic":
            n += 2 if orbit_period else 1
        else:
            n += 1
    return max(n, 1)


def _split_cols(cols, chan_u, names):
    """Per-channel copies of ``cols`` on the used samples (several channels)."""
    if not names:
        return cols
    return np.column_stack([cols * (chan_u == c)[:, None] for c in range(len(names))])


# --------------------------------------------------------------------------------------


def close_loop(
    t: ArrayLike,
    y: ArrayLike,
    *,
    base: str | ArrayLike | BlockBase = "poly1",
    aux: dict[str, ArrayLike] | None = None,
    valid: ArrayLike | None = None,
    candidates: Sequence[str | Callable] = DEFAULT_CANDIDATES,
    alpha: float = 0.01,
    max_effects: int = 5,
    orbit_period: float | None = None,
    catchall_knots: int = 24,
    options: dict[str, Any] | None = None,
    channel: ArrayLike | None = None,
    channel_names: Sequence[str] | None = None,
    noise_psd: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    resolution: float | None = None,
) -> ClosureResult:
    """Find the effects a linear base model lacks, add them and refit.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, strictly increasing (within each channel, non-decreasing
        overall when ``channel`` is given) [s].
    y : array_like, shape (N,)
        Data [m/s²] (e.g. one accelerometer axis, or raw − reference).
    base : {"poly0", "poly1", "poly2", "poly3"}, array_like (N, p0) or BlockBase
        The base model: a polynomial in ``t − t0`` (``t0``: first used sample; one
        per channel), the caller's own dense design matrix, or a block-diagonal
        design (:class:`~accal.closure.basis.BlockBase`, e.g. the per-period
        demodulation model; never formed densely).
    aux : dict of str to array_like, shape (N,), optional
        Auxiliary channels (temperatures, ...) for the ``auxiliary`` candidate.
    valid : array_like of bool, shape (N,), optional
        Samples to use (non-finite ``y`` are always excluded).
    candidates : sequence of str or callable
        Names in :data:`accal.closure.candidates.BUILDERS` or builder functions
        ``f(Context) -> list[Proposal]``.
    alpha : float
        Family-wise false-detection probability per selection step, and the level
        of the final ``unexplained`` test.
    max_effects : int
        Upper bound on the number of effects added.
    orbit_period : float, optional
        Nominal orbit (or revolution) period [s]; enables once/twice-per-revolution
        periodic proposals and per-orbit residual means.
    catchall_knots : int
        Knots of the piecewise-linear basis of the final ``unexplained`` test
        (24 over a day: structure slower than ~1 h); 0 disables it.
    options : dict, optional
        Search settings passed to the builders (see :class:`Context`).
    channel : array_like of int, shape (N,), optional
        Data channel ``0 .. C-1`` of every sample, for several channels sharing one
        time grid (e.g. the y and z axes of the rotating platform, interleaved in
        time).  Noises are taken as independent with a common PSD; every generic
        effect gets one coefficient per channel.
    channel_names : sequence of str, optional
        Names of the channels (default ``"0"``, ``"1"``, ...).
    noise_psd : callable, optional
        The instrument's two-sided noise PSD ``S(f)`` [(m/s²)²/Hz] (e.g.
        :class:`accal.estimators.noise.MicroStarPSD`): the reported covariances
        (before and after) use it instead of the residual's estimate, as the
        declared estimator's own sigmas do.  The estimate of a residual left by a
        rich base (the demodulation's per-period columns) under red noise came out
        low after effects were added: per-period sigmas 27 % under the true scatter.
        The tests always use the estimate.
    resolution : float, optional
        Numerical resolution of ``y`` [m/s²], e.g. float64 epsilon times the
        largest raw value when ``y`` is raw − reference.  Once the residual's RMS is
        within :data:`RESOLUTION_FACTOR` of it the residual is rounding, not
        noise: the search stops and no ``unexplained`` structure is reported (a
        noise-free raw − reference otherwise had its rounding reported as a
        1.9e-27 m/s² "unexplained" component); a note says so.

    Returns
    -------
    ClosureResult

    Raises
    ------
    ValidationError
        Bad shapes, fewer than 50 usable samples, or an unknown candidate/base.
    """
    t_all = np.asarray(t, dtype=np.float64)
    y_all = np.asarray(y, dtype=np.float64)
    if t_all.ndim != 1 or y_all.shape != t_all.shape:
        raise ValidationError(
            f"t and y must be 1-D of equal length, got {t_all.shape}, {y_all.shape}"
        )
    chan_all, names = _check_channels(t_all, channel, channel_names)
    use = np.isfinite(y_all) & np.isfinite(t_all)
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != t_all.shape:
            raise ValidationError(f"valid must have shape {t_all.shape}, got {v.shape}")
        use &= v
    if use.sum() < MIN_SAMPLES:
        raise ValidationError(f"need at least {MIN_SAMPLES} usable samples, got {int(use.sum())}")
    if not 0 < alpha < 1:
        raise ValidationError(f"alpha must be in (0, 1), got {alpha}")
    aux_all = {}
    for k, v in (aux or {}).items():
        a = np.asarray(v, dtype=np.float64)
        if a.shape != t_all.shape:
            raise ValidationError(
                f"auxiliary channel {k!r} must have shape {t_all.shape}, got {a.shape}"
            )
        aux_all[k] = a
    builders = _resolve(candidates)
    opts = dict(options or {})

    def again(valid_again: NDArray[np.bool_], **extra: Any) -> ClosureResult:
        """The same analysis on other samples (outliers or a lagged channel's start left out)."""
        return close_loop(
            t_all,
            y_all,
            base=base,
            aux=aux,
            valid=valid_again,
            candidates=candidates,
            alpha=alpha,
            max_effects=max_effects,
            orbit_period=orbit_period,
            catchall_knots=catchall_knots,
            options={**opts, **extra},
            channel=channel,
            channel_names=channel_names,
            noise_psd=noise_psd,
            resolution=resolution,
        )

    if not opts.get("_branched"):
        return _best_branch(again, use)
    t_u, y_u = t_all[use], y_all[use]
    chan_u = None if chan_all is None else chan_all[use]
    t0 = float(t_u[0])
    span = float(t_u[-1] - t_u[0]) or 1.0
    grid = make_grid(t_u, chan_u)
    bbase = _base_design(base, t_all, t0, span, chan_all, names)
    p0 = bbase.n_columns
    basis0 = Basis(bbase.block[use], bbase.columns[use], n_blocks=bbase.n_blocks)
    if basis0.rank_total + 10 > t_u.size:
        raise ValidationError(
            f"the base has rank {basis0.rank_total} for {t_u.size} usable samples: "
            "nothing is left to test"
        )
    fit0 = basis0.fit(y_u)
    if not opts.get("_screened"):
        bad = _outliers(fit0.resid, chan_u, t_u)
        if bad.any():
            later = use.copy()
            later[np.flatnonzero(use)[bad]] = False
            edges = _edge_runs(bad, fit0.resid) if chan_u is None else []
            if edges:
                # A constant offset of the first (last) k samples is a bias step k
                # samples from the end, closer than the epoch scan reaches by default
                # (QA: a 3e-9 m/s² step 60 s into a half day was left out as 60
                # outliers, and the table's bias kept it, 3e-9 m/s² off; a step near
                # each end, both).  Kept when the analysis with the scan reaching them
                # finds those steps.
                res = again(use, _screened=True, min_segment=min(k for k, _ in edges))
                epochs = [float(t_u[k] if first else t_u[t_u.size - k]) for k, first in edges]
                found = _step_epochs(res.effects)
                if all(any(abs(f - ep) < 1e-6 for f in found) for ep in epochs):
                    return res
            res = again(later, _screened=True)
            decay = [e for e in res.effects if e.name == "exponential_drift" and e.tau]
            if decay and float(t_u[bad].max()) <= t0 + 5.0 * float(decay[0].tau):
                # the "outliers" are the start of a fast decay the closure found without
                # them (1e-8 m/s², T = 120 s: its first 350 s were screened and its
                # amplitude came out 5.9e-10): analyse them with it
                return again(use, _screened=True)
            tb = t_u[bad]
            reach = OUTLIER_WINDOW * float(np.median(np.diff(t_u)))

            def near_step(effects: Sequence[Effect]) -> bool:  # within one screen window
                return any(
                    ep - reach <= tb[0] and tb[-1] <= ep + reach for ep in _step_epochs(effects)
                )

            if near_step(res.effects):
                # The "outliers" may be a step's edge seen from a running-median window
                # the record's end truncates (QA: a 3e-9 m/s² step 300 s before the end
                # was found, and 60 samples after it screened as a burst; with 120
                # screened the epoch was 22 s off).  Analysed with them when that gives
                # the same effects (a real burst there would be fitted as more steps).
                whole = again(use, _screened=True)
                same = sorted(e.name for e in whole.effects) == sorted(e.name for e in res.effects)
                if same and near_step(whole.effects):
                    return whole
            note = {
                "name": "outliers",
                "channel": None,
                "note": f"{int(bad.sum())} samples more than {OUTLIER_SIGMAS:g} robust σ from "
                "the running median of the residual left out of the analysis (a burst or "
                "spikes no candidate models; they stay in the data)",
                "details": {"n": int(bad.sum()), "first": float(t_u[bad][0])},
            }
            return dataclasses.replace(res, notes=(note, *res.notes))
    lev0_white = basis0.leverage(grid)
    beta = projection_bias(grid, basis0, fit0.resid, lev0_white)
    n_families = _families(builders, aux_all, orbit_period)
    search = _Search(
        t_all=t_all,
        use=use,
        t0=t0,
        span=span,
        grid=grid,
        basis0=basis0,
        y_u=y_u,
        aux=aux_all,
        orbit_period=orbit_period,
        options={
            **opts,
            "enabled": tuple(n for n, _ in builders),
            "alpha": alpha,
            "families": n_families,
        },
        builders=builders,
        chan_all=chan_all,
        names=names,
        base_labels=frozenset(bbase.column_labels()),
        n_families=n_families,
        alpha=alpha,
        beta=beta,
    )
    floor = RESOLUTION_FACTOR * float(resolution) if resolution and resolution > 0 else 0.0

    def at_floor(state) -> bool:
        """True (and noted) when the residual of ``state`` is rounding only."""
        rms = float(np.sqrt(np.mean(state[1].resid ** 2)))
        if rms > floor:
            return False
        _note(
            search.notes,
            "closure",
            None,
            f"residual RMS {rms:.2g} m/s² is at the data's numerical resolution "
            f"({float(resolution):.2g} m/s²): nothing left to test",
        )
        return True

    iterations = 0
    seen = {search.model_key()}
    while len(search.found) < max_effects and iterations < 3 * max_effects:
        if floor and at_floor(search.state(search.found)):
            break
        iterations += 1
        if not search.step() or search.model_key() in seen:
            break
        seen.add(search.model_key())
    if floor and at_floor(search.state(search.found)):
        # the model leaves rounding only: a proposal rejected on the way (its
        # coefficient differed between thirds of the record) explained nothing real
        search.unexplained.clear()

    def smooth_test(state):
        """The catch-all test of the model ``state`` (None if disabled or nothing left)."""
        if not catchall_knots or catchall_knots < 3 or (floor and at_floor(state)):
            return None, None
        b, f, lv = state
        zt = b.complement(_split_cols(_catchall(t_u, catchall_knots), chan_u, names))
        if zt.shape[1] == 0:
            return None, None
        nz = estimate_psd(grid, f.resid, lv)
        f_lo = 2.0 * catchall_knots / (grid.size * grid.step)
        model, _, nu = white_plus_flicker(grid, nz, f_lo, return_dof=True)
        # the extrapolation only below f_lo; above it the estimate is reliable
        model = np.where(grid.freqs >= f_lo, nz.psd, model)
        return wald_test(grid, f.resid, zt, lv, psd=model, psd_dof=nu), zt

    search.smooth_swap()
    w_smooth, zt_smooth = smooth_test(search.state(search.found))
    if w_smooth is not None and w_smooth.pvalue < alpha and search.backward(max_effects):
        w_smooth, zt_smooth = smooth_test(search.state(search.found))
    couplings = [f.prop.params for f in search.found if f.prop.name == "auxiliary"]
    lag = max((float(c.get("lag") or 0.0) for c in couplings), default=0.0)
    tc = max((float(c.get("tau") or 0.0) for c in couplings), default=0.0)
    if (lag > 0 or tc > 0) and not opts.get("_after_lag"):
        # A lagged channel is unknown for the first `lag` seconds (its regressor holds
        # the first value there); that flat start was fitted as an exponential
        # settling or a step (QA: 3e-9 m/s²/K at 1500 s lag gave both, bias error
        # 7e-10 -> -6e-10).  Redo the search without the first `max_lag` seconds:
        # there every lag searched is known (leaving out only the found lag biased
        # the re-search to lags shorter than it: 1206 s + a 300 s low-pass for 1500 s).
        # A low-pass-filtered channel's filter state is unknown at the start (the
        # regressor starts settled on the first value): the mismatch decays with the
        # filter's time constant and was reported as an exponential drift of that T
        # (QA: 1.04e-9 m/s², T = 298 s beside a 2e-9 coupling with a 300 s filter);
        # it is below e^-5 after FILTER_SETTLE time constants
        # (a lag of a few samples, e.g. 1 ± 6 s beside a low-pass, is not a lagged
        # channel: only those samples are left out for it)
        # The two add up: the filter state is known FILTER_SETTLE τ after the lagged
        # channel is (QA: lag 3000 s + 1000 s low-pass with only 5000 s left out gave a
        # spurious exponential of T = 935 s)
        step = float(np.median(np.diff(np.unique(t_all)))) if t_all.size > 1 else 1.0
        top_lag = max_lag(opts, span)
        lead_lag = top_lag
        period = float(opts.get("lag_period") or 0.0)
        if period > 0:
            # a block base (demodulation periods): every period left out loses its
            # values, so the lags a period-repeating channel is searched at (τ/2), or
            # the longer lag found (QA: with the cap at 1 h the first 6 periods of a
            # day had no extended values for a 120 s lag)
            lead_lag = min(top_lag, max(lag, 0.5 * period))
        lead = (lead_lag if lag > TAU_MIN_STEPS * step else lag) + FILTER_SETTLE * tc
        later = use & (t_all >= t0 + lead)
        # the same after every data gap: the channel was only known at the data's
        # times, so across a gap the lagged regressor was bridged (QA: steps of
        # ±2.5e-10 m/s² right after a gap, on a noise-free coupling) and the filter
        # stepped over the gap as if it were one sample
        # (gaps in the samples, where the channel is unknown: not rotation masks or
        # flagged samples, at which the channel is known; QA: with every rotation mask
        # taken for a gap a demod lag cap of 1080 s left nothing to re-search)
        tu_, first_ = np.unique(t_all, return_index=True)
        ends = []
        if tu_.size > 2:
            dtu = np.diff(tu_)
            ends += list(tu_[1:][dtu > 5.0 * np.median(dtu)])
            # and after every hole of a coupled channel (NaN: e.g. the grid points of a
            # resampled run's gap), which the search bridged (QA: lag 500 s after a
            # 1000 s gap of a resampled demod run: 4 false steps, a_Y z +152)
            for ch in {f.prop.channel for f in search.found if f.prop.name == "auxiliary"}:
                known = np.isfinite(aux_all[ch][first_]) if ch in aux_all else None
                if known is not None and known.any() and not known.all():
                    ends += list(tu_[1:][known[1:] & ~known[:-1]])
        for g_end in ends:
            later &= ~((t_all >= g_end) & (t_all < g_end + lead))
        if lead >= TAU_MIN_STEPS * step and int(later.sum()) >= MIN_SAMPLES:
            # the same lags as the first search (the shorter span would lower the cap
            # below the lag found: QA, 2000 s on a half day with gaps, capped at 1542 s)
            res = again(later, _after_lag=lead, _screened=True, max_lag=top_lag)
            coupled = {f.prop.channel for f in search.found if f.prop.name == "auxiliary"}
            kept = {e.channel for e in res.effects if e.name == "auxiliary"}
            if coupled <= kept:
                res = dataclasses.replace(res, effects=_exponentials_from(res.effects, t0))
                note = {
                    "name": "auxiliary",
                    "channel": None,
                    "note": f"the first {lead:.0f} s (and as much after each data gap) left "
                    f"out of the analysis: a coupling with a lag of {lag:.0f} s and a low-pass "
                    f"of {tc:.0f} s was found in the first search, and before the record "
                    "starts a lagged channel is unknown and a filter's state too",
                    "details": {"left_out": lead},
                }
                alts = (*res.alternatives, *search.alternatives)
                return dataclasses.replace(
                    res, notes=(*res.notes, note), alternatives=tuple(dict.fromkeys(alts))
                )
            # Without the start (and as much after each gap) the coupling was no longer
            # found (QA: 59 % of a half day with gaps left out, or the backward stage
            # preferring an orbit term): leaving it out of the model put c × mean(x)
            # into the bias (z 444 and 1053 at 293 K).  The first search's result stands.
            _note(
                search.notes,
                "auxiliary",
                None,
                f"the coupling to {', '.join(sorted(coupled - kept))} was not found again "
                f"without the first {lead:.0f} s (and as much after each data gap, "
                f"{int(later.sum())} of {int(use.sum())} samples left): the search on all "
                "samples is kept, its start may hold the channel's unknown history",
                {"left_out": lead},
            )
    # the final fit carries the Jacobian of every searched time constant, so that
    # its uncertainty reaches every σ (an exponential's T was fitted, not known)
    final = [
        _with_tau_jacobian(
            f, t_all, t0, use, lambda f=f: search.state([g for g in search.found if g is not f])[0]
        )
        for f in search.found
    ]
    # With the time constants free (their Jacobians in the design), an effect that only
    # took up the misfit of a held τ is no longer determined: drop the least significant
    # until every effect is significant given the others' augmented columns (QA: a
    # four-rest run with an angle scale error and a direction-dependent settling
    # transient kept a second shape, a quadratic and two lines at |c|/σ 0.6-2.6, each
    # reported at p 1e-16 to 1e-123 from the fit with τ held; a_Z error 9.0e-12 instead
    # of 5.8e-12)
    while len(final) > 1 and any(a is not b for a, b in zip(final, search.found, strict=True)):
        ps = search.final_p(final)
        worst = int(np.argmax(ps))
        if ps[worst] < alpha:
            break
        search._drop(worst)
        final.pop(worst)
    found = [
        (f.prop, p, {**f.info, "p_accept": f.p_adj})
        for f, p in zip(final, search.final_p(), strict=True)
    ]
    removed = [(f.prop, f.p_adj, f.info) for f in search.removed]
    unexplained = search.unexplained
    notes = search.notes
    basis, fit, lev = search.state(final)

    # ------------------------------------------------------------------ covariances
    if noise_psd is not None:
        f = grid.freqs
        fpos = np.where(f > 0, f, f[1] if f.size > 1 else 1.0)  # S(0) of a 1/f law: S(df)
        psd = psd0 = np.asarray(noise_psd(fpos), dtype=np.float64) / grid.step  # per sample
    else:
        noise = estimate_psd(grid, fit.resid, lev)
        nc = np.maximum(grid.counts, 1.0)[:, None]
        noise0 = estimate_psd(grid, fit0.resid, nc - (nc - lev0_white) * beta)
        psd, psd0 = noise.psd, noise0.psd
    ns = basis.seg_start.size
    rinv = basis.rinv
    v_ll = _sandwich(rinv, basis.block_cov(grid, psd))
    v_ll0 = _sandwich(rinv, basis0.block_cov(grid, psd0))
    k = fit.w_gamma.shape[0]
    if k:
        wg = fit.w_gamma.T  # (n, k)
        g_fft = grid.fft(wg)
        v_ww = _quad(g_fft, _two_sided(grid.size, g_fft.shape[-1]) * psd, grid.size)
        v_ww = 0.5 * (v_ww + v_ww.T)
        cw = np.fft.irfft(g_fft * psd, grid.size, axis=-1)[:, grid.channel, grid.idx].T  # C W'
        v_lw = np.einsum("spr,srk->spk", rinv, basis.block_coef(cw))
        a = fit.a_mat
        at = np.transpose(a, (0, 2, 1))
        cov_b = v_ll - v_lw @ at - a @ np.transpose(v_lw, (0, 2, 1)) + a @ (v_ww[None] @ at)
        cov_bg = v_lw - a @ v_ww[None]
        cov_d = a @ (v_ww[None] @ at)
    else:
        v_ww = np.zeros((0, 0))
        cov_b = v_ll
        cov_bg = np.zeros((ns, basis.p, 0))
        cov_d = np.zeros_like(v_ll)
    seg_of = basis.seg_of_block()
    nb, p = bbase.n_blocks, bbase.p
    base_cov = np.full((nb, p, p), np.nan)
    cross = np.full((nb, p, k), np.nan)
    var0 = np.full((nb, p), np.nan)
    var1 = np.full((nb, p), np.nan)
    vard = np.full((nb, p), np.nan)
    varp = np.full((nb, p), np.nan)
    has = seg_of >= 0
    sg = seg_of[has]
    base_cov[has] = cov_b[sg]
    cross[has] = cov_bg[sg]
    var0[has] = np.einsum("sii->si", v_ll0[sg])
    var1[has] = np.einsum("sii->si", cov_b[sg])
    vard[has] = np.einsum("sii->si", cov_d[sg])
    varp[has] = np.einsum("sii->si", v_ll[sg])  # base alone, final noise
    ident = np.isfinite(fit0.beta.reshape(nb, p))
    for arr in (var0, var1, vard, varp):
        arr[~ident] = np.nan

    # ------------------------------------------------------------------ unexplained
    if w_smooth is not None and w_smooth.pvalue < alpha:
        unexplained.append(_describe_smooth(grid, t_u, zt_smooth @ w_smooth.gamma, w_smooth))

    coef = np.concatenate([fit.beta, fit.gamma])
    eff_cols = (
        np.column_stack([pr.columns for pr, *_ in found]) if found else np.zeros((t_all.size, 0))
    )
    labels = bbase.column_labels() + tuple(lb for pr, *_ in found for lb in pr.labels)
    effects = _effects(found, fit.gamma, v_ww, span, t0)
    removed_eff = tuple(
        Effect(
            pr.name,
            pr.channel,
            float("nan"),
            float("nan"),
            pa,
            epoch=pr.params.get("epoch"),
            frequency=pr.params.get("frequency"),
            lag=pr.params.get("lag"),
            tau=pr.params.get("tau"),
            details={"removed": True},
        )
        for pr, pa, _ in removed
    )
    scale = bbase.column_scale()
    b0 = fit0.beta
    b1 = fit.beta
    sd = np.sqrt(np.maximum(var0.ravel(), 0.0)) * scale
    s1 = np.sqrt(np.maximum(var1.ravel(), 0.0)) * scale
    sdd = np.sqrt(np.maximum(vard.ravel(), 0.0)) * scale
    spl = np.sqrt(np.maximum(varp.ravel(), 0.0)) * scale
    base_out = tuple(
        BaseCoefficient(
            nm,
            float(b0[j] * scale[j]),
            float(sd[j]),
            float(b1[j] * scale[j]),
            float(s1[j]),
            float((b1[j] - b0[j]) * scale[j]),
            float(sdd[j]),
            float(spl[j]),
        )
        for j, nm in enumerate(bbase.column_names())
    )
    res_before = y_all - bbase.matvec(fit0.beta)
    res_after = y_all - bbase.matvec(fit.beta) - eff_cols @ fit.gamma
    seg = orbit_period if orbit_period else None
    return ClosureResult(
        effects=tuple(effects),
        unexplained=tuple(unexplained),
        base=base_out,
        t0=t0,
        rms_before=float(np.sqrt(np.mean(fit0.resid**2))),
        rms_after=float(np.sqrt(np.mean(fit.resid**2))),
        time=t_all,
        use=use,
        residual_before=res_before,
        residual_after=res_after,
        base_design=bbase,
        effect_columns=eff_cols,
        labels=labels,
        coef=coef,
        base_cov=base_cov,
        cross_cov=cross.reshape(nb * p, k),
        effects_cov=v_ww,
        n_base=p0,
        stats_before=characterise(t_u, fit0.resid, segment=seg, chan=chan_u),
        stats_after=characterise(t_u, res_after[use], segment=seg, chan=chan_u),
        iterations=iterations,
        notes=tuple(notes.values()),
        channel=chan_all,
        channel_names=names,
        removed=removed_eff,
        alternatives=tuple(search.alternatives),
    )


def _best_branch(again: Callable[..., ClosureResult], use: NDArray[np.bool_]) -> ClosureResult:
    """The search, and again with a coupling it passed over added first, if that explains more.

    Forward selection adds the effect that explains the most power.  A channel that
    varies with the orbit (a temperature) and the orbit term can explain nearly the
    same power while an effect not yet in the model (an exponential settling) masks
    the difference; once the orbit term is in, the coupling is no longer significant
    (QA: 4e-9 m/s² exponential + 3e-9 m/s²/K coupling to a 293 K channel, 1 s
    samples: an orbit term and "unexplained" structure were reported, and the bias at
    channel value 0 was 8.8e-7 m/s² off).  The other branch is kept when it explains
    the structure the first left unexplained and leaves a smaller residual on the
    samples both analysed.
    """
    first = again(use, _branched=True)
    coupled = {e.channel for e in first.effects if e.name == "auxiliary"}
    for ch in [c for c in first.alternatives if c not in coupled]:
        alt = again(use, _branched=True, _prefer=ch)
        if not any(e.name == "auxiliary" and e.channel == ch for e in alt.effects):
            continue
        both = first.use & alt.use
        rss_first = float(np.sum(first.residual_after[both] ** 2))
        rss_alt = float(np.sum(alt.residual_after[both] ** 2))
        if len(alt.unexplained) < len(first.unexplained) and rss_alt < rss_first:
            note = {
                "name": "auxiliary",
                "channel": ch,
                "note": f"the coupling to {ch} was tested before the other effects: the "
                f"search that added {', '.join(sorted({e.name for e in first.effects}))} "
                f"first left structure unexplained (residual RMS "
                f"{np.sqrt(rss_first / both.sum()):.3g} m/s², with the coupling first "
                f"{np.sqrt(rss_alt / both.sum()):.3g} m/s²)",
                "details": {"rms_first": float(np.sqrt(rss_first / both.sum()))},
            }
            return dataclasses.replace(alt, notes=(*alt.notes, note))
    return first


def _check_channels(t_all, channel, channel_names):
    if channel is None:
        if t_all.size > 1 and not np.all(np.diff(t_all) > 0):
            raise ValidationError("sample times must be strictly increasing")
        if channel_names:
            raise ValidationError("channel_names given without channel")
        return None, ()
    ch = np.asarray(channel)
    if ch.shape != t_all.shape or not np.issubdtype(ch.dtype, np.integer):
        raise ValidationError(
            f"channel must be integers of shape {t_all.shape}, got {ch.dtype} {ch.shape}"
        )
    ch = ch.astype(np.int64)
    n_ch = int(ch.max()) + 1 if ch.size else 1
    if ch.min(initial=0) < 0 or np.unique(ch).size != n_ch:
        raise ValidationError(f"channel must use every index 0 .. {n_ch - 1}")
    if t_all.size > 1 and not np.all(np.diff(t_all) >= 0):
        raise ValidationError("sample times must be non-decreasing")
    for c in range(n_ch):
        tc = t_all[ch == c]
        if tc.size > 1 and not np.all(np.diff(tc) > 0):
            raise ValidationError(f"sample times of channel {c} must be strictly increasing")
    names = (
        tuple(channel_names) if channel_names is not None else tuple(str(c) for c in range(n_ch))
    )
    if len(names) != n_ch:
        raise ValidationError(f"channel_names must have {n_ch} entries, got {len(names)}")
    if n_ch == 1:
        return None, ()
    return ch, names


def _note(notes: dict, name: str, channel: str | None, text: str, params=None) -> None:
    key = (name, channel, text)
    if key not in notes:
        d: dict[str, Any] = {"name": name, "channel": channel, "note": text}
        if params:
            d["details"] = dict(params)
        notes[key] = d


#: Outliers: samples this many robust σ (1.4826 MAD) from the residual's running median.
OUTLIER_SIGMAS = 10.0
#: Running-median window [samples] and the largest fraction of samples that may be
#: outliers (more is structure, e.g. a strong high-frequency line, not outliers).
OUTLIER_WINDOW = 241
OUTLIER_MAX_FRACTION = 0.005


def _outliers(
    r: NDArray[np.float64], chan: NDArray[np.int64] | None, t: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Samples of the base residual ``r`` far from the residual around them (each channel).

    A burst of 50 samples of 5e-8 m/s² in 1e-10 noise was fitted as two bias steps
    of ±2.9e-9 m/s² (the steps' least-squares area); the Wald tests assume Gaussian
    noise.  The level around a sample is the running median of the
    :data:`OUTLIER_WINDOW` samples before it and of those after it; the deviation
    is the smaller of the two (only the one that fits inside the segment at its
    ends), so a step's edge is never an outlier, a burst shorter than the window
    is one anywhere (also at the record's ends, where a centred median followed
    it), and the running medians never reach across a data gap.  Flagged samples
    are left out of the analysis (the caller keeps them in the data).  Nothing is
    flagged when more than :data:`OUTLIER_MAX_FRACTION` of a channel would be.
    """
    from scipy.ndimage import median_filter

    w = OUTLIER_WINDOW
    bad = np.zeros(r.size, dtype=bool)
    groups = (
        [np.arange(r.size)]
        if chan is None
        else [np.flatnonzero(chan == c) for c in np.unique(chan)]
    )
    for idx in groups:
        if idx.size < 4 * w:
            continue
        x, tt = r[idx], t[idx]
        steps = np.diff(tt)
        cut = np.flatnonzero(steps > 5.0 * np.median(steps)) + 1  # data gaps
        dev = np.full(x.size, np.inf)
        for seg in np.split(np.arange(x.size), cut):
            if seg.size < 2 * w:
                continue  # too short to tell an outlier from structure: none flagged
            xs = x[seg]
            # windows ending at (left) and starting at (right) each sample
            left = xs - median_filter(xs, size=w, origin=w // 2, mode="nearest")
            right = xs - median_filter(xs, size=w, origin=-(w // 2), mode="nearest")
            d = np.minimum(np.abs(left), np.abs(right))
            d[: w - 1] = np.abs(right[: w - 1])  # left window not inside the segment
            d[-(w - 1) :] = np.abs(left[-(w - 1) :])
            dev[seg] = d
        finite = np.isfinite(dev)
        if finite.sum() < 2 * w:
            continue
        sig = 1.4826 * float(np.median(dev[finite]))  # dev >= 0: MAD about 0
        if not sig > 0:
            continue
        hit = finite & (dev > OUTLIER_SIGMAS * sig)
        if 0 < hit.sum() <= OUTLIER_MAX_FRACTION * idx.size:
            bad[idx[hit]] = True
    return bad


def _step_epochs(effects: Sequence[Effect]) -> list[float]:
    """Epochs [s] of the bias steps among ``effects``."""
    return [e.epoch for e in effects if e.name == "bias_step" and e.epoch is not None]


#: Fewest samples of a run at the record's start or end that :func:`_edge_runs` takes
#: for a possible bias step rather than outliers.
EDGE_STEP_MIN = 10
#: Largest offset [robust σ of the other samples] of such a run taken for a step.  At
#: the record's end a step and a burst fit alike (the burst's other edge is outside
#: the record); instrument bias steps are ~1e-9-1e-8 m/s² (tens of σ for a residual
#: against a reference), bursts and spikes hundreds to thousands of σ.
EDGE_STEP_MAX_SIGMAS = 200.0


def _edge_runs(bad: NDArray[np.bool_], r: NDArray[np.float64]) -> list[tuple[int, bool]]:
    """``[(k, at_start), ...]`` when the flagged samples are the first and/or last ``k``
    (each ≥ :data:`EDGE_STEP_MIN`) and each run is a constant offset of at most
    :data:`EDGE_STEP_MAX_SIGMAS` from the samples next to it; else ``[]``.

    Constant: about their own median the run's samples are within
    :data:`OUTLIER_SIGMAS` robust σ, as the samples before and after a bias step
    are; a burst of spikes is not.  σ is that of the first differences of the
    other samples (1.4826 MAD / √2), which steps and slow structure elsewhere do
    not inflate (QA: beside a 2e-9 m/s² step mid-day the residual's own MAD made a
    5e-8 m/s² burst at the start ~100σ, and it was taken for a step, the bias
    5e-8 m/s² off).
    """
    idx = np.flatnonzero(bad)
    n = r.size
    if idx.size == 0:
        return []
    runs: list[tuple[int, bool]] = []
    k0 = int(np.argmax(~bad)) if not bad.all() else n  # leading flagged samples
    k1 = int(np.argmax(~bad[::-1])) if not bad.all() else n  # trailing ones
    if k0 + k1 != idx.size or k0 + k1 >= n:
        return []  # flagged samples away from the ends
    rest = r[~bad]
    d = np.diff(rest)
    sig = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2.0)
    if not sig > 0:
        return []
    for k, at_start in ((k0, True), (k1, False)):
        if k == 0:
            continue
        if k < EDGE_STEP_MIN:
            return []
        run = r[:k] if at_start else r[n - k :]
        near = r[k : k + OUTLIER_WINDOW] if at_start else r[max(0, n - k - OUTLIER_WINDOW) : n - k]
        if np.max(np.abs(run - np.median(run))) > OUTLIER_SIGMAS * sig:
            return []
        if abs(float(np.median(run) - np.median(near))) > EDGE_STEP_MAX_SIGMAS * sig:
            return []
        runs.append((k, at_start))
    return runs


#: A residual within this factor of the data's numerical resolution is rounding
#: (of the data and of the fit: a noise-free exponential left 17x eps·max|y|).  An
#: instrument's noise is ~1e10 times the resolution (GRACE: 1e-10 vs 7e-21 m/s²).
RESOLUTION_FACTOR = 1000.0

_PAIR_FACTOR = 10.0  # pairs are tested at alpha/10: per-step FWER <= 1.1 alpha
_PAIR_ANCHORS = 3
_PAIR_GATE = 0.2  # a masked proposal must be suggestive: corrected p < 0.2
_REFINE_DW = 4.0
_NO_SEARCH = ("quadratic_drift", "cubic_drift")  # nothing to refine


#: How much larger (Wald statistic less the parameter penalty) a slow exponential's score
#: must be to replace the polynomial drift terms found (:meth:`_Search.smooth_swap`).
#: Calibrated: on quadratic-only days where a slow exponential scored higher it did so by
#: 1-43 (three simulated 1/f days; the real Swarm storm day twice, 32-34: the 1/f model
#: extrapolated to the lowest frequencies underestimates them), on simulated slow decays
#: by 117-27,000 (one of T = span: 44).  A margin of 100 is an e^50 likelihood ratio: the choice
#: stands even if that extrapolation is 2x low.  Below it the polynomial terms stay.
SWAP_MIN_GAIN = 100.0
#: Time constants of a coupling's low-pass left out at the start (and after each gap):
#: the unknown initial filter state has decayed below e^-5 of its size by then.
FILTER_SETTLE = 5.0


@dataclass(eq=False)  # compared by identity: the proposal holds arrays
class _Found:
    prop: Proposal
    p_adj: float
    info: dict[str, Any]
    builder: int


@dataclass
class _Search:
    """State of the forward selection (see the module notes, steps 1-4)."""

    t_all: NDArray[np.float64]
    use: NDArray[np.bool_]
    t0: float
    span: float
    grid: Grid
    basis0: Basis
    y_u: NDArray[np.float64]
    aux: dict[str, NDArray[np.float64]]
    orbit_period: float | None
    options: dict[str, Any]
    builders: list[tuple[str, Callable]]
    chan_all: NDArray[np.int64] | None
    names: tuple[str, ...]
    base_labels: frozenset[str]
    n_families: int
    alpha: float
    beta: NDArray[np.float64]
    found: list[_Found] = field(default_factory=list)
    removed: list[_Found] = field(default_factory=list)
    unexplained: list[Effect] = field(default_factory=list)
    notes: dict[tuple, dict[str, Any]] = field(default_factory=dict)
    excluded: list[float] = field(default_factory=list)
    alternatives: list[str] = field(default_factory=list)
    _states: dict = field(default_factory=dict, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------
    def state(self, found: Sequence[_Found]) -> tuple[Basis, FitResult, NDArray[np.float64]]:
        """Basis, fit and leverage spectrum of the base plus the effects ``found`` (cached)."""
        key = tuple((f.prop.name, f.prop.channel, f.prop.labels, _key(f.prop)) for f in found)
        hit = self._states.get(key)
        if hit is not None:
            return hit
        if found:
            basis = self.basis0.extend(np.column_stack([f.prop.columns[self.use] for f in found]))
        else:
            basis = self.basis0
        out = (basis, basis.fit(self.y_u), self.leverage(basis))
        if len(self._states) >= 24:
            self._states.pop(next(iter(self._states)))
        self._states[key] = out
        return out

    def leverage(self, basis: Basis) -> NDArray[np.float64]:
        """Leverage spectrum with the measured suppression of the base (``beta``)."""
        lev = basis.leverage(self.grid)
        nc = np.maximum(self.grid.counts, 1.0)[:, None]
        return nc - (nc - lev) * self.beta

    def context(self, found: Sequence[_Found], basis, fit, lev) -> Context:
        return Context(
            t_all=self.t_all,
            use=self.use,
            t0=self.t0,
            span=self.span,
            grid=self.grid,
            residual=fit.resid,
            basis=basis,
            leverage=lev,
            labels=self.base_labels | {lb for f in found for lb in f.prop.labels},
            aux=self.aux,
            orbit_period=self.orbit_period,
            excluded_freqs=tuple(self.excluded),
            options=self.options,
            channel_all=self.chan_all,
            channel_names=self.names,
            cache=self._cache,
            n_lines=sum(f.prop.name == "periodic" and f.prop.channel == "line" for f in found),
            model_freqs=tuple(g for f in found for g in _freqs(f.prop)),
            orbit_frequency=next(
                (
                    float(f.prop.params["frequency"])
                    for f in found
                    if f.prop.name == "periodic" and f.prop.channel == "orbit"
                ),
                None,
            ),
        )

    def propose(self, ctx: Context, only: int | None = None) -> list[tuple[Proposal, int]]:
        """Proposals of every builder (or of builder ``only``); notes are recorded."""
        out = []
        for i, (_, build) in enumerate(self.builders):
            if only is not None and i != only:
                continue
            for prop in build(ctx):
                if prop.note is not None:
                    _note(self.notes, prop.name, prop.channel, prop.note, prop.params)
                else:
                    out.append((prop, i))
        return out

    def test(self, basis: Basis, fit: FitResult, lev, cols: NDArray[np.float64]):
        """Wald test of ``cols`` (all samples) on top of ``basis``; None if in its span."""
        zt = basis.complement(cols[self.use])
        if zt.shape[1] == 0:
            return None
        return wald_test(self.grid, fit.resid, zt, lev)

    def _padj(self, w, *mults: float, pair: bool = False) -> float:
        f = self.n_families ** (2 if pair else 1) * (_PAIR_FACTOR if pair else 1.0)
        return float(min(1.0, w.pvalue * float(np.prod(mults)) * f))

    # ------------------------------------------------------------------
    def step(self) -> bool:
        """One forward step (a single effect, or a pair); False when nothing is added.

        The best significant single proposal (most explained power) is compared
        with the best significant pair anchored on a *masked* proposal: one that
        explains more power than that single but is only suggestive on its own
        (``alpha ≤`` corrected p ``< 0.2``).  The larger explained power wins.
        """
        basis, fit, lev = self.state(self.found)
        ctx = self.context(self.found, basis, fit, lev)
        tested = []
        for prop, bi in self.propose(ctx):
            w = self.test(basis, fit, lev, prop.columns)
            if w is None:
                _note(
                    self.notes,
                    prop.name,
                    prop.channel,
                    "not identifiable: in the span of the model",
                )
                continue
            p_adj = self._padj(w, prop.multiplicity)
            # the richer variant where the plain term is not significant; for a coupling
            # only where it is not even suggestive (a suggestive one is a pair anchor:
            # a low-pass's start transient had been taken up by a square)
            mod = (
                self._extended(prop)
                if p_adj >= (_PAIR_GATE if prop.name == "auxiliary" else self.alpha)
                else None
            )
            wm = None if mod is None else self.test(basis, fit, lev, mod.columns)
            pm = 1.0 if wm is None else self._padj(wm, mod.multiplicity)
            if pm < self.alpha:
                # a periodic term whose amplitude changes over the record spreads its
                # power over the neighbouring frequencies, which the noise estimate
                # counts as noise: as it stands it is not significant (QA: a once-per-
                # revolution term growing 0 -> 4e-9 m/s²; a 3000 s line growing alike
                # was "no effect found"); a coupling mostly quadratic in its channel
                # likewise (QA: c2 = 2e-9 m/s²/K² on a 20 ± 1.5 K channel)
                prop, w, p_adj = mod, wm, pm
            elif p_adj < self.alpha and prop.name == "auxiliary":
                # a significant coupling: with its square, when the square is
                # significant given it, the pair competes on its own (QA: about the
                # middle of the channel's range the linear part is small, and a settling
                # shape explained more than the linear coupling alone)
                both = self._with_square(prop)
                if both is not None and self._square_adds(basis, prop, both):
                    wb = self.test(basis, fit, lev, both.columns)
                    pb = 1.0 if wb is None else self._padj(wb, both.multiplicity)
                    if pb < self.alpha:
                        tested.append((pb, float(wb.gamma @ wb.gamma), both, wb, bi))
            tested.append((p_adj, float(w.gamma @ w.gamma), prop, w, bi))
        sig = sorted((e for e in tested if e[0] < self.alpha), key=lambda e: -e[1])
        coupled = {f.prop.channel for f in self.found if f.prop.name == "auxiliary"}
        prefer = self.options.get("_prefer")
        if prefer is not None and prefer not in coupled:
            # the other branch (see close_loop): this channel's coupling first
            first = [e for e in sig if e[2].name == "auxiliary" and e[2].channel == prefer]
            sig = first + [e for e in sig if e[2].name != "auxiliary" or e[2].channel != prefer]
            if first:
                return self._add_single(basis, sig)
        top_sig = sig[0][1] if sig else 0.0
        masked = sorted(
            (e for e in tested if self.alpha <= e[0] < _PAIR_GATE and e[1] > top_sig),
            key=lambda e: -e[1],
        )[:_PAIR_ANCHORS]
        top = max((e[1] for e in tested), default=0.0)
        for e in tested:
            # two steps (a box: +1e-9 then -1e-9) mask each other completely: the one
            # left out inflates the low-frequency noise estimate, so the other is not
            # even suggestive (p 1.0); the step that explains the most power anchors a
            # pair whatever its p (the pair is still tested at alpha/10)
            if e[2].name == "bias_step" and e[0] >= _PAIR_GATE and e[1] >= top > top_sig:
                masked = [*masked[: _PAIR_ANCHORS - 1], e]
        pair = self._best_pair(basis, fit, lev, masked) if masked else None
        if pair is not None and pair[-1] > top_sig and self._add_pair(pair):
            return True
        return self._add_single(basis, sig)

    def _add_single(self, basis: Basis, sig: list) -> bool:
        """Add the first consistent of the significant proposals ``sig`` (best first).

        A significant coupling passed over for another effect is recorded in
        :attr:`alternatives` (an orbit-periodic temperature and the orbit term can
        explain the same power while an undeclared drift masks the difference).
        """
        coupled = {f.prop.channel for f in self.found if f.prop.name == "auxiliary"}
        for j, (p_adj, _, prop, w, bi) in enumerate(sig):
            info = {"stat": w.stat, "dof": w.dof, "multiplicity": prop.multiplicity}
            mod = self._extended(prop)
            checked = False
            if mod is not None and prop.check_consistency:
                # a periodic term whose amplitude changes over the record (or a coupling
                # with a quadratic part) fails the thirds test as it stands; its richer
                # variant may pass (QA: a once-per-revolution term growing 0 -> 4e-9 m/s²
                # over a day was fitted as two anti-phased sinusoids 0.0007 bins apart)
                ok, cinfo = self._thirds(basis, prop)
                if ok:
                    info.update(cinfo)
                    checked = True
                else:
                    _, fit, lev = self.state(self.found)
                    wm = self.test(basis, fit, lev, mod.columns)
                    pm = 1.0 if wm is None else self._padj(wm, mod.multiplicity)
                    if pm < self.alpha:
                        ok_m, minfo = self._thirds(basis, mod)
                        if ok_m:
                            p_adj, prop, checked = pm, mod, True
                            info = {
                                "stat": wm.stat,
                                "dof": wm.dof,
                                "multiplicity": mod.multiplicity,
                            }
                            info.update(
                                {**minfo, "plain_segment_deviation": cinfo.get("segment_deviation")}
                            )
            if not checked and not self._consistent(basis, prop, p_adj, info):
                continue
            if prop.name != "auxiliary":
                for e in sig[j + 1 :]:
                    ch = e[2].channel
                    if e[2].name == "auxiliary" and ch not in coupled | set(self.alternatives):
                        self.alternatives.append(ch)
            if prop.params.get("with_square"):
                # a coupling and its square: two effects, added as a pair (each must be
                # consistent given the other)
                lin, sq = _split_square(prop)
                fa = _Found(_independent(basis, lin, self.use), 1.0, {}, bi)
                if self._add_pair((p_adj, fa, sq, bi, w, 0.0)):
                    return True
                continue
            self._add([_Found(_independent(basis, prop, self.use), p_adj, info, bi)])
            self._settle(protect_last=True)
            return True
        return False

    def _extended(self, prop: Proposal) -> Proposal | None:
        """The richer variant of a proposal, tried when it fails as it stands."""
        return self._modulated(prop) or self._with_square(prop)

    def _square_adds(self, basis: Basis, prop: Proposal, both: Proposal) -> bool:
        """Whether the square in ``both`` is significant given ``prop`` (the coupling)."""
        k = prop.columns.shape[1]
        fa = _Found(_independent(basis, prop, self.use), 1.0, {}, -1)
        b_a, f_a, l_a = self.state([*self.found, fa])
        w = self.test(b_a, f_a, l_a, both.columns[:, k:])
        return w is not None and self._padj(w, both.multiplicity) < self.alpha

    def _with_square(self, prop: Proposal) -> Proposal | None:
        """A linear coupling together with its channel's square (one joint test).

        The columns of ``prop`` followed by those of channel ``NAME^2``
        (:func:`~accal.closure.candidates.squared_column`, with the coupling's lag and
        low-pass), per data channel like ``prop``'s; twice the multiplicity.  Added,
        it is split into the two effects the sequential search would give.
        """
        from accal.closure.candidates import SQUARED, squared_column

        name = prop.channel
        if (
            prop.name != "auxiliary"
            or name is None
            or name.endswith(SQUARED)
            or name not in self.aux
            or prop.params.get("with_square")
        ):
            return None
        col = squared_column(
            self.t_all, self.aux[name], float(prop.params["lag"]), float(prop.params["tau"])
        )
        if prop.axes is None:
            sq, labs = col[:, None], (f"aux:{name}{SQUARED}",)
        else:
            sq = np.column_stack([col * (self.chan_all == c) for c in range(len(self.names))])
            labs = tuple(f"aux:{name}{SQUARED}:{n}" for n in self.names)
        return dataclasses.replace(
            prop,
            columns=np.column_stack([prop.columns, sq]),
            labels=(*prop.labels, *labs),
            multiplicity=2.0 * prop.multiplicity,
            params={**prop.params, "with_square": prop.columns.shape[1]},
            axes=None if prop.axes is None else (*prop.axes, *self.names),
        )

    def _modulated(self, prop: Proposal) -> Proposal | None:
        """A periodic proposal with a linearly changing amplitude of its fundamental.

        ``A(t)·cos(2πft − φ)`` with ``A`` linear in ``t`` is, in the columns,
        ``cos, sin`` of the fundamental plus ``u·cos, u·sin`` with
        ``u = (t − t_mid)/span`` (``t_mid``: the middle of the used samples): the
        reported amplitude is the one at ``t_mid`` and the rate of change is
        ``hypot`` of the last two coefficients over the span [m/s² per s].  Only
        for one data channel, and not for a proposal that already has them.
        """
        if (
            prop.name != "periodic"
            or prop.axes is not None
            or prop.params.get("modulated")
            or prop.columns.shape[1] < 2
            or self.span <= 0
        ):
            return None
        f = float(prop.params["frequency"])
        u = (self.t_all - (self.t0 + 0.5 * self.span)) / self.span
        return dataclasses.replace(
            prop,
            columns=np.column_stack([prop.columns, prop.columns[:, :2] * u[:, None]]),
            labels=(*prop.labels, f"ucos@{f!r}", f"usin@{f!r}"),
            multiplicity=2.0 * prop.multiplicity,  # a second model of the same member
            params={**prop.params, "modulated": True},
        )

    def _thirds(self, basis: Basis, prop: Proposal) -> tuple[bool, dict[str, Any]]:
        return _consistency(
            self.grid,
            basis,
            prop.columns[self.use],
            self.y_u,
            self.t_all[self.use],
            self.leverage,
        )

    def _consistent(self, basis: Basis, prop: Proposal, p_adj: float, info) -> bool:
        if not prop.check_consistency:
            return True
        ok, cinfo = self._thirds(basis, prop)
        info.update(cinfo)
        if ok:
            return True
        f = prop.params.get("frequency")
        if f is not None:
            self.excluded.append(float(f))
        self.unexplained.append(
            Effect(
                "unexplained",
                prop.name if prop.channel is None else f"{prop.name}:{prop.channel}",
                _component_rms(basis, prop.columns[self.use], self.y_u),
                float("nan"),
                p_adj,
                frequency=f,
                details={
                    "reason": "coefficient differs between thirds of the record",
                    **info,
                    **prop.params,
                },
            )
        )
        return False

    def _add(self, new: list[_Found]) -> None:
        for f in new:
            self.found.append(f)
            if f.prop.params.get("frequency") is not None:
                self.excluded.append(float(f.prop.params["frequency"]))

    def _drop(self, i: int) -> None:
        gone = self.found.pop(i)
        self.removed.append(gone)
        f = gone.prop.params.get("frequency")
        if f is not None and float(f) in self.excluded:
            self.excluded.remove(float(f))

    def _best_pair(self, basis, fit, lev, anchors):
        """Two effects that mask each other: a masked proposal with its best partner.

        For each anchor ``A`` every family proposes given ``A``; ``A + B`` is tested
        jointly against the current model with the Bonferroni factor
        ``m_A m_B F² · 10``.  Returns the significant pair that explains the most
        power, ``(p_adj, A, B, builder_B, wald, explained power)``, or None.
        """
        best = None
        for _, _, pa, _, ba in anchors:
            fa = _Found(_independent(basis, pa, self.use), 1.0, {}, ba)
            b_a, f_a, l_a = self.state([*self.found, fa])
            ctx_a = self.context([*self.found, fa], b_a, f_a, l_a)
            for pb, bb in self.propose(ctx_a):
                w = self.test(basis, fit, lev, np.column_stack([fa.prop.columns, pb.columns]))
                if w is None:
                    continue
                p_adj = self._padj(w, pa.multiplicity, pb.multiplicity, pair=True)
                gain = float(w.gamma @ w.gamma)
                if p_adj < self.alpha and (best is None or gain > best[-1]):
                    best = (p_adj, fa, pb, bb, w, gain)
        return best

    def _add_pair(self, pair) -> bool:
        p_adj, fa, pb, bb, w, _ = pair
        b_a, *_ = self.state([*self.found, fa])
        fb = _Found(_independent(b_a, pb, self.use), p_adj, {}, bb)
        info = {"stat": w.stat, "dof": w.dof, "pair": [fa.prop.name, pb.name]}
        fa = _Found(fa.prop, p_adj, {**info, "multiplicity": fa.prop.multiplicity}, fa.builder)
        fb = _Found(fb.prop, p_adj, {**info, "multiplicity": pb.multiplicity}, bb)
        for x, other in ((fa, fb), (fb, fa)):
            b_o, *_ = self.state([*self.found, other])
            if not self._consistent(b_o, x.prop, p_adj, x.info):
                return False
        self._add([fa, fb])
        self._settle(protect_last=False)
        return True

    def _refine(self) -> bool:
        """Re-search every effect's lag, epoch or frequency given all the others.

        The new member replaces the old one only when its Wald statistic (given the
        others) is larger by more than ``_REFINE_DW``: a parameter the data do not
        determine (e.g. a lag once ``periodic`` holds the once-per-orbit part) stays
        where it was found.
        """
        changed = False
        for i in range(len(self.found)):
            cur = self.found[i]
            if cur.prop.name in _NO_SEARCH:
                continue
            rest = [f for j, f in enumerate(self.found) if j != i]
            b_r, f_r, l_r = self.state(rest)
            ctx = self.context(rest, b_r, f_r, l_r)
            alt = [
                p
                for p, _ in self.propose(ctx, only=cur.builder)
                if p.name == cur.prop.name and p.channel == cur.prop.channel
            ]
            if not alt or _key(alt[0]) == _key(cur.prop) or self._other_line(cur.prop, alt[0]):
                continue
            # move only on significant evidence (Wald statistics differ by > 4, ~2σ)
            w_cur = self.test(b_r, f_r, l_r, cur.prop.columns)
            w_alt = self.test(b_r, f_r, l_r, alt[0].columns)
            if w_alt is None or (
                w_cur is not None and w_alt.stat * w_alt.q - w_cur.stat * w_cur.q <= _REFINE_DW
            ):
                continue
            self.found[i] = _Found(
                _independent(b_r, alt[0], self.use),
                cur.p_adj,
                {**cur.info, "refined": True},
                cur.builder,
            )
            changed = True
        return changed

    def _other_line(self, cur: Proposal, alt: Proposal) -> bool:
        """Whether ``alt`` is another spectral line, not ``cur``'s frequency refined.

        The line family has many members: re-searched given the others, a line's
        slot would otherwise jump to a different (stronger-by-ratio) line and the
        first one would be lost.  A refinement moves by at most two DFT bins.
        """
        if cur.name != "periodic" or cur.channel != "line":
            return False
        f0, f1 = cur.params.get("frequency"), alt.params.get("frequency")
        if f0 is None or f1 is None:
            return False
        return abs(float(f1) - float(f0)) > 2.0 / (self.grid.size * self.grid.step)

    def _settle(self, protect_last: bool) -> None:
        """After an addition: refine the nonlinear parameters, then backward elimination."""
        for _ in range(3):
            refined = self._refine() if len(self.found) > 1 else False
            dropped = self._eliminate(protect_last)
            protect_last = False
            if not (refined or dropped):
                break

    def smooth_swap(self) -> bool:
        """The drift terms found against one slow exponential settling; the better stays.

        The forward search offers time constants up to a quarter of the span only (a
        slower decay is close to a low-order polynomial over the record, and an
        exponential had taken a true cubic's place).  So a slow decay (T = 30,000 or
        60,000 s over a day) was removed as quadratic + cubic, or as a quadratic + a
        faster exponential, whose constant terms took the decay's amplitude into the
        bias: errors of 1e-8 and 3e-9 m/s² at z = 130 and 460.  Here the drift terms
        found (quadratic, cubic, exponential; at least one polynomial) are compared
        with one exponential of T up to
        :data:`~accal.closure.candidates.EXP_LONG_FRACTION` × span (not at that cap),
        both given the other effects, by their Wald statistic less the χ²₁ quantile at
        ``alpha`` per parameter (an exponential has an amplitude per channel and T):
        the exponential replaces them when its score is larger by more than
        :data:`SWAP_MIN_GAIN`.
        """
        from scipy import stats

        from accal.closure.candidates import EXP_LONG_FRACTION

        drift = ("quadratic_drift", "cubic_drift", "exponential_drift")
        smooth = [f for f in self.found if f.prop.name in drift]
        bi = next((i for i, (n, _) in enumerate(self.builders) if n == "exponential_drift"), None)
        if bi is None or not any(f.prop.name != "exponential_drift" for f in smooth):
            return False
        others = [f for f in self.found if f not in smooth]
        basis, fit, lev = self.state(others)
        ctx = self.context(others, basis, fit, lev)
        ctx = dataclasses.replace(
            ctx, options={**ctx.options, "exp_tau_max": EXP_LONG_FRACTION * self.span}
        )
        props = [p for p, _ in self.propose(ctx, only=bi)]
        if not props:
            return False
        exp = props[0]
        w_exp = self.test(basis, fit, lev, exp.columns)
        w_cur = self.test(basis, fit, lev, np.column_stack([f.prop.columns for f in smooth]))
        if w_exp is None or w_cur is None:
            return False

        def n_par(props: list[Proposal]) -> int:
            return sum(p.columns.shape[1] + (p.name == "exponential_drift") for p in props)

        k = float(stats.chi2.isf(self.alpha, 1))
        gain = (w_exp.stat * w_exp.q - k * n_par([exp])) - (
            w_cur.stat * w_cur.q - k * n_par([f.prop for f in smooth])
        )
        p_adj = self._padj(w_exp, exp.multiplicity)
        if gain <= SWAP_MIN_GAIN or p_adj >= self.alpha:
            return False
        info = {
            "stat": w_exp.stat,
            "dof": w_exp.dof,
            "multiplicity": exp.multiplicity,
            "replaces": [f.prop.name for f in smooth],
        }
        self.removed.extend(smooth)
        self.found = [*others, _Found(_independent(basis, exp, self.use), p_adj, info, bi)]
        self._settle(protect_last=True)
        return True

    def model_key(self) -> frozenset:
        """The current set of effects (to stop when a model comes back)."""
        return frozenset((f.prop.name, f.prop.channel, _key(f.prop)) for f in self.found)

    def backward(self, max_effects: int) -> bool:
        """Effects that mask one another: start from every family's best member.

        Run when forward selection leaves structure ``unexplained``.  The best member
        of every family (given the effects found) is added at once, their lags,
        epochs and frequencies are refined given each other, and backward
        elimination keeps those significant given all the others (periodic and
        auxiliary survivors must also pass the consistency check).  Kept only if a
        new effect survives; otherwise the forward result stands.
        """
        before = list(self.found)
        n_removed, n_unexpl, excluded = (
            len(self.removed),
            len(self.unexplained),
            list(self.excluded),
        )
        basis, fit, lev = self.state(before)
        ctx = self.context(before, basis, fit, lev)
        trial = list(before)
        df = 1.0 / (self.grid.size * self.grid.step)
        for prop, bi in self.propose(ctx):
            b, *_ = self.state(trial)
            if b.complement(prop.columns[self.use]).shape[1] == 0:
                continue
            if any(
                abs(f - g) <= 1.5 * df for f in _freqs(prop) for x in trial for g in _freqs(x.prop)
            ):
                # two sinusoids this close are nearly collinear: jointly they fit a
                # changing amplitude with two huge cancelling terms (QA: 9e-7 m/s² each
                # for a once-per-revolution term growing to 4e-9 m/s²)
                continue
            trial.append(_Found(_independent(b, prop, self.use), 1.0, {"stage": "backward"}, bi))
        if len(trial) == len(before):
            return False
        self.found = trial
        self._settle(protect_last=False)
        while self.found:  # elimination stops at one effect: test that one too
            p = self.final_p()
            worst = int(np.argmax(p))
            if p[worst] < self.alpha:
                break
            self._drop(worst)
        for f in list(self.found):  # identity, not ==: _Found holds arrays
            if any(f is g for g in before) or not f.prop.check_consistency:
                continue
            b_o, *_ = self.state([g for g in self.found if g is not f])
            if not self._consistent(b_o, f.prop, 1.0, f.info):
                self.found = [g for g in self.found if g is not f]
        if len(self.found) > max_effects:
            p = self.final_p()
            keep = sorted(np.argsort(p)[:max_effects])
            self.found = [self.found[i] for i in keep]
        before_keys = {(f.prop.name, f.prop.channel) for f in before}
        if not any((f.prop.name, f.prop.channel) not in before_keys for f in self.found):
            self.found = before
            del self.removed[n_removed:]
            del self.unexplained[n_unexpl:]
            self.excluded = excluded
            return False
        # report as "removed" only forward effects the joint fit made redundant
        ids = {id(f) for f in before}
        self.removed[n_removed:] = [f for f in self.removed[n_removed:] if id(f) in ids]
        return True

    def final_p(self, found: Sequence[_Found] | None = None) -> list[float]:
        """Corrected p-value of every effect given all the others (the reported one).

        ``found``: those effects instead of :attr:`found` (e.g. with their Jacobians).
        """
        found = self.found if found is None else found
        out = []
        for i, f in enumerate(found):
            others = [g for j, g in enumerate(found) if j != i]
            basis, fit, lev = self.state(others)
            w = self.test(basis, fit, lev, f.prop.columns)
            out.append(1.0 if w is None else self._padj(w, f.prop.multiplicity))
        return out

    def _significant_given(self, i: int, others: Sequence[_Found]) -> bool:
        basis, fit, lev = self.state(others)
        prop = self.found[i].prop
        w = self.test(basis, fit, lev, prop.columns)
        return w is not None and self._padj(w, prop.multiplicity) < self.alpha

    def _eliminate(self, protect_last: bool) -> bool:
        """Backward elimination, with the newest effect re-searched without each earlier one.

        An earlier effect ``i`` is dropped if it is not significant given the others,
        or given the others with the newest effect's family re-searched without
        ``i`` (its lag, epoch or frequency may have been pulled off by ``i``: e.g. the
        once-per-orbit part of a lagged temperature coupling taken as ``periodic``).
        """
        any_drop = False
        changed = True
        while changed and len(self.found) > 1:
            changed = False
            last = len(self.found) - 1
            for i in range(len(self.found) - (1 if protect_last else 0)):
                others = [f for j, f in enumerate(self.found) if j != i]
                if not self._significant_given(i, others):
                    self._drop(i)
                    changed = any_drop = True
                    break
                if not protect_last or i == last:
                    continue
                newest = self.found[last]
                rest = [f for j, f in enumerate(self.found) if j not in (i, last)]
                b_r, f_r, l_r = self.state(rest)
                ctx = self.context(rest, b_r, f_r, l_r)
                alt = [
                    p
                    for p, _ in self.propose(ctx, only=newest.builder)
                    if p.name == newest.prop.name and p.channel == newest.prop.channel
                ]
                if not alt or _same_member(alt[0], self.found[i].prop, self.use):
                    # re-searched without i, the family lands on i itself: i and the
                    # newest are two distinct members (e.g. two spectral lines)
                    continue
                cand = _Found(
                    _independent(b_r, alt[0], self.use), newest.p_adj, newest.info, newest.builder
                )
                if not self._significant_given(i, [*rest, cand]):
                    self.found[last] = cand
                    self._drop(i)
                    changed = any_drop = True
                    break
        # the loop stops at one effect; a survivor of drops was last tested with the
        # dropped ones (QA: a step accepted as a pair with a quadratic, p 3.9e-4, stayed
        # when the quadratic went, at corrected p 0.19 alone)
        if any_drop and len(self.found) == 1 and not self._significant_given(0, []):
            self._drop(0)
        return any_drop


def _same_member(a: Proposal, b: Proposal, use: NDArray[np.bool_], tol: float = 0.1) -> bool:
    """Whether proposal ``a``'s columns lie (to ``tol`` in relative norm) in ``b``'s span."""
    if a.name != b.name or a.channel != b.channel:
        return False
    za, zb = a.columns[use], b.columns[use]
    coef, *_ = np.linalg.lstsq(zb, za, rcond=None)
    left = np.linalg.norm(za - zb @ coef, axis=0)
    return bool(np.all(left <= tol * np.maximum(np.linalg.norm(za, axis=0), 1e-300)))


def _split_square(prop: Proposal) -> tuple[Proposal, Proposal]:
    """The coupling and its square from a :meth:`_Search._with_square` proposal."""
    from accal.closure.candidates import SQUARED

    k = int(prop.params["with_square"])
    params = {kk: v for kk, v in prop.params.items() if kk != "with_square"}
    axes = prop.axes
    lin = dataclasses.replace(
        prop,
        columns=prop.columns[:, :k],
        labels=prop.labels[:k],
        params=params,
        axes=None if axes is None else axes[:k],
    )
    sq = dataclasses.replace(
        prop,
        channel=f"{prop.channel}{SQUARED}",
        columns=prop.columns[:, k:],
        labels=prop.labels[k:],
        params=dict(params),
        axes=None if axes is None else axes[k:],
        jacobian=None,
    )
    return lin, sq


def _freqs(prop: Proposal) -> list[float]:
    """The frequencies of a periodic proposal's sinusoids [Hz] (none for others)."""
    if prop.name != "periodic" or prop.params.get("frequency") is None:
        return []
    f = float(prop.params["frequency"])
    return [n * f for n in prop.params.get("harmonics", (1,))]


def _key(prop: Proposal) -> tuple:
    """What identifies a family member (lag, epoch, frequency, ...)."""
    return tuple(sorted((k, repr(v)) for k, v in prop.params.items()))


def _sandwich(rinv: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R⁻¹ G R⁻ᵀ`` per block."""
    return np.einsum("spr,srq,stq->spt", rinv, g, rinv)


def _component_rms(basis: Basis, z: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """RMS of the part of ``y`` explained by columns ``z`` on top of the design."""
    fit: FitResult = basis.extend(z).fit(y)
    c = np.nan_to_num(fit.gamma[-z.shape[1] :])
    return float(np.sqrt(np.mean((z @ c) ** 2)))


def _describe_smooth(grid: Grid, t: NDArray[np.float64], comp: NDArray[np.float64], w) -> Effect:
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
    )


def _amplitude(a: float, b: float, cov: NDArray[np.float64]) -> tuple[float, float]:
    """``hypot(a, b)`` of a cos/sin pair and its σ from their 2×2 covariance ``cov``."""
    amp = float(np.hypot(a, b))
    g = np.array([a, b]) / amp if amp > 0 else np.zeros(2)
    return amp, float(np.sqrt(max(g @ cov @ g, 0.0)))


def _main_coefficient(prop: Proposal, c, cc, span: float) -> tuple[float, float, dict[str, Any]]:
    """The reported coefficient/sigma of one channel's columns of an effect, plus details."""
    sig = np.sqrt(np.clip(np.diag(cc), 0, None))
    q = c.size
    if prop.name in ("quadratic_drift", "cubic_drift"):
        powers = prop.params["powers"][-q:]
        si = np.array([span**-k for k in powers])
        return (
            float(c[-1] * si[-1]),
            float(sig[-1] * si[-1]),
            {"coefficients": (c * si).tolist(), "sigmas": (sig * si).tolist()},
        )
    if prop.name == "periodic":
        amps, phases, amp_sig = [], [], []
        mod: dict[str, Any] = {}
        if prop.params.get("modulated") and prop.labels[-1].startswith("usin@"):
            # the last two columns: u·cos, u·sin with u = (t − t_mid)/span
            rate, rate_sig = _amplitude(c[-2], c[-1], cc[-2:, -2:])
            mod = {"amplitude_rate": rate / span, "amplitude_rate_sigma": rate_sig / span}
            q -= 2
        for h in range(q // 2):
            a, b = c[2 * h], c[2 * h + 1]
            amp, amp_s = _amplitude(a, b, cc[2 * h : 2 * h + 2, 2 * h : 2 * h + 2])
            amps.append(amp)
            amp_sig.append(amp_s)
            phases.append(float(np.arctan2(-b, a)))
        return (
            amps[0],
            amp_sig[0],
            {
                "coefficients": c.tolist(),
                "sigmas": sig.tolist(),
                "amplitudes": amps,
                "amplitude_sigmas": amp_sig,
                "phases": phases,
                **mod,
            },
        )
    return float(c[0]), float(sig[0]), {"coefficients": c.tolist(), "sigmas": sig.tolist()}


def _exponentials_from(effects: Sequence[Effect], t0: float) -> list[Effect]:
    """``effects`` with each exponential's amplitude referred to ``t0``.

    A search that left out the record's start (a lagged coupling) fits
    ``A'·exp(−(t − t0')/T)`` from its own first sample ``t0'``; the record's
    amplitude is ``A = A'·exp((t0' − t0)/T)`` (QA: 4.9e-10 was reported for a decay
    of 3e-9 starting 5400 s earlier).  Its σ adds T's: ``∂A/∂T = −A·(t0' − t0)/T²``.
    """
    out = []
    for e in effects:
        t_e = e.details.get("t0")
        if e.name != "exponential_drift" or not e.tau or t_e is None or t_e == t0:
            out.append(e)
            continue
        shift = float(t_e) - t0
        s_tau = float(e.details.get("tau_sigma") or 0.0)
        coef, sigma = _moved_amplitude(e.coefficient, e.sigma, shift, e.tau, s_tau)
        details = {**e.details, "t0": t0, "amplitude_moved_from": float(t_e)}
        if "axes" in e.details:
            details["axes"] = {
                ax: {
                    **d,
                    **dict(
                        zip(
                            ("coefficient", "sigma"),
                            _moved_amplitude(d["coefficient"], d["sigma"], shift, e.tau, s_tau),
                            strict=True,
                        )
                    ),
                }
                for ax, d in e.details["axes"].items()
            }
        out.append(dataclasses.replace(e, coefficient=coef, sigma=sigma, details=details))
    return out


def _moved_amplitude(
    amp: float, sigma: float, shift: float, tau: float, tau_sigma: float
) -> tuple[float, float]:
    """An exponential's amplitude ``shift`` [s] earlier, and its σ (with T's σ)."""
    factor = float(np.exp(shift / tau))
    a = amp * factor
    return a, float(np.hypot(sigma * factor, a * shift / tau**2 * tau_sigma))


def _effects(
    found: list[tuple[Proposal, float, dict[str, Any]]],
    gamma: NDArray[np.float64],
    cov: NDArray[np.float64],
    span: float,
    t0: float,
) -> list[Effect]:
    out = []
    j = 0
    for prop, p_adj, info in found:
        q = prop.columns.shape[1]
        c = gamma[j : j + q]
        cc = cov[j : j + q, j : j + q]
        details: dict[str, Any] = {**info, "n_columns": q}
        axis = None
        if prop.axes is None:
            coef, sig, det = _main_coefficient(prop, c, cc, span)
            details.update(det)
        else:
            per: dict[str, dict[str, Any]] = {}
            for ax in dict.fromkeys(prop.axes):
                idx = [i for i, a in enumerate(prop.axes) if a == ax]
                ca, sa, det = _main_coefficient(prop, c[idx], cc[np.ix_(idx, idx)], span)
                per[ax] = {"coefficient": ca, "sigma": sa, **det}
            axis = max(per, key=lambda a: abs(per[a]["coefficient"]) / max(per[a]["sigma"], 1e-300))
            coef, sig = per[axis]["coefficient"], per[axis]["sigma"]
            details["axes"] = per
        kw: dict[str, Any] = {}
        if prop.name in ("quadratic_drift", "cubic_drift"):
            details["powers"] = list(prop.params["powers"])
            details["t0"] = t0
        elif prop.name == "periodic":
            details.update({"harmonics": list(prop.params["harmonics"]), "t0": t0})
            kw["frequency"] = prop.params["frequency"]
        elif prop.name == "bias_step":
            kw["epoch"] = prop.params["epoch"]
        elif prop.name in ("auxiliary", "exponential_drift", "intra_period_shape"):
            if prop.name == "auxiliary":
                kw["lag"] = prop.params["lag"]
            elif prop.name == "exponential_drift":
                details["t0"] = t0
            else:
                details["tau_searched"] = prop.params["tau"]
            kw["tau"] = prop.params["tau"]
            n_e = int(prop.params.get("jacobian", 0))
            i = 0 if axis is None else prop.axes.index(axis)
            amp = float(c[i])
            for k, par in enumerate(prop.params.get("jacobian_params", ("tau",)) if n_e else ()):
                # see _with_tau_jacobian: β = A·δ (δ of ln T, or of the lag [s])
                jb = n_e * (k + 1) + i
                beta, s_beta = float(c[jb]), float(np.sqrt(max(cc[jb, jb], 0.0)))
                if amp == 0.0:
                    continue
                if par == "tau":
                    # the Gauss-Newton step, unless it is not a small one (T would
                    # shrink below a tenth or turn negative: the searched value stands)
                    if 1.0 + beta / amp > 0.1:
                        kw["tau"] = float(prop.params["tau"]) * (1.0 + beta / amp)
                    details["tau_sigma"] = float(prop.params["tau"]) * s_beta / abs(amp)
                else:  # a lag searched from 0 up: the step stays there
                    kw[par] = max(float(prop.params[par]) + beta / amp, 0.0)
                    details[f"{par}_sigma"] = s_beta / abs(amp)
        else:  # angle_offset and caller-supplied builders
            details.update(prop.params)
        out.append(
            Effect(prop.name, prop.channel, coef, sig, p_adj, details=details, axis=axis, **kw)
        )
        j += q
    return out
