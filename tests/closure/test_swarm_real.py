"""close_loop on the real Swarm-A day (2024-05-11, storm), with and without injected effects.

The real along-track signal (σ ≈ 3.6e-7 m/s², strong orbital and storm-time
structure) is the "noise" here, so injected effects are sized against it: the
measured detection limit on this day is ~1-3e-6 m/s² for a step (not reached
inside the storm's main phase).  Without a reference the orbit-phase signal model
is in the null, so a coupling to a channel whose only non-orbital content is a
random walk (``temp`` below) is not identifiable; the quadratic needs a reference
(tests/closure/test_close_loop.py).  docs/closure.md has the numbers.
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
    t = s.time
    tau = t - t[0]
    rng = np.random.default_rng(2024)
    temp = 1.2 * np.sin(2 * np.pi * tau / 86400 + 0.7) + 0.5 * np.sin(2 * np.pi * tau / ORBIT + 2)
    temp += 0.3 * np.cumsum(rng.standard_normal(t.size)) / np.sqrt(t.size)
    ref = close_loop(t, s.axis("x"), valid=s.valid, aux={"temp": temp}, orbit_period=ORBIT)
    return t, s.axis("x"), s.valid, temp, ref


def test_real_day_runs_and_reports_sensibly(swarm):
    """The null: nothing injected into the ESA-calibrated series, nothing removed.

    The day's orbit-periodic and storm-time structure is real signal: with the
    orbit-phase signal model in the null (no reference) no candidate, the coupling to
    ``temp`` included, may be removed (measured: no effect at all, no rejection).
    """
    t, y, valid, temp, res = swarm
    assert res.rms_after <= res.rms_before
    for e in res.effects + res.unexplained:
        assert e.name in EFFECT_NAMES
        assert np.isfinite(e.coefficient)
    assert not [e.name for e in res.effects if e.instrument]
    assert res.signal_model  # the signal model is named in the result
    assert any(c["channel"] == "temp" and c["status"] == "considered" for c in res.considered)
    d = res.to_dict()
    assert d["rms_before"] >= d["rms_after"] > 0


def test_injected_bias_and_drift_are_absorbed_by_the_base(swarm):
    """The declared model: the estimates move by exactly the injection, nothing is reported."""
    t, y, valid, temp, ref = swarm
    tau = t - t[0]
    res = close_loop(t, y + 5e-7 + 5e-12 * tau, valid=valid, aux={"temp": temp}, orbit_period=ORBIT)
    assert [e.name for e in res.effects] == [e.name for e in ref.effects]
    b, d = res.base_coefficient("bias"), res.base_coefficient("drift")
    b0, d0 = ref.base_coefficient("bias"), ref.base_coefficient("drift")
    assert b.after - b0.after == pytest.approx(5e-7 + 5e-12 * (res.t0 - t[0]), rel=1e-6)
    assert d.after - d0.after == pytest.approx(5e-12, rel=1e-6)


@pytest.mark.parametrize(("frac", "size"), [(0.3, 4e-6), (0.9, 3e-6)])
def test_injected_step_is_found_and_nothing_else_removed(swarm, frac, size):
    """A 3e-6 or 4e-6 m/s² bias step (the day's detection limit is ~3e-6) at 30 % or
    90 % of the storm day, with a bias and drift: the step at its epoch, its size
    within 3σ, nothing else removed.  Measured: 3.87e-6 ± 3.4e-7 and 2.97e-6 ± 3.1e-7,
    epochs to the sample.  A 3e-6 step at 30 % is at the limit: found with the orbit
    period at 5607.2 s, missed at 5625.16 s (the storm day does not fix the period:
    the harmonic fit's residual changes by 0.5 % over 5590-5650 s), the estimate since
    each harmonic is weighted by its noise.  (At 62 % of the day, inside the storm's
    main phase, the same step is not detected: docs/closure.md.)"""
    t, y, valid, temp, ref = swarm
    tau = t - t[0]
    epoch = t[0] + frac * tau[-1]
    inj = 5e-7 + 5e-12 * tau + size * (t >= epoch)
    res = close_loop(t, y + inj, valid=valid, aux={"temp": temp}, orbit_period=ORBIT)
    removed = [e for e in res.effects if e.instrument]
    assert [e.name for e in removed] == ["bias_step"]
    step = removed[0]
    assert abs(step.epoch - epoch) <= 60.0
    assert abs(step.coefficient - size) < 3 * step.sigma
