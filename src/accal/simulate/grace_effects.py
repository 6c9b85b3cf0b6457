"""The injected instrument effects of a simulated GRACE day (:mod:`accal.simulate.grace`).

The ``--effect`` specifications (:mod:`accal.simulate.effects`) parsed for a day
(:func:`parsed_effects`), the auxiliary channels the couplings need
(:func:`coupling_channels`), the sum of the effects' terms added to the raw reading
(:func:`effects_sum`) and their truth entries (:func:`day_effect_truth`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.simulate.effects import (
    CHANNEL_PREROLL,
    VECTOR_EFFECTS,
    Effect,
    channel_seed,
    effect_term,
    effect_truth,
    parse_effect,
    temperature_channel,
    vector_term,
)


def parsed_effects(kwargs: dict[str, Any]) -> list[Effect]:
    """The effects of a simulation's keyword arguments, parsed as simulate_grace_day does."""
    span = int(round(kwargs.get("duration", 86400.0) / kwargs.get("dt", 1.0))) * kwargs.get(
        "dt", 1.0
    )
    effects = kwargs.get("effects", ())
    return [e if isinstance(e, Effect) else parse_effect(e, duration=span) for e in effects]


def coupling_channels(
    effects: Sequence[Effect], t0: float, n: int, dt: float, seed: int, orbit_period: float
) -> tuple[NDArray, dict[str, NDArray], dict[str, dict]]:
    """The auxiliary channels the couplings need, from CHANNEL_PREROLL before t0 to the end."""
    names = sorted({e.params["channel"] for e in effects if e.name == "coupling"})
    if not names:
        return np.zeros(0), {}, {}
    pre = int(np.ceil(CHANNEL_PREROLL / dt))
    tc = dt * np.arange(-pre, n)  # elapsed time since t0
    values, params = {}, {}
    for name in names:
        rng = np.random.default_rng(channel_seed(seed, name))
        values[name], params[name] = temperature_channel(tc, orbit_period, rng)
        params[name]["unit"] = "K"
    return tc, values, params


def effects_sum(
    effects: Sequence[Effect],
    tau: NDArray,
    span: float,
    scaled_true: NDArray,
    channels: dict[str, tuple[NDArray, NDArray]],
    t0: float,
) -> NDArray[np.float64]:
    """The sum of the effects' terms per axis [m/s²], shape (n, 3)."""
    out = np.zeros((tau.size, 3))
    for e in effects:
        if e.name in VECTOR_EFFECTS:
            out += vector_term(e, scaled_true)
            continue
        i = e.index
        out[:, i] += effect_term(
            e, tau, duration=span, scaled_true=scaled_true[:, i], channels=channels, t0=t0
        )
    return out


def day_effect_truth(e: Effect, t0: float, s: NDArray, span: float) -> dict[str, Any]:
    """The truth entry of an effect: a vector effect as given, the others with their axis's ``s``."""
    if e.name in VECTOR_EFFECTS:
        return effect_truth(e, t0, 1.0)
    return effect_truth(e, t0, float(s[e.index]), duration=span)
