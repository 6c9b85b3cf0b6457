"""A pair of steps whose one member is dropped: the other must stand on its own.

Two steps are proposed together (they can mask each other) and, when accepted, enter
the model as two effects at the pair's multiplicity.  When one of them is then
eliminated, the other was admitted only with it.  Before 2026-11-29 the elimination
stopped at one effect, so that member stayed and was removed from the calibrated
series with a corrected p of 1 (a QA helper's own generator: white noise, ~3e-11 m/s²
steps on 3 of 72 clean axes).

The day is drawn here with numpy, the QA generator's recipe: one day at 1 Hz of a
bias, a 1e-12 m/s²/s drift and white noise of 1e-10 m/s² per sample on three axes,
nothing else (no signal, no effect).
"""

from __future__ import annotations

import numpy as np

from accal.closure import close_loop
from accal.closure.period import estimate_period

N = 86400
T0 = 740059202.0  # GPS seconds of 2023-06-15


def _day(seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Three axes of bias + drift + white noise [m/s²], in the QA generator's draw order
    (its temperature's phase and walk come first)."""
    rng = np.random.default_rng(seed)
    rng.uniform(0.0, 2.0 * np.pi)
    rng.normal(0.0, 0.002, N + 1200)
    bias = rng.normal(0.0, 1e-6, 3)
    t = np.arange(N, dtype=float)
    return t, {ax: bias[i] + 1e-12 * t + rng.normal(0.0, 1e-10, N) for i, ax in enumerate("xyz")}


def test_lone_member_of_a_pair_is_retested_and_dropped():
    """Seed 118, x: the pair was accepted, one step eliminated; the other (3.3e-11 m/s²,
    p = 1 alone) was removed.  Now nothing is removed, and every effect reported has a
    corrected p below alpha."""
    t, acc = _day(118)
    alpha = 0.01
    # as grace-bias does: the period estimated once on the three detrended axes
    detrended = [v - np.polyval(np.polyfit(t, v, 1), t) for v in acc.values()]
    period = estimate_period(t, np.column_stack(detrended), 5600.0)
    res = close_loop(
        T0 + t,
        acc["x"],
        orbit_period=period,
        candidates=("bias_step", "periodic"),
        alpha=alpha,
        options={"orbit_period_fixed": True},
        signal_proxies={o: acc[o] for o in "yz"},
    )
    assert [e.name for e in res.effects if e.instrument] == []
    assert all(e.significance < alpha for e in res.effects)
