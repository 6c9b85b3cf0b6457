"""An effect is reported on the columns it was fitted with (issue 19, QA q07).

A polynomial's columns are ``((t − t0)/scale)^k`` with the origin and scale of the
search that proposed them.  When a lagged channel's first samples are unknown the
selection starts again without them and keeps the effects of the first search, whose
columns refer to the record's first sample and whole span; the final model's span is
shorter.  Converting with that span reported a 1e-13 m/s⁴ in-period quadratic 0.7 %
high, 400σ (the QA's platform run with a 300 s lagged temperature coupling).
"""

from __future__ import annotations

import numpy as np
import pytest

from accal.closure.candidates import Proposal
from accal.closure.final import describe


def _prop(name: str, params: dict) -> Proposal:
    return Proposal(name, None, np.zeros((10, 1)), ("t^2",), 1.0, params)


def test_a_quadratic_is_converted_with_its_own_scale_and_origin():
    gamma, sigma = np.array([7.46e-4]), np.array([[1e-8**2]])
    prop = _prop("quadratic_drift", {"powers": (2,), "scale": 86399.0, "t0": 0.0})
    (e,) = describe([(prop, 1e-9, {})], gamma, sigma, span=86099.0, t0=300.0, channel_units={})
    assert e.coefficient == pytest.approx(7.46e-4 / 86399.0**2, rel=1e-15)
    assert e.sigma == pytest.approx(1e-8 / 86399.0**2, rel=1e-15)
    assert e.details["t0"] == 0.0


def test_without_its_own_scale_the_final_span_is_used():
    prop = _prop("quadratic_drift", {"powers": (2,)})
    (e,) = describe(
        [(prop, 1e-9, {})], np.array([2.0]), np.eye(1), span=100.0, t0=5.0, channel_units={}
    )
    assert e.coefficient == 2.0 / 100.0**2 and e.details["t0"] == 5.0


def test_a_line_keeps_the_origin_of_its_phase():
    prop = Proposal(
        "periodic", None, np.zeros((10, 2)), ("cos", "sin"), 1.0,
        {"frequency": 1e-3, "harmonics": (1,), "t0": 0.0},
    )  # fmt: skip
    (e,) = describe(
        [(prop, 1e-9, {})], np.array([1.0, 0.0]), np.eye(2), span=1e4, t0=300.0, channel_units={}
    )
    assert e.details["t0"] == 0.0
