"""Instrument effects added to a raw accelerometer reading, and the auxiliary channels
they couple to (shared by :mod:`tests.indep.grace` and :mod:`tests.indep.swarm`).

An effect is a tuple ``(kind, axis, ...)``; times are relative to the first epoch ``t0``
of the record [s]:

* ``("step", axis, epoch, size)``: ``size · [t − t0 ≥ epoch]``;
* ``("coupling", axis, channel, coef, lag, tau)``: ``coef · LP_tau(x(t − lag))``, ``x`` the
  channel (a generated temperature-like series), ``LP_tau`` a first-order low-pass
  (``tau = 0``: none); not centred, so a coupling to a 293 K channel adds ``coef · 293 K``;
* ``("quadratic", axis, coef)``: ``coef · (t − t0)²`` [m/s⁴];
* ``("scale", axis, rel_error)``: ``rel_error · (s · a_true)`` (a scale-factor error);
* ``("sawtooth", axis, amp, period[, phase])``: ``amp · (2 frac((t − t0)/period + phase) − 1)``;
* ``("growing_periodic", axis, amp, period, rate[, phase])``:
  ``(amp + rate (t − t0)) · sin(2π ((t − t0)/period + phase))`` (``rate`` in m/s³);
* ``("exponential", axis, amp, tau)``: ``amp · exp(−(t − t0)/tau)``.

``period`` may be ``"orbit"`` (the orbit period of the simulation); ``phase`` is in cycles.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ._common import FloatArray, axis_index, delayed, first_order, rng_for, temperature_channel

#: Effect kinds and their tuple layout (after the kind).
EFFECT_LAYOUT = {
    "step": ("axis", "epoch", "size"),
    "coupling": ("axis", "channel", "coef", "lag", "tau"),
    "quadratic": ("axis", "coef"),
    "scale": ("axis", "rel_error"),
    "sawtooth": ("axis", "amp", "period", "phase"),
    "growing_periodic": ("axis", "amp", "period", "rate", "phase"),
    "exponential": ("axis", "amp", "tau"),
}
#: A coupling's low-pass starts this many time constants before the record (e^-30: settled).
COUPLING_SETTLE = 30.0
#: Optional trailing fields and their defaults.
EFFECT_DEFAULTS = {"phase": 0.0}


def parse_effect(e: Sequence[Any], axes: tuple[str, ...] = ("x", "y", "z")) -> dict[str, Any]:
    """An effect tuple as a dict: ``kind``, ``axis`` (an index into ``axes``), parameters.

    Raises
    ------
    ValueError
        Unknown kind, wrong number of fields, bad axis, negative lag/tau.
    """
    if not isinstance(e, Sequence) or isinstance(e, str) or not e:
        raise ValueError(f"effects: expected tuples (kind, axis, ...), got {e!r}")
    kind = e[0]
    if kind not in EFFECT_LAYOUT:
        raise ValueError(f"effects: expected a kind in {', '.join(EFFECT_LAYOUT)}, got {kind!r}")
    names = EFFECT_LAYOUT[kind]
    required = [k for k in names if k not in EFFECT_DEFAULTS]
    args = list(e[1:])
    if not len(required) <= len(args) <= len(names):
        raise ValueError(
            f"effects: {kind!r} expects ({', '.join(('kind', *names))}), got {tuple(e)!r}"
        )
    out: dict[str, Any] = {"kind": kind}
    out.update({k: v for k, v in EFFECT_DEFAULTS.items() if k in names})
    out.update(dict(zip(names, args, strict=False)))
    out["axis"] = axis_index(out["axis"], axes)
    if kind == "coupling":
        out["channel"] = str(out["channel"])
        if out["lag"] < 0 or out["tau"] < 0:
            raise ValueError(f"effects: coupling lag and tau must be >= 0, got {tuple(e)!r}")
    if kind == "exponential" and not out["tau"] > 0:
        raise ValueError(f"effects: exponential tau must be > 0, got {tuple(e)!r}")
    if "period" in out and out["period"] != "orbit" and not float(out["period"]) > 0:
        raise ValueError(f"effects: period must be > 0 or 'orbit', got {tuple(e)!r}")
    return out


def effect_contribution(
    e: Mapping[str, Any],
    tr: FloatArray,
    dt: float,
    orbit_period: float,
    scaled_signal: FloatArray | None,
    channels: Mapping[str, tuple[FloatArray, FloatArray]],
) -> FloatArray:
    """The exact contribution [m/s²] of one parsed effect.

    Parameters
    ----------
    e : mapping
        From :func:`parse_effect`.
    tr : ndarray, shape (n,)
        Times relative to the first epoch [s].
    dt : float
        Sampling interval [s] (of the channels' grid, for the low-pass).
    orbit_period : float
        [s], for ``period="orbit"``.
    scaled_signal : ndarray, shape (n, n_axes) or None
        ``s · a_true`` (for ``scale``).
    channels : mapping of str to (t_ext, x_ext)
        Each channel on a grid that extends the record to the past (relative times,
        ending with ``tr``), so lagged and filtered values exist from the first epoch.

    Returns
    -------
    ndarray, shape (n,)
    """
    kind = e["kind"]
    if kind == "step":
        return np.where(tr >= e["epoch"], float(e["size"]), 0.0)
    if kind == "coupling":
        t_ext, x = channels[e["channel"]]
        # the filter starts COUPLING_SETTLE time constants before the record, whatever the
        # other couplings made the channel's prefix: the contribution is the effect's own
        start = int(np.searchsorted(t_ext, -COUPLING_SETTLE * e["tau"] - 0.5 * dt))
        y = first_order(delayed(t_ext[start:], t_ext, x, e["lag"]), dt, e["tau"])
        return e["coef"] * y[-tr.size :]
    if kind == "quadratic":
        return e["coef"] * tr**2
    if kind == "scale":
        if scaled_signal is None:
            raise ValueError("effects: 'scale' needs the true signal")
        return e["rel_error"] * scaled_signal[:, e["axis"]]
    if kind == "exponential":
        return e["amp"] * np.exp(-tr / e["tau"])
    period = orbit_period if e["period"] == "orbit" else float(e["period"])
    if kind == "sawtooth":
        return e["amp"] * (2 * np.mod(tr / period + e["phase"], 1.0) - 1)
    return (e["amp"] + e["rate"] * tr) * np.sin(2 * np.pi * (tr / period + e["phase"]))


def make_channels(
    seed: int,
    names: Iterable[str],
    effects: Iterable[Mapping[str, Any]],
    n: int,
    dt: float,
    orbit_period: float,
) -> tuple[dict[str, tuple[FloatArray, FloatArray]], dict[str, dict]]:
    """Temperature-like channels on a grid ending at the record's samples.

    Each channel named in ``names`` or coupled to by an effect is drawn with
    :func:`tests.indep._common.temperature_channel` from its own random stream
    (``seed``, ``"channel"``, name), on relative times ``k dt`` for ``k = −k0 .. n−1``,
    where ``k0`` covers the longest ``lag + COUPLING_SETTLE tau`` of the couplings to it.

    Returns
    -------
    channels : dict of str to (t_ext, x_ext)
    params : dict of str to dict
        The drawn parameters of each channel.
    """
    effects = list(effects)
    wanted = dict.fromkeys(names)
    for e in effects:
        if e["kind"] == "coupling":
            wanted[e["channel"]] = None
    out, params = {}, {}
    for name in wanted:
        pre = max(
            [e["lag"] + COUPLING_SETTLE * e["tau"] for e in effects if e.get("channel") == name]
            + [0.0]
        )
        k0 = int(np.ceil(pre / dt)) + 1
        t_ext = np.arange(-k0, n) * dt
        vals, p = temperature_channel(
            t_ext, rng_for(seed, "channel", name), orbit_period=orbit_period
        )
        out[name] = (t_ext, vals)
        params[name] = p
    return out, params


def apply_effects(
    effects: Iterable[Mapping[str, Any]],
    tr: FloatArray,
    dt: float,
    orbit_period: float,
    scaled_signal: FloatArray | None,
    channels: Mapping[str, tuple[FloatArray, FloatArray]],
    n_axes: int,
) -> tuple[list[dict[str, Any]], FloatArray]:
    """Contributions of parsed effects: each effect dict with ``contribution`` added, and
    their sum per axis, shape (n, n_axes)."""
    done, total = [], np.zeros((tr.size, n_axes))
    for e in effects:
        c = effect_contribution(e, tr, dt, orbit_period, scaled_signal, channels)
        total[:, e["axis"]] += c
        done.append({**e, "contribution": c})
    return done, total
