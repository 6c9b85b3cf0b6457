"""Per-block estimation: pass 1 scan and pass 2 estimates of :func:`demodulate_stream`.

:func:`_scan_block` (usable periods and eq. 16 leakage), :func:`_estimate_block`
(per-period estimates, bias coefficients, eq. 21 covariance at lag 0) and
:func:`_shape_gain` (the response to an in-period slope and curvature).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .blocks import _Block, _block_basis, _Setup
from .lagcov import _lag_cov, _weight_spectra
from .weights import (
    _batched_solve,
    _design_joint,
    _leakage,
    _weights_eq14,
    _weights_gls,
    _weights_joint,
)


def _scan_block(st: _Setup, blk: _Block) -> tuple[NDArray, NDArray, NDArray]:
    """Pass 1: n_used, keep (enough samples at 0 and π), eq. 16 leakage with V̂b = [1, t]."""
    m, c, s, va, vb, _ = _block_basis(st, blk, with_aux=False)
    n_used = m.sum(axis=1).astype(np.int64)
    atrest = m > 0
    has0 = np.any(atrest & (c > 0.999), axis=1)
    hasp = np.any(atrest & (c < -0.999), axis=1)
    keep = (n_used >= st.need) & has0 & hasp
    return n_used, keep, _leakage(va, vb, c * m, s * m, m)


def _estimate_block(st: _Setup, blk: _Block, solver: str, cache: dict) -> dict[str, Any]:
    """Pass 2: per-period estimates, weights and covariances of one block."""
    pa, q, tau = st.pa, st.q, st.tau
    m, c, s, va, vb, scales = _block_basis(st, blk)
    pb = vb.shape[2]
    a = blk.arrs
    ok = a["valid"].astype(bool)
    n_used = m.sum(axis=1).astype(np.int64)
    atrest = m > 0
    has0 = np.any(atrest & (c > 0.999), axis=1)
    hasp = np.any(atrest & (c < -0.999), axis=1)
    keep = (n_used >= st.need) & has0 & hasp
    leak = _leakage(va, vb, c * m, s * m, m)
    my = np.where(ok, a["m_y"], 0.0)
    mz = np.where(ok, a["m_z"], 0.0)
    data = np.concatenate([my, mz], axis=1)
    if solver == "eq14":
        w, good = _weights_eq14(va, c, s, m)
    else:
        x = _design_joint(va, vb, c, s, m)
        if solver == "joint":
            w, good = _weights_joint(x)
        else:
            w, good = _weights_gls(x, m, st.r_reg, cache)
        w = w[:, :, : 2 * pa]
    keep &= good
    w[~keep] = 0.0
    w = np.nan_to_num(w)
    est = np.einsum("pqa,pq->pa", w, data)
    # bias coefficients: LS fit of the residual on the unmasked samples (eqs. 17-19)
    cy = np.einsum("pqa,pa->pq", va, est[:, :pa])
    cz = np.einsum("pqa,pa->pq", va, est[:, pa:])
    ry = (my - c * cy - s * cz) * m
    rz = (mz + s * cy - c * cz) * m
    vbm = vb * m[..., None]
    nb = np.einsum("pqa,pqb->pab", vbm, vbm)
    nb[~keep] = np.eye(pb)
    bsol, _ = _batched_solve(
        nb, np.stack([np.einsum("pqa,pq->pa", vbm, ry), np.einsum("pqa,pq->pa", vbm, rz)], axis=2)
    )
    bias_y, bias_z = bsol[..., 0].copy(), bsol[..., 1].copy()
    for b in (bias_y, bias_z):
        b[:, 1] /= tau
        for j, sc in enumerate(scales):
            b[:, 2 + j] /= sc
    spec = _weight_spectra(w, q)
    cov0 = _lag_cov(spec, spec, st.kernels[0])  # eq. 21, lag 0
    unit = np.ones(2 * pa)
    if pa == 2:
        unit[[1, 3]] = 1.0 / tau  # slope = coefficient/τ (normalised time)
    rd0 = cov0[:, 0, 0].copy()
    rd0_other = (
        _lag_cov(spec[:, :1], spec[:, :1], st.kernel_other)[:, 0, 0]
        if st.kernel_other is not None
        else None
    )
    gain, xgain = _shape_gain(st, w, c, s, pa)
    est = est * unit
    cov0 = cov0 * unit[None, :, None] * unit[None, None, :]
    sig = np.sqrt(np.maximum(np.einsum("paa->pa", cov0), 0.0))
    kk = np.flatnonzero(keep)
    t = a["time"]
    return {
        "keep": keep,
        "spec1": spec[:, :1],
        "rd0": rd0,
        "rd0_other": rd0_other,
        "n_masked": float(m.size - m.sum()),
        "n_samples": int(m.size),
        "rows": {
            "period_index": blk.p0 + kk,
            "t_start": t[kk, 0],
            "t_mid": 0.5 * (t[kk, 0] + t[kk, -1]),
            "est": est[kk],
            "sig": sig[kk],
            "bias_y": bias_y[kk],
            "bias_z": bias_z[kk],
            "n_used": n_used[kk],
            "leakage": leak[kk],
            "cov": cov0[kk],
            "gain": gain[kk],
            "xgain": xgain[kk],
        },
    }


def _shape_gain(st: _Setup, w: NDArray, c: NDArray, s: NDArray, pa: int) -> tuple[NDArray, NDArray]:
    """(P, 2, 2) twice: response of (a_Y, a_Z) to ``u`` and ``u² − ⟨u²⟩`` (minus their
    period means) of the signal on the same axis, and on the other axis.

    The signal of eq. 4, ``m_y = c·h, m_z = −s·h`` (Y) and ``m_y = s·h, m_z = c·h``
    (Z), through the estimator's weights; the true per-period mean of ``h`` (0 for
    ``u``; ``⟨u²⟩`` removed) is subtracted from the same axis' response.  The other
    axis' is 0 for a pattern with rests at two opposite angles, not with four: the
    mean model's a_Y then follows a_Z's slope (QA: −56 s · d(a_Z)/dt, 54σ RMS).
    """
    u = st.u
    same, cross = np.empty((w.shape[0], 2, 2)), np.empty((w.shape[0], 2, 2))
    for j, h in enumerate((u, u**2 - np.mean(u**2))):
        shapes = [np.concatenate([top * h, bot * h], axis=1) for top, bot in ((c, -s), (s, c))]
        for ax in (0, 1):
            wa = w[:, :, ax * pa]
            same[:, ax, j] = np.einsum("pq,pq->p", wa, shapes[ax])
            cross[:, ax, j] = np.einsum("pq,pq->p", wa, shapes[1 - ax])
    return same, cross
