"""Unit tests of accal.closure.select helpers."""

from __future__ import annotations

import pytest


def test_exponential_amplitude_is_referred_to_the_record_start():
    """QA: after a lagged coupling's re-search (the first 5400 s left out) a 3e-9 m/s²
    decay was reported as 4.9e-10, its value at the re-search's first sample.  The
    amplitude is moved to the record's start, its σ gains T's."""
    import math

    from accal.closure.final import refer_exponentials
    from accal.closure.results import Effect

    shift, tau, s_tau = 5400.0, 2832.0, 200.0
    e = Effect(
        "exponential_drift", None, 4.9e-10, 1.5e-11, 1e-9, tau=tau,
        details={"t0": 1000.0 + shift, "tau_sigma": s_tau,
                 "axes": {"z": {"coefficient": 4.9e-10, "sigma": 1.5e-11}}},
    )  # fmt: skip
    step = Effect("bias_step", None, 1e-9, 1e-11, 1e-9, epoch=5000.0)
    moved, same = refer_exponentials([e, step], 1000.0)
    f = math.exp(shift / tau)
    assert moved.coefficient == pytest.approx(4.9e-10 * f, rel=1e-12)
    want_sigma = math.hypot(1.5e-11 * f, 4.9e-10 * f * shift / tau**2 * s_tau)
    assert moved.sigma == pytest.approx(want_sigma, rel=1e-12)
    assert moved.details["t0"] == 1000.0 and moved.details["amplitude_moved_from"] == 6400.0
    assert moved.details["axes"]["z"]["coefficient"] == pytest.approx(moved.coefficient)
    assert same is step
    assert refer_exponentials([moved], 1000.0)[0] is moved  # already at the start
