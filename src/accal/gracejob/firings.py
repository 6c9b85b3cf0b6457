"""The thruster firings a closure of Level-1B data must know (THR1B, issue 19)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accal.closure.edgekernel import TRANSITION
from accal.crn import is_level1b
from accal.gracejob.options import GraceBiasOptions
from accal.io.thrusters import find_thruster_file, firing_mask, foreign_day, read_thrusters
from accal.series import AccSeries

__all__ = ["closure_firings"]


def closure_firings(
    path: Path, series: AccSeries, opts: GraceBiasOptions
) -> tuple[np.ndarray | None, str | None]:
    """Samples a thruster firing reaches in Level-1B data, and a note saying so.

    The THR1B file (``opts.thrusters`` or beside ``path``; none with
    ``--thruster-margins off``) gives the firings; the CRN filter spreads each over
    ±:data:`accal.closure.edgekernel.TRANSITION` s of the data (the reference fit's
    margins are for the firing itself).  :func:`accal.closure.firings.firing_test`
    then asks a coupling to an angular acceleration to hold on the other samples: a
    thruster's force and torque move the linear and the angular accelerations together
    at a fixed ratio per thruster, a real acceleration and no lever arm (QA thruster
    days, 2026-11-29: such "couplings" removed on 30 of 36 clean days).  ``(None,
    None)`` for data that are not Level-1B or with ``--thruster-margins off``; without
    a THR1B file ``(None, note)``: the firings are unknown, and a coupling to an
    angular acceleration is then reported, not removed (``options["firings_unknown"]``).
    """
    if opts.thruster_margins is None or not is_level1b(series.meta):
        return None, None
    thr = opts.thrusters if opts.thrusters is not None else find_thruster_file(path)
    if thr is None:
        return None, (
            "no THR1B file beside the input (or --thrusters): the firings are unknown, so "
            "a coupling to an angular acceleration is reported, not removed"
        )
    firings = read_thrusters(thr)
    foreign = foreign_day(firings, series.time, thr)
    if foreign is not None:
        return None, (f"{foreign}: a coupling to an angular acceleration is reported, not removed")
    mask = firing_mask(series.time, firings, before=TRANSITION, after=TRANSITION)
    note = (
        f"{Path(thr).name}: {int(mask.sum())} samples within ±{TRANSITION:g} s of a thruster "
        "firing; a coupling to an angular acceleration must hold without them"
    )
    return mask, note
