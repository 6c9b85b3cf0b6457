"""A coupled channel the data do not follow over a stretch: the channel is unknown there.

A housekeeping channel can be wrong where the accelerometer is not: a thermistor's
glitch or its settling after switch-on puts a bump in the channel that the
acceleration never saw.  A coupling fitted to the whole record then predicts a
response the data do not have, and the search explains that misfit with whatever fits
it: QA's platform runs with a 0.5 K spike or a 0.5 K settling ramp in a temperature's
first 600 s (3e-8 m/s²/K at 700 s) had the coupling found, then the channel's square,
a bias step and an exponential drift removed from the calibrated series, and per-period
errors 10× those of the same runs with the sensor clean (2026-11-28).

Right after a search adds a coupling, :func:`find_fault` asks whether its coefficient
changes over one stretch of the record, the data following the channel *less* there.
The model of a stretch ``W``: the coupling's column with the rest of the model
projected out, ``z̃``, centred on ``W`` and zero outside, with ``W``'s own offset free
(a fault has its own level; uncentred, the window's column carried the channel's level
there, and a glitch on a cold stretch came out as the data following the channel
*more*).  Its coefficient ``δ`` is a local change of the coupling, relative to the
coupling outside ``W`` (:func:`_relative`): ``−1`` where the data do not follow the
channel at all.  Every window between :data:`FAULT_NODES` equally spaced nodes, up to
:data:`FAULT_MAX_SHARE` of the record, is ranked by its white-noise explained power
(cumulative sums, all windows at once) among those whose relative change is a fault's
(:func:`_fault_like`); the best is tested like any candidate (the coloured-noise Wald
test of :func:`accal.closure.significance.test_proposal`) with the number of windows
as its multiplicity (Bonferroni), at the search's ``alpha``, and its relative change
checked again with the test's covariance.  The stretch is then widened over the
neighbouring nodes whose residual is loud (:func:`_grown`: the glitch's tails).

A significant stretch is not an effect: nothing is removed for it.  The channel is
taken as unknown over the stretch less the lag (:func:`mark_faults` sets it NaN there),
and the samples whose lagged, filtered channel reaches it are left out of the
analysis like those before the channel's first value
(:mod:`accal.closure.unknownhistory`): the search runs again without them and must
find the coupling again.  At most :data:`MAX_FAULTS` stretches per channel are taken
out, and none that would leave out more than :data:`FAULT_MAX_SHARE` of the record
with the ones before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from accal.closure.candidates import Proposal
from accal.closure.madeup import made_up
from accal.closure.significance import test_proposal

if TYPE_CHECKING:  # annotations only
    from accal.closure.search import Found, Search

__all__ = [
    "FAULT_MAX_SHARE",
    "FAULT_NODES",
    "MAX_FAULTS",
    "Fault",
    "fault_notes",
    "faulted",
    "find_fault",
    "mark_faults",
]

#: Window edges over the record (a day: 120 s apart); at least 5 samples apart.
FAULT_NODES = 720
#: Longest stretch, and the most of the record all of a channel's stretches may cover.
FAULT_MAX_SHARE = 0.25
#: Largest relative change of the coefficient in a stretch that is a fault: the data
#: follow at most half of the channel's variation there (QA's glitches: −1.03; a
#: coupling fitted to 3e-3 relative precision changed by 1-3 % of itself over hours
#: of clean-sensor runs, significant at p ~1e-11 but not a fault).
FAULT_CHANGE = -0.5
#: Smallest relative change of a fault, and how far below it (in σ) one may lie
#: (:func:`_fault_like`): a faulty channel is not followed (−1), its coupling's fitted
#: lag and shape let the misfit come out somewhat beyond (QA glitches: −0.71 to −1.03).
FAULT_FLOOR = -1.5
FAULT_SIGMAS = 2.0
#: A node next to a fault's window whose mean squared residual is this many times the
#: median node's joins the stretch (:func:`_grown`).
GROW_RATIO = 2.0
#: Most stretches taken out of one channel.
MAX_FAULTS = 3
#: Key of :class:`Fault` records in a search's ``options`` (shared by the searches of
#: one closure, so that a search started again knows the faults found before).
OPTION_KEY = "channel_faults"


@dataclass(frozen=True)
class Fault:
    """A stretch where the data do not follow a coupled channel.

    ``start``/``stop`` are data times [s]; the channel is unknown over them less
    ``lag``.  ``change`` is the fitted local change of the coefficient relative to
    the coupling's (−1: the data do not follow the channel at all there), per data
    channel; ``p_adj`` the test's p-value times ``n_windows``; ``t0`` the record's
    first sample time [s] (the note says how far into the record the stretch is when
    the time scale does not start at 0, e.g. GPS seconds).
    """

    channel: str
    start: float
    stop: float
    lag: float
    change: tuple[float, ...]
    p_adj: float
    n_windows: int
    t0: float = 0.0

    def _when(self, a: float, b: float) -> str:
        """``a-b s``, and how far into the record when its time scale does not start at 0."""
        into = f" ({a - self.t0:.0f}-{b - self.t0:.0f} s into the record)" if self.t0 else ""
        return f"{a:.0f}-{b:.0f} s{into}"

    def note(self) -> dict[str, Any]:
        """The closure note of this fault."""
        ch = ", ".join(f"{v:+.2f}" for v in self.change)
        text = (
            f"channel {self.channel} is taken as unknown over "
            f"{self._when(self.start - self.lag, self.stop - self.lag)}: the data at "
            f"{self._when(self.start, self.stop)} do not follow it as the rest of the record "
            f"does (coupling coefficient changed by {ch} of itself there, p "
            f"{self.p_adj:.2g} over {self.n_windows} stretches tried): a fault of the "
            "channel, not of the data; the samples it reaches are left out"
        )
        details = {
            "fault_start": self.start,
            "fault_stop": self.stop,
            "lag": self.lag,
            "relative_change": list(self.change),
            "p_value": self.p_adj,
            "stretches_tried": self.n_windows,
        }
        return {"name": "auxiliary", "channel": self.channel, "note": text, "details": details}


def faulted(options: dict[str, Any], channel: str | None) -> bool:
    """Whether a fault of ``channel`` is recorded in ``options`` (:data:`OPTION_KEY`)."""
    return any(f.channel == channel for f in options.get(OPTION_KEY, ()))


def fault_notes(options: dict[str, Any]) -> list[dict[str, Any]]:
    """The notes of the faults recorded in ``options`` (:data:`OPTION_KEY`)."""
    return [f.note() for f in options.get(OPTION_KEY, ())]


def _window_sums(t_u, masks, r, zt, n_nodes):
    """Per-node cumulative sums over each data channel's samples (``masks``, the
    coupling's column ``k`` lives on channel ``k``): ``edges`` (K+1,) and a dict of
    (K+1, q) arrays ``n``, ``r``, ``z``, ``zz``, ``rz`` (counts, Σr, Σz̃, Σz̃², Σrz̃)."""
    edges = np.linspace(t_u[0], t_u[-1], n_nodes + 1)
    edges[-1] = np.nextafter(edges[-1], np.inf)
    b = np.clip(np.searchsorted(edges, t_u, side="right") - 1, 0, n_nodes - 1)
    q = zt.shape[1]
    out = {key: np.zeros((n_nodes + 1, q)) for key in ("n", "r", "z", "zz", "rz", "rr")}
    for k in range(q):
        m = masks[k].astype(np.float64)
        zk = zt[:, k] * m
        for key, w in (
            ("n", m), ("r", r * m), ("z", zk), ("zz", zk * zk), ("rz", r * zk), ("rr", r * r * m)
        ):  # fmt: skip
            out[key][1:, k] = np.cumsum(np.bincount(b, w, minlength=n_nodes))
    return edges, out


def _grown(sums, i: int, length: int) -> tuple[int, int]:
    """``(first, stop)`` nodes of the window widened over the neighbouring nodes whose
    mean squared residual exceeds :data:`GROW_RATIO` times the median node's, at most
    the window's length on each side: a glitch's tails, where the data still miss
    what the channel says but too little of its variation is the glitch's for the
    window's test (a 1.5 K Gaussian glitch of σ 300 s left 5e-11 m/s² at 3σ, and a
    pair of steps took it, before 2026-11-29)."""
    n = np.diff(sums["n"].sum(axis=1))
    rr = np.diff(sums["rr"].sum(axis=1))
    mean = np.where(n > 0, rr / np.maximum(n, 1.0), np.nan)
    ref = float(np.nanmedian(mean)) if np.any(n > 0) else np.nan
    if not ref > 0:
        return i, i + length
    loud = mean > GROW_RATIO * ref  # NaN (no samples) stops the growth
    lo, hi = i, i + length
    while lo > max(i - length, 0) and loud[lo - 1]:
        lo -= 1
    while hi < min(i + 2 * length, n.size) and loud[hi]:
        hi += 1
    return lo, hi


def _in_window(c, i, length):
    """The sums of :func:`_window_sums` over windows of ``length`` nodes (from node
    ``i`` on, every ``i`` when ``i`` is None)."""
    if i is None:
        return {key: v[length:] - v[:-length] for key, v in c.items()}
    return {key: v[i + length] - v[i] for key, v in c.items()}


def _centred(w):
    """``(Σ r (z̃ − z̄_W), Σ (z̃ − z̄_W)², counts)`` of window sums ``w``: the column
    with its mean over the window out (the window's own offset is in the model)."""
    n = np.maximum(w["n"], 1.0)
    return w["rz"] - w["r"] * w["z"] / n, w["zz"] - w["z"] ** 2 / n, w["n"]


def _relative(delta, coef, den, frac):
    """The relative change of the coefficient in the window and its per-channel parts.

    Joint fit of the coupling ``c'`` (everywhere) and the window's ``δ`` (inside):
    the coupling alone fitted ``c = c' + δ·f`` with ``f = d/D`` the window's share of
    the column's information (``d = Σ_W (z̃ − z̄_W)²``, ``D = Σ z̃²``), so ``c' = c −
    δ·f`` and the change is ``δ/c'`` per data channel; combined, ``ρ = Σ_k δ_k c'_k
    d_k / Σ_k c'_k² d_k`` (each channel weighted by its information).  Returns ``(ρ,
    weights w_k = c'_k d_k / Σ c'² d, per-channel δ_k/c'_k)``; arrays broadcast over
    windows (last axis: data channels).
    """
    cp = coef - delta * frac
    info = np.maximum(np.sum(cp**2 * den, axis=-1, keepdims=True), 1e-300)
    w = cp * den / info
    per = delta / np.where(cp != 0, cp, 1.0)
    return np.sum(w * delta, axis=-1), w, per


def _best_window(c, coef, tot, longest, sigma2):
    """``(stat, first node, length, n_windows)`` of the window with the most white-noise
    explained power among those where the data follow the channel like a fault
    (:func:`_fault_like` of :func:`_relative`'s ``ρ`` with its white-noise σ)."""
    best = (0.0, 0, 0)
    n_win = 0
    for length in range(1, longest + 1):
        num, den, cnt = _centred(_in_window(c, None, length))
        n_win += num.shape[0]
        ok = (cnt >= 3) & (den > 1e-12 * tot) & (den < (1.0 - 1e-9) * tot)
        safe = np.where(ok, den, 1.0)
        frac = np.where(ok, safe / tot, 0.0)
        # (z̃ − z̄_W)·1_W with z̃ (in the model) projected out: ‖·‖² = d (1 − d/D)
        norm2 = safe * np.maximum(1.0 - frac, 1e-12)
        pw = np.where(ok, num**2 / norm2, 0.0)
        delta = np.where(ok, num / norm2, 0.0)
        rel, w, _ = _relative(delta, coef, np.where(ok, den, 0.0), frac)
        var = sigma2 * np.sum(np.where(ok, w**2 / norm2, 0.0), axis=-1)
        like = _fault_like(rel, np.sqrt(var)) & np.any(ok, axis=1)
        stat = np.where(like, pw.sum(axis=1), 0.0)
        i = int(np.argmax(stat))
        if stat[i] > best[0]:
            best = (float(stat[i]), i, length)
    return (*best, n_win)


def _fault_like(rel, sigma_rel):
    """Whether a relative change ``rel`` ± ``sigma_rel`` is a fault's: at most
    :data:`FAULT_CHANGE` (the data follow at most half the channel's variation), and
    not below :data:`FAULT_FLOOR` by more than :data:`FAULT_SIGMAS` σ (a faulty channel
    is not followed; data going against it, several times its coupling, are structure
    of another kind that happens to correlate with it over the stretch: a
    ``tests.indep`` platform run with a clean sensor had ρ = −7 to −10 over 2 minutes,
    p 4e-6 after the windows)."""
    return (rel <= FAULT_CHANGE) & (rel >= FAULT_FLOOR - FAULT_SIGMAS * sigma_rel)


def find_fault(search: Search, f: Found) -> Fault | None:
    """The stretch where the data follow coupling ``f``'s channel less than elsewhere,
    when significant at the search's ``alpha`` (module notes); None otherwise.

    The samples where the coupling's regressor is already made up
    (:func:`accal.closure.madeup.made_up`: the first lag of the record) are not
    scanned: the search leaves them out anyway, and a held channel is no fault.
    """
    use = search.use
    t_u = search.t_all[use]
    span = float(t_u[-1] - t_u[0])
    step = search.grid.step
    n_nodes = int(min(FAULT_NODES, np.floor(span / (5.0 * step))))
    longest = int(np.floor(FAULT_MAX_SHARE * n_nodes))
    if n_nodes < 8 or longest < 1:
        return None
    others = [g for g in search.found if g is not f]
    basis, fit, lev = search.state(search.found)
    basis_wo, fit_wo, _ = search.state(others)
    z = f.prop.columns[use]
    zt = z - basis_wo.project(z)
    nz = np.einsum("ij,ij->j", zt, zt)
    if not np.all(nz > 0):
        return None
    coef = (zt.T @ fit_wo.resid) / nz  # the coupling's coefficient per data channel
    hit = made_up(search, f, search.t_all)
    known = np.ones(t_u.size, dtype=bool) if hit is None else ~hit[0][use]
    masks = _column_channels(search, f, known)
    r_known = fit.resid[known]
    sigma2 = float(np.mean(r_known**2)) if r_known.size else 0.0
    edges, sums = _window_sums(t_u, masks, fit.resid, zt, n_nodes)
    stat, i, length, n_win = _best_window(sums, coef, nz, longest, sigma2)
    if not stat > 0:
        return None
    a, b = float(edges[i]), float(edges[i + length])
    inside = (t_u >= a) & (t_u < b)
    box = np.column_stack([inside & m for m in masks]).astype(np.float64)
    centre = _in_window(sums, i, length)
    v = box * (zt - centre["z"] / np.maximum(centre["n"], 1.0))
    with_box = basis.extend(box)  # the window's own offset per data channel
    cols = np.zeros((search.t_all.size, v.shape[1]))
    cols[use] = v
    labels = tuple(f"fault:{lb}" for lb in f.prop.labels)
    prop = Proposal("auxiliary", f.prop.channel, cols, labels, float(n_win))
    tested = test_proposal(search.grid, with_box, with_box.fit(search.y_u).resid, lev, prop, use, 1)
    if tested is None or not tested.p_adj < search.alpha:
        return None
    # the change per data channel and the combined one, with its coloured-noise σ
    # (the test's covariance of the window's coefficients δ_k)
    num, den, _ = _centred(centre)
    delta = _window_coefficients(tested, with_box, v)
    if delta is None:
        norm2 = np.maximum(den * (1.0 - den / nz), 1e-300)
        delta = (num / norm2, np.diag(sigma2 / norm2))
    rel, w, per = _relative(delta[0], coef, den, den / nz)
    if not _fault_like(rel, np.sqrt(max(float(w @ delta[1] @ w), 0.0))):
        return None
    change = tuple(float(v) for v in per)
    lo, hi = _grown(sums, i, length)
    inside = (t_u >= edges[lo]) & (t_u < edges[hi]) & known
    a, b = float(t_u[inside][0]), float(t_u[inside][-1]) + step  # [a, b)
    lag = f.prop.path[0]
    t0 = float(np.nanmin(search.t_all))  # the record's first sample
    return Fault(str(f.prop.channel), a, b, lag, change, float(tested.p_adj), int(n_win), t0)


def _column_channels(search: Search, f: Found, known) -> list:
    """Used-sample mask of the data channel each of ``f``'s columns lives on (all the
    used samples for one channel), the made-up samples (``~known``) out."""
    names = f.prop.axes
    if not names or search.chan_all is None:
        return [known.copy() for _ in range(f.prop.columns.shape[1])]
    ch = search.chan_all[search.use]
    return [known & (ch == list(search.names).index(a)) for a in names]


def _window_coefficients(tested, basis, v):
    """``(δ, cov δ)`` of the window's columns ``v`` (used samples) from the test: its
    coefficients ``γ`` are those of the orthonormal ``Q`` of ``P⊥v`` (the model
    projected out), ``P⊥v = Q R`` with ``R = QᵀP⊥v``, so ``δ = R⁻¹γ`` (None when a
    column was dropped as dependent)."""
    q = tested.zt
    if q.shape[1] != v.shape[1]:
        return None
    r = q.T @ (v - basis.project(v))
    try:
        r_inv = np.linalg.inv(r)
    except np.linalg.LinAlgError:
        return None
    return r_inv @ tested.wald.gamma, r_inv @ tested.wald.cov @ r_inv.T


def mark_faults(search: Search, skip=frozenset()) -> bool:
    """Look for a fault of each coupling the search holds (but those in ``skip``, the
    squares of channels, and those looked at before); mark the first one found: its
    channel NaN over the stretch less the lag (in ``search.aux``, shared by the
    searches of one closure) and the fault recorded in ``search.options``.  Whether
    one was marked (the caller then searches again without the samples it reaches,
    :mod:`accal.closure.unknownhistory`)."""
    faults = search.options.setdefault(OPTION_KEY, [])
    checked = search.cache.setdefault("faults checked", set())
    for f in search.found:
        name = str(f.prop.channel)
        if f.prop.name != "auxiliary" or f in skip or f.prop.squared:
            continue
        if f in checked or name not in search.aux:  # Found: compared by identity
            continue
        checked.add(f)
        mine = [g for g in faults if g.channel == name]
        if len(mine) >= MAX_FAULTS:
            continue
        fault = find_fault(search, f)
        if fault is None:
            continue
        t = search.t_all
        span = float(np.ptp(t[np.isfinite(t)])) or 1.0
        covered = sum(g.stop - g.start for g in mine) + fault.stop - fault.start
        if covered > FAULT_MAX_SHARE * span:
            continue
        x = np.array(search.aux[name], dtype=np.float64, copy=True)
        x[(t >= fault.start - fault.lag) & (t < fault.stop - fault.lag)] = np.nan
        search.aux[name] = x
        faults.append(fault)
        note = fault.note()
        search.note(note["name"], note["channel"], note["note"], note["details"])
        return True
    return False
