"""The ``demod`` pipeline: read → validate → demodulate → write, per run file.

Like :mod:`accal.pipeline`, this sequences the other layers (the reader
:func:`accal.io.rawlog.open_rawlog`, the estimators of
:mod:`accal.estimators.demod` and :mod:`accal.estimators.resample`, the writers
of :mod:`accal.io.writers` and :mod:`accal.io.merge`); the numbers come from the
estimators.  It also holds the library side of ``accal design``, ``accal budget``
and ``accal simulate gap`` so that the CLI stays thin.

The code lives in the modules of :mod:`accal.demodjob`, one topic each; this
module re-exports their public names, so ``from accal.pipeline_demod import X``
keeps working.  The outputs of :func:`run_demod` are described in
:mod:`accal.demodjob.batch`.
"""

from __future__ import annotations

from accal.demodjob.batch import process_run, run_demod
from accal.demodjob.closure import change_statistics, close_run, closure_summary
from accal.demodjob.closure_outputs import (
    apply_closure,
    leak_of,
    misfit_of,
    write_demod_closure,
)
from accal.demodjob.diagnose import current_summaries, diagnose_demod_dir
from accal.demodjob.options import (
    CHUNK_ROWS,
    MIN_CHUNK_ROWS,
    STANDARD_INTEGRATION,
    DemodOptions,
    DemodRunSummary,
    RunInfo,
    RunOutcome,
)
from accal.demodjob.outputs import (
    check_distinct_runs,
    check_output_format,
    load_summary,
    output_paths,
    remove_stale_summaries,
    summary_source,
)
from accal.demodjob.planning import budget_report, parse_taus, plot_budget, write_design
from accal.demodjob.reading import estimate, load_psd, sampling_step, validated_chunks
from accal.demodjob.report import (
    LEAKAGE_WARN,
    NOISE_RATIO_WARN,
    SHIFT_WARN,
    summary_markdown,
    summary_warnings,
    tau_of,
)
from accal.demodjob.simulate import SIMULATE_CHUNK_DAYS, write_simulated_gap
from accal.demodjob.summary import (
    MASK_RTOL,
    SHIFT_NEAR,
    consistency_summary,
    find_run,
    leakage_summary,
    noise_summary,
    summarise,
)
from accal.demodjob.table import PERIOD_UNITS, period_rows

__all__ = [
    "CHUNK_ROWS",
    "LEAKAGE_WARN",
    "MASK_RTOL",
    "MIN_CHUNK_ROWS",
    "NOISE_RATIO_WARN",
    "PERIOD_UNITS",
    "SHIFT_NEAR",
    "SHIFT_WARN",
    "SIMULATE_CHUNK_DAYS",
    "STANDARD_INTEGRATION",
    "DemodOptions",
    "DemodRunSummary",
    "RunInfo",
    "RunOutcome",
    "apply_closure",
    "leak_of",
    "misfit_of",
    "budget_report",
    "change_statistics",
    "check_distinct_runs",
    "check_output_format",
    "close_run",
    "closure_summary",
    "consistency_summary",
    "current_summaries",
    "diagnose_demod_dir",
    "estimate",
    "find_run",
    "leakage_summary",
    "load_psd",
    "load_summary",
    "noise_summary",
    "output_paths",
    "parse_taus",
    "period_rows",
    "plot_budget",
    "process_run",
    "remove_stale_summaries",
    "run_demod",
    "sampling_step",
    "summarise",
    "summary_markdown",
    "summary_source",
    "summary_warnings",
    "tau_of",
    "validated_chunks",
    "write_demod_closure",
    "write_design",
    "write_simulated_gap",
]
