"""The GRACE / GRACE-FO AHK1B (accelerometer housekeeping) file specification.

The module constants below are the specification, read by :mod:`accal.io.ahk_records`
and :mod:`accal.io.ahk` (:func:`accal.io.housekeeping.read_housekeeping`).

The AHK1B record
----------------
Every record is ``gps_time`` [s] ``gps_time_frac`` [µs] ``time_ref`` (``G`` = GPS)
``id`` (A/B/C/D) ``qualflg`` (8 characters of 0/1) ``prod_flag`` (32 characters of
0/1, bit 0 rightmost), then one value for each set bit of ``prod_flag`` in
increasing bit order.  Records carry different field sets; a channel is NaN in the
records that do not carry it.

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

from typing import NamedTuple


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


#: Accepted record times [s since 2000-01-01 12:00:00 GPS]: the GPS epoch (1980-01-06)
#: to 2100-01-01; anything outside is a corrupt time, not a housekeeping epoch.
TIME_RANGE = (-630_763_200, 3_155_716_800)


#: Absolute zero [°C]; a temperature channel below it is reported (GRACE-FO ``TICUR``
#: reads -273.2 °C in the samples: the redundant ICU is off and reads 0 K).
ABSOLUTE_ZERO_C = -273.15
