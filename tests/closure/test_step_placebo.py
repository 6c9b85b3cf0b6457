"""A step's σ on a per-block base holds what the model lacks within a block (placebo epochs).

Data drawn here (not with accal's simulators): per-block affine bias, white noise and,
in the first tests, a curvature inside every block that the base does not model (as a
rotating platform's signal changes within a demodulation period).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import BlockBase, close_loop

Q = 400  # samples per block
NB = 60  # blocks
SIZE = 3e-9
NOISE = 1e-10


def _day(seed: int, curvature: float):
    rng = np.random.default_rng(seed)
    n = NB * Q
    t = 5000.0 + np.arange(n, dtype=float)
    blk = np.arange(n) // Q
    u = (np.arange(n) % Q - (Q - 1) / 2) / Q
    bias = 1e-6 * rng.standard_normal(NB)
    y = bias[blk] + 1e-9 * rng.standard_normal(NB)[blk] * u
    y += NOISE * rng.standard_normal(n)
    # an unmodelled shape inside every block, a different amplitude in each
    y += curvature * rng.standard_normal(NB)[blk] * (u**2 - 1.0 / 12.0)
    b_step = int(rng.integers(10, NB - 10))
    epoch = t[b_step * Q + int(rng.integers(100, Q - 100))]
    y += SIZE * (t >= epoch)
    bb = BlockBase(blk, np.column_stack([np.ones(n), u]), ("bias", "drift"))
    _day.truth = {"bias": bias, "step_block": b_step}
    return t, y, bb, epoch


def _white(f):
    """The noise drawn: white, two-sided PSD σ²·Δt [(m/s²)²/Hz] (Δt = 1 s)."""
    return np.full_like(np.asarray(f, dtype=float), NOISE**2)


def _step(res, epoch):
    steps = [e for e in res.effects if e.name == "bias_step" and abs(e.epoch - epoch) <= 5]
    assert steps, [(e.name, e.epoch) for e in res.effects]
    return steps[0]


def test_unmodelled_shape_in_the_blocks_widens_the_step_sigma():
    zs, ratio = [], []
    for seed in range(6):
        t, y, bb, epoch = _day(seed, curvature=2e-9)
        # the instrument's noise model given, as demod gives its PSD: it knows nothing
        # of the shape
        res = close_loop(t, y, base=bb, candidates=("bias_step",), noise_psd=_white)
        st = _step(res, epoch)
        zs.append((st.coefficient - SIZE) / st.sigma)
        model = st.details["sigma_noise_model"][0]
        ratio.append(st.sigma / model)
        assert st.sigma == pytest.approx(max(model, st.details["sigma_placebo"][0]), rel=1e-9)
    # the in-block shape moves the size by several times the noise model's σ
    assert min(ratio) > 3.0, ratio
    assert np.sqrt(np.mean(np.square(zs))) < 1.5, zs


def test_without_unmodelled_shape_the_placebo_sigma_is_the_noise_models():
    ratios, zs = [], []
    for seed in range(6):
        t, y, bb, epoch = _day(100 + seed, curvature=0.0)
        res = close_loop(t, y, base=bb, candidates=("bias_step",), noise_psd=_white)
        st = _step(res, epoch)
        ratios.append(st.details["sigma_placebo"][0] / st.details["sigma_noise_model"][0])
        zs.append((st.coefficient - SIZE) / st.sigma)
    assert 0.6 < np.median(ratios) < 1.6, ratios
    assert np.sqrt(np.mean(np.square(zs))) < 1.6, zs


def test_one_block_base_has_no_placebo():
    rng = np.random.default_rng(7)
    n = 20_000
    t = np.arange(n, dtype=float)
    y = 1e-7 + NOISE * rng.standard_normal(n) + SIZE * (t >= 12_345.0)
    res = close_loop(t, y, base="poly1", candidates=("bias_step",))
    st = _step(res, 12_345.0)
    assert "sigma_placebo" not in st.details
    assert abs(st.coefficient - SIZE) < 5 * st.sigma


def test_the_wider_step_sigma_reaches_the_bias_of_the_steps_block():
    """The step's block estimates its bias with the step: ``b = b_plain − a·γ``, so the
    step's wider σ must widen that bias's σ (error propagation), not stay the noise
    model's."""
    zs, widened = [], []
    for seed in range(6):
        t, y, bb, epoch = _day(seed, curvature=2e-9)
        truth = _day.truth
        res = close_loop(t, y, base=bb, candidates=("bias_step",), noise_psd=_white)
        _step(res, epoch)
        b = res.base_coefficient(f"bias[{truth['step_block']}]")
        zs.append((b.after - truth["bias"][truth["step_block"]]) / b.sigma_after)
        widened.append(b.sigma_after / b.sigma_plain)
        # a block before the step does not see it: its σ stays the plain one's (a
        # block after it has ``b = mean − γ`` and carries the step's σ in full)
        before = res.base_coefficient(f"bias[{truth['step_block'] - 5}]")
        assert before.sigma_after == pytest.approx(before.sigma_plain, rel=0.05)
        after = res.base_coefficient(f"bias[{truth['step_block'] + 5}]")
        assert after.sigma_after > 0.9 * _step(res, epoch).sigma
    assert min(widened) > 2.0, widened
    assert np.sqrt(np.mean(np.square(zs))) < 1.5, zs
