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


def _line_day(seed: int, coupled: bool):
    """Two data channels; a temperature that is mostly a 4100 s cycle (plus a walk);
    either a bias line at that period (no coupling) or a true lagged coupling."""
    rng = np.random.default_rng(seed)
    tt = np.arange(N, dtype=float)
    ext = np.arange(-1000, N, dtype=float)
    temp_ext = _temperature(ext, rng)
    temp = temp_ext[1000:]
    t = np.repeat(tt, 2)
    ch = np.tile([0, 1], N)
    y = np.empty(2 * N)
    y[0::2] = 1e-7 + 2e-11 * rng.standard_normal(N)
    y[1::2] = -2e-7 + 2e-11 * rng.standard_normal(N)
    if coupled:
        lagged = np.interp(tt - LAG, ext, temp_ext)
        y[0::2] += 3e-8 * lagged
        y[1::2] += 3e-8 * lagged
    else:  # a line at the temperature's period on channel y only, 3e-10 m/s²
        y[0::2] += 3e-10 * np.sin(2 * np.pi * tt / 4100.0 + 0.7)
    return t, y, ch, np.repeat(temp, 2)


def test_a_line_at_the_channels_period_is_not_taken_for_a_coupling():
    """A lagged channel that is mostly one sinusoid fits any line at its period; the
    coupling must explain more than that line does (validation.competing_line_test),
    otherwise the channel's walk times the coefficient would be removed from the data."""
    t, y, ch, temp = _line_day(3, coupled=False)
    res = close_loop(t, y, channel=ch, channel_names=("y", "z"), aux={"temperature": temp},
                     candidates=("auxiliary", "periodic"))  # fmt: skip
    assert not [e for e in res.effects if e.name == "auxiliary"], [
        (e.name, e.channel) for e in res.effects
    ]
    lines = [e for e in res.effects if e.name == "periodic"]
    assert lines and abs(1.0 / lines[0].frequency - 4100.0) < 5.0
    rej = [r for r in res.rejected if r.name == "auxiliary"]
    assert rej and "lines at the channel's own periods" in rej[0].details["reason"]


def test_a_true_coupling_to_a_cycling_channel_is_still_found():
    t, y, ch, temp = _line_day(4, coupled=True)
    res = close_loop(t, y, channel=ch, channel_names=("y", "z"), aux={"temperature": temp},
                     candidates=("auxiliary", "periodic"))  # fmt: skip
    found = [e for e in res.effects if e.name == "auxiliary"]
    assert found, [(e.name, e.channel) for e in res.effects]
    c = found[0].details["axes"]["y"]
    assert abs(c["coefficient"] - 3e-8) < 3 * c["sigma"] + 1e-3 * 3e-8
    assert found[0].details["competing_lines"]["score"] > 0
