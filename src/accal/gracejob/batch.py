"""A batch of ``accal grace-bias``: :func:`run`, with its manifest and table commits.

:func:`run` is the shared runner (:func:`accal.batch_runner.run_batch`) with the
steps of :class:`GraceBiasJob`: it decides which inputs are due (the manifest and
the table say which are current), runs them (local workers or a dask scheduler; with
``--arc`` an arc of inputs per task), and commits their rows and manifest records as
they finish (:func:`_commit`); :func:`options_key` is what the manifest compares.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import json
import os
import time as _time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from accal.batch import Manifest, RunLog, failure_message, file_signature
from accal.batch_runner import BatchJob, run_batch
from accal.errors import AccalError, ValidationError
from accal.gracejob.options import GraceBiasOptions
from accal.gracejob.outcome import KEPT_EARLIER, FileOutcome, RunSummary, internal_error
from accal.gracejob.outputs import file_size, output_stem
from accal.gracejob.process import process_one
from accal.gracejob.table import merge_bias_drift, read_bias_drift_arrow
from accal.io.writers import sync_files


def options_key(opts: GraceBiasOptions) -> dict[str, Any]:
    """The options as a canonical JSON-able dict (what the manifest compares).

    Files named in the options (reference, aux, truth) enter with their size and
    mtime, so changing them makes the inputs out of date.  Without ``close_loop``
    its settings (``alpha``, ``orbit_period``, ``plots``) are left out: they change nothing.
    """
    d = asdict(opts)
    # outputs differ only in whether the noise spectra are saved; the pooling itself
    # is redone over the whole table after every run
    if d.pop("pool_days"):
        d["noise_spectra"] = True
    if not opts.reference_fit:  # settings of the reference fit alone change nothing without it
        for k in (
            "bias_basis",
            "thrusters",
            "thruster_margins",
            "reference_frame",
            "attitude",
            "arc",
        ):
            d.pop(k)
    if not opts.close_loop:  # settings of the closure alone change nothing without it
        for k in ("alpha", "orbit_period", "plots"):
            d.pop(k)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            try:
                d[k] = {"path": os.path.realpath(v), **file_signature(v)}
            except OSError:
                d[k] = {"path": str(v)}
        elif isinstance(v, tuple):
            d[k] = list(v)
    return json.loads(json.dumps(d, sort_keys=True))


def run(
    paths: Iterable[Path],
    out_dir: Path,
    opts: GraceBiasOptions,
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
) -> RunSummary:
    """Process every input into ``out_dir``; failures are recorded, not raised.

    The batch is :func:`accal.batch_runner.run_batch` with the steps of
    :class:`GraceBiasJob`.

    Parameters
    ----------
    paths : iterable of Path
        Inputs (already expanded, see :func:`accal.batch.discover`).
    out_dir : Path
        Output directory (created).  It holds the cumulative ``bias_drift``
        table, a manifest, a log and a lock file.
    opts : GraceBiasOptions
        Options.
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
        How often the table and manifest are committed during a batch [s]
        (also at the end): a killed batch loses at most this much work.
    log : bool
        Append to ``out_dir/accal.log``.
    unmatched : sequence of (Path, str)
        Command-line inputs that expanded to no file, with their one-line message
        (``problems`` of :func:`accal.batch.discover`): counted and logged as failed.

    Returns
    -------
    RunSummary

    Raises
    ------
    accal.batch.LockedError
        If another run holds the output directory.
    """
    return run_batch(
        GraceBiasJob(opts),
        paths,
        out_dir,
        fail_fast=fail_fast,
        progress=progress,
        workers=workers,
        scheduler=scheduler,
        force=force,
        checksum=checksum,
        commit_seconds=commit_seconds,
        log=log,
        unmatched=unmatched,
    )


class GraceBiasJob(BatchJob):
    """The steps of a ``grace-bias`` batch (:class:`accal.batch_runner.BatchJob`).

    Parameters
    ----------
    opts : GraceBiasOptions
        Options.
    """

    command = "grace-bias"

    def __init__(self, opts: GraceBiasOptions) -> None:
        self.opts = opts
        self.table_path: Path | None = None

    def options_key(self) -> dict[str, Any]:
        """:func:`options_key` of the options."""
        return options_key(self.opts)

    def nothing_to_read(
        self, paths: list[Path], unmatched: Sequence[tuple[Path, str]], seconds: float
    ) -> RunSummary:
        """Each input failed (none exists)."""
        return _nothing_to_read(paths, unmatched, seconds)

    def check_out_dir(self, out_dir: Path) -> None:
        """Refuse a directory with a ``bias_drift`` table of the other format."""
        _check_table_format(out_dir, self.opts.fmt)

    def plan(
        self,
        paths: list[Path],
        unmatched: Sequence[tuple[Path, str]],
        manifest: Manifest,
        force: bool,
        checksum: bool,
        rlog: RunLog,
    ) -> tuple[dict[int, FileOutcome], list[int]]:
        """Unmatched, clashing and current inputs are settled; the others run."""
        results, todo, self.table_path = _plan(
            paths, unmatched, self.out_dir, self.opts, manifest, self.key, force, checksum, rlog
        )
        if self.opts.arc != "day" and todo:
            # an arc is fitted whole: any input to redo redoes all of them (imported
            # here: the reference fit's modules import scipy, ~0.3 s of start-up)
            from accal.pipeline_arcs import redo_all

            todo = redo_all(todo, results, paths)
        return results, todo

    def task(self, run_token: str | None) -> Callable[[Path], FileOutcome]:
        """:func:`accal.gracejob.process.process_one` with the options."""
        return functools.partial(
            process_one, out_dir=self.out_dir, opts=self.opts, run_token=run_token
        )

    def internal_error(self, path: Path, exc: BaseException) -> FileOutcome:
        """A failed outcome naming the bug or the dead worker."""
        return internal_error(path, exc)

    def outcomes(
        self,
        paths: list[Path],
        *,
        workers: int,
        scheduler: Any,
        rlog: RunLog,
        run_token: str | None,
    ) -> Iterator[tuple[int, FileOutcome]]:
        """The inputs' outcomes; with ``--arc``, the arcs' (each arc one task, fitted whole).

        The arcs run on the same workers as the inputs of a day-by-day batch
        (:func:`accal.pipeline_arcs.arc_outcomes`: the inputs are read in parallel,
        grouped here, then fitted an arc per task).
        """
        if self.opts.arc == "day":
            return super().outcomes(
                paths, workers=workers, scheduler=scheduler, rlog=rlog, run_token=run_token
            )
        # imported here: the reference fit's modules import scipy (~0.3 s of start-up)
        from accal.pipeline_arcs import arc_outcomes

        return arc_outcomes(
            paths,
            self.out_dir,
            self.opts,
            workers=workers,
            scheduler=scheduler,
            on_note=rlog,
            run_token=run_token,
        )

    def write(self, outcome: FileOutcome) -> FileOutcome:
        """A failed input whose calibrated file is there keeps its earlier outputs."""
        if (
            not outcome.ok
            and (self.out_dir / f"{output_stem(outcome.path)}.calibrated.{self.opts.fmt}").exists()
        ):
            # processed by an earlier run: its outputs stay (nothing is lost),
            # and the user is told they come from the file's earlier version
            outcome = dataclasses.replace(outcome, kept_earlier=True)
        return outcome

    def log_outcome(self, outcome: FileOutcome, rlog: RunLog) -> None:
        """``ok FILE: N samples`` or ``FAILED ...``, and the warnings."""
        rlog(
            f"ok {outcome.path}: {outcome.n_samples} samples"
            if outcome.ok
            else f"FAILED {outcome.message}"
            + (f" ({KEPT_EARLIER})" if outcome.kept_earlier else "")
        )
        for w in outcome.warnings:
            rlog(f"warning {outcome.path}: {w}")

    def commit(self, outcomes: list[FileOutcome]) -> None:
        """Merge the outcomes' rows into the table, then record them (:func:`_commit`)."""
        self.table_path = (
            _commit(self.out_dir, self.opts, self.manifest, self.key, outcomes, self.checksum)
            or self.table_path
        )

    def finish(self, interrupted: bool, rlog: RunLog) -> None:
        """``--pool-days``: the pooled σ over the whole table."""
        if self.opts.pool_days and not interrupted:
            _pool_table(self.out_dir, self.opts, self.table_path, rlog)

    def summarise(
        self,
        outcomes: list[FileOutcome],
        seconds: float,
        *,
        n_inputs: int,
        log_path: Path | None,
        workers: int,
    ) -> RunSummary:
        """The :class:`RunSummary` of the outcomes."""
        return RunSummary(
            outcomes,
            self.table_path,
            seconds,
            n_inputs=n_inputs,
            log_path=log_path,
            workers=workers,
        )


def _nothing_to_read(
    paths: list[Path], unmatched: Sequence[tuple[Path, str]], start: float
) -> RunSummary:
    """The summary of a run none of whose inputs exists: each one failed."""
    gone = [FileOutcome(Path(p), False, msg) for p, msg in unmatched]
    gone += [
        FileOutcome(p, False, failure_message(p, ValidationError("no such file"))) for p in paths
    ]
    return RunSummary(gone, None, _time.perf_counter() - start, n_inputs=len(gone))


def _check_table_format(out_dir: Path, fmt: str) -> None:
    """Refuse a directory whose ``bias_drift`` table is of the other format."""
    other = "csv" if fmt == "parquet" else "parquet"
    if (out_dir / f"bias_drift.{other}").exists():
        raise AccalError(
            f"{out_dir} holds bias_drift.{other} of --format {other} runs; use --format "
            f"{other} there, or another --out for {fmt}"
        )


def _plan(
    paths: list[Path],
    unmatched: Sequence[tuple[Path, str]],
    out_dir: Path,
    opts: GraceBiasOptions,
    manifest: Manifest,
    key: dict[str, Any],
    force: bool,
    checksum: bool,
    rlog: RunLog,
) -> tuple[dict[int, FileOutcome], list[int], Path | None]:
    """Decide what each input needs: ``(results so far, indices to run, table path)``.

    ``results`` holds the inputs already settled (unmatched, output clash, current),
    keyed by input index (the unmatched ones by negative indices, ahead of the
    inputs); the others are to run.
    """
    results: dict[int, FileOutcome] = {}
    for k, (p, msg) in enumerate(unmatched):  # expanded to nothing: a failure
        results[k - len(unmatched)] = FileOutcome(Path(p), False, msg)
        rlog(f"FAILED {msg}")
    # an input is current only if its rows are still in the table: a deleted
    # or replaced table (QA: deleted, or overwritten by a filtered export) has
    # its inputs redone instead of skipped with no rows; a damaged one stops
    # the run here, every run, with its message (not only when work is due)
    table_path = _table_if_exists(out_dir, opts.fmt)
    tabled = collections.Counter(
        read_bias_drift_arrow(table_path).column("source").to_pylist()
        if table_path is not None
        else ()
    )
    todo: list[int] = []
    owners: dict[str, Path] = {}
    for i, p in enumerate(paths):
        stem = output_stem(p)
        # a missing or empty input fails without writing: it claims no outputs
        claims = p.is_file() and file_size(p) > 0
        if claims and owners.setdefault(stem, p) is not p:
            results[i] = FileOutcome(
                p,
                False,
                f"{p}: would write the same outputs ({stem}.*) as {owners[stem]} "
                "in this run; rename one or give it another --out",
            )
            rlog(f"FAILED {results[i].message}")
        elif (
            not force
            and tabled[p.name] >= manifest.entries.get(manifest.key(p), {}).get("n_rows", 1)
            and manifest.is_current(p, key, checksum=checksum)
        ):
            results[i] = FileOutcome(p, True, skipped=True)
            rlog(f"skip {p}: outputs current")
        else:
            todo.append(i)
    return results, todo, table_path


def _table_if_exists(out_dir: Path, fmt: str) -> Path | None:
    p = out_dir / f"bias_drift.{fmt}"
    return p if p.exists() else None


def _commit(
    out_dir: Path,
    opts: GraceBiasOptions,
    manifest: Any,
    key: dict[str, Any],
    outcomes: list[FileOutcome],
    checksum: bool,
) -> Path | None:
    """Merge the rows of ``outcomes`` into the table, then record them in the manifest.

    The order matters for crash safety: an input is recorded only once its
    outputs are on disk (one ``syncfs`` for the whole commit, see
    :func:`accal.io.writers.sync_files`) and its rows are in the table; an input
    with rows but no record is redone (and its rows replaced, never duplicated).
    """
    if not outcomes:
        return None
    sync_files(p for o in outcomes if o.ok for p in o.outputs)
    rows = [r for o in outcomes if o.ok for r in o.rows]
    # inputs of earlier runs whose outputs these took over (same name from another
    # directory, x.dat after x.asc): their records and rows go, they are no longer here
    displaced = {
        k: e
        for o in outcomes
        if o.ok
        for k, e in manifest.sharing_outputs(o.path, o.outputs).items()
    }
    new_sources = {o.path.name for o in outcomes if o.ok}
    drop = {e.get("source") for e in displaced.values()} - new_sources - {None}
    table = merge_bias_drift(out_dir, rows, opts.fmt, drop) if rows or drop else None
    for k in displaced:
        manifest.entries.pop(k, None)
    for o in outcomes:
        if o.ok:
            manifest.record(
                o.path,
                key,
                o.outputs,
                o.path.name,
                checksum=checksum,
                before=o.signature,
                n_rows=len(o.rows),
            )
        else:
            manifest.entries.pop(manifest.key(o.path), None)
    manifest.save()
    return table


def _pool_table(out_dir: Path, opts: GraceBiasOptions, table_path: Path | None, rlog) -> None:
    """Give the ``bias_drift`` rows pooled σ (``--pool-days``, :mod:`accal.pooling`)."""
    if table_path is None:
        return
    # imported here: accal.pooling imports scipy (~0.3 s of start-up), for --pool-days only
    from accal.pooling import pool_rows

    table = read_bias_drift_arrow(table_path)
    rows = table.to_pylist()
    stems = {r["source"]: output_stem(Path(r["source"])) for r in rows}
    n = pool_rows(rows, out_dir, stems, opts.pool_days)
    merge_bias_drift(out_dir, rows, opts.fmt)
    rlog(f"pooled sigmas (--pool-days {opts.pool_days}): {n} of {len(rows)} rows")
