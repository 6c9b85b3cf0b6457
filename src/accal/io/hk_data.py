"""Housekeeping channels on their own time grid: :class:`Housekeeping`, its interpolation.

Also the sorting of records by time and the merging of records with the same
epoch, shared by the AHK1B and the table readers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import ValidationError

#: Default largest spacing [s] of two housekeeping samples that :meth:`Housekeeping.on`
#: interpolates across: twice the 60-s sampling of the GRACE AHK1B temperatures, so one
#: missing sample is bridged and a longer outage gives NaN.
DEFAULT_MAX_GAP = 120.0


_NOT_PRESENT = -1


@dataclass(frozen=True)
class Housekeeping:
    """Housekeeping channels of one satellite (or one table) on their own time grid.

    Attributes
    ----------
    time : ndarray of float64, shape (n,)
        Record epochs, strictly increasing [s, GPS seconds since 2000-01-01 12:00:00].
    channels : dict of str to ndarray of float64, shape (n,)
        Measured quantities; NaN where a record does not carry the channel.
    units : dict of str to str
        Unit of ``time``, of every channel and of every flag (temperatures in
        ``"degC"``, voltages in ``"V"``; ``"unknown"`` where the source gives none).
    satellite : str
        ``"GRACE-A"`` ... ``"GRACE-FO-D"``, or ``""`` for a table.
    meta : dict
        The file's header, unchanged (``meta["grace"]``, ``meta["gracefo"]`` or
        ``meta["table"]``), and ``meta["housekeeping"]`` (format, ``prod_flag`` bit
        of every field, inferred units, record counts).
    flags : dict of str to ndarray of int64, shape (n,)
        Integer-valued record information that must not be interpolated:
        ``qualflg`` and ``status``/``statusflag`` bitmasks (bit 0 = rightmost
        character), block numbers, clock counts, sync codes; -1 where a record
        does not carry it.
    warnings : tuple of str
        The reader's findings (short files, duplicated epochs, ...).

    Raises
    ------
    ValidationError
        On construction, if the arrays are not 1-D of one length, time is not finite
        and strictly increasing, or a channel has no unit.
    """

    time: NDArray[np.float64]
    channels: dict[str, NDArray[np.float64]]
    units: dict[str, str]
    satellite: str = ""
    meta: dict[str, Any] = field(default_factory=dict)
    flags: dict[str, NDArray[np.int64]] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=np.float64)
        if t.ndim != 1:
            raise ValidationError(f"housekeeping time must be 1-D, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ValidationError("housekeeping time must be finite")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValidationError("housekeeping time must be strictly increasing")
        chans = {}
        for k, v in self.channels.items():
            a = np.asarray(v, dtype=np.float64)
            if a.shape != t.shape:
                raise ValidationError(f"channel {k!r} must have shape {t.shape}, got {a.shape}")
            if k not in self.units:
                raise ValidationError(f"channel {k!r} has no unit in 'units'")
            chans[k] = a
        flags = {}
        for k, v in self.flags.items():
            a = np.asarray(v, dtype=np.int64)
            if a.shape != t.shape:
                raise ValidationError(f"flag {k!r} must have shape {t.shape}, got {a.shape}")
            flags[k] = a
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "channels", chans)
        object.__setattr__(self, "flags", flags)
        object.__setattr__(self, "units", dict(self.units))
        object.__setattr__(self, "warnings", tuple(self.warnings))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def on(
        self,
        t: ArrayLike,
        max_gap: float = DEFAULT_MAX_GAP,
        names: str | list[str] | tuple[str, ...] | None = None,
    ) -> dict[str, NDArray[np.float64]]:
        """Interpolate every channel linearly onto the epochs ``t``.

        Parameters
        ----------
        t : array_like of float, shape (m,)
            Target epochs, e.g. the accelerometer's ``AccSeries.time``
            [s, GPS seconds]; any order, NaN allowed (gives NaN).
        max_gap : float, optional
            Largest spacing of the two bracketing samples of a channel that is
            interpolated across [s]; default :data:`DEFAULT_MAX_GAP` (120 s).
            ``np.inf`` disables the check.
        names : str or sequence of str, optional
            Channel(s) to interpolate; default all of :attr:`channels`.

        Returns
        -------
        dict of str to ndarray of float64, shape (m,)
            One array per channel, in the channel's unit.  NaN where ``t`` lies
            outside the channel's coverage (before its first or after its last
            finite sample) or between two samples farther apart than ``max_gap``;
            a target epoch equal to a sample epoch always gets that sample.

        Raises
        ------
        ValidationError
            ``t`` not 1-D numeric, ``max_gap`` not positive, unknown channel name.

        Notes
        -----
        Each channel is interpolated between its own finite samples (records
        without the channel are skipped), with :func:`numpy.interp`.
        """
        try:
            tt = np.asarray(t, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValidationError("target epochs t must be numeric") from None
        if tt.ndim != 1:
            raise ValidationError(f"target epochs t must be 1-D, got shape {tt.shape}")
        try:
            gap = float(max_gap)
        except (TypeError, ValueError):
            raise ValidationError(f"max_gap must be a number [s], got {max_gap!r}") from None
        if not gap > 0:
            raise ValidationError(f"max_gap must be positive [s], got {max_gap!r}")
        if names is None:
            names = tuple(self.channels)
        elif isinstance(names, str):
            names = (names,)
        unknown = [n for n in names if n not in self.channels]
        if unknown:
            raise ValidationError(
                f"unknown housekeeping channel(s) {', '.join(map(repr, unknown))}; "
                f"channels are {_listing(self.channels)}"
            )
        out = {}
        for name in names:
            x = self.channels[name]
            ok = np.isfinite(x)
            out[name] = _interp_gapped(self.time[ok], x[ok], tt, gap)
        return out


#: Longest name, and longest listing, in a one-line message [characters].
NAME_CHARS, LISTING_CHARS = 40, 160


def _listing(names: Any, limit: int = 20) -> str:
    """Names for a one-line message: non-printable ones quoted, each cut to
    :data:`NAME_CHARS`, at most ``limit`` shown and at most :data:`LISTING_CHARS` in all
    (the deep fuzz found a 400-character column name making the message 500 long)."""
    shown: list[str] = []
    names = list(names)
    for n in names[:limit]:
        text = str(n) if str(n).isprintable() else repr(n)
        text = text if len(text) <= NAME_CHARS else text[: NAME_CHARS - 1] + "…"
        if shown and len(", ".join([*shown, text])) > LISTING_CHARS:
            break
        shown.append(text)
    more = f", ... ({len(names) - len(shown)} more)" if len(names) > len(shown) else ""
    return (", ".join(shown) + more) or "none"


def _interp_gapped(
    tv: NDArray[np.float64], xv: NDArray[np.float64], t: NDArray[np.float64], max_gap: float
) -> NDArray[np.float64]:
    """Linear interpolation of samples (tv, xv) at t; NaN outside [tv0, tv-1] and across gaps."""
    res = np.full(t.shape, np.nan)
    n = tv.size
    if n == 0:
        return res
    if n == 1:
        res[t == tv[0]] = xv[0]
        return res
    inside = (t >= tv[0]) & (t <= tv[-1])
    ti = t[inside]
    k = np.clip(np.searchsorted(tv, ti, side="right") - 1, 0, n - 2)
    t0, t1 = tv[k], tv[k + 1]
    ok = ((t1 - t0) <= max_gap) | (ti == t0) | (ti == t1)
    vals = np.interp(ti, tv, xv)
    vals[~ok] = np.nan
    res[inside] = vals
    return res


def _first_valid(
    group: NDArray[np.intp], values: NDArray, valid: NDArray[np.bool_], m: int, fill: Any
) -> tuple[NDArray, int]:
    """Per group, the first valid value (groups in sorted-stable order); count conflicts."""
    out = np.full(m, fill, dtype=values.dtype)
    g, v = group[valid], values[valid]
    _, first = np.unique(g, return_index=True)
    out[g[first]] = v[first]
    return out, int(np.count_nonzero(v != out[g]))


def _sort_merge(
    time: NDArray[np.float64],
    channels: dict[str, NDArray[np.float64]],
    flags: dict[str, NDArray[np.int64]],
) -> tuple[NDArray[np.float64], dict, dict, list[str]]:
    """Sort by time and merge records with the same epoch (first value in file order kept)."""
    warn: list[str] = []
    n_back = int(np.count_nonzero(np.diff(time) < 0))
    if n_back:
        order = np.argsort(time, kind="stable")
        time = time[order]
        channels = {k: v[order] for k, v in channels.items()}
        flags = {k: v[order] for k, v in flags.items()}
        warn.append(f"{n_back} records out of time order (sorted)")
    new = np.concatenate(([True], np.diff(time) > 0)) if time.size else np.zeros(0, bool)
    n_dup = int(time.size - np.count_nonzero(new))
    if n_dup:
        group = np.cumsum(new) - 1
        m = int(np.count_nonzero(new))
        conflicts = 0
        merged_c, merged_f = {}, {}
        for k, v in channels.items():
            merged_c[k], c = _first_valid(group, v, np.isfinite(v), m, np.nan)
            conflicts += c
        for k, v in flags.items():
            merged_f[k], c = _first_valid(group, v, v != _NOT_PRESENT, m, _NOT_PRESENT)
            conflicts += c
        channels, flags, time = merged_c, merged_f, time[new]
        msg = f"{n_dup} records with a repeated epoch merged"
        if conflicts:
            msg += f" ({conflicts} conflicting values, first in file order kept)"
        warn.append(msg)
    return time, channels, flags, warn
