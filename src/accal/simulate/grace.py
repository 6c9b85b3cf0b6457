"""Synthetic GRACE / GRACE-FO ACC1B days that look like the real Level-1B files.

The simulated raw reading follows the wavelet paper's eq. (9) plus injected
instrument effects, ``a_raw = s·a_true + b + d·(t − t0) + noise + Σ effects``:

* ``a_true``: the non-gravitational acceleration of :mod:`accal.simulate.orbit_signal`
  (drag with once- and twice-per-revolution terms and a slow density trend, solar
  radiation pressure with eclipses and smoothed entry/exit, Earth albedo; optionally a
  geomagnetic storm and thruster pulses), on an orbit whose period is drawn per day
  in 5,550–5,700 s;
* ``b``, ``s``: the GRACE TN-02 a-priori values for the satellite and date
  (``s = 1/scale``, raw-data sign ``b = −bias_TN02·s``), GRACE-FO C/D values from
  the measured 2023 means (:data:`GRACEFO_OFFSETS`);
* ``d``: a random drift of a few 1e-14 m/s³;
* noise: one-sided ASD ``noise·sqrt(1 + f_c/f)·sqrt(1 + (f/f_r)⁴)`` (white in the
  measurement band, a 1/f rise below ``f_c`` = 1 mHz, a rise above ``f_r`` =
  20 mHz), through a CRN-like low-pass (:data:`CRN_BOXCAR`, :data:`CRN_ORDER`), a
  stand-in for the CRN filter the Level-1B processing applies to the 10 Hz data before
  decimating to 1 Hz [2]_ (its parameters here are fitted to the samples' first and
  second differences, not taken from the processing);
* effects: ``--effect`` specifications (:mod:`accal.simulate.effects`).

The other nine ACC1B columns are filled as in the real files: ``ang_accl_x/y/z`` are
the offset of the sample files plus an orbit-periodic signal of ~2e-7 rad/s² plus
white noise and a 60 s Gauss-Markov wander at the samples' levels (GRACE A/B,
:data:`ANGULAR_NOISE`, :data:`ANGULAR_WANDER`); GRACE-FO C/D are written as ACT1B,
whose angular columns are 0 in the real files, and keep that.  ``acl_x/y/z_res`` are
Gaussian with the samples' robust spread plus rarer spikes (heavy tails, as in the samples).

Magnitudes measured on the real samples (``data/samples``, 60 s of 2003-09-14 and
100 s of 2023-06-01; ``σ_d`` = std of first differences / √2, robust σ = 1.4826·MAD)
and used here:

=====  ================================  ===========================  ===============================
sat    ang_accl mean [rad/s²]            ang_accl σ_d [rad/s²]        acl_res robust σ [m/s²]
=====  ================================  ===========================  ===============================
A      3.3220e-4, −3.9353e-5, −2.9153e-4  7.87e-7, 2.40e-7, 6.42e-8    2.45e-9, 3.68e-9, 7.26e-9
B      −4.1715e-4, −7.4392e-6, −5.8413e-4 1.11e-7, 2.89e-8, 3.53e-8    3.42e-9, 2.72e-9, 1.64e-8
C, D   0 (ACT1B)                          0                           C 1.43e-9, 1.25e-9, 1.63e-9;
                                                                      D 7.11e-10, 3.19e-10, 6.82e-10
=====  ================================  ===========================  ===============================

The lin_accl first differences of the samples (std, 60–100 s) are 2e-11 – 5e-10
m/s² (median 3e-11), the second differences / √6 2e-13 – 4e-11 (median 2.5e-12):
the noise's rise ``f_r`` and the CRN-like filter are chosen to give 2.7e-11 and
5e-12 at the default ``noise`` of 1e-10 m/s²/√Hz (``tests/test_simulate_realism.py``).

Random draws come from one seed, split into independent streams (:data:`STREAMS`):
the instrument drift, the orbit and forces, the noise, the angular and residual
columns, the gaps and flags, the storm, the thrusters, the reference noise, the
THR1B counters and each auxiliary channel have their own, so that adding a storm,
thrusters, a reference or an effect changes nothing else of the day.  Without an
explicit seed it is :func:`default_seed` of the date and satellite, so different
days and satellites differ while every run of the same day gives the same file; an
explicit seed is used as given.

Besides the ACC1B file (:func:`write_simulated_grace`): a reference table
(``s·a_true`` plus a POD-like reference noise, :func:`reference_noise`) for
``accal grace-bias --reference``, with the scale matrix to expect in the truth; a
THR1B file of the thruster pulses (:func:`accal.simulate.thr1b.write_simulated_thr1b`); and arcs of
consecutive days with a continuous bias and one reference table
(:func:`write_simulated_arc`).

References
----------
.. [1] Bettadpur, S. (2009). Recommendation for a-priori bias & scale parameters for
   Level-1B ACC data (version 2), GRACE TN-02 (``shared/data/REFERENCE_VALUES.md``).
.. [2] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product User
   Handbook, JPL D-22027 (ACC1B columns; the CRN filter of the Level-1B processing).
.. [3] Bezděk, A. (2010). Calibration of accelerometers aboard GRACE satellites by
   comparison with POD-based nongravitational accelerations. J. Geodyn. 50(5),
   410–423.
.. [4] Calabia, A., Jin, S. (2015). GPS-based non-gravitational accelerations and
   accelerometer calibration. In: Satellite Positioning (ed. S. Jin), InTech,
   doi:10.5772/59975.
.. [5] van den IJssel, J., Visser, P. (2007). Performance of GPS-based accelerometry:
   CHAMP and GRACE. Adv. Space Res. 39(10), 1597–1603.
.. [6] Ren, L., Schön, S. (2018). PPP-based Swarm kinematic orbit determination.
   Ann. Geophys. 36, 1227, doi:10.5194/angeo-36-1227-2018.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import ValidationError
from accal.simulate.effects import (
    CHANNEL_PREROLL,
    EXTRA_PARAMETER_UNITS,
    PARAMETER_UNITS,
    VECTOR_EFFECTS,
    Effect,
    channel_seed,
    effect_term,
    effect_truth,
    first_order_recursion,
    parse_effect,
    reference_scale,
    temperature_channel,
    vector_term,
)
from accal.simulate.thr1b import thruster_path, write_simulated_thr1b

#: Nominal orbital period [s] (the simulated day draws its own, see ``orbit_period``
#: in the truth and :data:`accal.simulate.orbit_signal.ORBIT_PERIOD_RANGE`).
ORBIT_PERIOD = 5600.0

#: Most samples of a simulated record (about 1 GB of memory; 11.6 days at 1 s).
MAX_SAMPLES = 1_000_000

#: Raw-data offsets (m/s², eq. 9 sign) for GRACE-FO C and D, from the measured
#: 100-s means on 2023-06-01 (shared/data/SOURCES.md).
GRACEFO_OFFSETS = {"C": (-0.278e-6, -10.651e-6, -0.182e-6), "D": (0.278e-6, 10.650e-6, -0.183e-6)}

#: ang_accl offsets [rad/s²]: the means of the real 2003-09-14 ACC1B samples.
ANGULAR_OFFSETS = {
    "A": (3.3220e-4, -3.9353e-5, -2.9153e-4),
    "B": (-4.1715e-4, -7.4392e-6, -5.8413e-4),
}

#: ang_accl white noise σ [rad/s²]: std of first differences / √2 of the samples.
ANGULAR_NOISE = {"A": (7.87e-7, 2.40e-7, 6.42e-8), "B": (1.11e-7, 2.89e-8, 3.53e-8)}

#: ang_accl slow wander [rad/s²]: a first-order Gauss-Markov process of correlation
#: time :data:`ANGULAR_WANDER_TAU`.  σ from the samples: the spread of the values
#: beyond the white noise, ``sqrt(σ_robust² − σ_d²)``, is the within-60-s spread of
#: the process, 0.51 σ for a 60 s correlation time.
ANGULAR_WANDER = {"A": (1.0e-6, 2.8e-7, 1.7e-7), "B": (6.1e-7, 2.5e-7, 5.2e-8)}
ANGULAR_WANDER_TAU = 60.0

#: acl_*_res robust σ (1.4826·MAD) [m/s²] of the real samples: the Gaussian core.
RESIDUAL_SIGMA = {
    "A": (2.45e-9, 3.68e-9, 7.26e-9),
    "B": (3.42e-9, 2.72e-9, 1.64e-8),
    "C": (1.43e-9, 1.25e-9, 1.63e-9),
    "D": (7.11e-10, 3.19e-10, 6.82e-10),
}
#: acl_*_res spikes: the fraction of samples that get an extra Gaussian draw of
#: ``RESIDUAL_SPIKE_SIZE`` × the core σ.  In the samples the std of first differences
#: is 4.5–19 times the robust σ for GRACE A/B and 3–6 times for C/D (1.4 for Gaussian
#: noise); with spikes the ratio is ``sqrt(2(1 + p·size²))``: p from the median ratio
#: of each satellite's three axes (A 7.8, B 10, C 3.3, D 6).
RESIDUAL_SPIKES = {"A": 0.07, "B": 0.12, "C": 0.011, "D": 0.043}
RESIDUAL_SPIKE_SIZE = 20.0

#: Noise shape: 1/f corner [Hz], f⁴ rise of the PSD above [Hz].
NOISE_CORNER, NOISE_RISE = 1e-3, 0.02

#: CRN-like low-pass of the noise: ``CRN_ORDER`` cascaded boxcars of ``CRN_BOXCAR``
#: seconds (−3 dB at 35 mHz, first zero at 0.2 Hz).
CRN_BOXCAR, CRN_ORDER = 5.0, 7

#: Random streams of a day: ``numpy.random.default_rng([seed, STREAMS[name]])``.
STREAMS = {
    "instrument": 0,
    "orbit": 1,
    "noise": 2,
    "angular": 3,
    "residual": 4,
    "gaps": 5,
    "storm": 6,
    "thrusters": 7,
    "reference": 8,
    "thr1b": 9,
}

#: Reference noise (``--reference-noise``): default level [m/s²], the RMS of the
#: noise at orbit scales, i.e. below :data:`REFERENCE_BAND` [Hz].
REFERENCE_NOISE, REFERENCE_BAND = 1e-9, 1e-3
#: Reference noise shape: the f⁴ rise of the PSD equals the white floor at
#: :data:`REFERENCE_CORNER` [Hz] and is band-limited (levels off) above
#: :data:`REFERENCE_LIMIT` [Hz] (:func:`reference_noise_psd`).
REFERENCE_CORNER, REFERENCE_LIMIT = 0.2, 0.5


def default_seed(date: str, satellite: str) -> int:
    """The seed of a simulated day when none is given: a hash of date and satellite.

    Parameters
    ----------
    date : str
        UTC day, ``YYYY-MM-DD``.
    satellite : str
        ``"A"``, ``"B"``, ``"C"`` or ``"D"``.

    Returns
    -------
    int
        The first 8 bytes (little-endian) of SHA-256 of ``"accal.simulate.grace:"``
        + date + ``":"`` + satellite: the same on every machine and Python version
        (unlike :func:`hash`), different for every (date, satellite).
    """
    digest = hashlib.sha256(f"accal.simulate.grace:{date}:{satellite}".encode()).digest()
    return int.from_bytes(digest[:8], "little")


def stream(seed: int, name: str) -> np.random.Generator:
    """The random generator of one part of a simulated day (:data:`STREAMS`)."""
    return np.random.default_rng([seed, STREAMS[name]])


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
        True non-gravitational acceleration [m/s²] (thruster pulses included).
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
        The sum of the injected effects [m/s²] (``raw`` minus the same day without them).
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


def coloured_noise(
    n: int, dt: float, level: float, corner: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Gaussian noise with one-sided ASD ``level·sqrt(1 + corner/f)`` [m/s²/√Hz].

    A thin wrapper of :func:`accal.simulate.noise.coloured_noise` (two-sided PSD
    ``level²(1 + corner/|f|)/2``, white samples drawn in time, no padding), kept for
    the tests and benchmarks that draw GRACE-like noise of their own; the simulated
    day uses :func:`instrument_noise`.

    Parameters
    ----------
    n : int
        Samples.
    dt : float
        Sampling interval [s].
    level : float
        White level of the one-sided ASD [m s⁻² Hz⁻¹ᐟ²].
    corner : float
        Corner frequency of the 1/f rise [Hz].
    rng : numpy.random.Generator
        Random source.

    Returns
    -------
    ndarray, shape (n,)
        Noise [m s⁻²].
    """
    from accal.simulate.noise import coloured_noise as shaped

    if level == 0:  # noise-free (simulate --noise 0): no 0 x inf at f = 0
        return np.zeros(n)

    def psd(f):
        with np.errstate(divide="ignore"):
            return 0.5 * level**2 * (1.0 + corner / np.abs(f))

    return shaped(n, psd, 1.0 / dt, rng, pad=False, white="time")[0]


def crn_lowpass(x: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
    """CRN-like low-pass along the last axis: :data:`CRN_ORDER` boxcars of :data:`CRN_BOXCAR` s.

    Returns the fully overlapped part (``CRN_ORDER·(L − 1)`` samples shorter, ``L``
    the boxcar length in samples); with ``L < 2`` (``dt`` > 3.3 s) ``x`` unchanged.
    """
    length = int(round(CRN_BOXCAR / dt))
    if length < 2:
        return x
    kernel = np.ones(length) / length
    for _ in range(CRN_ORDER):
        x = np.apply_along_axis(np.convolve, -1, x, kernel, mode="valid")
    return x


def instrument_noise(n: int, dt: float, level: float, rng: np.random.Generator) -> NDArray:
    """Accelerometer noise of the three axes [m/s²], shape (n, 3).

    One-sided ASD ``level·sqrt(1 + NOISE_CORNER/f)·sqrt(1 + (f/NOISE_RISE)⁴)`` drawn
    by FFT shaping, then :func:`crn_lowpass`: in the measurement band (0.1–20 mHz)
    the ASD is ``level``; at 1 Hz sampling the first differences have a std of
    ~0.27·``level``·√Hz and the samples ~0.75·``level``·√Hz.
    """
    from accal.simulate.noise import coloured_noise as shaped

    if level == 0:
        return np.zeros((n, 3))
    length = int(round(CRN_BOXCAR / dt))
    pad = CRN_ORDER * (length - 1) if length >= 2 else 0

    def psd(f):
        f = np.abs(f)
        with np.errstate(divide="ignore"):
            return 0.5 * level**2 * (1.0 + NOISE_CORNER / f) * (1.0 + (f / NOISE_RISE) ** 4)

    x = shaped(n + pad, psd, 1.0 / dt, rng, size=3, pad=False, white="time")
    return crn_lowpass(x, dt).T.copy()


def reference_noise_psd(f: NDArray[np.float64], level: float) -> NDArray[np.float64]:
    """One-sided PSD of the reference noise [m² s⁻⁴ Hz⁻¹] at frequencies ``f`` [Hz].

    ``W²·(1 + (f/f_c)⁴ / (1 + (f/f_l)⁴))`` with ``W² = level²/REFERENCE_BAND``,
    ``f_c`` = :data:`REFERENCE_CORNER`, ``f_l`` = :data:`REFERENCE_LIMIT`: a white floor
    ``W`` plus the f⁴ rise of a twice-differentiated white position noise, levelling
    off above ``f_l``.  ``level`` is the RMS below ``REFERENCE_BAND`` (the rise adds
    1e-10 relative there).  See :func:`reference_noise`.
    """
    f = np.abs(np.asarray(f, dtype=np.float64))
    rise = (f / REFERENCE_CORNER) ** 4 / (1.0 + (f / REFERENCE_LIMIT) ** 4)
    return level**2 / REFERENCE_BAND * (1.0 + rise)


def reference_noise(n: int, dt: float, level: float, rng: np.random.Generator) -> NDArray:
    """Noise of a POD-derived reference acceleration [m/s²], shape (n, 3).

    A reference derived from precise orbit determination (POD) is the second time
    derivative of the GPS orbit minus modelled gravitational accelerations
    (Bezděk 2010; Calabia & Jin 2015; see the module's References): differentiating
    twice multiplies the position noise's PSD by ``(2πf)⁴``, so the reference is good
    over long periods and poor at high frequency; GPS-based accelerometry recovers
    "predominantly the longer wavelengths" (van den IJssel & Visser 2007).  Kinematic positions
    carry 1.5–2.5 cm of noise per axis (Swarm: Ren & Schön 2018): differentiated as
    they are (2 cm every 10 s) they would give an ASD of 1.1e-7 m/s²/√Hz at the orbit
    frequency and 3.5e-6 at 1 mHz, which is why calibrations use smoothed,
    reduced-dynamic or long-averaged POD accelerations.  The model here stands for
    such a smoothed reference; its numbers are a choice (no published spectrum of a
    POD-derived acceleration was at hand), set so that the errors are ~1e-9 m/s² at
    orbit scales (1 % of a 1e-7 drag signal) and rise over 0.1–0.5 Hz:

    * one-sided PSD :func:`reference_noise_psd`, ``W²·(1 + (f/f_c)⁴/(1 + (f/f_l)⁴))``,
      ``W = level/sqrt(1 mHz)``, ``f_c`` = 0.2 Hz, ``f_l`` = 0.5 Hz;
    * at the default ``level`` of 1e-9 m/s² (the RMS below 1 mHz, periods over
      1000 s): ASD 3.2e-8 m/s²/√Hz up to 0.1 Hz, 4.4e-8 at 0.2 Hz, 1.4e-7 at 0.5 Hz,
      2.0e-7 above; the 1 Hz samples have an RMS of 5.6e-8 m/s² (4.2e-7 at 10 Hz);
    * drawn by FFT shaping of white samples (:func:`accal.simulate.noise.coloured_noise`,
      padded to twice the length so that the ends are independent), the three axes
      independent; the record mean is not removed exactly (padding).

    Parameters
    ----------
    n : int
        Samples.
    dt : float
        Sampling interval [s].
    level : float
        RMS at orbit scales [m/s²] (0: no noise).
    rng : numpy.random.Generator
        Random source (the day's ``"reference"`` stream).

    Returns
    -------
    ndarray, shape (n, 3)
        [m/s²].
    """
    from accal.simulate.noise import coloured_noise as shaped

    if level == 0:
        return np.zeros((n, 3))
    x = shaped(
        n, lambda f: 0.5 * reference_noise_psd(f, level), 1.0 / dt, rng, size=3, white="time"
    )
    return x.T.copy()


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
    from accal.calibration import tn02_bias, tn02_scale

    if satellite in ("A", "B"):
        sat = f"GRACE-{satellite}"
        scale = np.array(tn02_scale(sat))
        mjd = 51544.0 + (t0 + 43200.0) / 86400.0
        bias = -np.array(tn02_bias(sat, mjd)) / scale
    else:
        scale = np.ones(3)
        bias = np.array(GRACEFO_OFFSETS[satellite])
    return 1.0 / scale, scale, bias


def _other_columns(satellite: str, angular: NDArray, seed: int, dt: float) -> dict[str, NDArray]:
    """ang_accl_x/y/z and acl_x/y/z_res of the ACC1B file (module docstring)."""
    n = angular.shape[0]
    if satellite in ANGULAR_OFFSETS:
        rng = stream(seed, "angular")
        white = np.array(ANGULAR_NOISE[satellite]) * rng.standard_normal((n, 3))
        # Gauss-Markov wander, stationary from the first sample
        a = float(np.exp(-dt / ANGULAR_WANDER_TAU))
        g = rng.standard_normal((n, 3)) * np.sqrt(1.0 - a * a)
        g[0] = rng.standard_normal(3)
        wander = np.column_stack([first_order_recursion(g[:, i], a) for i in range(3)])
        ang = np.array(ANGULAR_OFFSETS[satellite]) + angular + white
        ang = ang + np.array(ANGULAR_WANDER[satellite]) * wander
    else:  # GRACE-FO ACT1B: the angular columns are 0 in the real files
        ang = np.zeros((n, 3))
    rng = stream(seed, "residual")
    core = np.array(RESIDUAL_SIGMA[satellite])
    res = core * rng.standard_normal((n, 3))
    spikes = rng.random((n, 3)) < RESIDUAL_SPIKES[satellite]
    res += np.where(spikes, RESIDUAL_SPIKE_SIZE * core * rng.standard_normal((n, 3)), 0.0)
    out = {f"ang_accl_{a}": ang[:, i] for i, a in enumerate("xyz")}
    out.update({f"acl_{a}_res": res[:, i] for i, a in enumerate("xyz")})
    return out


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


def _channels(
    effects: Sequence[Effect], t0: float, n: int, dt: float, seed: int, orbit_period: float
) -> tuple[NDArray, dict[str, NDArray], dict[str, dict]]:
    """The auxiliary channels the couplings need, from CHANNEL_PREROLL before t0 to the end."""
    names = sorted({e.params["channel"] for e in effects if e.name == "coupling"})
    if not names:
        return np.zeros(0), {}, {}
    pre = int(np.ceil(CHANNEL_PREROLL / dt))
    tc = dt * np.arange(-pre, n)  # elapsed time since t0
    values, params = {}, {}
    for name in names:
        rng = np.random.default_rng(channel_seed(seed, name))
        values[name], params[name] = temperature_channel(tc, orbit_period, rng)
        params[name]["unit"] = "K"
    return tc, values, params


def _trend(t: NDArray, y: NDArray, valid: NDArray) -> dict[str, list[float]]:
    """Per-axis LS bias (at t[0]) and drift of ``y`` (n, 3) over the valid samples."""
    from accal.estimators.trend import fit_trend

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
    from accal.simulate.orbit_signal import environment
    from accal.timescale import gps_day_start

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
    true = env.linear
    s, scale, prior_bias = _offsets(satellite, t0)
    bias = prior_bias if bias is None else np.asarray(bias, dtype=np.float64).reshape(3)
    tc, channels, channel_params = _channels(parsed, t0, n, dt, seed, env.truth["orbit_period"])
    instrument = _effects(
        parsed, tau, span, s * true, {k: (tc, v) for k, v in channels.items()}, t0
    )
    raw = (
        s * true
        + bias
        + np.outer(tau, drift)
        + instrument_noise(n, dt, noise, stream(seed, "noise"))
    )
    if parsed:
        raw = raw + instrument
    aux = _other_columns(satellite, env.angular, seed, dt)
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
        "effects": [_effect_truth(e, t0, s, span) for e in parsed],
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


def _effects(
    effects: Sequence[Effect],
    tau: NDArray,
    span: float,
    scaled_true: NDArray,
    channels: dict[str, tuple[NDArray, NDArray]],
    t0: float,
) -> NDArray[np.float64]:
    """The sum of the effects' terms per axis [m/s²], shape (n, 3)."""
    out = np.zeros((tau.size, 3))
    for e in effects:
        if e.name in VECTOR_EFFECTS:
            out += vector_term(e, scaled_true)
            continue
        i = e.index
        out[:, i] += effect_term(
            e, tau, duration=span, scaled_true=scaled_true[:, i], channels=channels, t0=t0
        )
    return out


def _effect_truth(e: Effect, t0: float, s: NDArray, span: float) -> dict[str, Any]:
    if e.name in VECTOR_EFFECTS:
        return effect_truth(e, t0, 1.0)
    return effect_truth(e, t0, float(s[e.index]), duration=span)


def _model_truth(satellite: str) -> dict[str, Any]:
    """The fixed parts of the model in the truth: noise, other columns, units."""
    return {
        "noise_model": {
            "corner_hz": NOISE_CORNER,
            "rise_hz": NOISE_RISE,
            "crn_boxcar_s": CRN_BOXCAR,
            "crn_order": CRN_ORDER,
        },
        "ang_accl": _angular_truth(satellite),
        "acl_res": {
            "core_sigma": list(RESIDUAL_SIGMA[satellite]),
            "spike_fraction": RESIDUAL_SPIKES[satellite],
            "spike_size": RESIDUAL_SPIKE_SIZE,
        },
        "units": _UNITS,
    }


def _angular_truth(satellite: str) -> dict[str, Any]:
    if satellite in ANGULAR_OFFSETS:
        return {
            "offset": list(ANGULAR_OFFSETS[satellite]),
            "noise_sigma": list(ANGULAR_NOISE[satellite]),
            "wander_sigma": list(ANGULAR_WANDER[satellite]),
            "wander_tau_s": ANGULAR_WANDER_TAU,
            "signal": "truth['angular']: once and twice per revolution",
        }
    zero = [0.0] * 3
    return {
        "offset": zero,
        "noise_sigma": zero,
        "wander_sigma": zero,
        "signal": "none: ACT1B writes 0",
    }


def aux_path(out: str | Path) -> Path:
    """The auxiliary-channel table written beside a simulated file: ``<out>.aux.parquet``."""
    out = Path(out)
    return out.with_name(out.name + ".aux.parquet")


def _reference(
    day: SimulatedDay, level: float, dt: float, n: int, effects: Sequence[Effect]
) -> tuple[NDArray, dict[str, Any]]:
    """``s·a_true`` plus reference noise on the day's epochs, and its truth entry."""
    seed = int(day.truth["seed"])
    idx = np.rint((day.time - day.truth["t0"]) / dt).astype(np.int64)
    noise = reference_noise(n, dt, level, stream(seed, "reference"))[idx]
    ref = np.asarray(day.truth["scale_s"]) * day.true
    if level > 0:  # 0: exactly s·a_true (no −0.0 + 0.0 turned into +0.0)
        ref = ref + noise
    info = {
        "content": "s*a_true (nominal scale_s, thrusters included) + reference noise [m/s^2]",
        "scale": reference_scale(list(effects)).tolist(),
        "scale_meaning": "S of a_ref = S (a_raw - b(t) - other effects - instrument noise) + "
        "reference noise; row i = scale_x, scale_y, scale_z of the grace-bias row of axis i "
        "(identity without scale effects)",
        "noise": {
            "level": level,
            "level_meaning": "RMS of the noise below band_hz [m/s^2]",
            "band_hz": REFERENCE_BAND,
            "floor_asd": level / np.sqrt(REFERENCE_BAND),
            "corner_hz": REFERENCE_CORNER,
            "limit_hz": REFERENCE_LIMIT,
            "psd": "one-sided floor_asd^2 (1 + (f/corner_hz)^4 / (1 + (f/limit_hz)^4)) "
            "[m^2/s^4/Hz], axes independent",
            "stream": "reference",
            "rms": np.sqrt(np.mean(noise**2, axis=0)).tolist(),
        },
    }
    return ref, info


def _write_reference(path: str | Path, time: NDArray, ref: NDArray, meta: dict[str, Any]) -> None:
    from accal.io.writers import write_table

    write_table(
        {"gps_time": time, **{f"lin_accl_{a}": ref[:, i] for i, a in enumerate("xyz")}},
        path,
        units={"gps_time": "s", **{f"lin_accl_{a}": "m/s^2" for a in "xyz"}},
        meta=meta,
    )


def _parsed(kwargs: dict[str, Any]) -> list[Effect]:
    """The effects of a simulation's keyword arguments, parsed as simulate_grace_day does."""
    span = int(round(kwargs.get("duration", 86400.0) / kwargs.get("dt", 1.0))) * kwargs.get(
        "dt", 1.0
    )
    effects = kwargs.get("effects", ())
    return [e if isinstance(e, Effect) else parse_effect(e, duration=span) for e in effects]


def _write_day(out: Path, day: SimulatedDay, thrusters: bool) -> Path:
    """Write a simulated day's side files, then its ACC1B file and truth; the truth path."""
    from accal.io.grace_l1b import DEFAULT_INVALID_BITS, write_grace_acc1b
    from accal.io.writers import atomic_path, write_table
    from accal.series import AccSeries

    sat = day.truth["satellite"]
    # flagged samples get the lowest bit that the reader treats as invalid (bit 0: Vp)
    flag = DEFAULT_INVALID_BITS & -DEFAULT_INVALID_BITS
    quality = np.where(day.valid, 0, flag).astype(np.uint32)
    series = AccSeries(
        time=day.time,
        acc=day.raw,
        valid=day.valid,
        quality=quality,
        aux=day.aux,
        satellite=f"GRACE-{sat}" if sat in "AB" else f"GRACE-FO-{sat}",
    )
    source = {"source": f"accal simulate grace ({out.name})", "seed": day.truth["seed"]}
    if day.channels:
        units = {"gps_time": "s", **{k: "K" for k in day.channels}}
        write_table(
            {"gps_time": day.channel_time, **day.channels},
            aux_path(out),
            fmt="parquet",
            units=units,
            meta={**source, "channels": day.truth["channels"]},
        )
    if thrusters:
        write_simulated_thr1b(
            thruster_path(out, sat),
            day.truth["thrusters"],
            sat,
            day.truth["t0"],
            stream(int(day.truth["seed"]), "thr1b"),
        )
    # the data file and its truth last: a side file that cannot be written leaves no day
    write_grace_acc1b(series, out, flavour="grace" if sat in "AB" else "gracefo")
    truth_path = out.with_name(out.name + ".truth.json")
    with atomic_path(truth_path) as tmp:
        tmp.write_text(json.dumps(day.truth, indent=2) + "\n")
    return truth_path


def write_simulated_grace(
    out: str | Path,
    *,
    reference_out: str | Path | None = None,
    reference_noise: float = REFERENCE_NOISE,
    **kwargs: Any,
) -> Path:
    """Simulate a day and write it as an ACC1B file plus ``<out>.truth.json``.

    Keyword arguments go to :func:`simulate_grace_day`.  GRACE A/B days are
    written in the GRACE RL02 ASCII layout, C/D in the GRACE-FO RL04 YAML layout,
    with all 12 columns.  A day with couplings also gets its channels in
    ``<out>.aux.parquet`` (:func:`aux_path`; columns ``gps_time`` [s] and one per
    channel, units in the Parquet metadata, readable by ``accal grace-bias --aux``).
    A day with ``thrusters=True`` also gets its pulses as a THR1B file
    (:func:`thruster_path`, :func:`accal.simulate.thr1b.write_simulated_thr1b`), which ``accal
    grace-bias`` finds beside the data and uses to leave the firings out.

    Parameters
    ----------
    out : str or Path
        The ACC1B file.
    reference_out : str or Path, optional
        Also write the reference acceleration: the true non-gravitational
        acceleration ``s·a_true`` (nominal scale, thrusters included, the scale
        errors of ``scale``/``scalematrix`` effects not) plus the reference noise
        of :func:`reference_noise`, at the data epochs, as a table (``gps_time``,
        ``lin_accl_x/y/z``; CSV for a ``.csv`` name, else Parquet) readable by
        ``accal grace-bias --reference``.  The truth gets ``reference``: ``scale``
        (the 3×3 ``S`` of ``a_ref = S·(a_raw − b(t))`` to compare with the fit,
        :func:`accal.simulate.effects.reference_scale`) and ``noise`` (model,
        level and the drawn RMS per axis).
    reference_noise : float
        Reference noise level [m/s²]: the RMS at orbit scales (below
        :data:`REFERENCE_BAND`); 0 writes ``s·a_true`` alone (the reference of
        earlier versions, same values and metadata).  Drawn from the day's
        ``"reference"`` stream: the other outputs of a seed do not change.

    Returns
    -------
    Path
        The truth file.
    """
    out = Path(out)
    day = simulate_grace_day(**kwargs)
    if reference_out is not None:
        dt = float(kwargs.get("dt", 1.0))
        n = int(round(float(kwargs.get("duration", 86400.0)) / dt))
        ref, info = _reference(day, reference_noise, dt, n, _parsed(kwargs))
        day.truth["reference"] = {"file": Path(reference_out).name, **info}
        source = {"source": f"accal simulate grace ({out.name})", "seed": day.truth["seed"]}
        content = "s * a_true (nominal scale_s of the truth)"
        if reference_noise > 0:
            content += f" + reference noise (truth['reference']['noise'] of {out.name})"
        _write_reference(reference_out, day.time, ref, {**source, "content": content})
    return _write_day(out, day, bool(kwargs.get("thrusters", False)))


def arc_paths(out: str | Path, date: str, days: int) -> list[Path]:
    """The data files of a multi-day simulation: ``out`` with ``date`` replaced by each day's.

    Raises
    ------
    ValidationError
        ``days > 1`` and the name of ``out`` does not contain ``date``.
    """
    out = Path(out)
    if days > 1 and date not in out.name:
        raise ValidationError(
            f"simulating {days} days needs the date {date} in the output name (it is replaced "
            f"by each day's date), got {out.name!r}"
        )
    start = np.datetime64(date, "D")
    return [out.with_name(out.name.replace(date, str(start + k))) for k in range(days)]


def arc_files(
    out: str | Path,
    date: str,
    days: int,
    satellite: str,
    *,
    coupling: bool = False,
    thrusters: bool = False,
    reference_out: str | Path | None = None,
) -> list[Path]:
    """The files a :func:`write_simulated_arc` call wrote, besides the truth files.

    Parameters
    ----------
    out, date, days
        As given to :func:`write_simulated_arc`.
    satellite : str
        ``A``, ``B``, ``C`` or ``D`` (names the THR1B files).
    coupling : bool
        A ``coupling`` effect was injected: each day's auxiliary table
        (:func:`aux_path`) is listed when it exists.
    thrusters : bool
        Thruster pulses were simulated: each day's THR1B file is listed.
    reference_out : str or Path, optional
        The reference table, listed last.

    Returns
    -------
    list of Path
        For each day its data file, then its auxiliary table and THR1B file; then
        the reference table.
    """
    written: list[Path] = []
    for path in arc_paths(out, date, days):
        written.append(path)
        if coupling and aux_path(path).exists():
            written.append(aux_path(path))
        if thrusters:
            written.append(thruster_path(path, satellite))
    if reference_out is not None:
        written.append(Path(reference_out))
    return written


def write_simulated_arc(
    out: str | Path,
    *,
    days: int,
    date: str = "2005-01-01",
    seed: int | None = None,
    reference_out: str | Path | None = None,
    reference_noise: float = REFERENCE_NOISE,
    **kwargs: Any,
) -> list[Path]:
    """Simulate ``days`` consecutive days as one arc: a data file per day, one reference.

    Each day is :func:`simulate_grace_day` of its date (seed: ``seed + k`` for day
    ``k``, or the day's :func:`default_seed`), written as by
    :func:`write_simulated_grace` to :func:`arc_paths` (``out`` with the date
    replaced); with ``days = 1`` it is exactly :func:`write_simulated_grace`.  What
    makes the days one arc:

    * the eq. 9 bias is continuous: day ``k`` starts at the bias of day ``k − 1``
      continued by its drift, ``b_k = b_{k−1} + d_{k−1}·(t0_k − t0_{k−1})`` (each day
      keeps its own random drift, so the bias is piecewise linear); the truth of
      every day has its ``bias`` at its ``t0``;
    * ``splinebias`` effects with random coefficients have their nodes in GPS time,
      so the spline is continuous across the days; ``scale`` and ``scalematrix``
      effects are the same every day.  The other effects restart each day (epochs
      from each day's start);
    * ``reference_out`` gets one table covering all days (concatenated), for
      ``accal grace-bias --reference REF --arc Nd``; the reference noise is drawn
      per day (POD arcs are usually daily).

    Every truth gets ``arc``: ``days``, ``index``, ``first_date`` and the data files.

    Parameters
    ----------
    out : str or Path
        The first day's ACC1B file; its name must contain ``date`` when ``days > 1``.
    days : int
        Number of days (>= 1).
    date : str
        First day, ``YYYY-MM-DD``.
    seed : int, optional
        Seed of the first day; day ``k`` uses ``seed + k``.
    reference_out, reference_noise
        As in :func:`write_simulated_grace`.
    **kwargs
        Passed to :func:`simulate_grace_day` for every day.

    Returns
    -------
    list of Path
        The truth files, one per day.
    """
    from accal.timescale import gps_day_start

    if days < 1:
        raise ValidationError(f"days must be >= 1, got {days}")
    if days == 1:
        truth = write_simulated_grace(
            out,
            reference_out=reference_out,
            reference_noise=reference_noise,
            date=date,
            seed=seed,
            **kwargs,
        )
        return [truth]
    paths = arc_paths(out, date, days)
    start = np.datetime64(date, "D")
    dt = float(kwargs.get("dt", 1.0))
    n = int(round(float(kwargs.get("duration", 86400.0)) / dt))
    effects = _parsed(kwargs)
    kwargs = {**kwargs, "effects": effects}
    times, refs, seeds, truths = [], [], [], []
    prev: dict[str, Any] | None = None
    for k, path in enumerate(paths):
        day_date = str(start + k)
        bias = None
        if prev is not None:
            step = gps_day_start(day_date) - prev["t0"]
            bias = np.asarray(prev["bias"]) + np.asarray(prev["drift"]) * step
        day = simulate_grace_day(
            date=day_date, seed=None if seed is None else seed + k, bias=bias, **kwargs
        )
        day.truth["arc"] = {
            "days": days,
            "index": k,
            "first_date": date,
            "files": [p.name for p in paths],
            "bias": "continued from the previous day: b_k = b_(k-1) + d_(k-1) (t0_k - t0_(k-1))",
        }
        if reference_out is not None:
            ref, info = _reference(day, reference_noise, dt, n, effects)
            day.truth["reference"] = {"file": Path(reference_out).name, **info}
            times.append(day.time)
            refs.append(ref)
        seeds.append(day.truth["seed"])
        truths.append(_write_day(path, day, bool(kwargs.get("thrusters", False))))
        prev = day.truth
    if reference_out is not None:
        content = "s * a_true (nominal scale_s of the truths)"
        if reference_noise > 0:
            content += " + reference noise (truth['reference']['noise'] of each day)"
        meta = {
            "source": f"accal simulate grace ({paths[0].name} .. {paths[-1].name})",
            "seed": seeds,
            "content": content,
        }
        _write_reference(reference_out, np.concatenate(times), np.concatenate(refs), meta)
    return truths
