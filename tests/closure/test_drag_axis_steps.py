"""Bias steps on the drag axis without a reference (issue 19).

The along-track drag varies with the density the satellite flies through, not only
with the orbit: a few % over tens of minutes, which the one-orbit smooth curve of the
null model cannot follow.  A step's least-squares statistic has its weight at those
low frequencies, so on x a 1e-8 m/s² step was never found.  On the drag axis
(recognised from the data and the other axes) the null model takes a smooth curve
with knots a 24th of an orbit apart, and a step is told from the signal by its edge
(:func:`accal.closure.nuisance.choose_template`); what the curve cannot follow either
(transitions over a few minutes, an eclipse edge that drifts with the orbit) is not a
step unless it is sharper than a 2-minute ramp and does not come back one or two
orbits away (:func:`accal.closure.validation.sharpness_test`, ``recurrence_test``).

The days are drawn here, with numpy only (not ``accal simulate``, not ``tests.indep``):
drag proportional to a density with once- and twice-per-revolution terms, a 10 % trend
and 2 % non-periodic fluctuations (two spectral shapes: a smooth one and a Lorentzian
whose f⁻² tail puts drag changes at every time scale); solar pressure switched off in
eclipse with a short penumbra; cross-track and radial parts of the drag; white noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop
from accal.closure.report import result_to_dict, to_markdown

PERIOD = 5610.0
N = 86400


def drawn_day(seed: int, shape: str, step: tuple[float, float] | None = None):
    """(t, x, y, z) of one 1 Hz day [s, m/s²]; ``step``: (epoch [s], size [m/s²]) on x."""
    rng = np.random.default_rng(seed)
    t = np.arange(N, dtype=float)
    u = 2.0 * np.pi * t / PERIOD
    f = np.fft.rfftfreq(N, 1.0)
    if shape == "smooth":
        filt = np.exp(-0.5 * (f / 8e-4) ** 2)
    else:  # Lorentzian: an Ornstein-Uhlenbeck density, corner 0.3 mHz
        filt = 1.0 / np.sqrt(1.0 + (f / 3e-4) ** 2)
    fluct = np.fft.irfft(np.fft.rfft(rng.standard_normal(N)) * filt, N)
    fluct *= 0.02 / fluct.std()
    density = (1.0 + 0.25 * np.cos(u - 0.3) + 0.05 * np.cos(2 * u)) * (1.0 + fluct)
    drag = 4e-7 * density * (1.0 + 0.1 * t / N)
    illum = np.clip((np.cos(u) + 0.35) / 0.02, 0.0, 1.0)  # umbra, a ~30 s penumbra
    srp = 3e-8 * illum
    x = -drag + 0.3 * srp + 1e-10 * rng.standard_normal(N)
    y = 0.02 * drag + 0.8 * srp + 1e-10 * rng.standard_normal(N)
    z = 0.01 * drag - 0.5 * srp + 1e-10 * rng.standard_normal(N)
    if step is not None:
        x = x + step[1] * (t >= step[0])
    return t, x, y, z


def closure_x(t, x, y, z, **kw):
    return close_loop(
        t, x, base="poly1", orbit_period=PERIOD, signal_proxies={"y": y, "z": z}, **kw
    )


def removed(res) -> list:
    return [e for e in res.effects if e.instrument]


def test_a_step_on_the_drag_axis_is_found():
    epoch, size = 34567.0, 1e-8
    t, x, y, z = drawn_day(2, "smooth", (epoch, size))
    res = closure_x(t, x, y, z, candidates=("bias_step",))
    assert res.signal_model["knot_rule"]["fine"], res.signal_model
    assert res.signal_model["knot_spacing"] == pytest.approx(PERIOD / 24, rel=0.01)
    steps = [e for e in removed(res) if e.name == "bias_step"]
    assert len(steps) == 1, removed(res)
    assert abs(steps[0].epoch - epoch) <= 2.0
    assert abs(steps[0].coefficient - size) < 2.0 * steps[0].sigma
    assert steps[0].sigma < 0.2 * size
    # the report says why the axis has the fine curve; closure.json carries the rule
    assert "the drag axis" in to_markdown(res)
    assert result_to_dict(res)["signal_model"]["knot_rule"]["fine"] is True


def test_a_clean_drag_axis_with_drag_changes_at_every_scale_loses_nothing():
    """The Lorentzian density: drag changes of ~5e-10 m/s² per second; nothing is a step."""
    t, x, y, z = drawn_day(1, "lorentz")
    res = closure_x(t, x, y, z)
    assert removed(res) == [], [(e.name, e.coefficient, e.epoch) for e in removed(res)]


def test_the_other_axes_keep_the_orbit_curve():
    t, x, y, z = drawn_day(2, "smooth")
    res = close_loop(
        t, y, base="poly1", orbit_period=PERIOD, signal_proxies={"x": x, "z": z},
        candidates=("bias_step",),
    )  # fmt: skip
    rule = res.signal_model["knot_rule"]
    assert not rule["fine"]
    assert rule["slow_std"] < min(rule["slow_std_other_axes"][:1])
    assert res.signal_model["knot_spacing"] == pytest.approx(res.signal_model["period"])


def test_without_the_other_axes_the_drag_axis_is_not_recognised():
    t, x, _, _ = drawn_day(2, "smooth")
    res = close_loop(t, x, base="poly1", orbit_period=PERIOD, candidates=("bias_step",))
    assert not res.signal_model["knot_rule"]["fine"]
    assert res.signal_model["knot_rule"]["residual_ratio"] >= 2.0
