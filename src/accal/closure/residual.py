"""Residual characterisation and the coloured-noise significance test.

Two jobs, both pure functions over arrays:

* :func:`characterise`: what is left in a residual (gap-tolerant Welch PSD on the
  continuous segments, per-segment means, low-frequency share, kurtosis;
  :mod:`accal.closure.residual_stats`);
* :func:`wald_test`: is a block of extra regressors significant *under the
  residual's own coloured noise*? (:mod:`accal.closure.wald`, which says why a
  sandwich Wald test and not AR prewhitening), on the PSD estimate of
  :mod:`accal.closure.noise_psd`.

This module gathers their names.
"""

from __future__ import annotations

from accal.closure.noise_psd import (
    Grid,
    NoisePSD,
    as_leverage,
    estimate_psd,
    leverage_of,
    make_grid,
    projection_bias,
    two_sided_weights,
)
from accal.closure.residual_stats import (
    ResidualStats,
    characterise,
    continuous_segments,
    welch_segments,
)
from accal.closure.wald import (
    WaldResult,
    orthonormal_complement,
    quad_form,
    sandwich_cov,
    wald_test,
    white_plus_flicker,
)

#: Former names, imported by accal.closure.final and accal.closure.significance.
_two_sided = two_sided_weights
_quad = quad_form
_as_leverage = as_leverage

__all__ = [
    "Grid",
    "NoisePSD",
    "ResidualStats",
    "WaldResult",
    "as_leverage",
    "characterise",
    "continuous_segments",
    "estimate_psd",
    "leverage_of",
    "make_grid",
    "orthonormal_complement",
    "projection_bias",
    "quad_form",
    "sandwich_cov",
    "two_sided_weights",
    "wald_test",
    "welch_segments",
    "white_plus_flicker",
]
