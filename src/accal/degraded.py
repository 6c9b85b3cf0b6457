"""Days on which a GRACE / GRACE-FO accelerometer record is not a nominal measurement.

Two accelerometers of the missions stopped giving their own usable data:

* **GRACE-FO D (GF2)**: about one month after launch (22 May 2018), during
  in-orbit checkout in June 2018, the noise of the GRACE-D accelerometer rose by
  orders of magnitude, with bias jumps and thermally correlated noise on two axes,
  and it has not recovered [1]_, [2]_, [3]_.  The Level-1B accelerometer product of
  GRACE-D (ACT1B, "Transformed Accelerometer Data") is therefore a *transplant*:
  GRACE-C's measured accelerations with time and attitude corrections and modelled
  GRACE-D thruster responses added [2]_, [4]_.  Its bias and drift are GRACE-C's
  (rotated), not GRACE-D's.
* **GRACE-B**: to spare its failing battery, GRACE-B's accelerometer instrument
  control unit (ICU) was switched off in autumn 2016 and never switched on again
  (ESA reported it "still completely off" on 21 October 2016 and "remains off" on
  15 February 2017 [5]_, [6]_).  The GRACE-B accelerometer data from November 2016
  to the end of the science mission (June/October 2017) are GRACE-A data
  transplanted to B [7]_.

:data:`DEFAULT_PERIODS` encodes this as a table of :class:`Period` rows;
:func:`classify_day` looks a (satellite, day) up in it and also reads the file
header (``AccSeries.meta``): a header that says "transplant", or that names an
input accelerometer file of the *other* satellite, makes the day a transplant
whatever the table says.  Users extend or replace the table with a TOML or YAML
file (:func:`load_periods`).

Statuses (:data:`STATUSES`), from best to worst for bias estimation:

``nominal``
    Nothing known against the day: the bias/drift is the instrument's own.
``degraded``
    The satellite's own measurement, but known to be corrupted (noise, jumps).
``transplant``
    Not this satellite's measurement: another accelerometer's data mapped onto it.
    A bias/drift fitted to it describes the *other* instrument.
``off``
    The instrument was switched off: a file for that day cannot hold its data.

Uncertainties (say so when you rely on them):

* GRACE-B switch-off day: not confirmed from the sources at hand.  The ICU was off
  by 21 October 2016 (while GRACE-A's was switched back on on 11 October 2016,
  14:12 UTC [5]_); one source says "in November 2016 the GRACE B accelerometer had
  been switched off for the first time" [8]_, the transplant paper covers the
  months November 2016 - June 2017 [7]_.  The table marks GRACE-B ``off`` from
  2016-09-01 (conservative: the September 2016 power-saving period, an
  assumption) to 2016-10-31 and ``transplant`` from 2016-11-01 on.  GRACE-A's own
  ICU-off weeks of September/October 2016 (and the earlier ICU-off periods of
  2011-2016 battery management) are not in the table: those days have no data.
* GRACE-D onset day: "June 2018" [3]_, "after one month in orbit" [2]_; the day is
  not pinned down here.  The table flags GRACE-D from launch (2018-05-22), which
  also covers the in-orbit-checkout weeks; whether the released RL04 ACT1B for
  those first weeks is a transplant too is not confirmed.
* The real RL04 ACT1B headers (``data/samples/ACT1B_2023-06-01_D_04.txt``) do *not*
  say "transplant": the title is "GRACE-FO Level-1B Transformed Accelerometer
  Data", the source "Transformed Accelerometer data for GRACE D", and the input
  is ``ACT1A_2023-06-01_D_04.dat`` - the same wording as for GRACE-C.  For
  GRACE-D the date table is what flags the day; the header test is for products
  that do say it (e.g. third-party transplants) and for cross-satellite inputs.

References
----------
.. [1] Harvey, N., McCullough, C. M., Save, H. (2022). Modeling GRACE-FO
   accelerometer data for the version 04 release. Advances in Space Research 69(3),
   1393-1407 (cited from memory and through [3]; DOI not verified here).
.. [2] Behzadpour, S., Mayer-Gürr, T., Krauss, S. (2021). GRACE Follow-On
   accelerometer data recovery. J. Geophys. Res. Solid Earth 126, e2020JB021297.
   https://doi.org/10.1029/2020JB021297
.. [3] A 2024 study of the GRACE-D accelerometer (ProQuest document 3046475402;
   authors not retrieved), summarising [1]: "noise levels on the GRACE-D
   accelerometer increased by orders of magnitude in June 2018, and have not
   recovered since".
.. [4] Öhlinger, F., Mayer-Gürr, T. (2024). Improved alternative GRACE-FO
   accelerometer transplant product computed at TU Graz. EGU24-10401.
   https://doi.org/10.5194/egusphere-egu24-10401
.. [5] ESA Earth Online, GRACE news, 21 October 2016: "GRACE - Planned switch-on of
   MWA / ICU".
.. [6] ESA Earth Online, GRACE news, 15 February 2017: "GRACE operational issue:
   Planned switch-off of MWA".
.. [7] Bandikova, T., McCullough, C., Kruizinga, G. L., Save, H., Christophe, B.
   (2019). GRACE accelerometer data transplant. Advances in Space Research 64(3),
   623-644. https://doi.org/10.1016/j.asr.2019.05.021
.. [8] Secondary citation of a GRACE Antarctic mass study, quoting "in November
   2016 the GRACE B accelerometer had been switched off for the first time to save
   battery power and non-gravitational accelerations measured onboard GRACE A were
   transplanted to GRACE B" (original not retrieved).
"""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from accal.errors import FormatError, ValidationError, check_option

#: Day statuses, from best to worst for bias estimation.
STATUSES = ("nominal", "degraded", "transplant", "off")

#: Products a :class:`Period` may be restricted to (None = any product).
PRODUCTS = ("ACC1B", "ACT1B")

#: Spellings of the satellite names -> accal's names (``AccSeries.satellite``).
SATELLITE_ALIASES = {
    "GRACE-A": ("GRACE-A", "GRACE A", "GRACEA", "A", "GRACE-1", "GRACE1"),
    "GRACE-B": ("GRACE-B", "GRACE B", "GRACEB", "B", "GRACE-2", "GRACE2"),
    "GRACE-FO-C": ("GRACE-FO-C", "GRACE-C", "GRACE C", "C", "GF1", "GRACE-FO-1", "GRACE-FO 1"),
    "GRACE-FO-D": ("GRACE-FO-D", "GRACE-D", "GRACE D", "D", "GF2", "GRACE-FO-2", "GRACE-FO 2"),
}
_ALIAS = {a.upper(): name for name, aliases in SATELLITE_ALIASES.items() for a in aliases}
_LETTER = {"GRACE-A": "A", "GRACE-B": "B", "GRACE-FO-C": "C", "GRACE-FO-D": "D"}

#: An input accelerometer file named in a header: ``ACC1A_2016-11-01_A_02.dat``.
_INPUT_FILE_RE = re.compile(r"\b(AC[CT]1[AB])_(\d{4}-\d{2}-\d{2})_([A-D])_")
_TRANSPLANT_RE = re.compile(r"transplant", re.IGNORECASE)


def normalise_satellite(satellite: str) -> str:
    """Return accal's name for a GRACE/GRACE-FO satellite spelling; others unchanged.

    ``"GRACE B"``, ``"B"``, ``"GRACE-2"`` -> ``"GRACE-B"``; ``"GF2"``, ``"GRACE D"``
    -> ``"GRACE-FO-D"``; ``"Swarm-A"`` stays ``"Swarm-A"``.
    """
    s = str(satellite).strip()
    return _ALIAS.get(s.upper().replace("_", "-"), s)


def _as_date(value: Any, what: str = "date") -> _dt.date:
    if isinstance(value, _dt.datetime):
        return value.date()
    if isinstance(value, _dt.date):
        return value
    if hasattr(value, "astype") and str(getattr(value, "dtype", "")).startswith("datetime64"):
        value = str(value.astype("datetime64[D]"))
    try:
        return _dt.date.fromisoformat(str(value).strip()[:10])
    except ValueError:
        raise ValidationError(
            f"Invalid value for the {what!r} parameter: expected a date 'YYYY-MM-DD', "
            f"got {str(value)[:40]!r}"
        ) from None


@dataclass(frozen=True)
class Period:
    """A run of days with one status for one satellite (a row of the table).

    Attributes
    ----------
    satellite : str
        accal's name (``GRACE-B``, ``GRACE-FO-D``, ...; aliases are normalised).
    start, end : datetime.date
        First and last day, inclusive (UTC calendar days); ``end`` None = open.
    status : str
        One of :data:`STATUSES`.
    reason : str
        One line for the table's reason column (cite the source briefly).
    product : str or None
        Restrict the row to files of this product (``ACC1B`` or ``ACT1B``, read
        from the header); None matches any file, including an unknown product.
    source : str
        Full reference, for people reading the table.
    """

    satellite: str
    start: _dt.date
    end: _dt.date | None
    status: str
    reason: str
    product: str | None = None
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "satellite", normalise_satellite(self.satellite))
        if self.satellite.upper().startswith("GRACE") and self.satellite not in _LETTER:
            # another mission's name is kept as written; a misspelt GRACE one would
            # silently never match
            raise ValidationError(
                f"unknown GRACE satellite {self.satellite!r} "
                f"(one of {', '.join(_LETTER)}, or A-D, GRACE C, GF1, ...)"
            )
        object.__setattr__(self, "start", _as_date(self.start, "start"))
        if self.end is not None:
            object.__setattr__(self, "end", _as_date(self.end, "end"))
            if self.end < self.start:
                raise ValidationError(f"period end {self.end} is before its start {self.start}")
        check_option("status", self.status, STATUSES)
        if self.product is not None:
            check_option("product", self.product, PRODUCTS)
        if "\n" in self.reason:
            raise ValidationError("period reason must be one line")

    def covers(self, satellite: str, day: _dt.date, product: str | None) -> bool:
        """Return True if this row applies to ``satellite`` on ``day`` for ``product``."""
        return (
            self.satellite == satellite
            and self.start <= day
            and (self.end is None or day <= self.end)
            and (self.product is None or self.product == product)
        )


#: The built-in table (see the module docstring for sources and uncertainties).
#: First matching row wins, so specific rows (a product) come before general ones.
DEFAULT_PERIODS: tuple[Period, ...] = (
    Period(
        "GRACE-FO-D",
        _dt.date(2018, 5, 22),
        None,
        "degraded",
        "GRACE-D's own accelerometer data: noise up by orders of magnitude since June 2018 "
        "(Harvey et al. 2022)",
        product="ACC1B",
        source="Harvey, McCullough, Save (2022), Adv. Space Res. 69(3), 1393-1407",
    ),
    Period(
        "GRACE-FO-D",
        _dt.date(2018, 5, 22),
        None,
        "transplant",
        "GRACE-D ACT1B is GRACE-C data transplanted to D (D accelerometer degraded since "
        "June 2018; Behzadpour et al. 2021)",
        source="Behzadpour, Mayer-Gürr, Krauss (2021), doi:10.1029/2020JB021297; "
        "Harvey et al. (2022), Adv. Space Res. 69(3)",
    ),
    Period(
        "GRACE-B",
        _dt.date(2016, 9, 1),
        _dt.date(2016, 10, 31),
        "off",
        "GRACE-B accelerometer ICU switched off (battery), off on 2016-10-21 per ESA; "
        "switch-off day unconfirmed, start assumed",
        source="ESA GRACE news of 2016-10-21 and 2017-02-15",
    ),
    Period(
        "GRACE-B",
        _dt.date(2016, 11, 1),
        None,
        "transplant",
        "GRACE-B accelerometer off since autumn 2016: data are GRACE-A's transplanted to B "
        "(Bandikova et al. 2019)",
        source="Bandikova et al. (2019), doi:10.1016/j.asr.2019.05.021",
    ),
)


def _header(meta: Mapping[str, Any]) -> Mapping[str, Any]:
    """The L1B header inside ``AccSeries.meta`` (or ``meta`` itself if it is one)."""
    for key in ("gracefo", "grace"):
        if isinstance(meta.get(key), Mapping):
            return meta[key]
    return meta


def _strings(obj: Any, path: str = "") -> Iterable[tuple[str, str]]:
    """Yield (dotted key, text) for every key and string value in a nested header."""
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            key = f"{path}.{k}" if path else str(k)
            yield key, str(k)
            yield from _strings(v, key)
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            yield from _strings(v, f"{path}[{i}]")
    elif isinstance(obj, str):
        yield path, obj


def header_product(meta: Mapping[str, Any] | None) -> str | None:
    """The accelerometer product of a file from its header: ``ACC1B``, ``ACT1B`` or None.

    GRACE headers name it in the ``FILE TYPE ipXXX1BF`` key; GRACE-FO YAML headers
    in the title ("... Transformed Accelerometer Data" is ACT1B).
    """
    if not meta:
        return None
    hdr = _header(meta)
    for key in hdr:
        m = re.search(r"ip(AC[CT]1B)F", str(key))
        if m:
            return m.group(1)
    attrs = hdr.get("global_attributes")
    title = str(attrs.get("title", "")) if isinstance(attrs, Mapping) else ""
    if re.search(r"transformed|transplant", title, re.IGNORECASE):
        return "ACT1B"
    if re.search(r"accelerometer", title, re.IGNORECASE):
        return "ACC1B"
    return None


def header_evidence(meta: Mapping[str, Any] | None, satellite: str) -> str | None:
    """Return why the header shows a transplant, or None.

    Two kinds of evidence: the word "transplant" in any key or value, or an input
    accelerometer file (``ACC1A_2016-11-01_A_02.dat``) of another satellite than
    ``satellite``.
    """
    if not meta:
        return None
    hdr = _header(meta)
    own = _LETTER.get(normalise_satellite(satellite))
    for key, text in _strings(hdr):
        if _TRANSPLANT_RE.search(text):
            return f"header {key[:40]} says {text.strip()[:60]!r}"
        if own is not None:
            for m in _INPUT_FILE_RE.finditer(text):
                if m.group(3) != own:
                    return (
                        f"header input {m.group(0)}... is satellite {m.group(3)}'s data, "
                        f"not {own}'s (transplant)"
                    )
    return None


def classify_day(
    satellite: str,
    date: str | _dt.date | Any,
    meta: Mapping[str, Any] | None = None,
    *,
    periods: Iterable[Period] | None = None,
) -> tuple[str, str]:
    """Say whether an accelerometer day is nominal, degraded, a transplant or off.

    Parameters
    ----------
    satellite : str
        ``AccSeries.satellite`` (``GRACE-B``, ``GRACE-FO-D``, ...; aliases such as
        ``"GRACE D"`` or ``"GF2"`` are accepted).
    date : str, datetime.date or numpy.datetime64
        The UTC day (``"YYYY-MM-DD"``; the bias table's ``date``).
    meta : mapping, optional
        ``AccSeries.meta`` (or a bare L1B header): its product (ACC1B/ACT1B)
        selects product-specific rows, and transplant evidence in it
        (:func:`header_evidence`) overrides the table.
    periods : iterable of Period, optional
        The table; default :data:`DEFAULT_PERIODS`.  The first row that covers
        the day wins (:func:`load_periods` puts user rows first).

    Returns
    -------
    status : str
        One of :data:`STATUSES`.
    reason : str
        One line saying why; empty for a nominal day of a GRACE/GRACE-FO satellite
        (or one the table names), "no degraded-day entries for X" for any other.

    Raises
    ------
    accal.errors.ValidationError
        ``date`` is not a date.

    Examples
    --------
    >>> classify_day("GRACE-FO-D", "2023-06-01")[0]
    'transplant'
    >>> classify_day("GRACE-B", "2005-01-01")
    ('nominal', '')
    """
    sat = normalise_satellite(satellite)
    day = _as_date(date)
    table = DEFAULT_PERIODS if periods is None else tuple(periods)
    evidence = header_evidence(meta, sat)
    if evidence is not None:
        return "transplant", evidence
    product = header_product(meta)
    for row in table:
        if row.covers(sat, day, product):
            return row.status, row.reason
    if sat in SATELLITE_ALIASES or any(row.satellite == sat for row in table):
        return "nominal", ""
    return "nominal", f"no degraded-day entries for {sat or 'an unnamed satellite'!s}"


# --------------------------------------------------------------------------- user tables


def _period_from(entry: Any, path: Path, i: int) -> Period:
    if not isinstance(entry, Mapping):
        raise FormatError(f"period {i + 1} is not a table/mapping", path)
    unknown = sorted(
        set(entry) - {"satellite", "start", "end", "status", "reason", "product", "source"}
    )
    if unknown:
        raise FormatError(f"period {i + 1}: unknown key(s) {', '.join(unknown)}", path)
    missing = [k for k in ("satellite", "start", "status") if k not in entry]
    if missing:
        raise FormatError(f"period {i + 1}: missing key(s) {', '.join(missing)}", path)
    try:
        return Period(
            satellite=str(entry["satellite"]),
            start=entry["start"],
            end=entry.get("end"),
            status=str(entry["status"]),
            reason=str(entry.get("reason", "")),
            product=None if entry.get("product") is None else str(entry["product"]),
            source=str(entry.get("source", "")),
        )
    except ValidationError as exc:
        raise FormatError(f"period {i + 1}: {exc}", path) from None


def load_periods(
    path: str | Path, *, defaults: Iterable[Period] = DEFAULT_PERIODS
) -> tuple[Period, ...]:
    """Read a degraded-day table from a TOML or YAML file, ahead of ``defaults``.

    Parameters
    ----------
    path : str or Path
        ``.toml``, or ``.yaml``/``.yml``.  Rows are a list ``period`` of tables
        with ``satellite``, ``start``, optional ``end`` (inclusive), ``status``,
        ``reason``, optional ``product`` and ``source``; a top-level
        ``replace_defaults = true`` drops the built-in rows.  For example::

            [[period]]
            satellite = "GRACE-A"
            start = 2016-09-01
            end = 2016-10-11
            status = "off"
            reason = "ICU off for battery management (ESA news 2016-10-21)"

    defaults : iterable of Period, optional
        Rows placed after the file's (default :data:`DEFAULT_PERIODS`).

    Returns
    -------
    tuple of Period
        The file's rows first (so they override), then ``defaults``.

    Raises
    ------
    accal.errors.FormatError
        Unreadable file, invalid TOML/YAML, or a row that is not valid.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"cannot read degraded-day table: {exc}", path) from None
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise FormatError(f"invalid YAML: {str(exc).splitlines()[0]}", path) from None
    else:
        import tomllib

        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise FormatError(f"invalid TOML: {exc}", path) from None
    doc = doc or {}
    if not isinstance(doc, Mapping):
        raise FormatError("expected a table with a 'period' list", path)
    entries = doc.get("period", [])
    if not isinstance(entries, list):
        raise FormatError("'period' must be a list of tables ([[period]] in TOML)", path)
    rows = tuple(_period_from(e, path, i) for i, e in enumerate(entries))
    return rows if doc.get("replace_defaults", False) is True else rows + tuple(defaults)


__all__ = [
    "DEFAULT_PERIODS",
    "PRODUCTS",
    "STATUSES",
    "Period",
    "classify_day",
    "header_evidence",
    "header_product",
    "load_periods",
    "normalise_satellite",
]
