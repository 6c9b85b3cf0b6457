"""Entry point of the ``accal`` console script and of ``python -m accal``."""

from __future__ import annotations

import sys

from accal._runtime import single_threaded_blas

single_threaded_blas()  # before numpy is loaded: see accal._runtime


class Terminated(KeyboardInterrupt):
    """SIGTERM (``timeout``, systemd, a cron supervisor): stop as on Ctrl-C."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise Terminated(f"signal {signum}")


def main() -> None:
    """Run the command line (imported here: Ctrl-C during the imports is one line).

    SIGTERM is handled like Ctrl-C: the file being written is removed (no hidden
    temporary is left behind), a batch commits the inputs that finished, and the
    exit status is 130.  Worker processes keep the default action (see
    :func:`accal.batch._worker_init`).
    """
    import signal

    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from accal.cli import main as cli
    except KeyboardInterrupt:
        sys.stderr.write("accal: interrupted\n")
        sys.exit(130)
    cli()


if __name__ == "__main__":  # pragma: no cover
    main()
