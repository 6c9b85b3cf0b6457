"""Hypothesis properties of the seeds of ``accal simulate grace`` (accal.simulate.grace).

Without a seed, a simulated day's random draws depend on its date and satellite
(:func:`~accal.simulate.grace.default_seed`): different days get different noise,
the same day always the same file.  An explicit seed is used exactly as given.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.simulate.grace import STREAMS, default_seed, simulate_grace_day

dates = st.dates(dt.date(2002, 4, 1), dt.date(2030, 12, 31)).map(dt.date.isoformat)
satellites = st.sampled_from("ABCD")
DURATION = 200.0  # [s]: enough samples to tell two noise draws apart


def _noise(day) -> np.ndarray:
    """The simulated raw readings minus everything deterministic but the drift."""
    s = np.asarray(day.truth["scale_s"])
    return day.raw - s * day.true - np.asarray(day.truth["bias"])


@settings(max_examples=25, deadline=None)
@given(a=st.tuples(dates, satellites), b=st.tuples(dates, satellites))
def test_default_seed_differs_between_days_and_satellites(a, b):
    da = simulate_grace_day(date=a[0], satellite=a[1], duration=DURATION)
    db = simulate_grace_day(date=b[0], satellite=b[1], duration=DURATION)
    if a == b:
        assert np.array_equal(da.raw, db.raw) and da.truth == db.truth
    else:
        assert default_seed(*a) != default_seed(*b)
        assert not np.allclose(_noise(da), _noise(db), rtol=0, atol=1e-13)
        assert da.truth["drift"] != db.truth["drift"]
    assert da.truth["seed"] == default_seed(*a)


@settings(max_examples=25, deadline=None)
@given(a=st.tuples(dates, satellites), b=st.tuples(dates, satellites), seed=st.integers(0, 2**63))
def test_explicit_seed_is_exact(a, b, seed):
    """An explicit seed is the generator's seed, whatever the day: same draws on any date."""
    da = simulate_grace_day(date=a[0], satellite=a[1], duration=DURATION, seed=seed)
    db = simulate_grace_day(date=b[0], satellite=b[1], duration=DURATION, seed=seed)
    assert da.truth["seed"] == seed
    assert da.truth["drift"] == db.truth["drift"]  # its own stream, nothing date-dependent
    # the drift is the first draw of the day's "instrument" stream, [seed, 0]
    rng = np.random.default_rng([seed, STREAMS["instrument"]])
    assert da.truth["drift"] == rng.uniform(-5e-14, 5e-14, 3).tolist()
    # and the orbit stream does not depend on the date either
    assert da.truth["orbit_period"] == db.truth["orbit_period"]


def test_default_seed_is_stable():
    """Pinned: the seed of a (date, satellite) must not change between versions."""
    assert default_seed("2005-01-01", "A") == 5343762106077581989
    assert default_seed("2005-01-02", "A") == 3475412176276034175
    assert default_seed("2005-01-01", "B") == 16960101291714988360
