"""The options of every batch command (``grace-bias``, ``demod``): where and how again.

``-j/--workers``, ``--scheduler``, ``--force`` and ``--checksum`` mean the same in
every command that runs on :func:`accal.batch_runner.run_batch`; they are declared
here once (issue 21: ``demod`` had copies of ``grace-bias``'s).  Only the name of
what a command processes differs (``inputs``, ``runs``).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import click

from accal._cliutil import option_stack

__all__ = ["batch_options", "for_scheduler"]

T = TypeVar("T")


def batch_options(noun: str = "inputs") -> Callable[[Any], Any]:
    """``-j/--workers``, ``--scheduler``, ``--force``, ``--checksum``, in that order.

    Parameters
    ----------
    noun : str
        What the command processes, plural (``"inputs"``, ``"runs"``), as the help
        texts name it.

    Returns
    -------
    callable
        An option stack (:func:`accal._cliutil.option_stack`): a decorator, or one
        item of a command's option list.  The values are ``workers`` (int or None:
        all cores), ``scheduler`` (str or None), ``force`` and ``checksum`` (bool).
    """
    return option_stack(
        [
            click.option(
                "--workers",
                "-j",
                type=click.IntRange(min=1),
                default=None,
                help="Worker processes on this machine [default: all cores].",
            ),
            click.option(
                "--scheduler",
                default=None,
                metavar="ADDRESS",
                help="Run on a dask.distributed cluster (e.g. tcp://host:8786); workers must "
                "see the same file system.",
            ),
            click.option(
                "--force",
                is_flag=True,
                help=f"Redo {noun} whose outputs are current (OUT/manifest.json).",
            ),
            click.option(
                "--checksum",
                is_flag=True,
                help=f"Decide 'current' by SHA-256 of the {noun} instead of size and mtime.",
            ),
        ]
    )


def for_scheduler(
    scheduler: str | None, paths: Sequence[Path], out: Path, opts: T
) -> tuple[list[Path], Path, T]:
    """The inputs, the output directory and the options' files as absolute paths
    when the batch runs on a Dask cluster (``scheduler`` given), else unchanged.

    A Dask worker resolves a relative path against its own working directory, not
    the one the command was typed in (QA: every input "no such file", and a relative
    ``--out`` created beside the worker's directory, outside the intended one).
    ``opts`` is a frozen dataclass; its :class:`~pathlib.Path` fields are made absolute.
    """
    if scheduler is None:
        return list(paths), out, opts
    paths = [Path(os.path.abspath(p)) for p in paths]
    changes = {
        f.name: Path(os.path.abspath(getattr(opts, f.name)))
        for f in dataclasses.fields(opts)  # type: ignore[arg-type]
        if isinstance(getattr(opts, f.name), Path)
    }
    return paths, Path(os.path.abspath(out)), dataclasses.replace(opts, **changes)  # type: ignore[type-var]
