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
4. add the best significant proposal and go back to 1, at most ``max_effects`` times;
5. finally test a generic smooth basis (piecewise-linear, ``catchall_knots`` knots) on
   top of the final model against the white + 1/f noise model fitted above twice the
   basis' frequencies and extrapolated down (the residual itself cannot tell slow
   structure from slow noise): if it is significant, whatever it captures is
   reported as ``unexplained`` with its dominant frequency, never as a named effect.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.closure.candidates import BUILDERS, Context, Proposal
from accal.closure.residual import (
    Grid,
    ResidualStats,
    characterise,
    estimate_psd,
    make_grid,
    orthonormal_complement,
    sandwich_cov,
    wald_test,
    white_plus_flicker,
)
from accal.errors import ValidationError, check_option

__all__ = ["DEFAULT_CANDIDATES", "BaseCoefficient", "ClosureResult", "Effect", "close_loop"]

DEFAULT_CANDIDATES = ("quadratic_drift", "cubic_drift", "bias_step", "periodic", "auxiliary")
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
        ``quadratic_drift``, ``cubic_drift``, ``bias_step``, ``periodic``,
        ``auxiliary``, ``angle_offset`` or ``unexplained``.
    channel : str or None
        Auxiliary channel name; ``"orbit"``/``"line"`` for periodic effects;
        for ``unexplained``: ``"smooth"`` (catch-all) or the rejected kind.
    coefficient : float
        Step size [m/s²]; coefficient of the highest power of ``(t − t0)``
        [m/s⁴ or m/s⁵]; coupling [m/s² per channel unit]; amplitude of the
        fundamental [m/s²]; RMS of the unexplained component [m/s²].
    sigma : float
        1σ uncertainty of ``coefficient`` under the coloured-noise model.
    significance : float
        Multiplicity-corrected p-value of the test that admitted the effect.
    epoch : float or None
        Step epoch (first sample after the step) [s].
    frequency : float or None
        Fundamental frequency (periodic) or dominant frequency (unexplained) [Hz].
    lag : float or None
        Lag of the auxiliary response [s].
    tau : float or None
        Time constant of the first-order auxiliary response [s] (0: none).
    details : dict
        Everything else (all coefficients of the family, phases, shape, ...).
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


@dataclass(frozen=True)
class BaseCoefficient:
    """A base-model coefficient before and after closing the loop.

    ``sigma_change`` is the uncertainty of the difference of the two (correlated)
    linear estimators, evaluated under the final residual's noise.
    """

    name: str
    before: float
    sigma_before: float
    after: float
    sigma_after: float
    change: float
    sigma_change: float

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
        ``t0``, ``drift`` [m/s³], ... in powers of ``t − t0``.
    t0 : float
        Reference epoch, the first used sample [s].
    rms_before, rms_after : float
        Residual RMS over the used samples [m/s²].
    time : ndarray, shape (N,)
        Sample times [s].
    use : ndarray of bool, shape (N,)
        Samples used.
    residual_before, residual_after : ndarray, shape (N,)
        ``y − model`` on all samples [m/s²].
    design : ndarray, shape (N, k)
        Final design (base columns first); ``labels`` names its columns.
    coef : ndarray, shape (k,)
        Coefficients of ``design`` (internal scaling: powers of ``(t−t0)/span``).
    cov : ndarray, shape (k, k)
        Their coloured-noise covariance.
    n_base : int
        Number of base columns.
    stats_before, stats_after : ResidualStats
        Residual characterisation before/after.
    iterations : int
        Selection iterations run.
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
    design: NDArray[np.float64]
    labels: tuple[str, ...]
    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    n_base: int
    stats_before: ResidualStats
    stats_after: ResidualStats
    iterations: int

    @property
    def found(self) -> bool:
        """True when any effect or unexplained structure was reported."""
        return bool(self.effects or self.unexplained)

    def model(self) -> NDArray[np.float64]:
        """The final model (base + effects) on all samples [m/s²]."""
        return self.design @ self.coef

    def effects_model(self) -> NDArray[np.float64]:
        """The effects alone (what to subtract to correct the data) on all samples [m/s²]."""
        return self.design[:, self.n_base :] @ self.coef[self.n_base :]

    def base_coefficient(self, name: str) -> BaseCoefficient:
        """The :class:`BaseCoefficient` called ``name``."""
        for b in self.base:
            if b.name == name:
                return b
        raise KeyError(f"no base coefficient {name!r} (have {[b.name for b in self.base]})")

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


@dataclass
class _Fit:
    coef: NDArray[np.float64]
    resid: NDArray[np.float64]
    qx: NDArray[np.float64]
    weights: NDArray[np.float64]  # (k, n): coef = weights @ y


def _lsq(x: NDArray[np.float64], y: NDArray[np.float64]) -> _Fit:
    q, r = np.linalg.qr(x)
    w = np.linalg.solve(r, q.T)
    coef = w @ y
    return _Fit(coef, y - x @ coef, q, w)


def _base_design(
    base: str | ArrayLike, t: NDArray[np.float64], t0: float, span: float
) -> tuple[NDArray[np.float64], tuple[str, ...], tuple[str, ...], NDArray[np.float64]]:
    """Columns, names, labels and SI scale factors of the base design."""
    if isinstance(base, str):
        check_option("base", base, _POLY_BASES)
        order = int(base[-1])
        u = (t - t0) / span
        cols = np.column_stack([u**k for k in range(order + 1)])
        scale = np.array([span**-k for k in range(order + 1)])
        return cols, _POLY_NAMES[: order + 1], tuple(f"t^{k}" for k in range(order + 1)), scale
    x = np.asarray(base, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != t.size:
        raise ValidationError(f"base design must have shape ({t.size}, p), got {x.shape}")
    p = x.shape[1]
    names = tuple(f"b{j}" for j in range(p))
    return x, names, tuple(f"base{j}" for j in range(p)), np.ones(p)


def _segment_masks(t: NDArray[np.float64], k: int = 3) -> list[NDArray[np.bool_]]:
    edges = np.linspace(t[0], t[-1], k + 1)
    seg = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, k - 1)
    return [seg == j for j in range(k)]


def _consistency(
    grid: Grid, x: NDArray[np.float64], z: NDArray[np.float64], y: NDArray[np.float64], t
) -> tuple[bool, dict[str, Any]]:
    """Is the effect's coefficient the same in each third of the record?"""
    masks = _segment_masks(t)
    xz = np.column_stack([x, z])
    fit = _lsq(xz, y)
    extra = np.column_stack([z * m[:, None] for m in masks[:-1]])
    zt = orthonormal_complement(extra, fit.qx)
    if zt.shape[1] == 0:
        return True, {}
    q_fft = np.fft.rfft(grid.place(fit.qx), axis=1)
    w = wald_test(grid, fit.resid, zt, q_fft)
    full = fit.coef[x.shape[1] :]
    seg_coefs = []
    for m in masks:
        if m.sum() < 10 * (x.shape[1] + z.shape[1]):
            continue
        sub = np.column_stack([x * m[:, None], z * m[:, None]])
        keep = np.linalg.norm(sub, axis=0) > 0
        c, *_ = np.linalg.lstsq(sub[:, keep][m], y[m], rcond=None)
        seg_coefs.append(c[-z.shape[1] :])
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


def close_loop(
    t: ArrayLike,
    y: ArrayLike,
    *,
    base: str | ArrayLike = "poly1",
    aux: dict[str, ArrayLike] | None = None,
    valid: ArrayLike | None = None,
    candidates: Sequence[str | Callable] = DEFAULT_CANDIDATES,
    alpha: float = 0.01,
    max_effects: int = 5,
    orbit_period: float | None = None,
    catchall_knots: int = 24,
    options: dict[str, Any] | None = None,
) -> ClosureResult:
    """Find the effects a linear base model lacks, add them and refit.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, strictly increasing [s].
    y : array_like, shape (N,)
        Data [m/s²] (e.g. one accelerometer axis, or raw − reference).
    base : {"poly0", "poly1", "poly2", "poly3"} or array_like, shape (N, p0)
        The base model: a polynomial in ``t − t0`` (``t0``: first used sample) or
        the caller's own design matrix (e.g. the demodulation basis).
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
    if t_all.size > 1 and not np.all(np.diff(t_all) > 0):
        raise ValidationError("sample times must be strictly increasing")
    use = np.isfinite(y_all) & np.isfinite(t_all)
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != t_all.shape:
            raise ValidationError(f"valid must have shape {t_all.shape}, got {v.shape}")
        use &= v
    if use.sum() < 50:
        raise ValidationError(f"need at least 50 usable samples, got {int(use.sum())}")
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

    t_u, y_u = t_all[use], y_all[use]
    t0 = float(t_u[0])
    span = float(t_u[-1] - t_u[0]) or 1.0
    grid = make_grid(t_u)
    x0, base_names, base_labels, base_scale = _base_design(base, t_all, t0, span)
    p0 = x0.shape[1]
    n_families = 0
    for name, _ in builders:
        if name == "auxiliary":
            n_families += len(aux_all)
        elif name == "periodic":
            n_families += 2 if orbit_period else 1
        else:
            n_families += 1
    n_families = max(n_families, 1)

    cols = [x0]
    labels = list(base_labels)
    found: list[tuple[Proposal, float, dict[str, Any]]] = []
    unexplained: list[Effect] = []
    excluded: list[float] = []
    fit0 = _lsq(x0[use], y_u)
    fit = fit0
    iterations = 0
    for _ in range(max_effects):
        iterations += 1
        x = np.column_stack(cols)
        qx_fft = np.fft.rfft(grid.place(fit.qx), axis=1)
        ctx = Context(
            t_all=t_all,
            use=use,
            t0=t0,
            span=span,
            grid=grid,
            residual=fit.resid,
            qx=fit.qx,
            qx_fft=qx_fft,
            labels=frozenset(labels),
            aux=aux_all,
            orbit_period=orbit_period,
            excluded_freqs=tuple(excluded),
            options={**opts, "enabled": tuple(n for n, _ in builders)},
        )
        tested = []
        for _, build in builders:
            for prop in build(ctx):
                zt = orthonormal_complement(prop.columns[use], fit.qx)
                if zt.shape[1] == 0:
                    continue
                w = wald_test(grid, fit.resid, zt, qx_fft)
                p_adj = min(1.0, w.pvalue * prop.multiplicity * n_families)
                # gate: significance; rank: explained power (RSS reduction)
                gain = float(w.gamma @ w.gamma)
                tested.append((p_adj >= alpha, -gain, len(tested), p_adj, prop, w))
        tested.sort(key=lambda e: e[:3])
        accepted = None
        for _, _, _, p_adj, prop, w in tested:
            if p_adj >= alpha:
                break
            info: dict[str, Any] = {"stat": w.stat, "dof": w.dof, "multiplicity": prop.multiplicity}
            if prop.check_consistency:
                ok, cinfo = _consistency(grid, x[use], prop.columns[use], y_u, t_u)
                info.update(cinfo)
                if not ok:
                    f = prop.params.get("frequency")
                    if f is not None:
                        excluded.append(float(f))
                    unexplained.append(
                        Effect(
                            "unexplained",
                            prop.name if prop.channel is None else f"{prop.name}:{prop.channel}",
                            _component_rms(prop.columns[use], x[use], y_u),
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
                    continue
            accepted = (prop, p_adj, info)
            break
        if accepted is None:
            break
        prop = accepted[0]
        found.append(accepted)
        cols.append(prop.columns)
        labels.extend(prop.labels)
        if prop.params.get("frequency") is not None:
            excluded.append(float(prop.params["frequency"]))
        fit = _lsq(np.column_stack(cols)[use], y_u)

    x_all = np.column_stack(cols)
    cov = sandwich_cov(grid, fit.resid, fit.weights, fit.qx)
    cov0 = sandwich_cov(grid, fit0.resid, fit0.weights, fit0.qx)
    dw = fit.weights[:p0] - fit0.weights
    covd = sandwich_cov(grid, fit.resid, dw, fit.qx)

    if catchall_knots and catchall_knots >= 3:
        zt = orthonormal_complement(_catchall(t_u, catchall_knots), fit.qx)
        if zt.shape[1]:
            qx_fft = np.fft.rfft(grid.place(fit.qx), axis=1)
            noise = estimate_psd(grid, fit.resid, qx_fft)
            f_lo = 2.0 * catchall_knots / (grid.size * grid.step)
            model, _ = white_plus_flicker(grid, noise, f_lo)
            w = wald_test(grid, fit.resid, zt, qx_fft, psd=model)
            if w.pvalue < alpha:
                unexplained.append(_describe_smooth(grid, t_u, zt @ w.gamma, w))

    effects = _effects(found, fit.coef, cov, p0, span, t0)
    base_out = []
    for j, nm in enumerate(base_names):
        s = base_scale[j]
        base_out.append(
            BaseCoefficient(
                nm,
                float(fit0.coef[j] * s),
                float(np.sqrt(max(cov0[j, j], 0.0)) * s),
                float(fit.coef[j] * s),
                float(np.sqrt(max(cov[j, j], 0.0)) * s),
                float((fit.coef[j] - fit0.coef[j]) * s),
                float(np.sqrt(max(covd[j, j], 0.0)) * s),
            )
        )
    res_before = y_all - x0 @ fit0.coef
    res_after = y_all - x_all @ fit.coef
    seg = orbit_period if orbit_period else None
    return ClosureResult(
        effects=tuple(effects),
        unexplained=tuple(unexplained),
        base=tuple(base_out),
        t0=t0,
        rms_before=float(np.sqrt(np.mean(fit0.resid**2))),
        rms_after=float(np.sqrt(np.mean(fit.resid**2))),
        time=t_all,
        use=use,
        residual_before=res_before,
        residual_after=res_after,
        design=x_all,
        labels=tuple(labels),
        coef=fit.coef,
        cov=cov,
        n_base=p0,
        stats_before=characterise(t_u, fit0.resid, segment=seg),
        stats_after=characterise(t_u, res_after[use], segment=seg),
        iterations=iterations,
    )


def _component_rms(z: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """RMS of the part of ``y`` explained by columns ``z`` on top of design ``x``."""
    c = _lsq(np.column_stack([x, z]), y).coef[x.shape[1] :]
    return float(np.sqrt(np.mean((z @ c) ** 2)))


def _describe_smooth(grid: Grid, t: NDArray[np.float64], comp: NDArray[np.float64], w) -> Effect:
    """An ``unexplained`` effect from the catch-all component ``comp`` (used samples)."""
    spec = np.abs(np.fft.rfft(grid.place(comp)[0])) ** 2
    spec[0] = 0.0
    k = int(np.argmax(spec))
    f = float(grid.freqs[k])
    idx = np.linspace(0, t.size - 1, min(100, t.size)).astype(int)
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
            "shape_t": t[idx].tolist(),
            "shape": comp[idx].tolist(),
        },
    )


def _effects(
    found: list[tuple[Proposal, float, dict[str, Any]]],
    coef: NDArray[np.float64],
    cov: NDArray[np.float64],
    p0: int,
    span: float,
    t0: float,
) -> list[Effect]:
    out = []
    j = p0
    for prop, p_adj, info in found:
        q = prop.columns.shape[1]
        c = coef[j : j + q]
        cc = cov[j : j + q, j : j + q]
        sig = np.sqrt(np.clip(np.diag(cc), 0, None))
        details: dict[str, Any] = {**info, "coefficients": c.tolist(), "sigmas": sig.tolist()}
        if prop.name in ("quadratic_drift", "cubic_drift"):
            powers = prop.params["powers"]
            si = np.array([span**-k for k in powers])
            details["powers"] = list(powers)
            details["coefficients"] = (c * si).tolist()
            details["sigmas"] = (sig * si).tolist()
            details["t0"] = t0
            eff = Effect(
                prop.name,
                None,
                float(c[-1] * si[-1]),
                float(sig[-1] * si[-1]),
                p_adj,
                details=details,
            )
        elif prop.name == "periodic":
            amps, phases, amp_sig = [], [], []
            for h in range(q // 2):
                a, b = c[2 * h], c[2 * h + 1]
                amp = float(np.hypot(a, b))
                g = np.array([a, b]) / amp if amp > 0 else np.zeros(2)
                sub = cc[2 * h : 2 * h + 2, 2 * h : 2 * h + 2]
                amps.append(amp)
                amp_sig.append(float(np.sqrt(max(g @ sub @ g, 0.0))))
                phases.append(float(np.arctan2(-b, a)))
            details.update(
                {
                    "harmonics": list(prop.params["harmonics"]),
                    "amplitudes": amps,
                    "amplitude_sigmas": amp_sig,
                    "phases": phases,
                    "t0": t0,
                }
            )
            eff = Effect(
                "periodic",
                prop.channel,
                amps[0],
                amp_sig[0],
                p_adj,
                frequency=prop.params["frequency"],
                details=details,
            )
        elif prop.name == "bias_step":
            eff = Effect(
                "bias_step",
                None,
                float(c[0]),
                float(sig[0]),
                p_adj,
                epoch=prop.params["epoch"],
                details=details,
            )
        elif prop.name == "auxiliary":
            eff = Effect(
                "auxiliary",
                prop.channel,
                float(c[0]),
                float(sig[0]),
                p_adj,
                lag=prop.params["lag"],
                tau=prop.params["tau"],
                details=details,
            )
        else:  # caller-supplied builders
            details.update(prop.params)
            eff = Effect(
                prop.name, prop.channel, float(c[0]), float(sig[0]), p_adj, details=details
            )
        out.append(eff)
        j += q
    return out
