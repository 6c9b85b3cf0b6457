"""What happened to the inputs of ``accal grace-bias``: one input, and a batch.

:class:`FileOutcome` (one input: its table rows, outputs, warnings, peak memory),
:class:`RunSummary` (a batch, with its one-line end-of-run summary), and the
helpers that make an outcome of a failure or measure the memory of a worker
(:func:`peak_rss_mb`, re-exported from :mod:`accal.batch_summary`, where the
summary's shared part is).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from accal.batch import Outcome, internal_error_message
from accal.batch_summary import BatchSummary, peak_rss_mb

__all__ = [
    "KEPT_EARLIER",
    "FileOutcome",
    "RunSummary",
    "internal_error",
    "peak_rss_mb",
]


@dataclass(frozen=True)
class FileOutcome(Outcome):
    """What happened to one input (:class:`accal.batch.Outcome` plus grace-bias results).

    Attributes
    ----------
    rows : list of dict
        Rows for ``bias_drift`` (one per axis and method).
    n_samples : int
        Samples read.
    skipped : bool
        True when the manifest says the outputs are current (nothing was done).
    n_bytes : int
        Size of the input [bytes].
    closure : dict
        ``{axis: closure summary}`` of a ``--close-loop`` run (see ``closure.json``).
    warnings : tuple of str
        What the reader and the pipeline found worth telling (duplicated or
        out-of-order records, gaps, header/record/file-name disagreements, ...).
    peak_rss : float
        Peak resident memory of the process that ran the input, when it finished
        [MB] (0 where unknown).
    signature : dict or None
        Size and mtime of the input before it was read (see
        :meth:`accal.batch.Manifest.record`).
    kept_earlier : bool
        A failed input whose calibrated file from an earlier run is in the directory:
        those outputs (calibrated file, report, table rows) are kept, not removed.
    """

    rows: list[dict[str, Any]] = field(default_factory=list)
    n_samples: int = 0
    skipped: bool = False
    n_bytes: int = 0
    closure: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    peak_rss: float = 0.0
    signature: dict[str, Any] | None = None
    kept_earlier: bool = False


@dataclass(frozen=True)
class RunSummary(BatchSummary):
    """Result of a ``grace-bias`` batch: :class:`accal.batch_summary.BatchSummary`
    (counts, throughput, end-of-run line) of :class:`FileOutcome`, its line naming
    ``accal grace-bias``.

    ``outcomes`` are in input order; inputs not run (``--fail-fast``) are absent.
    """

    outcomes: list[FileOutcome]

    command: ClassVar[str] = "accal grace-bias"


#: What a failed input's earlier outputs are (said in the log and on stderr).
KEPT_EARLIER = (
    "the outputs of an earlier run for it are kept (calibrated file, report, table rows); "
    "they are replaced once it is processed again"
)


def internal_error(path: Path, exc: BaseException) -> FileOutcome:
    """The failed outcome of an exception that escaped the task (a bug, a dead worker)."""
    return FileOutcome(Path(path), False, internal_error_message(path, exc))
