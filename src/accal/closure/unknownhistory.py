"""Couplings whose channel's history is unknown at used samples: search again without them.

A lagged or low-passed channel is unknown before the record and after its holes (its
regressor there holds the first or last value): the samples there are fitted with a
made-up regressor (QA: a 1000 s lag, its coefficient 7σ off; after a resampled gap,
false steps).  The selection pauses at the first coupling with such samples
(:func:`unknown_pause`), searches again from the start without them
(:func:`without_unknown_history`; when they are at most :data:`CONTINUE_SHARE` of the
samples, from the first search's model, :func:`_continue_from`) and keeps that search
when it finds the coupling again.  Otherwise the first search goes on with the
coupling (its first one: fewer samples can lose a real coupling, a GRACE day at 1e-9
m/s²/K in closure-detection) and pauses at the next such coupling, which must be found
again without every coupling's made-up samples or is rejected
(:func:`reject_unconfirmed`): a later coupling can be fitting the misfit that the
first one's made-up samples leave.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from accal.closure.channelfault import mark_faults
from accal.closure.inputs import MIN_SAMPLES
from accal.closure.madeup import coupling_firings, made_up
from accal.closure.search import Found, augmented, run, swap_smooth

if TYPE_CHECKING:  # annotations only
    from accal.closure.search import Search

__all__ = [
    "UNKNOWN_DEPTH",
    "fired",
    "reject_unconfirmed",
    "unknown_history",
    "new_unknown",
    "pause_at",
    "unknown_pause",
    "without_unknown_history",
]

#: Searches again at most this many times for couplings found only without the samples
#: an earlier coupling's unknown history left out.
UNKNOWN_DEPTH = 3

#: Made-up samples at most this share of the used ones: the search without them goes
#: on from the first one's model (:func:`_continue_from`) instead of starting over.
CONTINUE_SHARE = 0.01


class Unknown(NamedTuple):
    """Samples where accepted couplings' channels are unknown (:func:`unknown_history`)."""

    mask: NDArray[np.bool_]
    lead: float
    channels: set


def _regions(
    search: Search, t_all: NDArray[np.float64], skip=frozenset()
) -> list[tuple[Found, NDArray, float]]:
    """``(effect, mask, lead)`` of every accepted coupling with an unknown history (but
    those in ``skip``): :func:`accal.closure.madeup.made_up`."""
    out = []
    for f in search.found:
        if f.prop.name != "auxiliary" or f in skip:
            continue
        hit = made_up(search, f, t_all)
        if hit is not None:
            out.append((f, *hit))
    return out


def unknown_history(search: Search, t_all: NDArray[np.float64], skip=frozenset()) -> Unknown | None:
    """Samples where an accepted coupling's lagged, filtered channel is not known
    (:func:`_regions`, all couplings but ``skip`` together); None when none of them is
    used."""
    regions = _regions(search, t_all, skip)
    if not regions:
        return None
    mask = np.logical_or.reduce([m for _, m, _ in regions])
    if not (mask & search.use).any():
        return None
    return Unknown(
        mask, max(lead for _, _, lead in regions), {f.prop.channel for f, _, _ in regions}
    )


def unknown_pause(s: Search, skip=frozenset()) -> bool:
    """Whether ``s`` holds a coupling (not in ``skip``) whose channel's history is
    unknown at a used sample."""
    return unknown_history(s, s.t_all, skip) is not None


def pause_at(s: Search, skip=frozenset()) -> bool:
    """The selection's pause: a coupling (not in ``skip``) whose channel the data do
    not follow over a stretch (:func:`accal.closure.channelfault.mark_faults` marks the
    channel unknown there), or whose channel's history is unknown at a used sample
    (:func:`unknown_pause`)."""
    return mark_faults(s, skip) or unknown_pause(s, skip)


def new_unknown(search: Search, skip) -> list[Found]:
    """The couplings not in ``skip`` whose channel's history is unknown at used samples."""
    return [f for f, m, _ in _regions(search, search.t_all, skip) if (m & search.use).any()]


def without_unknown_history(
    search, use, setup, make, max_effects, stop, depth: int = 0, skip=frozenset()
):
    """The search again without the samples a coupled channel's history is unknown at.

    Returns ``(search, st)`` of the second search when it keeps the couplings (but
    those in ``skip``, kept in ``search`` unconfirmed), else None (``search`` stands;
    :func:`reject_unconfirmed` is the caller's).  ``search``
    may be paused at the coupling (:func:`~accal.closure.search.run`'s ``until``): the
    second search is a whole one from the start, so the first one's remaining steps
    are not needed for it (a platform coupling run: one selection step of ~1.2 s
    saved); when the made-up samples are at most :data:`CONTINUE_SHARE` of the used
    ones it starts from the first one's model instead (:func:`_continue_from`).  A
    coupling the second search finds with samples of its own unknown is searched for
    again the same way, at most :data:`UNKNOWN_DEPTH` times; not
    confirmed so, it stays in the second search, as the first coupling of a search
    does (rejecting it there, the first search went on and took the made-up start of
    a 2,000 s lag and 1,500 s low-pass for a 10σ step: ``test_close_loop.py``).
    """
    if unknown_history(search, search.t_all, skip) is None:
        return None
    unknown = unknown_history(search, search.t_all)  # every coupling's made-up samples
    if unknown is None or int((use & ~unknown.mask).sum()) < MIN_SAMPLES:
        return None
    lead = unknown.lead
    coupled = {f.prop.channel for f in new_unknown(search, skip)}
    use2 = use & ~unknown.mask
    share = int((use & unknown.mask).sum()) / max(int(use.sum()), 1)
    search.drop_caches()  # memory for the second search (rebuilt if this one is kept)
    st2 = setup.build(use2)
    again = make(st2, use2)
    if share <= CONTINUE_SHARE and not _continue_from(again, search, coupled):
        return None
    # another coupling with an unknown history among the samples left: the same again
    run(again, max_effects, stop, until=pause_at if depth + 1 < UNKNOWN_DEPTH else None)
    deeper = None
    if again.paused:
        deeper = without_unknown_history(again, use2, setup, make, max_effects, stop, depth + 1)
        if deeper is None:  # its first coupling stays, as in the first search
            run(again, max_effects, stop)
    if deeper is not None:
        again, st2 = deeper
    else:
        swap_smooth(again)
    kept = {f.prop.channel for f in again.found if f.prop.name == "auxiliary"}
    if not coupled <= kept:
        return None
    fire = _firing_mask(search, skip) & use
    n_hole = int((use & unknown.mask & ~fire).sum())
    why = []
    if n_hole:
        why.append(
            f"{n_hole} where the lagged and filtered values reach before the channel's "
            f"start or a hole (the first {lead:.0f} s and after holes): unknown there"
        )
    if fire.any():
        why.append(
            f"{int(fire.sum())} within the known thruster firings, where each thruster "
            "moves the linear and angular accelerations at its own ratio (no lever arm)"
        )
    again.note(
        "auxiliary",
        None,
        f"{int((use & unknown.mask).sum())} samples left out of the analysis for the "
        f"coupled channel(s) {', '.join(sorted(coupled))}: {'; '.join(why)}",
        {"left_out": lead, "left_out_firings": int(fire.sum())},
    )
    return again, st2


def fired(search: Search, f: Found) -> bool:
    """Whether coupling ``f`` is to an angular acceleration whose known thruster firings
    reach used samples (:func:`accal.closure.madeup.coupling_firings`).  Such a coupling
    not found again without them is rejected even when it is a search's first: at a
    firing each thruster moves the linear and angular accelerations at its own ratio,
    real accelerations that are no lever arm, not a history nobody could know (a clean
    QA thruster day, 2026-11-29: a y coupling of 4.0e-4 ± 6.1e-5 m to ``ang_accl_y`` at a
    7.4 s lag, which a lever arm does not have, was kept unconfirmed and removed)."""
    hit = coupling_firings(search, f)
    return hit is not None and bool((hit & search.use).any())


def _firing_mask(search: Search, skip) -> NDArray[np.bool_]:
    """The samples the known thruster firings take from the accepted couplings (not in
    ``skip``) to an angular acceleration (:func:`accal.closure.madeup.coupling_firings`)."""
    out = np.zeros(search.t_all.size, dtype=bool)
    for f in search.found:
        hit = None if f in skip else coupling_firings(search, f)
        if hit is not None:
            out |= hit
    return out


def _continue_from(again: Search, search: Search, coupled: set) -> bool:
    """Start ``again`` (the samples without the made-up ones) from ``search``'s model:
    its effects re-tested there, the least significant dropped while one is not
    (:meth:`~accal.closure.search.Search.eliminate`); whether the couplings to the
    ``coupled`` channels (those to confirm) are kept.

    Used when the made-up samples are at most :data:`CONTINUE_SHARE` of the used
    ones.  The effects found before the coupling never saw its made-up regressor, and
    the coupling's lag and low-pass were searched with at most 1 % of their samples
    made up; what must be confirmed is the evidence, which is tested here on the
    samples left, with the coupling's multiplicity (its whole lag search).  A platform
    run with a 3e-8 m/s²/K coupling at a 23 s lag (23 samples made up): one
    selection step of ~1.1 s saved (``make bench-closure``).  The rejected and
    eliminated candidates carry over (their verdicts do not hinge on 1 % of the
    samples), and so does the step count.
    """
    basis = again.basis0
    for f in search.found:
        g = Found(f.prop, f.p_adj, f.verdict, f.stat, member=f.member)
        if f.aug is not None:
            g.aug = augmented(f.prop, again, basis)
        again.found.append(g)
        basis = again.state(again.found)[0]
    again.rejected.extend(search.rejected)
    again.removed.extend(search.removed)
    again.notes.update(search.notes)
    again.iterations = search.iterations
    again.eliminate(n_new=2)  # every effect re-tested, the last one too
    return coupled <= {f.prop.channel for f in again.found if f.prop.name == "auxiliary"}


def reject_unconfirmed(search: Search, skip=frozenset()) -> None:
    """Move the couplings (not in ``skip``) whose channel's history is unknown at used
    samples from the model to the rejected ones (in place; the search goes on from the
    model without them).

    The search without those samples (:func:`without_unknown_history`) did not find
    them: their evidence rests on samples where a lagged, filtered channel was made
    up, theirs or an earlier coupling's.  On a platform run with a 3e-7 m/s²/K
    coupling through a 200 s low-pass at 400 s (p_adj 2e-5 with its made-up samples,
    0.024 without; kept, as the first coupling of a search is) the search went on and
    added the square of the channel at a 3,173 s lag, made up over its first 3,173 s
    and never searched again without them (before 2026-11-28).
    """
    hit = [(f, m) for f, m, _ in _regions(search, search.t_all, skip) if (m & search.use).any()]
    if not hit:
        return
    out = {id(f): int((m & search.use).sum()) for f, m in hit}
    keep = []
    for f in search.found:
        if id(f) not in out:
            keep.append(f)
            continue
        why = (
            f"not confirmed without the {out[id(f)]} samples where its lagged and filtered "
            "channel is unknown or a known thruster firing reaches it (the search "
            "without them did not find it)"
        )
        verdict = dataclasses.replace(f.verdict, ok=False, reason=why)
        search.rejected.append(dataclasses.replace(f, verdict=verdict))
    search.found[:] = keep
