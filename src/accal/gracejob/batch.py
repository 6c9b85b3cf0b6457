"""A batch of ``accal grace-bias``: :func:`run`, with its manifest and table commits.

:func:`run` decides which inputs are due (the manifest and the table say which
are current), runs them (local workers, a dask scheduler, or the arcs of the
reference fit), and commits their rows and manifest records as they finish
(:func:`_commit`); :func:`options_key` is what the manifest compares.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import json
import os
import time as _time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import (
    Interrupted,
    Manifest,
    OutputLock,
    RunLog,
    execute,
    failure_message,
    file_signature,
    remove_stale_temporaries,
)
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
    start = _time.perf_counter()
    out_dir = Path(out_dir)
    paths = [Path(p) for p in paths]
    if not out_dir.exists() and not any(os.path.lexists(p) for p in paths):
        # nothing to read: each input fails without a new output directory, lock and log
        # being created for it (issue 23: a failed run left them behind)
        return _nothing_to_read(paths, unmatched, start)
    out_dir.mkdir(parents=True, exist_ok=True)
    if fail_fast:
        workers, scheduler = 1, None
    _check_table_format(out_dir, opts.fmt)
    with OutputLock(out_dir, "accal grace-bias") as lock:
        remove_stale_temporaries(out_dir)
        rlog = RunLog(out_dir, enabled=log)
        try:
            key = options_key(opts)
            rlog(
                f"start accal {__version__} grace-bias: {len(paths)} inputs, workers={workers}, "
                f"scheduler={scheduler if isinstance(scheduler, str | None) else 'client'}, "
                f"force={force}, options={json.dumps(key, sort_keys=True)}"
            )
            manifest = Manifest.load(out_dir)
            results, todo, table_path = _plan(
                paths, unmatched, out_dir, opts, manifest, key, force, checksum, rlog
            )
            commits = _Commits(out_dir, opts, manifest, key, checksum, table_path)
            if opts.arc != "day":
                # imported here: the reference fit's modules import scipy (~0.3 s of start-up)
                from accal.pipeline_arcs import arc_outcomes, redo_all

                if todo:  # an arc is fitted whole: any input to redo redoes all of them
                    todo = redo_all(todo, results, paths)
                gen = arc_outcomes([paths[i] for i in todo], out_dir, opts)
            else:
                task = functools.partial(
                    process_one, out_dir=out_dir, opts=opts, run_token=lock.token
                )
                gen = execute(
                    task,
                    [paths[i] for i in todo],
                    workers=workers,
                    scheduler=scheduler,
                    on_error=internal_error,
                    on_note=rlog,
                )
            done = gen if progress is None else progress(gen, total=len(todo))
            interrupted = _collect(
                done, gen, todo, results, commits, rlog, fail_fast, commit_seconds
            )
            table_path = commits.commit()
            if opts.pool_days and not interrupted:
                _pool_table(out_dir, opts, table_path, rlog)
            if manifest.changed:  # checksums added to entries recorded without one
                manifest.save()
            outcomes = [results[i] for i in sorted(results)]
            summary = RunSummary(
                outcomes,
                table_path,
                _time.perf_counter() - start,
                n_inputs=len(paths) + len(unmatched),
                log_path=rlog.path if log else None,
                workers=1
                if opts.arc != "day"
                else max(1, min(workers, len(todo)))
                if scheduler is None
                else workers,
            )
            rlog(summary.line())
            if interrupted:
                remove_stale_temporaries(out_dir)  # of the workers stopped mid-write
                rlog("interrupted (Ctrl-C): finished inputs kept; a re-run does the rest")
                raise Interrupted(summary)
            return summary
        finally:
            rlog.close()


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


class _Commits:
    """The outcomes not yet committed (:func:`_commit`), and when the last commit was."""

    def __init__(
        self,
        out_dir: Path,
        opts: GraceBiasOptions,
        manifest: Manifest,
        key: dict[str, Any],
        checksum: bool,
        table_path: Path | None,
    ) -> None:
        self.out_dir, self.opts, self.manifest = out_dir, opts, manifest
        self.key, self.checksum, self.table_path = key, checksum, table_path
        self.pending: list[FileOutcome] = []
        self.last = _time.monotonic()

    def commit(self) -> Path | None:
        """Commit the pending outcomes; the table's path (the earlier one if none written)."""
        self.table_path = (
            _commit(self.out_dir, self.opts, self.manifest, self.key, self.pending, self.checksum)
            or self.table_path
        )
        self.pending, self.last = [], _time.monotonic()
        return self.table_path


def _collect(
    done: Iterable[tuple[int, FileOutcome]],
    gen: Any,
    todo: list[int],
    results: dict[int, FileOutcome],
    commits: _Commits,
    rlog: RunLog,
    fail_fast: bool,
    commit_seconds: float,
) -> bool:
    """Take the outcomes as they finish, logging them and committing every ``commit_seconds``.

    Returns True when interrupted (Ctrl-C): what finished is kept, for the caller
    to commit.
    """
    opts, out_dir = commits.opts, commits.out_dir
    try:
        for j, outcome in done:
            if (
                not outcome.ok
                and (out_dir / f"{output_stem(outcome.path)}.calibrated.{opts.fmt}").exists()
            ):
                # processed by an earlier run: its outputs stay (nothing is lost),
                # and the user is told they come from the file's earlier version
                outcome = dataclasses.replace(outcome, kept_earlier=True)
            results[todo[j]] = outcome
            commits.pending.append(outcome)
            rlog(
                f"ok {outcome.path}: {outcome.n_samples} samples"
                if outcome.ok
                else f"FAILED {outcome.message}"
                + (f" ({KEPT_EARLIER})" if outcome.kept_earlier else "")
            )
            for w in outcome.warnings:
                rlog(f"warning {outcome.path}: {w}")
            if fail_fast and not outcome.ok:
                break
            if _time.monotonic() - commits.last > commit_seconds:
                commits.commit()
    except KeyboardInterrupt:
        gen.close()  # stops the worker pool now if Ctrl-C came between results
        return True  # keep what finished: the caller commits it
    return False


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
