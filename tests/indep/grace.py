"""Independent generator of GRACE / GRACE-FO accelerometer days and Level-1B writers.

The model (magnitudes and their sources in ``tests/indep/README.md``)::

    lin_accl = H * (s ⊙ a_true + Σ effects) + b + d (t − t0) + noise   (raw-data sign)

with ``a_true`` the non-gravitational acceleration in the science reference frame (x
along the line of sight ≈ along-track, y cross-track, z radial), ``s`` the scale
(``1/scale_TN02``), ``b`` the bias at ``t0`` (the first epoch of the day) and ``d`` the
drift, ``H *`` the CRN-like low-pass of the Level-1B processing (the noise is drawn with
it).  Nothing here imports ``accal``.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._common import (
    DAY,
    FloatArray,
    boxcar_smooth,
    crn_like_filter,
    crn_like_response,
    delayed,
    diff_std,
    first_order,
    gps_day_start,
    gps_to_calendar,
    noise_psd,
    rng_for,
    shaped_noise,
)
from .effects import apply_effects, make_channels, parse_effect

#: Raw 60-s means of the real samples [m/s²] (ACC1B 2003-09-14 A/B, ACT1B 2023-06-01 C/D),
#: used as the raw offsets ``b`` (a per-seed jitter of 1e-8 m/s² is added).
RAW_OFFSETS = {
    "A": (1.2136e-6, -28.512e-6, 0.52945e-6),
    "B": (0.54605e-6, -9.3832e-6, 0.85335e-6),
    "C": (-0.278e-6, -10.651e-6, -0.182e-6),
    "D": (0.278e-6, 10.650e-6, -0.183e-6),
}
#: Angular-acceleration offsets [rad/s²]: the 60-s means of the real 2003 files.  ACT1B
#: (GRACE-FO C/D) carries no angular accelerations: its columns are 0, as in the real files.
ANG_OFFSETS = {
    "A": (3.3220e-4, -3.9353e-5, -2.9153e-4),
    "B": (-4.1715e-4, -7.4392e-6, -5.8413e-4),
}
#: White angular-acceleration noise per sample [rad/s²]: first-difference std / √2 of the
#: real 2003 files.
ANG_NOISE = {"A": (7.87e-7, 2.40e-7, 6.42e-8), "B": (1.11e-7, 2.89e-8, 3.53e-8)}
#: High-frequency content of the real L1B linear accelerations [m/s²]: first-difference
#: std / √2 of each axis over the real 60-s (2003) and 100-s (2023) samples.  The
#: generator's ``hf_noise`` (0.01-0.1 Hz, CRN-like low-passed) is scaled to it.
HF_D1 = {
    "A": (2.41e-11, 3.16e-11, 3.83e-11),
    "B": (1.44e-11, 1.77e-11, 1.14e-10),
    "C": (1.40e-11, 3.62e-10, 6.22e-11),
    "D": (2.01e-11, 1.23e-11, 2.13e-12),
}
#: Corner [Hz] below which the high-frequency content is cut (f²/(f² + f_h²)).
HF_CORNER = 0.01
#: 1/f corner [Hz] of the angular-acceleration noise (the real 60-s std is 1.2-3.9x the
#: first-difference noise: there is low-frequency content).
ANG_CORNER = 0.1
#: Noise of the L1B residual columns acl_*_res [m/s²] (std of the real files).
RES_NOISE = {
    "A": (1.28e-8, 1.10e-8, 7.02e-8),
    "B": (1.33e-8, 3.58e-8, 1.13e-7),
    "C": (3.52e-9, 3.92e-9, 3.65e-9),
    "D": (1.73e-9, 1.33e-9, 2.90e-9),
}
#: Scale factor ranges: ``scale_TN02`` drawn per axis in U(0.96, 0.98) for GRACE, 1 for
#: GRACE-FO; ``s = 1/scale_TN02``.
SCALE_RANGE = {"A": (0.96, 0.98), "B": (0.96, 0.98), "C": (1.0, 1.0), "D": (1.0, 1.0)}
#: First day of the default dates: ``BASE_DATE + (seed % DATE_SPAN)`` days.
BASE_DATE = {
    "A": _dt.date(2005, 1, 1),
    "B": _dt.date(2005, 1, 1),
    "C": _dt.date(2019, 1, 1),
    "D": _dt.date(2019, 1, 1),
}
DATE_SPAN = {"A": 3650, "B": 3650, "C": 1800, "D": 1800}
#: Earth radius [m] and GM [m³/s²] (orbit radius from the period, eclipse geometry).
R_EARTH, GM_EARTH = 6378137.0, 3.986004418e14
#: Penumbra: the eclipse switch is a linear ramp of this duration [s].
PENUMBRA = 40.0
#: Relative area of the spacecraft seen along x, y, z (SRP scaling; GRACE is long in x).
SRP_AREA = (0.15, 1.0, 0.8)
#: Half-length of the CRN filter window [s]: samples within it of a gap get qualflg bits 5-7.
CRN_HALF_WINDOW = 35.0
SATELLITES = ("A", "B", "C", "D")


@dataclass(frozen=True)
class GraceDay:
    """One simulated day of Level-1B accelerometer data with its truth.

    Attributes
    ----------
    satellite : str
        ``"A"``, ``"B"`` (GRACE) or ``"C"``, ``"D"`` (GRACE-FO).
    date : datetime.date
        The GPS-calendar day of the file.
    time : ndarray, shape (n,)
        GPS seconds since 2000-01-01 12:00:00 [s]; ``t0 + k dt`` (integer seconds at 1 Hz),
        gap samples removed.
    lin_accl : ndarray, shape (n, 3)
        Raw linear accelerations x, y, z [m/s²].
    ang_accl : ndarray, shape (n, 3)
        Angular accelerations [rad/s²] (0 for GRACE-FO, whose ACT1B carries none).
    acl_res : ndarray, shape (n, 3)
        The L1B residual columns acl_x_res ... [m/s²].
    qualflg : ndarray of int64, shape (n,)
        L1B quality bitmask (bits 5-7: an interpolated point within 35 s / 15 s / 5 s of
        the CRN window centre, set around gaps and around 10 Hz micro-gaps).
    signal : ndarray, shape (n, 3)
        The true non-gravitational acceleration ``a_true`` [m/s²].
    channels : dict of str to ndarray, shape (n,)
        Auxiliary channels (temperatures [K]).
    truth : dict
        ``bias``, ``drift``, ``scale`` (``s``; each a list of 3 floats, raw sign:
        ``a_raw = s·a_true + b + d·(t − t0)``), ``t0`` [s], ``orbit_period`` [s], ``beta``
        [rad], ``effects`` (one dict per effect with ``kind``, ``axis``, its parameters and
        ``contribution``, ndarray (n,) [m/s²] added to that axis), ``effects_total``
        (n, 3), ``noise_series`` (n, 3), ``noise`` (model and parameters),
        ``signal_parts`` (drag, srp, albedo_ir, thrusters: (n, 3) each), ``signal_mean``
        and ``signal_trend`` (intercept at t0 and slope of a LS line through ``s·a_true``),
        ``bias_tn02`` and ``scale_tn02`` (TN-02 sign: ``a_cal = bias_tn02 + scale_tn02 ·
        a_raw``), ``storm``, ``thrusters``, ``gaps``, ``channels`` (drawn parameters),
        ``illumination`` (n,) (0 in umbra, 1 in sun, a 40-s ramp between), ``seed``,
        ``units``.
    """

    satellite: str
    date: _dt.date
    time: FloatArray
    lin_accl: FloatArray
    ang_accl: FloatArray
    acl_res: FloatArray
    qualflg: np.ndarray
    signal: FloatArray
    channels: dict[str, FloatArray] = field(default_factory=dict)
    truth: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of records."""
        return int(self.time.size)

    def l1b_name(self, product: str | None = None) -> str:
        """The Level-1B file name of this day, e.g. ``ACC1B_2005-01-01_A_02.asc``.

        ``product`` defaults to ``ACC1B`` (release 02, ``.asc``) for GRACE and ``ACT1B``
        (release 04, ``.txt``) for GRACE-FO.
        """
        fo = self.satellite in ("C", "D")
        product = product or ("ACT1B" if fo else "ACC1B")
        return f"{product}_{self.date.isoformat()}_{self.satellite}_{'04' if fo else '02'}" + (
            ".txt" if fo else ".asc"
        )


# ============================================================================ generator
def grace_day(
    seed: int,
    satellite: str = "A",
    *,
    duration: float = 86400.0,
    dt: float = 1.0,
    noise: str = "white+1/f",
    noise_level: float = 1e-10,
    noise_corner: float = 1e-3,
    noise_tau: float = 600.0,
    lowpass: float | None = 0.1,
    storm: bool = False,
    thrusters: bool = False,
    gaps: int = 0,
    microgaps_per_hour: float = 1.0,
    effects: Iterable[Sequence[Any]] = (),
    hf_noise: bool = True,
    channels: Iterable[str] = ("temperature",),
    date: _dt.date | str | None = None,
    beta: float | None = None,
    drag_sign: float = -1.0,
) -> GraceDay:
    """Simulate one day of GRACE (A/B) or GRACE-FO (C/D) Level-1B accelerometer data.

    Parameters
    ----------
    seed : int
        Non-negative seed; every random component has its own stream derived from it,
        so adding an effect does not change the noise or the signal.
    satellite : {"A", "B", "C", "D"}
        Sets the raw offsets, scale, angular-acceleration and residual magnitudes.
    duration : float
        [s]; the grid is ``t0 + k dt``, ``k = 0 .. round(duration/dt) − 1``.
    dt : float
        Sampling interval [s].
    noise : {"white", "white+1/f", "randomwalk", "ar1", "bandlimited-1rev"}
        Accelerometer noise model (one-sided PSDs in
        :func:`tests.indep._common.noise_psd`), drawn by FFT shaping with 8x padding.
    noise_level : float
        One-sided ASD of the white part [m s⁻² Hz⁻¹ᐟ²].
    noise_corner : float
        Corner frequency of the 1/f, random-walk and AR(1) parts [Hz].
    noise_tau : float
        AR(1) time constant [s].
    lowpass : float or None
        Bandwidth [Hz] of the CRN-like low-pass (L1B data are CRN-filtered: their
        sample-to-sample noise is far below the in-band level), applied to everything
        measured: the noise, the true signal (thruster pulses, eclipse edges) and the
        instrument effects (a step is a ~70 s ramp; :func:`tests.indep._common.crn_like_filter`);
        ``signal`` and the effects' contributions in the truth are the filtered ones.  None:
        nothing filtered.
    storm : bool
        Multiply the thermospheric density by 2-4 over a few hours.
    thrusters : bool
        Add attitude-thruster pulses (1e-8-1e-7 m/s², 1-5 s, 2-6 per hour) to the true
        signal, and the matching angular-acceleration pulses.
    gaps : int
        Number of data gaps (10 s - 30 min, log-uniform); their records are removed.
    microgaps_per_hour : float
        Rate of 10 Hz micro-gaps that only set qualflg bits 5-7 (records kept).
    hf_noise : bool
        Add the high-frequency (0.01-0.1 Hz) content of real L1B data, scaled per satellite
        and axis to the first-difference noise of the real samples (:data:`HF_D1`); it is
        part of ``truth["noise_series"]`` and also in ``truth["noise_hf"]``.
    effects : iterable of tuples
        Instrument effects added to the raw reading, each ``(kind, axis, ...)`` with axis
        ``"x"``/``"y"``/``"z"`` or 0/1/2 and times relative to ``t0`` [s]:

        * ``("step", axis, epoch, size)``: ``size · [t − t0 ≥ epoch]``;
        * ``("coupling", axis, channel, coef, lag, tau)``: ``coef · LP_tau(x(t − lag))``
          with ``x`` the channel ``channel`` (generated, returned in ``channels``) and
          ``LP_tau`` a first-order low-pass (tau = 0: none); not centred;
        * ``("quadratic", axis, coef)``: ``coef · (t − t0)²`` [m/s⁴];
        * ``("scale", axis, rel_error)``: ``rel_error · s · a_true``;
        * ``("sawtooth", axis, amp, period[, phase])``:
          ``amp · (2 frac((t − t0)/period + phase) − 1)``;
        * ``("growing_periodic", axis, amp, period, rate[, phase])``:
          ``(amp + rate (t − t0)) · sin(2π (t − t0)/period + 2π phase)``;
        * ``("exponential", axis, amp, tau)``: ``amp · exp(−(t − t0)/tau)``.

        ``period`` may be ``"orbit"`` (the drawn orbit period); ``phase`` is in cycles.
    channels : iterable of str
        Temperature-like channels always generated (coupled ones are added).
    date : datetime.date or str, optional
        The day; default ``2005-01-01`` (A/B) or ``2019-01-01`` (C/D) plus
        ``seed % 3650`` (``% 1800``) days.
    beta : float, optional
        Sun elevation above the orbit plane [deg]; drawn in U(−75, 75) by default (no
        eclipse above ~68.5°).
    drag_sign : float
        −1: SRF +x points along the flight direction (drag on −x); +1 for a satellite
        flying backwards (the leading one of a pair), which rotates the signal by 180°
        about z.

    Returns
    -------
    GraceDay

    Raises
    ------
    ValueError
        An unknown satellite, noise model or effect, an axis out of range, a non-positive
        ``duration``/``dt``, a negative ``gaps``.
    """
    sat = str(satellite).upper()
    if sat not in SATELLITES:
        raise ValueError(f"satellite: expected one of A, B, C, D, got {satellite!r}")
    if not (dt > 0 and duration > 0):
        raise ValueError(f"duration, dt: expected positive values, got {duration!r}, {dt!r}")
    if gaps < 0:
        raise ValueError(f"gaps: expected a non-negative integer, got {gaps!r}")
    eff = [parse_effect(e) for e in effects]
    day = (
        _as_date(date)
        if date is not None
        else BASE_DATE[sat] + _dt.timedelta(days=int(seed) % DATE_SPAN[sat])
    )
    n = int(round(duration / dt))
    t0 = float(gps_day_start(day))
    tr = np.arange(n) * dt
    time = t0 + tr

    # ---- orbit and environment ------------------------------------------------------
    ro = rng_for(seed, "orbit")
    period = ro.uniform(5550.0, 5700.0)
    beta_draw = ro.uniform(-75.0, 75.0)
    beta = np.deg2rad(beta_draw if beta is None else float(beta))
    u = ro.uniform(0, 2 * np.pi) + 2 * np.pi * tr / period  # 0 = closest to the Sun
    radius = (GM_EARTH * (period / (2 * np.pi)) ** 2) ** (1 / 3)
    s_par = np.cos(beta) * np.cos(u)
    shadow = (s_par < 0) & (np.sqrt(1 - s_par**2) * radius < R_EARTH)
    illum = np.clip(1.0 - boxcar_smooth(shadow.astype(float), int(round(PENUMBRA / dt))), 0, 1)
    illum[illum < 1e-9] = 0.0  # exact umbra and full sun despite the running sums' rounding
    illum[illum > 1 - 1e-9] = 1.0

    rd = rng_for(seed, "drag")
    drag0 = rd.uniform(1e-7, 5e-7)
    m1, ph1 = rd.uniform(0.1, 0.4), rd.uniform(0.3, 0.8)
    m2, ph2 = rd.uniform(0.03, 0.15), rd.uniform(0, 2 * np.pi)
    trend = rd.uniform(-0.2, 0.2)
    cross, radial = rd.uniform(-0.03, 0.03), rd.uniform(-0.01, 0.01)
    # 2 % density fluctuations (travelling disturbances) below ~0.5 mHz
    rf = rng_for(seed, "drag-fluctuations")
    fluct = shaped_noise(n, dt, lambda f: 1.0 / (1.0 + (f / 5e-4) ** 4), rf, pad=2)
    fluct *= 0.02 / max(float(np.std(fluct)), 1e-300)
    density = (
        (1 + m1 * np.cos(u - ph1) + m2 * np.cos(2 * u - ph2))
        * (1 + trend * (tr - duration / 2) / DAY)
        * (1 + fluct)
    )
    storm_truth = None
    if storm:
        rs = rng_for(seed, "storm")
        start = rs.uniform(0.1, 0.5) * duration
        peak, rise, decay = rs.uniform(2, 4), rs.uniform(1, 3) * 3600, rs.uniform(3, 8) * 3600
        x = np.clip(tr - start, 0, None)
        env = (1 - np.exp(-x / rise)) * np.exp(-x / decay)
        env /= max(float(env.max()), 1e-300)
        density = density * (1 + (peak - 1) * env)
        storm_truth = {"start": t0 + start, "peak_factor": peak, "rise": rise, "decay": decay}
    drag = drag0 * density
    a_drag = np.column_stack([-drag, cross * drag, radial * drag])

    rp = rng_for(seed, "srp")
    srp0 = rp.uniform(3e-8, 6e-8)
    sun = np.column_stack(
        [-np.cos(beta) * np.sin(u), np.full(n, np.sin(beta)), np.cos(beta) * np.cos(u)]
    )
    a_srp = -srp0 * illum[:, None] * sun * np.asarray(SRP_AREA)
    ir, alb = rp.uniform(2e-9, 4e-9), rp.uniform(3e-9, 8e-9)
    a_alb = np.zeros((n, 3))
    a_alb[:, 2] = ir + alb * np.clip(s_par, 0, None)

    a_thr = np.zeros((n, 3))
    ang_thr = np.zeros((n, 3))
    thr_truth: list[dict[str, Any]] = []
    if thrusters:
        rt = rng_for(seed, "thrusters")
        rate = rt.uniform(2, 6)
        for _ in range(rt.poisson(rate * duration / 3600.0)):
            st, du = rt.uniform(0, duration), rt.uniform(1, 5)
            main = int(rt.integers(3))
            amp = np.exp(rt.uniform(np.log(1e-8), np.log(1e-7)))
            vec = rt.uniform(0.1, 0.3, 3) * amp * rt.choice([-1.0, 1.0], 3)
            vec[main] = amp * rt.choice([-1.0, 1.0])
            ang_axis = int(rt.integers(3))
            ang = rt.uniform(5e-6, 3e-5) * rt.choice([-1.0, 1.0])
            on = (tr >= st) & (tr < st + du)
            a_thr[on] += vec
            ang_thr[on, ang_axis] += ang
            thr_truth.append(
                {
                    "start": t0 + st,
                    "duration": du,
                    "lin": vec.tolist(),
                    "ang_axis": "xyz"[ang_axis],
                    "ang": ang,
                }
            )

    frame = np.array([-drag_sign, -drag_sign, 1.0])  # 180° about z when flying backwards
    parts = {
        "drag": a_drag * frame,
        "srp": a_srp * frame,
        "albedo_ir": a_alb * frame,
        "thrusters": a_thr,
    }
    signal = parts["drag"] + parts["srp"] + parts["albedo_ir"] + parts["thrusters"]

    # ---- instrument --------------------------------------------------------------------
    ri = rng_for(seed, "instrument")
    bias = np.asarray(RAW_OFFSETS[sat]) + ri.normal(0, 1e-8, 3)
    lo, hi = SCALE_RANGE[sat]
    scale = 1.0 / ri.uniform(lo, hi, 3)
    drift = ri.choice([-1.0, 1.0], 3) * np.exp(ri.uniform(np.log(3e-15), np.log(1e-13), 3))

    psd = noise_psd(
        noise,
        noise_level,
        corner=noise_corner,
        tau=noise_tau,
        orbit_frequency=1.0 / period,
        lowpass=lowpass,
    )
    pad = 1 if noise == "white" else 8  # a flat spectrum needs no low-frequency padding
    noise_series = np.column_stack(
        [shaped_noise(n, dt, psd, rng_for(seed, "noise", k), pad=pad) for k in range(3)]
    )
    noise_hf = np.zeros((n, 3))
    if hf_noise:

        def hf_shape(f: FloatArray) -> FloatArray:
            return f**2 / (f**2 + HF_CORNER**2) * crn_like_response(f, lowpass or 0.1)

        unit = diff_std(hf_shape, dt)
        for k in range(3):
            level = np.sqrt(2) * HF_D1[sat][k] / unit
            noise_hf[:, k] = level * shaped_noise(n, dt, hf_shape, rng_for(seed, "hf", k), pad=1)
        noise_series = noise_series + noise_hf

    # ---- channels and effects ----------------------------------------------------------
    chan_full, chan_truth = make_channels(seed, channels, eff, n, dt, period)
    base_scaled = scale * signal
    eff, effects_total = apply_effects(eff, tr, dt, period, base_scaled, chan_full, 3)
    if lowpass is not None:  # the L1B filter acts on all that was measured, not only the noise
        signal = crn_like_filter(signal, dt, lowpass)
        base_scaled = scale * signal
        effects_total = crn_like_filter(effects_total, dt, lowpass)
        for e in eff:
            e["contribution"] = crn_like_filter(e["contribution"], dt, lowpass)

    lin = base_scaled + bias + np.outer(tr, drift) + effects_total + noise_series

    # ---- angular accelerations and residual columns -----------------------------------
    ra = rng_for(seed, "angular")
    ang = np.zeros((n, 3))
    ang_truth: dict[str, Any] = {}
    if sat in ANG_OFFSETS:
        lag, tau_a = ra.uniform(60, 300), ra.uniform(200, 600)
        dv = drag - drag.mean()
        resp = first_order(delayed(tr, tr, dv, lag), dt, tau_a)
        resp /= max(float(np.ptp(resp)) / 2, 1e-300)
        amps = ra.uniform(1e-7, 3e-7, 3) * ra.choice([-1.0, 1.0], 3)
        offs = np.asarray(ANG_OFFSETS[sat]) + ra.normal(0, 5e-6, 3)
        sig = np.asarray(ANG_NOISE[sat])
        ang_psd = noise_psd("white+1/f", 1.0, corner=ANG_CORNER)
        unit = diff_std(ang_psd, dt) / np.sqrt(2)
        # the measured part goes through the L1B filter like lin_accl (its thruster pulses
        # stay simultaneous with the linear ones); the noise is scaled to the samples' own
        # first differences (ANG_NOISE) as it is
        ang = crn_like_filter(offs + np.outer(resp, amps) + ang_thr, dt, lowpass)
        for k in range(3):
            rk = rng_for(seed, "angular-noise", k)
            ang[:, k] += shaped_noise(n, dt, ang_psd, rk, pad=2) * (sig[k] / unit)
        ang_truth = {"offset": offs.tolist(), "orbit_amp": amps.tolist(), "lag": lag, "tau": tau_a}
    rr = rng_for(seed, "residuals")
    res = rr.standard_t(5, (n, 3)) * (np.asarray(RES_NOISE[sat]) / np.sqrt(5 / 3))

    # ---- gaps and flags ----------------------------------------------------------------
    rg = rng_for(seed, "gaps")
    keep = np.ones(n, bool)
    gap_list = []
    spans: list[tuple[float, float]] = []
    for _ in range(int(gaps)):
        for _attempt in range(100):  # disjoint gaps, at least 60 s apart and from the ends
            length = np.exp(rg.uniform(np.log(10.0), np.log(1800.0)))
            start = rg.uniform(60.0, max(duration - 60.0 - length, 61.0))
            if all(start > e + 60.0 or start + length < s - 60.0 for s, e in spans):
                break
        else:
            raise ValueError(f"gaps: {gaps} gaps do not fit in {duration} s")
        spans.append((start, start + length))
        hole = (tr >= start) & (tr < start + length)
        keep &= ~hole
        if hole.any():
            gap_list.append((t0 + float(tr[hole][0]), t0 + float(tr[hole][-1]) + dt))
    micro = list(rg.uniform(0, duration, rg.poisson(microgaps_per_hour * duration / 3600.0)))
    qual = _gap_flags(tr, keep, micro)

    sl = np.flatnonzero(keep)
    s_sig = base_scaled[sl]
    coef = [np.polynomial.polynomial.polyfit(tr[sl], s_sig[:, k], 1) for k in range(3)]
    truth: dict[str, Any] = {
        "seed": int(seed),
        "satellite": sat,
        "date": day.isoformat(),
        "t0": t0,
        "dt": float(dt),
        "bias": bias.tolist(),
        "drift": drift.tolist(),
        "scale": scale.tolist(),
        "bias_tn02": (-bias / scale).tolist(),
        "scale_tn02": (1.0 / scale).tolist(),
        "orbit_period": float(period),
        "beta": float(beta),
        "eclipse_fraction": float(shadow.mean()),
        "illumination": illum[sl],
        "drag_mean": float(drag.mean()),
        "srp": float(srp0),
        "noise": {
            "model": noise,
            "level": float(noise_level),
            "corner": float(noise_corner),
            "tau": float(noise_tau),
            "lowpass": lowpass,
            "psd": psd,
        },
        "noise_series": noise_series[sl],
        "noise_hf": noise_hf[sl],
        "effects": [
            {
                **{k: v for k, v in e.items() if k != "contribution"},
                "axis": "xyz"[e["axis"]],
                "contribution": e["contribution"][sl],
            }
            for e in eff
        ],
        "effects_total": effects_total[sl],
        "signal_parts": {k: v[sl] for k, v in parts.items()},
        "signal_mean": s_sig.mean(axis=0).tolist(),
        "signal_trend": {
            "intercept": [float(c[0]) for c in coef],
            "slope": [float(c[1]) for c in coef],
        },
        "angular": ang_truth,
        "storm": storm_truth,
        "thrusters": thr_truth,
        "gaps": gap_list,
        "microgaps": [t0 + m for m in micro],
        "channels": chan_truth,
        "units": {
            "time": "s (GPS since 2000-01-01 12:00:00)",
            "bias": "m/s^2",
            "drift": "m/s^3",
            "scale": "1",
            "ang_accl": "rad/s^2",
            "channels": "K",
        },
    }
    chans = {name: tv[1][-n:][sl] for name, tv in chan_full.items()}
    return GraceDay(
        satellite=sat,
        date=day,
        time=time[sl],
        lin_accl=lin[sl],
        ang_accl=ang[sl],
        acl_res=res[sl],
        qualflg=qual[sl],
        signal=signal[sl],
        channels=chans,
        truth=truth,
    )


def _as_date(date: _dt.date | str) -> _dt.date:
    if isinstance(date, _dt.datetime):
        return date.date()
    if isinstance(date, _dt.date):
        return date
    try:
        return _dt.date.fromisoformat(str(date))
    except ValueError:
        raise ValueError(f"date: expected YYYY-MM-DD, got {date!r}") from None


def _gap_flags(tr: FloatArray, keep: np.ndarray, micro: list[float]) -> np.ndarray:
    """qualflg bits 5/6/7 for samples whose CRN window holds an interpolated point more
    than 15 s / 5-15 s / less than 5 s from its centre (around gaps and micro-gaps)."""
    holes = np.concatenate([tr[~keep], np.asarray(micro, float)])
    qual = np.zeros(tr.size, np.int64)
    if holes.size == 0:
        return qual
    holes.sort()
    i = np.searchsorted(holes, tr)
    left = np.abs(tr - holes[np.clip(i - 1, 0, holes.size - 1)])
    right = np.abs(holes[np.clip(i, 0, holes.size - 1)] - tr)
    dist = np.minimum(left, right)
    qual[(dist > 15) & (dist <= CRN_HALF_WINDOW)] |= 1 << 5
    qual[(dist > 5) & (dist <= 15)] |= 1 << 6
    qual[dist <= 5] |= 1 << 7
    return qual


# ============================================================================ writers
def _fmt_column(values: FloatArray) -> list[str]:
    """Full precision (the shortest repr that reads back to the same double); exact zeros
    as ``0``, like the angular accelerations of the real ACT1B files."""
    out = list(map(repr, np.asarray(values, float).tolist()))
    for i in np.flatnonzero(values == 0):
        out[i] = "0"
    return out


def _records(day: GraceDay) -> str:
    """The data records: ``time id 9 floats  qualflg`` (12 fields, two spaces before flags)."""
    if not np.allclose(day.time, np.round(day.time), rtol=0, atol=1e-9):
        raise ValueError("day.time: Level-1B records need integer GPS seconds")
    data = np.column_stack([day.lin_accl, day.ang_accl, day.acl_res])
    cols = [list(map(str, np.round(day.time).astype(np.int64).tolist()))]
    cols.append([day.satellite] * day.n)
    cols += [_fmt_column(data[:, k]) for k in range(9)]
    cols.append([f" {q:08b}" for q in day.qualflg.tolist()])
    return "".join(" ".join(row) + "\n" for row in zip(*cols, strict=True))


def _header_line(key: str, value: str) -> str:
    return f"{key:<30}: {value}".ljust(80)


def write_acc1b_grace(day: GraceDay, path: str | Path) -> Path:
    """Write ``day`` as a GRACE Level-1B ACC1B ASCII file (RL02 layout).

    The header is the one of the real ``ACC1B_2003-09-14_A_00.asc``: 80-column
    ``KEY<30>: value`` lines (SATELLITE NAME, TIME FIRST OBS / TIME LAST OBS with the GPS
    calendar instant, NUMBER OF DATA RECORDS, FILESIZE, ...) ending with
    ``END OF HEADER``; records are ``gps_time id lin_accl_x..z ang_accl_x..z
    acl_x_res..acl_z_res  qualflg`` with full-precision floats.

    Parameters
    ----------
    day : GraceDay
        Integer GPS seconds required.
    path : str or Path
        Output file (parent directories created).

    Returns
    -------
    Path
    """
    path = Path(path)
    body = _records(day)
    first, last = (day.time[0], day.time[-1]) if day.n else (day.truth["t0"],) * 2

    def obs(t: float) -> str:
        c = gps_to_calendar(t)
        return f"{t:.6f} ({c:%Y-%m-%d %H:%M:%S}.{c.microsecond // 10000:02d})"

    stamp = f"{day.date + _dt.timedelta(days=20):%Y-%m-%d} 01:48:33"
    name = day.l1b_name("ACC1B")
    keys = [
        ("PRODUCER AGENCY", "NASA"),
        ("PRODUCER INSTITUTION", "JPL"),
        ("FILE TYPE ipACC1BF", "8"),
        ("FILE FORMAT 0=BINARY 1=ASCII", "1"),
        ("NUMBER OF HEADER RECORDS", "{nhdr}"),
        ("SOFTWARE VERSION", "tests.indep synthetic (not a JPL product)"),
        ("SOFTWARE LINK TIME", "n/a"),
        ("REFERENCE DOCUMENTATION", "GRACE Level 1 Software Handbook"),
        ("SATELLITE NAME", f"GRACE {day.satellite}"),
        ("SENSOR NAME", "ACC"),
        ("TIME EPOCH (GPS TIME)", "2000-01-01 12:00:00"),
        ("TIME FIRST OBS(SEC PAST EPOCH)", obs(first)),
        ("TIME LAST OBS(SEC PAST EPOCH)", obs(last)),
        ("NUMBER OF DATA RECORDS", str(day.n)),
        ("PRODUCT CREATE START TIME(UTC)", f"{stamp} by tests.indep"),
        ("PRODUCT CREATE END TIME(UTC)", f"{stamp} by tests.indep"),
        ("FILESIZE (BYTES)", "{size}"),
        ("FILENAME", name),
        ("PROCESS LEVEL (1A OR 1B)", "1B"),
        ("INPUT FILE NAME", f"ACC1A<-ACC1A_{day.date.isoformat()}_{day.satellite}_02.dat"),
        ("INPUT FILE TIME TAG (UTC)", f"ACC1A<-{stamp} by tests.indep"),
    ]
    lines = [(k, v.replace("{nhdr}", str(len(keys)))) for k, v in keys]

    def build(size: str) -> str:
        text = "\n".join(_header_line(k, v.replace("{size}", size)) for k, v in lines)
        return text + "\n" + "END OF HEADER".ljust(80) + "\n"

    # every header line is padded to 80 columns, so the size digits do not change its length
    size = len(build("0").encode()) + len(body.encode())
    header = build(str(size))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(header + body)
    return path


#: The GRACE-FO RL04 YAML header, after the real ``ACT1B_2023-06-01_C_04.txt``
#: (placeholders in braces).
ACT1B_HEADER = """\
header:
  dimensions:
    num_records: {num_records}
  global_attributes:
    acknowledgement: GRACE-FO is a joint mission of the US National Aeronautics and Space Administration and the German Research Center for Geosciences.  Use the digital object identifier provided in the id attribute when citing this data.  See https://podaac.jpl.nasa.gov/CitingPODAAC
    conventions: CF-1.6, ACDD-1.3, ISO 8601
    creator_email: gracefo@podaac.jpl.nasa.gov
    creator_institution: NASA/JPL
    creator_name: GRACE Follow-On Science Data System
    creator_type: group
    creator_url: http://gracefo.jpl.nasa.gov
    date_created: {created}
    date_issued: {created}
    history:
      - "INPUT FILE NAME               : ACC1A<-ACT1A_{date}_{sat}_04.dat"
      - "INPUT FILE CREATION TIME (UTC): ACC1A<-{created_space} by tests.indep"
    id: 10.5067/GFJPL-L1B04
    institution: NASA/JPL
    instrument: ACC
    instrument_vocabulary: NASA Global Change Master Directory instrument keywords
    keywords: GRACE-FO, ACC
    keywords_vocabulary: NASA Global Change Master Directory (GCMD) Science Keywords
    license: https://science.nasa.gov/earth-science/earth-science-data/data-information-policy
    naming_authority: org.doi.dx
    platform: GRACE {sat}
    platform_vocabulary: NASA Global Change Master Directory platform keywords
    processing_level: 1B
    product_version: 04
    program: NASA Earth Systematic Missions Program
    project: NASA Gravity Recovery And Climate Experiment Follow-On (GRACE-FO)
    publisher_email: podaac@jpl.nasa.gov
    publisher_institution: NASA/JPL
    publisher_name: Physical Oceanography Distributed Active Archive Center
    publisher_type: group
    publisher_url: http://podaac.jpl.nasa.gov
    references: https://podaac.jpl.nasa.gov/gravity/gracefo-documentation
    source: Transformed Accelerometer data for GRACE {sat} (synthetic, tests.indep)
    summary: Transformed 1-Hz linear and angular accelerations of the ACC proof mass in SRF
    time_coverage_start: {cov_start}
    time_coverage_stop: {cov_stop}
    title: GRACE-FO Level-1B Transformed Accelerometer Data
  non-standard_attributes:
    epoch_time: 2000-01-01T12:00:00.00
    software_build_time: 2020-01-07T15:32:24-08:00
    software_version: tests.indep synthetic
    start_time_epoch_secs: {start}
    stop_time_epoch_secs: {stop}
  variables:
{variables}# End of YAML header
"""

_ACT1B_VARIABLES = [
    (
        "gps_time",
        "referenceInformation",
        "Continuous seconds past 01-Jan-2000 11:59:47 UTC",
        "second",
    ),
    ("GRACEFO_id", "referenceInformation", "GRACE-FO satellite identifier", "char"),
    ("lin_accl_x", "physicalMeasurement", "Linear acceleration along X-axis", "m/s2"),
    ("lin_accl_y", "physicalMeasurement", "Linear acceleration along Y-axis", "m/s2"),
    ("lin_accl_z", "physicalMeasurement", "Linear acceleration along Z-axis", "m/s2"),
    (
        "ang_accl_x",
        "physicalMeasurement",
        "Angular acceleration about X-axis, 0 for ACT1B",
        "rad/s2",
    ),
    (
        "ang_accl_y",
        "physicalMeasurement",
        "Angular acceleration about Y-axis, 0 for ACT1B",
        "rad/s2",
    ),
    (
        "ang_accl_z",
        "physicalMeasurement",
        "Angular acceleration about Z-axis, 0 for ACT1B",
        "rad/s2",
    ),
    ("acl_x_res", "modelResult", "Residual of lin_accl_x from non-CRN-filtered value", "m/s2"),
    ("acl_y_res", "modelResult", "Residual of lin_accl_y from non-CRN-filtered value", "m/s2"),
    ("acl_z_res", "modelResult", "Residual of lin_accl_z from non-CRN-filtered value", "m/s2"),
]
_ORDINALS = ["1st", "2nd", "3rd"] + [f"{k}th" for k in range(4, 13)]
_QUALFLG_YAML = """\
    - qualflg:
        comment: 12th column
        coverage_content_type: qualityInformation
        flag_masks: 1b, 2b, 4b, 8b, 16b, 32b, 64b, 128b
        flag_meanings:
          - bit 0 = Vp (proof mass voltage) out of nominal range
          - bit 1 = Not defined
          - bit 2 = At least one of acl_x_res, acl_y_res, and acl_z_res is > 10 microns/s^2
          - bit 3 = Extrapolated CLK1B clock offset value used for data point > 5 s from center of CRN filter window
          - bit 4 = Extrapolated CLK1B clock offset value used for data point <= 5 s from center of CRN filter window
          - bit 5 = Interpolated data point (due to gap) exists > 15 s from center of CRN filter window
          - bit 6 = Interpolated data point (due to gap) exists > 5 s but < 15 s from center of CRN filter window
          - bit 7 = Interpolated data point (due to gap) exists < 5 s from center of CRN filter window
        long_name: Data quality flag
"""


def _act1b_variables() -> str:
    out = []
    for i, (name, ctype, long_name, unit) in enumerate(_ACT1B_VARIABLES):
        out.append(
            f"    - {name}:\n        comment: {_ORDINALS[i]} column\n"
            f"        coverage_content_type: {ctype}\n        long_name: {long_name}\n"
            f"        units: {unit}\n"
        )
        if name == "GRACEFO_id":
            out.append(
                "        valid_range: C,D\n        value_meanings:\n"
                "          - C = GRACE-FO 1 (GRACE C)\n          - D = GRACE-FO 2 (GRACE D)\n"
            )
    return "".join(out) + _QUALFLG_YAML


def write_act1b_gracefo(day: GraceDay, path: str | Path) -> Path:
    """Write ``day`` as a GRACE-FO Level-1B ACT1B ASCII file (RL04 YAML layout).

    The YAML header copies the structure of the real ``ACT1B_2023-06-01_C_04.txt``
    (dimensions/num_records = the number of records written, global attributes with
    platform and time coverage, non-standard attributes with start/stop epoch seconds,
    the 12 variables with the qualflg bit meanings) and ends with ``# End of YAML
    header``; records are as in :func:`write_acc1b_grace` (exact zeros written ``0``).

    Parameters
    ----------
    day : GraceDay
        Integer GPS seconds required.
    path : str or Path
        Output file.

    Returns
    -------
    Path
    """
    path = Path(path)
    body = _records(day)
    first, last = (day.time[0], day.time[-1]) if day.n else (day.truth["t0"],) * 2
    created = _dt.datetime.combine(day.date + _dt.timedelta(days=8), _dt.time(1, 1, 9))

    def iso(t: float) -> str:
        c = gps_to_calendar(t)
        return f"{c:%Y-%m-%dT%H:%M:%S}.{c.microsecond // 10000:02d}"

    header = ACT1B_HEADER.format(
        num_records=day.n,
        created=f"{created:%Y-%m-%dT%H:%M:%SZ}",
        created_space=f"{created:%Y-%m-%d %H:%M:%S}",
        date=day.date.isoformat(),
        sat=day.satellite,
        cov_start=iso(first),
        cov_stop=iso(last),
        start=int(round(first)),
        stop=int(round(last)),
        variables=_act1b_variables(),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(header + body)
    return path
