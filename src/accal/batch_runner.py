"""The runner every batch command shares: lock, log, manifest, workers, commits, summary.

:func:`run_batch` runs a :class:`BatchJob` over its inputs.  The job says what is
particular to the command, as a short list of steps (as pvlib's
``ModelChain.run_model``):

1. :meth:`~BatchJob.plan`: which inputs are settled already (expanded to nothing,
   an output clash, current in the manifest) and which are to run;
2. :meth:`~BatchJob.outcomes`: run those (by default the picklable
   :meth:`~BatchJob.task` through :func:`accal.batch.execute`: in this process, on
   local worker processes or on a dask.distributed cluster), yielding outcomes as
   they complete;
3. :meth:`~BatchJob.write`: in this process, as each outcome arrives: what the
   workers leave to it (demod: the run's rows and summaries), or a mark on the
   outcome (grace-bias: a failed input's earlier outputs are kept);
4. :meth:`~BatchJob.commit`: every ``commit_seconds`` and at the end, the pending
   outcomes into the cumulative table and the manifest (after their outputs);
5. :meth:`~BatchJob.finish` and :meth:`~BatchJob.summarise`: after the last one.

The runner holds the output directory's lock, appends to its log, loads the
manifest, counts and logs the outcomes, honours ``fail_fast`` and turns Ctrl-C
into :class:`accal.batch.Interrupted` (with the summary of what finished, which
is committed first).
"""

from __future__ import annotations

import json
import os
import time as _time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import (
    Interrupted,
    Manifest,
    OutputLock,
    RunLog,
    execute,
    remove_stale_temporaries,
)

__all__ = ["BatchJob", "run_batch", "scheduler_name"]


def scheduler_name(scheduler: str | Any | None) -> str:
    """How the log names a scheduler: its address, ``None``, or ``client``."""
    return str(scheduler) if isinstance(scheduler, str | None) else "client"


class BatchJob:
    """The steps of one command's batch (subclass and override; see the module docstring).

    Attributes
    ----------
    command : str
        The command's name (``"grace-bias"``, ``"demod"``): the lock and the log say it.
    """

    command: str = "accal"

    def options_key(self) -> dict[str, Any]:
        """The options as a canonical JSON-able dict (what the manifest compares)."""
        raise NotImplementedError

    def start_line(self, n_inputs: int, workers: int, scheduler: Any, force: bool) -> str:
        """The log's first line of a run."""
        return (
            f"start accal {__version__} {self.command}: {n_inputs} inputs, workers={workers}, "
            f"scheduler={scheduler_name(scheduler)}, force={force}, "
            f"options={json.dumps(self.key, sort_keys=True)}"
        )

    def nothing_to_read(
        self, paths: list[Path], unmatched: Sequence[tuple[Path, str]], seconds: float
    ) -> Any:
        """The summary of a run none of whose inputs exists (nothing is created)."""
        raise NotImplementedError

    def check_out_dir(self, out_dir: Path) -> None:
        """Refuse an output directory the job cannot write into (before its lock)."""

    def plan(
        self,
        paths: list[Path],
        unmatched: Sequence[tuple[Path, str]],
        manifest: Manifest,
        force: bool,
        checksum: bool,
        rlog: RunLog,
    ) -> tuple[dict[int, Any], list[int]]:
        """``(settled outcomes by input index, indices of the inputs to run)``.

        The unmatched inputs take negative indices, ahead of the inputs.
        """
        raise NotImplementedError

    def task(self, run_token: str | None) -> Callable[[Path], Any]:
        """The picklable ``task(path) -> outcome`` the workers run."""
        raise NotImplementedError

    def internal_error(self, path: Path, exc: BaseException) -> Any:
        """The outcome of an exception that escaped :meth:`task` (a bug, a dead worker)."""
        raise NotImplementedError

    def outcomes(
        self,
        paths: list[Path],
        *,
        workers: int,
        scheduler: Any,
        rlog: RunLog,
        run_token: str | None,
    ) -> Iterator[tuple[int, Any]]:
        """Run :meth:`task` on ``paths``; ``(index into paths, outcome)`` as each completes."""
        return execute(
            self.task(run_token),
            paths,
            workers=workers,
            scheduler=scheduler,
            on_error=self.internal_error,
            on_note=rlog,
        )

    def write(self, outcome: Any) -> Any:
        """Finish one outcome in this process as it arrives; the outcome to keep."""
        return outcome

    def log_outcome(self, outcome: Any, rlog: RunLog) -> None:
        """Log one outcome (``ok ...`` or ``FAILED ...``, its warnings)."""
        rlog(f"ok {outcome.path}" if outcome.ok else f"FAILED {outcome.message}")
        for w in getattr(outcome, "warnings", ()):
            rlog(f"warning {outcome.path}: {w}")

    def commit(self, outcomes: list[Any]) -> None:
        """Commit finished outcomes (table, then manifest); called with none too."""

    def finish(self, interrupted: bool, rlog: RunLog) -> None:
        """After the last commit (e.g. the pooled σ of grace-bias's table)."""

    def summarise(
        self,
        outcomes: list[Any],
        seconds: float,
        *,
        n_inputs: int,
        log_path: Path | None,
        workers: int,
    ) -> Any:
        """The run's summary (with a ``line()`` for the log)."""
        raise NotImplementedError

    # set by run_batch before plan()
    out_dir: Path
    manifest: Manifest
    key: dict[str, Any]
    checksum: bool = False


def run_batch(
    job: BatchJob,
    paths: Iterable[Path],
    out_dir: Path,
    *,
    fail_fast: bool = False,
    progress: Callable[..., Iterable[Any]] | None = None,
    workers: int = 1,
    scheduler: str | Any | None = None,
    force: bool = False,
    checksum: bool = False,
    commit_seconds: float = 15.0,
    log: bool = True,
    unmatched: Sequence[tuple[Path, str]] = (),
) -> Any:
    """Run ``job`` on every input into ``out_dir``; failures are recorded, not raised.

    Parameters
    ----------
    job : BatchJob
        The command's steps.
    paths : iterable of Path
        Inputs (already expanded, see :func:`accal.batch.discover`).
    out_dir : Path
        Output directory (created).  It holds the job's outputs, a manifest, a
        log and a lock file.
    fail_fast : bool
        Stop at the first failure (runs serially; the inputs already processed
        are still written).
    progress : callable, optional
        ``progress(iterable, total=N)`` wraps the completions (e.g. ``tqdm``).
    workers : int
        Local worker processes; results are identical to a serial run.
    scheduler : str or distributed.Client, optional
        A dask.distributed scheduler to run on instead of local workers.
    force : bool
        Redo inputs that the manifest says are current.
    checksum : bool
        Compare inputs by SHA-256 instead of size and mtime.
    commit_seconds : float
        How often the job's commits run during a batch [s] (also at the end): a
        killed batch loses at most this much work.
    log : bool
        Append to ``out_dir/accal.log``.
    unmatched : sequence of (Path, str)
        Command-line inputs that expanded to no file, with their one-line message:
        counted and logged as failed.

    Returns
    -------
    summary : object
        The job's summary (:meth:`BatchJob.summarise`).

    Raises
    ------
    accal.batch.LockedError
        If another run holds the output directory.
    accal.batch.Interrupted
        On Ctrl-C (SIGINT, SIGTERM), after committing the inputs that finished.
    """
    start = _time.perf_counter()
    out_dir = Path(out_dir)
    paths = [Path(p) for p in paths]
    if not out_dir.exists() and not any(os.path.lexists(p) for p in paths):
        # nothing to read: each input fails without a new output directory, lock and log
        # being created for it (issue 23: a failed run left them behind)
        return job.nothing_to_read(paths, unmatched, _time.perf_counter() - start)
    out_dir.mkdir(parents=True, exist_ok=True)
    if fail_fast:
        workers, scheduler = 1, None
    job.check_out_dir(out_dir)
    with OutputLock(out_dir, f"accal {job.command}") as lock:
        remove_stale_temporaries(out_dir)
        rlog = RunLog(out_dir, enabled=log)
        try:
            job.out_dir, job.checksum = out_dir, checksum
            job.key = job.options_key()
            rlog(job.start_line(len(paths), workers, scheduler, force))
            job.manifest = Manifest.load(out_dir)
            results, todo = job.plan(paths, unmatched, job.manifest, force, checksum, rlog)
            gen = job.outcomes(
                [paths[i] for i in todo],
                workers=workers,
                scheduler=scheduler,
                rlog=rlog,
                run_token=lock.token,
            )
            done = gen if progress is None else progress(gen, total=len(todo))
            pending: list[Any] = []
            interrupted = _collect(
                job, done, gen, todo, results, pending, rlog, fail_fast, commit_seconds
            )
            job.commit(pending)
            job.finish(interrupted, rlog)
            if job.manifest.changed:  # checksums added to entries recorded without one
                job.manifest.save()
            summary = job.summarise(
                [results[i] for i in sorted(results)],
                _time.perf_counter() - start,
                n_inputs=len(paths) + len(unmatched),
                log_path=rlog.path if log else None,
                workers=max(1, min(workers, len(todo))) if scheduler is None else workers,
            )
            rlog(summary.line())
            if interrupted:
                remove_stale_temporaries(out_dir)  # of the workers stopped mid-write
                rlog(
                    "interrupted (SIGINT or SIGTERM): finished inputs kept; a re-run does the rest"
                )
                raise Interrupted(summary)
            return summary
        finally:
            rlog.close()


def _collect(
    job: BatchJob,
    done: Iterable[tuple[int, Any]],
    gen: Any,
    todo: list[int],
    results: dict[int, Any],
    pending: list[Any],
    rlog: RunLog,
    fail_fast: bool,
    commit_seconds: float,
) -> bool:
    """Take the outcomes as they finish: write, log, commit every ``commit_seconds``.

    Outcomes not yet committed are left in ``pending`` for the caller.  Returns
    True when interrupted (Ctrl-C): what finished is kept, for the caller to commit.
    """
    last = _time.monotonic()
    try:
        for j, outcome in done:
            outcome = job.write(outcome)
            results[todo[j]] = outcome
            pending.append(outcome)
            job.log_outcome(outcome, rlog)
            if fail_fast and not outcome.ok:
                break
            if _time.monotonic() - last > commit_seconds:
                job.commit(pending)
                pending.clear()
                last = _time.monotonic()
    except KeyboardInterrupt:
        gen.close()  # stops the worker pool now if Ctrl-C came between results
        return True  # keep what finished: the caller commits it
    return False
