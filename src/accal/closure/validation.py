"""Validation of a significant candidate before it may change the model: do no harm.

A candidate that passes its test of significance
(:mod:`accal.closure.significance`) still has to show three things before it is
added to the model (and, for an instrument effect, removed from the data):

1. **Identifiable** (:func:`identifiability`): the data can tell it from the
   signal.  Of the candidate's variation beyond the *bias* part of the null model
   (the declared polynomial or per-period bias, and the effects already added), at
   least the kind's ``ident_min`` (:mod:`accal.closure.kinds`) must lie outside the
   *signal* part (the orbit-phase template without a reference, the per-period
   modulated signal of the rotating platform).  What lies inside can only be
   estimated from the small remainder, and removing it would move the signal's
   estimate by the candidate times its projection: a line near the modulation
   frequency is the modulated signal (its sidebands), a lagged low-passed channel
   with an orbital cycle is a free once-per-revolution sinusoid.  With several
   columns the least favourable direction counts (the smallest generalised
   eigenvalue of the two Gram matrices).
2. **Confirmed on held-out stretches** (:func:`cross_validate`): the record is cut
   into :data:`N_FOLDS` contiguous stretches; for each, the candidate's coefficient
   is estimated on the others (with the whole model partialled out: Frisch-Waugh-
   Lovell) and used to predict the held-out stretch.  The candidate must lower the
   held-out squared error in total.  A coefficient that is not the same over the
   record (the candidate has fitted a stretch of signal, not an effect) fails.  A
   stretch whose complement holds under :data:`MIN_TRAIN_INFO` of the candidate's
   information is not assessable (an effect confined to it cannot be predicted from
   elsewhere); when the assessable stretches hold under :data:`MIN_ASSESSABLE` of
   the in-sample gain, the check does not apply and says so.
3. **Physically plausible** (:func:`accal.closure.kinds.plausible`).

Without a reference, an instrument effect must also not be a change of the signal
seen on the other axes (:func:`signal_proxy_test`, with ``proxies``).

A candidate that fails is reported with the reason and never removed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh

from accal.closure.basis import Basis
from accal.closure.candidates import Context, Proposal
from accal.closure.kinds import EFFECT_NAMES, IDENT_MIN, kind_of, plausible
from accal.closure.residual import WaldResult, wald_test

__all__ = [
    "N_FOLDS",
    "SignalProxies",
    "Verdict",
    "cross_validate",
    "identifiability",
    "signal_proxy_test",
    "validate",
]

#: Contiguous stretches of the cross-validation.
N_FOLDS = 6
#: Least share of the candidate's information a fold's complement must hold.
MIN_TRAIN_INFO = 0.2
#: Least share of the in-sample gain on assessable folds for the check to apply.
MIN_ASSESSABLE = 0.25


@dataclass(frozen=True)
class Verdict:
    """Outcome of :func:`validate`.

    Attributes
    ----------
    ok : bool
        All three checks passed.
    reason : str
        Why not (empty when ``ok``).
    identifiability : float
        Share of the candidate's variation outside the signal model (1 without one).
    cv : dict
        The cross-validation: ``gain`` and ``gain_in_sample`` on the assessable folds
        [(m/s²)²], ``ratio``, ``folds``, ``assessable``, ``applicable``.
    coefficient : float
        Fitted coefficient (largest contribution over the columns), SI.
    plausible : bool
        Within the kind's physical bounds.
    signal_proxy : dict
        :func:`signal_proxy_test` (empty when not made): ``channels``, ``p_adj``,
        ``stat``.
    """

    ok: bool
    reason: str
    identifiability: float
    cv: dict[str, Any] = field(default_factory=dict)
    coefficient: float = float("nan")
    plausible: bool = True
    signal_proxy: dict[str, Any] = field(default_factory=dict)

    def details(self) -> dict[str, Any]:
        """The checks as ``closure.json`` details."""
        out = {
            "identifiability": self.identifiability,
            "cross_validation": dict(self.cv),
            "plausible": self.plausible,
        }
        if self.signal_proxy:
            out["signal_proxy"] = dict(self.signal_proxy)
        return out


@dataclass(frozen=True)
class SignalProxies:
    """Series that carry the target's signal, not its instrument (the other axes).

    Attributes
    ----------
    columns : ndarray, shape (N, q)
        The series on all samples [m/s²] (finite wherever the closure uses samples).
    names : tuple of str
        Their names, for reports.
    """

    columns: NDArray[np.float64]
    names: tuple[str, ...]


def signal_proxy_test(
    prop: Proposal,
    ctx: Context,
    proxies: SignalProxies,
    wald: WaldResult,
    factor: float,
) -> dict[str, Any]:
    """The candidate's test again with the other axes' signal in the model, its noise held.

    A change of the signal that the orbit-phase template cannot follow (a storm's
    onset: the density rises within an hour and the cross-track and radial drag,
    1-3 % of the along-track drag, rise with it) leaves a kink in the residual that a
    bias step fits (closure-detection: a removed 1-3e-9 m/s² step on 3 of 12 storm
    days, none without the storm on the same days and noise).  The same change is on
    the other axes, many times larger than their noise, so with those series as
    regressors (one free coefficient each: their coefficients are pinned by the whole
    day's signal, so an instrument effect on one axis cannot hide in them) it is
    explained, while an instrument effect of one axis is not.  The test is the
    candidate's Wald test (:func:`accal.closure.residual.wald_test`) of its columns
    orthogonalised against the model and the proxies, on the residual with the
    proxies fitted, with the noise PSD and degrees of freedom of the test that
    admitted it held: a re-estimated PSD would be lowered by the signal the proxies
    explain and make every candidate more significant (a 1/f wander then became a 5σ
    step on a quiet day).  This is the identifiability rule (issue 19, item 3:
    "tested with the orbit harmonics and other signal-shaped nuisances already in
    the null model") applied to the signal that is not orbit-periodic.

    Returns
    -------
    dict
        ``channels``, ``stat`` (Wald statistic per column), ``p_adj`` (p-value times
        ``factor``, the multiplicity and families of the admitting test).
    """
    use = ctx.use
    pcols = proxies.columns[use]
    q_p = ctx.basis.complement(pcols)
    out: dict[str, Any] = {"channels": list(proxies.names)}
    if q_p.shape[1] == 0 or wald.psd is None:
        return {**out, "stat": float(wald.stat), "p_adj": float(min(1.0, wald.pvalue * factor))}
    r_p = ctx.residual - q_p @ (q_p.T @ ctx.residual)
    z = prop.columns[use]
    z = ctx.basis.complement(z)
    z = z - q_p @ (q_p.T @ z)
    u, sv, _ = np.linalg.svd(z, full_matrices=False)
    keep = sv > 1e-8 * max(float(sv[0]) if sv.size else 0.0, 1e-300)
    if not keep.any():
        return {**out, "stat": 0.0, "p_adj": 1.0}
    w = wald_test(ctx.grid, r_p, u[:, keep], ctx.leverage, psd=wald.psd, psd_dof=wald.dof)
    return {**out, "stat": float(w.stat), "p_adj": float(min(1.0, w.pvalue * factor))}


def _gram_ratio(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Smallest generalised eigenvalue of ``a x = λ b x`` (``b`` positive semi-definite)."""
    if a.shape[0] == 1:
        return float(a[0, 0] / b[0, 0]) if b[0, 0] > 0 else 1.0
    scale = np.sqrt(np.maximum(np.diag(b), 1e-300))
    an = a / np.outer(scale, scale)
    bn = b / np.outer(scale, scale)
    lam_b, vec_b = np.linalg.eigh(bn)
    keep = lam_b > 1e-10 * max(float(lam_b.max()), 1e-300)
    if not keep.any():
        return 1.0
    w = vec_b[:, keep] / np.sqrt(lam_b[keep])
    return float(eigh(w.T @ an @ w, eigvals_only=True)[0])


def identifiability(z: NDArray[np.float64], full: Basis, bias: Basis | None) -> float:
    """Share of ``z``'s variation beyond the bias model that lies outside the signal model.

    ``z`` (used samples, (n, q)); ``full``: the whole current model (bias, signal,
    effects); ``bias``: the same without its signal part (None: there is none, 1).
    """
    if bias is None:
        return 1.0
    zf = z - full.project(z)
    zb = z - bias.project(z)
    return float(np.clip(_gram_ratio(zf.T @ zf, zb.T @ zb), 0.0, 1.0))


def _folds(t: NDArray[np.float64], k: int) -> NDArray[np.int64]:
    """Fold of each sample: ``k`` contiguous stretches of equal sample counts."""
    n = t.size
    return np.minimum((np.arange(n) * k) // max(n, 1), k - 1)


def cross_validate(
    t: NDArray[np.float64], r: NDArray[np.float64], zp: NDArray[np.float64], k: int = N_FOLDS
) -> dict[str, Any]:
    """Held-out prediction gain of the candidate columns ``zp`` for the residual ``r``.

    ``zp`` is the candidate with the current model projected out, ``r`` the current
    residual (both on the used samples, time order ``t``).  Fold ``j``'s
    coefficient ``c₋ⱼ`` is fitted on the other folds; its gain is ``‖r_j‖² − ‖r_j −
    Z_j c₋ⱼ‖²``.  Returns ``gain`` (summed over the assessable folds),
    ``gain_in_sample`` (the same folds, the coefficient of all the data), their
    ``ratio``, ``folds``, ``assessable`` and ``applicable`` (see the module notes).
    """
    fold = _folds(t, k)
    q = zp.shape[1]
    a = zp.T @ zp
    b = zp.T @ r
    c = np.linalg.lstsq(a, b, rcond=1e-12)[0]
    gain, gain_in, gain_tot, n_ok = 0.0, 0.0, 0.0, 0
    for j in range(k):
        m = fold == j
        if not m.any():
            continue
        zj, rj = zp[m], r[m]
        aj = zj.T @ zj
        bj = zj.T @ rj
        g_in = float(2.0 * c @ bj - c @ aj @ c)
        gain_tot += g_in
        at = a - aj
        if _gram_ratio(at, a) < MIN_TRAIN_INFO:
            continue
        cj = np.linalg.lstsq(at, b - bj, rcond=1e-12)[0]
        gain += float(2.0 * cj @ bj - cj @ aj @ cj)
        gain_in += g_in
        n_ok += 1
    applicable = n_ok >= 2 and gain_in >= MIN_ASSESSABLE * max(gain_tot, 0.0) and gain_tot > 0
    return {
        "gain": gain,
        "gain_in_sample": gain_in,
        "ratio": gain / gain_in if gain_in > 0 else float("nan"),
        "folds": k,
        "assessable": n_ok,
        "applicable": bool(applicable),
        "columns": q,
        "units": {"gain": "(m/s^2)^2"},
    }


def _coefficient(prop: Proposal, zp, zb, r) -> tuple[float, float]:
    """(coefficient, extent) of the column contributing most to the fit.

    The extent is the peak-to-peak of the column beyond the bias model (``zb``: what
    the effect adds to the declared model, e.g. the in-period curvature of a ``t²``
    term under a per-period affine bias, not its value after a day).
    """
    c = np.linalg.lstsq(zp.T @ zp, zp.T @ r, rcond=1e-12)[0]
    ext = np.ptp(zb, axis=0)
    j = int(np.argmax(np.abs(c) * ext))
    return float(c[j]), float(ext[j])


def validate(
    prop: Proposal,
    ctx: Context,
    bias_basis: Basis | None,
    t_used: NDArray[np.float64],
    signal_basis: Basis | None = None,
    *,
    proxies: SignalProxies | None = None,
    wald: WaldResult | None = None,
    factor: float = 1.0,
    alpha: float = 0.01,
) -> Verdict:
    """The checks of the module notes for ``prop`` on top of the model in ``ctx``.

    ``signal_basis``: the model with the signal's extension (the signal may vary
    within a modulation period beyond the declared model), for identifiability.
    ``proxies``: the other axes (:func:`signal_proxy_test`), applied to instrument
    kinds with ``wald`` (the admitting test), its multiplicity ``factor`` and ``alpha``.
    """
    kind = kind_of(prop.name) if prop.name in EFFECT_NAMES else None
    z = prop.columns[ctx.use]
    zp = z - ctx.basis.project(z)
    zb = z - bias_basis.project(z) if bias_basis is not None else zp
    ident = identifiability(z, signal_basis or ctx.basis, bias_basis)
    ident_min = kind.ident_min if kind is not None else IDENT_MIN
    coef, extent = _coefficient(prop, zp, zb, ctx.residual)
    cv = cross_validate(t_used, ctx.residual, zp)
    ok_plaus, why = plausible(prop, coef, ctx, extent)
    if ident < ident_min:
        return Verdict(
            False,
            f"not identifiable: only {ident:.1%} of it lies outside the signal model "
            f"(needs {ident_min:.1%}): it cannot be told from the signal",
            ident,
            cv,
            coef,
            ok_plaus,
        )
    proxy: dict[str, Any] = {}
    if proxies is not None and wald is not None and kind is not None and kind.instrument:
        proxy = signal_proxy_test(prop, ctx, proxies, wald, factor)
        if not proxy["p_adj"] < alpha:
            return Verdict(
                False,
                "not identifiable: a change of the signal on the other axes "
                f"({', '.join(proxies.names)}) explains it as well (corrected p "
                f"{proxy['p_adj']:.2g} given them, needs < {alpha:g})",
                ident,
                cv,
                coef,
                ok_plaus,
                proxy,
            )
    if cv["applicable"] and not cv["gain"] > 0:
        return Verdict(
            False,
            "not confirmed on held-out stretches: fitted on the rest of the record it "
            f"predicts them worse than without it (held-out gain {cv['gain']:.3g} against "
            f"{cv['gain_in_sample']:.3g} in sample, {cv['assessable']} of {cv['folds']} "
            "stretches assessable)",
            ident,
            cv,
            coef,
            ok_plaus,
            proxy,
        )
    if not ok_plaus:
        return Verdict(False, f"implausible: {why}", ident, cv, coef, False, proxy)
    return Verdict(True, "", ident, cv, coef, True, proxy)
