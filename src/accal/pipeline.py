"""The ``grace-bias`` pipeline: read → validate → estimate → correct → write, per input.

This module only sequences the other layers (readers in :mod:`accal.io`,
estimators in :mod:`accal.estimators`, writers in :mod:`accal.io.writers`); it
computes nothing itself.  One input's failure never stops the others: each is
reported as a :class:`FileOutcome` with a one-line message.

The code lives in the modules of :mod:`accal.gracejob`, one topic each; this
module re-exports their public names, so ``from accal.pipeline import X`` keeps
working (and, for the modules that imported them from here, the old private
names ``_nan_to_none``, ``_write_json``, ... of the now public functions).
"""

from __future__ import annotations

from accal.gracejob.batch import options_key, run
from accal.gracejob.fit import (
    InputFit,
    calibrate,
    estimate,
    fit_input,
    row_source,
    signal_share,
    table_rows,
)
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import (
    KEPT_EARLIER,
    FileOutcome,
    RunSummary,
    internal_error,
    peak_rss_mb,
)
from accal.gracejob.outputs import (
    CALIBRATED_UNITS,
    calibrated_frame,
    file_size,
    nan_to_none,
    output_stem,
    write_json,
)
from accal.gracejob.process import process_file, process_one
from accal.gracejob.reading import (
    REFERENCE_MAX_BRIDGE,
    name_mismatch,
    read_input,
    read_with_reference,
    subtract_reference,
    with_warnings,
)
from accal.gracejob.table import (
    BIAS_DRIFT_UNITS,
    CORE_COLUMNS,
    KEY_COLUMNS,
    REFERENCE_UNITS,
    find_bias_drift,
    merge_bias_drift,
    read_bias_drift,
    read_bias_drift_arrow,
)

# the names these functions had here before they were made public (still imported
# from here by accal.demodjob.outputs: _nan_to_none)
_internal_error = internal_error
_nan_to_none = nan_to_none
_peak_rss_mb = peak_rss_mb
_read_bias_drift_arrow = read_bias_drift_arrow
_read_with_reference = read_with_reference
_row_source = row_source
_size = file_size
_with_warnings = with_warnings
_write_json = write_json

__all__ = [
    "BIAS_DRIFT_UNITS",
    "CALIBRATED_UNITS",
    "CORE_COLUMNS",
    "KEPT_EARLIER",
    "KEY_COLUMNS",
    "REFERENCE_MAX_BRIDGE",
    "REFERENCE_UNITS",
    "FileOutcome",
    "GraceBiasOptions",
    "InputFit",
    "RunSummary",
    "calibrate",
    "calibrated_frame",
    "estimate",
    "file_size",
    "find_bias_drift",
    "fit_input",
    "internal_error",
    "merge_bias_drift",
    "name_mismatch",
    "nan_to_none",
    "options_key",
    "output_stem",
    "peak_rss_mb",
    "process_file",
    "process_one",
    "read_bias_drift",
    "read_bias_drift_arrow",
    "read_input",
    "read_with_reference",
    "row_source",
    "run",
    "signal_share",
    "subtract_reference",
    "table_rows",
    "with_warnings",
    "write_json",
]
