"""Entry point of the ``accal`` console script and of ``python -m accal``."""

from __future__ import annotations

import sys

from accal._runtime import single_threaded_blas

single_threaded_blas()  # before numpy is loaded: see accal._runtime


def main() -> None:
    """Run the command line (imported here: Ctrl-C during the imports is one line)."""
    try:
        from accal.cli import main as cli
    except KeyboardInterrupt:
        sys.stderr.write("accal: interrupted\n")
        sys.exit(130)
    cli()


if __name__ == "__main__":  # pragma: no cover
    main()
