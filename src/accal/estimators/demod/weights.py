"""Weights of the linear per-period estimators, ``â = W'm``.

Eq. 14 demodulation, the joint least squares of eq. 17 and its generalised least
squares (section 5.3), with the normalised eq. 16 leakage that decides between
eq. 14 and eq. 17.
"""

from __future__ import annotations

import numpy as np


def _batched_solve(a, b):
    # a (P, p, p), b (P, p, k); returns None rows for singular systems
    cond = np.linalg.cond(a)
    ok = np.isfinite(cond) & (cond < 1e12)
    out = np.full(b.shape, np.nan)
    if ok.any():
        out[ok] = np.linalg.solve(a[ok], b[ok])
    return out, ok


def _leakage(va, vb, cmask, smask, m):
    # va (P,q,pa) unmasked, vb (P,q,pb); normalised max |ṽ' Λ b̂| / (|ṽ||M b̂|)  (eq. 16)
    vt = va * m[..., None]
    nv = np.sqrt(np.einsum("pqa,pqa->pa", vt, vt))
    bm = vb * m[..., None]
    nb = np.sqrt(np.einsum("pqb,pqb->pb", bm, bm))
    out = np.zeros(va.shape[0])
    for lam in (cmask, smask):
        g = np.abs(np.einsum("pqa,pq,pqb->pab", vt, lam, vb))
        den = nv[:, :, None] * nb[:, None, :]
        g = np.divide(g, den, out=np.zeros_like(g), where=den > 0)
        out = np.maximum(out, np.max(g.reshape(g.shape[0], -1), axis=1))
    return out


def _weights_eq14(va, c, s, m):
    # returns W (P, 2q, 2pa): params (aY..., aZ...) from stacked data (my; mz)  (eq. 14)
    vt = va * m[..., None]
    a = np.einsum("pqa,pqb->pab", vt, vt)
    eye = np.broadcast_to(np.eye(va.shape[2]), a.shape)
    ainv, ok = _batched_solve(a, np.array(eye))
    base = np.einsum("pqa,pab->pqb", vt, ainv)  # Ṽa (Ṽa'Ṽa)⁻¹
    wc = base * c[..., None]
    ws = base * s[..., None]
    top = np.concatenate([wc, ws], axis=2)  # weights on my for (aY, aZ)
    bot = np.concatenate([-ws, wc], axis=2)  # weights on mz
    return np.concatenate([top, bot], axis=1), ok


def _design_joint(va, vb, c, s, m):
    # eq. 17 design (P, 2q, 2pa+2pb), masked rows zero
    z = np.zeros_like(vb)
    cv, sv = va * c[..., None], va * s[..., None]
    top = np.concatenate([cv, sv, vb, z], axis=2)
    bot = np.concatenate([-sv, cv, z, vb], axis=2)
    x = np.concatenate([top, bot], axis=1)
    mm = np.concatenate([m, m], axis=1)
    return x * mm[..., None]


def _weights_joint(x):
    n = np.einsum("pqa,pqb->pab", x, x)
    sol, ok = _batched_solve(n, np.transpose(x, (0, 2, 1)))
    return np.transpose(sol, (0, 2, 1)), ok


#: Cholesky factors of distinct mask layouts kept between blocks (GLS).
_GLS_CACHE_SIZE = 32


def _weights_gls(x, m, r_reg, cache=None):
    import scipy.linalg as sla

    npr, q2, p = x.shape
    q = q2 // 2
    w = np.full(x.shape, np.nan)
    ok = np.zeros(npr, bool)
    cache = {} if cache is None else cache
    if "toeplitz" not in cache:
        cache["toeplitz"] = sla.toeplitz(r_reg[:q])
    full = cache["toeplitz"]
    keys = [m[i].astype(bool).tobytes() for i in range(npr)]
    groups: dict[bytes, list[int]] = {}
    for i, k in enumerate(keys):
        groups.setdefault(k, []).append(i)
    for key, members in groups.items():
        rows = np.array(members)
        idx = np.flatnonzero(np.frombuffer(key, dtype=bool))
        n_o = idx.size
        if n_o == 0:
            continue
        cf = cache.pop(key, None)  # re-inserted below: most recently used last
        if cf is None:
            cf = sla.cho_factor(full[np.ix_(idx, idx)], lower=True)
        cache[key] = cf
        while len(cache) > _GLS_CACHE_SIZE + 1:
            del cache[next(k for k in cache if k != "toeplitz")]
        # stack both data axes of every period in the group as right-hand sides
        xo = np.concatenate([x[rows][:, :q][:, idx], x[rows][:, q:][:, idx]], axis=1)
        g = len(members)
        rhs = np.transpose(xo.reshape(g, 2, n_o, p), (2, 0, 1, 3)).reshape(n_o, -1)
        sol = sla.cho_solve(cf, rhs).reshape(n_o, g, 2, p)
        ox = np.transpose(sol, (1, 2, 0, 3)).reshape(g, 2 * n_o, p)  # Ω⁻¹ X
        nmat = np.einsum("gna,gnb->gab", xo, ox)
        inv, good = _batched_solve(nmat, np.broadcast_to(np.eye(p), nmat.shape).copy())
        wo = np.einsum("gna,gab->gnb", ox, np.nan_to_num(inv))
        wg = np.zeros((g, q2, p))
        wg[:, idx] = wo[:, :n_o]
        wg[:, q + idx] = wo[:, n_o:]
        w[rows[good]] = wg[good]
        ok[rows[good]] = True
    return w, ok
