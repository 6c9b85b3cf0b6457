"""One simulated GRACE / GRACE-FO day of raw ACC1B data (:mod:`accal.simulate.grace`).

The simulated raw reading follows the wavelet paper's eq. (9) plus injected
instrument effects, ``a_raw = s·a_true + b + d·(t − t0) + noise + Σ effects``
(:func:`simulate_grace_day`).  The Level-1B processing low-passes all that the
instrument measured with its CRN filter, so ``a_true`` and the effects are the
band-limited ones (:func:`accal.crn.crn_smooth`: a thruster pulse or a
bias step is spread over the filter's ~35 s; orbit-scale terms pass unchanged) and the
noise is drawn through the same filter:

* ``a_true``: the non-gravitational acceleration of :mod:`accal.simulate.orbit_signal`
  (drag with once- and twice-per-revolution terms and a slow density trend, solar
  radiation pressure with eclipses and smoothed entry/exit, Earth albedo; optionally a
  geomagnetic storm and thruster pulses), on an orbit whose period is drawn per day
  in 5,550–5,700 s;
* ``b``, ``s``: the GRACE TN-02 a-priori values for the satellite and date [1]_
  (``s = 1/scale``, raw-data sign ``b = −bias_TN02·s``), GRACE-FO C/D values from
  the measured 2023 means (:data:`GRACEFO_OFFSETS`);
* ``d``: a random drift of a few 1e-14 m/s³;
* noise: :func:`accal.simulate.grace_noise.instrument_noise`;
* effects: ``--effect`` specifications (:mod:`accal.simulate.grace_effects`).

The other columns are :mod:`accal.simulate.grace_columns`; the random streams
:mod:`accal.simulate.grace_seeds`.

References
----------
.. [1] Bettadpur, S. (2009). Recommendation for a-priori bias & scale parameters for
   Level-1B ACC data (version 2), GRACE TN-02 (``shared/data/REFERENCE_VALUES.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.calibration import tn02_bias, tn02_scale
from accal.crn import crn_smooth
from accal.errors import ValidationError
from accal.estimators.trend import fit_trend
from accal.simulate.effects import EXTRA_PARAMETER_UNITS, PARAMETER_UNITS, Effect, parse_effect
from accal.simulate.grace_columns import (
    RESIDUAL_SIGMA,
    RESIDUAL_SPIKE_SIZE,
    RESIDUAL_SPIKES,
    angular_truth,
    other_columns,
)
from accal.simulate.grace_effects import coupling_channels, day_effect_truth, effects_sum
from accal.simulate.grace_noise import (
    CRN_BOXCAR,
    CRN_ORDER,
    NOISE_CORNER,
    NOISE_RISE,
    instrument_noise,
)
from accal.simulate.grace_seeds import default_seed, stream
from accal.simulate.orbit_signal import environment
from accal.timescale import gps_day_start

#: Nominal orbital period [s] (the simulated day draws its own, see ``orbit_period``
#: in the truth and :data:`accal.simulate.orbit_signal.ORBIT_PERIOD_RANGE`).
ORBIT_PERIOD = 5600.0

#: Most samples of a simulated record (about 1 GB of memory; 11.6 days at 1 s).
MAX_SAMPLES = 1_000_000

#: Raw-data offsets (m/s², eq. 9 sign) for GRACE-FO C and D, from the measured
#: 100-s means on 2023-06-01 (shared/data/SOURCES.md).
GRACEFO_OFFSETS = {"C": (-0.278e-6, -10.651e-6, -0.182e-6), "D": (0.278e-6, 10.650e-6, -0.183e-6)}


@dataclass(frozen=True)
class SimulatedDay:
    """A simulated day: times, raw accelerations and the truth.

    Attributes
    ----------
    time : ndarray, shape (n,)
        GPS seconds [s].
    raw : ndarray, shape (n, 3)
        Raw readings ``lin_accl_x/y/z`` [m/s²].
    true : ndarray, shape (n, 3)
        True non-gravitational acceleration [m/s²] (thruster pulses included), as the
        Level-1B CRN filter band-limits it (:func:`~accal.crn.crn_smooth`).
    valid : ndarray of bool, shape (n,)
        False for flagged samples.
    truth : dict
        ``bias`` [m/s²] (at ``t0``), ``drift`` [m/s³], ``scale_s`` (eq. 9 ``s``),
        ``t0`` [s], ``seed`` (the one used), ``signal_trend``: the LS bias/drift of
        ``s·a_true`` alone (the part of the true signal any trend estimator will
        also see), ``effects`` and ``effects_trend`` (the LS bias/drift of the
        injected effects), the orbit, eclipses, forces, storm and thrusters.
    aux : dict
        The other ACC1B columns: ``ang_accl_x/y/z`` [rad/s²], ``acl_x/y/z_res`` [m/s²].
    instrument : ndarray, shape (n, 3)
        The sum of the injected effects [m/s²] (``raw`` minus the same day without them),
        band-limited like ``true``.
    channel_time : ndarray, shape (m,)
        GPS seconds of the auxiliary channels [s] (empty without a coupling).
    channels : dict
        Auxiliary channels on ``channel_time`` (e.g. ``temperature`` [K]).
    """

    time: NDArray[np.float64]
    raw: NDArray[np.float64]
    true: NDArray[np.float64]
    valid: NDArray[np.bool_]
    truth: dict[str, Any]
    aux: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    instrument: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    channel_time: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    channels: dict[str, NDArray[np.float64]] = field(default_factory=dict)


def _check(satellite: str, duration: float, dt: float, n_gaps: int, seed: int | None) -> None:
    if satellite not in ("A", "B", "C", "D"):
        raise ValidationError(f"satellite must be A, B, C or D, got {satellite!r}")
    if not 0 < duration < np.inf or not 0 < dt < np.inf:
        raise ValidationError(
            f"duration and dt must be positive and finite, got duration = {duration} s, dt = {dt} s"
        )
    if not duration / dt <= MAX_SAMPLES:
        raise ValidationError(
            f"duration / dt = {duration / dt:.4g} samples; at most {MAX_SAMPLES} are simulated"
        )
    if not 0 <= n_gaps <= MAX_SAMPLES:
        raise ValidationError(f"n_gaps must be in [0, {MAX_SAMPLES}], got {n_gaps}")
    if seed is not None and seed < 0:
        raise ValidationError(f"seed must be an integer >= 0, got {seed}")


def _offsets(satellite: str, t0: float) -> tuple[NDArray, NDArray, NDArray]:
    """(s, TN-02 scale, b): eq. 9 scale and bias of the satellite on the day."""
    if satellite in ("A", "B"):
        sat = f"GRACE-{satellite}"
        scale = np.array(tn02_scale(sat))
        mjd = 51544.0 + (t0 + 43200.0) / 86400.0
        bias = -np.array(tn02_bias(sat, mjd)) / scale
    else:
        scale = np.ones(3)
        bias = np.array(GRACEFO_OFFSETS[satellite])
    return 1.0 / scale, scale, bias


def _gaps_and_flags(
    n: int, dt: float, n_gaps: int, flagged_fraction: float, rng: np.random.Generator
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(keep, valid): samples left in the file (gaps of 60–1800 s cut out) and unflagged."""
    keep = np.ones(n, dtype=bool)
    for _ in range(n_gaps):
        length = int(rng.uniform(60, 1800) / dt)
        start = int(rng.integers(1, max(2, n - length - 1)))
        keep[start : start + length] = False
    keep[0] = True  # t0 of the truth is the first sample
    valid = np.ones(n, dtype=bool)
    n_flag = int(flagged_fraction * n)
    while n_flag > 0:
        burst = int(min(n_flag, rng.integers(5, 120)))
        start = int(rng.integers(1, max(2, n - burst)))
        valid[start : start + burst] = False
        n_flag -= burst
    return keep, valid


def _trend(t: NDArray, y: NDArray, valid: NDArray) -> dict[str, list[float]]:
    """Per-axis LS bias (at t[0]) and drift of ``y`` (n, 3) over the valid samples."""
    fits = [fit_trend(t, y[:, i], method="lsq", valid=valid) for i in range(3)]
    return {"bias": [f.bias for f in fits], "drift": [f.drift for f in fits]}


def simulate_grace_day(
    *,
    date: str = "2005-01-01",
    satellite: str = "A",
    seed: int | None = None,
    duration: float = 86400.0,
    dt: float = 1.0,
    n_gaps: int = 0,
    flagged_fraction: float = 0.0,
    noise: float = 1e-10,
    storm: bool = False,
    thrusters: bool = False,
    effects: Sequence[str | Effect] = (),
    bias: Sequence[float] | None = None,
) -> SimulatedDay:
    """Simulate one day of raw ACC1B data.

    Parameters
    ----------
    date : str
        UTC day, ``YYYY-MM-DD``.
    satellite : {"A", "B", "C", "D"}
        GRACE A/B or GRACE-FO C/D.
    seed : int, optional
        Random seed (>= 0), used as given.  Default :func:`default_seed` of ``date``
        and ``satellite`` (deterministic, different for each day and satellite).
    duration : float
        Length [s]; at most :data:`MAX_SAMPLES` samples of ``dt``.
    dt : float
        Sampling interval [s].
    n_gaps : int
        Number of gaps (each 60–1800 s) cut out of the record (at most
        :data:`MAX_SAMPLES`).
    flagged_fraction : float
        Fraction of samples flagged invalid (in short bursts).
    noise : float
        Noise level in the measurement band [m/s²/√Hz] (0: no noise).
    storm : bool
        Add a geomagnetic storm (:func:`accal.simulate.orbit_signal.draw_storm`).
    thrusters : bool
        Add thruster pulses to the true signal (:func:`~accal.simulate.orbit_signal.draw_thrusters`).
    effects : sequence of str or Effect
        Instrument effects (``"step:axis=x,epoch=43200,size=3e-9"``, see
        :mod:`accal.simulate.effects`).
    bias : sequence of 3 float, optional
        Eq. 9 bias ``b`` at the first sample [m/s²] instead of the satellite's
        a-priori value (TN-02 for GRACE A/B, :data:`GRACEFO_OFFSETS`); a multi-day
        arc passes the previous day's bias continued by its drift
        (:func:`write_simulated_arc`).

    Returns
    -------
    SimulatedDay

    Raises
    ------
    ValidationError
        For a bad satellite, a non-positive or non-finite ``duration`` or ``dt``,
        more than :data:`MAX_SAMPLES` samples or gaps, a negative ``seed`` or a bad
        effect specification.
    """
    _check(satellite, duration, dt, n_gaps, seed)
    seed = default_seed(date, satellite) if seed is None else int(seed)
    n = int(round(duration / dt))
    span = n * dt
    parsed = [e if isinstance(e, Effect) else parse_effect(e, duration=span) for e in effects]
    drift = stream(seed, "instrument").uniform(-5e-14, 5e-14, 3)
    t0 = gps_day_start(date)
    tau = dt * np.arange(n)
    t = t0 + tau
    env = environment(
        tau,
        t0=t0,
        satellite=satellite,
        orbit_rng=stream(seed, "orbit"),
        storm_rng=stream(seed, "storm") if storm else None,
        thruster_rng=stream(seed, "thrusters") if thrusters else None,
        dt=dt,
        duration=span,
    )
    s, scale, prior_bias = _offsets(satellite, t0)
    bias = prior_bias if bias is None else np.asarray(bias, dtype=np.float64).reshape(3)
    tc, channels, channel_params = coupling_channels(
        parsed, t0, n, dt, seed, env.truth["orbit_period"]
    )
    instrument = effects_sum(
        parsed, tau, span, s * env.linear, {k: (tc, v) for k, v in channels.items()}, t0
    )
    # the Level-1B filter acts on all that was measured (the noise is drawn with it): the
    # true acceleration as the file band-limits it, and the effects
    true = crn_smooth(env.linear, dt)
    instrument = crn_smooth(instrument, dt)
    raw = (
        s * true
        + bias
        + np.outer(tau, drift)
        + instrument_noise(n, dt, noise, stream(seed, "noise"))
    )
    if parsed:
        raw = raw + instrument
    aux = other_columns(satellite, env.angular, seed, dt)
    keep, valid = _gaps_and_flags(n, dt, n_gaps, flagged_fraction, stream(seed, "gaps"))
    t, raw, true, valid, instrument = t[keep], raw[keep], true[keep], valid[keep], instrument[keep]
    aux = {k: v[keep] for k, v in aux.items()}
    truth = {
        "satellite": satellite,
        "date": date,
        "seed": seed,
        "t0": float(t[0]),
        "bias": bias.tolist(),
        "drift": drift.tolist(),
        "scale_s": s.tolist(),
        "scale_tn02": scale.tolist(),
        "noise_asd": noise,
        "signal_trend": _trend(t, s * true, valid),
        "n_samples": int(t.size),
        "n_flagged": int((~valid).sum()),
        # gaps in the file: cut-outs that overlap or touch merge into one (QA: 3 asked,
        # 2 in the file, and the truth said 3)
        "n_gaps": int(np.count_nonzero(np.diff(keep.astype(np.int8)) == -1)),
        "n_gaps_requested": n_gaps,
        **env.truth,
        **_model_truth(satellite),
        "effects": [day_effect_truth(e, t0, s, span) for e in parsed],
        "channels": channel_params,
    }
    if parsed:
        truth["effects_trend"] = _trend(t, instrument, valid)
    if any(e.name in ("scalematrix", "splinebias") for e in parsed):
        units = {**PARAMETER_UNITS, **EXTRA_PARAMETER_UNITS}
        truth["units"] = {**truth["units"], "effects": units}
    return SimulatedDay(t, raw, true, valid, truth, aux, instrument, t0 + tc, channels)


_UNITS = {
    "bias": "m/s^2",
    "drift": "m/s^3",
    "t0": "s (GPS)",
    "orbit_period": "s",
    "eclipses": "s (GPS), centres of the entry and exit ramps",
    "penumbra_s": "s",
    "thrusters": "epoch s (GPS), epoch_s and length s, amplitude m/s^2",
    "storm": "onset s (GPS), onset_s, rise_s and decay_s s, factor 1",
    "drag": "level m/s^2",
    "srp": "level m/s^2",
    "angular": "rad/s^2",
    "effects": PARAMETER_UNITS,
}


def _model_truth(satellite: str) -> dict[str, Any]:
    """The fixed parts of the model in the truth: noise, other columns, units."""
    return {
        "noise_model": {
            "corner_hz": NOISE_CORNER,
            "rise_hz": NOISE_RISE,
            "crn_boxcar_s": CRN_BOXCAR,
            "crn_order": CRN_ORDER,
        },
        "ang_accl": angular_truth(satellite),
        "acl_res": {
            "core_sigma": list(RESIDUAL_SIGMA[satellite]),
            "spike_fraction": RESIDUAL_SPIKES[satellite],
            "spike_size": RESIDUAL_SPIKE_SIZE,
        },
        "units": _UNITS,
    }
