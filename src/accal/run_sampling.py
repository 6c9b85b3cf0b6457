"""Whether ``demod --tau`` suits the sampling of the runs given (read from their first chunk)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from accal.io.rawlog import open_rawlog
from accal.pipeline_demod import DemodOptions, sampling_step


def too_coarse_for_tau(runs: Sequence[Path], opts: DemodOptions) -> list[tuple[Path, float]]:
    """The runs sampled more coarsely than ``opts.tau`` when no run suits it, else ``[]``.

    The sampling step is found as :func:`accal.pipeline_demod.estimate` finds it
    (first chunk of the run).  A run that cannot be read is left out (the run
    itself reports it, as a failed run); so is a run too coarse for τ beside
    others it suits (QA: one run in ms stopped a whole batch with exit 2): the
    option is wrong only when it suits none.

    Parameters
    ----------
    runs : sequence of Path
        The run files.
    opts : accal.pipeline_demod.DemodOptions
        The validated options (``tau`` [s], ``chunk_rows``, ``resample``).

    Returns
    -------
    list of (Path, float)
        Each run with fewer than one sample per τ and its sampling step [s], in
        the order given; empty when a run suits τ or none could be read.
    """
    tau = float(opts.tau)
    coarse = []
    for path in runs:
        try:
            # no pyarrow pool in this process: the workers can then be forked
            stream = open_rawlog(path, rows=int(opts.chunk_rows), threads=False)
            step = sampling_step(stream, opts)
        except Exception:  # noqa: BLE001 (a bad run fails in run_demod, with its message)
            continue
        if not 0 < step < math.inf:
            continue
        if tau / step >= 1 - 1e-6:
            return []  # tau suits this run: the others fail on their own
        coarse.append((path, step))  # 0 samples per period; its "nearest" whole tau is 0
    return coarse
