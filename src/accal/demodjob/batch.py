"""The ``accal demod`` job: one run file (:func:`process_run`) and a batch (:func:`run_demod`).

A batch is the shared runner (:func:`accal.batch_runner.run_batch`) with the
steps of :class:`DemodJob`: the manifest skips runs whose file and options did
not change (and whose outputs and rows are there), the runs are demodulated in
this process, on local worker processes (``-j``) or on a dask.distributed
cluster (``--scheduler``) by :func:`demod_task` (:func:`compute_run`), and each
run's outputs are written here as it completes (:func:`write_run`), then recorded
in the manifest.

Outputs of :func:`run_demod`
----------------------------
``DIR/periods.<fmt>``: one cumulative table, one row per source and period, with
a ``source`` column (the input's file name).  Every run merges its rows into it;
a re-run of a source replaces that source's rows (never duplicates them).  The
options, solver and Rd of every source are in the table metadata
(``accal.meta["sources"]``).

Summaries: with one input ``DIR/summary.json`` and ``DIR/summary.md``; with
several ``DIR/<stem>.summary.json`` and ``DIR/<stem>.summary.md`` where ``<stem>``
is the input name without its suffixes (``run1.csv.gz`` → ``run1``); inputs whose
stems collide (or whose file names do) fail, each but the first, with a one-line
message; the others run.  One input into a directory that
already holds the summary of another run (one run per call, from cron) is named
after its stem too, so the earlier run's summary stays beside its rows.  An input's summaries and its
rows in the table are written together (temporary files renamed at the end):
either all of them appear or none (a failed input leaves the directory as it was).

``DIR/manifest.json``, ``DIR/accal.log`` and ``DIR/.accal.lock``: what was
processed with which options (incremental re-runs), the run log, the lock (as
``grace-bias``'s, :mod:`accal.batch`).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import functools
import json
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import (
    LOCK,
    Manifest,
    RunLog,
    check_input,
    failure_message,
    file_signature,
    internal_error_message,
    write_error_message,
)
from accal.batch_runner import BatchJob, run_batch, scheduler_name
from accal.batch_summary import peak_rss_mb, reset_peak_rss
from accal.demodjob.closure import close_run, closure_summary
from accal.demodjob.closure_outputs import (
    apply_closure,
    leak_of,
    misfit_of,
    write_demod_closure,
)
from accal.demodjob.options import DemodOptions, DemodResult, DemodRunSummary, RunOutcome
from accal.demodjob.outputs import (
    check_output_format,
    json_text,
    output_paths,
    remove_stale_summaries,
    stem_clashes,
)
from accal.demodjob.reading import estimate, load_psd
from accal.demodjob.report import summary_markdown, summary_warnings
from accal.demodjob.summary import summarise, summary_of_extended
from accal.demodjob.table import add_utc_columns, period_rows
from accal.errors import AccalError, ValidationError
from accal.io.merge import merge_table
from accal.io.writers import atomic_path, run_guard

#: The periods table's three outputs of a run: (periods table, summary.json, summary.md).
Targets = tuple[Path, Path, Path]


def compute_run(path: Path, out_dir: Path, opts: DemodOptions, psd: Any) -> RunOutcome:
    """read → validate → demodulate one run file; nothing is written but closure plots.

    The outcome carries the run's rows, summary and closure (``result``) for
    :func:`write_run`.

    Raises
    ------
    AccalError
        On bad input.
    """
    res, info = estimate(path, opts, psd)
    rows, units = period_rows(res, path.name, info.units)
    summary = summarise(path, info, res, opts, out_dir=out_dir)
    closure: dict[str, Any] | None = None
    plots: list[Path] = []
    if opts.close_loop:
        step = info.step if info.resample is not None else None
        used = res.noise.used if getattr(res, "noise", None) is not None else psd
        closure, extended, plots = close_run(path, opts, out_dir, step=step, psd=used)
        rows, units = apply_closure(rows, units, extended, leak_of(res, opts), misfit_of(res))
        summary["closure"] = closure_summary(closure)
        summary_of_extended(summary, rows, closure["model"])
    history = []
    if info.resample is not None:
        history.append(
            f"accal {__version__}: resample_uniform(step={info.step:.9g}, "
            f"gap_factor={opts.gap_factor:g})"
        )
    history.append(f"accal {__version__}: demodulate")
    source_meta = {
        "tau": opts.tau,
        "mask": opts.mask,
        "method": opts.method,
        "solver": res.solver,
        "signal_model": opts.signal_model,
        "bias_model": opts.bias_model,
        "psd": opts.psd,
        "Rd": summary["Rd"],
        "n_periods": res.n_periods,
        "n_kept": int(res.a_Y.size),
        "accal_version": __version__,
        "history": history,
    }
    return RunOutcome(
        path,
        True,
        outputs=tuple(plots),
        summary=summary,
        warnings=summary_warnings(summary),
        n_samples=int(info.n_samples),
        n_rows=len(rows["period"]),
        result=DemodResult(rows, units, source_meta, closure),
    )


def write_run(outcome: RunOutcome, targets: Targets, fmt: str) -> RunOutcome:
    """Write a computed run (:func:`compute_run`): its rows, summaries, closure (all or none).

    The run's rows are merged into the cumulative periods table (replacing the
    rows of an earlier run of the same source); the table and the run's two
    summaries are renamed into place together.

    Returns
    -------
    RunOutcome
        With the outputs written, and without ``result``.
    """
    res = outcome.result
    if res is None:
        raise ValueError(f"{outcome.path}: nothing computed to write")
    path = outcome.path
    # the source's current summary (accal diagnose), last as it always was
    source_meta = {**res.source_meta, "summary": targets[1].name}

    def table_meta(old: dict[str, Any]) -> dict[str, Any]:
        sources = dict(old.get("sources") or {})
        sources[path.name] = source_meta
        return {"accal_version": __version__, "sources": dict(sorted(sources.items()))}

    p_path, _, _ = targets
    with contextlib.ExitStack() as stack:
        tmp = [stack.enter_context(atomic_path(p)) for p in targets]
        merge_table(
            p_path,
            res.rows,
            key=("source",),
            sort=("source", "period"),
            fmt=fmt,
            units=res.units,
            meta=table_meta,
            out=tmp[0],
        )
        add_utc_columns(tmp[0], p_path, fmt)
        tmp[1].write_text(json_text(outcome.summary))
        tmp[2].write_text(summary_markdown(outcome.summary))
    remove_stale_summaries(targets[1].parent, path.name, targets[1])
    # without --close-loop an earlier closure of this source no longer applies (QA: its
    # report and plots stayed, and contradicted the periods written now)
    write_demod_closure(targets[0].parent, path.name, res.closure)
    return dataclasses.replace(outcome, outputs=(*targets, *outcome.outputs), result=None)


def process_run(path: Path, targets: Targets, opts: DemodOptions, psd: Any) -> RunOutcome:
    """read → validate → demodulate → write for one run file (all outputs or none).

    :func:`compute_run` then :func:`write_run`, in this process.

    Raises
    ------
    AccalError
        On bad input; nothing is written then.
    """
    return write_run(compute_run(path, targets[1].parent, opts, psd), targets, opts.fmt)


def demod_task(
    path: Path, out_dir: Path, opts: DemodOptions, psd: Any, run_token: str | None = None
) -> RunOutcome:
    """:func:`compute_run` with every failure turned into a one-line :class:`RunOutcome`.

    Module-level and picklable: the task the worker processes and the dask
    workers run.  ``run_token``: the lock token of the submitting run; the closure
    plots are renamed into ``out_dir`` only while that run holds the lock
    (:func:`accal.io.writers.run_guard`).
    """
    path = Path(path)
    reset_peak_rss()  # the run's peak, not the worker's lifetime one (a Dask worker's)
    with run_guard(Path(out_dir) / LOCK if run_token else None, run_token):
        try:
            check_input(path)
            try:  # before the read: a run replaced while it is processed is redone next time
                before: dict[str, Any] | None = file_signature(path)
            except OSError:
                before = None
            outcome = compute_run(path, Path(out_dir), opts, psd)
            outcome = dataclasses.replace(
                outcome, signature=before, n_bytes=before["size"] if before else 0
            )
        except AccalError as exc:
            outcome = RunOutcome(path, False, failure_message(path, exc))
        except Exception as exc:  # a bug, not bad input: keep the batch going
            outcome = RunOutcome(path, False, internal_error_message(path, exc))
    return dataclasses.replace(outcome, peak_rss=peak_rss_mb())


def options_key(opts: DemodOptions) -> dict[str, Any]:
    """The options as a canonical JSON-able dict (what the manifest compares).

    A ``--psd`` table enters with its size and mtime, so changing it makes the
    runs out of date.  ``chunk_rows`` changes nothing (the results do not depend
    on it); without ``close_loop`` neither do ``alpha`` and ``plots``.
    """
    d = asdict(opts)
    d.pop("chunk_rows")
    if not opts.close_loop:
        for k in ("alpha", "plots"):
            d.pop(k)
    if str(opts.psd).lower() not in ("auto", "microstar"):
        try:
            d["psd"] = {"path": os.path.realpath(opts.psd), **file_signature(Path(opts.psd))}
        except OSError:
            d["psd"] = {"path": str(opts.psd)}
    return json.loads(json.dumps(d, sort_keys=True))


def run_demod(
    paths: Iterable[Path],
    out_dir: Path,
    opts: DemodOptions,
    *,
    progress: Callable[..., Iterable[Any]] | None = None,
    psd: Any = None,
    workers: int = 1,
    scheduler: str | Any | None = None,
    force: bool = False,
    checksum: bool = False,
    commit_seconds: float = 15.0,
) -> DemodRunSummary:
    """Demodulate every run file; failures are recorded, not raised.

    Parameters
    ----------
    paths : iterable of Path
        Run files.
    out_dir : Path
        Output directory (created).
    opts : DemodOptions
        Options.
    progress : callable, optional
        ``progress(iterable, total=N)`` wraps the completions (e.g. ``tqdm``).
    psd : PSD, optional
        The noise model already loaded from ``opts.psd`` (:func:`load_psd`).
    workers : int
        Local worker processes; the outputs are identical to a serial run.
    scheduler : str or distributed.Client, optional
        A dask.distributed scheduler to run on instead of local workers (its
        workers must see the same file system).
    force : bool
        Redo runs that the manifest says are current.
    checksum : bool
        Compare run files by SHA-256 instead of size and mtime.
    commit_seconds : float
        How often the manifest is saved during a batch [s] (also at the end).

    Returns
    -------
    DemodRunSummary

    Raises
    ------
    AccalError
        Before any input is processed: unreadable ``--psd`` table, a run given
        twice, a periods table of the other ``--format`` in ``out_dir``, another
        run holding ``out_dir`` (:class:`accal.batch.LockedError`).
    accal.batch.Interrupted
        On Ctrl-C, after writing the runs that finished.
    """
    paths = [Path(p) for p in paths]
    targets = output_paths(paths, out_dir, opts.fmt)
    check_output_format(out_dir, opts.fmt)
    if psd is None:
        psd = load_psd(opts.psd)
    job = DemodJob(opts, psd, dict(zip(paths, targets, strict=True)), stem_clashes(paths))
    return run_batch(
        job,
        paths,
        out_dir,
        progress=progress,
        workers=workers,
        scheduler=scheduler,
        force=force,
        checksum=checksum,
        commit_seconds=commit_seconds,
    )


class DemodJob(BatchJob):
    """The steps of an ``accal demod`` batch (:class:`accal.batch_runner.BatchJob`).

    Parameters
    ----------
    opts : DemodOptions
        Options.
    psd : PSD
        The a-priori noise model (:func:`load_psd`).
    targets : dict
        ``(periods table, summary.json, summary.md)`` of each run
        (:func:`accal.demodjob.outputs.output_paths`).
    clashes : dict, optional
        The runs another run of the call writes the outputs of, with their messages
        (:func:`accal.demodjob.outputs.stem_clashes`): failed, not run.
    """

    command = "demod"

    def __init__(
        self,
        opts: DemodOptions,
        psd: Any,
        targets: dict[Path, Targets],
        clashes: dict[Path, str] | None = None,
    ) -> None:
        self.opts, self.psd, self.targets = opts, psd, targets
        self.clashes = dict(clashes or {})

    def options_key(self) -> dict[str, Any]:
        """:func:`options_key` of the options."""
        return options_key(self.opts)

    def start_line(self, n_inputs: int, workers: int, scheduler: Any, force: bool) -> str:
        """``start accal demod: N runs, ...`` (the version, workers, options)."""
        return (
            f"start accal demod: {n_inputs} runs, accal {__version__}, workers={workers}, "
            f"scheduler={scheduler_name(scheduler)}, force={force}, "
            f"options={json.dumps(self.key, sort_keys=True)}"
        )

    def nothing_to_read(
        self, paths: list[Path], unmatched: Sequence[tuple[Path, str]], seconds: float
    ) -> DemodRunSummary:
        """Each run failed (none exists); nothing is created."""
        missing = [RunOutcome(p, False, failure_message(p, ValidationError("no such file")))
                   for p in paths]  # fmt: skip
        return DemodRunSummary(missing, None, seconds, n_inputs=len(paths))

    def check_out_dir(self, out_dir: Path) -> None:
        """Refuse a periods table of the other ``--format``."""
        check_output_format(out_dir, self.opts.fmt)

    def plan(
        self,
        paths: list[Path],
        unmatched: Sequence[tuple[Path, str]],
        manifest: Manifest,
        force: bool,
        checksum: bool,
        rlog: RunLog,
    ) -> tuple[dict[int, RunOutcome], list[int]]:
        """A run is skipped when the manifest says it is current, its outputs are those
        this call would write and its rows are in the periods table; the others run."""
        results: dict[int, RunOutcome] = {}
        todo: list[int] = []
        tabled: collections.Counter[str] | None = None
        for i, p in enumerate(paths):
            if p in self.clashes:  # another input of this call writes its outputs
                results[i] = RunOutcome(p, False, self.clashes[p])
                rlog(f"FAILED {self.clashes[p]}")
                continue
            entry = manifest.entries.get(manifest.key(p)) if not force else None
            names = {t.name for t in self.targets[p]}
            if (
                entry is not None
                and names <= set(entry.get("outputs", ()))
                and manifest.is_current(p, self.key, checksum=checksum)
            ):
                if tabled is None:  # a deleted or replaced table: its runs are redone
                    tabled = self._tabled()
                if tabled[p.name] >= entry.get("n_rows", 1):
                    results[i] = RunOutcome(p, True, skipped=True)
                    rlog(f"skip {p}: outputs current")
                    continue
            todo.append(i)
        return results, todo

    def _tabled(self) -> collections.Counter[str]:
        """Rows per source in the periods table (none when it is missing or unreadable)."""
        table = self.out_dir / f"periods.{self.opts.fmt}"
        try:
            if self.opts.fmt == "parquet":
                import pyarrow.parquet as pq

                with pq.ParquetFile(table) as pf:  # one thread: see io.table_parse
                    sources = pf.read(columns=["source"], use_threads=False)
                sources = sources.column("source").to_pylist()
            else:
                import pandas as pd

                sources = pd.read_csv(table, usecols=["source"], comment="#")["source"].tolist()
        except (OSError, ValueError, KeyError):
            return collections.Counter()
        return collections.Counter(sources)

    def task(self, run_token: str | None) -> Callable[[Path], RunOutcome]:
        """:func:`demod_task` with the options and the PSD."""
        return functools.partial(
            demod_task, out_dir=self.out_dir, opts=self.opts, psd=self.psd, run_token=run_token
        )

    def internal_error(self, path: Path, exc: BaseException) -> RunOutcome:
        """A failed outcome naming the bug or the dead worker."""
        return RunOutcome(Path(path), False, internal_error_message(path, exc))

    def write(self, outcome: RunOutcome) -> RunOutcome:
        """Write a computed run's rows, summaries and closure (:func:`write_run`)."""
        if not outcome.ok or outcome.result is None:
            return outcome
        path = outcome.path
        try:
            return write_run(outcome, self.targets[path], self.opts.fmt)
        except AccalError as exc:
            message = failure_message(path, exc)
        except OSError as exc:  # disk full, permissions, ...
            message = write_error_message(path, exc)
        except Exception as exc:  # a bug, not bad input: keep the batch going
            message = internal_error_message(path, exc)
        return RunOutcome(path, False, message, peak_rss=outcome.peak_rss)

    def commit(self, outcomes: list[RunOutcome]) -> None:
        """Record the written runs in the manifest, forget the failed ones.

        A run's outputs and rows are on disk before it is recorded; a run of another
        directory whose rows (same file name, the table's ``source``) this one
        replaced is forgotten, so re-running it redoes it.
        """
        manifest = self.manifest
        changed = False
        for o in outcomes:
            if o.ok and not o.skipped:
                me = manifest.key(o.path)
                for k in [
                    k for k, e in manifest.entries.items()
                    if k != me and e.get("source") == o.path.name
                ]:  # fmt: skip
                    del manifest.entries[k]
                closure = ("closure.json", "closure.md") if self.opts.close_loop else ()
                manifest.record(
                    o.path,
                    self.key,
                    [*o.outputs, *closure],
                    o.path.name,
                    checksum=self.checksum,
                    before=o.signature,
                    n_rows=o.n_rows,
                )
                changed = True
            elif not o.ok:
                changed |= manifest.entries.pop(manifest.key(o.path), None) is not None
        if changed:
            manifest.save()

    def summarise(
        self,
        outcomes: list[RunOutcome],
        seconds: float,
        *,
        n_inputs: int,
        log_path: Path | None,
        workers: int,
    ) -> DemodRunSummary:
        """The :class:`DemodRunSummary` (its table: the periods table, if there)."""
        table = self.out_dir / f"periods.{self.opts.fmt}"
        return DemodRunSummary(
            outcomes,
            table if table.exists() else None,
            seconds,
            n_inputs=n_inputs,
            log_path=log_path,
            workers=workers,
        )
