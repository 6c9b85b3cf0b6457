"""The ang_accl and acl_res columns of a simulated GRACE ACC1B day (:mod:`accal.simulate.grace`).

The other ACC1B columns than ``lin_accl`` are filled as in the real files:
``ang_accl_x/y/z`` are the offset of the sample files plus an orbit-periodic signal
of ~2e-7 rad/s² plus white noise and a 60 s Gauss-Markov wander at the samples'
levels (GRACE A/B, :data:`ANGULAR_NOISE`, :data:`ANGULAR_WANDER`); GRACE-FO C/D are
written as ACT1B, whose angular columns are 0 in the real files, and keep that.
``acl_x/y/z_res`` are Gaussian with the samples' robust spread plus rarer spikes
(heavy tails, as in the samples).

Magnitudes measured on the real samples (``data/samples``, 60 s of 2003-09-14 and
100 s of 2023-06-01; ``σ_d`` = std of first differences / √2, robust σ = 1.4826·MAD)
and used here:

=====  ================================  ===========================  ===============================
sat    ang_accl mean [rad/s²]            ang_accl σ_d [rad/s²]        acl_res robust σ [m/s²]
=====  ================================  ===========================  ===============================
A      3.3220e-4, −3.9353e-5, −2.9153e-4  7.87e-7, 2.40e-7, 6.42e-8    2.45e-9, 3.68e-9, 7.26e-9
B      −4.1715e-4, −7.4392e-6, −5.8413e-4 1.11e-7, 2.89e-8, 3.53e-8    3.42e-9, 2.72e-9, 1.64e-8
C, D   0 (ACT1B)                          0                           C 1.43e-9, 1.25e-9, 1.63e-9;
                                                                      D 7.11e-10, 3.19e-10, 6.82e-10
=====  ================================  ===========================  ===============================
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.simulate.effects import first_order_recursion
from accal.simulate.grace_seeds import stream

#: ang_accl offsets [rad/s²]: the means of the real 2003-09-14 ACC1B samples.
ANGULAR_OFFSETS = {
    "A": (3.3220e-4, -3.9353e-5, -2.9153e-4),
    "B": (-4.1715e-4, -7.4392e-6, -5.8413e-4),
}

#: ang_accl white noise σ [rad/s²]: std of first differences / √2 of the samples.
ANGULAR_NOISE = {"A": (7.87e-7, 2.40e-7, 6.42e-8), "B": (1.11e-7, 2.89e-8, 3.53e-8)}

#: ang_accl slow wander [rad/s²]: a first-order Gauss-Markov process of correlation
#: time :data:`ANGULAR_WANDER_TAU`.  σ from the samples: the spread of the values
#: beyond the white noise, ``sqrt(σ_robust² − σ_d²)``, is the within-60-s spread of
#: the process, 0.51 σ for a 60 s correlation time.
ANGULAR_WANDER = {"A": (1.0e-6, 2.8e-7, 1.7e-7), "B": (6.1e-7, 2.5e-7, 5.2e-8)}
ANGULAR_WANDER_TAU = 60.0

#: acl_*_res robust σ (1.4826·MAD) [m/s²] of the real samples: the Gaussian core.
RESIDUAL_SIGMA = {
    "A": (2.45e-9, 3.68e-9, 7.26e-9),
    "B": (3.42e-9, 2.72e-9, 1.64e-8),
    "C": (1.43e-9, 1.25e-9, 1.63e-9),
    "D": (7.11e-10, 3.19e-10, 6.82e-10),
}
#: acl_*_res spikes: the fraction of samples that get an extra Gaussian draw of
#: ``RESIDUAL_SPIKE_SIZE`` × the core σ.  In the samples the std of first differences
#: is 4.5–19 times the robust σ for GRACE A/B and 3–6 times for C/D (1.4 for Gaussian
#: noise); with spikes the ratio is ``sqrt(2(1 + p·size²))``: p from the median ratio
#: of each satellite's three axes (A 7.8, B 10, C 3.3, D 6).
RESIDUAL_SPIKES = {"A": 0.07, "B": 0.12, "C": 0.011, "D": 0.043}
RESIDUAL_SPIKE_SIZE = 20.0


def other_columns(satellite: str, angular: NDArray, seed: int, dt: float) -> dict[str, NDArray]:
    """ang_accl_x/y/z and acl_x/y/z_res of the ACC1B file (module docstring)."""
    n = angular.shape[0]
    if satellite in ANGULAR_OFFSETS:
        rng = stream(seed, "angular")
        white = np.array(ANGULAR_NOISE[satellite]) * rng.standard_normal((n, 3))
        # Gauss-Markov wander, stationary from the first sample
        a = float(np.exp(-dt / ANGULAR_WANDER_TAU))
        g = rng.standard_normal((n, 3)) * np.sqrt(1.0 - a * a)
        g[0] = rng.standard_normal(3)
        wander = np.column_stack([first_order_recursion(g[:, i], a) for i in range(3)])
        ang = np.array(ANGULAR_OFFSETS[satellite]) + angular + white
        ang = ang + np.array(ANGULAR_WANDER[satellite]) * wander
    else:  # GRACE-FO ACT1B: the angular columns are 0 in the real files
        ang = np.zeros((n, 3))
    rng = stream(seed, "residual")
    core = np.array(RESIDUAL_SIGMA[satellite])
    res = core * rng.standard_normal((n, 3))
    spikes = rng.random((n, 3)) < RESIDUAL_SPIKES[satellite]
    res += np.where(spikes, RESIDUAL_SPIKE_SIZE * core * rng.standard_normal((n, 3)), 0.0)
    out = {f"ang_accl_{a}": ang[:, i] for i, a in enumerate("xyz")}
    out.update({f"acl_{a}_res": res[:, i] for i, a in enumerate("xyz")})
    return out


def angular_truth(satellite: str) -> dict[str, Any]:
    if satellite in ANGULAR_OFFSETS:
        return {
            "offset": list(ANGULAR_OFFSETS[satellite]),
            "noise_sigma": list(ANGULAR_NOISE[satellite]),
            "wander_sigma": list(ANGULAR_WANDER[satellite]),
            "wander_tau_s": ANGULAR_WANDER_TAU,
            "signal": "truth['angular']: once and twice per revolution",
        }
    zero = [0.0] * 3
    return {
        "offset": zero,
        "noise_sigma": zero,
        "wander_sigma": zero,
        "signal": "none: ACT1B writes 0",
    }
