"""The real Swarm-A storm day with independently generated auxiliary channels and injected
instrument effects (for closure tests on measured data; nothing here imports ``accal``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._common import rng_for
from .effects import apply_effects, make_channels, parse_effect
from .tables import write_table

#: The real sample (ESA Level-2 ACCACAL v0304, Swarm A, 2024-05-11; PROVENANCE.md).
SWARM_FILE = "SW_A_ACCACAL_20240511_a_cal_x.csv.gz"
#: Columns of the sample, in order.
SWARM_COLUMNS = ("time_utc", "a_cal_x", "flag_val", "flag_thr")
#: GPS − UTC in 2024 [s].
GPS_MINUS_UTC_2024 = 18.0
#: Units written with the table.
SWARM_UNITS = {"a_cal_x": "m/s^2"}


@dataclass(frozen=True)
class SwarmDay:
    """The Swarm-A day with channels and effects, and its truth.

    Attributes
    ----------
    table : pandas.DataFrame
        ``time_utc`` (ISO-8601 strings, as in the sample), ``a_cal_x`` [m/s²] (the real
        values plus the injected bias, drift and effects), ``flag_val``, ``flag_thr``, then
        one column per channel [K].
    truth : dict
        ``a_cal_x_original`` (ndarray), ``t`` (seconds since the first sample), ``t0_utc``,
        ``t0_gps`` (GPS seconds of the first sample, UTC + 18 s), ``bias`` [m/s²] and
        ``drift`` [m/s³] injected (at ``t0``), ``effects`` (dicts with ``contribution``),
        ``effects_total``, ``channels`` (drawn parameters), ``orbit_period``, ``seed``.

    Unpacks as ``table, truth = swarm_day_with_channels(...)``.
    """

    table: Any  # pandas.DataFrame (pandas is imported where used)
    truth: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Any]:
        return iter((self.table, self.truth))


def swarm_day_with_channels(
    samples_dir: str | Path,
    seed: int,
    *,
    channels: Iterable[str] = ("temperature",),
    effects: Iterable[Sequence[Any]] = (),
    bias: float = 0.0,
    drift: float = 0.0,
    orbit_period: float | None = None,
) -> SwarmDay:
    """Load the real Swarm-A day and add generated channels and injected effects.

    Parameters
    ----------
    samples_dir : str or Path
        Directory holding ``SW_A_ACCACAL_20240511_a_cal_x.csv.gz`` (``data/samples``).
    seed : int
        Non-negative seed (channels and orbit period; effects are deterministic).
    channels : iterable of str
        Temperature-like channels to generate (those coupled to are added): ~293 K with an
        orbital cycle, a trend, a random walk, heater cycling and read-out noise
        (:func:`tests.indep._common.temperature_channel`).
    effects : iterable of tuples
        As for :func:`tests.indep.grace.grace_day` (:mod:`tests.indep.effects`), axis
        ``"x"`` only; ``("scale", "x", e)`` scales the real ``a_cal_x``.  E.g. a lagged
        coupling ``("coupling", "x", "temperature", 2e-9, 600.0, 300.0)``.
    bias, drift : float
        Added to ``a_cal_x`` as ``bias + drift · (t − t0)`` [m/s², m/s³].
    orbit_period : float, optional
        Of the channels' orbital cycle [s]; drawn in U(5550, 5700) by default (Swarm A
        flew at ~450 km in 2024: ~5600 s).

    Returns
    -------
    SwarmDay

    Raises
    ------
    FileNotFoundError
        The sample is not in ``samples_dir``.
    ValueError
        A bad effect or an axis other than x.
    """
    import pandas as pd

    path = Path(samples_dir) / SWARM_FILE
    src = pd.read_csv(path, dtype={"time_utc": str})
    if tuple(src.columns) != SWARM_COLUMNS:
        raise ValueError(f"{path}: expected columns {SWARM_COLUMNS}, got {tuple(src.columns)}")
    utc = pd.to_datetime(src["time_utc"]).to_numpy().astype("datetime64[ns]")
    t = (utc - utc[0]).astype(np.int64) / 1e9
    n = t.size
    dt = float(np.median(np.diff(t)))
    period = (
        float(orbit_period)
        if orbit_period is not None
        else float(rng_for(seed, "swarm-orbit").uniform(5550.0, 5700.0))
    )
    eff = [parse_effect(e, ("x",)) for e in effects]
    chan, chan_truth = make_channels(seed, channels, eff, n, dt, period)
    a0 = src["a_cal_x"].to_numpy(float)
    eff, total = apply_effects(eff, t, dt, period, a0[:, None], chan, 1)
    a = a0 + bias + drift * t + total[:, 0]
    table = pd.DataFrame(
        {
            "time_utc": src["time_utc"].to_numpy(),
            "a_cal_x": a,
            "flag_val": src["flag_val"].to_numpy(),
            "flag_thr": src["flag_thr"].to_numpy(),
        }
    )
    for name, (_, x) in chan.items():
        table[name] = x[-n:]
    t0_utc = np.datetime_as_string(utc[0].astype("datetime64[ms]"), unit="ms")
    gps0 = (utc[0] - np.datetime64("2000-01-01T12:00:00", "ns")).astype(np.int64) / 1e9
    truth = {
        "seed": int(seed),
        "a_cal_x_original": a0,
        "t": t,
        "t0_utc": str(t0_utc),
        "t0_gps": float(gps0 + GPS_MINUS_UTC_2024),
        "bias": float(bias),
        "drift": float(drift),
        "effects": [{**e, "axis": "x"} for e in eff],
        "effects_total": total[:, 0],
        "channels": chan_truth,
        "orbit_period": period,
        "units": {"a_cal_x": "m/s^2", "bias": "m/s^2", "drift": "m/s^3", "channels": "K"},
    }
    return SwarmDay(table=table, truth=truth)


def write_swarm_table(day: SwarmDay, path: str | Path, *, utc_as_timestamp: bool = True) -> Path:
    """Write a :class:`SwarmDay` table as Parquet or (gzipped) CSV with units.

    Parameters
    ----------
    day : SwarmDay
    path : str or Path
        ``.parquet``, ``.csv`` or ``.csv.gz``.
    utc_as_timestamp : bool
        Parquet: write ``time_utc`` as a timestamp column (ms, naive UTC) rather than text.

    Returns
    -------
    Path
    """
    import pandas as pd

    tab = day.table
    cols: dict[str, Any] = {c: tab[c].to_numpy() for c in tab.columns}
    if utc_as_timestamp:
        cols["time_utc"] = pd.to_datetime(tab["time_utc"]).to_numpy().astype("datetime64[ms]")
    units = dict(SWARM_UNITS)
    units.update({name: "K" for name in day.truth["channels"]})
    return write_table(path, cols, units)
