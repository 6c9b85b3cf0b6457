"""A coupling to a channel that repeats with the demodulation period: its lag is known
only modulo the period, and the report says so.

The platform temperature of :func:`tests.indep.platform_run` is kicked by every
rotation (a τ-periodic heating transient) on top of a slow daily cycle; with the
per-period base removing the slow part, lags a period apart explain the same power
(QA: a 933 s lag came out as 329 s).  The generator is the independent one of
``tests/indep``, not accal's simulator.
"""

from __future__ import annotations

import numpy as np
from tests.indep import platform_run

from accal.closure.demod import close_loop_demod
from accal.estimators.noise import as_psd


def test_lags_a_period_apart_are_reported_as_aliases():
    lag, coef = 932.5, 3e-8
    run = platform_run(7302, effects=[("coupling", "temperature", coef, lag, "both")])
    tab = run.table
    res, _ = close_loop_demod(
        tab["time"].to_numpy(),
        (tab["m_y"].to_numpy(), tab["m_z"].to_numpy()),
        tab["theta"].to_numpy(),
        tau=600.0,
        aux={"temperature": tab["temperature"].to_numpy()},
        noise_psd=as_psd(None),
        rest_tol=1e-9,
    )
    (e,) = [e for e in res.effects if e.name == "auxiliary"]
    aliases = np.asarray(e.details["lag_aliases"])
    # the shortest alias is reported; the true lag is one of the aliases
    assert e.lag == aliases.min() < lag
    assert np.min(np.abs(aliases - lag)) < 10.0
    # aliases are whole periods apart
    assert np.allclose(np.diff(aliases) / 600.0, np.round(np.diff(aliases) / 600.0), atol=0.02)
    # the spread over the aliases is in the sigma: sigma >= |coef| x spread
    ax = e.details["axes"]["y"]
    assert e.details["alias_spread"] > 0
    assert ax["sigma"] >= abs(ax["coefficient"]) * e.details["alias_spread"]
    # measured: 2.914e-8 +- 2.7e-10 (spread 0.56 %) for 3e-8; the shortfall is not the
    # alias (a half day fitted at 934.6 s gives 2.954e-8 +- 1.5e-10): not explained yet
    assert abs(ax["coefficient"] - coef) < 0.05 * coef
