"""A level that comes back within the hour is a transient, not two bias steps.

Days drawn here with numpy (``white_noise_day``: bias, drift, white noise) and a
10-minute box of constant acceleration on one axis with 30 s ramps, like a manoeuvre's
thrust; QA's along-track manoeuvre of 3e-7 m/s² had been removed as two bias steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure import close_loop
from accal.closure.boxes import BOX_MAX, box_reasons, give_back

from .conftest import white_noise_day


def _box(t, start, length, size, ramp=30.0):
    up = np.clip((t - start) / ramp, 0.0, 1.0)
    down = np.clip((t - start - length) / ramp, 0.0, 1.0)
    return size * (up - down)


def _close(t, y):
    return close_loop(t, y, orbit_period=5600.0, candidates=("bias_step",),
                      options={"orbit_period_fixed": True, "step_transition": True})  # fmt: skip


@pytest.mark.parametrize("size", [3e-9, -2e-8])
def test_a_manoeuvre_is_not_removed_as_two_steps(size):
    t, y = white_noise_day(31)
    y = y + _box(t - t[0], 45000.0, 600.0, size)
    res = _close(t, y)
    assert not [e for e in res.effects if e.name == "bias_step"], res.effects
    boxes = [e for e in res.rejected if "a box" in e.details.get("reason", "")]
    assert len(boxes) == 2
    assert sorted(np.sign(e.coefficient) for e in boxes) == [-1.0, 1.0]


def test_a_lasting_step_beside_a_smaller_return_is_kept():
    """A 2e-9 step and, 20 min later, a −5e-10 one (a quarter: no box): both removed."""
    t, y = white_noise_day(32)
    tt = t - t[0]
    y = y + 2e-9 * (tt >= 40000.0) - 5e-10 * (tt >= 41200.0)
    res = _close(t, y)
    steps = sorted(e.epoch - t[0] for e in res.effects if e.name == "bias_step")
    assert len(steps) == 2 and abs(steps[0] - 40000.0) < 60 and abs(steps[1] - 41200.0) < 60


def test_box_rule():
    assert box_reasons([(0.0, 1.0, 0), (600.0, -0.6, 1)]).keys() == {0, 1}
    assert box_reasons([(0.0, 1.0, 0), (600.0, -0.4, 1)]) == {}  # under half
    assert box_reasons([(0.0, 1.0, 0), (600.0, 1.0, 1)]) == {}  # same sign: a staircase
    assert box_reasons([(0.0, 1.0, 0), (BOX_MAX + 1.0, -1.0, 1)]) == {}  # too far apart


class _Search:
    """The parts of a search that :func:`give_back` uses."""

    def __init__(self, found):
        self.found, self.rejected, self.notes = list(found), [], []

    def note(self, name, channel, text):
        self.notes.append(text)


def test_a_step_that_gives_a_jump_back_is_no_step_and_the_jump_goes_back():
    """QA (an outside generator): a −4.19e-9 m/s² edge-scan jump and a +3.90e-9
    least-squares step at the same epoch, two orbits after a real 2e-8 step, were both
    removed.  The pair is a box of no width: the step is rejected and the jump dropped;
    the real step and a jump with no step at its epoch stay."""
    from types import SimpleNamespace

    from accal.closure.candidates import Proposal
    from accal.closure.jumps import Jump
    from accal.closure.search import Found
    from accal.closure.validation import Verdict

    t = np.arange(100_000.0)

    def step(epoch):
        col = (t >= epoch).astype(float)[:, None]
        return Proposal("bias_step", None, col, (f"step@{epoch!r}",), 1.0, {"epoch": epoch})

    def jump(epoch, size):
        return Jump(epoch, size, 7e-10, 1e-6, size, 9e-10, 100.0, 120.0, 80_000)

    final = [
        Found(step(68_300.0), 1e-9, Verdict(True, "", 1.0)),
        Found(step(79_615.0), 1e-6, Verdict(True, "", 1.0)),
    ]
    fit = SimpleNamespace(gamma=np.array([2.02e-8, 3.9e-9]))
    jumps = (jump(79_600.0, -4.19e-9), jump(30_000.0, -4e-9))
    search = _Search(final)
    kept = give_back(search, final, fit, jumps)
    assert kept == (jumps[1],)
    assert [f.prop.params["epoch"] for f in search.found] == [68_300.0]
    (rej,) = search.rejected
    assert not rej.verdict.ok and "gives back the edge-scan jump" in rej.verdict.reason
    assert len(search.notes) == 1 and "gave it back" in search.notes[0]
    # of the same sign, or under half the jump's size, the step is a step of its own
    for size in (-4e-9, 1.5e-9):
        search = _Search(final)
        fit = SimpleNamespace(gamma=np.array([2.02e-8, size]))
        assert give_back(search, final, fit, jumps) == jumps and not search.rejected
