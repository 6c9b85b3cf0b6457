"""Independent generators of accelerometer test data (no ``accal`` import).

Closure tests and Monte-Carlo benchmarks use these as a second source of truth beside
``accal.simulate``: they are written from the papers, the real sample files and the
format specifications only.  Plain numpy/scipy/pandas/pyarrow; deterministic by seed.
See ``tests/indep/README.md`` for what each generator models and where the magnitudes
come from.

API
---
grace_day(seed, satellite="A", *, duration=86400, dt=1.0, noise="white+1/f", ...) -> GraceDay
write_acc1b_grace(day, path), write_act1b_gracefo(day, path)
swarm_day_with_channels(samples_dir, seed, *, channels=("temperature",), effects=(), ...)
    -> SwarmDay (unpacks as table, truth); write_swarm_table(day, path)
platform_run(seed, *, days=1.0, tau=600.0, mask=200.0, fs=1.0, noise_psd="microstar",
             signal="slow", effects=()) -> PlatformRun (unpacks as table, truth)
write_platform_run(run, path), write_platform_truth(run, path)
write_table(path, columns, units=None, *, meta=None, fmt=None), read_units(path)
calibration_pattern(tau, mask, fs=1.0) -> Pattern, microstar_psd(f), rest_mask(theta)
"""

from ._common import gps_day_start, noise_psd, shaped_noise, temperature_channel
from .grace import GraceDay, grace_day, write_acc1b_grace, write_act1b_gracefo
from .rotating import (
    Pattern,
    PlatformRun,
    calibration_pattern,
    microstar_psd,
    platform_run,
    rest_mask,
    write_platform_run,
    write_platform_truth,
)
from .swarm import SwarmDay, swarm_day_with_channels, write_swarm_table
from .tables import read_units, write_table

__all__ = [
    "GraceDay",
    "Pattern",
    "PlatformRun",
    "SwarmDay",
    "calibration_pattern",
    "gps_day_start",
    "grace_day",
    "microstar_psd",
    "noise_psd",
    "platform_run",
    "read_units",
    "rest_mask",
    "shaped_noise",
    "swarm_day_with_channels",
    "temperature_channel",
    "write_acc1b_grace",
    "write_act1b_gracefo",
    "write_platform_run",
    "write_platform_truth",
    "write_swarm_table",
    "write_table",
]
