"""Synthetic Gravity Advanced Package data: MicroSTAR on a rotating platform.

Measurements follow eq. 4 of Lenoir et al. (2013) with a calibration pattern
from :func:`accal.estimators.design.design_pattern`, coloured noise drawn from
the eq. 1 PSD (FFT shaping), and an affine, drifting bias (optionally coupled
to a temperature that rises after every rotation).  The truth table gives the
per-period means of the true accelerations.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import ValidationError
from ..estimators.design import design_pattern
from ..estimators.noise import PSD, as_psd

__all__ = ["simulate_gap", "coloured_noise"]


def coloured_noise(
    n: int, psd: PSD, fs: float, rng: np.random.Generator, size: int = 1
) -> NDArray[np.float64]:
    """Gaussian noise with a two-sided PSD, by FFT shaping of white noise.

    A record twice as long is synthesised and cut, so the circular wrap is not
    visible; the zero-frequency bin (infinite for 1/f noise) is set to 0, which
    only removes the record mean.

    Parameters
    ----------
    n : int
        Samples.
    psd : MicroStarPSD or TabulatedPSD
        Two-sided PSD [m² s⁻⁴ Hz⁻¹].
    fs : float
        Sampling frequency [Hz].
    rng : numpy.random.Generator
        Random source.
    size : int
        Independent series.

    Returns
    -------
    ndarray, shape (size, n)
        Noise [m s⁻²].
    """
    m = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfftfreq(m, 1.0 / fs)
    with np.errstate(divide="ignore"):
        amp = np.sqrt(fs * psd(f) * m)
    amp[0] = 0.0
    z = rng.standard_normal((size, f.size)) + 1j * rng.standard_normal((size, f.size))
    z /= np.sqrt(2.0)
    if m % 2 == 0:
        z[:, -1] = z[:, -1].real * np.sqrt(2.0)
    x = np.fft.irfft(z * amp, m, axis=1)
    return x[:, :n]


def simulate_gap(
    days: float = 1.0,
    tau: float = 600.0,
    mask: float = 200.0,
    fs: float = 1.0,
    seed: int | None = 0,
    *,
    bias: float = 1e-6,
    bias_drift: float = 1e-6 / 86400.0,
    a_Y: float = 4.6e-7,
    a_Z: float = -2.3e-7,
    signal_amplitude: float = 0.0,
    signal_period: float = 86400.0,
    temperature_coupling: float = 0.0,
    quadratic: float = 0.0,
    psd=None,
    noise: bool = True,
    with_x: bool = False,
    kind: str = "fig2",
):
    """Simulate ``m_y``, ``m_z`` (eq. 4) on a rotating platform, with truth.

    Parameters
    ----------
    days : float
        Duration [day]; truncated to whole periods.
    tau, mask : float
        Modulation period τ and masking time TM [s].
    fs : float
        Sampling frequency [Hz].
    seed : int or None
        Seed of the noise.
    bias : float
        Bias at t = 0 on y and z (z gets -0.7 times it) [m s⁻²].
    bias_drift : float
        Bias drift [m s⁻³] (default: 1e-6 m s⁻² per day).
    a_Y, a_Z : float
        Constant non-gravitational acceleration in the spacecraft frame
        [m s⁻²] (4.6e-7: solar pressure at 1 AU, section 3.2).
    signal_amplitude : float
        Amplitude of an added ``sin(2π t/signal_period)`` on a_Y and ``cos`` on a_Z [m s⁻²].
    signal_period : float
        Its period [s].
    temperature_coupling : float
        Bias sensitivity to the temperature [m s⁻² K⁻¹]; the temperature rises
        by 0.05 K after every rotation and relaxes with a 300 s time constant.
    quadratic : float
        Quadratic factor k2 of eq. 4 on both axes [s² m⁻¹].
    psd : PSD or (f, S), optional
        Noise PSD (eq. 1 by default).
    noise : bool
        Add noise.
    with_x : bool
        Also return an ``m_x`` column (a_X = 0, bias, noise).
    kind : {"fig2", "fig1"}
        Calibration pattern.

    Returns
    -------
    data : pandas.DataFrame
        ``time`` [s], ``m_y``, ``m_z`` [m s⁻²], ``theta`` [rad], ``temperature`` [K]
        (and ``m_x``).
    truth : pandas.DataFrame
        Per period: ``period``, ``t_start``, ``t_mid`` [s], ``a_Y``, ``a_Z`` (true
        means), ``bias_y``, ``bias_z`` (mean bias) [m s⁻²].
    """
    import pandas as pd

    pat = design_pattern(tau, mask, fs, kind=kind)
    q = pat.q
    n_per = int(days * 86400.0 * fs) // q
    if n_per < 1:
        raise ValidationError(f"days = {days} is shorter than one period of {tau} s")
    n = n_per * q
    t = np.arange(n) / fs
    theta = np.tile(pat.theta, n_per)
    rng = np.random.default_rng(seed)
    ay = a_Y + signal_amplitude * np.sin(2 * np.pi * t / signal_period)
    az = a_Z + signal_amplitude * np.cos(2 * np.pi * t / signal_period)
    # temperature: +0.05 K kick after each rotation, 300 s relaxation
    moving = ~np.tile(pat.mask_nominal, n_per)
    ends = np.flatnonzero(moving[:-1] & ~moving[1:]) + 1
    kicks = np.zeros(n)
    kicks[ends] = 0.05
    lam = np.exp(-1.0 / (300.0 * fs))
    from scipy.signal import lfilter

    temp = 293.15 + lfilter([1.0], [1.0, -lam], kicks)
    by = bias + bias_drift * t + temperature_coupling * (temp - 293.15)
    bz = -0.7 * bias + 0.5 * bias_drift * t + 0.5 * temperature_coupling * (temp - 293.15)
    c, s = np.cos(theta), np.sin(theta)
    py = c * ay + s * az
    pz = -s * ay + c * az
    my = py + quadratic * py**2 + by
    mz = pz + quadratic * pz**2 + bz
    cols = {"time": t}
    if noise:
        nz = coloured_noise(n, as_psd(psd), fs, rng, size=3 if with_x else 2)
        my = my + nz[0]
        mz = mz + nz[1]
    if with_x:
        cols["m_x"] = 0.3 * bias + (nz[2] if noise else 0.0)
    cols.update({"m_y": my, "m_z": mz, "theta": theta, "temperature": temp})
    data = pd.DataFrame(cols)
    per = np.arange(n_per)
    truth = pd.DataFrame(
        {
            "period": per,
            "t_start": per * q / fs,
            "t_mid": (per + 0.5) * q / fs,
            "a_Y": ay.reshape(n_per, q).mean(axis=1),
            "a_Z": az.reshape(n_per, q).mean(axis=1),
            "bias_y": by.reshape(n_per, q).mean(axis=1),
            "bias_z": bz.reshape(n_per, q).mean(axis=1),
        }
    )
    return data, truth
