"""Reader of GRACE / GRACE-FO THR1B thruster files and a mask of the samples near firings.

:func:`read_thrusters` returns a :class:`ThrusterFirings` (record epochs, cumulative
counts, per-record on-times, accumulated durations and the derived
:class:`FiringEvents`); :func:`firing_mask` marks the accelerometer epochs that lie
near a firing; :func:`find_thruster_file` finds the THR1B file that belongs to an
ACC1B / ACT1B file.  Supported inputs (both may be gzip-compressed, detected by
magic bytes, see :func:`accal.io.common.read_bytes`):

* GRACE THR1B ASCII (RL00-RL03): fixed-width header ending with ``END OF HEADER``
  (``FILE TYPE ipTHR1XF``), header in ``meta["grace"]``;
* GRACE-FO THR1B ASCII (RL04): YAML header naming every column, ending with
  ``# End of YAML header``, header in ``meta["gracefo"]``.

Binary THR1B files (``FILE FORMAT 0``) are refused with
:class:`~accal.errors.UnsupportedFormatError`.

The THR1B record
----------------
47 whitespace-separated fields (both missions; the GRACE-FO YAML header numbers
them "1st column" ... "47th column"):

====  ======================================  ===========================================
 #    GRACE-FO name (YAML header)              meaning
====  ======================================  ===========================================
1-2   ``time_intg``, ``time_frac``             activation time [s GPS since 2000-01-01
                                               12:00:00] and its µs part
3     ``time_ref``                             ``G`` = GPS time, ``R`` = receiver / OBC time
4     ``GRACEFO_id``                           satellite letter (A, B, C, D)
5-18  ``thrust_count_att_ctrl_{1,2}_{1..6}``,  cumulative number of work cycles of each
      ``thrust_count_undef_{1,2}``             thruster (wraps after 4294967295)
19-32 ``on_time_att_ctrl_{1,2}_{1..6}``,       on-time of each thruster for this time tag
      ``on_time_orb_ctrl_{1,2}``               [ms]
33-46 ``accum_dur_*``                          accumulated firing duration [ms]
47    ``qualflg``                              8 characters of 0/1, bit 0 rightmost
====  ======================================  ===========================================

Sources: JPL's GRACE Level-1 I/O library, ``THR1X_t`` in ``GRACEiolib.h`` and the
ASCII writer ``WrAsciiTHR1XFRecord.c`` (shjzhang/KineOrbits @277b078b,
``tool/GraceRead_L1_2008_03_20/``, the source of the GRACE samples): ``time_intg``
is the "Activation time", ``thrust_count[14]`` the "Count of number of work cycles
that each thruster has been activated", ``on_time[14]`` the "Thruster on time for
this time epoch (millisec)", ``accum_dur[14]`` the "Accumulated thruster firing
duration time (millisec)", written in this order with ``qualflg`` last; the
thruster table there lists thrusters 1-12 as the attitude-control thrusters
A11-A16, A21-A26 and 13-14 as the orbit-control thrusters O11, O21.  The GRACE-FO
names and units are those of the files' own YAML headers (the reader refuses a
header whose column list differs from :data:`GRACEFO_COLUMNS`).  GROOPS reads the
same layout (``GraceL1b2Thruster``, ``source/programs/conversion/grace/
graceL1b2Thruster.cpp``: 4 fixed fields, 14 counts, 14 on-times, 14 durations,
``qualflg``).  The text of the JPL Level-1B handbook (Case et al. 2010, JPL
D-22027) on THR1B could not be consulted for this module; nothing here relies on
it alone.

Differences between the missions (checked on the samples in ``data/samples``):

* GRACE: fields 17-18 are the counters of the orbit-control thrusters (named
  ``thrust_count_undef_{1,2}`` as in GRACE-FO for uniformity) and fields 33-46 are
  one accumulated duration per thruster (named here ``accum_dur_<thruster>``; the
  GRACE header names no columns).  In both 2003 files each duration increases by
  exactly that record's on-time.
* GRACE-FO: fields 17-18 are "Undefined" (always 0), so the orbit-control
  thrusters have no counter (:data:`GRACEFO_UNCOUNTED`); fields 33-46 are
  ``accum_dur_att_ctrl`` (all attitude thrusters together), eleven undefined
  fields, ``accum_dur_orb_ctrl`` and one more undefined field.
  ``accum_dur_att_ctrl`` increases by exactly the sum of the record's twelve
  attitude on-times in both samples.

Attitude thrusters fire in pairs ("nominally operated in pairs which are
accommodated such, that force free reaction control is achieved": GRACE Thruster
Specification summary in the GRACE Product Specification Document v4.5, quoted by
the NASA GCMD instrument entry THR): in all four samples every firing of
``att_ctrl_1_k`` comes with a firing of ``att_ctrl_2_k`` at the same epoch with the
same on-time, so one physical torque pulse gives two events.

Units: times and durations in **seconds** (on-times and accumulated durations are
converted from ms).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import FormatError, UnsupportedFormatError, ValidationError
from accal.io.common import check_gps_time, one_line
from accal.io.grace_l1b import (
    SATELLITES,
    grace_int,
    header_satellite,
    load_yaml_header,
    parse_grace_header,
    read_l1b_bytes,
    refuse_binary,
    split_header,
)
from accal.timescale import gps_to_date

#: The 14 thrusters in record order: attitude control branch 1 and 2, thrusters 1-6
#: (GRACE A11-A16, A21-A26), then the two orbit-control thrusters (O11, O21).
THRUSTERS: tuple[str, ...] = (
    *(f"att_ctrl_{b}_{k}" for b in (1, 2) for k in range(1, 7)),
    "orb_ctrl_1",
    "orb_ctrl_2",
)
N_THRUSTERS = len(THRUSTERS)

#: Counter columns (fields 5-18), one per thruster in :data:`THRUSTERS` order.
COUNT_COLUMNS: tuple[str, ...] = (
    *(f"thrust_count_{t}" for t in THRUSTERS[:12]),
    "thrust_count_undef_1",
    "thrust_count_undef_2",
)
#: On-time columns (fields 19-32) [ms in the file], one per thruster.
ON_TIME_COLUMNS: tuple[str, ...] = tuple(f"on_time_{t}" for t in THRUSTERS)
#: Accumulated-duration columns (fields 33-46) of GRACE: one per thruster (our names).
GRACE_ACCUM_COLUMNS: tuple[str, ...] = tuple(f"accum_dur_{t}" for t in THRUSTERS)
#: Accumulated-duration columns (fields 33-46) of GRACE-FO, as in the YAML header.
GRACEFO_ACCUM_COLUMNS: tuple[str, ...] = (
    "accum_dur_att_ctrl",
    *(f"accum_dur_undef_{i}" for i in range(1, 12)),
    "accum_dur_orb_ctrl",
    "accum_dur_undef_12",
)
#: The 47 columns of a GRACE-FO THR1B record, as its YAML header lists them.
GRACEFO_COLUMNS: tuple[str, ...] = (
    "time_intg",
    "time_frac",
    "time_ref",
    "GRACEFO_id",
    *COUNT_COLUMNS,
    *ON_TIME_COLUMNS,
    *GRACEFO_ACCUM_COLUMNS,
    "qualflg",
)
N_FIELDS = len(GRACEFO_COLUMNS)

#: GRACE-FO thrusters whose counter column is "Undefined" (always 0): their firings are
#: taken from ``on_time > 0`` instead of a count increase.
GRACEFO_UNCOUNTED: tuple[str, ...] = ("orb_ctrl_1", "orb_ctrl_2")

#: ``qualflg`` bit meanings (GRACE-FO YAML header; GRACE ``THR1X_t`` has bits 0, 1, 6, 7).
QUALFLG_BITS = {
    0: "On-time not calculated",
    1: "Multiple unaccounted thrusts prior to current record",
    2: "branch 1 is active (GRACE-FO)",
    3: "branch 2 is active (GRACE-FO)",
    6: "No OBC-to-Receiver Time mapping",
    7: "No clock correction available",
}

#: Margins of :func:`firing_mask` [s]: GROOPS ``InstrumentRemoveEpochsThruster``
#: (``marginBefore`` 0.1 s before the start, ``marginAfter`` 0.7 s after the end of a firing).
DEFAULT_BEFORE = 0.1
DEFAULT_AFTER = 0.7

#: Largest counter value: the counters wrap to 0 after it (YAML ``valid_range``).
COUNTER_MAX = 4_294_967_295

_FIELD_NAMES = GRACEFO_COLUMNS  # for messages (GRACE: same positions)
_ACC_NAME = re.compile(
    r"(?P<product>ACC1B|ACT1B)_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rel>\d+)"
    r"(?P<ext>\.[A-Za-z0-9]+)?(?P<gz>\.gz)?$"
)


# --------------------------------------------------------------------------- data model


@dataclass(frozen=True)
class FiringEvents:
    """Thruster firings, one per (record, thruster), sorted by start time.

    Attributes
    ----------
    start : ndarray of float64, shape (m,)
        Firing start [s, GPS seconds since 2000-01-01 12:00:00]: the THR1B record
        epoch (the "Activation time" of ``THR1X_t``).
    duration : ndarray of float64, shape (m,)
        On-time of the firing [s] (the record's ``on_time_*`` / 1000); 0 where the
        on-time was not calculated.
    thruster : ndarray of int64, shape (m,)
        Index into :data:`THRUSTERS`.
    record : ndarray of int64, shape (m,)
        Index of the record (into :attr:`ThrusterFirings.time`) that reports it.
    cycles : ndarray of int64, shape (m,)
        Increase of the thruster's counter since the previous record (work cycles);
        0 where the event is taken from the on-time alone (first record, thrusters
        without a counter).

    Raises
    ------
    ValidationError
        Arrays not 1-D of one length, non-finite start, negative or non-finite duration.
    """

    start: NDArray[np.float64]
    duration: NDArray[np.float64]
    thruster: NDArray[np.int64]
    record: NDArray[np.int64]
    cycles: NDArray[np.int64]

    def __post_init__(self) -> None:
        start = np.asarray(self.start, dtype=np.float64)
        if start.ndim != 1:
            raise ValidationError(f"event start must be 1-D, got shape {start.shape}")
        arrays = {"start": start}
        for name in ("duration", "thruster", "record", "cycles"):
            dtype = np.float64 if name == "duration" else np.int64
            a = np.asarray(getattr(self, name), dtype=dtype)
            if a.shape != start.shape:
                raise ValidationError(f"event {name} must have shape {start.shape}, got {a.shape}")
            arrays[name] = a
        if not np.isfinite(start).all():
            raise ValidationError("event start times must be finite")
        d = arrays["duration"]
        if not (np.isfinite(d).all() and (d >= 0).all()):
            raise ValidationError("event durations must be finite and >= 0 [s]")
        for name, a in arrays.items():
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.start.shape[0])

    @property
    def end(self) -> NDArray[np.float64]:
        """Firing end [s, GPS]: ``start + duration``."""
        return self.start + self.duration

    @classmethod
    def from_intervals(cls, start: ArrayLike, duration: ArrayLike) -> FiringEvents:
        """Events from start times [s, GPS] and durations [s] alone (thruster 0, no record)."""
        s = np.asarray(start, dtype=np.float64)
        zeros = np.zeros(s.shape, dtype=np.int64)
        return cls(s, np.asarray(duration, dtype=np.float64), zeros, zeros - 1, zeros)


@dataclass(frozen=True)
class ThrusterFirings:
    """The content of one THR1B file and the firings derived from it.

    Attributes
    ----------
    time : ndarray of float64, shape (n,)
        Record epochs, non-decreasing [s, GPS seconds since 2000-01-01 12:00:00,
        ``time_intg + 1e-6 * time_frac``].
    satellite : str
        ``"GRACE-A"`` ... ``"GRACE-FO-D"``.
    counts : ndarray of int64, shape (n, 14)
        Cumulative work-cycle counters, columns in :data:`THRUSTERS` order
        (:data:`COUNT_COLUMNS`); for GRACE-FO the orbit-thruster columns are the
        file's undefined fields (0).
    on_time : ndarray of float64, shape (n, 14)
        On-time of every thruster for the record's time tag [s], columns in
        :data:`THRUSTERS` order (:data:`ON_TIME_COLUMNS`).
    accum_dur : dict of str to ndarray of float64, shape (n,)
        Accumulated firing durations [s] as the file gives them: per thruster
        (GRACE, :data:`GRACE_ACCUM_COLUMNS`) or per thruster group (GRACE-FO,
        :data:`GRACEFO_ACCUM_COLUMNS`, undefined fields included).
    qualflg : ndarray of int64, shape (n,)
        Quality flags, bit 0 = rightmost character (:data:`QUALFLG_BITS`).
    events : FiringEvents
        The firings derived by :func:`read_thrusters` (see its Notes).
    uncounted : tuple of str
        Thrusters without a counter in this format (events from ``on_time > 0``).
    meta : dict
        The header, unchanged (``meta["grace"]`` or ``meta["gracefo"]``), and
        ``meta["thrusters"]`` (format, record counts).
    warnings : tuple of str
        The reader's findings (short file, counters going back, ...).
    """

    time: NDArray[np.float64]
    satellite: str
    counts: NDArray[np.int64]
    on_time: NDArray[np.float64]
    accum_dur: dict[str, NDArray[np.float64]]
    qualflg: NDArray[np.int64]
    events: FiringEvents
    uncounted: tuple[str, ...] = ()
    meta: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    @property
    def thrusters(self) -> tuple[str, ...]:
        """Names of the 14 thrusters (columns of :attr:`counts` and :attr:`on_time`)."""
        return THRUSTERS

    def __len__(self) -> int:
        return int(self.time.shape[0])


# --------------------------------------------------------------------------- header


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = parse_grace_header(header, path)
    file_type = next((k for k in meta if k.startswith("FILE TYPE")), None)
    if file_type is not None:
        m = re.search(r"ip(\w{3}1[ABX])F", file_type)
        if m and m.group(1) not in ("THR1A", "THR1B", "THR1X"):
            raise UnsupportedFormatError(
                f"file type {m.group(0)!r} is not thruster data (THR1B)", path, lines[file_type]
            )
    refuse_binary(meta, lines, path, "THR1B")
    letter = header_satellite(meta, lines, path)
    n = grace_int(meta, lines, "NUMBER OF DATA RECORDS", path)
    return {
        "meta": {"grace": meta},
        "letter": letter,
        "n_header": n,
        "accum": GRACE_ACCUM_COLUMNS,
        "uncounted": (),
        "format": "grace-thr1b",
    }


def _interpret_gracefo(header: bytes, path: Path) -> dict[str, Any]:
    hdr = load_yaml_header(header, path)
    try:
        n_header = int(hdr["dimensions"]["num_records"])
    except (KeyError, TypeError, ValueError):
        raise FormatError(
            "YAML header: 'dimensions: num_records' missing or not an integer", path
        ) from None
    variables = hdr.get("variables") or []
    if not isinstance(variables, list) or not all(isinstance(v, dict) and v for v in variables):
        raise FormatError("YAML header: 'variables' is not a list of mappings", path)
    names = tuple(str(next(iter(v))) for v in variables)
    if names != GRACEFO_COLUMNS:
        diff = next(
            (i for i, (a, b) in enumerate(zip(names, GRACEFO_COLUMNS, strict=False)) if a != b),
            min(len(names), N_FIELDS),
        )
        got = names[diff] if diff < len(names) else "(end of list)"
        raise UnsupportedFormatError(
            f"YAML header: column {diff + 1} is {one_line(got, 40)!r}, expected "
            f"{GRACEFO_COLUMNS[diff] if diff < N_FIELDS else '(end of list)'!r} "
            f"(not a THR1B thruster file, or an unknown THR1B layout)",
            path,
        )
    attrs = hdr.get("global_attributes") or {}
    platform = str(attrs.get("platform", "")) if isinstance(attrs, dict) else ""
    letter = platform.split()[-1] if platform.split() else ""
    if letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {one_line(platform, 40)!r}, expected 'GRACE C' or 'GRACE D'",
            path,
        )
    return {
        "meta": {"gracefo": hdr},
        "letter": letter,
        "n_header": n_header,
        "accum": GRACEFO_ACCUM_COLUMNS,
        "uncounted": GRACEFO_UNCOUNTED,
        "format": "gracefo-thr1b",
    }


# --------------------------------------------------------------------------- records


def _parse_records(data: bytes, first_line: int, path: Path) -> dict[str, Any]:
    """Parse the data section; every bad record raises FormatError naming its line."""
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        line = first_line + data[: exc.start].count(b"\n")
        raise FormatError("non-ASCII bytes in a record (binary data?)", path, line) from None
    lines: list[int] = []
    ints: list[list[int]] = []
    time_ref: list[str] = []
    ids: list[str] = []
    qual: list[int] = []
    for i, raw_line in enumerate(text.split("\n")):
        tok = raw_line.split()
        if not tok:
            continue
        line = first_line + i
        if len(tok) != N_FIELDS:
            raise FormatError(
                f"record has {len(tok)} fields, expected {N_FIELDS} (time, time fraction, "
                "time_ref, id, 14 counts, 14 on-times, 14 durations, qualflg)",
                path,
                line,
            )
        row = []
        for j in (0, 1, *range(4, N_FIELDS - 1)):
            s = tok[j]
            if not (s.isdigit() and s.isascii()):
                raise FormatError(
                    f"{_FIELD_NAMES[j]} (field {j + 1}): not a non-negative integer: "
                    f"{one_line(s, 20)!r}",
                    path,
                    line,
                )
            row.append(int(s))
        if row[1] > 999_999:
            raise FormatError(f"time_frac {row[1]} µs is not in 0 ... 999999", path, line)
        big = [v for v in row[2:] if v > COUNTER_MAX]
        if big:
            raise FormatError(f"value {big[0]} exceeds the 32-bit counter range", path, line)
        if tok[2] not in ("G", "R"):
            raise FormatError(
                f"time_ref {one_line(tok[2], 10)!r} is not G (GPS) or R (receiver)", path, line
            )
        if tok[3] not in SATELLITES:
            raise FormatError(
                f"satellite id {one_line(tok[3], 10)!r} is not one of A, B, C, D", path, line
            )
        q = tok[-1]
        if len(q) != 8 or q.strip("01"):
            raise FormatError(f"qualflg {one_line(q, 20)!r} is not 8 characters of 0/1", path, line)
        lines.append(line)
        ints.append(row)
        time_ref.append(tok[2])
        ids.append(tok[3])
        qual.append(int(q, 2))
    if not ints:
        raise FormatError("header but no data records", path, first_line)
    a = np.array(ints, dtype=np.int64)
    return {
        "time": a[:, 0] + a[:, 1] * 1e-6,
        "counts": a[:, 2:16],
        "on_time_ms": a[:, 16:30],
        "accum_ms": a[:, 30:44],
        "time_ref": np.array(time_ref),
        "id": np.array(ids),
        "qualflg": np.array(qual, dtype=np.int64),
        "line": np.array(lines, dtype=np.int64),
    }


def _derive_events(
    counts: NDArray[np.int64],
    on_time: NDArray[np.float64],
    counted: NDArray[np.bool_],
    time: NDArray[np.float64],
) -> tuple[FiringEvents, NDArray[np.bool_], NDArray[np.bool_]]:
    """Firing events from counters and on-times (rules in :func:`read_thrusters`).

    Returns the events and two (n, 14) masks for the warnings: counters that went
    back, and on-times without a count increase.
    """
    n = counts.shape[0]
    step = np.zeros_like(counts)
    step[1:] = np.diff(counts, axis=0)
    has_prev = np.zeros((n, 1), dtype=bool)
    has_prev[1:] = True
    by_count = has_prev & counted & (step > 0)
    by_on_time = (~has_prev | ~counted) & (on_time > 0)
    back = has_prev & counted & (step < 0)
    orphan = has_prev & counted & (step == 0) & (on_time > 0)
    rec, thr = np.nonzero(by_count | by_on_time)
    cycles = np.where(by_count[rec, thr], step[rec, thr], 0)
    order = np.lexsort((thr, time[rec]))
    rec, thr, cycles = rec[order], thr[order], cycles[order]
    events = FiringEvents(time[rec], on_time[rec, thr], thr, rec, cycles)
    return events, back, orphan


def _where(mask: NDArray[np.bool_], lines: NDArray[np.int64]) -> str:
    """'N (thrusters ..., first at line L)' for a (n, 14) mask."""
    rec, thr = np.nonzero(mask)
    names = ", ".join(THRUSTERS[k] for k in sorted(set(thr.tolist())))
    return f"{rec.size} ({names}; first at line {int(lines[rec.min()])})"


# --------------------------------------------------------------------------- public


def read_thrusters(path: str | Path) -> ThrusterFirings:
    """Read a GRACE / GRACE-FO THR1B thruster file and derive its firing events.

    Parameters
    ----------
    path : str or Path
        GRACE THR1B ASCII (``END OF HEADER``) or GRACE-FO RL04 THR1B ASCII (YAML
        header), optionally gzipped (detected by content, not name).

    Returns
    -------
    ThrusterFirings
        Record epochs [s, GPS], counters, on-times [s], accumulated durations [s],
        ``qualflg``, the derived :class:`FiringEvents`, the header in ``meta`` and
        the findings in ``warnings``.

    Raises
    ------
    FormatError
        Missing, unreadable, empty or corrupt file, no end-of-header marker, a
        header without records, or a bad record: wrong number of fields, a field
        that is not a non-negative integer, ``time_frac`` over 999999, ``time_ref``
        other than G/R, an id other than A-D, a ``qualflg`` that is not 8 characters
        of 0/1, mixed satellite ids.  The message names the file and ``.line`` the
        1-based line of the record.
    UnsupportedFormatError
        A binary THR1B file, a GRACE header of another product (e.g. ACC1B), a
        GRACE-FO header whose column list is not :data:`GRACEFO_COLUMNS`.

    Notes
    -----
    **Firing events.**  A record is written when thrusters fire; its epoch is the
    firing start ("Activation time", ``THR1X_t`` in JPL's ``GRACEiolib.h``; GROOPS
    ``InstrumentRemoveEpochsThruster`` likewise puts its "margin before start of
    firing" before the record epoch).  For record ``i`` and thruster ``k``:

    1. ``i > 0`` and the counter of ``k`` increased since record ``i - 1``: an event
       at ``time[i]`` lasting ``on_time[i, k]``, with ``cycles`` = the increase.
       An increase of more than one (``qualflg`` bit 1, "Multiple unaccounted
       thrusts prior to current record") is still one event, whose on-time is the
       record's (in the GRACE samples it is about twice a single pulse: the
       earlier pulse is not separately timed).
    2. ``i = 0``: no previous counter to compare with; the first record's own
       on-times describe firings "for this time tag", so every thruster with
       ``on_time[0, k] > 0`` gives an event (``cycles`` 0).  This is what GROOPS
       does: ``GraceL1b2Thruster`` keeps the on-times of every record, the first
       included, and ``InstrumentRemoveEpochsThruster`` masks around every record.
    3. Thrusters without a counter (GRACE-FO orbit thrusters, whose count fields
       are "Undefined"): an event wherever ``on_time[i, k] > 0`` (``cycles`` 0).
    4. A counter that decreased (reset, or the wrap after 4294967295): no event,
       and a warning.  A positive on-time without a count increase (``i > 0``):
       no event, and a warning.  An event whose on-time is 0 (``qualflg`` bit 0,
       "On-time not calculated") keeps duration 0, with a warning.

    In the four samples, rules 1 and "on-time > 0" agree on every record.  Records
    out of time order are sorted (stable) before the differences are taken, with a
    warning; a record count different from the header's is a warning (the GRACE-FO
    samples are cut after 100 records).
    """
    path = Path(path)
    raw = read_l1b_bytes(path)
    flavour, header, data_start, first_line = split_header(raw, path)
    info = (_interpret_gracefo if flavour == "gracefo" else _interpret_grace)(header, path)
    rec = _parse_records(raw[data_start:], first_line, path)
    lines = rec["line"]
    check_gps_time(rec["time"], path, lambda i: int(lines[i]))
    warn: list[str] = []
    ids = sorted(set(rec["id"].tolist()))
    if len(ids) > 1:
        raise FormatError(f"mixed satellite ids {ids} in one file", path)
    if ids[0] != info["letter"]:
        warn.append(
            f"records carry satellite id {ids[0]!r} but the header names {info['letter']!r}"
        )
    n_recv = int(np.count_nonzero(rec["time_ref"] == "R"))
    if n_recv:
        warn.append(f"{n_recv} records carry receiver time (time_ref R), not GPS time")
    n = int(rec["time"].size)
    if info["n_header"] is not None and info["n_header"] != n:
        warn.append(f"header announces {info['n_header']} data records, file has {n}")
    time = rec["time"]
    order = np.arange(n)
    n_back = int(np.count_nonzero(np.diff(time) < 0))
    if n_back:
        order = np.argsort(time, kind="stable")
        warn.append(f"{n_back} records out of time order (sorted)")
    n_dup = int(np.count_nonzero(np.diff(time[order]) == 0))
    if n_dup:
        warn.append(f"{n_dup} records repeat the epoch of the previous record")
    time, lines = time[order], lines[order]
    counts = rec["counts"][order]
    on_time = rec["on_time_ms"][order] / 1000.0
    qualflg = rec["qualflg"][order]
    counted = np.array([t not in info["uncounted"] for t in THRUSTERS])
    events, back, orphan = _derive_events(counts, on_time, counted, time)
    if back.any():
        warn.append(f"counters went back (reset or wrap), no event: {_where(back, lines)}")
    if orphan.any():
        warn.append(
            f"on-times without a count increase, not taken as firings: {_where(orphan, lines)}"
        )
    zero = events.duration == 0
    if zero.any():
        warn.append(f"{int(zero.sum())} firings without an on-time (duration 0 s)")
    accum = {name: rec["accum_ms"][order, j] / 1000.0 for j, name in enumerate(info["accum"])}
    meta = dict(info["meta"])
    meta["thrusters"] = {
        "format": info["format"],
        "n_records_header": info["n_header"],
        "n_rows": n,
    }
    return ThrusterFirings(
        time=time,
        satellite=SATELLITES[info["letter"]],
        counts=counts,
        on_time=on_time,
        accum_dur=accum,
        qualflg=qualflg,
        events=events,
        uncounted=tuple(info["uncounted"]),
        meta=meta,
        warnings=tuple(warn),
    )


#: A THR1B file whose records all lie further than this from the data [s] is another
#: day's (:func:`foreign_day`).
FOREIGN_MARGIN = 3600.0


def foreign_day(firings: ThrusterFirings, times: ArrayLike, path: str | Path) -> str | None:
    """Why ``firings`` (read from ``path``) are not those of the data at ``times``, or None.

    QA (2026-11-30): a THR1B file beside a day whose records were of another epoch was
    used without a word: no firing fell in the day, ``n_thruster`` 0, and the fit
    differed from the one with the day's firings.  Records only where the counters
    change make a file's span shorter than its day, so only a file with no record
    within :data:`FOREIGN_MARGIN` of the data is taken for another day's.
    """
    t = np.asarray(times, dtype=np.float64)
    rec = firings.time
    if t.size == 0 or rec.size == 0:
        return None
    if rec[-1] >= t[0] - FOREIGN_MARGIN and rec[0] <= t[-1] + FOREIGN_MARGIN:
        return None
    return (
        f"{Path(path).name}: its records are of {gps_to_date(float(rec[0]))} to "
        f"{gps_to_date(float(rec[-1]))} (GPS), the data of {gps_to_date(float(t[0]))}: "
        "another day's thruster file, not used (the firings are unknown)"
    )


def firing_mask(
    times: ArrayLike,
    firings: ThrusterFirings | FiringEvents,
    before: float = DEFAULT_BEFORE,
    after: float = DEFAULT_AFTER,
) -> NDArray[np.bool_]:
    """True where a sample lies within a margin around any thruster firing.

    Parameters
    ----------
    times : array_like of float, shape (n,)
        Sample epochs [s, GPS seconds since 2000-01-01 12:00:00], any order; NaN
        gives False.
    firings : ThrusterFirings or FiringEvents
        The firings (``firings.events`` for a :class:`ThrusterFirings`).
    before : float, optional
        Margin before the start of a firing [s], >= 0; default 0.1 s.
    after : float, optional
        Margin after the end of a firing [s], >= 0; default 0.7 s.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where ``start - before <= t <= start + duration + after`` for some firing
        (closed intervals).

    Raises
    ------
    ValidationError
        ``times`` not 1-D numeric, a margin negative or not finite.

    Notes
    -----
    The defaults are those of GROOPS ``InstrumentRemoveEpochsThruster``
    (``marginBefore`` 0.1 s "before start of firing", ``marginAfter`` 0.7 s "after
    end of firing"), which removes samples with ``start - 0.1 <= t < end + 0.7``
    (half-open; here the end is included too).  GROOPS takes one interval per THR1B
    record, ending at the longest on-time of the record; the per-thruster events
    give the same union wherever every record yields an event (true of the
    samples).  The intervals are sorted and merged, then each sample is located
    with :func:`numpy.searchsorted`: O((n + m) log m) for n samples and m firings.
    """
    try:
        t = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError("sample epochs 'times' must be numeric") from None
    if t.ndim != 1:
        raise ValidationError(f"sample epochs 'times' must be 1-D, got shape {t.shape}")
    for name, value in (("before", before), ("after", after)):
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValidationError(f"{name} must be a number [s], got {value!r}") from None
        if not (np.isfinite(v) and v >= 0):
            raise ValidationError(f"{name} must be finite and >= 0 [s], got {value!r}")
    events = firings.events if isinstance(firings, ThrusterFirings) else firings
    if not isinstance(events, FiringEvents):
        raise ValidationError(
            f"firings must be ThrusterFirings or FiringEvents, got {type(firings).__name__}"
        )
    if len(events) == 0 or t.size == 0:
        return np.zeros(t.shape, dtype=bool)
    lo = events.start - float(before)
    hi = (events.start + events.duration) + float(after)
    order = np.argsort(lo, kind="stable")
    lo, hi = lo[order], np.maximum.accumulate(hi[order])
    new = np.ones(lo.size, dtype=bool)
    new[1:] = lo[1:] > hi[:-1]
    first = np.flatnonzero(new)
    last = np.append(first[1:] - 1, lo.size - 1)
    lo_m, hi_m = lo[first], hi[last]
    k = np.searchsorted(lo_m, t, side="right") - 1
    inside = k >= 0
    inside[inside] = t[inside] <= hi_m[k[inside]]
    return inside


def find_thruster_file(acc_path: str | Path) -> Path | None:
    """The THR1B file next to an ACC1B / ACT1B file (same date, satellite, release).

    Parameters
    ----------
    acc_path : str or Path
        An accelerometer file named like ``ACC1B_2003-09-14_A_00.asc`` or
        ``ACT1B_2023-06-01_C_04.txt`` (optionally ``.gz``; a prefix before the
        product name is kept).

    Returns
    -------
    Path or None
        The first existing file, in the same directory, named ``THR1B`` with the
        same date, satellite and release and suffix ``.asc`` or ``.txt`` (the one
        of ``acc_path`` first; each plain, then gzipped, or the other way round
        when ``acc_path`` is gzipped); None if there is none or the name is not an
        ACC1B / ACT1B name.  Binary THR1B files (``.dat``) are not looked for:
        :func:`read_thrusters` cannot read them.
    """
    p = Path(acc_path)
    m = _ACC_NAME.search(p.name)
    if m is None:
        return None
    stem = f"{p.name[: m.start()]}THR1B_{m['date']}_{m['sat']}_{m['rel']}"
    exts = [".txt", ".asc"] if m["ext"] == ".txt" else [".asc", ".txt"]
    gz = (".gz", "") if m["gz"] or m["ext"] == ".gz" else ("", ".gz")
    for ext in exts:
        for z in gz:
            candidate = p.with_name(stem + ext + z)
            if candidate.is_file():
                return candidate
    return None


__all__ = [
    "COUNT_COLUMNS",
    "DEFAULT_AFTER",
    "DEFAULT_BEFORE",
    "GRACEFO_ACCUM_COLUMNS",
    "GRACEFO_COLUMNS",
    "GRACEFO_UNCOUNTED",
    "GRACE_ACCUM_COLUMNS",
    "ON_TIME_COLUMNS",
    "QUALFLG_BITS",
    "THRUSTERS",
    "FiringEvents",
    "ThrusterFirings",
    "find_thruster_file",
    "firing_mask",
    "foreign_day",
    "read_thrusters",
]
