"""Demodulation of rotating-platform accelerometer data (Lenoir et al. 2013).

``accal demod`` calls :func:`demodulate` (data → per-period unbiased accelerations
with uncertainties) and :func:`budget` (pattern → Rd[k], σ over an integration
time, optimal modulation period).  Everything here is a pure function over
arrays returning frozen dataclasses.

Method (equation numbers of the paper)
--------------------------------------
Per modulation period of ``q = τ·fs`` samples, with the rest mask ``M``
(section 4.2: discrete θ̇ = 0 and θ̈ = 0), ``Ṽa = M Va`` and ``Va = [1]`` (signal
mean, eq. 18) or ``[1, t]`` (affine signal, eq. 19):

* ``solver="eq14"``: ``âY = (Ṽa'Ṽa)⁻¹ Ṽa'(Λc my - Λs mz)``,
  ``âZ = (Ṽa'Ṽa)⁻¹ Ṽa'(Λs my + Λc mz)`` (eq. 14 normalised as in section 5.1);
  exact when eq. 16 holds, ``Ṽa' Λ V̂b = 0``.  The normalised leakage
  ``max |ṽ' Λ b̂| / (|ṽ| |M b̂|)`` is reported per period.
* ``solver="joint"``: least squares of eq. 17 on the unmasked samples, with the
  bias basis ``V̂b = [1, t]`` (+ auxiliary channels, eq. 18's temperature) in
  the model; needs no orthogonality.  ``"auto"`` uses eq. 14 when the leakage is
  below ``leak_tol`` and there is no auxiliary channel, eq. 17 otherwise.
* ``method="gls"``: generalised least squares of eq. 17 per period (section 5.3),
  with the noise covariance of the period's unmasked samples built from the PSD
  (rotation samples are gaps; the 1/f part is handled by the structure function,
  see :mod:`accal.estimators.noise`).

Every estimator is linear, ``â = W'm``; its covariance with any other period's is
``-W_i' T_D W_j`` (eq. 21 in the time domain), which gives σ per period and
``Rd[k]`` (eq. 23).

Streaming
---------
:func:`demodulate_stream` takes the record in chunks of any size (a year of 1 Hz
data in bounded memory) and gives the same per-period results as
:func:`demodulate`, which is the one-chunk case: the incomplete last period of a
chunk is carried over, the rest mask sees the neighbouring samples across chunk
borders, the GLS covariance is per period, and the lagged products of Rd[k]
pair periods across chunk borders.  Missing samples (``valid`` False, e.g. the
gaps left by resampling) are masked like rotation samples.

Modules
-------
This package re-exports the public names of its modules (import them from here):

* :mod:`.stream`: :func:`demodulate_stream`, :func:`demodulate`,
  :func:`demodulate_table`;
* :mod:`.passes`: the two passes of :func:`demodulate_stream` over the blocks;
* :mod:`.records`: :class:`DemodChunk`, :class:`DemodResult`, :class:`NoiseReport`;
* :mod:`.checks`: input checks, sampling step, θ convention;
* :mod:`.blocks`: chunks → blocks of whole periods, rest mask, bases (eqs. 18-19);
* :mod:`.estimate`: per-block scan and estimates;
* :mod:`.weights`: estimator weights (eqs. 14, 16, 17, GLS of section 5.3);
* :mod:`.lagcov`: covariance between periods (eq. 21);
* :mod:`.layout`: rotation layout of the periods;
* :mod:`.residual`: noise from the data (issue 20);
* :mod:`.series`: :func:`sigma_mean`, :func:`fit_sinusoid` (eq. 24),
  :func:`signal_leakage`;
* :mod:`.uncertainty`: :func:`budget`, :func:`tau_scan` (section 5, Figs. 5-6).

Also importable from here, for the callers that use them: the sampling-step and
θ helpers of :mod:`.checks` (:func:`sampling_step`, :func:`regular_step`,
:func:`step_tolerance`, :func:`theta_in_range`), :data:`LAYOUT_LAGS`,
``_ResidualSpectra`` and :func:`accal.estimators.design.rest_mask`.
"""

from __future__ import annotations

from ..design import rest_mask as rest_mask
from .checks import REST_ANGLE_TOL as REST_ANGLE_TOL
from .checks import STEP_RTOL as STEP_RTOL
from .checks import regular_step as regular_step
from .checks import sampling_step as sampling_step
from .checks import step_tolerance as step_tolerance
from .checks import theta_in_range as theta_in_range
from .layout import LAYOUT_AGREE as LAYOUT_AGREE
from .layout import LAYOUT_LAGS as LAYOUT_LAGS
from .records import DemodChunk, DemodResult, NoiseReport
from .residual import MAX_PSD_LAYOUTS as MAX_PSD_LAYOUTS
from .residual import MIN_PERIODS_DATA_PSD
from .residual import _ResidualSpectra as _ResidualSpectra
from .series import (
    SignalLeakage,
    SinusoidFit,
    fit_sinusoid,
    period_leakage,
    sigma_mean,
    signal_leakage,
    with_signal_leak,
)
from .stream import REQUIRED_COLUMNS, demodulate, demodulate_stream, demodulate_table, sigma_factor
from .uncertainty import BudgetResult, budget, tau_scan

__all__ = [
    "DemodChunk",
    "DemodResult",
    "NoiseReport",
    "BudgetResult",
    "SinusoidFit",
    "demodulate",
    "demodulate_stream",
    "demodulate_table",
    "budget",
    "tau_scan",
    "sigma_mean",
    "fit_sinusoid",
    "signal_leakage",
    "period_leakage",
    "with_signal_leak",
    "sigma_factor",
    "SignalLeakage",
    "REQUIRED_COLUMNS",
    "MIN_PERIODS_DATA_PSD",
]
