"""The seed and the random streams of a simulated GRACE day (:mod:`accal.simulate.grace`).

Random draws come from one seed, split into independent streams (:data:`STREAMS`):
the instrument drift, the orbit and forces, the noise, the angular and residual
columns, the gaps and flags, the storm, the thrusters, the reference noise, the
THR1B counters and each auxiliary channel have their own, so that adding a storm,
thrusters, a reference or an effect changes nothing else of the day.  Without an
explicit seed it is :func:`default_seed` of the date and satellite, so different
days and satellites differ while every run of the same day gives the same file; an
explicit seed is used as given.
"""

from __future__ import annotations

import hashlib

import numpy as np

#: Random streams of a day: ``numpy.random.default_rng([seed, STREAMS[name]])``.
STREAMS = {
    "instrument": 0,
    "orbit": 1,
    "noise": 2,
    "angular": 3,
    "residual": 4,
    "gaps": 5,
    "storm": 6,
    "thrusters": 7,
    "reference": 8,
    "thr1b": 9,
}


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


def stream(seed: int, name: str) -> np.random.Generator:
    """The random generator of one part of a simulated day (:data:`STREAMS`)."""
    return np.random.default_rng([seed, STREAMS[name]])
