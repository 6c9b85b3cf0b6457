"""``accal simulate``: synthetic inputs with a truth file (``grace`` and ``gap``)."""

from __future__ import annotations

import click

from accal.cli.simulate_gap import simulate_gap
from accal.cli.simulate_grace import simulate_grace

__all__ = ["simulate", "simulate_gap", "simulate_grace"]


@click.group("simulate")
def simulate() -> None:
    """Write synthetic input files with a truth file."""


simulate.add_command(simulate_grace, name="grace")
simulate.add_command(simulate_gap, name="gap")
