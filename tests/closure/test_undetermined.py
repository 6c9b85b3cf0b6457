"""An effect the data do not determine is reported, not removed (QA, 2026-11-30).

A coupling selected with its lag and low-pass held can have a coefficient of any size
once they are free: on a QA helper's GRACE-FO day (thermostat heater, storm) y's
coupling came out −8.1e-8 ± 1.7e-6 m/s²/K and its removal made the calibrated y 3.2×
further from the truth than no closure.  The rule on objects built here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from accal.closure.candidates import Proposal
from accal.closure.results import Effect
from accal.closure.search import Found
from accal.closure.select import DETERMINED_SIGMAS, reject_undetermined
from accal.closure.validation import Verdict


def found(name: str) -> Found:
    prop = Proposal(name, "T", np.zeros((10, 1)), ("aux:T",), 1.0, {"lag": 100.0})
    return Found(prop, 1e-6, Verdict(ok=True, reason="", identifiability=1.0))


def effect(coef: float, sigma: float, instrument: bool = True) -> Effect:
    return Effect("auxiliary", "T", coef, sigma, 1e-6, instrument=instrument, unit="m/s^2/K")


def test_an_effect_within_its_sigma_of_zero_moves_to_the_rejected_with_its_reason():
    assert DETERMINED_SIGMAS == 1.0
    kept, lost, line = found("auxiliary"), found("auxiliary"), found("periodic")
    search = SimpleNamespace(found=[kept, lost, line], rejected=[])
    jump = effect(3e-9, 1e-10)  # a jump taken out before the search: never judged here
    res = SimpleNamespace(
        effects=(jump, effect(-3.7e-9, 2.2e-9), effect(-8.1e-8, 1.7e-6), effect(1e-12, 1.0, False))
    )
    assert reject_undetermined(search, res, n_jumps=1)
    assert search.found == [kept, line]  # a reported (non-instrument) term is not judged
    (r,) = search.rejected
    assert r.prop is lost.prop and not r.verdict.ok
    assert r.verdict.reason.startswith("not determined: -8.1e-08 ± 1.7e-06 m/s^2/K")
    assert "within 1σ of zero" in r.verdict.reason


def test_nothing_changes_when_every_effect_is_determined_or_the_lists_differ():
    search = SimpleNamespace(found=[found("auxiliary")], rejected=[])
    assert not reject_undetermined(search, SimpleNamespace(effects=(effect(5e-9, 1e-9),)), 0)
    assert not reject_undetermined(search, SimpleNamespace(effects=()), 0)
    assert len(search.found) == 1 and search.rejected == []
