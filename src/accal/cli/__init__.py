"""Command-line interface (click).  Thin: parse options, call the library, map errors.

One module per command (:mod:`accal.cli.grace_bias`, :mod:`~accal.cli.table`,
:mod:`~accal.cli.diagnose`, :mod:`~accal.cli.demod`, :mod:`~accal.cli.design`,
:mod:`~accal.cli.budget`, :mod:`~accal.cli.simulate`); this module defines the
group ``main`` and registers them in workflow order.

Exit status: 0 when every input was processed, 1 when some failed (the others are
still processed and written), 2 for usage errors.  Every failure is one line on
stderr: ``accal: FILE[:LINE]: what is wrong``.

Start-up: ``accal --help`` imports click and the command modules only; each
command imports the library it calls when it runs (numpy ~0.2 s, accal.pipeline
~0.35 s, accal.pipeline_demod ~0.3 s, medians of ``python -X importtime``; 2026-11).
"""

from __future__ import annotations

import os

import click

from accal import __version__
from accal._cliutil import CONTEXT_SETTINGS, Group, usage_fail
from accal._runtime import tune_allocator
from accal.cli.budget import budget
from accal.cli.demod import demod
from accal.cli.design import design
from accal.cli.diagnose import diagnose
from accal.cli.grace_bias import grace_bias
from accal.cli.plot import plot_cmd
from accal.cli.simulate import simulate, simulate_gap, simulate_grace
from accal.cli.table import table_cmd

__all__ = [
    "budget",
    "demod",
    "design",
    "diagnose",
    "grace_bias",
    "main",
    "simulate",
    "simulate_gap",
    "simulate_grace",
    "table_cmd",
]


@click.group(cls=Group, context_settings=CONTEXT_SETTINGS)
@click.version_option(__version__, prog_name="accal")
@click.option("--debug", is_flag=True, help="Show tracebacks of internal errors (for bug reports).")
def main(debug: bool) -> None:
    """accal: calibrate spacecraft electrostatic-accelerometer data."""
    tune_allocator()
    if debug:
        os.environ["ACCAL_DEBUG"] = "1"  # inherited by worker processes
    from accal.batch import forced_start_method  # after tune_allocator; not for --help
    from accal.errors import AccalError

    try:
        forced_start_method()  # a bad value is a usage error now, not at the first pool
    except AccalError as exc:
        usage_fail(str(exc))


main.add_command(grace_bias)
main.add_command(table_cmd)
main.add_command(plot_cmd)
main.add_command(diagnose)
main.add_command(demod)
main.add_command(design)
main.add_command(budget)
main.add_command(simulate)
