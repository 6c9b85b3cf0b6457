"""What :func:`accal.closure.close_loop` returns: effects, base coefficients, the result.

Units are SI throughout; each :class:`Effect` carries the machine-readable unit of
its coefficient.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.blockbase import BlockBase
from accal.closure.residual import ResidualStats

__all__ = ["BaseCoefficient", "ClosureResult", "Effect"]


@dataclass(frozen=True)
class Effect:
    """One effect found (or one piece of structure left unexplained).

    Attributes
    ----------
    name : str
        One of :data:`accal.closure.kinds.EFFECT_NAMES`.
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
    instrument : bool
        An instrument effect (its kind's property, :mod:`accal.closure.kinds`):
        ``grace-bias`` removes it from the calibrated series.
    unit : str
        Machine-readable unit of ``coefficient``.
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
    instrument: bool = False
    unit: str = ""


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
    eliminated : tuple of Effect
        Effects added and later eliminated from the model by backward elimination
        (they stood in for another effect); never removed from the data.  What was
        removed from the data is :attr:`effects` with ``instrument`` set.
    rejected : tuple of Effect
        Significant candidates that were *not* added: not identifiable from the
        signal, not confirmed on held-out stretches, or physically implausible
        (``details["reason"]``); reported, never removed from the data.
    considered : tuple of dict
        The channels offered to the coupling search and those left out, with why
        (``{"channel", "status", "reason"}``).
    signal_model : dict
        The signal part of the null model (e.g. the orbit-phase template when
        there is no reference), empty when there is none.
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
    eliminated: tuple[Effect, ...] = ()
    rejected: tuple[Effect, ...] = ()
    considered: tuple[dict[str, Any], ...] = ()
    signal_model: dict[str, Any] = field(default_factory=dict)

    @property
    def removed(self) -> tuple[Effect, ...]:
        """Deprecated name of :attr:`eliminated` (these effects were *not* removed from
        the data)."""
        warnings.warn(
            "ClosureResult.removed is deprecated: it holds the effects eliminated from the "
            "model, not those removed from the data; use .eliminated",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.eliminated

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

    def instrument_model(self) -> NDArray[np.float64]:
        """The instrument effects alone (what ``grace-bias`` subtracts) on all samples [m/s²]."""
        out = np.zeros(self.time.size)
        for e, m in self.effect_models():
            if e.instrument:
                out += m
        return out

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
