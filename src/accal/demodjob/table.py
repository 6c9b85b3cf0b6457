"""The per-period rows of ``accal demod`` (the ``periods`` table) and their units."""

from __future__ import annotations

from typing import Any

import numpy as np

PERIOD_UNITS = {
    "source": "input file name",
    "period": "index of the modulation period from the start of the run",
    "t_start": "s (first sample of the period; time origin of the input)",
    "t_mid": "s (mean sample time of the period: the epoch a_Y, a_Z and the bias refer to)",
    "a_Y": "m/s^2 (period mean of the acceleration along Y, bias removed)",
    "a_Z": "m/s^2 (period mean of the acceleration along Z, bias removed)",
    "sigma_Y": "m/s^2 (1 sigma of a_Y from the noise PSD)",
    "sigma_Z": "m/s^2 (1 sigma of a_Z from the noise PSD)",
    "slope_Y": "m/s^3 (slope of a_Y within the period; affine signal model)",
    "slope_Z": "m/s^3 (slope of a_Z within the period; affine signal model)",
    "sigma_slope_Y": "m/s^3 (1 sigma)",
    "sigma_slope_Z": "m/s^3 (1 sigma)",
    "bias_y": "m/s^2 (bias of m_y at t_mid)",
    "bias_z": "m/s^2 (bias of m_z at t_mid)",
    "drift_y": "m/s^3 (bias drift of m_y)",
    "drift_z": "m/s^3 (bias drift of m_z)",
    "n_used": "unmasked samples used",
    "masked_time": "s (measured masked time of the period)",
    "leakage": "normalised eq. 16 residual, max |v'Lambda b|/(|v||Mb|) (0 = exact rejection)",
}


def period_rows(
    res: Any, source: str, units_of: dict[str, str]
) -> tuple[dict[str, Any], dict[str, str]]:
    """The per-period rows of one source (columns as numpy arrays) and their units."""
    n = res.a_Y.size
    data: dict[str, Any] = {
        "source": np.array([source] * n, dtype=object),
        "period": res.period_index.astype(np.int64),
        "t_start": res.t_start,
        "t_mid": res.t_mid,
        "a_Y": res.a_Y,
        "a_Z": res.a_Z,
        "sigma_Y": res.sigma_Y,
        "sigma_Z": res.sigma_Z,
    }
    if res.signal_model == "affine":
        for k in ("slope_Y", "slope_Z", "sigma_slope_Y", "sigma_slope_Z"):
            data[k] = getattr(res, k)
    units = {k: PERIOD_UNITS[k] for k in data}
    for j, name in enumerate(res.bias_names):
        for ax, b in (("y", res.bias_y), ("z", res.bias_z)):
            if name in ("bias", "drift"):
                col = f"{name}_{ax}"
                units[col] = PERIOD_UNITS[col]
            else:
                col = f"bias_{ax}_{name}"
                units[col] = f"m/s^2 per {units_of.get(name, 'unit')} of {name} (m_{ax})"
            data[col] = np.ascontiguousarray(b[:, j])
    data["n_used"] = res.n_used.astype(np.int64)
    data["masked_time"] = res.masked_time
    data["leakage"] = res.leakage
    units.update({k: PERIOD_UNITS[k] for k in ("n_used", "masked_time", "leakage")})
    return data, units
