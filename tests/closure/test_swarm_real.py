"""close_loop on the real Swarm-A day (2024-05-11, storm), with and without injected effects.

The real along-track signal (σ ≈ 3.6e-7 m/s², strong orbital and storm-time
structure) is the "noise" here, so injected effects are sized against it.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import EFFECT_NAMES, close_loop
from accal.io import read

ORBIT = 5640.0  # Swarm A, ~460 km [s]


@pytest.fixture(scope="module")
def swarm(samples):
    s = read(samples["swarm_a"], columns={"x": "a_cal_x"})
    return s.time, s.axis("x"), s.valid


def test_real_day_runs_and_reports_sensibly(swarm):
    t, y, valid = swarm
    res = close_loop(t, y, valid=valid, orbit_period=ORBIT)
    assert res.rms_after <= res.rms_before
    for e in res.effects + res.unexplained:
        assert e.name in EFFECT_NAMES
        assert np.isfinite(e.coefficient)
    for e in res.effects:
        assert np.isfinite(e.sigma) and e.sigma > 0
    # measured (docs/closure.md): periodic 1/rev found (1.1e-7 m/s²), smooth storm-time
    # structure left unexplained (dominant period ~1 day)
    assert res.found
    d = res.to_dict()
    assert d["rms_before"] > d["rms_after"] > 0


def test_injected_lagged_coupling_is_found_in_real_signal(swarm):
    """A temperature-like channel coupled with a 900 s lag is recovered from the storm day.

    Injected steps (up to 1e-6 m/s²) are *not* detected on this day: the storm-time
    low-frequency signal dominates the noise estimate (docs/closure.md).
    """
    t, y, valid = swarm
    tau = t - t[0]
    rng = np.random.default_rng(11)
    temp = 1.5 * np.sin(2 * np.pi * tau / 86400 + 1.0) + 0.4 * np.sin(2 * np.pi * tau / ORBIT)
    temp += 0.3 * np.cumsum(rng.standard_normal(t.size)) / np.sqrt(t.size)
    inj = 1e-6 * np.interp(tau - 900.0, tau, temp)
    res = close_loop(t, y + inj, valid=valid, aux={"temp": temp}, orbit_period=ORBIT)
    names = [e.name for e in res.effects]
    assert "auxiliary" in names
    aux = res.effects[names.index("auxiliary")]
    # measured 1.02e-6 ± 9e-9; the lag is not determined on this day once the real
    # once-per-orbit signal is modelled as ``periodic`` (only the channel's daily and
    # random-walk parts are left to fix it), so it is not checked
    assert abs(aux.coefficient - 1e-6) < 3 * aux.sigma + 0.05e-6
