"""The closure reports of a batch: ``OUT/closure.json`` and ``OUT/closure.md``.

:func:`write_closure_reports` merges a run's closure results into the output
directory's reports (the sources of earlier runs kept), and writes ``closure.md``: the
summary across inputs (:func:`summary_table`), the batch's failed inputs, then each
input's and axis' section.  Used by ``accal grace-bias --close-loop`` and ``accal
diagnose``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from accal import __version__
from accal.gracejob.outcome import FileOutcome
from accal.gracejob.outputs import output_stem, write_json
from accal.io.writers import atomic_path

__all__ = ["read_sources", "summary_table", "write_closure_reports"]


def read_sources(jpath: Path) -> dict[str, Any]:
    """The ``sources`` of an earlier ``closure.json`` (empty when there is none or it
    cannot be read)."""
    try:
        old = json.loads(Path(jpath).read_text())
    except (OSError, ValueError):
        return {}
    return old.get("sources", {}) if isinstance(old, dict) else {}


def _closure_of_report(path: Path) -> dict[str, Any]:
    """The ``closure`` entry of an input's ``<stem>.report.json`` ({} if none or unreadable)."""
    try:
        entry = json.loads(path.read_text()).get("closure")
    except (OSError, ValueError, AttributeError):
        return {}
    return entry if isinstance(entry, dict) else {}


def write_closure_reports(
    out_dir: Path, outcomes: Sequence[FileOutcome], *, diagnose: bool = False
) -> tuple[Path, Path]:
    """Merge this run's closure results into ``OUT/closure.json`` and ``OUT/closure.md``.

    With ``diagnose`` (``accal diagnose``: the calibrated files are only read) the
    report says which instrument effects a ``grace-bias --close-loop`` re-run would
    remove, instead of claiming they were removed.

    Layout of ``closure.json``: ``{"accal_version": ..., "sources": {SOURCE: {AXIS:
    entry}}}`` where ``entry`` is :meth:`accal.closure.ClosureResult.to_dict` plus
    ``model`` (the fitted model, e.g. ``poly1+bias_step@2005-01-01T10:00:00GPS``, GPS calendar) and
    ``removed_from_calibrated`` (the effects subtracted from the calibrated series).
    Sources of earlier runs in the same directory are kept; a re-run replaces its
    own entries, and a re-run without ``--close-loop`` removes them.  With no source
    left the two files are removed.
    """
    out_dir = Path(out_dir)
    jpath = out_dir / "closure.json"
    sources = read_sources(jpath)
    for o in outcomes:
        if o.ok and o.closure:
            sources[o.path.name] = o.closure
        elif o.ok and getattr(o, "skipped", False) and o.path.name not in sources:
            # current, but its closure is not in closure.json: the run that made it was
            # interrupted (or killed) before the reports were merged (QA: a re-run then
            # skipped those days and closure.json lacked 2-6 of 10): its report.json has it
            earlier = _closure_of_report(out_dir / f"{output_stem(o.path)}.report.json")
            if earlier:
                sources[o.path.name] = earlier
        elif (
            o.ok
            and not diagnose
            and not getattr(o, "skipped", False)
            and sources.pop(o.path.name, None) is not None
        ):
            # redone without --close-loop: its table rows and calibrated file are the
            # plain fit's now, so its old closure (report and plots) no longer applies
            stem = output_stem(o.path)
            for kind in ("closure", "closure-psd", "closure-effects"):
                for ax in "xyz":
                    (out_dir / f"{stem}.{kind}.{ax}.png").unlink(missing_ok=True)
    sources = dict(sorted(sources.items()))
    mpath = out_dir / "closure.md"
    if not sources:
        for f in (jpath, mpath):
            f.unlink(missing_ok=True)
        return jpath, mpath
    write_json(jpath, {"accal_version": __version__, "sources": sources})
    lines = [
        "# accal closure report",
        "",
        f"{len(sources)} input(s); per input and axis: the effects the bias + drift model "
        "lacked, their significance, and the coefficients before/after.  "
        + (
            "accal diagnose read the calibrated files and changed nothing: the effects under "
            "'would remove' are those `accal grace-bias --close-loop` would subtract"
            if diagnose
            else "Effects listed under 'removed from calibrated' were subtracted from the "
            "calibrated series"
        )
        + "; periodic terms and unexplained structure are reported only.",
        "",
    ]
    lines += summary_table(sources, diagnose=diagnose)
    lines += _failed_inputs(outcomes, sources)
    for src, axes in sources.items():
        for ax, entry in axes.items():
            md = entry.get("markdown") or f"## {src} axis {ax}\n"
            lines.append(md.rstrip())
            lines += _estimates_markdown(entry.get("estimates") or {})
            if "would_remove" in entry:  # from accal diagnose
                would = entry.get("would_remove") or []
                lines += [
                    "",
                    "Would remove (re-run grace-bias --close-loop; the calibrated file is "
                    f"unchanged): {', '.join(would) or 'nothing'}.",
                    "",
                ]
                continue
            removed = entry.get("removed_from_calibrated") or []
            lines += ["", f"Removed from calibrated: {', '.join(removed) or 'nothing'}.", ""]

    with atomic_path(mpath) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return jpath, mpath


def _failed_inputs(outcomes: Sequence[FileOutcome], sources: dict[str, Any]) -> list[str]:
    """Lines of ``closure.md`` naming this run's failed inputs (each with its one-line
    error) and saying which of them keep an earlier run's closure in the report (QA,
    2026-11-29: a run with four bad files opened with "8 input(s)" and said nothing)."""
    failed = [o for o in outcomes if not o.ok]
    if not failed:
        return []
    lines = [f"**{len(failed)} input(s) failed in this run** (nothing written for them):", ""]
    for o in failed:
        kept = (
            " The report below keeps an earlier run's closure of this input."
            if o.path.name in sources
            else ""
        )
        lines.append(f"- {(o.message or o.path.name).rstrip('.')}.{kept}")
    return [*lines, ""]


def _entry_name(e: dict[str, Any]) -> str:
    """An effect's name for the summary, with its channel (``auxiliary(ang_accl_y)``)."""
    ch = e.get("channel")
    return f"{e['name']}({ch})" if ch not in (None, "") else str(e["name"])


def summary_table(sources: dict[str, dict[str, Any]], diagnose: bool = False) -> list[str]:
    """The summary across inputs that opens ``closure.md``: per input and axis, what was
    removed (with ``diagnose``: would be removed), what was significant but not
    removed, and how far the closure moved the table's bias and drift (in their σ: do
    no harm)."""
    removed_head = "would remove" if diagnose else "removed"
    lines = [
        "## Summary",
        "",
        f"| input | axis | {removed_head} | significant, not removed | unexplained "
        "| bias moved [σ] | drift moved [σ] |",
        "|---|---|---|---|---|---|---|",
    ]
    n_moved = n_axes = 0
    for src, axes in sources.items():
        for ax, entry in axes.items():
            removed = entry.get("removed_from_calibrated", entry.get("would_remove")) or []
            rejected = [_entry_name(e) for e in entry.get("rejected") or []]
            moved = {"bias": 0.0, "drift": 0.0}
            for m in (entry.get("estimates") or {}).values():
                for q in moved:
                    if q in m and m[q].get("change_sigmas") is not None:
                        moved[q] = max(moved[q], float(m[q]["change_sigmas"]))
            n_axes += 1
            n_moved += any(v > 1.0 for v in moved.values())
            # accal diagnose refits nothing: no "moved" to show (a 0.00 read as "harmless")
            shown = {q: f"{v:.2f}" if entry.get("estimates") else "–" for q, v in moved.items()}
            lines.append(
                f"| {src} | {ax} | {', '.join(removed) or '–'} | {', '.join(rejected) or '–'} "
                f"| {'yes' if entry.get('unexplained') else '–'} | {shown['bias']} "
                f"| {shown['drift']} |"
            )
    lines += [
        "",
        "accal diagnose refits nothing: the estimates a re-run would move are not shown (–)."
        if diagnose
        else f"{n_moved} of {n_axes} axes had an estimate moved by more than its σ.",
        "",
    ]
    return lines


def _estimates_markdown(estimates: dict[str, Any]) -> list[str]:
    if not estimates:
        return []
    has_truth = any("true_error_before" in e for m in estimates.values() for e in m.values())
    head = "| method | quantity | before ± σ | after ± σ | change / σ_after |"
    sep = "|---|---|---|---|---|"
    if has_truth:
        head += " true error before | true error after |"
        sep += "---|---|"
    lines = ["", "Refitted estimates (the table's values):", "", head, sep]
    for m, ent in estimates.items():
        for q, e in ent.items():
            row = (
                f"| {m} | {q} | {e['before']:.4g} ± {e['sigma_before']:.2g} "
                f"| {e['after']:.4g} ± {e['sigma_after']:.2g} | {e['change_sigmas']:.2f} |"
            )
            if has_truth:
                row += f" {e['true_error_before']:.3g} | {e['true_error_after']:.3g} |"
            lines.append(row)
    return lines
