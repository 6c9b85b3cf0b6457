"""σ widened after the final fit, and the widening carried to the base coefficients.

The final fit's covariances come from the noise model and the linearised model; two
effects get a larger σ from elsewhere: a bias step on a per-period base from its
placebo epochs (:func:`placebo_step_sigmas`), a coupling from its profile with the lag
and τ free (:func:`widened_couplings`, the σ set by
:func:`accal.closure.lagprofile.add_lag_uncertainties`).  Either way the effect's row
and column of the effects' covariance are scaled (correlations kept) and the change
reaches the base coefficients by error propagation (:func:`propagate`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from accal.closure.candidates import step_placebo_sigma
from accal.closure.search import Found

__all__ = [
    "add_base_covariance",
    "placebo_step_sigmas",
    "propagate",
    "scale_variance",
    "widened_couplings",
]


def placebo_step_sigmas(ctx, final: list[Found], found, cov, fit) -> None:
    """A step's size variance: the larger of the noise model's and the placebo epochs'
    (:func:`~accal.closure.candidates.step_placebo_sigma`), in ``cov`` (in place); both
    σ in the effect's details.

    The base coefficients after the closure are the plain ones less ``A γ`` (``A``:
    ``fit.a_mat``, per block), so the wider step covariance ``V_ww + ΔV`` reaches them
    as ``cov_b + A ΔV Aᵀ`` (the step's own block: its a_Y, a_Z), ``cov_d + A ΔV Aᵀ``
    and ``cov_bg − A ΔV`` (error propagation of ``b_after = b_plain − A γ``).
    """
    v_ww = cov["v_ww"]
    v_old = v_ww.copy()
    j = 0
    for i, f in enumerate(final):
        q = f.prop.columns.shape[1]
        if f.prop.name == "bias_step" and f.prop.params.get("epoch") is not None:
            emp = step_placebo_sigma(ctx, float(f.prop.params["epoch"]))
            if emp is not None and emp.size == q:
                model = np.sqrt(np.maximum(np.diag(v_ww)[j : j + q], 0.0))
                for k in range(q):
                    if emp[k] > model[k] > 0:
                        scale_variance(v_ww, j + k, emp[k] / model[k])
                found[i][2]["sigma_noise_model"] = [float(x) for x in model]
                found[i][2]["sigma_placebo"] = [float(x) for x in emp]
        j += q
    propagate(cov, fit.a_mat, v_ww - v_old)


def widened_couplings(final: list[Found], effects, cov, fit, n_jumps: int) -> None:
    """A coupling whose σ its profile widened (:func:`~accal.closure.lagprofile.
    add_lag_uncertainties`): its row and column of the effects' covariance scaled to
    that σ, and the change carried to the base coefficients as in
    :func:`placebo_step_sigmas` (in place; the jumps' ``n_jumps`` columns come first)."""
    v_ww = cov["v_ww"]
    v_old = v_ww.copy()
    j = n_jumps
    for f, e in zip(final, effects, strict=True):
        if f.prop.name == "auxiliary":
            for k, g in _widening(f, e):  # a main column
                scale_variance(v_ww, j + k, g)
        j += f.prop.columns.shape[1]
    propagate(cov, fit.a_mat, (v_ww - v_old)[n_jumps:, n_jumps:], n_jumps)


def _widening(f: Found, e: Any) -> list[tuple[int, float]]:
    """``(column, σ after / σ before)`` of each main column of a coupling whose profile
    widened its σ: the first column, or with several data channels each channel's first
    (``f.prop.axes`` names the channel of every column)."""
    if f.prop.axes is None:
        lin = e.details.get("coefficient_sigma_linearised")
        return [(0, e.sigma / lin)] if lin and e.sigma > lin > 0 else []
    out = []
    for ax, d in e.details.get("axes", {}).items():
        lin = d.get("sigma_linearised")
        if lin and d["sigma"] > lin > 0 and ax in f.prop.axes:
            out.append((list(f.prop.axes).index(ax), d["sigma"] / lin))
    return out


def propagate(cov, a, dv, offset: int = 0) -> None:
    """A change ``dv`` of the effects' covariance carried to the base coefficients:
    ``b_after = b_plain − A γ`` gains ``A dv Aᵀ`` (``cov_b``, ``cov_d``) and ``cov(b, γ)``
    loses ``A dv`` (the effects' columns of ``cov_bg`` from ``offset``)."""
    if not np.any(dv):
        return
    add = a @ (dv[None] @ np.transpose(a, (0, 2, 1)))  # a: (segments, p, k)
    cov["cov_b"] = cov["cov_b"] + add
    cov["cov_d"] = cov["cov_d"] + add
    bg = cov["cov_bg"].copy()
    bg[:, :, offset:] = bg[:, :, offset:] - a @ dv[None]
    cov["cov_bg"] = bg


def add_base_covariance(cov, basis, extra) -> None:
    """Add ``extra`` (n_blocks, p, p), per block of the base, to the base coefficients'
    covariance after the closure and to that of their change (``cov_b``, ``cov_d``, per
    segment of ``basis``; in place): a variance the final fit's noise model does not
    hold (:func:`accal.closure.aliasspread.add_alias_spread`)."""
    seg_of = basis.seg_of_block()
    has = seg_of >= 0
    for key in ("cov_b", "cov_d"):
        out = cov[key].copy()
        out[seg_of[has]] += extra[has]
        cov[key] = out


def scale_variance(v, j: int, g: float) -> None:
    """Scale the σ of entry ``j`` of the covariance ``v`` by ``g`` (its row and column;
    correlations kept; in place)."""
    v[j, :] *= g
    v[:, j] *= g
