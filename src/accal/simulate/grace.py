"""Synthetic GRACE / GRACE-FO ACC1B days with a known bias, drift and scale.

The simulated raw reading follows the wavelet paper's eq. (9),
``a_raw = s·a_true + b + d·(t − t0)``, with

* ``a_true``: non-gravitational acceleration at GRACE altitude (magnitudes from
  ``shared/data/REFERENCE_VALUES.md``): along-track (x) drag ~ −2e-7 m/s² modulated
  once and twice per revolution (orbital period ~5,600 s) with a slow day-scale
  variation; solar-radiation pressure ~5e-8 m/s² once per revolution on y and z,
  switched off in eclipse;
* ``b``, ``s``: the GRACE TN-02 a-priori values for the satellite and date
  (``s = 1/scale``, raw-data sign ``b = −bias_TN02·s``), GRACE-FO C/D values from the
  measured 2023 means;
* ``d``: a random drift of a few 1e-14 m/s³;
* noise: white at ``noise`` m/s²/√Hz plus a 1/f rise below 1 mHz
  (SuperSTAR-like), drawn by FFT shaping.

Random draws (noise, drift, phases, gaps, flags) come from one seed.  Without an
explicit seed it is :func:`default_seed` of the date and satellite, so different
days and satellites get different noise while every run of the same day gives the
same file; an explicit seed is used as given.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import ValidationError

ORBIT_PERIOD = 5600.0  # [s]

#: Most samples of a simulated record (about 1 GB of memory; 11.6 days at 1 s).
MAX_SAMPLES = 1_000_000

#: Raw-data offsets (m/s², eq. 9 sign) for GRACE-FO C and D, from the measured
#: 100-s means on 2023-06-01 (shared/data/SOURCES.md).
GRACEFO_OFFSETS = {"C": (-0.278e-6, -10.651e-6, -0.182e-6), "D": (0.278e-6, 10.650e-6, -0.183e-6)}


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


@dataclass(frozen=True)
class SimulatedDay:
    """A simulated day: times, raw accelerations and the truth.

    Attributes
    ----------
    time : ndarray, shape (n,)
        GPS seconds [s].
    raw : ndarray, shape (n, 3)
        Raw readings [m/s²].
    true : ndarray, shape (n, 3)
        True non-gravitational acceleration [m/s²].
    valid : ndarray of bool, shape (n,)
        False for flagged samples.
    truth : dict
        ``bias`` [m/s²] (at ``t0``), ``drift`` [m/s³], ``scale_s`` (eq. 9 ``s``),
        ``t0`` [s], ``seed`` (the one used), plus ``signal_trend``: the LS bias/drift of ``s·a_true`` alone
        (the part of the true signal any trend estimator will also see).
    """

    time: NDArray[np.float64]
    raw: NDArray[np.float64]
    true: NDArray[np.float64]
    valid: NDArray[np.bool_]
    truth: dict[str, Any]


def coloured_noise(
    n: int, dt: float, level: float, corner: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Gaussian noise with one-sided ASD ``level·sqrt(1 + corner/f)`` [m/s²/√Hz].

    A thin wrapper of :func:`accal.simulate.noise.coloured_noise` (two-sided PSD
    ``level²(1 + corner/|f|)/2``, white samples drawn in time, no padding: the
    same draws, hence the same noise for a given seed, as before the merge).

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
        White noise level [m/s²/√Hz].

    Returns
    -------
    SimulatedDay

    Raises
    ------
    ValidationError
        For a bad satellite, a non-positive or non-finite ``duration`` or ``dt``,
        more than :data:`MAX_SAMPLES` samples or gaps, or a negative ``seed``.
    """
    from accal.calibration import tn02_bias, tn02_scale
    from accal.timescale import gps_day_start

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
    if seed is None:
        seed = default_seed(date, satellite)
    elif seed < 0:
        raise ValidationError(f"seed must be an integer >= 0, got {seed}")
    rng = np.random.default_rng(seed)
    t0 = gps_day_start(date)
    n = int(round(duration / dt))
    t = t0 + dt * np.arange(n)
    tau = t - t0
    phase = rng.uniform(0, 2 * np.pi)
    w = 2 * np.pi / ORBIT_PERIOD
    drag_level = rng.uniform(0.5e-7, 3e-7)
    slow = 1.0 + 0.3 * np.sin(2 * np.pi * tau / 86400.0 + rng.uniform(0, 2 * np.pi))
    ax = (
        -drag_level
        * slow
        * (1 + 0.25 * np.cos(w * tau + phase) + 0.08 * np.cos(2 * w * tau + 2 * phase))
    )
    sun = np.cos(w * tau + phase + 1.0)
    eclipse = sun < -0.55
    srp = 5e-8 * np.where(eclipse, 0.0, 1.0)
    ay = srp * (0.3 + 0.7 * np.sin(w * tau + phase)) + 2e-9 * np.cos(2 * w * tau)
    az = srp * 0.4 * np.cos(w * tau + phase) + 1e-8 * np.sin(w * tau)
    true = np.column_stack([ax, ay, az])

    if satellite in ("A", "B"):
        sat = f"GRACE-{satellite}"
        scale = np.array(tn02_scale(sat))
        mjd = 51544.0 + (t0 + 43200.0) / 86400.0
        bias = -np.array(tn02_bias(sat, mjd)) / scale
    else:
        scale = np.ones(3)
        bias = np.array(GRACEFO_OFFSETS[satellite])
    s = 1.0 / scale
    drift = rng.uniform(-5e-14, 5e-14, 3)
    nz = np.column_stack([coloured_noise(n, dt, noise, 1e-3, rng) for _ in range(3)])
    raw = s * true + bias + np.outer(tau, drift) + nz

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
    t, raw, true, valid = t[keep], raw[keep], true[keep], valid[keep]

    from accal.estimators.trend import fit_trend

    sig_trend = [fit_trend(t, s[i] * true[:, i], method="lsq", valid=valid) for i in range(3)]
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
        "signal_trend": {
            "bias": [f.bias for f in sig_trend],
            "drift": [f.drift for f in sig_trend],
        },
        "n_samples": int(t.size),
        "n_flagged": int((~valid).sum()),
        # gaps in the file: cut-outs that overlap or touch merge into one (QA: 3 asked,
        # 2 in the file, and the truth said 3)
        "n_gaps": int(np.count_nonzero(np.diff(keep.astype(np.int8)) == -1)),
        "n_gaps_requested": n_gaps,
        "units": {"bias": "m/s^2", "drift": "m/s^3", "t0": "s (GPS)"},
    }
    return SimulatedDay(t, raw, true, valid, truth)


def write_simulated_grace(out: str | Path, **kwargs: Any) -> Path:
    """Simulate a day and write it as an ACC1B file plus ``<out>.truth.json``.

    Keyword arguments go to :func:`simulate_grace_day`.  GRACE A/B days are
    written in the GRACE RL02 ASCII layout, C/D in the GRACE-FO RL04 YAML layout.

    Returns
    -------
    Path
        The truth file.
    """
    from accal.io.grace_l1b import DEFAULT_INVALID_BITS, write_grace_acc1b
    from accal.io.writers import atomic_path
    from accal.series import AccSeries

    out = Path(out)
    day = simulate_grace_day(**kwargs)
    sat = day.truth["satellite"]
    # flagged samples get the lowest bit that the reader treats as invalid (bit 0: Vp)
    flag = DEFAULT_INVALID_BITS & -DEFAULT_INVALID_BITS
    quality = np.where(day.valid, 0, flag).astype(np.uint32)
    series = AccSeries(
        time=day.time,
        acc=day.raw,
        valid=day.valid,
        quality=quality,
        satellite=f"GRACE-{sat}" if sat in "AB" else f"GRACE-FO-{sat}",
    )
    write_grace_acc1b(series, out, flavour="grace" if sat in "AB" else "gracefo")
    truth_path = out.with_name(out.name + ".truth.json")
    with atomic_path(truth_path) as tmp:
        tmp.write_text(json.dumps(day.truth, indent=2) + "\n")
    return truth_path
