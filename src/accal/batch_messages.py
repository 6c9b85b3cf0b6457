"""What a batch says about one input: its outcome and its one-line messages.

:class:`Outcome` is what happened to an input (the part every command shares);
:func:`failure_message`, :func:`write_error_message` and
:func:`internal_error_message` make the one-line ``FILE[:LINE]: what is wrong`` of
an input error, an output that could not be written and a bug (or a worker that
died, :class:`WorkerDied`); :func:`check_input` refuses an input no reader should
touch; :class:`Interrupted` is a batch stopped by Ctrl-C.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from accal._runtime import interrupted
from accal.errors import AccalError, ValidationError


class Interrupted(Exception):  # noqa: N818 - a state, not a failure of the input
    """A batch stopped by Ctrl-C (SIGINT) after committing the inputs that finished.

    ``summary`` is the run's summary at that point (inputs never started count as
    not run); a re-run finishes the batch.
    """

    def __init__(self, summary: Any) -> None:
        super().__init__("interrupted")
        self.summary = summary


@dataclass(frozen=True)
class Outcome:
    """What happened to one input of a batch (the part every command shares).

    Attributes
    ----------
    path : Path
        The input.
    ok : bool
        True if processed and written.
    message : str
        One-line error (``FILE[:LINE]: what is wrong``) when not ok.
    outputs : tuple of Path
        Files written for this input.
    """

    path: Path
    ok: bool
    message: str = ""
    outputs: tuple[Path, ...] = ()


class WorkerDied(RuntimeError):
    """The worker process running an input ended abruptly (killed, out of memory)."""


def failure_message(path: Path | str, exc: AccalError) -> str:
    """One line ``FILE[:LINE]: what is wrong`` for an input error."""
    msg = str(exc).replace("\n", " ")
    if getattr(exc, "path", None) is None:
        msg = f"{path}: {msg}"
    return msg


def check_input(path: Path) -> None:
    """Refuse, before anything opens it, an input that no reader should touch.

    * a name that is not valid UTF-8 (its bytes kept as surrogates): the table,
      manifest and reports key inputs by name, and those are UTF-8;
    * a FIFO, device or socket: reading it could block for ever (with the output
      directory locked) or never end (``/dev/zero``).

    Raises
    ------
    ValidationError
        With the reason (the caller names the file).
    """
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        raise ValidationError("file name is not valid UTF-8; rename the file") from None
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return  # missing or unreadable: the reader says so
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        kind = "a FIFO" if stat.S_ISFIFO(mode) else "a device or socket"
        raise ValidationError(f"not a regular file ({kind})")


def write_error_message(path: Path | str, exc: OSError) -> str:
    """One line for an output that could not be written (read-only or full disk, ...)."""
    where = f" ({exc.filename})" if exc.filename else ""
    return f"{path}: cannot write outputs{where}: {exc.strerror or exc}"


def internal_error_message(path: Path | str, exc: BaseException) -> str:
    """One line for a bug (not bad input); with ``ACCAL_DEBUG`` set, the traceback.

    A worker that died (:class:`WorkerDied`) is not a bug of accal: its line says
    what ended it.

    Raises
    ------
    KeyboardInterrupt
        The process was interrupted (:func:`accal._runtime.interrupted`): the error
        is the interruption's doing, and the run stops as on Ctrl-C.
    """
    if isinstance(exc, WorkerDied):
        return f"{path}: {exc}"
    if interrupted():  # a Ctrl-C that landed in an import or a C extension and came out as
        # ImportError ("initialization failed") or a partially initialised module: the run
        # was interrupted, it is not a bug (issue 23 finding 5)
        raise KeyboardInterrupt from exc
    msg = (
        f"{path}: internal error ({type(exc).__name__}: {exc}); "
        "please report it with the output of 'accal --debug ...'"
    )
    if os.environ.get("ACCAL_DEBUG"):
        import traceback  # ~20 ms (python -X importtime), for --debug only

        msg += "\n" + "".join(traceback.format_exception(exc))
    return msg
