"""A coupling to a channel with a large mean (a 293 K temperature) on two data channels.

The two-channel lag scan formed ‖(I − P)x‖² of the raw channel: a few mK of variation
are 1e-10 of its norm and were lost to cancellation, so every platform coupling scanned as
zero power.  Data drawn here, not with accal's simulators.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop

N = 30_000
LAG = 300.0


def _temperature(tt: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    walk = np.cumsum(rng.standard_normal(tt.size)) * 2e-5
    return 293.15 + 0.005 * np.sin(2 * np.pi * tt / 4100.0) + walk - walk.mean()


@pytest.mark.parametrize("seed", [1, 2])
def test_lagged_coupling_to_a_warm_channel_is_found_on_two_channels(seed):
    rng = np.random.default_rng(seed)
    tt = np.arange(N, dtype=float)
    ext = np.arange(-1000, N, dtype=float)
    temp_ext = _temperature(ext, rng)
    temp = temp_ext[1000:]
    lagged = np.interp(tt - LAG, ext, temp_ext)
    coef = 3e-8  # m/s² per K: 1.5e-10 m/s² over the 5 mK swing (the platform's size)
    t = np.repeat(tt, 2)
    ch = np.tile([0, 1], N)
    y = np.empty(2 * N)
    y[0::2] = 1e-7 + 2e-11 * rng.standard_normal(N) + coef * lagged
    y[1::2] = -2e-7 + 2e-11 * rng.standard_normal(N) + coef * lagged
    res = close_loop(
        t,
        y,
        channel=ch,
        channel_names=("y", "z"),
        aux={"temperature": np.repeat(temp, 2)},
        candidates=("auxiliary",),
    )
    found = [e for e in res.effects if e.name == "auxiliary" and e.channel == "temperature"]
    assert found, [(e.name, e.channel) for e in res.effects]
    e = found[0]
    for ax in ("y", "z"):
        c = e.details["axes"][ax]
        assert abs(c["coefficient"] - coef) < 3 * c["sigma"] + 1e-3 * coef
    assert abs(e.lag - LAG) < 30.0
