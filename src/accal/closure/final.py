"""The final fit of a closure: nonlinear parameters' Jacobians, covariances, reported effects.

* :func:`with_jacobian`: an effect whose shape depends on a searched time constant
  or lag is fitted with those held; linearised at the fitted value the model gains
  one column per parameter (Gauss-Newton), so the parameter's σ and its cost to the
  other coefficients are in every covariance.
* :func:`covariances`: the coloured-noise covariances of the base coefficients
  before and after, and of the effects (sandwich ``G C Gᵀ`` evaluated spectrally,
  block by block for a block base).
* :func:`describe`: the :class:`~accal.closure.results.Effect` of each model term,
  with its coefficient in SI units and its σ.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import qr

from accal.closure.basis import Basis, FitResult
from accal.closure.candidates import Proposal
from accal.closure.kinds import EFFECT_NAMES, kind_of, unit_of
from accal.closure.residual import Grid, _quad, _two_sided, estimate_psd
from accal.closure.results import Effect
from accal.closure.transition import transition_columns

__all__ = [
    "covariances",
    "describe",
    "independent",
    "moved_amplitude",
    "refer_exponentials",
    "with_jacobian",
]


def independent(basis: Basis, prop: Proposal, use: NDArray[np.bool_], tol: float = 1e-8):
    """``prop`` reduced to columns independent of the design and of each other.

    Each column is measured against its own norm (the QR of the columns scaled to unit
    norm; Golub & Van Loan 2013, sec. 5.4.2): a coupling to a temperature near 294 K
    has a regressor ~1e6 times the norm of its lag Jacobian, and against the largest
    column a Jacobian 18 % of which lies outside the model was taken for dependent and
    dropped, so the coefficient's σ left out the lag and τ (a 2e-8 m/s²/K coupling
    found at 2.20e-8 ± 2.8e-10, ``docs/closure.md``;
    ``tests/closure/test_coupling_sigma_ridge.py``).
    """
    z = prop.columns[use]
    norms0 = np.linalg.norm(z, axis=0)
    scale = np.where(norms0 > 0, norms0, 1.0)
    zt = (z - basis.project(z)) / scale
    _, r, piv = qr(zt, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    keep = np.sort(piv[: int(np.sum(d > tol))])
    if keep.size == z.shape[1]:
        return prop
    return Proposal(
        prop.name,
        prop.channel,
        prop.columns[:, keep],
        tuple(prop.labels[i] for i in keep),
        prop.multiplicity,
        prop.params,
        None if prop.axes is None else tuple(prop.axes[i] for i in keep),
    )


def with_jacobian(prop: Proposal, t_all, t0: float, use, rest: Basis) -> Proposal:
    """``prop`` with the Jacobian columns of its searched time constant / lag appended.

    An exponential ``A·exp(−(t−t0)/T)`` linearised at the fitted ``T`` adds ``β·((t −
    t0)/T)·e`` with ``β = A·δ/T`` (σ(T) = σ(β)·T/|A|); a coupling through a
    low-pass adds ``∂h/∂lnτ`` and ``∂h/∂lag`` (:attr:`Proposal.jacobian`).  A
    Jacobian that is not independent of ``rest`` (the base and the other effects)
    is not added.  A bias step in low-passed data (``options["step_transition"]`` of
    :func:`accal.closure.close_loop`; one channel) gets the local columns of its
    transition instead (:mod:`accal.closure.transition`).
    """
    cols = prop.columns
    if prop.name == "bias_step" and prop.params.get("transition") and prop.axes is None:
        return _with_transition(prop, t_all, use, rest)
    if prop.name == "exponential_drift" and prop.params.get("tau"):
        parts = [("tau", cols * ((t_all - t0) / float(prop.params["tau"]))[:, None])]
    elif prop.jacobian is not None:
        parts = prop.jacobian()
    else:
        return prop
    jac = np.column_stack([d for _, d in parts])
    names = [k for k, _ in parts]
    aug = Proposal(
        prop.name,
        prop.channel,
        np.column_stack([cols, jac]),
        (*prop.labels, *(f"d{lb}/d{k}" for k in names for lb in prop.labels)),
        prop.multiplicity,
        {**prop.params, "jacobian": cols.shape[1], "jacobian_params": names},
        None if prop.axes is None else tuple(prop.axes) * (1 + len(names)),
    )
    if independent(rest, aug, use).columns.shape[1] != aug.columns.shape[1]:
        return prop
    return aug


def _with_transition(prop: Proposal, t_all, use, rest: Basis) -> Proposal:
    """A single-channel bias step with its transition's local columns
    (:func:`accal.closure.transition.transition_columns`); those not independent of
    ``rest`` and of the others (a gap at the epoch, a coarse sampling) are left out."""
    steps = np.diff(t_all[use])
    dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    parts = transition_columns(t_all, float(prop.params["epoch"]), dt)
    if not parts:
        return prop
    names = [k for k, _ in parts]
    aug = Proposal(
        prop.name,
        prop.channel,
        np.column_stack([prop.columns] + [d for _, d in parts]),
        (*prop.labels, *(f"d{lb}/d{k}" for k in names for lb in prop.labels)),
        prop.multiplicity,
        prop.params,
    )
    red = independent(rest, aug, use)
    if red.labels[0] != prop.labels[0]:  # the step itself is not independent
        return prop
    kept = [names[aug.labels.index(lb) - 1] for lb in red.labels[1:]]
    params = {**prop.params, "jacobian": 1, "jacobian_params": kept}
    return dataclasses.replace(red, params=params)


def _sandwich(rinv: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R⁻¹ G R⁻ᵀ`` per block."""
    return np.einsum("spr,srq,stq->spt", rinv, g, rinv)


def model_psd(grid: Grid, noise_psd) -> NDArray[np.float64]:
    """A given two-sided PSD function on the grid's frequencies, per sample."""
    f = grid.freqs
    fpos = np.where(f > 0, f, f[1] if f.size > 1 else 1.0)  # S(0) of a 1/f law: S(df)
    return np.asarray(noise_psd(fpos), dtype=np.float64) / grid.step


def covariances(
    grid: Grid,
    basis: Basis,
    fit: FitResult,
    lev: NDArray[np.float64],
    basis0: Basis,
    fit0: FitResult,
    lev0: NDArray[np.float64],
    noise_psd=None,
) -> dict[str, NDArray[np.float64]]:
    """Covariances of the final fit under coloured noise, per block of the base.

    Returns ``v_ww`` (effects, (k, k)), ``cov_b`` (base after, per segment),
    ``cov_bg`` (base–effects), ``cov_d`` (what estimating the effects adds),
    ``v_ll`` (base alone under the final noise), ``v_ll0`` (base alone, before).
    With ``noise_psd`` the instrument's model PSD is used before and after,
    otherwise the residuals' estimates.
    """
    if noise_psd is not None:
        psd = psd0 = model_psd(grid, noise_psd)
    else:
        psd = estimate_psd(grid, fit.resid, lev).psd
        psd0 = estimate_psd(grid, fit0.resid, lev0).psd
    ns = basis.seg_start.size
    rinv = basis.rinv
    v_ll = _sandwich(rinv, basis.block_cov(grid, psd))
    v_ll0 = _sandwich(rinv, basis0.block_cov(grid, psd0))
    k = fit.k_kept
    if k:
        wg = fit.w_gamma.T  # (n, k)
        g_fft = grid.fft(wg)
        v_ww = _quad(g_fft, _two_sided(grid.size, g_fft.shape[-1]) * psd, grid.size)
        v_ww = 0.5 * (v_ww + v_ww.T)
        cw = np.fft.irfft(g_fft * psd, grid.size, axis=-1)[:, grid.channel, grid.idx].T
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
    return {
        "v_ww": v_ww,
        "cov_b": cov_b,
        "cov_bg": cov_bg,
        "cov_d": cov_d,
        "v_ll": v_ll,
        "v_ll0": v_ll0,
    }


def _amplitude(a: float, b: float, cov: NDArray[np.float64]) -> tuple[float, float]:
    """``hypot(a, b)`` of a cos/sin pair and its σ from their 2×2 covariance ``cov``."""
    amp = float(np.hypot(a, b))
    g = np.array([a, b]) / amp if amp > 0 else np.zeros(2)
    return amp, float(np.sqrt(max(g @ cov @ g, 0.0)))


def _main_coefficient(prop: Proposal, c, cc, span: float) -> tuple[float, float, dict[str, Any]]:
    """The reported coefficient/sigma of one channel's columns of an effect, plus details.

    A polynomial's columns are ``((t − t0)/scale)^k`` with the ``scale`` of the search
    that proposed them (its ``params``), which may not be the final model's ``span``: a
    search started again without a lagged channel's unknown first samples keeps the
    effects of the first (QA: a 1e-13 m/s⁴ quadratic reported 0.7 % high, 400σ, as
    (86,399/86,099)² with the first 300 s left out).
    """
    sig = np.sqrt(np.clip(np.diag(cc), 0, None))
    q = c.size
    if prop.name in ("quadratic_drift", "cubic_drift"):
        span = float(prop.params.get("scale", span))
        powers = prop.params["powers"][-q:]
        si = np.array([span**-k for k in powers])
        return (
            float(c[-1] * si[-1]),
            float(sig[-1] * si[-1]),
            {"coefficients": (c * si).tolist(), "sigmas": (sig * si).tolist()},
        )
    if prop.name == "periodic":
        amps, phases, amp_sig = [], [], []
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
            },
        )
    return float(c[0]), float(sig[0]), {"coefficients": c.tolist(), "sigmas": sig.tolist()}


def _nonlinear(prop: Proposal, c, cc, i: int, kw: dict, details: dict) -> None:
    """Update ``kw`` (``tau``/``lag``) and ``details`` (their σ) from the Jacobian columns."""
    n_e = int(prop.params.get("jacobian", 0))
    amp = float(c[i])
    for k, par in enumerate(prop.params.get("jacobian_params", ("tau",)) if n_e else ()):
        if par.startswith("transition"):  # a step's shape (accal.closure.transition)
            continue
        # β = A·δ (δ of ln T, or of the lag [s])
        jb = n_e * (k + 1) + i
        beta, s_beta = float(c[jb]), float(np.sqrt(max(cc[jb, jb], 0.0)))
        if amp == 0.0:
            continue
        if par == "tau":
            if 1.0 + beta / amp > 0.1:  # a small Gauss-Newton step only
                kw["tau"] = float(prop.params["tau"]) * (1.0 + beta / amp)
            details["tau_sigma"] = float(prop.params["tau"]) * s_beta / abs(amp)
        else:
            kw[par] = max(float(prop.params[par]) + beta / amp, 0.0)
            details[f"{par}_sigma"] = s_beta / abs(amp)


def describe(
    found: list[tuple[Proposal, float, dict[str, Any]]],
    gamma: NDArray[np.float64],
    cov: NDArray[np.float64],
    span: float,
    t0: float,
    channel_units: dict[str, str],
) -> list[Effect]:
    """The :class:`Effect` of each ``(proposal, p, details)`` from the final fit."""
    out = []
    j = 0
    for prop, p_adj, info in found:
        q = prop.columns.shape[1]
        c = gamma[j : j + q]
        cc = cov[j : j + q, j : j + q]
        details: dict[str, Any] = {**info, "n_columns": q, "multiplicity": prop.multiplicity}
        axis = None
        if prop.axes is None:
            coef, sig, det = _main_coefficient(prop, c, cc, span)
            details.update(det)
            i = 0
        else:
            per: dict[str, dict[str, Any]] = {}
            for ax in dict.fromkeys(prop.axes):
                idx = [k for k, a in enumerate(prop.axes) if a == ax]
                ca, sa, det = _main_coefficient(prop, c[idx], cc[np.ix_(idx, idx)], span)
                per[ax] = {"coefficient": ca, "sigma": sa, **det}
            axis = max(per, key=lambda a: abs(per[a]["coefficient"]) / max(per[a]["sigma"], 1e-300))
            coef, sig = per[axis]["coefficient"], per[axis]["sigma"]
            details["axes"] = per
            i = prop.axes.index(axis)
        kw: dict[str, Any] = {}
        for k in ("epoch", "frequency", "lag", "tau"):
            if prop.params.get(k) is not None:
                kw[k] = prop.params[k]
        if prop.name in ("quadratic_drift", "cubic_drift"):
            details["powers"] = list(prop.params["powers"])
            details["t0"] = float(prop.params.get("t0", t0))  # the columns' own origin
        elif prop.name == "periodic":
            harm = list(prop.params["harmonics"])
            details.update({"harmonics": harm, "t0": float(prop.params.get("t0", t0))})
        elif prop.name == "exponential_drift":
            details["t0"] = float(prop.params.get("t0", t0))
        elif prop.name == "intra_period_shape":
            details["tau_searched"] = prop.params["tau"]
        elif prop.name == "bias_step" and prop.params.get("ramp_duration"):
            # a ramp over minutes (accal.closure.softstep): its duration [s] and test
            details["ramp_duration"] = float(prop.params["ramp_duration"])
            details["ramp_p"] = float(prop.params["ramp_p"])
        elif prop.name not in ("bias_step", "auxiliary", "scale"):
            details.update({k: v for k, v in prop.params.items() if k != "jacobian"})
        if prop.params.get("jacobian"):
            _nonlinear(prop, c, cc, i, kw, details)
        known = prop.name in EFFECT_NAMES
        out.append(
            Effect(
                prop.name,
                prop.channel,
                coef,
                sig,
                p_adj,
                details=details,
                axis=axis,
                instrument=bool(kind_of(prop.name).instrument) if known else False,
                unit=unit_of(prop, channel_units),
                **kw,
            )
        )
        j += q
    return out


def refer_exponentials(effects: Sequence[Effect], t0: float) -> list[Effect]:
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
        coef, sigma = moved_amplitude(e.coefficient, e.sigma, shift, e.tau, s_tau)
        details = {**e.details, "t0": t0, "amplitude_moved_from": float(t_e)}
        if "axes" in e.details:
            details["axes"] = {
                ax: {
                    **d,
                    **dict(
                        zip(
                            ("coefficient", "sigma"),
                            moved_amplitude(d["coefficient"], d["sigma"], shift, e.tau, s_tau),
                            strict=True,
                        )
                    ),
                }
                for ax, d in e.details["axes"].items()
            }
        out.append(dataclasses.replace(e, coefficient=coef, sigma=sigma, details=details))
    return out


def moved_amplitude(
    amp: float, sigma: float, shift: float, tau: float, tau_sigma: float
) -> tuple[float, float]:
    """An exponential's amplitude ``shift`` [s] earlier, and its σ (with T's σ)."""
    factor = float(np.exp(shift / tau))
    a = amp * factor
    return a, float(np.hypot(sigma * factor, a * shift / tau**2 * tau_sigma))
