"""The closure's peak finder against scipy.signal's (the definitions it reproduces)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import signal

from accal.closure.peaks import local_maxima, prominences, prominent_peaks

# small integers: plateaus, equal bases and equal neighbouring peaks are frequent
CURVES = arrays(np.float64, st.integers(0, 60), elements=st.integers(-4, 4).map(float))


@settings(max_examples=400, deadline=None)
@given(CURVES)
def test_local_maxima_are_scipys(x):
    assert local_maxima(x).tolist() == signal.find_peaks(x)[0].tolist()


@settings(max_examples=400, deadline=None)
@given(CURVES)
def test_prominences_are_scipys(x):
    peaks = signal.find_peaks(x)[0]
    assert prominences(x, peaks).tolist() == signal.peak_prominences(x, peaks)[0].tolist()


@settings(max_examples=300, deadline=None)
@given(CURVES, st.sampled_from([0.0, 0.5, 1.0, 2.0, 3.0]))
def test_prominent_peaks_are_scipys(x, level):
    expected = signal.find_peaks(x, prominence=level)[0]
    assert prominent_peaks(x, level).tolist() == expected.tolist()


def test_a_noisy_profile_of_a_day_is_scipys():
    """A scan's length (3,601 lags) of a smooth curve with noise, at the profile's level."""
    rng = np.random.default_rng(3)
    lag = np.arange(3601.0)
    x = np.exp(-0.5 * ((lag - 1200.0) / 40.0) ** 2) + 0.3 * np.cos(lag / 97.0)
    x += 0.01 * rng.standard_normal(lag.size)
    for level in (1e-3, 0.02, 0.5):
        expected = signal.find_peaks(x, prominence=level)[0]
        assert prominent_peaks(x, level).tolist() == expected.tolist()
    # the cosine's peaks rise 0.6 above their troughs, the Gaussian ~1.3
    assert prominent_peaks(x, 0.8).tolist() == [1150 + int(np.argmax(x[1150:1250]))]


@pytest.mark.parametrize("x", [[], [1.0], [1.0, 2.0], [2.0, 2.0, 2.0]])
def test_short_or_flat_curves_have_no_peaks(x):
    assert prominent_peaks(np.array(x), 0.0).size == 0
