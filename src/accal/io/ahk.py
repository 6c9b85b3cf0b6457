"""Reader of GRACE / GRACE-FO AHK1B files (accelerometer housekeeping) into :class:`Housekeeping`.

Headers are split and parsed with the helpers of :mod:`accal.io.grace.header`,
records by :mod:`accal.io.ahk_records`; the format is :mod:`accal.io.ahk_spec`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import FormatError, UnsupportedFormatError
from accal.io.ahk_records import _parse_records
from accal.io.ahk_spec import (
    ABSOLUTE_ZERO_C,
    GRACE_FIELDS,
    GRACE_FILE_TYPES,
    GRACEFO_BIT_MEANINGS,
    GRACEFO_FIELDS,
    GRACEFO_INFERRED_UNITS,
    N_FIXED,
    RECORD_COLUMNS,
)
from accal.io.common import shorten
from accal.io.grace.header import (
    global_attributes,
    grace_int,
    header_satellite,
    load_yaml_header,
    parse_grace_header,
    refuse_binary,
    split_header,
)
from accal.io.grace.spec import SATELLITES
from accal.io.hk_data import Housekeeping, _sort_merge
from accal.series import UNITS

_BIT_MEANING_RE = re.compile(r"^bits?\s+(\d+)(?:\s*-\s*(\d+))?\s*=\s*(.*?)\s*$")


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = parse_grace_header(header, path)
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
        "n_header": grace_int(meta, lines, "NUMBER OF DATA RECORDS", path),
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
    platform = str(global_attributes(hdr, path).get("platform", ""))
    letter = platform.split()[-1] if platform.split() else ""
    if letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {shorten(platform, 40)}, expected 'GRACE C' or 'GRACE D'",
            path,
        )
    return {
        "meta": {"gracefo": hdr},
        "letter": letter,
        "n_header": n_header,
        "fields": GRACEFO_FIELDS,
        "format": "gracefo-ahk1b",
    }


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


def read_ahk1b(raw: bytes, path: Path) -> Housekeeping:
    flavour, header, data_start, first_line = split_header(raw, path)
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
