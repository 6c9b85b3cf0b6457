"""What happened to the inputs of ``accal grace-bias``: one input, and a batch.

:class:`FileOutcome` (one input: its table rows, outputs, warnings, peak memory),
:class:`RunSummary` (a batch, with its one-line end-of-run summary), and the
helpers that make an outcome of a failure or measure the memory of a worker.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from accal.batch import Outcome, internal_error_message


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
class RunSummary:
    """Result of a batch run.

    ``outcomes`` are in input order; inputs not run (``--fail-fast``) are absent.
    """

    outcomes: list[FileOutcome]
    table_path: Path | None
    seconds: float
    n_inputs: int = 0
    log_path: Path | None = None
    workers: int = 1

    @property
    def n_ok(self) -> int:
        """Inputs processed now."""
        return sum(o.ok and not o.skipped for o in self.outcomes)

    @property
    def n_skipped(self) -> int:
        """Inputs whose outputs were current."""
        return sum(o.skipped for o in self.outcomes)

    @property
    def n_failed(self) -> int:
        """Inputs that failed."""
        return sum(not o.ok for o in self.outcomes)

    @property
    def n_not_run(self) -> int:
        """Inputs never started (after a failure with ``fail_fast``)."""
        return self.n_inputs - len(self.outcomes)

    @property
    def n_samples(self) -> int:
        """Samples read."""
        return sum(o.n_samples for o in self.outcomes)

    @property
    def n_bytes(self) -> int:
        """Bytes read (inputs processed now)."""
        return sum(o.n_bytes for o in self.outcomes if not o.skipped)

    @property
    def peak_rss(self) -> float:
        """Largest peak resident memory of a process that ran inputs [MB]."""
        return max((o.peak_rss for o in self.outcomes), default=0.0)

    def line(self, command: str = "accal grace-bias") -> str:
        """The one-line end-of-run summary."""
        done = self.n_ok + self.n_failed
        rate = (
            f"{self.n_bytes / 1e6 / self.seconds:.1f} MB/s, {done / self.seconds:.2f} files/s"
            if self.seconds > 0
            else "-"
        )
        rss = f", peak RSS {self.peak_rss:.0f} MB per worker" if self.peak_rss > 0 else ""
        return (
            f"{command}: {self.n_ok} ok, {self.n_skipped} skipped (current), {self.n_failed} "
            f"failed, {self.n_not_run} not run; {self.n_samples:,} samples, "
            f"{self.n_bytes / 1e6:.1f} MB in {self.seconds:.2f} s ({rate}, {self.workers} "
            f"worker{'s' if self.workers != 1 else ''}{rss}); table: "
            f"{self.table_path or '(none written)'}"
        )


#: What a failed input's earlier outputs are (said in the log and on stderr).
KEPT_EARLIER = (
    "the outputs of an earlier run for it are kept (calibrated file, report, table rows); "
    "they are replaced once it is processed again"
)


def peak_rss_mb() -> float:
    """Peak resident memory of this process [MB] (0 where ``resource`` is missing)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return 0.0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1 << 20) if sys.platform == "darwin" else peak / 1024.0


def internal_error(path: Path, exc: BaseException) -> FileOutcome:
    return FileOutcome(Path(path), False, internal_error_message(path, exc))
