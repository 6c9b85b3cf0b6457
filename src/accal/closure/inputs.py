"""The inputs of :func:`accal.closure.close_loop` checked and set up.

The data, times and channels (:func:`check_inputs`, :func:`check_channels`), the
declared base as a block design (:func:`base_design`), the channels offered for
couplings (:func:`screen_channels`: never the target or a copy of it) and the other
axes offered as signal proxies (:func:`check_proxies`, :func:`usable_proxies`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.blockbase import BlockBase
from accal.closure.kinds import unit_class
from accal.closure.validation import SignalProxies
from accal.errors import ValidationError, check_option

__all__ = [
    "angular_about_offset",
    "MIN_COVERAGE",
    "MIN_SAMPLES",
    "SELF_CORRELATION",
    "base_design",
    "check_channels",
    "check_inputs",
    "check_proxies",
    "prepared_inputs",
    "screen_channels",
    "usable_proxies",
    "with_caller_notes",
]

#: Fewest usable samples :func:`accal.closure.close_loop` analyses.
MIN_SAMPLES = 50
#: A channel correlated with the data beyond this is the data (or derived from it).
SELF_CORRELATION = 0.99
#: Least share of the used samples a channel must cover to be offered.
MIN_COVERAGE = 0.9
POLY_BASES = ("poly0", "poly1", "poly2", "poly3")
POLY_NAMES = ("bias", "drift", "quadratic", "cubic")


def poly_base(order: int, t, t0: float, span: float, chan, names) -> BlockBase:
    u = (t - t0) / span
    cols = np.column_stack([u**k for k in range(order + 1)])
    scale = np.array([span**-k for k in range(order + 1)])
    nm = POLY_NAMES[: order + 1]
    lb = tuple(f"t^{k}" for k in range(order + 1))
    if not names:
        return BlockBase.from_dense(cols, nm, lb, scale)
    split = np.column_stack([cols * (chan == c)[:, None] for c in range(len(names))])
    return BlockBase.from_dense(
        split,
        tuple(f"{x}:{c}" for c in names for x in nm),
        tuple(f"{x}:{c}" for c in names for x in lb),
        np.tile(scale, len(names)),
    )


def base_design(base, t, t0: float, span: float, chan, names) -> BlockBase:
    """The base as a :class:`BlockBase` on all samples."""
    if isinstance(base, BlockBase):
        if base.block.size != t.size:
            raise ValidationError(f"base must cover {t.size} samples, got {base.block.size}")
        return base
    if isinstance(base, str):
        check_option("base", base, POLY_BASES)
        return poly_base(int(base[-1]), t, t0, span, chan, names)
    x = np.asarray(base, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != t.size:
        raise ValidationError(f"base design must have shape ({t.size}, p), got {x.shape}")
    p = x.shape[1]
    return BlockBase.from_dense(
        x, tuple(f"b{j}" for j in range(p)), tuple(f"base{j}" for j in range(p))
    )


def check_channels(t_all, channel, channel_names):
    if channel is None:
        if t_all.size > 1 and not np.all(np.diff(t_all) > 0):
            raise ValidationError("sample times must be strictly increasing")
        if channel_names:
            raise ValidationError("channel_names given without channel")
        return None, ()
    ch = np.asarray(channel)
    if ch.shape != t_all.shape or not np.issubdtype(ch.dtype, np.integer):
        raise ValidationError(
            f"channel must be integers of shape {t_all.shape}, got {ch.dtype} {ch.shape}"
        )
    ch = ch.astype(np.int64)
    n_ch = int(ch.max()) + 1 if ch.size else 1
    if ch.min(initial=0) < 0 or np.unique(ch).size != n_ch:
        raise ValidationError(f"channel must use every index 0 .. {n_ch - 1}")
    if t_all.size > 1 and not np.all(np.diff(t_all) >= 0):
        raise ValidationError("sample times must be non-decreasing")
    for c in range(n_ch):
        tc = t_all[ch == c]
        if tc.size > 1 and not np.all(np.diff(tc) > 0):
            raise ValidationError(f"sample times of channel {c} must be strictly increasing")
    names = (
        tuple(channel_names) if channel_names is not None else tuple(str(c) for c in range(n_ch))
    )
    if len(names) != n_ch:
        raise ValidationError(f"channel_names must have {n_ch} entries, got {len(names)}")
    if n_ch == 1:
        return None, ()
    return ch, names


def screen_channels(
    aux: dict[str, NDArray[np.float64]],
    y: NDArray[np.float64],
    use: NDArray[np.bool_],
    reference: NDArray[np.float64] | None = None,
) -> tuple[dict[str, NDArray[np.float64]], list[dict[str, Any]]]:
    """The channels a coupling may be tested to, and what became of each.

    Left out, with the reason: a channel covering under :data:`MIN_COVERAGE` of the
    used samples, a constant one, and one collinear with the data or the reference
    (``|corr| >`` :data:`SELF_CORRELATION` over the used samples): the target against
    itself (a table passed as its own ``--aux``) would "explain" everything.
    """
    kept, report = {}, []
    for name, x in aux.items():
        xu = x[use]
        ok = np.isfinite(xu)
        if ok.mean() < MIN_COVERAGE:
            report.append(
                {"channel": name, "status": "left out", "reason": f"covers {ok.mean():.0%}"}
            )
            continue
        if np.ptp(xu[ok]) == 0:
            report.append({"channel": name, "status": "left out", "reason": "constant"})
            continue
        why = ""
        for other, label in ((y, "the data"), (reference, "the reference")):
            if other is None:
                continue
            o = other[use][ok]
            if np.ptp(o) == 0:
                continue
            rho = float(np.corrcoef(xu[ok], o)[0, 1])
            if abs(rho) > SELF_CORRELATION:
                why = f"collinear with {label} (|r| = {abs(rho):.4f}): derived from it"
        if why:
            report.append({"channel": name, "status": "left out", "reason": why})
            continue
        kept[name] = x
        report.append({"channel": name, "status": "considered", "reason": ""})
    return kept, report


def angular_about_offset(
    aux: dict[str, NDArray[np.float64]], use: NDArray[np.bool_], units: dict[str, str]
) -> dict[str, NDArray[np.float64]]:
    """``aux`` with each angular acceleration less its mean over the used samples.

    A coupling ``c·x`` enters as given (the bias is the one at channel value 0), but
    an angular-acceleration channel's value 0 is not zero angular acceleration: the
    Level-1B ``ang_accl`` of the real GRACE-A 2003-09-14 sample average 3.3e-4,
    −3.9e-5 and −2.9e-4 rad/s², which over a day would spin the satellite up by tens of
    rad/s.  That mean is the angular channel's own offset; the true mean angular
    acceleration of a day is ``Δω/T`` ≈ 0.  Referred to it, a lever-arm coupling (real
    or not) leaves the bias alone instead of moving it by ``c`` times the offset (a QA
    thruster day: a false coupling of 4e-4 m per rad/s² moved the z bias 5.5σ, 1.2e-7
    m/s², 2026-11-29).  Other channels are left as given.
    """
    out = dict(aux)
    for name, x in aux.items():
        if unit_class(units.get(name, "")) != "angular":
            continue
        x = np.asarray(x, dtype=np.float64)
        ok = use & np.isfinite(x)
        if ok.any():
            out[name] = x - float(np.mean(x[ok]))
    return out


def check_inputs(t, y, valid, reference, aux, channel, channel_names):
    """``close_loop``'s arrays checked: (t, y, channel, names, use, reference, aux)."""
    t_all = np.asarray(t, dtype=np.float64)
    y_all = np.asarray(y, dtype=np.float64)
    if t_all.ndim != 1 or y_all.shape != t_all.shape:
        raise ValidationError(
            f"t and y must be 1-D of equal length, got {t_all.shape}, {y_all.shape}"
        )
    chan_all, names = check_channels(t_all, channel, channel_names)
    use = np.isfinite(y_all) & np.isfinite(t_all)
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != t_all.shape:
            raise ValidationError(f"valid must have shape {t_all.shape}, got {v.shape}")
        use &= v
    if use.sum() < MIN_SAMPLES:
        raise ValidationError(f"need at least {MIN_SAMPLES} usable samples, got {int(use.sum())}")
    ref_all = None
    if reference is not None:
        ref_all = np.asarray(reference, dtype=np.float64)
        if ref_all.shape != t_all.shape:
            raise ValidationError(f"reference must have shape {t_all.shape}, got {ref_all.shape}")
        use &= np.isfinite(ref_all)
    aux_all = _series_like(aux, t_all, "auxiliary channel")
    return t_all, y_all, chan_all, names, use, ref_all, aux_all


def check_proxies(proxies, t_all) -> dict[str, NDArray[np.float64]]:
    """``signal_proxies`` of :func:`close_loop` as float arrays of the data's shape."""
    return {str(k): a for k, a in _series_like(proxies, t_all, "signal proxy").items()}


def _series_like(series, t_all, what: str) -> dict:
    """Each series of the mapping as a float array, which must have ``t_all``'s shape."""
    out = {}
    for k, v in (series or {}).items():
        a = np.asarray(v, dtype=np.float64)
        if a.shape != t_all.shape:
            raise ValidationError(f"{what} {k!r} must have shape {t_all.shape}, got {a.shape}")
        out[k] = a
    return out


def usable_proxies(proxies, use, notes) -> SignalProxies | None:
    """The ``signal_proxies`` finite on every used sample (None: none); notes the others."""
    cols, names = [], []
    for k, a in proxies.items():
        if not np.all(np.isfinite(a[use])):
            text = f"signal proxy {k} left out: not finite on every used sample"
            notes[("closure", None, text)] = {"name": "closure", "channel": k, "note": text}
            continue
        cols.append(a)
        names.append(str(k))
    if not cols:
        return None
    return SignalProxies(np.column_stack(cols), tuple(names))


def with_caller_notes(
    screened: Sequence[dict[str, Any]], considered: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """The caller's verdicts (``screened``) followed by :func:`screen_channels`'s.

    An entry of ``screened`` with status ``"considered"`` is the caller's note on a
    channel it offers (e.g. how it was filtered): it becomes the reason of that
    channel's own entry when the screen kept the channel, and is not listed twice.
    """
    said = {d["channel"]: d["reason"] for d in screened if d.get("status") == "considered"}
    own = [d for d in screened if d.get("status") != "considered"]
    return own + [
        {**d, "reason": said[d["channel"]]}
        if d["status"] == "considered" and said.get(d["channel"])
        else d
        for d in considered
    ]


def prepared_inputs(
    t, y, valid, reference, aux, channel, channel_names, signal_proxies, screened, opts
) -> tuple:
    """``close_loop``'s inputs checked and prepared: ``(t, y, channel, names, use,
    reference, aux, proxies, considered)`` on all samples (:func:`check_inputs`,
    :func:`check_proxies`; the channels screened, :func:`screen_channels`, with the
    caller's notes; angular accelerations about their offset,
    :func:`angular_about_offset`).  ``opts``: the search options, whose
    ``"channel_units"`` type the channels and whose ``"firings"`` mask (if any) must
    have ``t``'s shape."""
    t_all, y_all, chan_all, names, use, ref_all, aux_all = check_inputs(
        t, y, valid, reference, aux, channel, channel_names
    )
    proxies_all = check_proxies(signal_proxies, t_all)
    aux_all, considered = screen_channels(aux_all, y_all, use, ref_all)
    considered = with_caller_notes(screened, considered)
    aux_all = angular_about_offset(aux_all, use, opts.get("channel_units", {}))
    firings = opts.get("firings")
    if firings is not None and np.shape(firings) != t_all.shape:
        raise ValidationError(
            f"options['firings'] must have shape {t_all.shape}, got {np.shape(firings)}"
        )
    return t_all, y_all, chan_all, names, use, ref_all, aux_all, proxies_all, considered
