"""Writer of GRACE (RL02-style) and GRACE-FO (RL04) ACC1B ASCII files, and header helpers.

:func:`calendar_text` and :func:`yaml_header_lines` also serve the writers of
other simulated L1B products (``accal.simulate``).
"""

from __future__ import annotations

import gzip
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import ValidationError, check_option
from accal.io.grace.header import _yaml
from accal.io.grace.spec import (
    AUX_COLUMNS,
    COLUMN_UNITS,
    GRACE_KEY_WIDTH,
    GRACEFO_COLUMNS,
    HEADER_END,
    SATELLITES,
)
from accal.io.writers import atomic_path
from accal.series import AccSeries
from accal.timescale import gps_to_gps_calendar


def _calendar(t: float) -> str:
    s = str(gps_to_gps_calendar([t])[0])  # 'YYYY-MM-DDTHH:MM:SS.fffffffff'
    date, _, clock = s.partition("T")
    return f"{date} {clock[:11]}"


def calendar_text(t: float) -> str:
    """GPS calendar time of ``t`` [s GPS] as L1B headers write it: ``YYYY-MM-DD HH:MM:SS.ff``."""
    return _calendar(t)


def yaml_header_lines(header: dict[str, Any]) -> list[str]:
    """A GRACE-FO YAML header ``{"header": header}`` as text lines, with the end marker.

    Written with the reader's own dumper (strings plain where YAML allows, as the
    real files), so :func:`read_grace_l1b`-style readers read it back unchanged.
    """
    yaml, _, dumper = _yaml()
    text = yaml.dump(
        {"header": header}, Dumper=dumper, sort_keys=False, allow_unicode=True, width=1 << 16
    )
    return [*text.rstrip("\n").split("\n"), "# End of YAML header"]


def _grace_header(series: AccSeries, letter: str) -> list[str]:
    n = len(series)
    t0, t1 = (float(series.time[0]), float(series.time[-1])) if n else (0.0, 0.0)
    hdr: dict[str, Any] = dict(series.meta.get("grace") or {})
    if not hdr:
        hdr = {
            "PRODUCER AGENCY": "accal",
            "PRODUCER INSTITUTION": "accal",
            "FILE TYPE ipACC1BF": "8",
            "FILE FORMAT 0=BINARY 1=ASCII": "1",
            "NUMBER OF HEADER RECORDS": "",
            "SOFTWARE VERSION": "accal.io.grace_l1b.write_grace_acc1b",
            "REFERENCE DOCUMENTATION": "GRACE Level 1 Software Handbook",
            "SATELLITE NAME": "",
            "SENSOR NAME": "ACC",
            "TIME EPOCH (GPS TIME)": "2000-01-01 12:00:00",
            "TIME FIRST OBS(SEC PAST EPOCH)": "",
            "TIME LAST OBS(SEC PAST EPOCH)": "",
            "NUMBER OF DATA RECORDS": "",
            "PROCESS LEVEL (1A OR 1B)": "1B",
        }
    hdr["FILE FORMAT 0=BINARY 1=ASCII"] = "1"
    hdr["SATELLITE NAME"] = f"GRACE {letter}"
    hdr["TIME FIRST OBS(SEC PAST EPOCH)"] = f"{t0:.6f} ({_calendar(t0)})"
    hdr["TIME LAST OBS(SEC PAST EPOCH)"] = f"{t1:.6f} ({_calendar(t1)})"
    hdr["NUMBER OF DATA RECORDS"] = str(n)
    n_lines = sum(len(v) if isinstance(v, list) else 1 for v in hdr.values())
    hdr["NUMBER OF HEADER RECORDS"] = str(n_lines)
    lines = []
    for key, value in hdr.items():
        for v in value if isinstance(value, list) else [value]:
            lines.append(f"{key:<{GRACE_KEY_WIDTH}}: {v}".ljust(80))
    lines.append("END OF HEADER".ljust(80))
    return lines


_ORDINAL = {1: "st", 2: "nd", 3: "rd"}


def _gracefo_header(series: AccSeries, letter: str) -> list[str]:
    import copy

    n = len(series)
    t0, t1 = (float(series.time[0]), float(series.time[-1])) if n else (0.0, 0.0)
    hdr = copy.deepcopy(series.meta.get("gracefo") or {})
    if not hdr:
        variables = []
        for i, name in enumerate(GRACEFO_COLUMNS, start=1):
            unit = {"GRACEFO_id": "char", "qualflg": "none"}.get(
                name, COLUMN_UNITS.get(name, "").replace("^", "")
            )
            if name == "gps_time":
                unit = "second"
            suffix = _ORDINAL.get(i if i < 20 else i % 10, "th")
            variables.append({name: {"comment": f"{i}{suffix} column", "units": unit}})
        hdr = {
            "dimensions": {"num_records": ""},
            "global_attributes": {
                "creator_name": "accal",
                "platform": "",
                "processing_level": "1B",
                "product_version": "04",
                "title": "GRACE-FO Level-1B Transformed Accelerometer Data (written by accal)",
            },
            "non-standard_attributes": {"epoch_time": "2000-01-01T12:00:00.00"},
            "variables": variables,
        }
    hdr.setdefault("dimensions", {})["num_records"] = str(n)
    ga = hdr.setdefault("global_attributes", {})
    ga["platform"] = f"GRACE {letter}"
    ga["time_coverage_start"] = _calendar(t0).replace(" ", "T")
    ga["time_coverage_stop"] = _calendar(t1).replace(" ", "T")
    nsa = hdr.setdefault("non-standard_attributes", {})
    nsa["start_time_epoch_secs"] = f"{t0:.0f}" if t0 == int(t0) else repr(t0)
    nsa["stop_time_epoch_secs"] = f"{t1:.0f}" if t1 == int(t1) else repr(t1)
    yaml, _, str_dumper = _yaml()
    text = yaml.dump(
        {"header": hdr}, Dumper=str_dumper, sort_keys=False, allow_unicode=True, width=1 << 16
    )
    return [*text.rstrip("\n").split("\n"), HEADER_END["gracefo"][0]]


def _format_floats(a: np.ndarray) -> list[str]:
    # repr() is the shortest string that reads back to the same double: exact round trip.
    return [repr(v) for v in a.tolist()]


def write_grace_acc1b(series: AccSeries, path: str | Path, *, flavour: str | None = None) -> Path:
    """Write ``series`` as a GRACE (RL02-style) or GRACE-FO (RL04) ACC1B ASCII file.

    Parameters
    ----------
    series : AccSeries
        Three axes x, y, z [m/s²]; satellite one of ``GRACE-A``, ``GRACE-B``,
        ``GRACE-FO-C``, ``GRACE-FO-D``; ``quality`` < 256 (8-bit qualflg).
        ``aux`` channels ``ang_accl_*`` [rad/s²] and ``acl_*_res`` [m/s²] are written
        when present (else 0); other auxiliary channels are dropped with a warning.
    path : str or Path
        Output file, written atomically; gzip-compressed if the name ends in ``.gz``.
    flavour : {"grace", "gracefo"}, optional
        Header style; default from the satellite (A/B: grace, C/D: gracefo).

    Returns
    -------
    Path
        The written path.

    Notes
    -----
    The header is ``meta["grace"]`` / ``meta["gracefo"]`` when present (so a file
    read and written again keeps its header), else a minimal one; the record
    count, first/last time and satellite fields are always refreshed.  Floats are
    written with ``repr`` (shortest exact representation, <= 17 significant
    digits; real files use 16), times as integers when integral, and two spaces
    before the 8-character ``qualflg`` as the JPL writer does.  Reading the
    output gives back the same time, acc, quality, valid, aux and meta.
    """
    inv = {v: k for k, v in SATELLITES.items()}
    if series.satellite not in inv:
        raise ValidationError(
            f"satellite must be one of {', '.join(inv)} to write GRACE L1B, "
            f"got {series.satellite!r}"
        )
    letter = inv[series.satellite]
    if flavour is None:
        flavour = "grace" if letter in "AB" else "gracefo"
    check_option("flavour", flavour, ("grace", "gracefo"))
    if (flavour == "grace") != (letter in "AB"):
        raise ValidationError(f"flavour {flavour!r} does not match satellite {series.satellite!r}")
    if tuple(series.axes) != ("x", "y", "z"):
        raise ValidationError(f"GRACE L1B needs axes ('x', 'y', 'z'), got {series.axes}")
    if len(series) == 0:
        raise ValidationError("cannot write an empty series (L1B files need data records)")
    q = series.quality
    if q.size and int(q.max()) > 255:
        raise ValidationError(f"quality must fit 8 bits (qualflg), got max {int(q.max())}")
    extra = sorted(set(series.aux) - set(AUX_COLUMNS))
    if extra:
        warnings.warn(
            f"{len(extra)} auxiliary channels not representable in L1B dropped: {extra}",
            stacklevel=2,
        )
    n = len(series)
    header = (
        _grace_header(series, letter) if flavour == "grace" else _gracefo_header(series, letter)
    )
    t = series.time
    integral = np.all(t == np.round(t)) and np.all(np.abs(t) < 2**53)
    tcol = [str(int(v)) for v in t.tolist()] if integral else _format_floats(t)
    cols = [tcol, [letter] * n]
    cols += [_format_floats(series.acc[:, i]) for i in range(3)]
    zero = ["0"] * n
    for c in AUX_COLUMNS:
        cols.append(_format_floats(np.asarray(series.aux[c], float)) if c in series.aux else zero)
    qual = [format(v, "08b") for v in q.tolist()]
    body = "\n".join(" ".join(row[:-1]) + "  " + row[-1] for row in zip(*cols, qual, strict=True))
    text = ("\n".join(header) + "\n" + body + "\n").encode("utf-8")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if path.suffix == ".gz" else text)
    return path
