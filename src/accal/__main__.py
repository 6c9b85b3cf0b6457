"""Entry point of the ``accal`` console script and of ``python -m accal``."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys

from accal._runtime import ignore_late_signals, single_threaded_blas

single_threaded_blas()  # before numpy is loaded: see accal._runtime

EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a Ctrl-C


class Terminated(KeyboardInterrupt):
    """SIGTERM (``timeout``, systemd, a cron supervisor): stop as on Ctrl-C."""


def _on_sigterm(signum: int, frame: object) -> None:
    ignore_late_signals()
    raise Terminated(f"signal {signum}")


def _on_sigint(signum: int, frame: object) -> None:
    """Ctrl-C: stop, once.  Further Ctrl-C while the run removes its temporaries and
    releases its lock would interrupt that clean-up (a user pressing it again, or
    pyarrow delivering the same one twice); they are ignored from here on (Ctrl-\\,
    SIGQUIT, still kills at once)."""
    ignore_late_signals()
    raise KeyboardInterrupt


def _exit_interrupted() -> None:
    """Leave with status 130 whatever further SIGINT/SIGTERM arrive on the way out.

    One Ctrl-C can be delivered twice: pyarrow re-sends a signal that cancelled one
    of its readers to the main thread (``pyarrow.lib.SignalStopHandler``), after
    Python's own handler has tripped.  The second one arrived after the interpreter
    had put back the default action during finalization (``_PySignal_Fini``) and
    killed the process with SIGINT after ``accal: interrupted`` was printed (status
    -2 instead of 130 in 4 of 30 interrupted ``accal demod`` runs).  So: a no-op
    handler for any late signal, the log handlers flushed, and ``os._exit`` once
    every ``finally`` block (temporaries removed, lock released) has run.
    """
    ignore_late_signals()
    _flush()
    os._exit(EXIT_INTERRUPTED)


def _flush() -> None:
    """Flush the log handlers and the standard streams before an ``os._exit``."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        if stream is None:  # closed at start (``2>&-`` in a crontab)
            continue
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing to say
            stream.flush()


def main() -> None:
    """Run the command line (imported here: Ctrl-C during the imports is one line).

    SIGTERM is handled like Ctrl-C: the file being written is removed (no hidden
    temporary is left behind), a batch commits the inputs that finished, and the
    exit status is 130.  Worker processes keep the default action (see
    :func:`accal.batch._worker_init`).
    """
    signal.signal(signal.SIGTERM, _on_sigterm)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not if ignored (nohup, &)
        signal.signal(signal.SIGINT, _on_sigint)
    try:
        try:
            from accal.cli import main as cli
        except KeyboardInterrupt:
            ignore_late_signals()
            sys.stderr.write("accal: interrupted\n")
            sys.exit(EXIT_INTERRUPTED)
        cli()
    except SystemExit as exc:
        if exc.code == EXIT_INTERRUPTED:
            _exit_interrupted()
        if "pyarrow.lib" in sys.modules:
            _exit_without_finalizing(exc.code)
        raise


def _exit_without_finalizing(code: object) -> None:
    """Leave with ``code`` (``SystemExit``'s meaning) without the interpreter's finalization.

    The run is over: outputs written and closed, temporaries removed, lock released
    (every ``finally`` has run).  What finalization would still do is tear down
    pyarrow's native thread pools, and a pool thread still joinable then makes the
    C++ runtime abort (``terminate called without an active exception``, exit 134 or
    a bus error instead of 1: a QA helper's runs with a bad ``--aux`` table, 4-9 of
    12-15 under load, 1 of 12 after pyarrow's reads were made single-threaded; the
    apache/arrow issue 34314 kind).  The log handlers and the standard streams are
    flushed first.
    """
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # SystemExit("message"): printed, status 1
        if sys.stderr is not None:
            with contextlib.suppress(OSError, ValueError):
                sys.stderr.write(f"{code}\n")
        status = 1
    _flush()
    os._exit(status)


if __name__ == "__main__":  # pragma: no cover
    main()
