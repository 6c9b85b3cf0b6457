"""Reader of accelerometer housekeeping: GRACE / GRACE-FO AHK1B and generic tables.

:func:`read_housekeeping` returns a :class:`Housekeeping` (time, channels, units,
flags, meta) whose :meth:`Housekeeping.on` interpolates every channel onto the
accelerometer epochs, so that ``accal grace-bias --close-loop --aux FILE`` can test
the accelerations against temperatures, voltages and the like.  Supported inputs
(all may be gzip-compressed, detected by magic bytes):

* GRACE AHK1B ASCII (RL00–RL03): fixed-width header ending with ``END OF HEADER``
  (read with the helpers of :mod:`accal.io.grace_l1b`), header in ``meta["grace"]``;
* GRACE-FO AHK1B ASCII (RL04): YAML header ending with ``# End of YAML header``,
  header in ``meta["gracefo"]``;
* a generic table (CSV or Parquet) with a ``gps_time`` or ``time`` column [s, GPS]
  (or ``time_utc``) and numeric channel columns, units from the CSV's
  ``-metadata.json`` sidecar or ``# units:`` lines, or ``accal.units`` metadata (as
  written by :func:`accal.io.writers.write_table`).

The AHK1B record
----------------
Every record is ``gps_time`` [s] ``gps_time_frac`` [µs] ``time_ref`` (``G`` = GPS)
``id`` (A/B/C/D) ``qualflg`` (8 characters of 0/1) ``prod_flag`` (32 characters of
0/1, bit 0 rightmost), then one value for each set bit of ``prod_flag`` in
increasing bit order.  Records carry different field sets; a channel is NaN in the
records that do not carry it.  The module constants below are the specification.

Sources of the field names and units
------------------------------------
GRACE (:data:`GRACE_FIELDS`, all verified): the ``ACC1A_t`` record of JPL's GRACE
Level-1 I/O library (``GRACEiolib.h``; AHK1B files are read with the ACC1A record
reader, ``ReadAHK1XFRecord.c``), which lists the ``prod_flag`` bits 0–28 and the
unit of every field, and JPL's ASCII writer ``WrAsciiACC1AFRecord.c`` (values in
increasing bit order, ``status`` as 8 characters of 0/1), both in the GraceRead
software copy of shjzhang/KineOrbits @277b078b (``tool/GraceRead_L1_2008_03_20/``),
the source of the sample files; the same mapping is read by GROOPS
(``graceL1b2AccHousekeeping.cpp``).  Bits 29–31 are "not currently used".

GRACE-FO (:data:`GRACEFO_FIELDS`): the names are those of the ``prod_flag``
``bit_meanings`` in the YAML header of the files themselves (bit 25 and bits 30–31
"Not defined"); the reader checks every file's list against
:data:`GRACEFO_BIT_MEANINGS` and refuses a file that differs.  Bits 26–29 take the
names of their ``variables`` entries (``icu_blk_nr``, ``PPS_source``,
``Sync_Qual``, ``statusflag``).  nasa-jpl/mango-ingest
(``src/masschange/ingest/datafilereaders/gracefoahk_base.py``) uses the same mapping.
**The GRACE-FO files give no units for these channels** (mango-ingest leaves
them as a to-do too); the units in :data:`GRACEFO_FIELDS` are inferred and listed
in :data:`GRACEFO_INFERRED_UNITS` and in ``meta["housekeeping"]["inferred_units"]``:
the temperatures ``TFEEU_*``, ``TSU_*``, ``TICUN``, ``TICUR`` in °C as for GRACE
(values 13–27 in the samples, and ``TICUR`` reads −273.2 °C, i.e. 0 K, while the
redundant ICU is off), the rails (``+3.3V``, ``+5V``, ``±15V``, ``±48V``) and
``analog_GND`` in V from their names and values, ``Vp`` and ``MES_Vd`` in V from
the ``statusflag`` bit meanings ("Vp 10V", "Vd 5Vrms").  The unit of
``MES_DET_*`` is unknown (values ~1e-3, unlike the GRACE displacements in m) and is
``"unknown"``.  (The ``variables`` list spells bit 18 ``TSU Z-``; the bit meanings,
used here, say ``TSU_Z-``.)

A set ``prod_flag`` bit without a verified field (GRACE bits 29–31, GRACE-FO bits
25, 30, 31) is read as one number named by its bit position, ``ahk_field_<bit>``,
with unit ``"unknown"``.

Units
-----
Voltages in V, currents in A, displacements in m, accelerations in m/s², and
**temperatures in °C** (``"degC"``, not converted to K).  Table columns declared in
mV, µV, kV, mA, µA or nA are converted to V or A.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import AccalError, FormatError, UnsupportedFormatError, ValidationError
from accal.io._common import PARQUET_MAGIC, check_binary, check_gps_time
from accal.io.grace_l1b import (
    _GRACE_END_RE,
    _GRACE_KEY_RE,
    SATELLITES,
    _grace_int,
    _parse_grace_header,
    _split_header,
    header_satellite,
    load_yaml_header,
    read_l1b_bytes,
    refuse_binary,
)
from accal.series import UNITS


class Field(NamedTuple):
    """One optional AHK1B field: name, unit and kind.

    ``kind`` is ``"f"`` (a number, goes to ``channels``), ``"i"`` (an integer
    counter or code, goes to ``flags``) or ``"b"`` (a 0/1 bit string, goes to
    ``flags`` as an integer, bit 0 = rightmost character).
    """

    name: str
    unit: str
    kind: str


#: GRACE AHK1B ``prod_flag`` bit -> field (``ACC1A_t`` in JPL's ``GRACEiolib.h``).
GRACE_FIELDS: dict[int, Field] = {
    0: Field("lin_accl_x", "m/s^2", "f"),
    1: Field("lin_accl_y", "m/s^2", "f"),
    2: Field("lin_accl_z", "m/s^2", "f"),
    3: Field("ang_accl_x", "rad/s^2", "f"),
    4: Field("ang_accl_y", "rad/s^2", "f"),
    5: Field("ang_accl_z", "rad/s^2", "f"),
    6: Field("bias_vol", "V", "f"),  # proof-mass bias voltage (averaged)
    7: Field("vd", "V", "f"),  # amplitude of the position-sensor AC voltage [V rms]
    8: Field("x1_out", "m", "f"),  # displacement of capacitive sensor X1
    9: Field("x2_out", "m", "f"),
    10: Field("x3_out", "m", "f"),
    11: Field("y1_out", "m", "f"),
    12: Field("y2_out", "m", "f"),
    13: Field("z1_out", "m", "f"),
    14: Field("tesu", "degC", "f"),  # temperature of the SU electronics
    15: Field("taicu", "degC", "f"),  # temperature of the ICU power supply board
    16: Field("tisu", "degC", "f"),  # temperature of the internal core
    17: Field("v15picu", "V", "f"),  # ICU reference voltage +15 V
    18: Field("v15micu", "V", "f"),  # ICU reference voltage -15 V
    19: Field("vr5picu", "V", "f"),  # ICU reference voltage +5 V
    20: Field("tcicu", "degC", "f"),  # temperature of the ICU A/D converter board
    21: Field("v15psu", "V", "f"),  # SU voltage +15 V
    22: Field("v15msu", "V", "f"),  # SU voltage -15 V
    23: Field("v48psu", "V", "f"),  # SU voltage +48 V
    24: Field("v48msu", "V", "f"),  # SU voltage -48 V
    25: Field("status", "bitmask", "b"),  # 60-second status byte
    26: Field("icu_blk_nr", "count", "i"),  # ICU block number
    27: Field("Tenhz_count", "count", "i"),  # 10 Hz clock count
    28: Field("Mhz_count", "count", "i"),  # MHz clock count
}

#: GRACE-FO AHK1B ``prod_flag`` bit -> field (names from the files' YAML headers;
#: units inferred, see :data:`GRACEFO_INFERRED_UNITS`).
GRACEFO_FIELDS: dict[int, Field] = {
    0: Field("TFEEU_IF", "degC", "f"),
    1: Field("TFEEU_REF", "degC", "f"),
    2: Field("TFEEU_X", "degC", "f"),
    3: Field("TFEEU_YZ", "degC", "f"),
    4: Field("analog_GND", "V", "f"),
    5: Field("+3.3V", "V", "f"),
    6: Field("Vp", "V", "f"),
    7: Field("MES_Vd", "V", "f"),
    8: Field("MES_DET_X1", "unknown", "f"),
    9: Field("MES_DET_X2", "unknown", "f"),
    10: Field("MES_DET_X3", "unknown", "f"),
    11: Field("MES_DET_Y1", "unknown", "f"),
    12: Field("MES_DET_Y2", "unknown", "f"),
    13: Field("MES_DET_Z1", "unknown", "f"),
    14: Field("TSU_Y+", "degC", "f"),
    15: Field("TICUN", "degC", "f"),
    16: Field("TSU_Y-", "degC", "f"),
    17: Field("TSU_Z+", "degC", "f"),
    18: Field("TSU_Z-", "degC", "f"),
    19: Field("+5V", "V", "f"),
    20: Field("TICUR", "degC", "f"),
    21: Field("+15V", "V", "f"),
    22: Field("-15V", "V", "f"),
    23: Field("+48V", "V", "f"),
    24: Field("-48V", "V", "f"),
    26: Field("icu_blk_nr", "count", "i"),
    27: Field("PPS_source", "code", "i"),
    28: Field("Sync_Qual", "code", "i"),
    29: Field("statusflag", "bitmask", "b"),
}

#: GRACE-FO channels whose unit is inferred (the files state none); MES_DET_* are "unknown".
GRACEFO_INFERRED_UNITS = tuple(
    f.name for f in GRACEFO_FIELDS.values() if f.kind == "f" and f.unit not in ("unknown",)
)

#: ``prod_flag`` ``bit_meanings`` of the GRACE-FO RL04 YAML header, as written in the files.
GRACEFO_BIT_MEANINGS: dict[int, str] = {
    **{b: f.name for b, f in GRACEFO_FIELDS.items() if b <= 24},
    25: "Not defined",
    26: "ICU block number",
    27: "PPS Source",
    28: "Sync Quality Index",
    29: "Status flag",
    30: "Not defined",
    31: "Not defined",
}

#: The six columns every AHK1B record starts with (GRACE-FO names; GRACE calls the
#: first two ``gps_time`` / ``gps_time_frac`` and the id ``GRACE_id``).
RECORD_COLUMNS = ("rcvtime_intg", "rcvtime_frac", "time_ref", "GRACEFO_id", "qualflg", "prod_flag")
N_FIXED = len(RECORD_COLUMNS)

#: GRACE ``FILE TYPE`` products read with the ACC1A/AHK record (``ipACC1AF`` in the samples).
GRACE_FILE_TYPES = ("ACC1A", "AHK1A", "AHK1B", "AHK1X")

#: Time columns of a generic table, in order of preference (GPS seconds, GPS seconds, UTC).
TIME_COLUMNS = ("gps_time", "time", "time_utc")

#: Accepted record times [s since 2000-01-01 12:00:00 GPS]: the GPS epoch (1980-01-06)
#: to 2100-01-01; anything outside is a corrupt time, not a housekeeping epoch.
TIME_RANGE = (-630_763_200, 3_155_716_800)

#: Default largest spacing [s] of two housekeeping samples that :meth:`Housekeeping.on`
#: interpolates across: twice the 60-s sampling of the GRACE AHK1B temperatures, so one
#: missing sample is bridged and a longer outage gives NaN.
DEFAULT_MAX_GAP = 120.0

#: Declared table units converted to SI: unit -> (factor, SI unit).
SI_PREFIXED = {
    f"{p}{u}": (s, u)
    for u in ("V", "A")
    for p, s in (("n", 1e-9), ("u", 1e-6), ("µ", 1e-6), ("μ", 1e-6), ("m", 1e-3), ("k", 1e3))
}

#: Absolute zero [°C]; a temperature channel below it is reported (GRACE-FO ``TICUR``
#: reads -273.2 °C in the samples: the redundant ICU is off and reads 0 K).
ABSOLUTE_ZERO_C = -273.15

_BIT_MEANING_RE = re.compile(r"^bits?\s+(\d+)(?:\s*-\s*(\d+))?\s*=\s*(.*?)\s*$")
_NOT_PRESENT = -1


# --------------------------------------------------------------------------- data model


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


def _listing(names: Any, limit: int = 20) -> str:
    """Names for a one-line message: non-printable ones quoted, at most ``limit`` shown."""
    names = [n if str(n).isprintable() else repr(n) for n in names]
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return (", ".join(map(str, names[:limit])) + more) or "none"


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


# --------------------------------------------------------------------------- headers


def _flavour(raw: bytes) -> str:
    if raw.startswith(PARQUET_MAGIC):
        return "table"
    if raw.startswith(b"header:"):
        return "gracefo"
    first = raw[:4096].split(b"\n", 1)[0]
    if _GRACE_END_RE.search(raw[: 1 << 20]) or (
        _GRACE_KEY_RE.match(first) and not first.startswith(b"#")
    ):
        return "grace"
    return "table"


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = _parse_grace_header(header, path)
    file_type = next((k for k in meta if k.startswith("FILE TYPE")), None)
    if file_type is not None:
        m = re.search(r"ip(\w{3}1[ABX])F", file_type)
        if m and m.group(1) not in GRACE_FILE_TYPES:
            hint = (
                " (accelerometer data: give it as an input file, not as --aux; "
                "in Python read it with accal.io.read)"
                if m.group(1) in ("ACC1B", "ACT1B")
                else ""
            )
            raise UnsupportedFormatError(
                f"file type {m.group(0)!r} is not accelerometer housekeeping (AHK1B){hint}",
                path,
                lines[file_type],
            )
    refuse_binary(meta, lines, path, "AHK1B")
    letter = header_satellite(meta, lines, path)
    return {
        "meta": {"grace": meta},
        "letter": letter,
        "n_header": _grace_int(meta, lines, "NUMBER OF DATA RECORDS", path),
        "fields": GRACE_FIELDS,
        "format": "grace-ahk1b",
    }


def _bit_meanings(prod_flag: Any, path: Path) -> dict[int, str]:
    """Parse the ``bit_meanings`` list of the YAML ``prod_flag`` variable."""
    items = prod_flag.get("bit_meanings") if isinstance(prod_flag, dict) else None
    if not isinstance(items, list):
        return {}
    out: dict[int, str] = {}
    for item in items:
        m = _BIT_MEANING_RE.match(str(item))
        if m is None:
            raise FormatError(f"YAML header: prod_flag bit meaning {str(item)[:40]!r}", path)
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) else lo
        for bit in range(lo, min(hi, 31) + 1):
            out[bit] = m.group(3)
    return out


def _interpret_gracefo(header: bytes, path: Path) -> dict[str, Any]:
    hdr = load_yaml_header(header, path)
    try:
        n_header = int(hdr["dimensions"]["num_records"])
    except (KeyError, TypeError, ValueError):
        raise FormatError(
            "YAML header: 'dimensions: num_records' missing or not an integer", path
        ) from None
    variables = hdr.get("variables") or []
    if not isinstance(variables, list) or not all(
        isinstance(v, dict) and len(v) >= 1 for v in variables
    ):
        raise FormatError("YAML header: 'variables' is not a list of mappings", path)
    names = tuple(str(next(iter(v))) for v in variables)
    if names and names[:N_FIXED] != RECORD_COLUMNS:
        raise UnsupportedFormatError(
            f"columns {' '.join(names[:6])} ... are not AHK1B housekeeping columns "
            f"(expected {' '.join(RECORD_COLUMNS)})",
            path,
        )
    prod_flag = next((v["prod_flag"] for v in variables if "prod_flag" in v), None)
    meanings = _bit_meanings(prod_flag, path)
    for bit, got in meanings.items():
        want = GRACEFO_BIT_MEANINGS.get(bit)
        if got != want:
            raise UnsupportedFormatError(
                f"prod_flag bit {bit} is {got!r} in the YAML header, expected {want!r} "
                "(unknown AHK1B layout)",
                path,
            )
    platform = str((hdr.get("global_attributes") or {}).get("platform", ""))
    letter = platform.split()[-1] if platform.split() else ""
    if letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {platform!r}, expected 'GRACE C' or 'GRACE D'", path
        )
    return {
        "meta": {"gracefo": hdr},
        "letter": letter,
        "n_header": n_header,
        "fields": GRACEFO_FIELDS,
        "format": "gracefo-ahk1b",
    }


# --------------------------------------------------------------------------- records


_WHITESPACE = np.zeros(256, dtype=bool)
_WHITESPACE[[9, 10, 11, 12, 13, 32]] = True  # what bytes.split() splits on


class _Tokens(NamedTuple):
    """Whitespace-separated tokens of the data section, found without a Python loop."""

    buf: NDArray[np.uint8]
    starts: NDArray[np.intp]  # byte offset of every token
    lens: NDArray[np.intp]  # its length
    first: NDArray[np.intp]  # index of the first token of every record (non-blank line)
    count: NDArray[np.intp]  # number of tokens of every record
    line: NDArray[np.intp]  # 0-based line (within the data section) of every record


def _tokenize(data: bytes) -> _Tokens:
    buf = np.frombuffer(data, dtype=np.uint8)
    is_tok = buf > 32
    low = buf[~is_tok]
    if not _WHITESPACE[low].all():  # control characters other than whitespace
        at = int(np.flatnonzero((buf < 32) & ~_WHITESPACE[buf])[0])
        raise ValueError(at)
    edge = np.diff(is_tok.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(edge == 1)
    lens = np.flatnonzero(edge == -1) - starts
    newlines = np.flatnonzero(buf == 10)
    tok_line = np.searchsorted(newlines, starts)
    per_line = np.bincount(tok_line, minlength=newlines.size + 1)
    line = np.flatnonzero(per_line)
    first = (np.cumsum(per_line) - per_line)[line]
    # pad so that every token can be read as a full-width window
    pad = int(lens.max()) if lens.size else 1
    padded = np.concatenate((buf, np.zeros(pad, dtype=np.uint8)))
    return _Tokens(padded, starts, lens, first, per_line[line], line)


def _gather(tok: _Tokens, index: NDArray[np.intp]) -> NDArray[np.bytes_]:
    """The tokens ``index`` as a fixed-width bytes array (one vectorised copy)."""
    starts, lens = tok.starts[index], tok.lens[index]
    width = int(lens.max()) if lens.size else 1
    windows = np.lib.stride_tricks.sliding_window_view(tok.buf, width)
    mat = windows[starts]
    mat[np.arange(width) >= lens[:, None]] = 0
    return np.ascontiguousarray(mat).view(f"S{width}").reshape(-1)


def _bits(col: NDArray[np.bytes_], width: int | None = None) -> NDArray[np.int64] | int:
    """0/1 strings (bit 0 rightmost) as int64; on failure the index of the first bad value.

    ``width`` is the exact number of characters required; None accepts 1 to 32.
    """
    w = col.dtype.itemsize
    if col.size and w == (width or w) <= 32:
        # fast path: every value is exactly w characters of 0/1
        mat = col.view(np.uint8).reshape(col.size, w)
        if np.all((mat == 48) | (mat == 49)):
            out = np.zeros(col.size, dtype=np.int64)
            for j in range(w):
                out = (out << 1) | (mat[:, j] == 49)
            return out
    uniq, inv = np.unique(col, return_inverse=True)
    vals = np.empty(uniq.size, dtype=np.int64)
    for j, u in enumerate(uniq.tolist()):
        good = len(u) == width if width else 0 < len(u) <= 32
        if not good or u.strip(b"01"):
            return int(np.flatnonzero(inv.reshape(-1) == j)[0])
        vals[j] = int(u, 2)
    return vals[inv.reshape(-1)]


def _convert(col: NDArray[np.bytes_], dtype: type) -> NDArray | int:
    """Convert byte tokens to ``dtype``; on failure the index of the first bad token."""
    try:
        out = col.astype(dtype)
    except (ValueError, OverflowError, TypeError):
        for i, tok in enumerate(col.tolist()):
            try:
                dtype(tok)
            except (ValueError, OverflowError, TypeError):
                return i
        return 0
    if dtype is np.float64:
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            return int(bad[0])
    return out


def _parse_records(
    data: bytes, first_line: int, fields: dict[int, Field], path: Path
) -> tuple[dict[str, NDArray], dict[str, int], list[str]]:
    """Parse AHK1B records: fixed columns and the ``prod_flag``-selected fields.

    Returns the per-record arrays (``time``, ``time_ref``, ``id``, ``qualflg``,
    ``f:<name>`` floats with NaN, ``i:<name>`` ints with -1), the ``prod_flag`` bit
    of every field present, and the names of the positional (unverified) fields.
    Tokenising and conversion are vectorised (one pass per ``prod_flag`` layout
    and column): a 10 Hz GRACE-FO day of 864,000 records takes a few seconds.
    """
    if not data.strip():
        raise FormatError("header but no data records", path, first_line)
    if not data.endswith(b"\n"):
        raise FormatError(
            "truncated last line (no newline at end of file)", path, first_line + data.count(b"\n")
        )
    check_binary(data, path, first_line)
    try:
        tok = _tokenize(data)
    except ValueError as exc:
        at = int(exc.args[0])
        line = first_line + data[:at].count(b"\n")
        raise FormatError("control character inside a record", path, line) from None
    n = int(tok.first.size)

    def fail(msg: str, row: int) -> FormatError:
        return FormatError(msg, path, first_line + int(tok.line[row]))

    short = np.flatnonzero(tok.count < N_FIXED)
    if short.size:
        r = int(short[0])
        raise fail(
            f"record has {tok.count[r]} fields, expected at least {N_FIXED} "
            "(time, time fraction, time_ref, id, qualflg, prod_flag)",
            r,
        )
    cols = [_gather(tok, tok.first + j) for j in range(N_FIXED)]
    intg = _convert(cols[0], np.int64)
    if isinstance(intg, int):
        raise fail(f"time: not an integer number of seconds: {cols[0][intg][:20]!r}", intg)
    frac = _convert(cols[1], np.int64)
    if isinstance(frac, int):
        raise fail(f"time fraction: not an integer [µs]: {cols[1][frac][:20]!r}", frac)
    bad = np.flatnonzero((intg < TIME_RANGE[0]) | (intg > TIME_RANGE[1]))
    if bad.size:
        raise fail(
            f"time {intg[bad[0]]} s is outside {TIME_RANGE[0]:.0f} ... {TIME_RANGE[1]:.0f} s "
            "(GPS epoch ... 2100)",
            int(bad[0]),
        )
    bad = np.flatnonzero((frac < 0) | (frac > 999_999))
    if bad.size:
        raise fail(f"time fraction {frac[bad[0]]} µs is not in 0 ... 999999", int(bad[0]))
    for j, what in ((2, "time_ref"), (3, "satellite id")):
        long = np.flatnonzero(np.char.str_len(cols[j]) != 1)
        if long.size:
            r = int(long[0])
            raise fail(f"{what} {cols[j][r][:10]!r} is not one character", r)
    qualflg = _bits(cols[4], 8)
    if isinstance(qualflg, int):
        raise fail(f"qualflg {cols[4][qualflg][:20]!r} is not 8 characters of 0/1", qualflg)
    prod_flag = _bits(cols[5], 32)
    if isinstance(prod_flag, int):
        raise fail(f"prod_flag {cols[5][prod_flag][:40]!r} is not 32 characters of 0/1", prod_flag)
    out: dict[str, NDArray] = {}
    present: dict[str, int] = {}
    positional: list[str] = []
    layouts, which = np.unique(prod_flag, return_inverse=True)
    order = np.argsort(which.reshape(-1), kind="stable")
    bounds = np.searchsorted(which.reshape(-1)[order], np.arange(layouts.size + 1))
    for g, pf in enumerate(layouts.tolist()):
        rows = order[bounds[g] : bounds[g + 1]]
        bits = [b for b in range(32) if pf >> b & 1]
        width = N_FIXED + len(bits)
        wrong = np.flatnonzero(tok.count[rows] != width)
        if wrong.size:
            r = int(rows[wrong[0]])
            raise fail(
                f"record has {tok.count[r]} fields, its prod_flag {pf:032b} announces {width}", r
            )
        for c, bit in enumerate(bits, start=N_FIXED):
            fld = fields.get(bit)
            if fld is None:
                fld = Field(f"ahk_field_{bit}", "unknown", "f")
                if fld.name not in positional:
                    positional.append(fld.name)
            col = _gather(tok, tok.first[rows] + c)
            if fld.kind == "b":
                v = _bits(col)
            else:
                v = _convert(col, np.float64 if fld.kind == "f" else np.int64)
            if isinstance(v, int):
                kind = {"f": "not a finite number", "i": "not an integer", "b": "not 0/1 bits"}
                raise fail(f"{fld.name}: {kind[fld.kind]}: {col[v][:20]!r}", int(rows[v]))
            key = ("f:" if fld.kind == "f" else "i:") + fld.name
            if key not in out:
                out[key] = (
                    np.full(n, np.nan) if fld.kind == "f" else np.full(n, _NOT_PRESENT, np.int64)
                )
                present[fld.name] = bit
            out[key][rows] = v
    out.update(time=intg + frac * 1e-6, time_ref=cols[2], id=cols[3], qualflg=qualflg)
    return out, present, positional


def _check_ids(ids: NDArray[np.bytes_], letter: str, path: Path) -> list[str]:
    uniq = sorted(u.decode("latin-1") for u in np.unique(ids).tolist())
    bad = [u for u in uniq if u not in SATELLITES]
    if bad:
        raise FormatError(f"satellite id {bad[0]!r} is not one of A, B, C, D", path)
    if len(uniq) > 1:
        raise FormatError(f"mixed satellite ids {uniq} in one file", path)
    if uniq and uniq[0] != letter:
        return [f"records carry satellite id {uniq[0]!r} but the header names {letter!r}"]
    return []


def _check_time_ref(time_ref: NDArray[np.bytes_], path: Path) -> list[str]:
    uniq, counts = np.unique(time_ref, return_counts=True)
    found = dict(zip((u.decode("latin-1") for u in uniq.tolist()), counts.tolist(), strict=True))
    bad = sorted(set(found) - {"G", "R"})
    if bad:
        raise FormatError(f"time_ref {bad[0]!r} is not G (GPS) or R (receiver)", path)
    if "R" in found:
        return [f"{found['R']} records carry receiver time (time_ref R), not GPS time"]
    return []


def _read_ahk1b(raw: bytes, path: Path) -> Housekeeping:
    flavour, header, data_start, first_line = _split_header(raw, path)
    info = (_interpret_gracefo if flavour == "gracefo" else _interpret_grace)(header, path)
    cols, present, positional = _parse_records(raw[data_start:], first_line, info["fields"], path)
    warn = _check_ids(cols["id"], info["letter"], path)
    warn += _check_time_ref(cols["time_ref"], path)
    n_rows = int(cols["time"].size)
    if info["n_header"] is not None and info["n_header"] != n_rows:
        warn.append(f"header announces {info['n_header']} data records, file has {n_rows}")
    if positional:
        warn.append(
            f"prod_flag bits without a verified field read by position: {', '.join(positional)}"
        )
    by_name = {f.name: f for f in info["fields"].values()}
    present = dict(sorted(present.items(), key=lambda item: item[1]))
    channels = {k: cols["f:" + k] for k in present if "f:" + k in cols}
    flags = {"qualflg": cols["qualflg"], **{k: cols["i:" + k] for k in present if "i:" + k in cols}}
    units = {"time": UNITS["time"], "qualflg": "bitmask"}
    for name in (*channels, *flags):
        if name != "qualflg":
            units[name] = by_name[name].unit if name in by_name else "unknown"
    frozen = [
        k for k, v in channels.items() if units[k] == "degC" and np.nanmin(v) < ABSOLUTE_ZERO_C
    ]
    if frozen:
        warn.append(
            f"temperature channel(s) {', '.join(frozen)} read below absolute zero "
            "(sensor not powered?)"
        )
    time, channels, flags, more = _sort_merge(cols["time"], channels, flags)
    inferred = [c for c in channels if c in GRACEFO_INFERRED_UNITS] if flavour == "gracefo" else []
    meta = dict(info["meta"])
    meta["housekeeping"] = {
        "format": info["format"],
        "prod_flag_bits": present,
        "positional_fields": positional,
        "inferred_units": inferred,
        "n_records_header": info["n_header"],
        "n_rows": n_rows,
    }
    return Housekeeping(
        time=time,
        channels=channels,
        units=units,
        satellite=SATELLITES[info["letter"]],
        meta=meta,
        flags=flags,
        warnings=tuple(warn + more),
    )


# --------------------------------------------------------------------------- sort and merge


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


# --------------------------------------------------------------------------- tables


def _to_si(values: NDArray[np.float64], unit: str) -> tuple[NDArray[np.float64], str]:
    """Convert a prefixed voltage or current (mV, µA, ...) to V or A."""
    key = unit.strip()
    if key in SI_PREFIXED:
        factor, si = SI_PREFIXED[key]
        with np.errstate(over="ignore"):  # |x| > 1.8e305 kV is inf V
            return values * factor, si
    return values, unit


def _read_table(raw: bytes, path: Path) -> Housekeeping:
    from accal.io.tables import (
        numeric_column,
        read_csv_table,
        read_parquet_table,
        utc_column_to_gps,
    )

    reader = read_parquet_table if raw.startswith(PARQUET_MAGIC) else read_csv_table
    try:
        table, units, fmeta, first_line = reader(raw, path)
    except AccalError:
        raise
    except ValueError as exc:  # e.g. metadata that is not UTF-8 (UnicodeDecodeError)
        raise FormatError(f"corrupt table ({type(exc).__name__})", path) from None
    names = list(table.column_names)
    if table.num_rows == 0:
        raise FormatError("header but no data rows", path, first_line or None)
    tname = next((c for c in TIME_COLUMNS if c in names), None)
    if tname is None:
        raise FormatError(
            "no time column (gps_time or time [s GPS], or time_utc); "
            f"columns are {_listing(names)}",
            path,
        )
    line_of = (lambda i: first_line + i) if first_line else None
    tcol = table.column(tname)
    if tname == "time_utc":
        time = utc_column_to_gps(tcol, tname, path, line_of)
    else:
        time = numeric_column(tcol, tname, path, line_of, locate=True).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        line = first_line + int(bad[0]) if first_line else None
        raise FormatError(f"{tname}: missing or non-finite time", path, line)
    check_gps_time(time, path, line_of, name=tname, unit="row")
    units = units if isinstance(units, dict) else {}
    channels: dict[str, NDArray[np.float64]] = {}
    col_units = {"time": UNITS["time"]}
    converted, skipped = {}, []
    for name in names:
        if name == tname:
            continue
        try:
            values = numeric_column(table.column(name), name, path).astype(np.float64)
        except FormatError:
            skipped.append(name)
            continue
        declared = str(units.get(name, "unknown"))
        values, unit = _to_si(values, declared)
        if unit != declared:
            converted[name] = f"{declared} -> {unit}"
        channels[name] = values
        col_units[name] = unit
    if not channels:
        raise FormatError(
            f"no numeric channel besides {tname!r}; columns are {_listing(names)}", path
        )
    warn = [f"non-numeric columns ignored: {_listing(skipped)}"] if skipped else []
    n_rows = int(time.size)
    time, channels, _, more = _sort_merge(time, channels, {})
    meta = {
        "table": {"time_column": tname, "file_meta": fmeta},
        "housekeeping": {"format": "table", "converted_units": converted, "n_rows": n_rows},
    }
    return Housekeeping(
        time=time, channels=channels, units=col_units, meta=meta, warnings=tuple(warn + more)
    )


# --------------------------------------------------------------------------- public


def read_housekeeping(path: str | Path) -> Housekeeping:
    """Read accelerometer housekeeping from a GRACE / GRACE-FO AHK1B file or a table.

    Parameters
    ----------
    path : str or Path
        GRACE AHK1B ASCII (``END OF HEADER``), GRACE-FO RL04 AHK1B ASCII (YAML
        header), or a CSV / Parquet table with ``gps_time`` or ``time`` [s, GPS]
        (or ``time_utc``) and numeric channel columns; optionally gzipped
        (detected by content, not name).

    Returns
    -------
    Housekeeping
        ``time`` [s, GPS] strictly increasing (records sorted, records with the
        same epoch merged), ``channels`` as float64 with NaN where a record lacks
        the channel, their ``units`` (temperatures in °C; voltages in V), integer
        ``flags`` (``qualflg``, status words, counters), ``satellite``, the header
        in ``meta`` and the findings in ``warnings``.

    Raises
    ------
    FormatError
        Missing, unreadable, empty, truncated or corrupt file, header without data,
        bad records (``.line`` is the 1-based line where known), a table without a
        time column or channels, with duplicated column names or with times outside
        1980-01-06 ... 2100-01-01.
    UnsupportedFormatError
        A recognised file of another kind: an ACC1B/ACT1B accelerometer file,
        binary AHK1B, a GRACE-FO header with an unknown ``prod_flag`` layout.

    Notes
    -----
    Field names and units, and which of them are verified, are described in the
    module docstring (:mod:`accal.io.housekeeping`).  A record count different
    from the header's is a warning (the GRACE-FO samples are cut after 100
    records).  Parsing is vectorised per ``prod_flag`` layout: a 10 Hz GRACE-FO
    day (864,000 records) takes a few seconds, a GRACE day (8,640) a fraction.
    """
    path = Path(path)
    raw = read_l1b_bytes(path)
    if _flavour(raw) == "table":
        return _read_table(raw, path)
    return _read_ahk1b(raw, path)


__all__ = [
    "DEFAULT_MAX_GAP",
    "GRACEFO_BIT_MEANINGS",
    "GRACEFO_FIELDS",
    "GRACEFO_INFERRED_UNITS",
    "GRACE_FIELDS",
    "Field",
    "Housekeeping",
    "read_housekeeping",
]
