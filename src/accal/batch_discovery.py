"""Batch inputs: command-line files, directories and patterns expanded and grouped.

:func:`discover` expands files, directories (``--recursive``) and glob patterns
into a sorted, de-duplicated list; :func:`group_inputs` groups them by (satellite,
day) when the name follows the Level-1B convention ``PROD_YYYY-MM-DD_S_RR.ext``
(:func:`name_key`).
"""

from __future__ import annotations

import fnmatch
import glob
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: Names taken from a directory scan unless ``--include`` says otherwise.
DEFAULT_INCLUDE = ("*ACC1B_*", "*ACT1B_*")
#: Names never taken from a directory scan (accal's own outputs).
EXCLUDE = (
    "*.calibrated.*",
    "*.noise.npz",
    "bias_drift.*",
    "*.json",
    "*.md",
    "*.png",
    "*.log",
    "*.rpt",
    "*.lock",
    ".*",
)

#: A Level-1B file name: product, date, satellite and release.
L1B_NAME = re.compile(
    r"(?P<product>[A-Z]{3}1[AB])_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rel>\d+)"
)
_GLOB_CHARS = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class InputGroup:
    """Inputs of one satellite and day (``key`` is ``("?", "?")`` when unknown)."""

    key: tuple[str, str]
    paths: tuple[Path, ...]


def name_key(path: Path) -> tuple[str, str] | None:
    """``(satellite, date)`` from a Level-1B file name, else None."""
    m = L1B_NAME.search(path.name)
    return (m["sat"], m["date"]) if m else None


def discover(
    inputs: Iterable[str | Path],
    *,
    recursive: bool = False,
    include: Sequence[str] = DEFAULT_INCLUDE,
) -> tuple[list[Path], list[tuple[Path, str]]]:
    """Expand command-line inputs into files.

    Parameters
    ----------
    inputs : iterable of str or Path
        Files (taken as given, even if they do not exist: the reader reports them),
        directories (their files matching ``include``; the whole tree with
        ``recursive``) and glob patterns (``*``, ``?``, ``[...]``, ``**``).
    recursive : bool
        Descend into sub-directories of directory inputs.
    include : sequence of str
        Name patterns taken from directories (not applied to explicit files).

    Returns
    -------
    files : list of Path
        De-duplicated (by device and inode: symlinks and hard links to one file
        count once), in the order given; directory and
        pattern expansions sorted by name.
    problems : list of (Path, str)
        Inputs that expand to nothing, with a one-line reason.
    """
    files: list[Path] = []
    problems: list[tuple[Path, str]] = []
    seen: set[Any] = set()

    def add(p: Path) -> None:
        # the same file reached by two routes (symlink, hard link, ./x and x) once
        try:
            st = os.stat(p)
            key: Any = (st.st_dev, st.st_ino)
        except OSError:  # missing: the reader reports it (once per spelling)
            key = os.path.realpath(p)
        if key not in seen:
            seen.add(key)
            files.append(p)

    for raw in inputs:
        p = Path(raw)
        if p.is_dir():
            if not recursive:
                add(p)  # the task reports it, in input order, with the hint
                continue
            found = sorted(
                q
                for q in p.rglob("*")
                # not only regular files: a broken link or a FIFO under a matching name
                # is an input the reader refuses with its reason (QA: such days vanished
                # from a directory's run without a word, exit 0)
                if not q.is_dir() and _wanted(q.name, include) and not _hidden(q, p)
            )
            if not found:
                problems.append((p, f"{p}: no input file in directory (include: {list(include)})"))
            for q in found:
                add(q)
        elif not p.exists() and _GLOB_CHARS.search(str(raw)):
            found = sorted(Path(q) for q in glob.glob(str(raw), recursive=True))
            found = [q for q in found if not q.is_dir()]
            if not found:
                problems.append((p, f"{raw}: no file matches this pattern"))
            for q in found:
                add(q)
        else:
            add(p)
    return files, problems


def _wanted(name: str, include: Sequence[str]) -> bool:
    if any(fnmatch.fnmatch(name, x) for x in EXCLUDE):
        return False
    return any(fnmatch.fnmatch(name, x) for x in include)


def _hidden(q: Path, root: Path) -> bool:
    return any(part.startswith(".") for part in q.relative_to(root).parts)


def group_inputs(paths: Sequence[Path]) -> list[InputGroup]:
    """Group inputs by (satellite, day) from their names, sorted by day then satellite.

    Inputs whose names do not follow the Level-1B convention form one group with
    key ``("?", "?")`` at the end, in their given order.
    """
    groups: dict[tuple[str, str], list[Path]] = {}
    for p in paths:
        groups.setdefault(name_key(p) or ("?", "?"), []).append(p)
    keys = sorted((k for k in groups if k != ("?", "?")), key=lambda k: (k[1], k[0]))
    if ("?", "?") in groups:
        keys.append(("?", "?"))
    return [InputGroup(k, tuple(groups[k])) for k in keys]
