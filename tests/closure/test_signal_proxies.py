"""The other axes as signal proxies: a storm's onset is not a bias step (issue 19).

Without a reference the orbit-phase template cannot follow a change of the signal
that is not orbit-periodic, such as a storm's density rise; its kink in the
cross-track axis is fitted by bias steps.  The same rise is on the other axes, so an
instrument effect has to stay significant with them in the model
(:func:`accal.closure.validation.signal_proxy_test`).  The day is drawn here, not by
``accal simulate`` or ``tests.indep``: drag proportional to a density with a
once-per-revolution term, 0.5 % slow fluctuations and a storm that doubles it within
~10 minutes; its cross-track and radial parts 3 % and 1 % of the along-track drag;
solar pressure; white plus AR(1) noise on every axis.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop
from accal.errors import ValidationError

PERIOD = 5640.0
ONSET = 15000.0
ABRUPT = 31000.0


def drawn_day(seed: int, storm: bool | str, step: tuple[float, float] | None = None):
    """(t, data (n, 3)) of one 1 Hz day; ``step``: (epoch [s], size [m/s²]) on y;
    ``storm="abrupt"``: the density up by 8 % within a second at :data:`ABRUPT`."""
    rng = np.random.default_rng(seed)
    n = 86400
    t = np.arange(n, dtype=float)
    u = 2.0 * np.pi * t / PERIOD
    f = np.fft.rfftfreq(n, 1.0)
    spec = np.fft.rfft(rng.standard_normal(n)) / np.sqrt(1.0 + (f / 3e-4) ** 4)
    fluct = np.fft.irfft(spec, n)
    fluct *= 0.005 / fluct.std()
    density = (1.0 + 0.3 * np.cos(u - 0.5)) * (1.0 + fluct)
    if storm == "abrupt":
        density *= 1.0 + 0.08 * (t >= ABRUPT)
    elif storm:
        density *= 1.0 + (1.0 - np.exp(-np.clip(t - ONSET, 0.0, None) / 600.0))
    drag = 3e-7 * density
    srp = 4e-8 * np.column_stack([np.sin(u), np.full(n, 0.2), np.cos(u)])
    data = np.column_stack([-drag, 0.03 * drag, 0.01 * drag]) + srp
    a = np.exp(-1.0 / 900.0)
    red = np.zeros((n, 3))
    kick = 3e-12 * rng.standard_normal((n, 3))
    for i in range(1, n):
        red[i] = a * red[i - 1] + kick[i]
    data += 1e-10 * rng.standard_normal((n, 3)) + red
    if step is not None:
        data[:, 1] += step[1] * (t >= step[0])
    return t, data


def closure_y(t, data, proxies: dict | None, max_effects: int = 5):
    return close_loop(
        t,
        data[:, 1],
        base="poly1",
        orbit_period=PERIOD,
        candidates=("bias_step",),
        options={"orbit_period_fixed": True},
        signal_proxies=proxies,
        max_effects=max_effects,
    )


def removed(res) -> list:
    return [e for e in res.effects if e.instrument]


def test_a_storm_onset_is_not_removed_as_a_step():
    t, data = drawn_day(0, storm=True)
    # the hazard is real on this day: without the other axes, a step at the onset (the
    # first of several: the search is stopped there)
    alone = closure_y(t, data, None, max_effects=1)
    assert any(abs(e.epoch - ONSET) < 2000.0 for e in removed(alone)), removed(alone)
    res = closure_y(t, data, {"x": data[:, 0], "z": data[:, 2]})
    assert removed(res) == []
    assert res.signal_model["signal_proxies"] == ["x", "z"]
    for e in res.rejected:  # whatever was significant was told from the signal
        assert e.name == "bias_step"
        assert "other axes (x, z)" in e.details["reason"]
        assert e.details["signal_proxy"]["p_adj"] >= 0.01


def test_a_real_step_stays_and_a_bad_proxy_is_left_out_with_a_note():
    epoch, size = 50000.0, 3e-9
    t, data = drawn_day(1, storm=False, step=(epoch, size))
    bad = data[:, 2].copy()
    bad[100] = np.nan
    res = closure_y(t, data, {"x": data[:, 0], "z": data[:, 2], "broken": bad})
    assert res.signal_model["signal_proxies"] == ["x", "z"]
    assert any("signal proxy broken left out" in n["note"] for n in res.notes)
    (step,) = removed(res)
    assert step.name == "bias_step"
    assert abs(step.epoch - epoch) <= 60.0
    assert abs(step.coefficient - size) < 3.0 * step.sigma
    assert step.details["signal_proxy"]["p_adj"] < 0.01


def abrupt_day(seed: int, walk: float, onset: bool, x_step: float = 0.0):
    """(t, data (n, 3)): a day whose density jumps by 8 % within a second at 31000 s
    (``onset``; the storm days of an outside QA generator switched their variability on
    like that), with a random-walk wander of relative size ``walk`` over the day, the
    Level-1B low-pass on every axis, and a real bias step of ``x_step`` on x at
    50000 s."""
    rng = np.random.default_rng(seed)
    n = 86400
    t = np.arange(n, dtype=float)
    u = 2.0 * np.pi * t / PERIOD
    wander = np.convolve(np.cumsum(rng.normal(0.0, walk / np.sqrt(n), n)), np.ones(60) / 60, "same")
    density = (1.0 + 0.3 * np.cos(u - 0.5)) * (1.0 + wander) * (1.0 + 0.08 * onset * (t >= 31000))
    drag = 3e-7 * density
    srp = 4e-8 * np.column_stack([np.sin(u), np.full(n, 0.2), np.cos(u)])
    data = np.column_stack([-drag, 0.03 * drag, 0.01 * drag]) + srp
    data += rng.normal(0.0, 1e-10, (n, 3))
    data[:, 0] += x_step * (t >= 50000)
    for _ in range(7):  # a centred 11-sample moving average, ends held
        pad = np.concatenate([np.repeat(data[:1], 5, 0), data, np.repeat(data[-1:], 5, 0)])
        data = np.stack([np.convolve(c, np.ones(11) / 11, "valid") for c in pad.T], axis=1)
    return t, data


def closure_x(t, data, proxies: bool):
    return close_loop(
        t,
        data[:, 0],
        base="poly1",
        orbit_period=PERIOD,
        candidates=("bias_step",),
        signal_proxies={"y": data[:, 1], "z": data[:, 2]} if proxies else None,
    )


@pytest.mark.parametrize(
    ("seed", "walk", "method"),
    [
        (0, 1e-2, "spectrum-weighted jump"),
        # was found by the least-squares scan while the onset pulled the orbit period
        # (2026-11-29: the period is now searched with the onset's level shift out, and
        # the jump scan sees it); the least-squares path's check of the other axes is
        # test_a_storm_onset_is_not_removed_as_a_step's
        (1, 1e-3, "spectrum-weighted jump"),
        (5, 3e-4, "spectrum-weighted jump"),
    ],
)
def test_an_abrupt_change_of_the_drag_is_not_a_step_of_its_axis(seed, walk, method):
    """Seen on an outside QA storm day: a 3.4e-8 m/s² along-track "step" at the onset
    was removed with p 1e-55 by the jump scan, which did not ask the other axes."""
    t, data = abrupt_day(seed, walk, onset=True)
    alone = removed(closure_x(t, data, proxies=False))
    if method:  # the hazard is real on these days, and the test the one named
        (step,) = alone
        assert abs(step.epoch - 31000) < 60.0
        assert step.details.get("method", "least squares").startswith(method)
    res = closure_x(t, data, proxies=True)
    assert removed(res) == []
    told = [n["note"] for n in res.notes if "the other axis" in n["note"]]
    told += [e.details["reason"] for e in res.rejected if "other ax" in e.details["reason"]]
    assert told


@pytest.mark.parametrize("seed", [0, 3])
def test_an_abrupt_change_seen_on_noisy_axes_is_not_a_step(seed):
    """With the other axes noisy (white plus AR(1)), one coefficient each for the day
    is attenuated (errors in variables): given them, the onset's 1.8e-8 m/s² jump kept
    6.2σ.  Their own edges at the onset (7e-10 and 2.4e-10 m/s²) tell it."""
    t, data = drawn_day(seed, "abrupt")
    (step,) = removed(closure_x(t, data, proxies=False))
    assert abs(step.epoch - ABRUPT) < 60.0
    res = closure_x(t, data, proxies=True)
    assert removed(res) == []
    assert any("other axis y has an edge" in n["note"] for n in res.notes), res.notes


@pytest.mark.parametrize(("seed", "walk"), [(0, 1e-2), (1, 3e-4)])
def test_a_step_of_the_along_track_axis_alone_is_still_removed(seed, walk):
    t, data = abrupt_day(seed, walk, onset=False, x_step=1e-8)
    (step,) = removed(closure_x(t, data, proxies=True))
    assert abs(step.epoch - 50000) <= 60.0
    assert abs(step.coefficient - 1e-8) < 3.0 * step.sigma


def test_a_proxy_of_the_wrong_length_is_a_clear_error():
    t = np.arange(5000.0)
    y = np.zeros_like(t)
    with pytest.raises(ValidationError, match="signal proxy 'x' must have shape"):
        close_loop(t, y, orbit_period=PERIOD, signal_proxies={"x": np.zeros(10)})


def test_an_onset_hidden_on_an_axis_by_that_axis_own_step_is_still_seen():
    """QA (2026-11-29): a real 1e-8 m/s² step an hour after a storm's onset on the
    cross-track axis raised that axis' PSD so much that its own onset edge was not
    significant, and the onset was removed from the along-track axis as a bias step
    (3 of 18 storm days).  The other axes' own jumps are taken out before their edges
    are measured (``crossaxis._own_jumps``)."""
    t, data = abrupt_day(0, 1e-2, onset=True)
    rng = np.random.default_rng(100)
    cross = data[:, 1] + 1e-8 * (t >= ABRUPT + 3600)  # its own, unrelated step
    quiet = 1e-10 * rng.standard_normal(t.size)  # no signal: cannot tell
    res = close_loop(
        t, data[:, 0], base="poly1", orbit_period=PERIOD, candidates=("bias_step",),
        signal_proxies={"y": cross, "z": quiet},
    )  # fmt: skip
    assert removed(res) == []
    assert any("the other axis y has an edge" in n["note"] for n in res.notes), res.notes
