"""The result of :func:`accal.api.close_loop`: :class:`Closure`.

Part of :mod:`accal.api` (see its docstring); split from one module for size.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.timescale import gps_to_utc

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    import pandas as pd


# ---------------------------------------------------------------------------
# closure


@dataclass
class Closure:
    """What closing the loop found (``closure.json`` entries), with a table of the effects.

    Attributes
    ----------
    entries : dict of str to dict
        Per axis (``grace-bias``) or per run (``demod``): the ``closure.json`` entry
        (:meth:`accal.closure.ClosureResult.to_dict` plus ``model``,
        ``estimates`` before/after, ``markdown``).
    orbit_period : float or None
        Orbit period of the orbit-signal model [s]: estimated from the data near the
        nominal one (as ``accal grace-bias --close-loop`` does), None where the
        closure had no orbit model (a reference, a short record, ``demod``).
    fit : BiasFit or Demodulation or None
        The refit with the extended model (set by :func:`fit_bias` /
        :func:`demodulate`).
    gps_time : bool
        Whether the epochs are GPS seconds (``grace-bias``; a ``demod`` run's
        times are seconds from its own origin: no UTC epochs then).
    """

    entries: dict[str, dict[str, Any]] = field(repr=False)
    orbit_period: float | None = None
    fit: Any = field(default=None, repr=False)
    gps_time: bool = field(default=True, repr=False)

    def __repr__(self) -> str:
        found = {k: [e.get("name") for e in v.get("effects", [])] for k, v in self.entries.items()}
        return f"Closure(effects={found}, model={self.model}, orbit_period={self.orbit_period})"

    @property
    def model(self) -> dict[str, str]:
        """Fitted model per entry, e.g. ``{"x": "poly1+bias_step@..."}``."""
        return {k: str(e.get("model", "")) for k, e in self.entries.items()}

    @property
    def markdown(self) -> str:
        """The closure report (``closure.md``'s sections)."""
        return "\n\n".join(str(e.get("markdown", "")) for e in self.entries.values())

    def to_dataframe(self) -> pd.DataFrame:
        """One row per effect found (``kind="effect"``) or unexplained structure.

        Columns: ``axis``, ``kind``, ``name``, ``channel``, ``coefficient`` (in
        ``unit``, SI), ``sigma``, ``significance`` (p-value), ``epoch`` (GPS
        seconds, steps), ``epoch_utc``, ``epoch_sigma`` [s] (half the epoch's
        interval, :mod:`accal.closure.epochprofile`), ``frequency`` [Hz], ``lag``,
        ``lag_sigma`` [s] (:mod:`accal.closure.lagprofile`), ``tau`` [s],
        ``instrument`` (removed from the calibrated series), ``model``.

        Examples
        --------
        >>> import accal
        >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
        >>> accal.close_loop(day).to_dataframe().columns[:4].tolist()
        ['axis', 'kind', 'name', 'channel']
        """
        import pandas as pd

        cols = ["coefficient", "unit", "sigma", "significance", "epoch", "epoch_sigma"]
        cols += ["frequency", "lag", "lag_sigma", "tau", "instrument"]
        from_details = ("epoch_sigma", "lag_sigma")
        rows = []
        for key, entry in self.entries.items():
            for kind, items in (("effect", "effects"), ("unexplained", "unexplained")):
                for e in entry.get(items, []):
                    row = {"axis": e.get("axis") or key, "kind": kind, "name": e.get("name")}
                    row["channel"] = e.get("channel")
                    row.update({c: e.get(c) for c in cols if c not in from_details})
                    row.update({c: (e.get("details") or {}).get(c) for c in from_details})
                    row["model"] = entry.get("model", "")
                    rows.append(row)
        df = pd.DataFrame(rows, columns=["axis", "kind", "name", "channel", *cols, "model"])
        numeric = ("coefficient", "sigma", "significance", "epoch", "frequency", "lag", "tau")
        for c in (*numeric, *from_details):
            df[c] = pd.to_numeric(df[c], errors="coerce").astype(float)
        epochs = df["epoch"].to_numpy()
        utc = np.full(epochs.size, np.datetime64("NaT"), dtype="datetime64[ns]")
        known = np.isfinite(epochs) & (epochs > 0) & self.gps_time
        if known.any():
            utc[known] = gps_to_utc(epochs[known])
        df.insert(
            df.columns.get_loc("epoch") + 1, "epoch_utc", pd.Series(utc).dt.tz_localize("UTC")
        )
        df.attrs["units"] = {
            "coefficient": "in 'unit' (SI)",
            "sigma": "in 'unit' (1 sigma)",
            "significance": "p-value of the effect's test",
            "epoch": "s (GPS seconds since 2000-01-01 12:00:00; steps)",
            "epoch_utc": "UTC",
            "frequency": "Hz",
            "epoch_sigma": "s",
            "lag": "s",
            "lag_sigma": "s",
            "tau": "s",
        }
        df.attrs["orbit_period"] = self.orbit_period
        return df


def _orbit_period(entries: Mapping[str, Mapping[str, Any]]) -> float | None:
    """The period of the orbit-signal model the closure used (None if it had none)."""
    for entry in entries.values():
        period = (entry.get("signal_model") or {}).get("period")
        if period is not None:
            return float(period)
    return None
