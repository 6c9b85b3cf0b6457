"""Recurring jumps (accal.closure.comb.find_comb) with measures drawn here.

The measure stands in for the jump kernel: at a tooth with an edge it returns that
edge's z, elsewhere a standard normal draw (the kernel's z without an edge).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.comb import LEVEL, MIN_PERIOD, Comb, find_comb

SPAN = (0.0, 86_400.0)


def _measure(rng, edges=(), z_edge=3.5, sign=1.0, window=30.0):
    """``times -> (ok, z, size)``: z ~ N(0, 1), plus ``sign·z_edge`` within ``window``
    s of an edge time."""
    edges = np.asarray(edges, dtype=float)

    def measure(times):
        times = np.asarray(times, dtype=float)
        z = rng.normal(size=times.size)
        if edges.size:
            near = np.abs(times[:, None] - edges[None, :]).min(axis=1) <= window
            z[near] += sign * z_edge
        return np.ones(times.size, dtype=bool), z, 1e-10 * z

    return measure


def test_a_sawtooth_s_jumps_are_one_comb():
    period, first = 6379.3, 2100.0
    teeth = first + period * np.arange(14)
    teeth = teeth[teeth < SPAN[1]]
    picked = teeth[[3, 5, 6, 8, 10]] + np.array([4.0, -7.0, 2.0, 11.0, -3.0])  # epoch noise
    sizes = np.array([-1.99, -1.97, -1.88, -1.88, -1.97]) * 1e-9
    comb = find_comb(picked, sizes, np.full(5, 2.45e-10), SPAN,
                     _measure(np.random.default_rng(1), teeth, sign=-1.0))  # fmt: skip
    assert comb is not None
    assert comb.members == (0, 1, 2, 3, 4)
    assert comb.period == pytest.approx(period, abs=5.0)
    assert comb.n_checked == teeth.size - 5
    assert comb.p_value < LEVEL
    assert comb.size == pytest.approx(sizes.mean(), rel=1e-12)  # equal σ: the plain mean
    # its teeth reach the ends of the record and hold the jumps
    got = comb.teeth(*SPAN)
    assert got.size == teeth.size
    assert np.abs(got[:, None] - picked[None, :]).min(axis=0).max() <= 30.0
    assert "periodic effect" in comb.reason()


def test_teeth_near_the_orbit_template_are_weak_but_many():
    """The case behind the sum test: teeth at z ~2-4 (a period near the orbit's, the
    template following most of each edge), every one of the jumps' sign."""
    period = 5112.5
    teeth = 1816.0 + period * np.arange(17)
    picked = teeth[[10, 11, 15]]
    comb = find_comb(picked, np.array([-1.7, -1.8, -2.2]) * 1e-9, np.full(3, 3e-10), SPAN,
                     _measure(np.random.default_rng(2), teeth, z_edge=2.5, sign=-1.0))  # fmt: skip
    assert comb is not None and comb.period == pytest.approx(period, abs=1.0)


@pytest.mark.parametrize(
    "sizes, why",
    [
        ([2e-9, -2e-9, 2e-9], "signs differ: no pair of the second with another"),
        ([2e-9, 6e-9, 1.1e-8], "sizes disagree by far more than their σ"),
    ],
)
def test_unlike_jumps_are_no_comb(sizes, why):
    period = 5000.0
    picked = np.array([10_000.0, 10_000.0 + period, 10_000.0 + 3 * period])
    comb = find_comb(picked, np.array(sizes), np.full(3, 2e-10), SPAN,
                     _measure(np.random.default_rng(3)))  # fmt: skip
    if comb is not None:  # at most a comb of the two alike ones, needing their teeth
        pytest.fail(f"{why}: {comb}")


def test_a_comb_needs_three_teeth_to_check():
    """Two steps far apart leave at most two other teeth at every divisor: no test."""
    picked = np.array([20_000.0, 62_000.0])  # 42,000 s apart: P ≥ 10,500 s
    rng = np.random.default_rng(4)
    everywhere = _measure(rng, np.arange(0.0, 86_400.0, 10.0))  # an "edge" at every time
    comb = find_comb(picked, np.array([3e-9, 3e-9]), np.full(2, 3e-10), (0.0, 70_000.0),
                     everywhere)  # fmt: skip
    assert comb is None


def test_real_steps_are_rarely_a_comb():
    """Unrelated jumps of one sign and size (2-5 of them, epochs uniform) with no edges
    between them: a comb in fewer than 1 % of 2,000 draws (at most 40 pairs and
    divisors per draw, each at LEVEL)."""
    rng = np.random.default_rng(5)
    hits = 0
    n = 2000
    for _ in range(n):
        k = int(rng.integers(2, 6))
        epochs = np.sort(rng.uniform(3_000.0, 83_000.0, k))
        if np.diff(epochs).min() < MIN_PERIOD:
            continue
        sizes = 3e-9 + 2e-10 * rng.normal(size=k)
        hits += find_comb(epochs, sizes, np.full(k, 2e-10), SPAN, _measure(rng)) is not None
    assert hits / n < 0.01, hits  # 2026-11-29: see the note of the commit


def test_a_comb_s_teeth_cover_the_record():
    c = Comb(period=1000.0, anchor=2500.0, members=(0,), size=1e-9, n_checked=3,
             n_confirmed=3, p_value=1e-6)  # fmt: skip
    np.testing.assert_array_equal(c.teeth(0.0, 5000.0), [500.0, 1500.0, 2500.0, 3500.0, 4500.0])
