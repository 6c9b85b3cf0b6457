"""The jumps of :mod:`accal.closure.jumps` in the final fit of a closure.

The jumps are taken out of the data before the search (their sizes by the
spectrum-weighted kernel); the final fit is made on what is left, and here they come
back: as columns (:func:`jump_columns`), as reported effects (:func:`jump_effects`) and
in the covariances of the final fit (:func:`add_jump_covariance`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.jumps import Jump
from accal.closure.results import Effect

__all__ = ["add_jump_covariance", "jump_columns", "jump_effects"]


def jump_columns(t_all: NDArray[np.float64], jumps: tuple[Jump, ...]) -> NDArray[np.float64]:
    """The step indicator ``1[t ≥ epoch]`` of every jump on all samples: (N, n_jumps)."""
    if not jumps:
        return np.zeros((t_all.size, 0))
    return np.column_stack([(t_all >= j.epoch).astype(np.float64) for j in jumps])


def jump_effects(jumps: tuple[Jump, ...]) -> list[Any]:
    """The jumps as :class:`accal.closure.results.Effect` (``bias_step``, an instrument
    effect, removed from the calibrated series)."""
    return [
        Effect(
            "bias_step",
            None,
            j.size,
            j.sigma,
            j.p_adj,
            epoch=j.epoch,
            details=j.details(),
            instrument=True,
            unit="m/s^2",
        )
        for j in jumps
    ]


def add_jump_covariance(
    cov: dict[str, NDArray[np.float64]],
    basis: Any,
    cols_used: NDArray[np.float64],
    jumps: tuple[Jump, ...],
) -> None:
    """Put the jumps' sizes into the final fit's covariances (in place).

    The final fit is made on ``y − Σ ŝ_j J_j``, so its base coefficients are the fit of
    ``y`` less ``Σ A_j ŝ_j`` and its effects' less ``Σ Γ_j ŝ_j`` (``A_j``, ``Γ_j``: the
    fit of the column ``J_j``, :meth:`accal.closure.basis.Basis.fit`); with the sizes
    taken as independent of that fit (they rest on the few samples around each edge,
    the fit on the whole record): ``cov_b += Σ A_j A_jᵀ σ_j²`` (and ``cov_d``),
    ``cov(b, ŝ_j) = −A_j σ_j²``, likewise for the effects.  The jumps' columns come
    first in ``cov_bg`` and ``v_ww``.
    """
    var = np.array([j.sigma**2 for j in jumps])
    nj = var.size
    if nj == 0:
        return
    nb, p = cov["cov_b"].shape[:2]
    a = np.zeros((nb, p, nj))
    g = np.zeros((cov["v_ww"].shape[0], nj))
    for j in range(nj):  # one jump at a time: Basis.fit takes one series
        fj = basis.fit(cols_used[:, j])
        a[:, :, j] = np.nan_to_num(fj.beta.reshape(-1, p)[:nb])
        if g.shape[0]:
            g[:, j] = np.nan_to_num(fj.gamma[basis.keep])
    add_b = np.einsum("spj,sqj,j->spq", a, a, var)
    cov["cov_b"] = cov["cov_b"] + add_b
    cov["cov_d"] = cov["cov_d"] + add_b
    cross_j = -a * var[None, None, :]  # (nb, p, nj)
    cov_bg = cov["cov_bg"]
    if g.shape[0]:
        cov_bg = cov_bg - np.einsum("spj,kj,j->spk", a, g, var)
    cov["cov_bg"] = np.concatenate([cross_j, cov_bg], axis=2)
    v = cov["v_ww"] + (g * var) @ g.T if g.shape[0] else cov["v_ww"]
    out = np.zeros((nj + v.shape[0], nj + v.shape[0]))
    out[:nj, :nj] = np.diag(var)
    out[nj:, nj:] = v
    if g.shape[0]:
        out[nj:, :nj] = -g * var
        out[:nj, nj:] = (-g * var).T
    cov["v_ww"] = out
