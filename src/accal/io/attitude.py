"""Reader of GRACE / GRACE-FO star-camera attitude (SCA1B) and rotations inertial <-> SRF.

:func:`read_attitude` returns an :class:`Attitude` (time, quaternion, star-camera id,
formal error, quality flags); :func:`rotate_to_srf` and :func:`rotate_to_inertial`
rotate vectors between the inertial frame and the satellite reference frame (SRF)
with the attitude interpolated by spherical linear interpolation (SLERP), so that a
reference acceleration given in the inertial frame can be compared with the
accelerometer in the SRF.  :func:`find_attitude_file` finds the SCA1B file next to
an ACC1B / ACT1B file.  Supported inputs (optionally gzip-compressed, detected by
magic bytes):

* GRACE SCA1B ASCII (RL00-RL03): fixed-width ``KEY : value`` header ending with
  ``END OF HEADER``, kept in ``meta["grace"]`` (read with the helpers of
  :mod:`accal.io.grace_l1b`);
* GRACE-FO SCA1B ASCII (RL04): YAML header naming every column, ending with
  ``# End of YAML header``, kept in ``meta["gracefo"]``.

Binary GRACE SCA1B (``FILE FORMAT 0=BINARY 1=ASCII : 0``) is not supported.

The record
----------
``gps_time`` [s since 2000-01-01 12:00:00 GPS], satellite id (A/B/C/D), ``sca_id``
(GRACE-FO: 1, 2, 4 = camera 1, 2, 3, sums for combined cameras, +16 with the IMU),
the quaternion ``quatangle`` (scalar part, cos(θ/2)), ``quaticoeff``,
``quatjcoeff``, ``quatkcoeff``, ``qual_rss`` (RSS of the quaternion's formal
errors) and ``qualflg`` (8 characters of 0/1, bit 0 rightmost).  Column names are
those of the GRACE-FO header and of the handbooks [1]_ [2]_.

Convention
----------
SCA1B quaternions give "the rotation from the inertial frame to the SRF" ([1]_,
SCA1B; the GRACE-FO header's ``summary`` says "rotation quaternions from Inertial
Frame to SRF"), the inertial frame being ICRF / J2000.  Read as a *frame*
rotation: with ``q = (q0, q1, q2, q3)`` (``q0 = quatangle``) and the usual
(Hamilton) rotation matrix

.. math::

    R(q) = \\begin{pmatrix}
        q_0^2+q_1^2-q_2^2-q_3^2 & 2(q_1q_2-q_0q_3) & 2(q_1q_3+q_0q_2) \\\\
        2(q_1q_2+q_0q_3) & q_0^2-q_1^2+q_2^2-q_3^2 & 2(q_2q_3-q_0q_1) \\\\
        2(q_1q_3-q_0q_2) & 2(q_2q_3+q_0q_1) & q_0^2-q_1^2-q_2^2+q_3^2
    \\end{pmatrix},

which is ``scipy.spatial.transform.Rotation.from_quat([q1, q2, q3, q0])``
(scalar last), the **columns of R(q) are the SRF axes in inertial coordinates**:

.. math::

    v_\\mathrm{inertial} = R(q)\\, v_\\mathrm{SRF} = q \\otimes v_\\mathrm{SRF} \\otimes q^*,
    \\qquad
    v_\\mathrm{SRF} = R(q)^\\mathsf{T} v_\\mathrm{inertial}
    = q^* \\otimes v_\\mathrm{inertial} \\otimes q.

So ``R(q)`` as scipy builds it is SRF -> inertial (:attr:`Attitude.srf_to_inertial`)
and inertial -> SRF is its inverse.  Evidence: GROOPS builds ``Rotary3d`` from
``(quatangle, quaticoeff, quatjcoeff, quatkcoeff)`` with exactly ``R(q)`` above
(``source/base/rotary3d.cpp``) and documents the SCA1B rotation as "SRF to CRF"
(``source/programs/conversion/grace/graceL1b2StarCamera.cpp``); the MATLAB GRACE
toolkit of N. Pandit (``process-CM/IRFtoSRF.m``, citing the L1B ATBD [3]_) uses
``R_ECItoSRF = R(q)ᵀ``.  The real sample files confirm it: with ``R(q)`` as SRF ->
inertial, the SRF x axes of GRACE A and B (2003-09-14), and of GRACE-FO C and D
(2023-06-01), are antiparallel to within 0.5° (the two satellites point at each
other), and GRACE A's x axis points at GRACE B (from the GNV1B orbits, rotated to
the inertial frame by the Earth rotation angle) to within 0.25°; with the transpose
the angles are 120-135° (GRACE) and 18° (GRACE-FO) (``tests/io/test_attitude.py``).

References
----------
.. [1] Case, K., Kruizinga, G., Wu, S.-C. (2010). GRACE Level 1B Data Product User
   Handbook, JPL D-22027.
.. [2] Wen, H. Y., Kruizinga, G., Paik, M., Landerer, F., Bertiger, W., Sakumura, C.,
   Bandikova, T., Mccullough, C. (2019). Gravity Recovery and Climate Experiment
   Follow-On (GRACE-FO) Level-1 Data Product User Handbook, JPL D-56935.
.. [3] Wu, S.-C., Kruizinga, G., Bertiger, W. (2006). Algorithm Theoretical Basis
   Document for GRACE Level-1B Data Processing V1.2, JPL D-27672.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import FormatError, UnsupportedFormatError, ValidationError
from accal.io.common import (
    bits_from_strings,
    check_binary,
    check_gps_time,
    shorten,
    tidy,
)
from accal.io.grace.checks import check_header_span
from accal.io.grace.header import header_span, header_time, record_count, yaml_line
from accal.io.grace_l1b import (
    SATELLITES,
    header_satellite,
    load_yaml_header,
    parse_grace_header,
    read_l1b_bytes,
    refuse_binary,
    split_header,
)
from accal.series import UNITS

#: Data columns of SCA1B, in file order (GRACE calls the id ``GRACE_id``).
COLUMNS = (
    "gps_time",
    "GRACEFO_id",
    "sca_id",
    "quatangle",
    "quaticoeff",
    "quatjcoeff",
    "quatkcoeff",
    "qual_rss",
    "qualflg",
)

#: The four quaternion columns, scalar part first.
QUATERNION_COLUMNS = COLUMNS[3:7]

#: Units of the numeric columns.
COLUMN_UNITS = {
    "time": UNITS["time"],
    "sca_id": "code",
    "quaternion": "1",
    "qual_rss": "1",
    "qualflg": "bitmask",
}

#: Largest accepted deviation of a quaternion's norm from 1.  The files write 16
#: significant digits and the real samples deviate by at most 1e-10; a larger
#: deviation is a damaged record (a lost or changed digit), not rounding, and is a
#: :class:`~accal.errors.FormatError`.  Accepted quaternions are used normalised
#: (scipy normalises), so the tolerance does not bound the rotation's accuracy.
NORM_TOLERANCE = 1e-6
#: Largest share of an SCA1B file's records that may be damaged (quaternion norm off 1
#: by more than :data:`NORM_TOLERANCE`) and be left out with a warning; more is an error
#: (QA, 2026-11-30: one changed digit in one record failed the whole day).
MAX_DAMAGED_SHARE = 0.1

#: Default largest spacing [s] of two attitude records that is interpolated across.
#: Twice the 5-s sampling of GRACE SCA1B (one missing record is bridged) and ten
#: GRACE-FO (1 s) samples.  SLERP is exact for a rotation at constant rate (the
#: once-per-revolution pitch, 1.2 mrad/s); its error for an angular acceleration α
#: is about α·Δt²/8, i.e. 0.1 mrad for α = 1e-5 rad/s² across 10 s.
DEFAULT_MAX_GAP = 10.0

#: Products whose attitude file :func:`find_attitude_file` looks for.
ACC_PRODUCTS = ("ACC1B", "ACT1B")

_ACC_NAME = re.compile(
    r"^(?P<product>ACC1B|ACT1B)_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rel>\d+)"
    r"(?P<ext>(?:\.[A-Za-z0-9]+)*)$"
)


# --------------------------------------------------------------------------- data model


@dataclass(frozen=True)
class Attitude:
    """Star-camera attitude of one satellite: quaternions inertial -> SRF.

    Attributes
    ----------
    time : ndarray of float64, shape (n,)
        Record epochs, strictly increasing [s, GPS seconds since 2000-01-01 12:00:00].
    quat : ndarray of float64, shape (n, 4)
        Quaternions ``(quatangle, quaticoeff, quatjcoeff, quatkcoeff)``, scalar part
        first, of the rotation from the inertial frame (ICRF/J2000) to the SRF (see the
        module docstring for the convention).  Made sign-continuous on construction:
        a record whose quaternion has a negative dot product with the one before it is
        negated (``q`` and ``-q`` are one rotation).  The first record keeps its sign.
    sca_id : ndarray of int64, shape (n,)
        Star camera(s) used (see the module docstring).
    qual_rss : ndarray of float64, shape (n,)
        RSS of the formal errors of the quaternion [1].
    qualflg : ndarray of uint32, shape (n,)
        Quality flags, bit 0 = rightmost character of the file's ``qualflg``.
    satellite : str
        ``"GRACE-A"`` ... ``"GRACE-FO-D"``, or ``""``.
    meta : dict
        The file's header (``meta["grace"]`` or ``meta["gracefo"]``) and
        ``meta["attitude"]`` (record counts, sign flips, max norm deviation).
    warnings : tuple of str
        The reader's findings (record count, duplicated epochs, ...).

    Raises
    ------
    ValidationError
        On construction: arrays of the wrong shape, time not finite and strictly
        increasing, no record, or a quaternion not finite or not of unit norm to
        :data:`NORM_TOLERANCE`.
    """

    time: NDArray[np.float64]
    quat: NDArray[np.float64]
    sca_id: NDArray[np.int64]
    qual_rss: NDArray[np.float64]
    qualflg: NDArray[np.uint32]
    satellite: str = ""
    meta: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=np.float64)
        if t.ndim != 1 or t.size == 0:
            raise ValidationError(f"attitude time must be 1-D and not empty, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ValidationError("attitude time must be finite")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValidationError("attitude time must be strictly increasing")
        q = np.array(self.quat, dtype=np.float64)
        if q.shape != (t.size, 4):
            raise ValidationError(f"quat must have shape ({t.size}, 4), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValidationError("quat must be finite")
        norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > NORM_TOLERANCE)
        if bad.size:
            i = int(bad[0])
            raise ValidationError(
                f"quaternion {i} has norm {norm[i]:.10g}, not 1 to {NORM_TOLERANCE:g}"
            )
        q, _ = continuous_quaternions(q)
        arrays = {}
        for name, dtype in (("sca_id", np.int64), ("qual_rss", np.float64), ("qualflg", np.uint32)):
            a = np.asarray(getattr(self, name), dtype=dtype)
            if a.shape != t.shape:
                raise ValidationError(f"{name} must have shape {t.shape}, got {a.shape}")
            arrays[name] = a
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "quat", q)
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        object.__setattr__(self, "warnings", tuple(self.warnings))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def quatangle(self) -> NDArray[np.float64]:
        """Scalar part cos(θ/2) of the quaternions, shape (n,)."""
        return self.quat[:, 0]

    @property
    def quaticoeff(self) -> NDArray[np.float64]:
        """i component of the quaternions, shape (n,)."""
        return self.quat[:, 1]

    @property
    def quatjcoeff(self) -> NDArray[np.float64]:
        """j component of the quaternions, shape (n,)."""
        return self.quat[:, 2]

    @property
    def quatkcoeff(self) -> NDArray[np.float64]:
        """k component of the quaternions, shape (n,)."""
        return self.quat[:, 3]

    @property
    def srf_to_inertial(self) -> Any:
        """The records' rotations SRF -> inertial, a ``scipy.spatial.transform.Rotation``.

        ``Rotation.from_quat`` of the quaternions in scalar-last order, i.e. ``R(q)``
        of the module docstring: ``srf_to_inertial.apply(v_srf)`` gives inertial
        coordinates, ``srf_to_inertial.inv().apply(v_inertial)`` SRF coordinates.
        """
        from scipy.spatial.transform import Rotation

        return Rotation.from_quat(self.quat[:, [1, 2, 3, 0]])

    def covers(self, t: ArrayLike, max_gap: float = DEFAULT_MAX_GAP) -> NDArray[np.bool_]:
        """Which epochs ``t`` the attitude can be interpolated to.

        Parameters
        ----------
        t : array_like of float, shape (m,)
            Epochs [s, GPS seconds]; NaN allowed (not covered).
        max_gap : float, optional
            Largest spacing of the two bracketing records that is interpolated
            across [s]; default :data:`DEFAULT_MAX_GAP`.  ``np.inf`` disables it.

        Returns
        -------
        ndarray of bool, shape (m,)
            True where ``t`` equals a record epoch, or lies between the first and
            the last record and its two bracketing records are at most ``max_gap``
            apart.
        """
        t = _as_times(t)
        max_gap = _check_max_gap(max_gap)
        time = self.time
        ok = np.isfinite(t) & (t >= time[0]) & (t <= time[-1])
        if time.size == 1:
            return ok
        i = np.clip(np.searchsorted(time, np.where(ok, t, time[0]), side="right") - 1, 0, None)
        i = np.minimum(i, time.size - 2)
        lo, hi = time[i], time[i + 1]
        return ok & ((hi - lo <= max_gap) | (t == lo) | (t == hi))


def continuous_quaternions(quat: ArrayLike) -> tuple[NDArray[np.float64], int]:
    """Flip quaternion signs so that consecutive records have a non-negative dot product.

    Parameters
    ----------
    quat : array_like of float, shape (n, 4)
        Quaternions in time order (any component order).

    Returns
    -------
    quat : ndarray of float64, shape (n, 4)
        The same rotations (``q`` and ``-q`` are one rotation), the first record's
        sign kept, no sign jump between consecutive records.
    n_flips : int
        Number of sign jumps between consecutive records in the input.

    Notes
    -----
    A component-wise interpolation across a sign jump passes through (near) zero;
    SLERP in scipy takes the short path either way, so this is for a clean series,
    not needed for :func:`rotate_to_srf`.
    """
    q = np.array(quat, dtype=np.float64)
    if q.shape[0] < 2:
        return q, 0
    jump = np.einsum("ij,ij->i", q[1:], q[:-1]) < 0
    n_flips = int(np.count_nonzero(jump))
    if n_flips:
        sign = np.concatenate(([1.0], np.where(np.cumsum(jump) % 2 == 1, -1.0, 1.0)))
        q *= sign[:, None]
    return q, n_flips


# --------------------------------------------------------------------------- rotation


def _as_times(t: ArrayLike) -> NDArray[np.float64]:
    try:
        a = np.asarray(t, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError("times must be numeric [s, GPS]") from None
    if a.ndim != 1:
        raise ValidationError(f"times must be 1-D, got shape {a.shape}")
    return a


def _check_max_gap(max_gap: float) -> float:
    if isinstance(max_gap, bool) or not isinstance(max_gap, int | float | np.integer | np.floating):
        raise ValidationError(f"max_gap must be a number of seconds, got {max_gap!r}")
    if not max_gap > 0:
        raise ValidationError(f"max_gap must be positive, got {max_gap!r}")
    return float(max_gap)


def _rotate(
    times: ArrayLike, vectors: ArrayLike, attitude: Attitude, max_gap: float, inverse: bool
) -> NDArray[np.float64]:
    from scipy.spatial.transform import Slerp

    if not isinstance(attitude, Attitude):
        raise ValidationError(f"attitude must be an Attitude, got {type(attitude).__name__}")
    t = _as_times(times)
    try:
        v = np.asarray(vectors, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError("vectors must be numeric") from None
    if v.shape != (t.size, 3):
        raise ValidationError(f"vectors must have shape ({t.size}, 3), got {v.shape}")
    ok = attitude.covers(t, max_gap)
    out = np.full((t.size, 3), np.nan)
    if not ok.any():
        return out
    rot = attitude.srf_to_inertial
    r = (
        rot[np.zeros(int(ok.sum()), int)]
        if len(attitude) == 1
        else Slerp(attitude.time, rot)(t[ok])
    )
    out[ok] = r.inv().apply(v[ok]) if inverse else r.apply(v[ok])
    return out


def rotate_to_srf(
    times: ArrayLike,
    vectors_inertial: ArrayLike,
    attitude: Attitude,
    *,
    max_gap: float = DEFAULT_MAX_GAP,
) -> NDArray[np.float64]:
    """Rotate inertial vectors into the satellite reference frame (SRF).

    Parameters
    ----------
    times : array_like of float, shape (n,)
        Epochs of the vectors [s, GPS seconds since 2000-01-01 12:00:00], any order.
    vectors_inertial : array_like of float, shape (n, 3)
        Vectors in the inertial frame (ICRF/J2000), e.g. a reference acceleration
        [m/s²]; the unit is kept.
    attitude : Attitude
        Star-camera attitude of the satellite (:func:`read_attitude`).
    max_gap : float, optional
        Largest spacing of two attitude records interpolated across [s]; default
        :data:`DEFAULT_MAX_GAP` (10 s).  ``np.inf`` disables the check.

    Returns
    -------
    ndarray of float64, shape (n, 3)
        ``R(q(t))ᵀ v``: the vectors' SRF coordinates.  **NaN rows** where ``t`` is
        NaN, outside the attitude's first ... last record, or inside a gap of the
        attitude longer than ``max_gap`` (an epoch equal to a record epoch is always
        rotated); count them with :meth:`Attitude.covers`.

    Raises
    ------
    ValidationError
        Shapes that do not match, non-numeric input, ``max_gap`` not positive.

    Notes
    -----
    The attitude is interpolated to ``times`` by SLERP between the two bracketing
    records (``scipy.spatial.transform.Slerp``).  Epochs without attitude give NaN
    rather than an error because an accelerometer day and its attitude day never
    cover exactly the same span; the caller drops (and reports) those epochs as it
    does for flagged samples.
    """
    return _rotate(times, vectors_inertial, attitude, max_gap, inverse=True)


def rotate_to_inertial(
    times: ArrayLike,
    vectors_srf: ArrayLike,
    attitude: Attitude,
    *,
    max_gap: float = DEFAULT_MAX_GAP,
) -> NDArray[np.float64]:
    """Rotate SRF vectors into the inertial frame: the inverse of :func:`rotate_to_srf`.

    Parameters
    ----------
    times : array_like of float, shape (n,)
        Epochs [s, GPS seconds since 2000-01-01 12:00:00].
    vectors_srf : array_like of float, shape (n, 3)
        Vectors in the SRF (e.g. an ACC1B acceleration [m/s²]).
    attitude : Attitude
        Star-camera attitude of the satellite.
    max_gap : float, optional
        As in :func:`rotate_to_srf`.

    Returns
    -------
    ndarray of float64, shape (n, 3)
        ``R(q(t)) v`` in the inertial frame (ICRF/J2000); NaN rows where the
        attitude does not cover ``t`` (as in :func:`rotate_to_srf`).

    Raises
    ------
    ValidationError
        Shapes that do not match, non-numeric input, ``max_gap`` not positive.
    """
    return _rotate(times, vectors_srf, attitude, max_gap, inverse=False)


# --------------------------------------------------------------------------- find


def find_attitude_file(acc_path: str | Path) -> Path | None:
    """The SCA1B file of the same date, satellite and release next to an ACC1B / ACT1B file.

    Parameters
    ----------
    acc_path : str or Path
        An accelerometer file named like ``ACC1B_2003-09-14_A_00.asc`` or
        ``ACT1B_2023-06-01_C_04.txt`` (optionally ``.gz``).

    Returns
    -------
    Path or None
        ``SCA1B_<date>_<sat>_<release>`` in the same directory, with the
        accelerometer file's extension if such a file exists, else the first
        existing of ``.asc``, ``.txt``, ``.asc.gz``, ``.txt.gz``; None when the name
        is not an ACC1B / ACT1B name or no such file exists.
    """
    p = Path(acc_path)
    m = _ACC_NAME.match(p.name)
    if m is None:
        return None
    stem = f"SCA1B_{m['date']}_{m['sat']}_{m['rel']}"
    exts = [m["ext"], ".asc", ".txt", ".asc.gz", ".txt.gz"]
    for ext in dict.fromkeys(e for e in exts if e and not e.startswith(".dat")):
        cand = p.with_name(stem + ext)
        if cand.is_file():
            return cand
    return None


# --------------------------------------------------------------------------- read


def _interpret_grace(header: bytes, path: Path) -> dict[str, Any]:
    meta, lines = parse_grace_header(header, path)
    file_type = next((k for k in meta if k.startswith("FILE TYPE")), None)
    if file_type is not None:
        m = re.search(r"ip(\w{3}1[AB])F", file_type)
        if m and m.group(1) != "SCA1B":
            raise UnsupportedFormatError(
                f"file type {m.group(0)!r} is not SCA1B star-camera attitude",
                path,
                lines[file_type],
            )
    refuse_binary(meta, lines, path, "SCA1B")
    letter = header_satellite(meta, lines, path)
    first, last = (
        header_time(meta.get(key), key, path, lines.get(key))
        for key in ("TIME FIRST OBS(SEC PAST EPOCH)", "TIME LAST OBS(SEC PAST EPOCH)")
    )
    return {
        "meta": {"grace": meta},
        "letter": letter,
        "n_header": record_count(meta, lines, path),
        "span": header_span(first, last, path),
    }


def _interpret_gracefo(header: bytes, path: Path) -> dict[str, Any]:
    hdr = load_yaml_header(header, path)
    variables = hdr.get("variables") or []
    if not isinstance(variables, list) or not all(isinstance(v, dict) and v for v in variables):
        raise FormatError("YAML header: 'variables' is not a list of mappings", path)
    names = tuple(next(iter(v)) for v in variables)
    if names != COLUMNS:
        raise UnsupportedFormatError(
            f"columns {shorten(' '.join(names[:9]), 100)} are not the SCA1B columns "
            f"({' '.join(COLUMNS)})",
            path,
            yaml_line(header, "variables"),
        )
    dims = hdr.get("dimensions")
    try:
        n_header = int(dims["num_records"]) if isinstance(dims, dict) else None
    except (KeyError, TypeError, ValueError):
        n_header = None
    attrs = hdr.get("global_attributes") or {}
    platform = attrs.get("platform", "") if isinstance(attrs, dict) else ""
    letter = platform.split()[-1] if isinstance(platform, str) and platform.split() else ""
    if letter not in ("C", "D"):
        raise FormatError(
            f"YAML header: platform is {shorten(str(platform), 40)}, "
            "expected 'GRACE C' or 'GRACE D'",
            path,
            yaml_line(header, "platform"),
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
        "span": header_span(first, last, path),
    }


def _numbers(col: tuple[str, ...], name: str, dtype: type, path: Path, lines: list[int]) -> NDArray:
    """Column ``col`` as ``dtype``; FormatError naming the first bad value's line."""
    try:
        a = np.array(col, dtype=dtype)
    except (ValueError, OverflowError):
        a = None
    if a is not None and (dtype is not np.float64 or np.all(np.isfinite(a))):
        return a
    kind = "an integer" if dtype is np.int64 else "a finite number"
    for i, tok in enumerate(col):
        try:
            ok = bool(np.isfinite(float(tok))) if dtype is np.float64 else int(tok) is not None
        except ValueError:
            ok = False
        if not ok:
            raise FormatError(f"{name}: not {kind}: {shorten(tok, 30)}", path, lines[i])
    raise FormatError(f"{name}: cannot parse", path)  # pragma: no cover


def _parse_records(data: bytes, first_line: int, path: Path) -> dict[str, Any]:
    """Parse the SCA1B records ``data`` (``first_line``: file line of the first)."""
    check_binary(data, path, first_line)
    text = data.decode("utf-8")
    rows: list[list[str]] = []
    lines: list[int] = []
    all_lines = text.split("\n")
    last = len(all_lines) - 1
    for k, line in enumerate(all_lines):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != len(COLUMNS):
            if k == last:  # no newline after it
                raise FormatError(
                    "truncated last line (no newline at end of file)", path, first_line + k
                )
            raise FormatError(
                f"wrong number of columns: expected {len(COLUMNS)} "
                f"({' '.join(COLUMNS)}), got {len(fields)}",
                path,
                first_line + k,
            )
        rows.append(fields)
        lines.append(first_line + k)
    if not rows:
        raise FormatError("header but no data records", path, first_line)
    cols = list(zip(*rows, strict=True))
    time = _numbers(cols[0], "gps_time", np.float64, path, lines)
    check_gps_time(time, path, lambda i: lines[i])
    ids = np.array(cols[1])
    bad = np.flatnonzero(~np.isin(ids, list(SATELLITES)))
    if bad.size:
        i = int(bad[0])
        raise FormatError(
            f"satellite id {shorten(ids[i], 10)} is not one of A, B, C, D", path, lines[i]
        )
    sca_id = _numbers(cols[2], "sca_id", np.int64, path, lines)
    quat = np.column_stack(
        [_numbers(cols[j], COLUMNS[j], np.float64, path, lines) for j in range(3, 7)]
    )
    qual_rss = _numbers(cols[7], "qual_rss", np.float64, path, lines)
    import pyarrow as pa

    qualflg = bits_from_strings(
        pa.array(cols[8], type=pa.string()), path, first_line, line_of=lambda i: lines[i]
    )
    norm = np.linalg.norm(quat, axis=1)
    dev = np.abs(norm - 1.0)
    bad = np.flatnonzero(dev > NORM_TOLERANCE)
    damaged = ""
    if bad.size:
        i = int(bad[0])
        what = (
            f"quaternion norm {norm[i]:.10g} differs from 1 by {dev[i]:.3g} "
            f"(more than {NORM_TOLERANCE:g}): not a rotation, a damaged record"
        )
        if bad.size > MAX_DAMAGED_SHARE * len(rows):
            raise FormatError(
                what + (f" ({bad.size} of {len(rows)} records)" if bad.size > 1 else ""),
                path,
                lines[i],
            )
        damaged = (
            f"{bad.size} record(s) with a quaternion norm off 1 by more than "
            f"{NORM_TOLERANCE:g} (damaged; the first at line {lines[i]}, norm "
            f"{norm[i]:.10g}) left out: the attitude is interpolated across them"
        )
        keep = np.ones(len(rows), dtype=bool)
        keep[bad] = False
        time, ids, sca_id, quat = time[keep], ids[keep], sca_id[keep], quat[keep]
        qual_rss, qualflg, dev = qual_rss[keep], qualflg[keep], dev[keep]
        lines = [ln for ln, k in zip(lines, keep, strict=True) if k]
    return {
        "time": time,
        "ids": ids,
        "sca_id": sca_id,
        "quat": quat,
        "qual_rss": qual_rss,
        "qualflg": qualflg,
        "lines": lines,
        "max_norm_deviation": float(dev.max()),
        "damaged": damaged,
    }


def read_attitude(path: str | Path) -> Attitude:
    """Read a GRACE or GRACE-FO star-camera attitude file (SCA1B, ASCII).

    Parameters
    ----------
    path : str or Path
        GRACE SCA1B ASCII (``END OF HEADER``) or GRACE-FO RL04 SCA1B (YAML header),
        optionally gzipped (detected by content).

    Returns
    -------
    Attitude
        ``time`` [s, GPS since 2000-01-01 12:00:00] strictly increasing, ``quat``
        (inertial -> SRF, scalar first, made sign-continuous), ``sca_id``,
        ``qual_rss``, ``qualflg``, ``satellite``, the header in ``meta`` and the
        findings in ``warnings``.

    Raises
    ------
    FormatError
        Missing, unreadable, empty or corrupt file, no end-of-header marker, a
        malformed record (wrong number of columns, a value that is not a number,
        a non-finite value, a satellite id other than A-D, a ``qualflg`` that is not
        8 characters of 0/1), quaternions whose norm differs from 1 by more than
        :data:`NORM_TOLERANCE` in more than :data:`MAX_DAMAGED_SHARE` of the records
        (fewer are left out with a warning), epochs outside 1980-2100 or far outside the header's
        day, mixed satellite ids.  The message names the file and, for a record,
        its 1-based line (``str(err)`` is ``FILE:LINE: what is wrong``).
    UnsupportedFormatError
        Another L1B product (e.g. ACC1B), binary SCA1B, or a GRACE-FO header whose
        columns are not those of SCA1B.

    Notes
    -----
    Records out of time order are sorted and of duplicated epochs the first is
    kept (a warning says so); a record count different from the header's is a
    warning (the GRACE-FO samples are cut after 100 records).  Missing attitude is
    a gap in the records (L1B has no fill value); an empty or NaN quaternion
    field is a damaged record, an error.  The number of sign flips between
    consecutive quaternions (``q`` -> ``-q``, same rotation) and the largest norm
    deviation are in ``meta["attitude"]``.
    """
    path = Path(path)
    raw = read_l1b_bytes(path)
    flavour, header, data_start, first_line = split_header(raw, path)
    info = (_interpret_gracefo if flavour == "gracefo" else _interpret_grace)(header, path)
    cols = _parse_records(raw[data_start:], first_line, path)
    warn: list[str] = []
    uniq = sorted(set(cols["ids"].tolist()))
    if len(uniq) > 1:
        raise FormatError(f"mixed satellite ids {uniq} in one file", path)
    letter = info["letter"]
    if uniq[0] != letter:
        warn.append(
            f"records carry satellite id {uniq[0]!r} but the header names {letter!r}; "
            f"the records' {uniq[0]!r} is used"
        )
        letter = uniq[0]
    lines = cols["lines"]
    if cols["damaged"]:
        warn.append(cols["damaged"])
    warn += check_header_span(cols["time"], info["span"], path, lambda i: lines[i])
    arrays = {k: cols[k] for k in ("quat", "sca_id", "qual_rss", "qualflg")}
    t = tidy(cols["time"], arrays)
    n_rows = t.report["n_rows"]
    n_header = info["n_header"]
    if n_header is None:
        warn.append("the header gives no record count: a truncated file is not detected")
    elif n_header != n_rows:
        warn.append(f"header announces {n_header} data records, file has {n_rows}")
    quat, n_flips = continuous_quaternions(t.arrays["quat"])
    meta = dict(info["meta"])
    meta["attitude"] = {
        "format": flavour,
        "n_records_header": n_header,
        "n_rows": n_rows,
        "n_sign_flips": n_flips,
        "max_norm_deviation": cols["max_norm_deviation"],
        "nominal_step": t.report["nominal_step"],
        "n_gaps": t.report["n_gaps"],
    }
    return Attitude(
        time=t.time,
        quat=quat,
        sca_id=t.arrays["sca_id"],
        qual_rss=t.arrays["qual_rss"],
        qualflg=t.arrays["qualflg"],
        satellite=SATELLITES[letter],
        meta=meta,
        warnings=tuple(warn + t.warnings),
    )


__all__ = [
    "COLUMNS",
    "DEFAULT_MAX_GAP",
    "MAX_DAMAGED_SHARE",
    "NORM_TOLERANCE",
    "Attitude",
    "continuous_quaternions",
    "find_attitude_file",
    "read_attitude",
    "rotate_to_inertial",
    "rotate_to_srf",
]
