"""Davies' bound for a frequency searched over a band (the orbit term's multiplicity).

The orbit term's frequency is searched within ±3 % of the orbit frequency; its test
counted that as one test on a day, and on white noise the term was significant on 3
of 40 days at α = 0.01 (`signal_model="none"`, as with a reference).  The factor now
comes from Davies' bound (:func:`accal.closure.multiplicity.frequency_search_factor`),
checked here against a Monte-Carlo of the maximum periodogram over a band.
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.distributions import chi2_sf
from accal.closure.multiplicity import frequency_search_factor


def _threshold(level: float, factor: float, k: int) -> float:
    """``u`` with ``P(χ²_k > u) = level / factor``."""
    from scipy import optimize

    return optimize.brentq(lambda u: np.log(chi2_sf(u, k)) - np.log(level / factor), 0.1, 500.0)


@pytest.mark.parametrize("ordinates", [1.0, 4.0])
def test_bound_holds_and_is_not_far_off(ordinates):
    """White noise, 1,024 samples, one sinusoid whose frequency is searched over a band
    of 1 or 4 DFT ordinates (64 frequencies in it): the share of 4,000 draws whose
    maximum crosses the threshold the factor sets for α = 0.05 is at most α (+ 3
    Monte-Carlo σ) and more than α/4 (the bound is not the band's whole count)."""
    rng = np.random.default_rng(1)
    n, level, draws = 1024, 0.05, 4000
    t = np.arange(n, dtype=float)
    band = ordinates / n
    f = 100.0 / n + np.linspace(-0.5 * band, 0.5 * band, 64)
    e = np.exp(-2j * np.pi * np.outer(t - t.mean(), f))  # (n, 64)
    x = rng.standard_normal((draws, n))
    stat = 2.0 * np.abs(x @ e) ** 2 / n  # χ²₂ at each frequency (unit noise)
    factor = frequency_search_factor(t, band, [1], 1, level)
    share = float(np.mean(stat.max(axis=1) > _threshold(level, factor, 2)))
    assert share <= level + 3.0 * np.sqrt(level * (1 - level) / draws)
    assert share > level / 4.0
    assert factor > 1.0


def test_factor_grows_with_the_band_and_the_harmonics():
    t = np.arange(86400.0)
    one = frequency_search_factor(t, 0.06 / 5600.0, [1], 1, 0.01)
    two = frequency_search_factor(t, 0.06 / 5600.0, [1, 2], 1, 0.01)
    wide = frequency_search_factor(t, 0.12 / 5600.0, [1, 2], 1, 0.01)
    assert 1.0 < one < two < wide
    assert frequency_search_factor(t, 0.0, [1, 2], 1, 0.01) == 1.0
