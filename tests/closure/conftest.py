"""Synthetic days for the closure tests (GRACE-like noise from accal.simulate.grace)."""

from __future__ import annotations

import numpy as np
import pytest

from accal.simulate.grace import coloured_noise

ORBIT = 5600.0  # [s]
BIAS, DRIFT = 1.3e-6, 2e-14  # [m/s²], [m/s³]


def make_day(
    seed: int,
    *,
    n: int = 86400,
    dt: float = 1.0,
    noise: float = 1e-10,
    corner: float = 1e-3,
    quadratic: float = 0.0,
    cubic: float = 0.0,
    step: tuple[float, float] | None = None,
    orbit: tuple[float, float] | None = None,
    temp_coupling: float = 0.0,
    temp_lag: float = 600.0,
    chirp: float = 0.0,
    n_gaps: int = 0,
) -> dict:
    """One synthetic day: bias + drift + coloured noise + the requested effects.

    ``step = (fraction of span, size)``, ``orbit = (amp 1/rev, amp 2/rev)``; the
    temperature is a day-scale plus once-per-orbit variation [K] (also returned).
    """
    rng = np.random.default_rng(seed)
    t = 1e8 + dt * np.arange(n)
    tau = t - t[0]
    y = BIAS + DRIFT * tau + coloured_noise(n, dt, noise, corner, rng)
    y += quadratic * tau**2 + cubic * tau**3
    if step is not None:
        y += step[1] * (tau >= step[0] * tau[-1])
    if orbit is not None:
        ph = rng.uniform(0, 2 * np.pi)
        w = 2 * np.pi / ORBIT
        y += orbit[0] * np.cos(w * tau + ph) + orbit[1] * np.sin(2 * w * tau + ph)
    p1 = rng.uniform(0, 2 * np.pi)
    temp = 20 + 1.5 * np.sin(2 * np.pi * tau / 86400 + p1) + 0.4 * np.sin(2 * np.pi * tau / ORBIT)
    temp += 0.3 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n)
    if temp_coupling:
        y += temp_coupling * np.interp(tau - temp_lag, tau, temp)
    if chirp:
        # slow chirp: period 8 h at the start to 1.5 h at the end
        f = np.interp(tau, [0, tau[-1]], [1 / 28800, 1 / 5400])
        y += chirp * np.sin(2 * np.pi * np.cumsum(f) * dt)
    valid = np.ones(n, bool)
    for _ in range(n_gaps):
        a = int(rng.integers(1, n - 2000))
        valid[a : a + int(rng.integers(60, 1800))] = False
    return {"t": t, "y": y, "temp": temp, "valid": valid, "truth": {"bias": BIAS, "drift": DRIFT}}


@pytest.fixture(scope="session")
def sim():
    """The :func:`make_day` factory."""
    return make_day
