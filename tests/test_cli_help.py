"""``accal --help`` lists each command once, with a complete one-line summary (issue 21).

Before, the group's docstring listed the commands and Click listed them again,
with summaries cut at 45 characters ("... bias and drift of accelerometer...").
"""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner

from accal.cli import main

COMMANDS = ["grace-bias", "table", "plot", "diagnose", "demod", "design", "budget", "simulate"]


def _help(args: list[str], width: int) -> str:
    res = CliRunner().invoke(main, [*args, "--help"], terminal_width=width)
    assert res.exit_code == 0, res.output
    return res.output


def _command_rows(text: str) -> list[str]:
    """The lines of the ``Commands:`` section."""
    section = text.split("Commands:\n", 1)[1]
    return [line for line in section.splitlines() if line.strip()]


@pytest.mark.parametrize("width", [80, 100])
def test_root_help_lists_each_command_once_with_a_whole_summary(width):
    text = _help([], width)
    for name in COMMANDS:  # a row "  NAME  summary", once (no second list in the description)
        rows = re.findall(rf"^ +{re.escape(name)} {{2,}}\S", text, flags=re.MULTILINE)
        assert len(rows) == 1, (name, text)
    rows = _command_rows(text)
    assert [r.split()[0] for r in rows] == COMMANDS  # one line each, in workflow order
    for row in rows:
        summary = row.split(None, 1)[1]
        assert not summary.endswith("..."), row
        assert summary.endswith("."), row
    assert "calibrate spacecraft electrostatic-accelerometer data" in text


def test_simulate_help_lists_its_commands_with_whole_summaries():
    text = _help(["simulate"], 80)
    rows = _command_rows(text)
    assert sorted(r.split()[0] for r in rows) == ["gap", "grace"]
    for row in rows:
        assert not row.endswith("..."), row
        assert row.endswith("."), row
