"""Building blocks shared by the independent generators: random streams, coloured noise,
filters, a temperature-like channel and GPS-time helpers.

Plain numpy/scipy only; nothing here imports ``accal``.
"""

from __future__ import annotations

import datetime as _dt
import zlib
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft

#: GPS epoch of GRACE/GRACE-FO Level-1B time tags (GPS seconds are counted from here).
GPS_EPOCH = _dt.datetime(2000, 1, 1, 12, 0, 0)
#: Padding factor of the FFT noise shaping: the realisation is drawn on ``PAD`` times the
#: record length and cut, so the spectrum is right down to ``1/(PAD * duration)``.
PAD = 8
#: Seconds per day.
DAY = 86400.0

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- random streams
def rng_for(seed: int, *key: int | str) -> np.random.Generator:
    """An independent random generator for one component of a simulation.

    Parameters
    ----------
    seed : int
        The user's seed (any non-negative integer).
    *key : int or str
        Names the component (strings are hashed with CRC-32, which is stable across runs
        and machines, unlike :func:`hash`).

    Returns
    -------
    numpy.random.Generator
        A PCG64 generator whose stream depends only on ``seed`` and ``key``: adding an
        effect or a channel to a simulation does not change the other components' draws.
    """
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    spawn = tuple(zlib.crc32(k.encode()) if isinstance(k, str) else int(k) for k in key)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=spawn)))


# --------------------------------------------------------------------------- noise
def shaped_noise(
    n: int,
    dt: float,
    psd: Callable[[FloatArray], FloatArray],
    rng: np.random.Generator,
    *,
    pad: int = PAD,
) -> FloatArray:
    """Gaussian noise with a given one-sided PSD, drawn by FFT shaping with padding.

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sampling interval [s].
    psd : callable
        One-sided PSD ``S1(f)`` [unit² Hz⁻¹] for ``f > 0`` [Hz]; the variance of the
        output is ``∫_0^{fs/2} S1(f) df``.
    rng : numpy.random.Generator
        Random source.
    pad : int
        The realisation is ``pad * n`` samples long (cyclic) and its first ``n`` are
        returned, so frequencies down to ``1/(pad n dt)`` are represented; the DC bin is 0.

    Returns
    -------
    ndarray, shape (n,)

    Notes
    -----
    The bins ``W_k`` are complex Gaussians with ``E|W_k|² = M`` (the rfft of white
    ``N(0, 1)`` noise of length M); scaling bin k by ``sqrt(S1(f_k) fs / 2)`` and
    inverting gives a cyclic process whose variance is
    ``(fs/2) · mean over the 2-sided bins of S1(|f|) = ∫_0^{fs/2} S1 df``.
    """
    if n <= 0:
        return np.zeros(0)
    m = sfft.next_fast_len(max(pad, 1) * n, real=True)
    f = sfft.rfftfreq(m, dt)
    # complex Gaussian bins with E|X_k|² = m: the rfft of white N(0, 1) noise, drawn directly
    spec = rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)
    amp = np.zeros_like(f)
    amp[1:] = np.sqrt(np.maximum(psd(f[1:]), 0.0) * (0.25 * m / dt))
    return sfft.irfft(spec * amp, m)[:n]


def diff_std(psd: Callable[[FloatArray], FloatArray], dt: float, nf: int = 100_000) -> float:
    """Standard deviation of the first difference ``x_k − x_{k−1}`` of noise with one-sided
    PSD ``psd`` sampled at ``dt``: ``sqrt(∫_0^{fs/2} S1(f) 4 sin²(π f dt) df)``."""
    fs2 = 0.5 / dt
    f = (np.arange(nf) + 0.5) * (fs2 / nf)
    return float(np.sqrt(np.sum(psd(f) * 4 * np.sin(np.pi * f * dt) ** 2) * (fs2 / nf)))


def crn_like_response(f: FloatArray, bandwidth: float | None, order: int = 7) -> FloatArray:
    """Power response ``|H(f)|²`` of a CRN-like low-pass (self-convolved boxcar).

    ``H(f) = sinc(f / bandwidth) ** order``: ``order`` boxcars of length ``1/bandwidth``
    convolved (first zero at ``bandwidth``), the shape of the GRACE Level-1B CRN filter.
    ``bandwidth=None`` returns ones (no filter).
    """
    if bandwidth is None:
        return np.ones_like(f)
    return np.sinc(f / bandwidth) ** (2 * order)


def crn_like_filter(
    x: FloatArray, dt: float, bandwidth: float | None, order: int = 7
) -> FloatArray:
    """Apply the CRN-like low-pass of :func:`crn_like_response` along axis 0, zero phase.

    The Level-1B processing filters everything the instrument measured (signal, thruster
    pulses, instrument effects) with its CRN filter, not only the noise: a bias step in an
    ACC1B file is a ramp over the filter's window (GRACE: ~70 s, the "CRN filter window" of
    the ACC1B ``qualflg`` bits 5-7).  Amplitude response ``sinc(f/bandwidth) ** order``
    applied by FFT; the record is extended at both ends by its odd reflection about the end
    samples (``2 x[0] − x[k]``), which keeps constants and linear trends exact up to the
    ends.  ``bandwidth=None`` returns a copy.
    """
    x = np.array(x, dtype=np.float64)
    n = x.shape[0]
    if bandwidth is None or n < 3:
        return x
    m = min(n - 1, int(np.ceil(4 * order / (bandwidth * dt))))
    left = 2 * x[:1] - x[m:0:-1]
    right = 2 * x[-1:] - x[-2 : -m - 2 : -1]
    xp = np.concatenate([left, x, right], axis=0)
    size = sfft.next_fast_len(xp.shape[0], real=True)
    f = sfft.rfftfreq(size, dt)
    h = np.sinc(f / bandwidth) ** order
    shape = (-1,) + (1,) * (x.ndim - 1)
    y = sfft.irfft(sfft.rfft(xp, n=size, axis=0) * h.reshape(shape), n=size, axis=0)
    return y[m : m + n]


def noise_psd(
    kind: str,
    level: float,
    *,
    corner: float = 1e-3,
    tau: float = 600.0,
    orbit_frequency: float = 1 / 5600.0,
    lowpass: float | None = None,
) -> Callable[[FloatArray], FloatArray]:
    """One-sided PSD ``S1(f)`` [m² s⁻⁴ Hz⁻¹] of a named accelerometer-noise model.

    Parameters
    ----------
    kind : {"white", "white+1/f", "randomwalk", "ar1", "bandlimited-1rev"}
        ``white``: ``L²``; ``white+1/f``: ``L² (1 + fc/f)``; ``randomwalk``:
        ``L² (1 + (fc/f)²)``; ``ar1``: ``L² (1 + (fc/fτ)² / (1 + (f/fτ)²))`` with
        ``fτ = 1/(2π τ)`` (a leaky random walk, i.e. an AR(1) process of time constant τ,
        equal to ``randomwalk`` above fτ and flat below); ``bandlimited-1rev``:
        ``L² (1 + G exp(-(f - f_orb)² / (2 (w f_orb)²)))`` with ``G = 100``, ``w = 0.1``.
    level : float
        ``L``, the one-sided amplitude spectral density of the white part [m s⁻² Hz⁻¹ᐟ²].
    corner : float
        ``fc`` [Hz].
    tau : float
        AR(1) time constant [s].
    orbit_frequency : float
        ``f_orb`` [Hz].
    lowpass : float or None
        Bandwidth of a CRN-like low-pass applied on top (:func:`crn_like_response`).

    Returns
    -------
    callable
        ``S1(f)`` for an array of ``f > 0``.
    """
    l2 = float(level) ** 2
    if kind == "white":

        def base(f: FloatArray) -> FloatArray:
            return np.full_like(f, l2)

    elif kind == "white+1/f":

        def base(f: FloatArray) -> FloatArray:
            return l2 * (1.0 + corner / f)

    elif kind == "randomwalk":

        def base(f: FloatArray) -> FloatArray:
            return l2 * (1.0 + (corner / f) ** 2)

    elif kind == "ar1":
        ftau = 1.0 / (2 * np.pi * tau)

        def base(f: FloatArray) -> FloatArray:
            return l2 * (1.0 + (corner / ftau) ** 2 / (1.0 + (f / ftau) ** 2))

    elif kind == "bandlimited-1rev":

        def base(f: FloatArray) -> FloatArray:
            w = BAND_WIDTH * orbit_frequency
            return l2 * (1.0 + BAND_GAIN * np.exp(-0.5 * ((f - orbit_frequency) / w) ** 2))

    else:
        raise ValueError(f"noise: expected one of {', '.join(NOISE_KINDS)}, got {kind!r}")

    def psd(f: FloatArray) -> FloatArray:
        return base(f) * crn_like_response(f, lowpass)

    return psd


NOISE_KINDS = ("white", "white+1/f", "randomwalk", "ar1", "bandlimited-1rev")
#: PSD gain and relative half-width of the ``bandlimited-1rev`` noise band.
BAND_GAIN, BAND_WIDTH = 100.0, 0.1


# --------------------------------------------------------------------------- filters
def first_order(x: FloatArray, dt: float, tau: float) -> FloatArray:
    """First-order low-pass (time constant ``tau`` [s]) started in its steady state.

    Exact discretisation of ``τ ẏ = x − y`` for a piecewise-constant input:
    ``y_k = β y_{k−1} + α x_k``, ``α = 1 − β``, ``β = exp(−dt/τ)``, ``y_0 = x_0``; computed
    as the convolution with ``α β^j`` (truncated at ``β^j < e^{−40}``, renormalised to unit
    DC gain) of ``x`` preceded by copies of ``x_0``, by FFT (no ``scipy.signal``, whose
    import costs more than a simulated day).  ``tau <= 0`` returns ``x`` unchanged.
    """
    x = np.asarray(x, float)
    if tau <= 0 or x.size == 0:
        return x.copy()
    beta = np.exp(-dt / tau)
    k = int(min(np.ceil(40.0 * tau / dt), 10 * x.size + 1000)) + 1
    h = (1.0 - beta) * beta ** np.arange(k)
    h /= h.sum()
    xp = np.concatenate([np.full(k, x[0]), x])
    m = sfft.next_fast_len(xp.size + k, real=True)
    y = sfft.irfft(sfft.rfft(xp, m) * sfft.rfft(h, m), m)
    return y[k : k + x.size]


def delayed(t: FloatArray, t_src: FloatArray, x_src: FloatArray, lag: float) -> FloatArray:
    """``x(t − lag)`` by linear interpolation of ``x_src`` given on ``t_src``."""
    return np.interp(np.asarray(t, float) - lag, t_src, x_src)


def boxcar_smooth(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average over ``width`` samples (edges held): a linear ramp of
    ``width`` samples at every step of a 0/1 series (exact 0 and 1 away from steps)."""
    x = np.asarray(x, float)
    if width <= 1 or x.size == 0:
        return x.copy()
    lo, hi = width // 2, width - 1 - width // 2
    xp = np.concatenate([np.full(lo, x[0]), x, np.full(hi, x[-1])])
    c = np.concatenate([[0.0], np.cumsum(xp)])
    return (c[width:] - c[:-width]) / width


def two_sided_streams(rng: np.random.Generator, n_neg: int, n_pos: int, kind: str) -> FloatArray:
    """Standard normals for samples ``−n_neg .. n_pos − 1``: the non-negative part from one
    stream, the negative part (drawn backwards from −1) from another, both seeded from
    ``rng``; so the values at k >= 0 do not depend on ``n_neg``.  ``kind``: ``"white"`` or
    ``"walk"`` (a random walk with unit steps, 0 just before sample 0)."""
    fwd = np.random.default_rng(rng.integers(2**63))
    bwd = np.random.default_rng(rng.integers(2**63))
    pos, neg = fwd.standard_normal(n_pos), bwd.standard_normal(n_neg)
    if kind == "walk":
        pos = np.cumsum(pos)
        neg = -np.cumsum(neg)  # value at −1 − j, going back in time
    return np.concatenate([neg[::-1], pos])


# --------------------------------------------------------------------------- channels
def temperature_channel(
    t: FloatArray,
    rng: np.random.Generator,
    *,
    orbit_period: float = 5600.0,
    mean: float | None = None,
) -> tuple[FloatArray, dict]:
    """A spacecraft temperature-like channel [K] on the times ``t`` [s].

    Content (all amplitudes drawn from ``rng``): mean ``293.15 + U(−1, 1)`` K (or
    ``mean``); an orbital cycle ``U(0.05, 0.3)`` K at 1/rev and ``U(0.01, 0.05)`` K at
    2/rev; a linear trend ``U(−0.3, 0.3)`` K/day; a random walk of 0.01 K/√h; heater
    cycling (thermostat): an asymmetric triangle of ``U(0.005, 0.03)`` K, period
    ``U(900, 2400)`` s wandering by 3 %, duty cycle ``U(0.3, 0.6)``; white read-out
    noise of 1e-3 K.

    Parameters
    ----------
    t : ndarray
        Uniformly spaced times relative to the record's first sample [s]; negative times
        (a prefix for lagged couplings) come from their own random streams, so the values
        at ``t >= 0`` do not depend on the length of the prefix.
    rng : numpy.random.Generator
        Random source.
    orbit_period : float
        [s].
    mean : float, optional
        Mean temperature [K].

    Returns
    -------
    values : ndarray
        [K].
    params : dict
        The drawn parameters.
    """
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    n_neg = int(np.sum(t < 0))
    p = {
        "mean": float(mean) if mean is not None else 293.15 + rng.uniform(-1, 1),
        "orbit_amp": rng.uniform(0.05, 0.3),
        "orbit_phase": rng.uniform(0, 2 * np.pi),
        "orbit2_amp": rng.uniform(0.01, 0.05),
        "orbit2_phase": rng.uniform(0, 2 * np.pi),
        "trend_per_day": rng.uniform(-0.3, 0.3),
        "randomwalk_per_sqrt_hour": 0.01,
        "heater_amp": rng.uniform(0.005, 0.03),
        "heater_period": rng.uniform(900, 2400),
        "heater_duty": rng.uniform(0.3, 0.6),
        "heater_phase": rng.uniform(0, 1),
        "heater_wander_period": rng.uniform(4e4, 9e4),
        "heater_wander_phase": rng.uniform(0, 2 * np.pi),
        "readout_noise": 1e-3,
        "orbit_period": float(orbit_period),
    }
    w = 2 * np.pi / orbit_period
    rw = two_sided_streams(rng, n_neg, t.size - n_neg, "walk")
    rw *= (p["randomwalk_per_sqrt_hour"] / 60.0) * np.sqrt(dt)
    # heater: phase = ∫ dt / (period (1 + 0.03 sin(...))) ≈ t/period + the wander's integral
    tw = p["heater_wander_period"]
    phase = (
        p["heater_phase"]
        + t / p["heater_period"]
        + 0.03
        * tw
        / (2 * np.pi * p["heater_period"])
        * np.cos(2 * np.pi * t / tw + p["heater_wander_phase"])
    )
    fr = phase % 1.0
    d = p["heater_duty"]
    tri = np.where(fr < d, -1.0 + 2.0 * fr / d, 1.0 - 2.0 * (fr - d) / (1.0 - d))
    readout = two_sided_streams(rng, n_neg, t.size - n_neg, "white") * p["readout_noise"]
    values = (
        p["mean"]
        + p["orbit_amp"] * np.cos(w * t + p["orbit_phase"])
        + p["orbit2_amp"] * np.cos(2 * w * t + p["orbit2_phase"])
        + p["trend_per_day"] * t / DAY
        + rw
        + p["heater_amp"] * tri
        + readout
    )
    return values, {k: float(v) for k, v in p.items()}


# --------------------------------------------------------------------------- time
def gps_day_start(date: _dt.date) -> int:
    """GPS seconds (since 2000-01-01 12:00:00) of 00:00:00 of ``date`` on the GPS calendar.

    ``(date − 2000-01-01) · 86400 − 43200``: the first time tag of a Level-1B day file
    (2003-09-14 → 116769600, 2023-06-01 → 738849600, as in the real samples).
    """
    return (date - _dt.date(2000, 1, 1)).days * 86400 - 43200


def gps_to_calendar(seconds: float) -> _dt.datetime:
    """The GPS-calendar instant of GPS seconds (no leap seconds: GPS time is continuous)."""
    return GPS_EPOCH + _dt.timedelta(seconds=float(seconds))


def axis_index(axis: int | str, axes: tuple[str, ...] = ("x", "y", "z")) -> int:
    """Index of an axis given as a name (``"x"``) or an index; ValueError otherwise."""
    if isinstance(axis, str) and axis in axes:
        return axes.index(axis)
    if isinstance(axis, int | np.integer) and not isinstance(axis, bool) and 0 <= axis < len(axes):
        return int(axis)
    raise ValueError(f"axis: expected one of {', '.join(axes)} (or its index), got {axis!r}")
