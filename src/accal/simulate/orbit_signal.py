"""The true environment of a simulated GRACE / GRACE-FO day: orbit, eclipses, drag, thrusters.

Pure functions of the elapsed time ``tau`` [s] and of parameters drawn from a
random generator; :func:`environment` assembles the true non-gravitational linear
acceleration and the orbit-periodic angular acceleration in the science reference
frame (SRF) of one satellite, with a JSON-friendly truth.

Model (magnitudes from ``shared/data/REFERENCE_VALUES.md``, "Typical magnitudes")
-------------------------------------------------------------------------------
* **Orbit**: circular, period drawn per day in :data:`ORBIT_PERIOD_RANGE` (GRACE
  flew at ~300–500 km over its life, GRACE-FO at ~490 km; the period gives the
  radius through Kepler's third law), argument of latitude ``u`` counted from the
  projection of the Sun on the orbit plane, Sun elevation above that plane ``β``.
* **Eclipses**: cylindrical Earth shadow; the satellite is in shadow where
  ``cos β cos u < −sqrt(1 − (R/r)²)``.  Entry and exit are smoothed over
  :data:`PENUMBRA` seconds (a raised-cosine ramp of the solar-radiation pressure,
  standing for the penumbra and the thermal response of the panels).
* **Solar-radiation pressure** ~5e-8 m/s², directed away from the Sun, switched
  off in shadow; Earth albedo and infrared add a radial push of ~10 % of it.
* **Drag** ~1e-8 – 1e-6 m/s² along −velocity (here 5e-8 – 3e-7), with a
  once-per-revolution day/night density contrast and a twice-per-revolution term,
  a slow density trend over the day, a small cross-track part from the co-rotating
  atmosphere, and optionally a geomagnetic storm (density up by 2–4 within a few
  hours, then decaying).
* **Thrusters** (optional): attitude-thruster-like pulses of 1e-8 – 1e-7 m/s²,
  2–5 s long, a few per hour, on the linear axes.  They are real acceleration
  (signal), not an instrument effect.  The real THR1B samples of
  ``shared/data`` record attitude firings every 93 s (GRACE-A 2003), 130 s (B),
  137 s (GRACE-FO C 2023) and 245 s (D) on average, with on-times of 50–300 ms;
  most of them are too small to see at 1 Hz, and the pulses here stand for the
  rarer visible ones.
* **Angular acceleration**: once- and twice-per-revolution terms of ~2e-7 rad/s²
  per axis (attitude-control and gravity-gradient torques).

Frames: SRF ``x`` along the line of sight to the other satellite (≈ along-track),
``y`` ≈ cross-track, ``z`` ≈ radial (taken nadir-positive).  The two satellites
of a pair face each other, so one flies with ``+x`` forward and the other with
``+x`` backward (a 180° turn about ``z``: ``x`` and ``y`` change sign, as the real
GRACE-FO C/D offsets do, ``shared/data/SOURCES.md``).  Here A and C fly ``+x``
forward (drag along −x) and B and D backward; which satellite led changed during
the missions and is not modelled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Range of the orbital period drawn per day [s] (REFERENCE_VALUES.md: ~5,600 s).
ORBIT_PERIOD_RANGE = (5550.0, 5700.0)

#: Duration of the smoothed eclipse entry and exit ramps [s].
PENUMBRA = 40.0

#: Earth's equatorial radius [m] and gravitational parameter [m³/s²] (WGS-84).
EARTH_RADIUS, EARTH_GM = 6378137.0, 3.986004418e14

#: Solar-radiation-pressure level [m/s²] (REFERENCE_VALUES.md: ~5e-8 m/s²).
SRP_RANGE = (4e-8, 6e-8)

#: Along-track drag level [m/s²] (REFERENCE_VALUES.md: 1e-8 to 1e-6 m/s²).
DRAG_RANGE = (5e-8, 3e-7)

#: Relative SRP response of the SRF axes: the small frontal area of the
#: satellite (x) sees less pressure than its sides and top (an assumption).
SRP_AXIS_GAIN = (0.3, 1.0, 1.0)

#: Thruster pulses: rate [per hour], amplitude [m/s²], length [s].
THRUSTER_RATE, THRUSTER_AMPLITUDE, THRUSTER_LENGTH = (2.0, 6.0), (1e-8, 1e-7), (2, 5)

#: Angular acceleration signal: once- and twice-per-revolution amplitudes [rad/s²].
ANGULAR_ONCE, ANGULAR_TWICE = (1e-7, 3e-7), (3e-8, 1e-7)

#: Sign of SRF x (and y) relative to the flight direction, per satellite letter.
FORWARD = {"A": 1.0, "B": -1.0, "C": 1.0, "D": -1.0}


@dataclass(frozen=True)
class Orbit:
    """A circular orbit as the simulator needs it.

    Attributes
    ----------
    period : float
        Orbital period [s].
    phase : float
        Argument of latitude at the start of the record, counted from the Sun's
        projection on the orbit plane [rad].
    beta : float
        Sun elevation above the orbit plane [rad].
    radius : float
        Orbit radius [m], from ``period`` by Kepler's third law.
    """

    period: float
    phase: float
    beta: float
    radius: float

    def argument(self, tau: NDArray[np.float64]) -> NDArray[np.float64]:
        """Argument of latitude ``u`` [rad] at elapsed times ``tau`` [s]."""
        return self.phase + 2.0 * np.pi * tau / self.period

    def half_eclipse(self) -> float | None:
        """Half-width ``h`` of the shadow arc about ``u = π`` [rad]; None without eclipses."""
        c = np.sqrt(1.0 - (EARTH_RADIUS / self.radius) ** 2) / np.cos(self.beta)
        return float(np.arccos(c)) if c < 1.0 else None


def draw_orbit(rng: np.random.Generator) -> Orbit:
    """Draw the orbit of a day: period, phase and Sun elevation ``|β| <= 75°``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Random source (the simulator's orbit stream).

    Returns
    -------
    Orbit
        With ``|β|`` above ~68° (about one day in ten) the orbit is in full sun.
    """
    period = float(rng.uniform(*ORBIT_PERIOD_RANGE))
    phase = float(rng.uniform(0.0, 2.0 * np.pi))
    beta = float(np.deg2rad(rng.uniform(-75.0, 75.0)))
    radius = float((EARTH_GM * (period / (2.0 * np.pi)) ** 2) ** (1.0 / 3.0))
    return Orbit(period, phase, beta, radius)


def smooth_ramp(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """0 for ``x <= −1/2``, 1 for ``x >= 1/2``, ``(1 + sin πx)/2`` between."""
    return 0.5 * (1.0 + np.sin(np.pi * np.clip(x, -0.5, 0.5)))


def shadow(tau: NDArray[np.float64], orbit: Orbit, penumbra: float = PENUMBRA) -> NDArray:
    """Fraction of the Sun hidden at ``tau`` [s]: 1 in the umbra, 0 in sunlight.

    Parameters
    ----------
    tau : ndarray
        Elapsed time since the start of the record [s].
    orbit : Orbit
    penumbra : float
        Width of the entry and exit ramps [s].

    Returns
    -------
    ndarray
        The time inside the shadow arc, ``(h − |u − π|)/ω``, through a
        :func:`smooth_ramp` of width ``penumbra``, centred on the geometric shadow
        edge (the eclipse epochs of :func:`eclipse_epochs`); 0 without eclipses.
    """
    h = orbit.half_eclipse()
    if h is None:
        return np.zeros_like(tau)
    omega = 2.0 * np.pi / orbit.period
    phi = np.mod(orbit.argument(tau), 2.0 * np.pi) - np.pi  # in [−π, π): 0 mid-eclipse
    return smooth_ramp((h - np.abs(phi)) / omega / penumbra)


def eclipse_epochs(orbit: Orbit, t0: float, duration: float) -> list[dict[str, float]]:
    """Entry and exit epochs of the eclipses that touch ``[t0, t0 + duration]``.

    Returns
    -------
    list of dict
        ``entry`` and ``exit`` [s, GPS]: the centres of the ramps (the geometric
        shadow edges); an eclipse cut by the record's start or end keeps its
        epoch outside the record.
    """
    h = orbit.half_eclipse()
    if h is None:
        return []
    omega = 2.0 * np.pi / orbit.period
    out = []
    k = int(np.floor((orbit.phase - np.pi - h) / (2.0 * np.pi))) - 1
    while True:
        entry = (np.pi - h + 2.0 * np.pi * k - orbit.phase) / omega
        k += 1
        exit_ = entry + 2.0 * h / omega
        if entry > duration:
            return out
        if exit_ >= 0.0:
            out.append({"entry": t0 + float(entry), "exit": t0 + float(exit_)})


def draw_storm(rng: np.random.Generator, duration: float) -> dict[str, float]:
    """Draw a geomagnetic storm: onset, rise and decay time, density factor.

    Returns
    -------
    dict
        ``onset_s`` [s from the start, in the first half of the record],
        ``rise_s`` (2–5 h), ``decay_s`` (e-folding, 4–10 h), ``factor`` (2–4,
        the density at the peak relative to the quiet one).
    """
    return {
        "onset_s": float(rng.uniform(0.1, 0.5) * duration),
        "rise_s": float(rng.uniform(2.0, 5.0) * 3600.0),
        "decay_s": float(rng.uniform(4.0, 10.0) * 3600.0),
        "factor": float(rng.uniform(2.0, 4.0)),
    }


def storm_factor(tau: NDArray[np.float64], storm: dict[str, float] | None) -> NDArray:
    """Density multiplier of a storm.

    Parameters
    ----------
    tau : ndarray
        Elapsed time [s].
    storm : dict or None
        :func:`draw_storm`'s parameters; None: no storm.

    Returns
    -------
    ndarray
        1 before ``onset_s``, a smooth (raised-sine) rise to ``factor`` over
        ``rise_s``, then ``1 + (factor − 1)·exp(−(tau − peak)/decay_s)``.
    """
    if storm is None:
        return np.ones_like(tau)
    x = (tau - storm["onset_s"]) / storm["rise_s"]
    rise = smooth_ramp(x - 0.5)
    after = tau - storm["onset_s"] - storm["rise_s"]
    decay = np.exp(-np.maximum(after, 0.0) / storm["decay_s"])
    return 1.0 + (storm["factor"] - 1.0) * rise * decay


def draw_thrusters(
    rng: np.random.Generator, duration: float, dt: float, t0: float
) -> list[dict[str, Any]]:
    """Draw thruster pulses: Poisson count, uniform epochs on the sample grid.

    Returns
    -------
    list of dict
        Sorted by epoch: ``epoch`` [s, GPS] and ``epoch_s`` [s from the start]
        of the pulse start, ``length`` [s], ``axis`` (x, y or z), ``amplitude``
        [m/s², signed, peak].
    """
    rate = rng.uniform(*THRUSTER_RATE) / 3600.0
    n = int(rng.poisson(rate * duration))
    steps = int(duration / dt)
    starts = np.sort(rng.integers(0, max(steps, 1), n)) * dt
    lengths = rng.integers(THRUSTER_LENGTH[0], THRUSTER_LENGTH[1] + 1, n)
    axes = rng.integers(0, 3, n)
    lo, hi = np.log10(THRUSTER_AMPLITUDE)
    amps = 10.0 ** rng.uniform(lo, hi, n) * rng.choice([-1.0, 1.0], n)
    return [
        {
            "epoch": t0 + float(s),
            "epoch_s": float(s),
            "length": float(ln),
            "axis": "xyz"[int(ax)],
            "amplitude": float(a),
        }
        for s, ln, ax, a in zip(starts, lengths, axes, amps, strict=True)
    ]


def thruster_series(tau: NDArray[np.float64], pulses: list[dict[str, Any]]) -> NDArray:
    """Acceleration of thruster pulses on the SRF axes.

    Parameters
    ----------
    tau : ndarray, shape (n,)
        Elapsed time [s], increasing.
    pulses : list of dict
        As :func:`draw_thrusters` returns them.

    Returns
    -------
    ndarray, shape (n, 3)
        [m/s²]; each pulse is a half sine, ``amplitude·sin(π (tau − epoch_s)/length)``
        for ``epoch_s <= tau <= epoch_s + length`` (zero at both ends).
    """
    out = np.zeros((tau.size, 3))
    for p in pulses:
        lo, hi = np.searchsorted(tau, [p["epoch_s"], p["epoch_s"] + p["length"]])
        x = (tau[lo:hi] - p["epoch_s"]) / p["length"]
        out[lo:hi, "xyz".index(p["axis"])] += p["amplitude"] * np.sin(np.pi * x)
    return out


def draw_forces(rng: np.random.Generator) -> dict[str, Any]:
    """Draw the force-model parameters of a day (drag, SRP, angular signal)."""
    lo, hi = np.log10(DRAG_RANGE)
    return {
        "drag": {
            "level": float(10.0 ** rng.uniform(lo, hi)),
            "once_per_rev": float(rng.uniform(0.2, 0.4)),
            "twice_per_rev": float(rng.uniform(0.03, 0.1)),
            "bulge_phase": float(rng.uniform(0.3, 0.8)),  # density peak after the subsolar point
            "trend_per_day": float(rng.uniform(-0.4, 0.4)),
            "daily_amplitude": float(rng.uniform(0.0, 0.1)),
            "daily_phase": float(rng.uniform(0.0, 2.0 * np.pi)),
            "cross_track": float(rng.uniform(0.02, 0.06)),
            "node_phase": float(rng.uniform(0.0, 2.0 * np.pi)),
        },
        "srp": {"level": float(rng.uniform(*SRP_RANGE)), "earth_fraction": 0.1},
        "angular": {
            "once": rng.uniform(*ANGULAR_ONCE, 3).tolist(),
            "twice": rng.uniform(*ANGULAR_TWICE, 3).tolist(),
            "phase_once": rng.uniform(0.0, 2.0 * np.pi, 3).tolist(),
            "phase_twice": rng.uniform(0.0, 2.0 * np.pi, 3).tolist(),
        },
    }


def drag_density(
    tau: NDArray[np.float64], u: NDArray[np.float64], drag: dict[str, float], beta: float
) -> NDArray[np.float64]:
    """Relative density along the orbit (1 on average on a quiet day without trend).

    Parameters
    ----------
    tau : ndarray
        Elapsed time [s].
    u : ndarray
        Argument of latitude from the Sun's projection [rad].
    drag : dict
        ``draw_forces()["drag"]``.
    beta : float
        Sun elevation above the orbit plane [rad].

    Returns
    -------
    ndarray
        ``exp(k·(tau/day − 1/2))·(1 + A_d sin(2π tau/day + φ_d))`` times
        ``1 + A1 cos β cos(u − u_b) + A2 cos 2(u − u_b)``: the day/night contrast
        fades as the orbit turns to the terminator (``β → 90°``).
    """
    day = 86400.0
    slow = np.exp(drag["trend_per_day"] * (tau / day - 0.5)) * (
        1.0 + drag["daily_amplitude"] * np.sin(2.0 * np.pi * tau / day + drag["daily_phase"])
    )
    x = u - drag["bulge_phase"]
    orbit = 1.0 + drag["once_per_rev"] * np.cos(beta) * np.cos(x)
    return slow * (orbit + drag["twice_per_rev"] * np.cos(2.0 * x))


@dataclass(frozen=True)
class Environment:
    """True signals of a simulated day.

    Attributes
    ----------
    linear : ndarray, shape (n, 3)
        True non-gravitational acceleration in the SRF [m/s²].
    angular : ndarray, shape (n, 3)
        Orbit-periodic angular acceleration (no offset, no noise) [rad/s²].
    truth : dict
        Orbit, eclipses, force parameters, storm and thruster pulses (JSON-ready).
    """

    linear: NDArray[np.float64]
    angular: NDArray[np.float64]
    truth: dict[str, Any]


def environment(
    tau: NDArray[np.float64],
    *,
    t0: float,
    satellite: str,
    orbit_rng: np.random.Generator,
    storm_rng: np.random.Generator | None = None,
    thruster_rng: np.random.Generator | None = None,
    dt: float = 1.0,
    duration: float | None = None,
) -> Environment:
    """The true linear and angular accelerations of a day on the grid ``tau``.

    Parameters
    ----------
    tau : ndarray, shape (n,)
        Elapsed time since ``t0`` [s], increasing.
    t0 : float
        GPS seconds of ``tau = 0`` [s].
    satellite : {"A", "B", "C", "D"}
        Sets the flight direction of SRF x (:data:`FORWARD`).
    orbit_rng : numpy.random.Generator
        Source of the orbit and force parameters.
    storm_rng, thruster_rng : numpy.random.Generator, optional
        With a generator, a storm is drawn (:func:`draw_storm`) or thruster
        pulses (:func:`draw_thrusters`); None leaves them out.
    dt : float
        Sampling interval [s] (thruster epochs fall on the grid).
    duration : float, optional
        Record length [s]; default ``tau[-1] + dt``.

    Returns
    -------
    Environment
    """
    duration = float(tau[-1] + dt) if duration is None else duration
    orbit = draw_orbit(orbit_rng)
    forces = draw_forces(orbit_rng)
    storm = draw_storm(storm_rng, duration) if storm_rng is not None else None
    pulses = draw_thrusters(thruster_rng, duration, dt, t0) if thruster_rng is not None else []
    u = orbit.argument(tau)
    cb, sb = np.cos(orbit.beta), np.sin(orbit.beta)
    drag = forces["drag"]
    d = drag["level"] * drag_density(tau, u, drag, orbit.beta) * storm_factor(tau, storm)
    sun = 1.0 - shadow(tau, orbit)
    p = forces["srp"]["level"] * sun
    gain = SRP_AXIS_GAIN
    # RTN components (radial up, along-track, orbit normal); the SRP points away from the Sun
    along = -d + gain[0] * p * cb * np.sin(u)
    normal = -drag["cross_track"] * d * np.cos(u - drag["node_phase"]) - gain[1] * p * sb
    albedo = (
        forces["srp"]["earth_fraction"] * forces["srp"]["level"] * np.maximum(cb * np.cos(u), 0)
    )
    radial = -gain[2] * p * cb * np.cos(u) + albedo
    fwd = FORWARD[satellite]
    linear = np.column_stack([fwd * along, fwd * normal, -radial])
    if pulses:
        linear += thruster_series(tau, pulses)
    ang = forces["angular"]
    angular = np.column_stack(
        [
            ang["once"][i] * np.cos(u + ang["phase_once"][i])
            + ang["twice"][i] * np.cos(2.0 * u + ang["phase_twice"][i])
            for i in range(3)
        ]
    )
    truth = {
        "orbit_period": orbit.period,
        "orbit_phase": orbit.phase,
        "orbit_radius": orbit.radius,
        "beta_angle_deg": float(np.rad2deg(orbit.beta)),
        "penumbra_s": PENUMBRA,
        "eclipses": eclipse_epochs(orbit, t0, duration),
        "forward": fwd,
        **forces,
        "storm": None if storm is None else {**storm, "onset": t0 + storm["onset_s"]},
        "thrusters": pulses,
    }
    return Environment(linear, angular, truth)
