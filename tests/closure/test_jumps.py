"""Bias jumps by the spectrum-weighted step test (accal.closure.jumps), on data drawn here.

The generator below is written for these tests (not ``accal simulate`` nor
``tests.indep``): an orbit-periodic signal whose amplitude drifts, a smooth
non-periodic wander like the along-track drag's (a random walk, averaged over a
minute: far above the white noise below ~1 mHz, so the least-squares step scan has
its weight where the wander is), white noise, and what each test adds; then, as the
Level-1B processing does, all of it through a low-pass (seven 11-sample moving averages,
zero phase: a step becomes a ±35 s ramp).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop, jumpchecks, jumps

P = 5600.0  # orbit period [s]


def red_day(seed, n_orbits=6, step=None, boxes=None, wander=3e-11, white=1e-10, l1b=True, saw=None):
    """``(t, y)``: 1 Hz, ``n_orbits`` orbits; ``step=(epoch, size)`` (or a list of
    them); ``saw=(drop, period, first)``: a sawtooth rising by ``drop`` over each
    period and falling by it at ``first + k·period``; ``boxes=(size,
    width, phase)``: a box at that orbital phase in every orbit, drifting by 1 s per
    orbit (an eclipse edge the orbit template does not follow exactly); ``l1b``: the
    low-pass of the Level-1B processing on all of it."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(n_orbits * P), dtype=np.float64)
    w = 2 * np.pi / P
    amp = 1.0 + 0.1 * t / t[-1]
    y = amp * (2e-7 * np.cos(w * t) + 5e-8 * np.cos(2 * w * t + 1.0)) - 3e-7
    walk = np.cumsum(rng.normal(0.0, wander, t.size))
    y += np.convolve(walk, np.ones(60) / 60, mode="same")
    y += rng.normal(0.0, white, t.size)
    for epoch, size in [step] if isinstance(step, tuple) else step or []:
        y += size * (t >= epoch)
    if saw is not None:
        drop, period, first = saw
        y += drop * (((t - first) / period) % 1.0 - 0.5)
    if boxes is not None:
        size, width, phase = boxes
        for k in range(n_orbits):
            a = k * P + phase * P + k * 1.0
            y += size * ((t >= a) & (t < a + width))
    if l1b:
        for _ in range(7):  # centred 11-sample moving average, ends held
            y = np.convolve(
                np.r_[np.full(5, y[0]), y, np.full(5, y[-1])], np.ones(11) / 11, "valid"
            )
    return t, y


def _run(t, y):
    return close_loop(t, y, base="poly1", orbit_period=P, candidates=("bias_step",), alpha=0.01)


@pytest.mark.xfail(
    strict=True,
    reason="since the orbit template's leverage is exact (2026-11-29) this day's residual "
    "is estimated less red: its jump kernel is ~1,030 s wide, beyond jumps.HALF_MAX (600 s), "
    "which a real Swarm day needs (docs/closure.md); the least-squares scan misses the step",
)
def test_a_filtered_step_on_a_red_axis_is_found():
    epoch, size = 20_000.3, 3e-9
    t, y = red_day(1, step=(epoch, size))
    res = _run(t, y)
    steps = [e for e in res.effects if e.name == "bias_step"]
    assert len(steps) == 1, res.effects
    e = steps[0]
    assert e.instrument
    assert "spectrum-weighted" in e.details["method"]
    assert abs(e.epoch - 20_001.0) <= 3.0  # the ramp's middle, not the kernel's epoch
    assert abs(e.coefficient - size) < 2.0 * e.sigma, (e.coefficient, e.sigma)
    assert e.sigma < 0.2 * size  # levels either side of the ramp: σ ~3e-10 m/s²
    # the instrument model carries it, so grace-bias removes it
    inst = res.instrument_model()
    assert inst[t < e.epoch].max() == 0.0
    np.testing.assert_allclose(inst[t >= e.epoch], e.coefficient, rtol=0, atol=1e-22)
    # a line fitted through a later upward step starts low: taking the step out
    # raises the bias, by far more than the change's σ (the jump's own σ is in it)
    b = res.base_coefficient("bias")
    assert b.change > 3 * b.sigma_change > 0


def test_the_least_squares_scan_alone_misses_it():
    """The reason for the edge test: the same day with the least-squares scan only."""
    t, y = red_day(1, step=(20_000.3, 3e-9))
    scan = jumps.scan_jumps
    jumps.scan_jumps = lambda *a, **k: jumps.JumpScan()
    try:
        res = _run(t, y)
    finally:
        jumps.scan_jumps = scan
    assert not [e for e in res.effects if e.name == "bias_step" and abs(e.epoch - 20_001) < 60]


@pytest.mark.parametrize("seed", [2, 3, 4])
def test_clean_red_days_lose_nothing(seed):
    t, y = red_day(seed)
    res = _run(t, y)
    assert not [e for e in res.effects if e.instrument], res.effects


def test_boxes_at_every_orbit_are_not_jumps():
    """A 40 s box of 1e-9 m/s² at the same phase every orbit (drifting 1 s an orbit):
    its edges are sharp and far above the noise, but come in pairs and recur."""
    t, y = red_day(5, boxes=(1e-9, 40.0, 0.3))
    res = _run(t, y)
    assert not [e for e in res.effects if e.instrument], res.effects


def test_a_step_beside_the_boxes_is_still_found():
    epoch, size = 14_321.0, -4e-9
    t, y = red_day(6, step=(epoch, size), boxes=(1e-9, 40.0, 0.3))
    res = _run(t, y)
    steps = [e for e in res.effects if e.name == "bias_step" and e.instrument]
    assert len(steps) == 1, res.effects
    assert abs(steps[0].epoch - epoch) <= 3.0
    assert abs(steps[0].coefficient - size) < 2.0 * steps[0].sigma


def test_jump_sigma_means_what_it_says():
    """z = (size − truth)/σ over 12 noise draws: mean ~0, spread ~1."""
    z = []
    for seed in range(12):
        epoch = 9_000.0 + 1397.0 * seed + 0.5
        t, y = red_day(100 + seed, step=(epoch, 3e-9))
        res = _run(t, y)
        steps = [e for e in res.effects if e.name == "bias_step"]
        assert len(steps) == 1, (seed, res.effects)
        z.append((steps[0].coefficient - 3e-9) / steps[0].sigma)
    z = np.asarray(z)
    assert abs(z.mean()) < 0.75, z
    assert 0.6 < z.std(ddof=1) < 1.5, z


def test_white_noise_is_left_to_the_least_squares_scan():
    """With white noise the GLS kernel of a step is the whole record, not an edge: no
    edge scan (noted); what the least-squares scan makes of the step is its business."""
    rng = np.random.default_rng(9)
    t = np.arange(int(4 * P), dtype=np.float64)
    # unfiltered: white up to the Nyquist frequency
    y = 2e-7 * np.cos(2 * np.pi * t / P) + rng.normal(0, 1e-10, t.size) + 5e-10 * (t >= 9000.5)
    res = _run(t, y)
    notes = " ".join(n["note"] for n in res.notes)
    assert "not red enough" in notes
    assert not [e for e in res.effects if "method" in e.details]


def test_a_jump_has_an_epoch_interval_that_holds_its_ramp():
    """The jump test leaves its transition out, so its epoch interval is where the
    kernel's size stays within σ of its best: it holds the ramp's middle and is no
    wider than the transition's slack allows (here a ±35 s ramp in ±40 s)."""
    for seed in range(4):
        epoch = 9_000.0 + 1397.0 * seed + 0.5
        t, y = red_day(100 + seed, step=(epoch, 3e-9))
        res = _run(t, y)
        (e,) = [e for e in res.effects if e.name == "bias_step"]
        assert e.details["method"].startswith("spectrum-weighted jump")
        lo, hi = e.details["epoch_interval"]
        assert lo <= epoch <= hi, (seed, lo, epoch, hi)
        assert lo <= e.epoch <= hi
        assert hi - lo <= 4 * jumps.TRANSITION
        assert e.details["epoch_sigma"] == pytest.approx(0.5 * (hi - lo))


def test_a_sawtooth_is_not_taken_for_bias_steps():
    """A 2e-9 m/s² sawtooth of period 4100 s (rising, reset at every period): each reset
    passes every test of a lone jump, and taking five of them out left the ramps as a
    trend (the drift moved by 16σ).  They recur at one period: a periodic effect,
    reported in the notes, nothing removed (accal.closure.comb)."""
    t, y = red_day(11, saw=(-2e-9, 4100.0, 1234.5))
    res = _run(t, y)
    assert not [e for e in res.effects if e.instrument], res.effects
    notes = [n["note"] for n in res.notes if "comb of period" in n["note"]]
    assert notes, res.notes
    period = float(notes[0].split("comb of period ")[1].split(" s")[0])
    assert period == pytest.approx(4100.0, abs=10.0)
    d = res.base_coefficient("drift")
    assert abs(d.change) <= d.sigma_change


@pytest.mark.parametrize("seed", [13, 14])
def test_unrelated_steps_of_one_size_are_all_removed(seed):
    """Three steps of one sign and size at unrelated epochs are three bias steps, and
    nothing else: on seed 14 the scan had also removed "jumps" of 2.8e-9 and 2.2e-9
    m/s² one and two orbits before the 16,500 s step, its images in the orbit template
    (jumpchecks.image), and that step came out 3.7σ large."""
    truth = [(7_000.3, 3e-9), (16_500.7, 3e-9), (27_100.2, 3e-9)]
    t, y = red_day(seed, step=truth)
    res = _run(t, y)
    assert all(e.name == "bias_step" for e in res.effects), res.effects
    steps = sorted(res.effects, key=lambda e: e.epoch)
    assert [e.instrument for e in steps] == [True] * 3, res.effects
    for e, (epoch, size) in zip(steps, truth, strict=True):
        lo, hi = e.details["epoch_interval"]
        assert lo <= epoch <= hi and hi - lo < 120.0, (epoch, lo, hi)
        assert abs(e.coefficient - size) < 2.5 * e.sigma, (e.coefficient, e.sigma)


def test_an_effect_beside_a_jump_has_its_own_sigma():
    """QA: a step found by the jump test and a coupling beside it were reported with
    the same σ to every digit: the jumps' sizes come first in the final covariance and
    the effects' σ were read from its first rows (the jump's)."""
    t, y = red_day(21, step=(18_000.3, 1e-8))
    rng = np.random.default_rng(24)
    temp = 293.0 + 0.3 * np.sin(2 * np.pi * t / 86_400.0) + np.cumsum(rng.normal(0, 2e-3, t.size))
    y = y + 3e-8 * (temp - temp.mean())
    kw = {"base": "poly1", "orbit_period": P, "candidates": ("bias_step", "auxiliary"),
          "alpha": 0.01, "aux": {"temp": temp}}  # fmt: skip
    res = close_loop(t, y, **kw)
    (step,) = [e for e in res.effects if e.name == "bias_step"]
    (cpl,) = [e for e in res.effects if e.name == "auxiliary"]
    assert "spectrum-weighted" in step.details["method"]
    assert cpl.sigma != step.sigma
    assert abs(cpl.coefficient - 3e-8) < 3 * cpl.sigma, (cpl.coefficient, cpl.sigma)
    # the same day without the step: the coupling's σ is about the same
    plain = close_loop(t, y - 1e-8 * (t >= 18_000.3), **kw)
    (ref,) = [e for e in plain.effects if e.name == "auxiliary"]
    assert 0.5 < cpl.sigma / ref.sigma < 2.0, (cpl.sigma, ref.sigma)


def test_the_other_edges_are_judged_without_the_jumps_transition():
    """What a sharp step leaves of a low-passed one lies within its transition; the
    checks for a second edge see the line between the means of 10 s either side of it
    instead (a QA day's real 3e-9 m/s² step left a −1.55e-9 m/s² lump there, and a
    red kernel 83 s away took it for a box's other edge), and nothing else changes."""
    t = np.arange(1000.0)
    rng = np.random.default_rng(3)
    r = 1e-10 * rng.standard_normal(t.size)
    r[500:515] -= 1.5e-9
    out = jumpchecks.bridged(t, r, 500.0)
    tr = jumps.TRANSITION
    inside = np.abs(t - 500.0) <= tr
    np.testing.assert_array_equal(out[~inside], r[~inside])
    r0 = r[(t >= 500 - tr - 10) & (t < 500 - tr)].mean()
    r1 = r[(t > 500 + tr) & (t <= 500 + tr + 10)].mean()
    line = r0 + (r1 - r0) * (t[inside] - (500 - tr - 5)) / (2 * tr + 10)
    np.testing.assert_allclose(out[inside], line, rtol=0, atol=1e-24)
    # a side without samples: unchanged
    np.testing.assert_array_equal(jumpchecks.bridged(t[:520], r[:520], 500.0), r[:520])
