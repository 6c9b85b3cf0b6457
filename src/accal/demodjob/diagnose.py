"""``accal diagnose`` on an ``accal demod`` output directory: its current summaries, re-closed."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any

from accal.demodjob.closure import close_run
from accal.demodjob.closure_outputs import write_demod_closure
from accal.demodjob.options import DemodOptions
from accal.demodjob.outputs import load_summary
from accal.demodjob.summary import find_run
from accal.errors import AccalError
from accal.io.writers import read_table_metadata

#: Options of a source that a summary and the periods table metadata must share.
_SOURCE_OPTIONS = ("tau", "mask", "method", "signal_model", "bias_model", "psd")


def current_summaries(
    directory: Path, warnings: list[str] | None = None
) -> list[tuple[Path, dict[str, Any]]]:
    """The summaries of a demod output directory that describe its current periods table.

    The table's metadata (``accal.meta["sources"]``) lists every source whose rows
    it holds, with the name of the summary its last run wrote.  A summary is
    current when it is that one; summaries left by earlier runs (a source re-run
    under another summary name, with other options, or a source whose rows are no
    longer in the table) are ignored.  Tables of older accal versions do not name
    the summary: a summary is then current when its options are the table's for
    its source (the newest one if several are).

    Parameters
    ----------
    directory : Path
        The ``accal demod --out`` directory.
    warnings : list of str, optional
        Appended to: sources of the table left without a current summary.

    Returns
    -------
    list of (Path, dict)
        The summary files and their content, sorted by file name.
    """
    directory = Path(directory)
    tables = sorted(directory.glob("periods.*"), key=lambda q: q.stat().st_mtime)
    sources: dict[str, Any] | None = None
    if tables:
        with contextlib.suppress(Exception):  # unreadable metadata: every summary counts
            meta = read_table_metadata(tables[-1])[1]
            if isinstance(meta.get("sources"), dict):
                sources = meta["sources"]
    found: dict[str, tuple[Path, dict[str, Any]]] = {}
    for sp in sorted(directory.glob("*summary.json")):
        got = load_summary(sp)
        if got is None:
            continue  # not a demod summary
        name, s = got
        o = s["options"]
        if sources is not None:
            meta = sources.get(name)
            if not isinstance(meta, dict):
                continue  # its rows are no longer in the table
            if "summary" in meta:
                if meta["summary"] != sp.name:
                    continue  # an earlier run's summary
            elif any(meta.get(k, o.get(k)) != o.get(k) for k in _SOURCE_OPTIONS):
                continue  # older table: not the options of the rows
        old = found.get(name)
        if old is None or sp.stat().st_mtime > old[0].stat().st_mtime:
            found[name] = (sp, s)
    if warnings is not None and sources is not None:
        for name in sorted(set(sources) - set(found)):
            want = sources[name].get("summary") if isinstance(sources[name], dict) else None
            warnings.append(
                f"{name}: rows in {tables[-1].name} but no current summary"
                + (f" ({want} now belongs to another run)" if want else "")
                + f"; re-run accal demod on it into {directory} to diagnose it"
            )
    return sorted(found.values(), key=lambda x: x[0].name)


def diagnose_demod_dir(
    directory: Path,
    out_dir: Path,
    *,
    alpha: float = 0.01,
    warnings: list[str] | None = None,
    plots: bool = False,
) -> list[tuple[Path, dict[str, Any] | None, str]]:
    """Close the loop on the runs of an earlier ``accal demod`` output directory.

    Each current ``summary.json``/``<stem>.summary.json`` (:func:`current_summaries`:
    the ones that describe the periods table as it is) names its run file and
    options; the run is re-read (it must still exist; found by :func:`find_run`,
    from any working directory), resampled as it was, and analysed with the same
    declared model.  The periods table is not changed (re-run ``demod
    --close-loop`` for that); ``closure.json``/``closure.md`` and plots go to
    ``out_dir``.

    Parameters
    ----------
    directory : Path
        The ``accal demod --out`` directory.
    out_dir : Path
        Where the reports go.
    alpha : float
        False-detection probability per selection step.
    warnings : list of str, optional
        Appended to: sources of the periods table without a current summary.

    Returns
    -------
    list of (Path, dict or None, str)
        Per run: its path, its ``closure.json`` entry (None on failure) and a
        one-line error message (empty on success).
    """
    directory, out_dir = Path(directory), Path(out_dir)
    results: list[tuple[Path, dict[str, Any] | None, str]] = []
    for sp, s in current_summaries(directory, warnings):
        src = Path(s["source"])
        o = s["options"]
        rs = (s.get("input") or {}).get("resample") if isinstance(s.get("input"), dict) else None
        rs = rs if isinstance(rs, dict) and rs else None  # the resampling report, if resampled
        try:
            src = find_run(s, sp)
            opts = DemodOptions(
                tau=float(o["tau"]),
                mask=float(o["mask"]),
                signal_model=o.get("signal_model", "mean"),
                bias_model=o.get("bias_model", "affine"),
                resample=rs is not None,
                gap_factor=float(rs.get("gap_factor", 2.0)) if rs else 2.0,
                psd=str(o.get("psd") or "microstar"),
                close_loop=True,
                alpha=alpha,
                rest_tol=float(o.get("rest_tol", 1e-9)),
                plots=plots,
            )
            step = float(rs["step"]) if rs and "step" in rs else None
            out_dir.mkdir(parents=True, exist_ok=True)  # not before a run is found
            entry, _, _ = close_run(src, opts, out_dir, step=step)
            write_demod_closure(out_dir, src.name, entry)
            results.append((src, entry, ""))
        except AccalError as exc:
            msg = str(exc).replace("\n", " ")
            if getattr(exc, "path", None) is None and not msg.startswith(str(src)):
                msg = f"{src}: {msg}"
            results.append((src, None, msg))
    return results
