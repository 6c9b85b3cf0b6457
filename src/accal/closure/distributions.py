"""Tail probabilities of the F and χ² distributions, without importing ``scipy.stats``.

``scipy.stats`` costs ~0.6-1.8 s of start-up per process (its docstring machinery
builds every distribution), more than a closure's tests take on a small file; its
``f.sf``/``chi2.sf`` are these ``scipy.special`` functions, and its ``logsf`` for
both is ``log(sf)`` (scipy 1.17: neither distribution overrides ``_logsf``).
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = ["chi2_logsf", "chi2_sf", "excess_kurtosis", "f_logsf", "f_sf"]


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """``P(F > x)`` for ``F ~ F(dfn, dfd)`` (``scipy.special.fdtrc``)."""
    return float(special.fdtrc(dfn, dfd, x))


def chi2_sf(x: float, df: float) -> float:
    """``P(X > x)`` for ``X ~ χ²(df)`` (``scipy.special.chdtrc``)."""
    return float(special.chdtrc(df, x))


def f_logsf(x: float, dfn: float, dfd: float) -> float:
    """``log P(F > x)`` (``-inf`` when it underflows)."""
    with np.errstate(divide="ignore"):
        return float(np.log(f_sf(x, dfn, dfd)))


def chi2_logsf(x: float, df: float) -> float:
    """``log P(X > x)`` (``-inf`` when it underflows)."""
    with np.errstate(divide="ignore"):
        return float(np.log(chi2_sf(x, df)))


def excess_kurtosis(x: np.ndarray) -> float:
    """``m4 / m2² − 3`` with the biased central moments (``scipy.stats.kurtosis``'s default)."""
    d = np.asarray(x, dtype=np.float64) - np.mean(x)
    m2 = float(np.mean(d**2))
    return float(np.mean(d**4) / m2**2 - 3.0) if m2 > 0 else float("nan")
