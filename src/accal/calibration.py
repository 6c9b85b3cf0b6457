"""A-priori calibration parameters (presets) and the scale convention.

Scale convention used throughout accal (the TN-02 convention)::

    a_cal(t) = scale · (a_raw(t) − trend(t))

where ``trend`` is the bias/drift polynomial estimated from the raw data.  With the
wavelet paper's eq. (9), ``a_raw = s·a_true + b + d·t``, this means
``scale = 1/s``: the paper's eq. (11) scaled signal ``s·a_true`` is what remains
after removing the trend, and multiplying by ``scale`` undoes ``s``.

References
----------
.. [1] S. Bettadpur, "Recommendation for a-priori Bias & Scale Parameters for
   Level-1B ACC Data (Version 2)", GRACE TN-02 (2009).
"""

from __future__ import annotations

import math

from accal.errors import ValidationError

#: TN-02 v2 coefficients: (T0 [MJD], C0 [µm/s²], C1 [µm/s²/day], C2 [µm/s²/day²], scale)
#: per satellite and period (before / after 2003-03-07, MJD 52705).  Sign: TN-02's
#: ``a_cal = bias + scale · a_raw`` (bias is the correction *added* to the raw data).
TN02 = {
    "GRACE-A": (
        (
            52532,
            (-1.106, 27.042, -0.5486),
            (2.233e-4, 4.46e-3, -1.139e-6),
            (2.5e-7, 1.1e-6, 1.7e-7),
        ),
        (
            53736,
            (-1.2095, 29.3370, -0.5606),
            (-4.128e-5, 6.515e-4, -2.352e-6),
            (9.7e-9, -3.9e-7, 3.8e-9),
        ),
        (0.9595, 0.9797, 0.9485),
    ),
    "GRACE-B": (
        (
            52532,
            (-0.5647, 7.5101, -0.8602),
            (-7.788e-5, 7.495e-3, 1.399e-4),
            (2.4e-7, -9.6e-6, 2.5e-7),
        ),
        (
            53736,
            (-0.6049, 10.6860, -0.7901),
            (-1.982e-5, 1.159e-3, 4.783e-5),
            (3.5e-9, -4.3e-7, -6.5e-9),
        ),
        (0.9465, 0.9842, 0.9303),
    ),
}
_TN02_SWITCH_MJD = 52705  # 2003-03-07: last day of the first period


def tn02_scale(satellite: str) -> tuple[float, float, float]:
    """TN-02 a-priori scale factors (x, y, z) [dimensionless] for GRACE-A or GRACE-B."""
    try:
        return TN02[satellite][2]
    except KeyError:
        raise ValidationError(
            f"no TN-02 scale preset for satellite {satellite!r} (presets exist for "
            f"{', '.join(TN02)}); give --scale x,y,z explicitly"
        ) from None


def tn02_bias(satellite: str, mjd: float) -> tuple[float, float, float]:
    """TN-02 a-priori bias (x, y, z) [m/s²] on day ``mjd``, in TN-02's sign convention.

    ``bias(Td) = C0 + C1 (Td − T0) + C2 (Td − T0)²`` (TN-02 v2).
    """
    try:
        early, late, _ = TN02[satellite]
    except KeyError:
        raise ValidationError(f"no TN-02 bias preset for satellite {satellite!r}") from None
    t0, c0, c1, c2 = early if mjd <= _TN02_SWITCH_MJD else late
    dt = mjd - t0
    return tuple(1e-6 * (a + b * dt + c * dt * dt) for a, b, c in zip(c0, c1, c2, strict=True))


def parse_scale(value: str | None, satellite: str) -> tuple[float, float, float] | None:
    """Interpret a ``--scale`` value: ``None``, ``"tn02"`` or ``"sx,sy,sz"``.

    Parameters
    ----------
    value : str or None
        ``None``, ``""`` or ``"none"`` (no scale), ``"tn02"`` (the TN-02 preset of
        ``satellite``), one number (all three axes) or three ``"sx,sy,sz"``
        [dimensionless]; each must be positive and finite (``inf``, ``nan`` and
        values that overflow a float, such as ``1e400``, are refused).
    satellite : str
        Satellite of the data (for ``"tn02"``).

    Returns
    -------
    tuple of 3 float or None

    Raises
    ------
    ValidationError
        For any other value.
    """
    if value is None or value == "" or value == "none":
        return None
    if value.lower() == "tn02":
        return tn02_scale(satellite)
    parts = value.split(",")
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3 or not all(v > 0 and math.isfinite(v) for v in vals):
        raise ValidationError(
            f"--scale expects 'tn02', one positive finite number or three 'sx,sy,sz', got {value!r}"
        )
    return vals  # type: ignore[return-value]
