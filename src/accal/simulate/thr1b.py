"""THR1B files of simulated thruster pulses (``accal simulate grace --thrusters``).

The pulses :func:`accal.simulate.grace.simulate_grace_day` adds to the true signal
are written as a THR1B file beside the ACC1B/ACT1B file, in the GRACE ASCII (A/B)
or GRACE-FO YAML (C/D) layout that :func:`accal.io.thrusters.read_thrusters` reads
(formats: the real samples in ``data/samples`` and that module's docstring), so that
``accal grace-bias`` finds and screens the firings as it does for real days.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.io.grace_l1b import GRACE_KEY_WIDTH, calendar_text, yaml_header_lines
from accal.io.writers import atomic_path

__all__ = ["THRUSTER_PAIRS", "thr1b_records", "thruster_path", "write_simulated_thr1b"]

_L1B_NAME = re.compile(
    r"(?:ACC1B|ACT1B)_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rel>\d+)"
    r"(?:\.[A-Za-z0-9]+)?(?P<gz>\.gz)?$"
)


def thruster_path(out: str | Path, satellite: str) -> Path:
    """The THR1B file written beside a simulated ACC1B/ACT1B file (``--thrusters``).

    For an L1B name (``[prefix]ACC1B_2005-01-01_A_02.asc``, ``ACT1B_..._C_04.txt``,
    optionally ``.gz``) the THR1B name of the same prefix, date, satellite and
    release, ``.asc`` for GRACE A/B and ``.txt`` for GRACE-FO C/D (gzipped with the
    data file), which :func:`accal.io.thrusters.find_thruster_file` finds and
    ``accal grace-bias`` uses; for any other name ``<out>.THR1B.asc`` / ``.txt``
    (give it to ``grace-bias --thrusters``).
    """
    out = Path(out)
    ext = ".asc" if satellite in ("A", "B") else ".txt"
    m = _L1B_NAME.search(out.name)
    if m is None:
        return out.with_name(out.name + ".THR1B" + ext)
    gz = ".gz" if m["gz"] else ""
    return out.with_name(f"{out.name[: m.start()]}THR1B_{m['date']}_{m['sat']}_{m['rel']}{ext}{gz}")


#: Attitude-thruster pair (1-6) that stands for a simulated pulse on an axis with a
#: sign (a convention of the simulator: the real thrusters make torques, in pairs).
THRUSTER_PAIRS = {("x", 1): 1, ("x", -1): 2, ("y", 1): 3, ("y", -1): 4, ("z", 1): 5, ("z", -1): 6}


def thr1b_records(
    pulses: Sequence[dict[str, Any]], satellite: str, t0: float, rng: np.random.Generator
) -> dict[str, NDArray]:
    """THR1B records of simulated thruster pulses (:func:`write_simulated_thr1b`).

    One record per distinct pulse epoch (``time`` [s, GPS]); a pulse on axis ``a``
    with sign ``±`` fires the attitude pair :data:`THRUSTER_PAIRS` ``(a, ±)``: both
    ``att_ctrl_1_k`` and ``att_ctrl_2_k`` (columns ``k − 1`` and ``k + 5``) count one
    work cycle more, with the pulse length as on-time [ms], as the paired firings of
    the real files.  Counters and accumulated durations start at random values of
    the magnitudes of ``data/samples`` (GRACE: pairs equal, per-thruster durations,
    orbit counters small; GRACE-FO: branch 2 a few hundred cycles behind, one
    attitude and one orbit duration, undefined fields 0).  Two pulses of one pair
    at one epoch make one record with two cycles and ``qualflg`` bit 1.  No pulse:
    one record at ``t0`` with the start values and no on-time (no firing).

    Returns
    -------
    dict
        ``time`` (m,), ``counts`` (m, 14), ``on_time_ms`` (m, 14), ``accum_ms``
        (m, 14), ``qualflg`` (m,), all int64 but ``time``.
    """
    grace = satellite in ("A", "B")
    pair0 = rng.integers(100_000, 400_000, 6)
    counts0 = np.zeros(14, dtype=np.int64)
    counts0[:6] = pair0
    counts0[6:12] = pair0 if grace else pair0 - rng.integers(0, 500, 6)
    accum0 = np.zeros(14, dtype=np.int64)
    if grace:
        counts0[12:] = rng.integers(1, 100, 2)
        dur = rng.integers(10_000_000, 50_000_000, 6)
        accum0[:6] = dur
        accum0[6:12] = dur
        accum0[12:] = 100_000
    else:
        accum0[0] = rng.integers(50_000_000, 200_000_000)
        accum0[12] = rng.integers(10_000_000, 50_000_000)
    base_flag = 0 if grace else 0b1100  # GRACE-FO: branches 1 and 2 active (bits 2, 3)
    epochs = sorted({float(p["epoch"]) for p in pulses})
    if not epochs:
        zero = np.zeros((1, 14), dtype=np.int64)
        return {
            "time": np.array([t0]),
            "counts": counts0[None, :],
            "on_time_ms": zero,
            "accum_ms": accum0[None, :],
            "qualflg": np.array([base_flag], dtype=np.int64),
        }
    m = len(epochs)
    row = {e: i for i, e in enumerate(epochs)}
    inc = np.zeros((m, 14), dtype=np.int64)
    on = np.zeros((m, 14), dtype=np.int64)
    for p in pulses:
        k = THRUSTER_PAIRS[(p["axis"], 1 if p["amplitude"] > 0 else -1)]
        r = row[float(p["epoch"])]
        for j in (k - 1, k + 5):
            inc[r, j] += 1
            on[r, j] = max(on[r, j], int(round(1000.0 * p["length"])))
    counts = counts0 + np.cumsum(inc, axis=0)
    if grace:
        accum = accum0 + np.cumsum(on, axis=0)
    else:
        accum = np.tile(accum0, (m, 1))
        accum[:, 0] += np.cumsum(on[:, :12].sum(axis=1))
    qual = base_flag | np.where(inc.max(axis=1) > 1, 0b10, 0)
    return {
        "time": np.array(epochs),
        "counts": counts,
        "on_time_ms": on,
        "accum_ms": accum,
        "qualflg": qual.astype(np.int64),
    }


def _thr1b_header(rec: dict[str, NDArray], satellite: str) -> list[str]:
    from accal.io.thrusters import GRACEFO_COLUMNS

    n = rec["time"].size
    t0, t1 = float(rec["time"][0]), float(rec["time"][-1])
    if satellite in ("A", "B"):
        hdr = {
            "PRODUCER AGENCY": "accal",
            "PRODUCER INSTITUTION": "accal",
            "FILE TYPE ipTHR1XF": "16",
            "FILE FORMAT 0=BINARY 1=ASCII": "1",
            "NUMBER OF HEADER RECORDS": "15",
            "SOFTWARE VERSION": "accal.simulate.grace.write_simulated_thr1b",
            "REFERENCE DOCUMENTATION": "GRACE Level 1 Software Handbook",
            "SATELLITE NAME": f"GRACE {satellite}",
            "SENSOR NAME": "Nodef",
            "TIME EPOCH (GPS TIME)": "2000-01-01 12:00:00",
            "TIME FIRST OBS(SEC PAST EPOCH)": f"{t0:.6f} ({calendar_text(t0)})",
            "TIME LAST OBS(SEC PAST EPOCH)": f"{t1:.6f} ({calendar_text(t1)})",
            "NUMBER OF DATA RECORDS": str(n),
            "PROCESS LEVEL (1A OR 1B)": "1B",
        }
        lines = [f"{k:<{GRACE_KEY_WIDTH}}: {v}".ljust(80) for k, v in hdr.items()]
        return [*lines, "END OF HEADER".ljust(80)]
    units = {"time_intg": "seconds", "time_frac": "microseconds", "time_ref": "char"}
    variables = []
    for i, name in enumerate(GRACEFO_COLUMNS, start=1):
        suffix = {1: "st", 2: "nd", 3: "rd"}.get(i if i < 20 else i % 10, "th")
        entry = {"comment": f"{i}{suffix} column"}
        unit = units.get(name, "milliseconds" if name.startswith(("on_time", "accum")) else "")
        if unit:
            entry["units"] = unit
        variables.append({name: entry})
    hdr = {
        "dimensions": {"num_records": str(n)},
        "global_attributes": {
            "creator_name": "accal",
            "instrument": "Thrusters",
            "platform": f"GRACE {satellite}",
            "processing_level": "1B",
            "product_version": "04",
            "source": f"Thruster data from GRACE {satellite} (simulated by accal)",
            "time_coverage_start": calendar_text(t0).replace(" ", "T"),
            "time_coverage_stop": calendar_text(t1).replace(" ", "T"),
            "title": "GRACE-FO Level-1B Thruster Data (simulated by accal)",
        },
        "non-standard_attributes": {"epoch_time": "2000-01-01T12:00:00.00"},
        "variables": variables,
    }
    return yaml_header_lines(hdr)


def write_simulated_thr1b(
    path: str | Path,
    pulses: Sequence[dict[str, Any]],
    satellite: str,
    t0: float,
    rng: np.random.Generator,
) -> Path:
    """Write simulated thruster pulses as a THR1B file (:func:`accal.io.thrusters.read_thrusters`).

    GRACE A/B: the GRACE ASCII layout (fixed-width header ending ``END OF HEADER``,
    ``FILE TYPE ipTHR1XF``); GRACE-FO C/D: the RL04 YAML layout (the 47 columns of
    :data:`accal.io.thrusters.GRACEFO_COLUMNS`).  Records from :func:`thr1b_records`:
    the firing events read back start at the pulses' epochs, last the pulses'
    lengths, and come in attitude pairs.  Gzipped for a ``.gz`` name.

    Parameters
    ----------
    path : str or Path
        Output file (written atomically).
    pulses : sequence of dict
        ``truth["thrusters"]`` of a simulated day (``epoch`` [s, GPS], ``length`` [s],
        ``axis``, ``amplitude`` [m/s²]).
    satellite : {"A", "B", "C", "D"}
    t0 : float
        First epoch of the day [s, GPS] (the one record of a day without pulses).
    rng : numpy.random.Generator
        Source of the counters' start values (the day's ``"thr1b"`` stream).

    Returns
    -------
    Path
    """
    import gzip

    rec = thr1b_records(pulses, satellite, t0, rng)
    header = _thr1b_header(rec, satellite)
    body = []
    for i, t in enumerate(rec["time"].tolist()):
        whole = int(np.floor(t))
        frac = int(round((t - whole) * 1e6))
        if frac == 1_000_000:
            whole, frac = whole + 1, 0
        ints = [*rec["counts"][i], *rec["on_time_ms"][i], *rec["accum_ms"][i]]
        body.append(
            f"{whole} {frac} G {satellite}   "
            + " ".join(str(int(v)) for v in ints)
            + f"   {int(rec['qualflg'][i]):08b}"
        )
    text = ("\n".join(header) + "\n" + "\n".join(body) + "\n").encode("ascii")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if path.name.endswith(".gz") else text)
    return path
