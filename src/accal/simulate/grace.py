"""Synthetic GRACE / GRACE-FO ACC1B days that look like the real Level-1B files.

The simulated raw reading follows the wavelet paper's eq. (9) plus injected
instrument effects, ``a_raw = s·a_true + b + d·(t − t0) + noise + Σ effects``, and
all 12 ACC1B columns are filled at the magnitudes of the real files.  This module
gathers the simulator's public names; the code, with its sources, is in

* :mod:`accal.simulate.grace_signal`: the day (:func:`simulate_grace_day`,
  :class:`SimulatedDay`): eq. (9), the TN-02 bias and scale, the truth;
* :mod:`accal.simulate.grace_noise`: the instrument noise (with its CRN-like
  low-pass) and the noise of a POD-derived reference;
* :mod:`accal.simulate.grace_columns`: the ang_accl and acl_res columns;
* :mod:`accal.simulate.grace_effects`: the injected instrument effects and the
  auxiliary channels of couplings;
* :mod:`accal.simulate.grace_seeds`: the seed (:func:`default_seed`) and the random
  streams (:data:`STREAMS`);
* :mod:`accal.simulate.grace_files`: the ACC1B file and its truth
  (:func:`write_simulated_grace`), the auxiliary, THR1B and reference files, and
  arcs of consecutive days (:func:`write_simulated_arc`).
"""

from __future__ import annotations

from accal.crn import crn_smooth
from accal.simulate.grace_columns import (
    ANGULAR_NOISE,
    ANGULAR_OFFSETS,
    ANGULAR_WANDER,
    ANGULAR_WANDER_TAU,
    RESIDUAL_SIGMA,
    RESIDUAL_SPIKE_SIZE,
    RESIDUAL_SPIKES,
)
from accal.simulate.grace_files import (
    arc_files,
    arc_paths,
    aux_path,
    write_simulated_arc,
    write_simulated_grace,
)
from accal.simulate.grace_noise import (
    CRN_BOXCAR,
    CRN_ORDER,
    NOISE_CORNER,
    NOISE_RISE,
    REFERENCE_BAND,
    REFERENCE_CORNER,
    REFERENCE_LIMIT,
    REFERENCE_NOISE,
    coloured_noise,
    crn_lowpass,
    instrument_noise,
    reference_noise,
    reference_noise_psd,
)
from accal.simulate.grace_seeds import STREAMS, default_seed, stream
from accal.simulate.grace_signal import (
    GRACEFO_OFFSETS,
    MAX_SAMPLES,
    ORBIT_PERIOD,
    SimulatedDay,
    simulate_grace_day,
)
from accal.simulate.thr1b import thruster_path, write_simulated_thr1b

__all__ = [
    "ANGULAR_NOISE",
    "ANGULAR_OFFSETS",
    "ANGULAR_WANDER",
    "ANGULAR_WANDER_TAU",
    "CRN_BOXCAR",
    "CRN_ORDER",
    "GRACEFO_OFFSETS",
    "MAX_SAMPLES",
    "NOISE_CORNER",
    "NOISE_RISE",
    "ORBIT_PERIOD",
    "REFERENCE_BAND",
    "REFERENCE_CORNER",
    "REFERENCE_LIMIT",
    "REFERENCE_NOISE",
    "RESIDUAL_SIGMA",
    "RESIDUAL_SPIKES",
    "RESIDUAL_SPIKE_SIZE",
    "STREAMS",
    "SimulatedDay",
    "arc_files",
    "arc_paths",
    "aux_path",
    "coloured_noise",
    "crn_lowpass",
    "crn_smooth",
    "default_seed",
    "instrument_noise",
    "reference_noise",
    "reference_noise_psd",
    "simulate_grace_day",
    "stream",
    "thruster_path",
    "write_simulated_arc",
    "write_simulated_grace",
    "write_simulated_thr1b",
]
