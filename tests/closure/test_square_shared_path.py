"""The square of a coupled channel goes through the channel's own lag and low-pass.

Data from a numpy generator written here: one day at 2 s of ``bias + drift +
c1·T(t − L) + c2·(T(t − L) − mean T)²`` plus white noise, ``T`` slow sinusoids and a
random walk, so that the linear coupling alone is significant and enters first.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop

DT, N, LAG = 2.0, 43200, 900.0
C1, C2 = 3e-9, 5e-11  # m/s² per K, per K² (the linear coupling alone enters first)


def _day(seed: int, c2: float):
    rng = np.random.default_rng(seed)
    pre = int(LAG / DT)
    tt = DT * np.arange(-pre, N)
    walk = np.cumsum(rng.normal(0.0, 0.01, tt.size))
    temp = (
        20.0
        + 1.2 * np.sin(2 * np.pi * tt / 5600.0 + rng.uniform(0, 6.3))
        + 0.5 * np.sin(2 * np.pi * tt / 40000.0 + rng.uniform(0, 6.3))
        + walk
        - walk.mean()
    )
    seen = temp[:N]  # the channel L seconds late, as the data feel it
    y = 1e-7 + 1e-13 * DT * np.arange(N) + C1 * seen + c2 * (seen - temp[pre:].mean()) ** 2
    y = y + rng.normal(0.0, 3e-11, N)
    return DT * np.arange(N), y, temp[pre:]


def test_the_square_shares_the_linear_couplings_lag():
    t, y, temp = _day(5, C2)
    res = close_loop(t, y, aux={"T": temp}, signal_model="none", orbit_period=5600.0)
    by = {e.channel: e for e in res.effects if e.name == "auxiliary"}
    assert set(by) == {"T", "T^2"}, [(e.name, e.channel) for e in res.effects]
    assert by["T"].lag == pytest.approx(LAG, abs=3.0)
    assert by["T^2"].lag == by["T"].lag
    assert abs(by["T^2"].coefficient - C2) < 3 * by["T^2"].sigma
    # nothing else removed (an orbit-frequency line, reported only, may be left by the
    # lag's last fraction of a second: 3e-9 m/s²/K · 1.3e-3 K/s · 0.3 s ~ 1e-12 m/s²)
    assert [e.name for e in res.effects if e.instrument and e.name != "auxiliary"] == []


def test_a_coupled_channels_square_is_proposed_on_its_path(monkeypatch):
    """Every proposal of ``T^2`` made once ``T`` is coupled is at ``T``'s lag and τ."""
    import accal.closure.couplings as couplings

    seen = []
    real = couplings._proposals

    def spy(ctx, name, x, tc, lag, mult):
        seen.append((name, lag, tc, ctx.coupled.get("T")))
        return real(ctx, name, x, tc, lag, mult)

    monkeypatch.setattr(couplings, "_proposals", spy)
    t, y, temp = _day(5, C2)
    close_loop(t, y, aux={"T": temp}, signal_model="none", orbit_period=5600.0)
    after = [(lag, tc, path) for name, lag, tc, path in seen if name == "T^2" and path]
    assert after, seen
    assert all((lag, tc) == path for lag, tc, path in after)
