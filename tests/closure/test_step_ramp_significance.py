"""A bias step is kept for its edge, not for its ramp's columns (Search.p_final).

QA (2026-11-29, an outside generator's clean GRACE day, AR(1) noise and thruster
firings): a "step" of −5.2e-10 ± 5.4e-10 m/s² whose epoch could be anywhere in the
day was removed from the calibrated series with p 0: the local columns of its ramp
(accal.closure.transition) had taken up a firing's remnant at the epoch, and the final
elimination tested them together with the step.  The data are drawn here.
"""

from __future__ import annotations

import numpy as np

from accal.closure.basis import Basis
from accal.closure.candidates import Proposal
from accal.closure.final import with_jacobian
from accal.closure.noise_psd import make_grid
from accal.closure.search import Found, Search
from accal.closure.select import _final_effects
from accal.closure.validation import Verdict

N, EPOCH = 4_000, 2_000.0


def _search(y: np.ndarray) -> Search:
    t = np.arange(y.size, dtype=float)
    return Search(
        grid=make_grid(t), t_all=t, use=np.ones(y.size, dtype=bool), t0=0.0,
        span=float(y.size), y_u=y, basis0=Basis(np.zeros(y.size, dtype=np.int64),
        np.column_stack([np.ones(y.size), t / y.size])), bias0=None, signal0=None,
        builders=[], n_families=1, alpha=0.01, options={}, aux={}, orbit_period=None,
        base_labels=frozenset(),
    )  # fmt: skip


def _ramped_step(s: Search) -> Found:
    col = (s.t_all >= EPOCH).astype(float)[:, None]
    prop = Proposal("bias_step", None, col, (f"step@{EPOCH!r}",), 1.0,
                    {"epoch": EPOCH, "transition": True})  # fmt: skip
    f = Found(prop, 1e-4, Verdict(True, "", 1.0))
    f.aug = with_jacobian(prop, s.t_all, 0.0, s.use, s.basis0)
    assert f.aug.columns.shape[1] > 1  # the ramp's local columns are there
    return f


def _day(seed: int, step: float, bump: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(N, dtype=float)
    y = 1e-10 * rng.standard_normal(N) + step * (t >= EPOCH)
    return y + bump * np.exp(-0.5 * ((t - EPOCH - 3.0) / 4.0) ** 2)  # a firing's remnant


def test_a_bump_at_the_epoch_does_not_keep_a_step():
    s = _search(_day(1, 0.0, 2e-9))
    s.found = [_ramped_step(s)]
    final = [Found(f.model_prop, f.p_adj, f.verdict) for f in s.found]
    # with its ramp's columns the "step" explains the bump ...
    assert s.p_without(0, final) < 1e-6
    # ... but the edge alone, given them, is nothing
    assert s.p_final(0, final) > 0.05
    assert _final_effects(s) == [] and s.found == [] and len(s.removed) == 1


def test_a_real_step_with_a_bump_is_kept():
    s = _search(_day(2, 1e-10, 2e-9))  # 1e-10 m/s² over 2,000 samples each side: ~30σ
    s.found = [_ramped_step(s)]
    final = [Found(f.model_prop, f.p_adj, f.verdict) for f in s.found]
    assert s.p_final(0, final) < 1e-6
    assert len(_final_effects(s)) == 1 and len(s.found) == 1
