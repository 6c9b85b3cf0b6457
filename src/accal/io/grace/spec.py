"""The GRACE / GRACE-FO Level-1B accelerometer file specification (ACC1B, ACT1B).

The module constants below are the file specification, shared by the reader
(:mod:`accal.io.grace.acc`) and the writer (:mod:`accal.io.grace.writer`).
Supported variants:

* GRACE RL00–RL02 ASCII: fixed-width ``KEY : value`` header ending with the line
  ``END OF HEADER`` (RL03: ``# END OF HEADER``), then 12 space-separated fields per
  record, with two spaces before ``qualflg``.  Header kept in ``meta["grace"]``.
* GRACE binary (``FILE FORMAT 0=BINARY 1=ASCII : 0``): the same header, then
  big-endian 78-byte records (:data:`BINARY_DTYPE`).
* GRACE-FO RL04 ASCII: YAML header ending with ``# End of YAML header``, kept in
  ``meta["gracefo"]`` with every scalar as the string written in the file.

All may be gzip-compressed (detected by magic bytes).  Times stay GPS seconds
since 2000-01-01 12:00:00 GPS; accelerations are in m/s².

References
----------
.. [1] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product User
   Handbook, JPL D-22027.
.. [2] Wen, H. Y., Kruizinga, G., Paik, M., Landerer, F., Bertiger, W., Sakumura, C.,
   Bandikova, T., Mccullough, C. (2019). Gravity Recovery and Climate Experiment
   Follow-On (GRACE-FO) Level-1 Data Product User Handbook, JPL D-56935.
"""

from __future__ import annotations

import numpy as np

from accal.io.common import GPS_TIME_RANGE
from accal.series import UNITS

#: Data columns of ACC1B / ACT1B, in file order (GRACE-FO names the id ``GRACEFO_id``).
COLUMNS = (
    "gps_time",
    "GRACE_id",
    "lin_accl_x",
    "lin_accl_y",
    "lin_accl_z",
    "ang_accl_x",
    "ang_accl_y",
    "ang_accl_z",
    "acl_x_res",
    "acl_y_res",
    "acl_z_res",
    "qualflg",
)
GRACEFO_COLUMNS = ("gps_time", "GRACEFO_id", *COLUMNS[2:])

#: Column types as parsed (qualflg: 8 characters of 0/1, bit 0 = rightmost).
DTYPES = {
    "gps_time": "float64",
    "GRACE_id": "str",
    **{c: "float64" for c in COLUMNS[2:11]},
    "qualflg": "str",
}

#: Units of the numeric columns.
COLUMN_UNITS = {
    "gps_time": UNITS["time"],
    "lin_accl_x": "m/s^2",
    "lin_accl_y": "m/s^2",
    "lin_accl_z": "m/s^2",
    "ang_accl_x": "rad/s^2",
    "ang_accl_y": "rad/s^2",
    "ang_accl_z": "rad/s^2",
    "acl_x_res": "m/s^2",
    "acl_y_res": "m/s^2",
    "acl_z_res": "m/s^2",
}


def _unit(name: str) -> str:
    """A column's unit as messages write it (``m/s²``)."""
    return COLUMN_UNITS.get(name, "").replace("^2", "²")


#: Columns carried in ``AccSeries.aux``.
AUX_COLUMNS = COLUMNS[5:11]

#: Header end markers (a whole line, trailing blanks allowed).
HEADER_END = {"grace": ("END OF HEADER", "# END OF HEADER"), "gracefo": ("# End of YAML header",)}

#: Meaning of the ACC1B / ACT1B ``qualflg`` bits (GRACE-FO RL04 YAML header of the real
#: ACT1B files; the GRACE L1B handbook [1] lists the same bits for ACC1B).
QUALFLG_BITS = {
    0: "Vp (proof mass voltage) out of nominal range",
    1: "not defined",
    2: "at least one of acl_x_res, acl_y_res, acl_z_res is > 10 µm/s²",
    3: "extrapolated CLK1B clock offset used, data point > 5 s from CRN window centre",
    4: "extrapolated CLK1B clock offset used, data point <= 5 s from CRN window centre",
    5: "interpolated data point (gap) exists > 15 s from CRN window centre",
    6: "interpolated data point (gap) exists > 5 s and < 15 s from CRN window centre",
    7: "interpolated data point (gap) exists < 5 s from CRN window centre",
}

#: Bits of ``qualflg`` that make a sample invalid by default: 0 (proof-mass voltage out of
#: range, the instrument is not in its nominal state) and 2 (CRN-filter residual > 10 µm/s²,
#: the value is not trustworthy).  Bits 3-7 only report clock extrapolation or gap
#: interpolation somewhere in the 70-s filter window; they are common in good data (bit 5
#: is set on 32 of 60 records of the real GRACE-A 2003-09-14 file) and do not exclude.
DEFAULT_INVALID_BITS = 0b0000_0101

#: Satellite id letter -> accal satellite name.
SATELLITES = {"A": "GRACE-A", "B": "GRACE-B", "C": "GRACE-FO-C", "D": "GRACE-FO-D"}

#: Record of the binary GRACE L1B ACC1B format (big-endian, 78 bytes).
BINARY_DTYPE = np.dtype(
    [("gps_time", ">u4"), ("GRACE_id", "S1")]
    + [(c, ">f8") for c in COLUMNS[2:11]]
    + [("qualflg", "u1")]
)

#: Key width of the GRACE fixed-width header (``KEY`` padded to 30, then ``: value``).
GRACE_KEY_WIDTH = 30

#: Accepted ``gps_time`` range [s since 2000-01-01 12:00:00 GPS]: from the GPS epoch
#: (1980-01-06 00:00:00) to 2100-01-01 00:00:00.  Anything outside is a corrupt time
#: (a flipped exponent, a binary field read as time), not an L1B epoch.
TIME_RANGE = GPS_TIME_RANGE

#: Deepest nesting accepted in a GRACE-FO YAML header (the real headers nest 5 deep).
YAML_MAX_DEPTH = 32
