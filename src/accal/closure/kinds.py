"""The kinds of effect closure looks for, each with the properties the search needs.

A :class:`Kind` carries everything the rest of :mod:`accal.closure` and the
pipelines need to know about one kind of effect, so that no other module compares
effect names:

* ``builder``: proposes the best member of the family on the current residual
  (:mod:`accal.closure.candidates`, :mod:`~accal.closure.periodic`,
  :mod:`~accal.closure.couplings`, :mod:`~accal.closure.platform`);
* ``instrument``: whether an accepted effect is an instrument error, removed from
  the calibrated series by ``grace-bias`` (periodic terms are reported, never
  removed: at orbit frequencies they are as likely real non-gravitational signal);
* ``needs_reference``: whether the effect can only be told from the real signal on
  ``raw − reference`` (a slow polynomial or exponential drift is indistinguishable
  from the slow variation of drag on one raw axis);
* ``ident_min``: the share of the candidate's variation (beyond the bias model)
  that must lie outside the *signal* part of the null model for the data to tell
  it from the signal (:func:`accal.closure.validation.identifiability`);
* ``last_resort``: tried only after every significant candidate of the other kinds
  was validated or rejected (a free-frequency sinusoid fits any narrow-band
  structure, a channel's included: a heater cycle coupled in through a temperature
  came out as a line at the heater's period; the coupling names the cause);
* ``bound``: the physically plausible range of the coefficient
  (:func:`plausible`); an effect outside it is reported, not removed.

Plausibility bounds (documented in ``docs/closure.md``; generous by design: they
catch a regression that has fitted something other than the effect, e.g. a
"0.87 m lever arm" coupling to an orbit-periodic angular acceleration):

* bias step: at most :data:`STEP_MAX` (a fifth of the SuperSTAR ±5e-5 m/s²
  measurement range, Touboul et al. 1999: a larger jump is a mode change, not a
  calibration parameter) and at most twice the peak-to-peak residual of the base
  fit (a step larger than everything in the data is compensating for something);
* coupling to an angular acceleration [rad/s²]: a lever arm of at most
  :data:`LEVER_ARM_MAX` (the proof mass sits within ~0.1 mm of the centre of mass
  after the GRACE/GRACE-FO CoM calibration, Wang et al. 2010; Swarm's offset is
  of order cm);
* coupling to a temperature [K]: at most :data:`THERMAL_MAX` per K (SuperSTAR
  bias thermal sensitivities are of order 1e-9–1e-8 m/s²/K, Flury et al. 2008;
  the bound is 100× that);
* any other coupling, drift, exponential or settling shape: its contribution
  over the record at most :data:`AMPLITUDE_MAX`;
* scale error: ``|δs| ≤`` :data:`SCALE_MAX` (GRACE TN-02 scale factors are within
  7 % of 1);
* angle offset or angle scale of the platform: at most :data:`ANGLE_MAX`.

References
----------
P. Touboul et al., Acta Astronaut. 45 (1999) 605-617 (SuperSTAR, GRACE
accelerometer). F. Flury, S. Bettadpur, B. D. Tapley, Adv. Space Res. 42 (2008)
1414-1423 (GRACE accelerometer data, thermal effects). F. Wang, S. Bettadpur,
H. Save, G. Kruizinga, J. Spacecraft Rockets 47 (2010) 371-379 (GRACE CoM
calibration).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.timescale import gps_to_gps_calendar

if TYPE_CHECKING:
    from accal.closure.candidates import Context, Proposal

__all__ = [
    "EFFECT_NAMES",
    "Kind",
    "channel_class",
    "effect_label",
    "instrument_kinds",
    "kind_of",
    "kinds",
    "plausible",
    "unit_class",
    "unit_of",
]

#: Largest plausible bias step [m/s²].
STEP_MAX = 1e-5
#: Largest plausible lever arm of a coupling to an angular acceleration [m].
LEVER_ARM_MAX = 0.1
#: Largest plausible thermal sensitivity [m/s² per K].
THERMAL_MAX = 1e-6
#: Largest plausible contribution of a drift, coupling or shape over the record [m/s²].
AMPLITUDE_MAX = 1e-5
#: Largest plausible relative scale error.
SCALE_MAX = 0.2
#: Largest plausible angle offset [rad] or angle scale error [rad/rad] of the platform.
ANGLE_MAX = 0.05

#: Default share of a candidate's variation (beyond the bias model) outside the signal model.
IDENT_MIN = 0.002
#: ``ident_min`` of the platform's in-period bias shapes.  A direction-dependent
#: settling shape with 1.2 % of its variation outside the per-period signal stood in
#: for a lagged temperature coupling of 3e-8 m/s²/K and moved every period's a_Z by
#: 9.4σ (error 4.7e-12 -> 1.8e-10 m/s², closure-detection seed 7301): so little
#: outside the signal leaves the coefficient resting on the remainder, and whatever
#: else the remainder holds moves the signal.  Real transients drawn in
#: ``tests/closure/test_demod.py`` had 4.5-59 % (direction) and 95 % (common): the
#: threshold sits between, a margin of ~1.5x below the lowest (measured, not derived).
SHAPE_IDENT_MIN = 0.03


@dataclass(frozen=True)
class Kind:
    """One kind of effect and its properties (see the module notes).

    Attributes
    ----------
    name : str
        Name in results and ``closure.json``.
    builder : callable or None
        ``f(Context) -> list[Proposal]`` (None for ``unexplained``).
    instrument : bool
        Removed from the calibrated series when accepted (``grace-bias``).
    needs_reference : bool
        Only identifiable on ``raw − reference``.
    ident_min : float
        Least share of the candidate's variation outside the signal model.
    description : str
        One line for reports.
    last_resort : bool
        Validated only after the significant candidates of the other kinds.
    """

    name: str
    builder: Callable[[Context], list[Proposal]] | None
    instrument: bool
    needs_reference: bool = False
    ident_min: float = IDENT_MIN
    description: str = ""
    last_resort: bool = False


def _kinds() -> dict[str, Kind]:
    from accal.closure import candidates as c
    from accal.closure import couplings, periodic, platform

    ks = [
        Kind("quadratic_drift", c.quadratic_drift, True, True, description="(t − t0)² drift"),
        Kind("cubic_drift", c.cubic_drift, True, True, description="(t − t0)³ drift"),
        Kind(
            "exponential_drift",
            c.exponential_drift,
            True,
            True,
            description="exponential settling from the start of the record",
        ),
        Kind("bias_step", c.bias_step, True, description="bias step at an unknown epoch"),
        Kind(
            "periodic",
            periodic.periodic,
            False,
            ident_min=0.5,
            last_resort=True,
            description="sinusoids: orbit harmonics and spectral lines (reported, not removed)",
        ),
        Kind(
            "auxiliary",
            couplings.auxiliary,
            True,
            description="coupling to a channel of the data (lag, first-order response)",
        ),
        Kind(
            "scale",
            couplings.scale,
            True,
            True,
            description="scale error: residual proportional to the reference",
        ),
        Kind("angle_offset", platform.angle_offset, True, description="platform angle error"),
        Kind(
            "intra_period_shape",
            platform.intra_period_shape,
            True,
            ident_min=SHAPE_IDENT_MIN,
            description="bias shape repeating after every rotation",
        ),
        Kind("unexplained", None, False, description="structure no candidate explains"),
    ]
    return {k.name: k for k in ks}


_KINDS: dict[str, Kind] = {}


def kinds() -> dict[str, Kind]:
    """Every :class:`Kind` by name (built on first use: the builders import this module)."""
    if not _KINDS:
        _KINDS.update(_kinds())
    return dict(_KINDS)


#: Names an effect can carry in a result (``closure.json``).
EFFECT_NAMES = (
    "quadratic_drift",
    "cubic_drift",
    "exponential_drift",
    "bias_step",
    "periodic",
    "auxiliary",
    "scale",
    "angle_offset",
    "intra_period_shape",
    "unexplained",
)


def kind_of(name: str) -> Kind:
    """The :class:`Kind` called ``name`` (KeyError if unknown)."""
    return kinds()[name]


def instrument_kinds() -> tuple[str, ...]:
    """Names of the kinds removed from the calibrated series."""
    return tuple(n for n in EFFECT_NAMES if kind_of(n).instrument)


def unit_class(unit: str) -> str:
    """``"temperature"``, ``"angular"`` (an angular acceleration) or ``"other"`` for a unit."""
    u = (unit or "").replace(" ", "").lower()
    if u in ("k", "kelvin", "degc", "°c", "c", "celsius", "deg_c"):
        return "temperature"
    if u in ("rad/s^2", "rad/s2", "rad s-2", "rads-2", "rad/s**2"):
        return "angular"
    return "other"


def channel_class(options: dict[str, Any], channel: str) -> str:
    """:func:`unit_class` of a coupling's channel (its square: the channel's) by
    ``options["channel_units"]``."""
    units = dict(options.get("channel_units", {}))
    return unit_class(units.get(str(channel).removesuffix("^2"), ""))


def plausible(prop: Proposal, coef: float, ctx: Context, extent: float) -> tuple[bool, str]:
    """Whether coefficient ``coef`` of ``prop`` is physically plausible (see the notes).

    Parameters
    ----------
    prop : Proposal
        The candidate.
    coef : float
        Its fitted coefficient (largest in magnitude over the data channels) in SI units.
    ctx : Context
        The search state (``options["residual_ptp"]``: peak-to-peak of the base
        residual [m/s²]; ``options["channel_units"]``: unit of each channel).
    extent : float
        Peak-to-peak of the candidate's column over the used samples (its
        contribution over the record is ``|coef|·extent``).

    Returns
    -------
    (bool, str)
        Plausible, and if not, why (one clause).
    """
    name = prop.name
    amp = abs(coef) * extent
    if not np.isfinite(coef):
        return False, "coefficient not finite"
    if name == "bias_step":
        ptp = float(ctx.options.get("residual_ptp", np.inf))
        if abs(coef) > STEP_MAX:
            return False, f"step of {abs(coef):.2g} m/s² exceeds {STEP_MAX:g} m/s² (a mode change)"
        if abs(coef) > 2.0 * ptp:
            return False, f"step of {abs(coef):.2g} m/s² exceeds twice the residual's range"
        return True, ""
    if name == "scale":
        if abs(coef) > SCALE_MAX:
            return False, f"scale error {coef:+.3g} beyond ±{SCALE_MAX:g}"
        return True, ""
    if name == "angle_offset":
        if abs(coef) > ANGLE_MAX:
            return False, f"angle error {abs(coef):.3g} beyond {ANGLE_MAX:g} rad"
        return True, ""
    if name == "auxiliary":
        channel = str(prop.channel or "")
        squared = channel.endswith("^2")
        cls = channel_class(ctx.options, channel)
        if cls == "angular" and not squared and abs(coef) > LEVER_ARM_MAX:
            return False, (
                f"a lever arm of {abs(coef):.3g} m (coupling to an angular acceleration) "
                f"exceeds {LEVER_ARM_MAX:g} m"
            )
        if cls == "temperature" and not squared and abs(coef) > THERMAL_MAX:
            return False, f"{abs(coef):.3g} m/s² per K exceeds {THERMAL_MAX:g} m/s² per K"
    if name == "periodic":
        return True, ""
    if amp > AMPLITUDE_MAX:
        return False, f"its contribution over the record, {amp:.3g} m/s², exceeds {AMPLITUDE_MAX:g}"
    return True, ""


def unit_of(prop: Proposal | Any, channel_units: dict[str, str]) -> str:
    """The unit of ``prop``'s reported coefficient (SI, machine-readable)."""
    name = prop.name
    if name == "auxiliary":
        ch = str(prop.channel or "")
        u = channel_units.get(ch.removesuffix("^2"), "") or "unit"
        return f"m/s^2/({u})^2" if ch.endswith("^2") else f"m/s^2/({u})"
    return {
        "quadratic_drift": "m/s^4",
        "cubic_drift": "m/s^5",
        "scale": "1",
        "angle_offset": "rad",
    }.get(name, "m/s^2")


def effect_label(e: Any) -> str:
    """A short label of an effect for a model string (``bias_step@<GPS calendar>GPS``, ...)."""
    if e.name == "bias_step" and e.epoch is not None:
        # the GPS calendar, like the table's `date` (GRACE days are GPS days)
        gps = np.datetime_as_string(gps_to_gps_calendar(e.epoch).astype("datetime64[s]"))
        return f"bias_step@{gps}GPS"
    if e.name == "auxiliary":
        return f"auxiliary({e.channel})"
    if e.name == "exponential_drift" and e.tau is not None:
        return f"exponential_drift(tau={e.tau:.0f} s)"
    if e.name == "periodic" and e.frequency is not None:
        return f"periodic({e.frequency:.4g} Hz)"
    return e.name
