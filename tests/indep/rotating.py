"""Independent generator of rotating-platform (MicroSTAR + Bias Rejection System) runs.

Written from B. Lenoir, B. Christophe, S. Reynaud, *Adv. Space Res.* 51 (2013) 188-197,
doi:10.1016/j.asr.2012.08.001 (``/work/shared/papers/gap_bias_rejection.txt``) and
``docs/demod.md``; equation numbers are the paper's.  Nothing here imports ``accal``.

Measurement (eq. 4 with δk1 = k2 = 0)::

    m_y =  cos θ a_Y + sin θ a_Z + b_y(t) + n_y
    m_z = −sin θ a_Y + cos θ a_Z + b_z(t) + n_z

θ(t) follows the Fig. 2 calibration pattern: rests at 0 and π of a, b, c, b, a samples
(signs + − + − +) separated by four rotations of ``mask/4`` s each.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._common import (
    DAY,
    FloatArray,
    delayed,
    first_order,
    rng_for,
    shaped_noise,
    two_sided_streams,
)
from .tables import write_table

#: Eq. 1: K [m s⁻² Hz⁻¹ᐟ²], 1/f corner and f⁴ corner [Hz] of the MicroSTAR noise.
MICROSTAR_K, MICROSTAR_F1, MICROSTAR_F4 = 5.7e-11, 4.2e-3, 0.27
#: Mean non-gravitational acceleration at 1 AU quoted by the paper's set-up [m/s²].
SIGNAL_LEVEL = 4.6e-7
#: Units of the run file (those of ``accal simulate gap``'s run files).
RUN_UNITS = {"time": "s", "m_y": "m/s^2", "m_z": "m/s^2", "theta": "rad", "temperature": "K"}
#: Units of the truth table.
PERIOD_UNITS = {
    "period": "index",
    "t_start": "s",
    "t_mid": "s",
    "a_Y": "m/s^2",
    "a_Z": "m/s^2",
    "a_Y_rest": "m/s^2",
    "a_Z_rest": "m/s^2",
    "bias_y_rest": "m/s^2",
    "bias_z_rest": "m/s^2",
    "n_rest": "samples",
}


def microstar_psd(f: FloatArray) -> FloatArray:
    """Eq. 1, the **two-sided** MicroSTAR noise PSD [m² s⁻⁴ Hz⁻¹].

    ``S(f) = K² (1 + 4.2 mHz/|f| + (|f|/0.27 Hz)⁴)``, ``K = 5.7e-11 m s⁻² Hz⁻¹ᐟ²``;
    the variance at sampling frequency fs is ``∫_{−fs/2}^{fs/2} S df`` (docs/demod.md:
    read as one-sided it would halve every variance).
    """
    f = np.abs(np.asarray(f, float))
    return MICROSTAR_K**2 * (1.0 + MICROSTAR_F1 / f + (f / MICROSTAR_F4) ** 4)


def _smoothstep(x: FloatArray) -> FloatArray:
    """Quintic 0 → 1 with zero first and second derivatives at both ends."""
    return x**3 * (10 - 15 * x + 6 * x**2)


def rest_mask(theta: FloatArray, tol: float = 0.0) -> np.ndarray:
    """The paper's masking matrix M (§4.2): at rest where the discrete θ̇ and θ̈ are 0.

    ``θ̇_k = θ_k − θ_{k−1}``, ``θ̈_k = θ_{k+1} − 2θ_k + θ_{k−1}``, both within ``tol``;
    ``theta`` is taken as periodic (its first and last samples are neighbours).
    """
    th = np.asarray(theta, float)
    d1 = th - np.roll(th, 1)
    d2 = np.roll(th, -1) - 2 * th + np.roll(th, 1)
    return (np.abs(d1) <= tol) & (np.abs(d2) <= tol)


@dataclass(frozen=True)
class Pattern:
    """One period of the Fig. 2 calibration pattern.

    Attributes
    ----------
    theta : ndarray, shape (q,)
        θ at the samples of one period [rad], in {0, π} at rest.
    rest : ndarray of bool, shape (q,)
        The paper's mask (θ̇ = θ̈ = 0), periodic.
    a, b, c, r : int
        Rest lengths a, b, c and rotation length r, in samples
        (``a | r | b | r | c | r | b | r | a``, ``c = 2b − 2a``, ``r = mask fs / 4``).
    sum_c, sum_ct, sum_ct2 : float
        Σc, Σct, Σct² of ``c = cos θ · rest`` with t centred on the period and in units of
        the period (the eq. 16 conditions: the first two are 0, the third is minimised).
    """

    theta: FloatArray
    rest: np.ndarray
    a: int
    b: int
    c: int
    r: int
    sum_c: float
    sum_ct: float
    sum_ct2: float


def calibration_pattern(tau: float, mask: float, fs: float = 1.0) -> Pattern:
    """Design the Fig. 2 pattern for period ``tau`` [s] and masking time ``mask`` [s].

    Rotations are quintic smooth steps of ``r = mask fs / 4`` samples strictly between 0
    and π; rests of ``a, b, c = 2b − 2a, b, a`` samples with ``b = (τ − mask) fs / 4``.
    Σc = Σct = 0 hold by construction (the layout is symmetric and alternates signs with
    total 2a − 2b + c = 0); ``a`` is the integer in ``1 .. b − 1`` that minimises |Σct²|
    with the discrete mask (the paper's §4.2 mask drops one more sample at each end of a
    rotation).

    Raises
    ------
    ValueError
        ``tau fs`` not an integer, ``mask fs`` or ``(tau − mask) fs`` not divisible by 4,
        ``mask`` not in (0, tau).
    """
    q = tau * fs
    r4, rest4 = mask * fs / 4, (tau - mask) * fs / 4
    if not (0 < mask < tau):
        raise ValueError(f"mask: expected 0 < mask < tau = {tau}, got {mask!r}")
    for name, v in (("tau·fs", q), ("mask·fs/4", r4), ("(tau − mask)·fs/4", rest4)):
        if abs(v - round(v)) > 1e-9:
            raise ValueError(f"{name}: expected an integer, got {v!r}")
    q, r, b = int(round(q)), int(round(r4)), int(round(rest4))
    if b < 2:
        raise ValueError(f"(tau − mask)·fs/4: expected at least 2, got {b}")
    ramp = np.pi * _smoothstep((np.arange(r) + 1.0) / (r + 1.0))
    best: Pattern | None = None
    tc = (np.arange(q) - (q - 1) / 2) / q
    for a in range(1, b):
        c = 2 * b - 2 * a
        theta = np.concatenate(
            [
                np.zeros(a),
                ramp,
                np.full(b, np.pi),
                np.pi - ramp,
                np.zeros(c),
                ramp,
                np.full(b, np.pi),
                np.pi - ramp,
                np.zeros(a),
            ]
        )
        rest = rest_mask(theta)
        cvec = np.where(rest, np.cos(theta), 0.0)
        p = Pattern(
            theta,
            rest,
            a,
            b,
            c,
            r,
            float(cvec.sum()),
            float((cvec * tc).sum()),
            float((cvec * tc**2).sum() / rest.sum()),
        )
        if best is None or abs(p.sum_ct2) < abs(best.sum_ct2) - 1e-15:
            best = p
    assert best is not None
    return best


@dataclass(frozen=True)
class PlatformRun:
    """A simulated rotating-platform run and its truth.

    Attributes
    ----------
    table : pandas.DataFrame
        ``time`` [s], ``m_y``, ``m_z`` [m/s²], ``theta`` [rad], ``temperature`` [K] (and any
        other coupled channel) — the columns ``accal demod`` reads.
    periods : pandas.DataFrame
        One row per complete period: ``period``, ``t_start``, ``t_mid``, ``a_Y``, ``a_Z``
        (true means over the whole period), ``a_Y_rest``, ``a_Z_rest`` (over the samples at
        rest, what the demodulation with a constant signal per period estimates),
        ``bias_y_rest``, ``bias_z_rest`` (bias means over the rest samples), ``n_rest``.
    truth : dict
        ``pattern`` (a, b, c, r, Σ's), ``bias`` (``b0`` and ``drift`` per axis: the affine
        bias ``b0 + drift (t − t0)``), ``signal`` (parameters), ``a_Y``, ``a_Z`` (per
        sample), ``noise`` (model, ``psd`` two-sided callable), ``noise_y``, ``noise_z``,
        ``effects`` (dicts with ``contribution``: ndarray (n, 2) for y, z),
        ``effects_total`` (n, 2), ``rest`` (the mask), ``temperature`` (parameters),
        ``periods`` (= ``periods``), ``seed``.

    Unpacks as ``table, truth = platform_run(...)``.
    """

    table: Any  # pandas.DataFrame (pandas is imported where used)
    periods: Any
    truth: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Any]:
        return iter((self.table, self.truth))


#: Effect kinds of the platform and their tuple layout (after the kind).
PLATFORM_EFFECTS = {
    "step": ("axis", "epoch", "size"),
    "coupling": ("channel", "coef", "lag", "axis"),
    "inperiod_quadratic": ("coef", "axis"),
}


def _parse_platform_effect(e: Sequence[Any]) -> dict[str, Any]:
    if not isinstance(e, Sequence) or isinstance(e, str) or not e:
        raise ValueError(f"effects: expected tuples (kind, ...), got {e!r}")
    kind = e[0]
    if kind not in PLATFORM_EFFECTS:
        raise ValueError(f"effects: expected a kind in {', '.join(PLATFORM_EFFECTS)}, got {kind!r}")
    names = PLATFORM_EFFECTS[kind]
    n_req = len(names) if kind == "step" else len(names) - 1  # axis optional
    if not n_req <= len(e) - 1 <= len(names):
        raise ValueError(
            f"effects: {kind!r} expects ({', '.join(('kind', *names))}), got {tuple(e)!r}"
        )
    out = {"kind": kind, "axis": "both", **dict(zip(names, e[1:], strict=False))}
    if out["axis"] not in ("y", "z", "both"):
        raise ValueError(f"effects: axis must be 'y', 'z' or 'both', got {tuple(e)!r}")
    if kind == "coupling" and out["lag"] < 0:
        raise ValueError(f"effects: coupling lag must be >= 0, got {tuple(e)!r}")
    return out


def _platform_temperature(
    k_ext: np.ndarray, pattern_rest: np.ndarray, fs: float, rng: np.random.Generator
) -> tuple[FloatArray, dict]:
    """Platform temperature [K] at samples ``k_ext`` (0 = first sample of the run).

    Heat from each rotation through a first-order thermal response (its periodic steady
    state, the paper's §4.1 model: "at each rotation, heat is generated and induces a
    temporary increase of temperature") on top of a slow daily cycle, a trend, a random
    walk and read-out noise.  Values at ``k >= 0`` do not depend on the prefix length.
    """
    q = pattern_rest.size
    dt = 1.0 / fs
    t = k_ext / fs
    p = {
        "mean": 293.15 + rng.uniform(-0.5, 0.5),
        "daily_amp": rng.uniform(0.02, 0.1),
        "daily_phase": rng.uniform(0, 2 * np.pi),
        "trend_per_day": rng.uniform(-0.05, 0.05),
        "heating_full_rise": rng.uniform(0.03, 0.08),
        "thermal_tau": rng.uniform(200.0, 600.0),
        "randomwalk_per_sqrt_hour": 0.002,
        "readout_noise": 1e-4,
    }
    n_settle = int(np.ceil(40 * p["thermal_tau"] * fs / q)) + 1
    rotating = np.tile(~pattern_rest, n_settle).astype(float)
    one_period = first_order(rotating, dt, p["thermal_tau"])[-q:] * p["heating_full_rise"]
    n_neg = int(np.sum(k_ext < 0))
    rw = two_sided_streams(rng, n_neg, k_ext.size - n_neg, "walk")
    rw *= (p["randomwalk_per_sqrt_hour"] / 60) * np.sqrt(dt)
    readout = two_sided_streams(rng, n_neg, k_ext.size - n_neg, "white") * p["readout_noise"]
    temp = (
        p["mean"]
        + p["daily_amp"] * np.sin(2 * np.pi * t / DAY + p["daily_phase"])
        + p["trend_per_day"] * t / DAY
        + one_period[k_ext % q]
        + rw
        + readout
    )
    return temp, {k: float(v) for k, v in p.items()}


def platform_run(
    seed: int,
    *,
    days: float = 1.0,
    tau: float = 600.0,
    mask: float = 200.0,
    fs: float = 1.0,
    noise_psd: str | float = "microstar",
    signal: str | Callable[[FloatArray], tuple[FloatArray, FloatArray]] = "slow",
    effects: Iterable[Sequence[Any]] = (),
    t0: float = 0.0,
) -> PlatformRun:
    """Simulate a rotating-platform MicroSTAR run (eq. 4) with its per-period truth.

    Parameters
    ----------
    seed : int
        Non-negative seed; signal, bias, noise (y and z) and temperature have their own
        streams.
    days : float
        Duration [day]; ``round(days · 86400 · fs)`` samples.
    tau : float
        Modulation period [s] (``tau · fs`` an integer).
    mask : float
        Total rotation time per period [s] (``mask · fs`` and ``(tau − mask) · fs``
        divisible by 4).
    fs : float
        Sampling frequency [Hz].
    noise_psd : "microstar" or float
        ``"microstar"``: eq. 1 (two-sided, :func:`microstar_psd`); a float ``L``: white
        noise of two-sided PSD ``L²`` [m² s⁻⁴ Hz⁻¹] (so ``L = 5.7e-11`` is eq. 1's floor).
        Independent on y and z; 1/f drawn by FFT shaping with 8x padding.
    signal : {"slow", "constant"} or callable
        ``"constant"``: ``|a| = 4.6e-7 m/s²`` in a random direction of the (Y, Z) plane;
        ``"slow"``: that plus a daily term (amplitude U(2e-9, 5e-9)) and a
        once-per-rev-like term (period U(5550, 5700) s, amplitude U(0.5e-9, 2e-9)) on each
        axis; a callable ``f(t) -> (a_Y, a_Z)`` [m/s²] of run time ``t`` [s].
    effects : iterable of tuples
        Added to the bias:

        * ``("step", axis, epoch, size)``: ``size`` [m/s²] from ``t − t0 ≥ epoch``;
        * ``("coupling", channel, coef, lag[, axis])``: ``coef · x(t − lag)``, ``x`` the
          ``temperature`` channel (or another platform-temperature-like channel of that
          name, generated and added to the table) [coef in m s⁻² per channel unit];
        * ``("inperiod_quadratic", coef[, axis])``: ``coef · (t − t_k)²`` within every
          period k (``t_k`` its start), the same ``coef`` [m/s⁴] in every period.

        ``axis`` is ``"y"``, ``"z"`` or ``"both"`` (the default where optional).
    t0 : float
        Time of the first sample [s].

    Returns
    -------
    PlatformRun

    Raises
    ------
    ValueError
        Bad pattern parameters (:func:`calibration_pattern`), noise, signal or effects.
    """
    import pandas as pd

    pat = calibration_pattern(tau, mask, fs)
    q = pat.theta.size
    n = int(round(days * DAY * fs))
    if n < 1:
        raise ValueError(f"days: expected a positive duration, got {days!r}")
    eff = [_parse_platform_effect(e) for e in effects]
    max_lag = max([e["lag"] for e in eff if e["kind"] == "coupling"] + [0.0])
    # extended grid: samples before the run so lagged channels exist from the start
    n_pre = int(np.ceil(max_lag * fs)) + 2
    k_ext = np.arange(-n_pre, n)
    sl = slice(n_pre, None)
    k = k_ext[sl]
    tr = k / fs
    time = t0 + tr
    theta = pat.theta[k % q]
    rest = pat.rest[k % q]

    # ---- signal (Y, Z in the spacecraft frame) ------------------------------------------
    rs = rng_for(seed, "platform-signal")
    direction = rs.uniform(0, 2 * np.pi)
    sig_truth: dict[str, Any] = {"kind": signal if isinstance(signal, str) else "callable"}
    if callable(signal):
        a_y, a_z = (np.broadcast_to(np.asarray(v, float), tr.shape).copy() for v in signal(tr))
    elif signal in ("slow", "constant"):
        a_y = np.full(n, SIGNAL_LEVEL * np.cos(direction))
        a_z = np.full(n, SIGNAL_LEVEL * np.sin(direction))
        sig_truth.update({"level": SIGNAL_LEVEL, "direction": float(direction)})
        if signal == "slow":
            p_rev = rs.uniform(5550.0, 5700.0)
            for name, arr in (("Y", a_y), ("Z", a_z)):
                ad, phd = rs.uniform(2e-9, 5e-9), rs.uniform(0, 2 * np.pi)
                ar, pr = rs.uniform(0.5e-9, 2e-9), rs.uniform(0, 2 * np.pi)
                arr += ad * np.sin(2 * np.pi * tr / DAY + phd) + ar * np.sin(
                    2 * np.pi * tr / p_rev + pr
                )
                sig_truth[name] = {
                    "daily_amp": ad,
                    "daily_phase": phd,
                    "rev_amp": ar,
                    "rev_phase": pr,
                }
            sig_truth["rev_period"] = p_rev
    else:
        raise ValueError(f"signal: expected 'slow', 'constant' or a callable, got {signal!r}")

    # ---- bias, channels, effects --------------------------------------------------------
    rb = rng_for(seed, "platform-bias")
    b0 = rb.choice([-1.0, 1.0], 2) * rb.uniform(0.5e-6, 2e-6, 2)
    drift = rb.choice([-1.0, 1.0], 2) * rb.uniform(1e-12, 2e-11, 2)
    temp_ext, temp_truth = _platform_temperature(
        k_ext, pat.rest, fs, rng_for(seed, "platform-temperature")
    )
    chans_ext = {"temperature": temp_ext}
    chan_truth = {"temperature": temp_truth}
    for e in eff:
        if e["kind"] == "coupling" and e["channel"] not in chans_ext:
            x, p = _platform_temperature(
                k_ext, pat.rest, fs, rng_for(seed, "platform-channel", e["channel"])
            )
            chans_ext[e["channel"]], chan_truth[e["channel"]] = x, p
    t_ext = k_ext / fs
    total = np.zeros((n, 2))
    done = []
    for e in eff:
        if e["kind"] == "step":
            c = np.where(tr >= e["epoch"], float(e["size"]), 0.0)
        elif e["kind"] == "coupling":
            c = e["coef"] * delayed(tr, t_ext, chans_ext[e["channel"]], e["lag"])
        else:  # in-period quadratic, t_k the start of each period
            c = e["coef"] * ((k % q) / fs) ** 2
        cols = np.zeros((n, 2))
        for j, ax in enumerate("yz"):
            if e["axis"] in (ax, "both"):
                cols[:, j] = c
        total += cols
        done.append({**e, "contribution": cols})
    bias = b0 + np.outer(tr, drift) + total

    # ---- noise ----------------------------------------------------------------------------
    if isinstance(noise_psd, str):
        if noise_psd != "microstar":
            raise ValueError(f"noise_psd: expected 'microstar' or a float, got {noise_psd!r}")

        def two_sided(f: FloatArray) -> FloatArray:
            return microstar_psd(f)

        pad = 8
    else:
        level = float(noise_psd)

        def two_sided(f: FloatArray) -> FloatArray:
            return np.full_like(np.asarray(f, float), level**2)

        pad = 1
    dt = 1.0 / fs
    n_y = shaped_noise(
        n, dt, lambda f: 2 * two_sided(f), rng_for(seed, "platform-noise", 0), pad=pad
    )
    n_z = shaped_noise(
        n, dt, lambda f: 2 * two_sided(f), rng_for(seed, "platform-noise", 1), pad=pad
    )

    # ---- eq. 4 --------------------------------------------------------------------------
    c, s = np.cos(theta), np.sin(theta)
    m_y = c * a_y + s * a_z + bias[:, 0] + n_y
    m_z = -s * a_y + c * a_z + bias[:, 1] + n_z

    table = pd.DataFrame({"time": time, "m_y": m_y, "m_z": m_z, "theta": theta})
    for name, x in chans_ext.items():
        table[name] = x[sl]

    n_per = n // q
    m = n_per * q

    def per(x: FloatArray, w: np.ndarray | None = None) -> FloatArray:
        xr = x[:m].reshape(n_per, q)
        if w is None:
            return xr.mean(axis=1)
        wr = w[:m].reshape(n_per, q)
        return (xr * wr).sum(axis=1) / wr.sum(axis=1)

    periods = pd.DataFrame(
        {
            "period": np.arange(n_per),
            "t_start": time[:m:q],
            "t_mid": time[:m:q] + (q - 1) / (2 * fs),
            "a_Y": per(a_y),
            "a_Z": per(a_z),
            "a_Y_rest": per(a_y, rest),
            "a_Z_rest": per(a_z, rest),
            "bias_y_rest": per(bias[:, 0], rest),
            "bias_z_rest": per(bias[:, 1], rest),
            "n_rest": rest[:m].reshape(n_per, q).sum(axis=1),
        }
    )
    truth = {
        "seed": int(seed),
        "tau": float(tau),
        "mask": float(mask),
        "fs": float(fs),
        "t0": float(t0),
        "pattern": {
            "a": pat.a,
            "b": pat.b,
            "c": pat.c,
            "r": pat.r,
            "sum_c": pat.sum_c,
            "sum_ct": pat.sum_ct,
            "sum_ct2": pat.sum_ct2,
            "masked_per_period": int(q - pat.rest.sum()),
        },
        "signal": sig_truth,
        "a_Y": a_y,
        "a_Z": a_z,
        "bias": {"b0": b0.tolist(), "drift": drift.tolist(), "units": ["m/s^2", "m/s^3"]},
        "noise": {"model": noise_psd, "psd_two_sided": two_sided},
        "noise_y": n_y,
        "noise_z": n_z,
        "effects": done,
        "effects_total": total,
        "rest": rest,
        "channels": chan_truth,
        "periods": periods,
    }
    return PlatformRun(table=table, periods=periods, truth=truth)


def write_platform_run(run: PlatformRun, path: str | Path, *, fmt: str | None = None) -> Path:
    """Write the run table in the layout ``accal demod`` reads.

    Columns ``time`` [s], ``m_y``, ``m_z`` [m/s²], ``theta`` [rad] and the channels [K],
    units in the Parquet schema metadata (``accal.units``) or a ``# units:`` CSV line.
    """
    units = dict(RUN_UNITS)
    units.update({c: "K" for c in run.table.columns if c not in units})
    return write_table(path, run.table, units, fmt=fmt)


def write_platform_truth(run: PlatformRun, path: str | Path, *, fmt: str | None = None) -> Path:
    """Write the per-period truth table (:attr:`PlatformRun.periods`) with units."""
    return write_table(path, run.periods, PERIOD_UNITS, fmt=fmt)
