"""``closure.md`` across the inputs of a batch (accal.closure_reports.write_closure_reports)."""

from __future__ import annotations

from pathlib import Path

from accal.closure_reports import write_closure_reports
from accal.gracejob.outcome import FileOutcome


def _entry(removed: list[str], rejected: list[dict]) -> dict:
    return {
        "markdown": "## axis\n",
        "removed_from_calibrated": removed,
        "rejected": rejected,
        "unexplained": [],
        "estimates": {},
    }


def test_failed_inputs_are_named_and_earlier_results_marked(tmp_path):
    """A batch with a bad file: closure.md says so, with the file's one-line error, and
    marks an input whose earlier closure the report keeps (QA, 2026-11-29: the report
    opened with "8 input(s)" and said nothing of four failures)."""
    good = FileOutcome(
        Path("A_day1.asc"),
        True,
        closure={
            "z": _entry(
                ["bias_step@2005-01-01T10:00:00GPS"],
                [{"name": "auxiliary", "channel": "ang_accl_y"}, {"name": "bias_step"}],
            )
        },
    )
    write_closure_reports(tmp_path, [good])
    bad = FileOutcome(Path("A_day1.asc"), False, "A_day1.asc:12: not a number: 'abc'")
    empty = FileOutcome(Path("A_day2.asc"), False, "A_day2.asc: no data records")
    write_closure_reports(tmp_path, [bad, empty])
    md = (tmp_path / "closure.md").read_text()
    assert "**2 input(s) failed in this run**" in md
    assert "- A_day1.asc:12: not a number: 'abc'. The report below keeps an earlier run's" in md
    assert "- A_day2.asc: no data records." in md
    # rejected effects carry their channel in the summary
    assert "| auxiliary(ang_accl_y), bias_step |" in md


def test_diagnose_summary_says_would_remove(tmp_path):
    entry = _entry([], [])
    entry["would_remove"] = entry.pop("removed_from_calibrated")
    write_closure_reports(tmp_path, [FileOutcome(Path("d.asc"), True, closure={"x": entry})],
                          diagnose=True)  # fmt: skip
    md = (tmp_path / "closure.md").read_text()
    assert "| input | axis | would remove |" in md and "failed" not in md
    # nothing was refitted: no "moved 0.00σ" that reads as harmless (QA)
    assert "| d.asc | x | – | – | – | – | – |" in md
