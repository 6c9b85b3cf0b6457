"""A Wald test with a heteroskedasticity- and autocorrelation-consistent covariance.

The coloured-noise test (:func:`accal.closure.wald.wald_test`) takes the residual as
stationary: its covariance is the regressors' spectrum weighted by the residual's
PSD.  A regressor made of a few bumps that coincide with bumps of the residual (a
thruster firing moves the linear and the angular accelerations at once, through the
same filter) breaks that: the product ``z·r`` is concentrated in the bumps, and the
stationary σ of the coefficient is far too small (a coupling of y to
``ang_accl_z`` at 17σ on a `tests.indep` storm day, 2.2σ here; a z coupling to
``ang_accl_y`` at p 1e-26 on a QA thruster day, t = −2.0 here).

:func:`hac_wald` refers the same coefficients to the Newey & West (1987) covariance,
``V = (ZᵀZ)⁻¹ Ω (ZᵀZ)⁻¹`` with ``Ω = Σ_{|l|≤L} (1 − |l|/(L+1)) Σ_t u_t u_{t+l}ᵀ``,
``u_t = z_t r_t`` (Bartlett weights; ``r`` the residual of the model with the
regressors, i.e. the unrestricted Wald form, so that a real effect does not inflate
its own σ), and ``W = γᵀ V⁻¹ γ`` to χ²_q.  Lags count samples of the used set in
time order (gaps shorten them).

References
----------
W. K. Newey, K. D. West, Econometrica 55 (1987) 703-708.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from accal.closure.distributions import chi2_sf

__all__ = ["HAC_LAGS", "hac_wald"]

#: Bartlett truncation lag [samples]: beyond a firing's ±35 s through the Level-1B
#: filter several times over (a 1 Hz day).
HAC_LAGS = 300


def hac_wald(
    zt: NDArray[np.float64], residual: NDArray[np.float64], lags: int = HAC_LAGS
) -> tuple[float, float]:
    """``(W, p)``: Wald statistic of the regressors ``zt`` and its χ²_q p-value.

    Parameters
    ----------
    zt : ndarray, shape (n, q)
        Extra regressors, orthogonal to the current model's design.
    residual : ndarray, shape (n,)
        Residual of the current model (without ``zt``).
    lags : int
        Bartlett truncation ``L`` (samples).

    Returns
    -------
    (float, float)
        ``W = γᵀ V⁻¹ γ`` (module notes) and ``P(χ²_q > W)``; ``(0, 1)`` for no
        regressor or a singular covariance.
    """
    z = np.asarray(zt, dtype=np.float64)
    r = np.asarray(residual, dtype=np.float64)
    n, q = z.shape
    if q == 0 or n < 2:
        return 0.0, 1.0
    a = z.T @ z
    try:
        gamma = np.linalg.solve(a, z.T @ r)
    except np.linalg.LinAlgError:
        return 0.0, 1.0
    u = z * (r - z @ gamma)[:, None]
    lags = int(min(max(lags, 0), n - 1))
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(u, size, axis=0)  # (nf, q)
    # Γ_l[i, j] = Σ_t u_i(t) u_j(t + l), l = 0..L, by the cross-spectra
    cross = np.fft.irfft(np.conj(f)[:, :, None] * f[:, None, :], size, axis=0)[: lags + 1]
    w = 1.0 - np.arange(lags + 1) / (lags + 1.0)
    g = np.tensordot(w[1:], cross[1:], axes=1)
    omega = cross[0] + g + g.T
    try:
        a_inv = np.linalg.inv(a)
        v = a_inv @ omega @ a_inv
        stat = float(gamma @ np.linalg.solve(0.5 * (v + v.T), gamma))
    except np.linalg.LinAlgError:
        return 0.0, 1.0
    if not np.isfinite(stat) or stat < 0:
        return 0.0, 1.0
    return stat, chi2_sf(stat, q)
