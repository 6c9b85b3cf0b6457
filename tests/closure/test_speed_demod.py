"""Fast paths of :mod:`accal.closure.demod` and :mod:`accal.closure.platform` against
the straightforward ones: the rest runs of a platform record all at once equal them one
run at a time, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.demod import _rest_runs


def _rest_runs_loop(theta, rest, fs):
    """The rest runs one at a time (median with :func:`numpy.median`)."""
    n = theta.size
    since = np.full(n, np.nan)
    direction = np.zeros(n)
    angle = np.full(n, np.nan)
    starts = np.flatnonzero(rest & ~np.r_[False, rest[:-1]])
    stops = np.flatnonzero(rest & ~np.r_[rest[1:], False]) + 1
    prev = None
    for a, b in zip(starts, stops, strict=True):
        ang = float(np.round(np.median(theta[a:b]), 3))
        angle[a:b] = ang
        if a > 0:  # the first run's history is unknown
            since[a:b] = np.arange(b - a) / fs
        if prev is not None and ang != prev:
            direction[a:b] = np.sign(ang - prev)
        prev = ang
    return since, direction, angle


def _pattern(seed: int, n: int, start_at_rest: bool, nan: bool):
    """θ resting at a few angles (with jitter and odd/even run lengths) between ramps."""
    rng = np.random.default_rng(seed)
    theta = np.empty(n)
    rest = np.zeros(n, bool)
    k, at_rest = 0, start_at_rest
    angles = np.array([0.0, np.pi, np.pi / 2, 3 * np.pi / 2, -0.0])
    while k < n:
        length = int(rng.integers(1, 40))
        sl = slice(k, min(k + length, n))
        if at_rest:
            theta[sl] = rng.choice(angles) + 1e-4 * rng.standard_normal(sl.stop - sl.start)
            rest[sl] = True
        else:
            theta[sl] = rng.uniform(0, 2 * np.pi, sl.stop - sl.start)
        k, at_rest = sl.stop, not at_rest
    if nan:
        theta[np.flatnonzero(rest)[rng.integers(0, rest.sum(), 3)]] = np.nan
    return theta, rest


@pytest.mark.parametrize("seed", range(6))
def test_rest_runs_all_at_once_equal_one_at_a_time(seed):
    theta, rest = _pattern(seed, 3000, start_at_rest=seed % 2 == 0, nan=seed >= 4)
    fast = _rest_runs(theta, rest, 2.0)
    slow = _rest_runs_loop(theta, rest, 2.0)
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(a, b)
        assert np.array_equal(np.signbit(a), np.signbit(b))


def test_rest_runs_without_rest_and_all_rest():
    theta = np.linspace(0, 1, 50)
    for rest in (np.zeros(50, bool), np.ones(50, bool)):
        for a, b in zip(
            _rest_runs(theta, rest, 1.0), _rest_runs_loop(theta, rest, 1.0), strict=True
        ):
            np.testing.assert_array_equal(a, b)
