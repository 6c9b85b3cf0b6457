"""The files of an ``accal demod`` output directory: names, checks, summaries on disk.

``DIR/periods.<fmt>`` is one cumulative table for every input.  Summaries: with
one input ``DIR/summary.json`` and ``DIR/summary.md``; with several
``DIR/<stem>.summary.json`` and ``DIR/<stem>.summary.md`` (see
:mod:`accal.demodjob.batch`).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from accal.errors import ValidationError
from accal.gracejob.outputs import nan_to_none
from accal.io.writers import json_default
from accal.pipeline import output_stem


def json_text(obj: Any) -> str:
    """``obj`` as the text of a standard JSON file (non-finite floats as null, indented).

    The conventions of the JSON files grace-bias writes
    (:func:`accal.gracejob.outputs.nan_to_none`, :func:`accal.io.writers.json_default`).
    """
    return json.dumps(nan_to_none(obj), indent=2, default=json_default) + "\n"


def check_distinct_runs(paths: Sequence[Path]) -> None:
    """Refuse a run file given more than once (also under another name or via a link).

    Parameters
    ----------
    paths : sequence of Path
        The run files, as given.

    Raises
    ------
    ValidationError
        One line naming the file given twice.
    """
    seen: dict[Path, Path] = {}
    for p in map(Path, paths):
        try:
            key = p.resolve()
        except (RuntimeError, OSError):  # a symlink loop: the reader says so, per run
            key = Path(os.path.abspath(p))
        if key in seen:
            what = f"run {p} is given twice"
            if seen[key] != p:
                what = f"runs {seen[key]} and {p} are the same file"
            raise ValidationError(f"{what}; give each run once")
        seen[key] = p


def output_paths(paths: Sequence[Path], out_dir: Path, fmt: str) -> list[tuple[Path, Path, Path]]:
    """``(periods table, summary.json, summary.md)`` of each input (see :mod:`accal.demodjob.batch`).

    The periods table is the same cumulative ``DIR/periods.<fmt>`` for every input.
    An input whose summaries (or ``source`` rows) another input of the call would
    write too gets the same names: :func:`stem_clashes` says which, and the batch
    fails it alone.

    Raises
    ------
    ValidationError
        A run given twice (:func:`check_distinct_runs`).
    """
    check_distinct_runs(paths)
    table = out_dir / f"periods.{fmt}"
    if len(paths) == 1 and not _summaries_of_other_runs(out_dir, Path(paths[0]).name):
        return [(table, out_dir / "summary.json", out_dir / "summary.md")]
    out = []
    for p in paths:
        stem = output_stem(Path(p))
        out.append((table, out_dir / f"{stem}.summary.json", out_dir / f"{stem}.summary.md"))
    return out


def stem_clashes(paths: Sequence[Path]) -> dict[Path, str]:
    """The inputs that would write the summaries (``<stem>.summary.*``) or the ``source``
    rows (the file name) of an earlier input of the same call, each with its one-line
    message; the first of each stem is not among them.

    ``grace-bias`` fails such an input alone; ``demod`` refused the whole call before
    2026-11-30 (QA: two days of one stem in two directories stopped an archive run).
    """
    seen: dict[str, Path] = {}
    names: dict[str, Path] = {}
    out = {}
    for p in map(Path, paths):
        stem = output_stem(p)
        other = seen.get(stem) or names.get(p.name)
        if other is not None:
            out[p] = (
                f"{p}: would write the same outputs ({stem}.summary.*, rows of source "
                f"{p.name}) as {other} in this run; rename one or give it another --out"
            )
            continue
        seen[stem] = p
        names[p.name] = p
    return out


def _summaries_of_other_runs(out_dir: Path, name: str) -> bool:
    """Whether ``out_dir`` holds the summary of a run other than ``name``.

    One run per call into the same directory (a cron job) must not overwrite the
    ``summary.json`` of the run before it, whose rows stay in the periods table:
    the new run's summaries are then named after it, as with several inputs.
    """
    return any(
        (src := summary_source(sp)) is not None and src != name
        for sp in Path(out_dir).glob("*summary.json")
    )


def check_output_format(out_dir: Path, fmt: str) -> None:
    """Refuse a ``--format`` other than that of the periods table already in ``out_dir``.

    The periods table is cumulative: a second one in the other format beside it
    would split the directory's rows in two tables (as ``grace-bias`` refuses a
    second ``bias_drift`` table).

    Raises
    ------
    ValidationError
        One line naming the existing table.
    """
    other = "csv" if fmt == "parquet" else "parquet"
    table = Path(out_dir) / f"periods.{other}"
    if table.exists():
        raise ValidationError(
            f"{table}: the periods table of this --out is in --format {other}; use --format "
            f"{other} there, or another --out for --format {fmt}"
        )


def load_summary(path: Path) -> tuple[str, dict[str, Any]] | None:
    """(run file name, content) of a demod ``summary.json``, or None if it is not one."""
    try:
        s = json.loads(Path(path).read_text())
        if isinstance(s, dict) and isinstance(s.get("options"), dict):
            return Path(s["source"]).name, s
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return None


def summary_source(path: Path) -> str | None:
    """File name of the run a ``summary.json`` is about, or None if it is not a demod summary."""
    got = load_summary(path)
    return None if got is None else got[0]


def remove_stale_summaries(out_dir: Path, source: str, keep: Path) -> list[Path]:
    """Remove the summaries of ``source`` in ``out_dir`` other than ``keep`` (and their .md).

    A run that is re-run into the same directory under another summary name
    (``summary.json`` alone, ``<stem>.summary.json`` with others) replaces its
    rows in the periods table; its old summaries describe rows that are gone.

    Returns
    -------
    list of Path
        The files removed.
    """
    gone = []
    for sp in sorted(Path(out_dir).glob("*summary.json")):
        if sp.name == keep.name or summary_source(sp) != source:
            continue
        md = sp.with_name(sp.name[: -len(".json")] + ".md")
        for f in (sp, md):
            with contextlib.suppress(FileNotFoundError):
                f.unlink()
                gone.append(f)
    return gone
