"""What a batch did, for every batch command: :class:`BatchSummary`, :func:`peak_rss_mb`
and :func:`reset_peak_rss`.

The counts, the throughput and the one-line end-of-run summary of a batch of
:func:`accal.batch_runner.run_batch` (``accal grace-bias``, ``accal demod``), and
the peak memory each worker reports with its outcomes.  Each command's summary
names the command (:attr:`BatchSummary.command`): ``accal.gracejob.outcome.RunSummary``
and ``accal.demodjob.options.DemodRunSummary``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

__all__ = ["BatchSummary", "peak_rss_mb", "reset_peak_rss"]


@dataclass(frozen=True)
class BatchSummary:
    """Result of a batch run.

    ``outcomes`` are in input order; inputs not run (``--fail-fast``) are absent.
    Each outcome is an :class:`accal.batch.Outcome` with ``skipped``, ``n_samples``,
    ``n_bytes`` and ``peak_rss`` (a command's outcome class).

    Attributes
    ----------
    outcomes : list
        The outcomes of the inputs run or skipped, in input order.
    table_path : Path or None
        The command's cumulative table, None when none was written.
    seconds : float
        Wall time of the batch [s].
    n_inputs : int
        Inputs given (those never started included).
    log_path : Path or None
        The run log, None without one.
    workers : int
        Processes that ran inputs.
    command : str
        The command the end-of-run line names (a class attribute).
    """

    outcomes: Sequence[Any]
    table_path: Path | None
    seconds: float
    n_inputs: int = 0
    log_path: Path | None = None
    workers: int = 1

    command: ClassVar[str] = "accal"

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

    def line(self, command: str | None = None) -> str:
        """The one-line end-of-run summary.

        Parameters
        ----------
        command : str, optional
            The command it names (default: :attr:`command`).

        Returns
        -------
        str
            ``<command>: N ok, N skipped (current), N failed, N not run; ...``.
        """
        done = self.n_ok + self.n_failed
        rate = (
            f"{self.n_bytes / 1e6 / self.seconds:.1f} MB/s, {done / self.seconds:.2f} files/s"
            if self.seconds > 0
            else "-"
        )
        rss = f", peak RSS {self.peak_rss:.0f} MB per worker" if self.peak_rss > 0 else ""
        return (
            f"{command or self.command}: {self.n_ok} ok, {self.n_skipped} skipped (current), "
            f"{self.n_failed} failed, {self.n_not_run} not run; {self.n_samples:,} samples, "
            f"{self.n_bytes / 1e6:.1f} MB in {self.seconds:.2f} s ({rate}, {self.workers} "
            f"worker{'s' if self.workers != 1 else ''}{rss}); table: "
            f"{self.table_path or '(none written)'}"
        )


def reset_peak_rss() -> bool:
    """Start this process's peak resident memory afresh, where the system allows it.

    A worker runs many inputs, and a Dask worker lives beyond the batch (other
    clients' tasks, its own start-up): the process's lifetime peak
    (``ru_maxrss``) is then no measure of the input at hand.  On Linux (≥ 4.0)
    writing ``5`` to ``/proc/self/clear_refs`` sets the peak (``VmHWM``) to the
    current resident size (proc(5), "/proc/pid/clear_refs"); each input's task
    calls this first, so :func:`peak_rss_mb` then gives the peak of the process
    while that input ran.

    Returns
    -------
    bool
        Whether the peak was reset (False elsewhere, or where the file is not
        writable: :func:`peak_rss_mb` is then the process's lifetime peak).
    """
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        return False
    return True


def peak_rss_mb() -> float:
    """Peak resident memory of this process [MB] since :func:`reset_peak_rss` (else its
    lifetime peak; 0 where neither ``/proc`` nor ``resource`` tells it).

    Returns
    -------
    float
        ``VmHWM`` of ``/proc/self/status`` (Linux), else ``ru_maxrss`` in MB (kB on
        Linux, bytes on macOS).
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0  # kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return 0.0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1 << 20) if sys.platform == "darwin" else peak / 1024.0
