"""Synthetic Gravity Advanced Package data: MicroSTAR on a rotating platform.

Measurements follow eq. 4 of Lenoir et al. (2013) with a calibration pattern
from :func:`accal.estimators.design.design_pattern`, coloured noise drawn from
the eq. 1 PSD (FFT shaping, :func:`accal.simulate.noise.coloured_noise`), and an
affine, drifting bias (optionally coupled to a temperature that rises after
every rotation).  The truth table gives the per-period means of the true
accelerations.

:func:`simulate_gap` returns a whole record; :func:`simulate_gap_chunks` yields
it in blocks of whole periods (a year of 1 Hz data in bounded memory).  In the
chunked form the noise of each block is drawn independently: its 1/f part loses
its correlation across block borders, which fall between modulation periods, so
the per-period estimates and their statistics are unaffected.

References
----------
B. Lenoir, B. Christophe, S. Reynaud, Adv. Space Res. 51 (2013) 188-197,
doi:10.1016/j.asr.2012.08.001.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from ..errors import ValidationError
from ..estimators.design import CalibrationPattern, design_pattern
from ..estimators.noise import as_psd
from .noise import coloured_noise

__all__ = ["simulate_gap", "simulate_gap_chunks", "coloured_noise"]

#: Temperature model: kick after each rotation [K] and relaxation time [s].
TEMPERATURE_KICK, TEMPERATURE_TAU, TEMPERATURE_BASE = 0.05, 300.0, 293.15

#: Most samples in one block of :func:`simulate_gap_chunks` with a finite
#: ``chunk_days`` (10 days at 10 Hz; ~4 GB of memory while the block is drawn).
MAX_BLOCK_SAMPLES = 8_640_000


def _check_parameters(days: float, seed: int | None, prm: dict[str, Any]) -> None:
    """ValidationError for a non-finite parameter, a period <= 0 or a negative seed."""
    if not 0 < days < np.inf:
        raise ValidationError(f"days must be positive and finite, got {days}")
    if seed is not None and seed < 0:
        raise ValidationError(f"seed must be an integer >= 0, got {seed}")
    for name, value in prm.items():
        if not np.isfinite(value):
            raise ValidationError(f"{name} must be finite, got {value}")
    if not prm["signal_period"] > 0:
        raise ValidationError(f"signal_period must be positive, got {prm['signal_period']} s")


def _block(
    pat: CalibrationPattern,
    p0: int,
    n_per: int,
    rng: np.random.Generator,
    zi: np.ndarray,
    prm: dict[str, Any],
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """Periods ``p0 .. p0 + n_per - 1``: data columns, truth columns, filter state."""
    from scipy.signal import lfilter

    q, fs = pat.q, pat.fs
    n = n_per * q
    t = (p0 * q + np.arange(n)) / fs
    theta = np.tile(pat.theta, n_per)
    amp, period = prm["signal_amplitude"], prm["signal_period"]
    ay = prm["a_Y"] + amp * np.sin(2 * np.pi * t / period)
    az = prm["a_Z"] + amp * np.cos(2 * np.pi * t / period)
    # temperature: a kick after each rotation, first-order relaxation (state carried over)
    moving = ~np.tile(pat.mask_nominal, n_per)
    ends = np.flatnonzero(moving[:-1] & ~moving[1:]) + 1
    kicks = np.zeros(n)
    kicks[ends] = TEMPERATURE_KICK
    lam = np.exp(-1.0 / (TEMPERATURE_TAU * fs))
    rise, zf = lfilter([1.0], [1.0, -lam], kicks, zi=zi)
    temp = TEMPERATURE_BASE + rise
    bias, drift, coupling = prm["bias"], prm["bias_drift"], prm["temperature_coupling"]
    by = bias + drift * t + coupling * (temp - TEMPERATURE_BASE)
    bz = -0.7 * bias + 0.5 * drift * t + 0.5 * coupling * (temp - TEMPERATURE_BASE)
    c, s = np.cos(theta), np.sin(theta)
    py = c * ay + s * az  # eq. 4 (platform axes), scale factors 1
    pz = -s * ay + c * az
    k2 = prm["quadratic"]
    my = py + k2 * py**2 + by
    mz = pz + k2 * pz**2 + bz
    cols: dict[str, Any] = {"time": t}
    with_x = prm["with_x"]
    if prm["noise"]:
        nz = coloured_noise(n, prm["psd"], fs, rng, size=3 if with_x else 2)
        my = my + nz[0]
        mz = mz + nz[1]
    if with_x:
        cols["m_x"] = 0.3 * bias + (nz[2] if prm["noise"] else np.zeros(n))
    cols.update({"m_y": my, "m_z": mz, "theta": theta, "temperature": temp})
    per = p0 + np.arange(n_per)
    truth = {
        "period": per,
        "t_start": per * q / fs,
        "t_mid": (per + 0.5) * q / fs,
        "a_Y": ay.reshape(n_per, q).mean(axis=1),
        "a_Z": az.reshape(n_per, q).mean(axis=1),
        "bias_y": by.reshape(n_per, q).mean(axis=1),
        "bias_z": bz.reshape(n_per, q).mean(axis=1),
    }
    return cols, truth, zf


def simulate_gap_chunks(
    days: float = 1.0,
    tau: float = 600.0,
    mask: float = 200.0,
    fs: float = 1.0,
    seed: int | None = 0,
    *,
    chunk_days: float = 1.0,
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
) -> Iterator[tuple[dict[str, np.ndarray], dict[str, np.ndarray]]]:
    """Simulate a run block by block: :func:`simulate_gap` in bounded memory.

    Parameters
    ----------
    days, tau, mask, fs, seed
        As :func:`simulate_gap`.
    chunk_days : float
        Length of a block [day], rounded down to whole periods (at least one).
        When finite, a block also holds at most :data:`MAX_BLOCK_SAMPLES` samples
        (whole periods, at least one); ``inf``: the whole run in one block.
    bias, bias_drift, a_Y, a_Z, signal_amplitude, signal_period, temperature_coupling, quadratic, psd, noise, with_x, kind
        As :func:`simulate_gap`.

    Yields
    ------
    data : dict of str to ndarray
        The columns of :func:`simulate_gap`'s ``data`` for the block.
    truth : dict of str to ndarray
        The columns of its ``truth`` for the block's periods.

    Raises
    ------
    ValidationError
        For ``days`` not positive and finite, a negative ``seed``, a non-finite
        amplitude, coupling, bias or factor, a ``signal_period`` <= 0, or no
        calibration pattern for ``tau``, ``mask``, ``fs``.

    Notes
    -----
    The noise of each block is drawn independently (one random stream for the
    whole run); the temperature filter state, the bias drift and the signal
    phase run on across blocks.  With one block (``chunk_days >= days``) the
    output equals :func:`simulate_gap`'s.
    """
    values = {
        "bias": bias,
        "bias_drift": bias_drift,
        "a_Y": a_Y,
        "a_Z": a_Z,
        "signal_amplitude": signal_amplitude,
        "signal_period": signal_period,
        "temperature_coupling": temperature_coupling,
        "quadratic": quadratic,
    }
    _check_parameters(days, seed, values)
    pat = design_pattern(tau, mask, fs, kind=kind)
    q = pat.q
    n_total = int(days * 86400.0 * fs) // q
    if n_total < 1:
        raise ValidationError(f"days = {days} is shorter than one period of {tau} s")
    per_block = n_total if chunk_days >= days else max(1, int(chunk_days * 86400.0 * fs) // q)
    if np.isfinite(chunk_days):  # bounded memory at any fs (1 Hz: 100 days per block)
        per_block = min(per_block, max(1, MAX_BLOCK_SAMPLES // q))
    rng = np.random.default_rng(seed)
    prm = {**values, "psd": as_psd(psd), "noise": noise, "with_x": with_x}
    zi = np.zeros(1)
    for p0 in range(0, n_total, per_block):
        cols, truth, zi = _block(pat, p0, min(per_block, n_total - p0), rng, zi, prm)
        yield cols, truth


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
        Duration [day], positive and finite; truncated to whole periods.
    tau, mask : float
        Modulation period τ and masking time TM [s].
    fs : float
        Sampling frequency [Hz].
    seed : int or None
        Seed of the noise (an integer >= 0).
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
        Its period [s] (positive).
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

    ((data, truth),) = simulate_gap_chunks(
        days,
        tau,
        mask,
        fs,
        seed,
        chunk_days=float("inf"),
        bias=bias,
        bias_drift=bias_drift,
        a_Y=a_Y,
        a_Z=a_Z,
        signal_amplitude=signal_amplitude,
        signal_period=signal_period,
        temperature_coupling=temperature_coupling,
        quadratic=quadratic,
        psd=psd,
        noise=noise,
        with_x=with_x,
        kind=kind,
    )
    return pd.DataFrame(data), pd.DataFrame(truth)
