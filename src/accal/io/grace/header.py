"""L1B headers: sniffing, reading within the header's size, and parsing.

GRACE's fixed-width ``KEY : value`` header and GRACE-FO's YAML header (read by
the restricted loader of :func:`_yaml`) are split off the records and turned into
the reader's view of the file: flavour, satellite letter, record count, binary or
ASCII, columns and the first/last observation times.  The ACC1B reader and the
other L1B readers (attitude, thrusters, housekeeping) share these.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Any

import numpy as np

from accal.errors import FormatError, UnsupportedFormatError
from accal.io.common import GPS_TIME_RANGE, check_binary, peek, read_bytes, read_head, shorten
from accal.io.grace.spec import COLUMNS, GRACEFO_COLUMNS, HEADER_END, SATELLITES, YAML_MAX_DEPTH

GRACE_END_RE = re.compile(rb"^(?:# )?END OF HEADER[ \t]*\r?$", re.M)
_GRACEFO_END_RE = re.compile(rb"^# End of YAML header[ \t]*\r?$", re.M)
GRACE_KEY_RE = re.compile(rb"^(?:# )?[A-Z][A-Za-z0-9 ()=/.\-]{3,}:")
_HEADER_SEARCH = 1 << 20
_SNIFF_BYTES = 8192


@functools.cache
def _yaml() -> tuple[Any, Any, Any]:
    """Import pyyaml lazily (only GRACE-FO files need it) and build our loader/dumper.

    The loader keeps every plain scalar as the string written in the file and
    builds nothing but ``str``, ``list`` and ``dict``: explicit tags (``!!float``,
    ``!!timestamp``, ``!!binary``, ...), aliases (``*a``, which can expand a small
    header into an enormous ``meta``), duplicated keys and nesting deeper than
    :data:`YAML_MAX_DEPTH` are YAML errors.  The dumper writes strings plain where
    YAML allows it (like the real files).
    """
    import yaml
    from yaml.composer import ComposerError
    from yaml.constructor import ConstructorError, SafeConstructor
    from yaml.events import AliasEvent

    class _StrLoader(yaml.SafeLoader):
        _depth = 0

        def compose_node(self, parent: Any, index: Any) -> Any:
            event = self.peek_event()
            if isinstance(event, AliasEvent):
                raise ComposerError(None, None, "aliases (*name) are not allowed", event.start_mark)
            if self._depth >= YAML_MAX_DEPTH:
                raise ComposerError(
                    None, None, f"nested deeper than {YAML_MAX_DEPTH} levels", event.start_mark
                )
            self._depth += 1
            try:
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            seen = set()
            for key_node, _ in node.value:
                key = getattr(key_node, "value", None)
                if isinstance(key, str):
                    if key in seen:
                        raise ConstructorError(
                            None, None, f"duplicated key {key[:40]!r}", key_node.start_mark
                        )
                    seen.add(key)
            return super().construct_mapping(node, deep=deep)

    class _StrDumper(yaml.SafeDumper):
        pass

    _StrLoader.yaml_implicit_resolvers = {}
    _StrLoader.yaml_constructors = {
        "tag:yaml.org,2002:str": SafeConstructor.construct_yaml_str,
        "tag:yaml.org,2002:seq": SafeConstructor.construct_yaml_seq,
        "tag:yaml.org,2002:map": SafeConstructor.construct_yaml_map,
        None: SafeConstructor.construct_undefined,
    }
    _StrDumper.yaml_implicit_resolvers = {}
    return yaml, _StrLoader, _StrDumper


def sniff_grace_acc1b(path: str | Path) -> bool:
    """Return True if ``path`` looks like a GRACE / GRACE-FO L1B file (never raises).

    Reads at most 8 kB (decompressed); a true result does not guarantee the file
    is an ACC1B/ACT1B product or valid.
    """
    head = peek(path, _SNIFF_BYTES)
    if head.startswith(b"header:"):
        return b"num_records" in head and b"GRACE" in head
    first = head.split(b"\n", 1)[0]
    return (
        GRACE_KEY_RE.match(first) is not None
        and b"\nSATELLITE NAME" in head
        and (b"FILE FORMAT 0=BINARY 1=ASCII" in head or b"END OF HEADER" in head)
    )


#: Most bytes a data record of any L1B product takes, ASCII or binary (the longest
#: line of the bundled real ACC, ACT, AHK, GNV, SCA and THR samples is 346 bytes).
MAX_RECORD_BYTES = 1024
#: Below this size a file is read whatever its header announces: a wrong record
#: count stays a warning (:func:`read_grace_acc1b`), not a refusal.
L1B_SIZE_FLOOR = 64 << 20
_RECORD_COUNT_RE = re.compile(rb"(?:NUMBER OF DATA RECORDS|\bnum_records)\s*:\s*(\d{1,12})\b")


def read_l1b_bytes(path: str | Path) -> bytes:
    """The content of an L1B file, read only if its size fits the header's record count.

    A file larger than :data:`MAX_RECORD_BYTES` per record the header announces
    (and than :data:`L1B_SIZE_FLOOR`) is refused after reading its first MiB, before
    gigabytes of a wrong or padded file are read and parsed (issue 23, finding 9: a
    2 GB file reached 4.3 GB of memory and 30 s before failing).  Without a record
    count in the first MiB, :func:`accal.io.common.read_bytes` and its global
    limit decide.

    Raises
    ------
    FormatError
        As :func:`accal.io.common.read_bytes`, or the file is larger than its
        header's record count allows.
    """
    head = read_head(path, _HEADER_SEARCH)
    m = _RECORD_COUNT_RE.search(head)
    if m is None:
        return read_bytes(path)
    n = int(m.group(1))
    limit = max(m.end() + n * MAX_RECORD_BYTES + (1 << 20), L1B_SIZE_FLOOR)
    return read_bytes(
        path, limit, f"more than its header's {n:,} records can fill: padded, or not one L1B file?"
    )


def split_header(raw: bytes, path: Path) -> tuple[str, bytes, int, int]:
    """Return (flavour, header bytes, offset of data, 1-based line of first data row)."""
    head = raw[:_HEADER_SEARCH]
    flavour = "gracefo" if head.startswith(b"header:") else "grace"
    m = (_GRACEFO_END_RE if flavour == "gracefo" else GRACE_END_RE).search(head)
    if m is None:
        check_binary(head[:4096], path)
        want = " or ".join(repr(s) for s in HEADER_END[flavour])
        raise FormatError(f"no end-of-header marker ({want}) found", path)
    header = raw[: m.start()]
    check_binary(header, path)
    nl = raw.find(b"\n", m.end())
    data_start = len(raw) if nl < 0 else nl + 1
    first_data_line = raw[:data_start].count(b"\n") + 1
    return flavour, header, data_start, first_data_line


def parse_grace_header(header: bytes, path: Path) -> tuple[dict[str, Any], dict[str, int]]:
    meta: dict[str, Any] = {}
    lines: dict[str, int] = {}
    for i, raw_line in enumerate(header.decode("utf-8").split("\n"), start=1):
        line = raw_line.rstrip()
        if line.startswith("#"):
            line = line[1:].lstrip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        if not sep:
            raise FormatError(f"header line is not 'KEY : value': {shorten(line, 40)}", path, i)
        key, value = key.strip(), value.strip()
        if key in meta:
            prev = meta[key]
            meta[key] = [*prev, value] if isinstance(prev, list) else [prev, value]
        else:
            meta[key] = value
            lines[key] = i
    return meta, lines


def grace_int(meta: dict, lines: dict, key: str, path: Path) -> int | None:
    if key not in meta:
        return None
    value = meta[key]
    try:
        return int(str(value).split()[0])
    except (ValueError, IndexError):
        raise FormatError(
            f"header {key!r} is not an integer: {shorten(str(value), 40)}", path, lines.get(key)
        ) from None


def record_count(meta: dict, lines: dict, path: Path) -> int | None:
    """The header's NUMBER OF DATA RECORDS (None if absent); negative is an error."""
    key = "NUMBER OF DATA RECORDS"
    n = grace_int(meta, lines, key, path)
    if n is not None and n < 0:
        raise FormatError(f"header {key!r} is negative: {n}", path, lines.get(key))
    return n


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = parse_grace_header(header, path)
    file_type = next((k for k in meta if k.startswith("FILE TYPE")), None)
    if file_type is not None:
        m = re.search(r"ip(\w{3}1[AB])F", file_type)
        if m and m.group(1) not in ("ACC1B", "ACT1B"):
            raise UnsupportedFormatError(
                f"file type {m.group(0)!r} is not ACC1B/ACT1B accelerometer data "
                "(housekeeping such as AHK1B is not supported)",
                path,
                lines[file_type],
            )
    letter = header_satellite(meta, lines, path)
    fmt = grace_int(meta, lines, "FILE FORMAT 0=BINARY 1=ASCII", path)
    if fmt not in (None, 0, 1):
        raise FormatError(f"header 'FILE FORMAT' is {fmt}, expected 0 or 1", path)
    first, last = (
        header_time(meta.get(key), key, path, lines.get(key))
        for key in ("TIME FIRST OBS(SEC PAST EPOCH)", "TIME LAST OBS(SEC PAST EPOCH)")
    )
    return {
        "meta": {"grace": meta},
        "letter": letter,
        "n_header": record_count(meta, lines, path),
        "binary": fmt == 0,
        "columns": COLUMNS,
        "span": header_span(first, last, path),
    }


def header_time(value: Any, key: str, path: Path, line: int | None) -> float | None:
    """A header's observation time [s GPS]: None if absent, FormatError if not a time.

    GRACE headers give it as ``116769600.0 (2003-09-14 00:00:00.00)``: the first word.
    """
    if value is None:
        return None
    words = str(value).split()
    try:
        t = float(words[0]) if words else float("nan")
    except ValueError:
        t = float("nan")
    lo, hi = GPS_TIME_RANGE
    if not (np.isfinite(t) and lo <= t <= hi):
        raise FormatError(
            f"header {key!r} is not a GPS time in seconds: {shorten(str(value), 40)}", path, line
        )
    return t


def header_span(first: float | None, last: float | None, path: Path) -> tuple[float, float] | None:
    """The header's (first, last) observation times, both or None; last before first is wrong."""
    if first is None or last is None:
        return None
    if last < first:
        raise FormatError(
            f"header's last observation {last:.9g} s is before its first {first:.9g} s", path
        )
    return first, last


def load_yaml_header(header: bytes, path: Path) -> dict[str, Any]:
    """Parse a GRACE-FO YAML header into its ``header:`` mapping (scalars kept as str).

    Raises
    ------
    FormatError
        Invalid YAML (with its line), a construct refused by the loader of
        :func:`_yaml`, or no ``header:`` mapping.
    """
    yaml, str_loader, _ = _yaml()
    try:
        doc = yaml.load(header.decode("utf-8"), Loader=str_loader)  # noqa: S506 (safe loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise FormatError(f"YAML header: {problem}", path, line) from None
    except RecursionError:  # the loader caps nesting; belt and braces
        raise FormatError("YAML header: nested too deeply", path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("header"), dict):
        raise FormatError("YAML header has no 'header:' mapping", path, 1)
    return doc["header"]


def global_attributes(hdr: dict, path: Any) -> dict:
    """The ``global_attributes`` mapping of a GRACE-FO YAML header (empty when absent).

    Raises
    ------
    accal.errors.FormatError
        It is there but not a mapping (naming ``path``).
    """
    attrs = hdr.get("global_attributes") or {}
    if not isinstance(attrs, dict):
        raise FormatError("YAML header: 'global_attributes' is not a mapping", path)
    return attrs


def _interpret_gracefo(header: bytes, path: Path) -> dict[str, Any]:
    hdr = load_yaml_header(header, path)
    dims = hdr.get("dimensions")
    try:
        n_header = int(dims["num_records"]) if isinstance(dims, dict) else None
    except (KeyError, TypeError, ValueError):
        n_header = None
    if n_header is None:
        raise FormatError("YAML header: 'dimensions: num_records' missing or not an integer", path)
    variables = hdr.get("variables") or []
    if not isinstance(variables, list) or not all(isinstance(v, dict) and v for v in variables):
        raise FormatError("YAML header: 'variables' is not a list of mappings", path)
    names = tuple(next(iter(v)) for v in variables)
    if names and names != GRACEFO_COLUMNS:
        raise UnsupportedFormatError(
            f"columns {shorten(' '.join(names[:6]), 80)} ... are not ACC1B/ACT1B columns "
            "(only accelerometer data are supported)",
            path,
        )
    platform = global_attributes(hdr, path).get("platform", "")
    letter = platform.split()[-1] if isinstance(platform, str) and platform.split() else ""
    if platform is None or (isinstance(platform, str) and not platform.strip()):
        letter = ""  # no platform: the records' GRACEFO_id, else the file name (issue 23)
    elif letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {shorten(platform, 40)}, expected 'GRACE C' or 'GRACE D'",
            path,
        )
    nsa = hdr.get("non-standard_attributes") or {}
    if not isinstance(nsa, dict):
        raise FormatError("YAML header: 'non-standard_attributes' is not a mapping", path)
    first, last = (
        header_time(nsa.get(key), key, path, yaml_line(header, key))
        for key in ("start_time_epoch_secs", "stop_time_epoch_secs")
    )
    return {
        "meta": {"gracefo": hdr},
        "letter": letter,
        "n_header": n_header,
        "binary": False,
        "columns": GRACEFO_COLUMNS,
        "span": header_span(first, last, path),
    }


def yaml_line(header: bytes, key: str) -> int | None:
    """1-based line of the header where ``key:`` first appears (for messages)."""
    i = header.find(key.encode() + b":")
    return None if i < 0 else header.count(b"\n", 0, i) + 1


def header_satellite(meta: dict[str, Any], lines: dict[str, int], path: Path) -> str:
    """The satellite letter (A-D) of a GRACE-style header's ``SATELLITE NAME``.

    Raises
    ------
    FormatError
        Naming the file and header line when the name is not 'GRACE A' ... 'GRACE D'.
    """
    sat = str(meta.get("SATELLITE NAME", ""))
    letter = sat.split()[-1] if sat.split() else ""
    if letter not in SATELLITES:
        raise FormatError(
            f"header 'SATELLITE NAME' is {shorten(sat, 40)}, expected 'GRACE A' ... 'GRACE D'",
            path,
            lines.get("SATELLITE NAME"),
        )
    return letter


def refuse_binary(meta: dict[str, Any], lines: dict[str, int], path: Path, product: str) -> None:
    """UnsupportedFormatError for a binary (``FILE FORMAT 0``) file of an ASCII-only reader."""
    if grace_int(meta, lines, "FILE FORMAT 0=BINARY 1=ASCII", path) == 0:
        raise UnsupportedFormatError(
            f"binary {product} files are not supported (use the ASCII product)",
            path,
            lines.get("FILE FORMAT 0=BINARY 1=ASCII"),
        )
