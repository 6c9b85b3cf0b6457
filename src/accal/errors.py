"""accal's exception hierarchy.

Every error caused by bad input derives from :class:`AccalError`; the CLI turns
it into the one-line message ``accal: FILE[:LINE]: what is wrong`` and exit
status 1.  Anything else escaping a command is a bug.
"""

from __future__ import annotations

from pathlib import Path


class AccalError(Exception):
    """Base class for errors caused by the user's input or options."""


class FormatError(AccalError, ValueError):
    """An input file cannot be parsed.

    Parameters
    ----------
    message : str
        What is wrong, as one line.
    path : str or Path, optional
        The file.
    line : int, optional
        1-based line number in the (decompressed) file, where known.
    """

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        super().__init__(message)
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line

    def __str__(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path if self.line is None else f"{self.path}:{self.line}"
            where += ": "
        return f"{where}{self.message}"


class UnsupportedFormatError(FormatError, NotImplementedError):
    """The file is recognised but its version/variant is not supported."""


class ValidationError(AccalError, ValueError):
    """Input data or options violate a requirement of an estimator."""


def check_option(name: str, value: object, allowed: tuple | list) -> None:
    """Raise a uniform ``ValueError`` for a bad choice (MNE's ``_check_option``).

    Parameters
    ----------
    name : str
        Parameter name.
    value : object
        Value received.
    allowed : sequence
        Allowed values.
    """
    if value not in allowed:
        opts = ", ".join(repr(a) for a in allowed)
        raise ValidationError(
            f"Invalid value for the {name!r} parameter. Allowed values are {opts}, "
            f"but got {value!r} instead."
        )
