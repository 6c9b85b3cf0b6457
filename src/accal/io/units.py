"""Declared units of run-file columns, and their factors to SI.

A run file may say the unit of each column (Parquet ``accal.units`` metadata, a CSV's
``-metadata.json`` sidecar or ``# units:`` line).  accal works in SI (m/s², s, rad): a column declared in another
unit it knows is converted (with a warning that says so), a column declared in a
unit it does not know is refused, and a column whose unit is not declared is taken
as SI.  QA: m_y in ``g`` was read as m/s², a 9.8× wrong acceleration with no
warning; θ in ``mrad`` was taken for degrees.

The spelling is forgiving: a comment after the unit (``"s (GPS)"``, ``"m/s^2 raw"``)
is ignored, ``µ``/``μ``/``u`` are the same prefix, and ``m/s^2``, ``m/s2``,
``m s^-2``, ``m.s-2``, ``m/s/s`` and ``m/s²`` are one unit.
"""

from __future__ import annotations

import math
import re

#: Standard gravity [m/s²] (CGPM 1901), for accelerations declared in g.
STANDARD_GRAVITY = 9.80665

#: SI prefixes accal converts (lower case only: ``M`` is mega, not milli).
_PREFIX = {"k": 1e3, "m": 1e-3, "u": 1e-6, "n": 1e-9, "p": 1e-12}
_PREFIX_WORDS = (("milli", "m"), ("micro", "u"), ("nano", "n"), ("kilo", "k"))

#: Base units per kind and their factors to SI: acceleration [m/s²], time [s], angle [rad].
BASES: dict[str, dict[str, float]] = {
    "acceleration": {"m/s^2": 1.0, "g": STANDARD_GRAVITY, "gal": 1e-2},
    "time": {"s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0},
    "angle": {
        "rad": 1.0,
        "deg": math.pi / 180.0,
        "arcmin": math.pi / 10800.0,
        "arcsec": math.pi / 648000.0,
    },
}
#: Bases that take a prefix (mm/s², mGal, ms, mrad; not "mmin" or "mdeg").
_PREFIXED = {"m/s^2", "g", "gal", "s", "rad"}

#: The SI unit of each kind, as accal writes it.
SI = {"acceleration": "m/s^2", "time": "s", "angle": "rad"}

_ALIASES = {
    "sec": "s",
    "second": "s",
    "seconds": "s",
    "hour": "h",
    "hours": "h",
    "hr": "h",
    "day": "d",
    "days": "d",
    "radian": "rad",
    "radians": "rad",
    "degree": "deg",
    "degrees": "deg",
    "°": "deg",
    "g0": "g",
    "gn": "g",
}
# m/s^2 spellings: m/s2, m s^-2, m.s-2, m*s^-2, m/s/s, ms^-2 (after spaces are dropped)
_ACC = re.compile(r"^m(?:/s\^?2|/s/s|[.*]?s\^?-2)$")


def _base(text: str) -> str:
    u = text.lower()
    if _ACC.match(u):
        return "m/s^2"
    return _ALIASES.get(u, u)


def _factor(text: str, kind: str) -> float | None:
    """Factor of one spelling: a base unit, or a lower-case SI prefix and a base."""
    u = text.replace("µ", "u").replace("μ", "u").replace("²", "^2").replace("⁻", "-")
    u = u.replace("**", "^").replace(" ", "")
    for word, short in _PREFIX_WORDS:  # milli-g, milligal, micro-rad
        if u.lower().startswith(word):
            u = short + u[len(word) :].lstrip("-")
            break
    bases = BASES[kind]
    b = _base(u)
    if b in bases:
        return bases[b]
    if len(u) > 1 and u[0] in _PREFIX:  # case-sensitive: "Mm/s^2", "Ms", "MGal" are not milli
        b = _base(u[1:])
        if b in bases and b in _PREFIXED:
            return _PREFIX[u[0]] * bases[b]
    return None


def si_factor(unit: str | None, kind: str) -> float | None:
    """Factor from a declared unit to SI, or None for a unit of another or no known kind.

    Parameters
    ----------
    unit : str or None
        As declared; None, ``""`` and ``"unknown"`` mean not declared (factor 1).
    kind : {"acceleration", "time", "angle"}

    Returns
    -------
    float or None
        ``value_SI = factor · value``.
    """
    if unit is None:
        return 1.0
    text = re.split(r"[(\[]", str(unit), maxsplit=1)[0].strip()
    if not text or text.lower() == "unknown":
        return 1.0
    for candidate in (text, text.split()[0]):  # the whole unit, or its first word
        f = _factor(candidate, kind)
        if f is not None:
            return f
    return None


def known_units(kind: str) -> str:
    """The units of ``kind`` accal converts, for messages."""
    shown = {
        "acceleration": "m/s^2, mm/s^2, um/s^2, nm/s^2, g, mg, ug, Gal, mGal, uGal",
        "time": "s, ms, us, ns, min, h, d",
        "angle": "rad, mrad, urad, deg, arcmin, arcsec",
    }
    return shown[kind]
