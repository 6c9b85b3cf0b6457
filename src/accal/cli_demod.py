"""Facade: the rotating-platform commands, now in :mod:`accal.cli` (one module each).

Kept for the names tests import from here (``demod``, ``design``, ``budget``,
``simulate_gap``); new code imports them from :mod:`accal.cli`.
"""

from __future__ import annotations

from accal.cli.budget import budget
from accal.cli.demod import demod
from accal.cli.design import design
from accal.cli.simulate_gap import simulate_gap

__all__ = ["budget", "demod", "design", "simulate_gap"]
