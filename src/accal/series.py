"""The one data model shared by readers, estimators and writers.

An :class:`AccSeries` is a time series of accelerometer samples in SI units
(time in GPS seconds, accelerations in m/s²) with per-sample quality flags,
auxiliary channels carried along untouched, free-form metadata namespaced by
source (``meta["grace"]``, ``meta["gracefo"]``, ``meta["table"]``), the reader's
findings (:class:`ReadReport`) and a processing history.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Units of the fields, written into every output file's metadata.
UNITS = {
    "time": "s (GPS seconds since 2000-01-01 12:00:00 GPS)",
    "acc": "m/s^2",
}


@dataclass(frozen=True)
class ReadReport:
    """What a reader found and repaired in one input file.

    Attributes
    ----------
    n_records_header : int or None
        Record count announced by the header (None if the format has none).
    n_rows : int
        Data rows parsed.
    n_duplicates : int
        Rows dropped because their epoch repeated an earlier one (first kept).
    n_out_of_order : int
        Rows that were not in increasing time order (the series was sorted).
    n_flagged : int
        Samples marked invalid by the source's quality flags.
    n_gaps : int
        Number of gaps (time steps larger than 1.5 nominal steps).
    gap_seconds : float
        Total length of the gaps [s].
    nominal_step : float
        Median sampling interval [s].
    warnings : tuple of str
        Human-readable findings (short records, repaired quirks, ...).
    """

    n_records_header: int | None = None
    n_rows: int = 0
    n_duplicates: int = 0
    n_out_of_order: int = 0
    n_flagged: int = 0
    n_gaps: int = 0
    gap_seconds: float = 0.0
    nominal_step: float = float("nan")
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """Return the report as a plain dict (JSON-serialisable)."""
        d = dataclasses.asdict(self)
        d["warnings"] = list(self.warnings)
        return d


@dataclass(frozen=True)
class AccSeries:
    """Accelerometer time series in SI units.

    Attributes
    ----------
    time : ndarray of float64, shape (n,)
        Sample epochs, strictly increasing [s, GPS seconds since 2000-01-01 12:00:00].
    acc : ndarray of float64, shape (n, k)
        Linear accelerations, one column per axis [m/s²].
    axes : tuple of str
        Axis names of the columns of ``acc`` (subset of ``("x", "y", "z")``).
    valid : ndarray of bool, shape (n,)
        True where the source's quality information allows the sample to be used
        (the reader documents which flags make a sample invalid).
    quality : ndarray of uint32, shape (n,)
        Source quality bitmask, unchanged (e.g. GRACE ``qualflg``, bit 0 = LSB).
    aux : dict of str to ndarray, shape (n,)
        Auxiliary channels carried along (temperatures, flags, ...), units in ``units``.
    frame : str
        Reference frame of the axes (e.g. ``"SRF"``).
    satellite : str
        Satellite identifier (``"GRACE-A"``, ``"GRACE-FO-C"``, ``"Swarm-A"``, ...).
    units : dict of str to str
        Units of ``time``, ``acc`` and every auxiliary channel.
    meta : dict
        Everything else read from the file, unchanged, namespaced by source.
    report : ReadReport
        The reader's findings.
    history : tuple of str
        One entry per processing step, appended after the step succeeded.
    """

    time: NDArray[np.float64]
    acc: NDArray[np.float64]
    axes: tuple[str, ...] = ("x", "y", "z")
    valid: NDArray[np.bool_] | None = None
    quality: NDArray[np.uint32] | None = None
    aux: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    frame: str = "SRF"
    satellite: str = ""
    units: dict[str, str] = field(default_factory=lambda: dict(UNITS))
    meta: dict[str, Any] = field(default_factory=dict)
    report: ReadReport = field(default_factory=ReadReport)
    history: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=np.float64)
        a = np.asarray(self.acc, dtype=np.float64)
        if t.ndim != 1:
            raise ValueError(f"time must be 1-D, got shape {t.shape}")
        if a.ndim == 1:
            a = a[:, None]
        if a.ndim != 2 or a.shape[0] != t.shape[0]:
            raise ValueError(
                f"acc must have shape (n, k) with n = len(time) = {t.shape[0]}, got {a.shape}"
            )
        if len(self.axes) != a.shape[1]:
            raise ValueError(f"axes {self.axes} do not match acc with {a.shape[1]} columns")
        bad = [ax for ax in self.axes if ax not in ("x", "y", "z")]
        if bad:
            raise ValueError(f"axes must be among 'x', 'y', 'z', got {bad}")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("time must be strictly increasing")
        valid = np.ones(t.shape, dtype=bool) if self.valid is None else np.asarray(self.valid, bool)
        quality = (
            np.zeros(t.shape, dtype=np.uint32)
            if self.quality is None
            else np.asarray(self.quality, dtype=np.uint32)
        )
        for name, arr in (("valid", valid), ("quality", quality)):
            if arr.shape != t.shape:
                raise ValueError(f"{name} must have shape {t.shape}, got {arr.shape}")
        aux = {}
        for k, v in self.aux.items():
            v = np.asarray(v)
            if v.shape != t.shape:
                raise ValueError(
                    f"auxiliary channel {k!r} must have shape {t.shape}, got {v.shape}"
                )
            aux[k] = v
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "acc", a)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "quality", quality)
        object.__setattr__(self, "aux", aux)
        object.__setattr__(self, "axes", tuple(self.axes))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def axis(self, name: str) -> NDArray[np.float64]:
        """Return the column of ``acc`` for axis ``name`` [m/s²]."""
        try:
            return self.acc[:, self.axes.index(name)]
        except ValueError:
            raise KeyError(f"axis {name!r} not in series (has {self.axes})") from None

    def replace(self, **changes: Any) -> AccSeries:
        """Return a copy with fields replaced (like :func:`dataclasses.replace`)."""
        return dataclasses.replace(self, **changes)

    def with_history(self, entry: str) -> AccSeries:
        """Return a copy with ``entry`` appended to the history."""
        return dataclasses.replace(self, history=(*self.history, entry))


#: Acceleration units accal converts to m/s² (factor), case-insensitive, first word.
ACC_UNIT_FACTORS = {
    "m/s^2": 1.0,
    "m/s2": 1.0,
    "m/s**2": 1.0,
    "m.s-2": 1.0,
    "m s-2": 1.0,
    "mm/s^2": 1e-3,
    "mm/s2": 1e-3,
    "um/s^2": 1e-6,
    "µm/s^2": 1e-6,
    "μm/s^2": 1e-6,
    "um/s2": 1e-6,
    "nm/s^2": 1e-9,
    "nm/s2": 1e-9,
    "gal": 1e-2,
    "mgal": 1e-5,
    "ugal": 1e-8,
    "µgal": 1e-8,
}


def acceleration_factor(unit: str | None) -> float | None:
    """Factor from ``unit`` to m/s² (None if ``unit`` is not an acceleration unit known here).

    The unit is the first word of the string (accal writes ``"m/s^2 (trend removed)"``);
    a missing unit or ``"unknown"`` is taken as m/s² (what accal's readers assume).
    """
    if unit is None:
        return 1.0
    word = unit.strip().split(" (")[0].strip().lower()
    if word in ("", "unknown"):
        return 1.0
    return ACC_UNIT_FACTORS.get(word)
