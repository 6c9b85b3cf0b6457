"""The other axes' signal in the null model: what the orbit template leaves of it.

Without a reference, the series closure analyses carries the non-gravitational
signal.  The orbit template (:mod:`accal.closure.nuisance`) takes its orbit-periodic
part with a slowly changing amplitude; it cannot take the density's changes over
minutes to hours (travelling atmospheric disturbances of a few per cent at 5-30 min,
a storm's onset).  On the cross-track and radial axes those changes are the
along-track drag's, scaled by the direction of the relative wind in the satellite
frame, which changes over the orbit with the attitude and the thermospheric wind:
the drag acceleration is ``a = −½ ρ (C_D A / m) |v_r| v_r`` (Doornbos 2012,
*Thermospheric Density and Wind Determination from Satellite Dynamics*, Springer,
eq. 2.12), so ``a_y = a_x · v_r,y / v_r,x`` and likewise for z.

Left in the residual, they are the "noise" a coupling, step or drift on that axis
is tested against: on a QA helper's GRACE-FO day (3 % density wiggles) a 5e-9
m/s²/K coupling to a heater-cycled temperature on z had a Wald statistic of 21-23
at its lag (not significant among the search's 124 members), 125 with the along-track
axis' unexplained signal in the model (2026-11-30).  :func:`add_proxies` adds to the
null model's template, for each other axis ``p``, the part ``r`` of it that the null
model does not explain and ``r·cos(2πt/P)``, ``r·sin(2πt/P)`` (a ratio changing once
per revolution), all orthogonal to the null model.  The null model's own coefficients
(bias, drift, template) do not move.  An instrument effect of the target cannot hide
in the proxies' columns, whose coefficients the whole day's signal pins; one that
the proxy carries too is handled by ``exclude`` and :func:`leak_cov`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from accal.closure.noise_psd import Grid
from accal.closure.nuisance import OrbitTemplate
from accal.closure.wald import sandwich_cov

__all__ = ["add_proxies", "leak_cov"]


#: A proxy enters the model only when its unexplained part is this many times the
#: target's (RMS): its coefficient is then at most ~1/PROXY_RATIO, and so is the share
#: of an instrument effect the proxy carries too (a temperature coupling common to all
#: axes) that it takes from the target.
PROXY_RATIO = 5.0


def add_proxies(
    template: OrbitTemplate,
    proxies: NDArray[np.float64],
    t: NDArray[np.float64],
    target: NDArray[np.float64],
    exclude: NDArray[np.float64] | None = None,
) -> list[int]:
    """Add the other axes' unexplained signal to ``template`` (module notes).

    Only the proxies whose unexplained part is :data:`PROXY_RATIO` times the target's
    or more: the along-track axis for the cross-track and radial ones, not the reverse.
    With the radial axis (1 % of the drag) as a proxy of the along-track one its
    coefficient would be ~100, and a temperature coupling that both axes have would
    be taken from the along-track axis a hundredfold.

    Parameters
    ----------
    template : OrbitTemplate
        The orbit template of the null model, on the used samples (changed in place).
    proxies : ndarray, shape (n, q)
        The other axes on the used samples [m/s²], finite.
    t : ndarray, shape (n,)
        Times of the used samples [s] (any origin).
    target : ndarray, shape (n,)
        The analysed series on the used samples [m/s²].
    exclude : ndarray, shape (n, m), optional
        Columns the proxies' columns are made orthogonal to: the instrument effects
        found on the target.  A proxy carries the same effect when the axes share it
        (a temperature coupling of the whole accelerometer): ``z = c_z·T + k·D`` and
        ``r = D + c_x·T`` give ``c_z − k·c_x`` for the coefficient of ``T`` with ``r`` in
        the model, and ``c_z`` with the part of ``r`` orthogonal to ``T`` (the drawn day of
        ``tests/closure/test_proxies_in_model.py``: k = 0.054, the coefficient 9 % low,
        2.7σ).

    Returns
    -------
    list of int
        The indices of the proxies used.
    """
    p = np.asarray(proxies, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    if p.shape[1] == 0:
        return []
    r = template.remainder(p)
    own = float(
        np.sqrt(np.mean(template.remainder(np.asarray(target, dtype=np.float64)[:, None]) ** 2))
    )
    used = [j for j in range(r.shape[1]) if np.sqrt(np.mean(r[:, j] ** 2)) >= PROXY_RATIO * own]
    if not used:
        return []
    r = r[:, used]
    phase = 2.0 * np.pi * np.asarray(t, dtype=np.float64) / template.period
    cols = np.column_stack([r, r * np.cos(phase)[:, None], r * np.sin(phase)[:, None]])
    if exclude is not None and np.size(exclude):
        e = template.remainder(np.nan_to_num(np.asarray(exclude, dtype=np.float64)))
        cols = cols - e @ np.linalg.lstsq(e, cols, rcond=None)[0]
    template.proxy_columns = template.add_columns(cols)
    return used


def leak_cov(
    grid: Grid, template: OrbitTemplate, w_gamma: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Covariance the proxies' signal adds to the effects' coefficients when the proxies
    are orthogonal to the effects (``exclude`` of :func:`add_proxies`).

    The part ``k·D`` of the target along the effects' columns is then not taken by the
    proxies: it is in the coefficients, ``G·k·D`` (``G`` the estimator weights
    ``w_gamma``), and not in the residual whose PSD gives their σ.  Its covariance is
    the sandwich ``G S_w Gᵀ`` (:func:`accal.closure.wald.sandwich_cov`) of the proxies'
    fitted part ``w = Q Qᵀ y`` (``Q`` the proxies' orthonormal columns), whose spectrum
    is that of ``k·D``; this is ``k² σ_x²``, the variance of the correction ``k·ĉ_x``
    that makes ``c_z − k·c_x`` into ``c_z`` (module notes of :func:`add_proxies`).
    Zeros without proxies in the template.
    """
    k = w_gamma.shape[0]
    q = getattr(template, "proxy_columns", None)
    if q is None or q.shape[1] == 0 or k == 0:
        return np.zeros((k, k))
    w = q @ (q.T @ np.asarray(y, dtype=np.float64))
    none = np.zeros((grid.n_chan, grid.size // 2 + 1))
    return sandwich_cov(grid, w, w_gamma, none)
