"""accal: calibration of spacecraft electrostatic-accelerometer data.

Two jobs share one data model (:class:`accal.series.AccSeries`) and one
reader -> estimator -> writer pipeline:

* ``accal grace-bias``: per-day, per-axis bias and drift of GRACE / GRACE-FO
  Level-1B accelerometer data (wavelet detrending and least squares).
* ``accal demod``: unbiased acceleration from a rotating-platform
  accelerometer (MicroSTAR + Bias Rejection System).

The Python API (:mod:`accal.api`, ``docs/api.md``): ``accal.read``,
``accal.fit_bias``, ``accal.close_loop``, ``accal.demodulate``.  They are
imported on first use (PEP 562), so ``import accal`` costs the command line nothing.
"""

__version__ = "0.1.0"

__all__ = [
    "BiasFit",
    "Closure",
    "Demodulation",
    "__version__",
    "close_loop",
    "demodulate",
    "fit_bias",
    "read",
]

#: Names of :mod:`accal.api` exported here, imported on first access.
_API = frozenset(__all__) - {"__version__"}

# ``typing`` costs ~20 ms of start-up: type checkers take any ``TYPE_CHECKING`` name as true
TYPE_CHECKING = False
if TYPE_CHECKING:  # pragma: no cover (for type checkers and IDEs only)
    from accal.api import (
        BiasFit,
        Closure,
        Demodulation,
        close_loop,
        demodulate,
        fit_bias,
        read,
    )


def __getattr__(name: str) -> object:
    """Import the API names on first access (``accal.read`` → :func:`accal.api.read`)."""
    if name in _API:
        import importlib

        value = getattr(importlib.import_module("accal.api"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'accal' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
