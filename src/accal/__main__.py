"""Entry point of the ``accal`` console script and of ``python -m accal``."""

from accal._runtime import single_threaded_blas

single_threaded_blas()  # before numpy is loaded: see accal._runtime

from accal.cli import main  # noqa: E402

if __name__ == "__main__":  # pragma: no cover
    main()
