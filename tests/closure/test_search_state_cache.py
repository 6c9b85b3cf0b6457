"""The search's cache of model states must not be fooled by reused object ids.

CI (2026-11-28): ``accal diagnose`` on a platform run dropped a 30σ bias step or a
29σ temperature coupling on about one run in eight, depending only on where Python
put its objects.  The cache of model states was keyed by ``id()`` of the effects; the
final fit makes new copies of the effects, and a copy at the address of a freed
effect got the cached model of another effect set (one that already held it): its
test had nothing left to test, p = 1, and backward elimination removed it.
"""

from __future__ import annotations

import gc
import weakref

import numpy as np

from accal.closure.basis import Basis
from accal.closure.candidates import Proposal
from accal.closure.noise_psd import make_grid
from accal.closure.search import Found, Search
from accal.closure.validation import Verdict


def _search(n: int = 400) -> Search:
    t = np.arange(n, dtype=float)
    rng = np.random.default_rng(0)
    return Search(
        grid=make_grid(t),
        t_all=t,
        use=np.ones(n, dtype=bool),
        t0=0.0,
        span=float(n),
        y_u=rng.normal(size=n),
        basis0=Basis(np.zeros(n, dtype=np.int64), np.ones((n, 1))),
        bias0=None,
        signal0=None,
        builders=[],
        n_families=1,
        alpha=0.01,
        options={},
        aux={},
        orbit_period=None,
        base_labels=frozenset(),
    )


def _prop(col: np.ndarray, name: str) -> Proposal:
    return Proposal(name, None, col[:, None], (name,))


def test_state_of_a_new_effect_at_a_reused_id_is_its_own(monkeypatch):
    """Every effect gets the same id, as a copy at a freed effect's address does (the
    cache was keyed by ids; it is keyed by the effects now, which this must not see)."""
    import accal.closure.search as search_module

    monkeypatch.setattr(search_module, "id", lambda obj: 1, raising=False)
    s = _search()
    t = s.t_all
    step, ramp = (t >= 200.0).astype(float), (t - t.mean()) / t.size
    verdict = Verdict(True, "", 1.0)
    s.state([Found(_prop(step, "bias_step"), 0.0, verdict)])
    basis, fit, _ = s.state([Found(_prop(ramp, "linear_drift"), 0.0, verdict)])
    # the model holds the ramp: its fit leaves no ramp in the residual
    assert abs(float(fit.resid @ ramp)) < 1e-10 * np.linalg.norm(ramp)
    # and not the step: the step is still testable on top of it
    assert basis.complement(step[:, None]).shape[1] == 1


def test_state_cache_keeps_its_effects_alive():
    """While a state is cached its effects live, so no other effect can take their ids."""
    s = _search()
    f = Found(_prop((s.t_all >= 100.0).astype(float), "bias_step"), 0.0, Verdict(True, "", 1.0))
    s.state([f])
    ref = weakref.ref(f)
    del f
    gc.collect()
    assert ref() is not None


def test_state_is_cached_for_the_same_effects():
    s = _search()
    f = Found(_prop((s.t_all >= 100.0).astype(float), "bias_step"), 0.0, Verdict(True, "", 1.0))
    first = s.state([f])
    assert all(a is b for a, b in zip(s.state([f]), first, strict=True))
