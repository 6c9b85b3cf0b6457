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

The AHK1B record and the sources of its field names and units are described in
:mod:`accal.io.ahk_spec`; the AHK1B reader is :mod:`accal.io.ahk`, the table reader
:mod:`accal.io.hk_table`, :class:`Housekeeping` lives in :mod:`accal.io.hk_data`.
Every public name this module defined before the split is importable from here as
before; the private helpers are their modules' own.

Units
-----
Voltages in V, currents in A, displacements in m, accelerations in m/s², and
**temperatures in °C** (``"degC"``, not converted to K).  Table columns declared in
mV, µV, kV, mA, µA or nA are converted to V or A.
"""

from __future__ import annotations

from pathlib import Path

from accal.io.ahk import read_ahk1b
from accal.io.ahk_spec import (
    GRACE_FIELDS,
    GRACEFO_BIT_MEANINGS,
    GRACEFO_FIELDS,
    GRACEFO_INFERRED_UNITS,
    Field,
)
from accal.io.common import PARQUET_MAGIC
from accal.io.grace.header import GRACE_END_RE, GRACE_KEY_RE, read_l1b_bytes
from accal.io.hk_data import DEFAULT_MAX_GAP, Housekeeping
from accal.io.hk_table import SI_PREFIXED, TIME_COLUMNS, read_hk_table


def _flavour(raw: bytes) -> str:
    if raw.startswith(PARQUET_MAGIC):
        return "table"
    if raw.startswith(b"header:"):
        return "gracefo"
    first = raw[:4096].split(b"\n", 1)[0]
    if GRACE_END_RE.search(raw[: 1 << 20]) or (
        GRACE_KEY_RE.match(first) and not first.startswith(b"#")
    ):
        return "grace"
    return "table"


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
    docstring of :mod:`accal.io.ahk_spec`.  A record count different
    from the header's is a warning (the GRACE-FO samples are cut after 100
    records).  Parsing is vectorised per ``prod_flag`` layout: a 10 Hz GRACE-FO
    day (864,000 records) takes a few seconds, a GRACE day (8,640) a fraction.
    """
    path = Path(path)
    raw = read_l1b_bytes(path)
    if _flavour(raw) == "table":
        return read_hk_table(raw, path)
    return read_ahk1b(raw, path)


__all__ = [
    "DEFAULT_MAX_GAP",
    "SI_PREFIXED",
    "TIME_COLUMNS",
    "GRACEFO_BIT_MEANINGS",
    "GRACEFO_FIELDS",
    "GRACEFO_INFERRED_UNITS",
    "GRACE_FIELDS",
    "Field",
    "Housekeeping",
    "read_housekeeping",
]
