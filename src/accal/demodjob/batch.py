"""The ``accal demod`` job: one run file (:func:`process_run`) and a batch (:func:`run_demod`).

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
stems collide are refused before anything runs.  One input into a directory that
already holds the summary of another run (one run per call, from cron) is named
after its stem too, so the earlier run's summary stays beside its rows.  An input's summaries and its
rows in the table are written together (temporary files renamed at the end):
either all of them appear or none (a failed input leaves the directory as it was).
"""

from __future__ import annotations

import contextlib
import os
import time as _time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch import (
    OutputLock,
    RunLog,
    check_input,
    failure_message,
    internal_error_message,
    remove_stale_temporaries,
)
from accal.demodjob.closure import close_run
from accal.demodjob.closure_outputs import apply_closure, write_demod_closure
from accal.demodjob.options import DemodOptions, DemodRunSummary, RunOutcome
from accal.demodjob.outputs import (
    check_output_format,
    json_text,
    output_paths,
    remove_stale_summaries,
)
from accal.demodjob.reading import estimate, load_psd
from accal.demodjob.report import summary_markdown, summary_warnings
from accal.demodjob.summary import summarise, summary_of_extended
from accal.demodjob.table import add_utc_columns, period_rows
from accal.errors import AccalError, ValidationError
from accal.io.merge import merge_table
from accal.io.writers import atomic_path


def process_run(
    path: Path, targets: tuple[Path, Path, Path], opts: DemodOptions, psd: Any
) -> RunOutcome:
    """read → validate → demodulate → write for one run file (all outputs or none).

    The run's rows are merged into the cumulative periods table (replacing the
    rows of an earlier run of the same source); the table and the run's two
    summaries are renamed into place together.

    Raises
    ------
    AccalError
        On bad input; nothing is written then.
    """
    res, info = estimate(path, opts, psd)
    rows, units = period_rows(res, path.name, info.units)
    summary = summarise(path, info, res, opts, out_dir=targets[1].parent)
    closure: dict[str, Any] | None = None
    plots: list[Path] = []
    if opts.close_loop:
        step = info.step if info.resample is not None else None
        used = res.noise.used if getattr(res, "noise", None) is not None else psd
        closure, extended, plots = close_run(path, opts, targets[0].parent, step=step, psd=used)
        rows, units = apply_closure(rows, units, extended)
        summary["closure"] = {
            k: closure[k] for k in ("effects", "unexplained", "rms_before", "rms_after", "model")
        }
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
        "summary": targets[1].name,  # the source's current summary (accal diagnose)
    }

    def table_meta(old: dict[str, Any]) -> dict[str, Any]:
        sources = dict(old.get("sources") or {})
        sources[path.name] = source_meta
        return {"accal_version": __version__, "sources": dict(sorted(sources.items()))}

    p_path, _, _ = targets
    with contextlib.ExitStack() as stack:
        tmp = [stack.enter_context(atomic_path(p)) for p in targets]
        merge_table(
            p_path,
            rows,
            key=("source",),
            sort=("source", "period"),
            fmt=opts.fmt,
            units=units,
            meta=table_meta,
            out=tmp[0],
        )
        add_utc_columns(tmp[0], p_path, opts.fmt)
        tmp[1].write_text(json_text(summary))
        tmp[2].write_text(summary_markdown(summary))
    remove_stale_summaries(targets[1].parent, path.name, targets[1])
    # without --close-loop an earlier closure of this source no longer applies (QA: its
    # report and plots stayed, and contradicted the periods written now)
    write_demod_closure(targets[0].parent, path.name, closure)
    return RunOutcome(
        path,
        True,
        outputs=(*targets, *plots),
        summary=summary,
        warnings=summary_warnings(summary),
    )


def run_demod(
    paths: Iterable[Path],
    out_dir: Path,
    opts: DemodOptions,
    *,
    progress: Callable[[Iterable[Path]], Iterable[Path]] | None = None,
    psd: Any = None,
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
        Wraps the iterable of paths (e.g. ``tqdm``).
    psd : PSD, optional
        The noise model already loaded from ``opts.psd`` (:func:`load_psd`).

    Returns
    -------
    DemodRunSummary

    Raises
    ------
    AccalError
        Before any input is processed: unreadable ``--psd`` table, colliding output
        names, a periods table of the other ``--format`` in ``out_dir``.
    """
    start = _time.perf_counter()
    paths = [Path(p) for p in paths]
    targets = output_paths(paths, out_dir, opts.fmt)
    check_output_format(out_dir, opts.fmt)
    if psd is None:
        psd = load_psd(opts.psd)
    outcomes: list[RunOutcome] = []
    pairs = list(zip(paths, targets, strict=True))
    if not out_dir.exists() and not any(os.path.lexists(p) for p in paths):
        # nothing to read: fail each without creating the output directory, its lock
        # and log (issue 23: a failed `accal demod run1.parquet` left them behind)
        missing = [RunOutcome(p, False, failure_message(p, ValidationError("no such file")))
                   for p in paths]  # fmt: skip
        return DemodRunSummary(missing, _time.perf_counter() - start)
    out_dir.mkdir(parents=True, exist_ok=True)
    # one writer per output directory (the cumulative periods table); a killed
    # run's temporary files are removed under the lock
    with OutputLock(out_dir, "accal demod"):
        remove_stale_temporaries(out_dir)
        log = RunLog(out_dir)
        try:
            log(f"start accal demod: {len(paths)} runs, options={opts}")
            for path, tgt in progress(pairs, total=len(pairs)) if progress else pairs:
                try:
                    check_input(path)
                    outcomes.append(process_run(path, tgt, opts, psd))
                except AccalError as exc:
                    outcomes.append(RunOutcome(path, False, failure_message(path, exc)))
                except Exception as exc:  # a bug, not bad input: keep the batch going
                    outcomes.append(RunOutcome(path, False, internal_error_message(path, exc)))
                o = outcomes[-1]
                log(f"ok {path}" if o.ok else f"FAILED {o.message}")
                for w in o.warnings:  # in the log too: `-q` keeps them off the terminal
                    log(f"warning {path}: {w}")
            summary = DemodRunSummary(outcomes, _time.perf_counter() - start)
            log(
                f"accal demod: {summary.n_ok} ok, {summary.n_failed} failed in {summary.seconds:.2f} s"
            )
            return summary
        finally:
            log.close()
