"""Instrument and reference noise of a simulated GRACE day (:mod:`accal.simulate.grace`).

* instrument noise: one-sided ASD ``noise·sqrt(1 + f_c/f)·sqrt(1 + (f/f_r)⁴)`` (white
  in the measurement band, a 1/f rise below ``f_c`` = 1 mHz, a rise above ``f_r`` =
  20 mHz), through a CRN-like low-pass (:data:`CRN_BOXCAR`, :data:`CRN_ORDER`), a
  stand-in for the CRN filter the Level-1B processing applies to the 10 Hz data before
  decimating to 1 Hz [2]_ (its parameters here are fitted to the samples' first and
  second differences, not taken from the processing): :func:`instrument_noise`;
* the noise of a POD-derived reference acceleration (``--reference-noise``), good
  over long periods and poor at high frequency [3]_ [4]_ [5]_ [6]_:
  :func:`reference_noise`, :func:`reference_noise_psd`;
* :func:`coloured_noise`, GRACE-like noise for tests and benchmarks.

The lin_accl first differences of the samples (std, 60–100 s) are 2e-11 – 5e-10
m/s² (median 3e-11), the second differences / √6 2e-13 – 4e-11 (median 2.5e-12):
the noise's rise ``f_r`` and the CRN-like filter are chosen to give 2.7e-11 and
5e-12 at the default ``noise`` of 1e-10 m/s²/√Hz (``tests/test_simulate_realism.py``).

References
----------
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

import numpy as np
from numpy.typing import NDArray

from accal.crn import CRN_BOXCAR, CRN_ORDER
from accal.simulate.noise import coloured_noise as shaped

#: Noise shape: 1/f corner [Hz], f⁴ rise of the PSD above [Hz].
NOISE_CORNER, NOISE_RISE = 1e-3, 0.02

#: Reference noise (``--reference-noise``): default level [m/s²], the RMS of the
#: noise at orbit scales, i.e. below :data:`REFERENCE_BAND` [Hz].
REFERENCE_NOISE, REFERENCE_BAND = 1e-9, 1e-3
#: Reference noise shape: the f⁴ rise of the PSD equals the white floor at
#: :data:`REFERENCE_CORNER` [Hz] and is band-limited (levels off) above
#: :data:`REFERENCE_LIMIT` [Hz] (:func:`reference_noise_psd`).
REFERENCE_CORNER, REFERENCE_LIMIT = 0.2, 0.5


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
    if level == 0:
        return np.zeros((n, 3))
    x = shaped(
        n, lambda f: 0.5 * reference_noise_psd(f, level), 1.0 / dt, rng, size=3, white="time"
    )
    return x.T.copy()
