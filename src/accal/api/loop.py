"""Close the loop from Python: :func:`close_loop` (the CLI's defaults).

Part of :mod:`accal.api` (see its docstring); split from one module for size.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from accal.api.bias import BiasFit, fit_bias
from accal.api.closure_result import Closure
from accal.api.demod import Demodulation, demodulate
from accal.errors import ValidationError
from accal.series import AccSeries

if TYPE_CHECKING:  # pragma: no cover (imported lazily: start-up time)
    pass


# ---------------------------------------------------------------------------
# close the loop


def close_loop(
    data: AccSeries | BiasFit | Demodulation,
    *,
    aux: str | Path | None = None,
    alpha: float | None = None,
    orbit_period: float | None = None,
    truth: str | Path | None = None,
    **fit_options: Any,
) -> Closure:
    """Trace the residual of the fit to effects its model lacks, add them, refit.

    ``accal grace-bias --close-loop`` (for a series or a :class:`BiasFit`) or
    ``accal demod --close-loop`` (for a :class:`Demodulation`), with the CLI's
    defaults: every channel of the data (and of ``aux``) a candidate coupling,
    steps, periodic terms, and, without a reference, the orbit-periodic signal in
    the null model with its period estimated from the data near ``orbit_period``.

    Parameters
    ----------
    data : AccSeries, BiasFit or Demodulation
        A series (fitted with ``fit_options``) or an earlier result (refitted with
        its own options; the ones given here win).
    aux : str or Path, optional
        Housekeeping file of candidate channels (``--aux``; grace-bias only).
    alpha : float, optional
        False-detection probability per step (``--alpha``; default 0.01).
    orbit_period : float, optional
        Nominal orbit period [s] (default the CLI's 5600 s); the one used is
        :attr:`Closure.orbit_period`.
    truth : str or Path, optional
        Truth JSON of a simulation (grace-bias only).
    **fit_options
        Further options of :func:`fit_bias` for a series (``method``, ``reference``, ...).

    Returns
    -------
    Closure
        The findings per axis (:meth:`Closure.to_dataframe`) and the refit
        (:attr:`Closure.fit`).

    Examples
    --------
    >>> import accal
    >>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
    >>> closure = accal.close_loop(day)
    >>> sorted(closure.model), closure.fit.rows[0]["model"]
    (['x', 'y', 'z'], 'poly1')
    """
    given = {"aux": aux, "alpha": alpha, "orbit_period": orbit_period, "truth": truth}
    overrides = {k: v for k, v in given.items() if v is not None}
    if isinstance(data, Demodulation):
        if set(overrides) - {"alpha"} or fit_options:
            raise ValidationError("close_loop of a demodulation takes alpha only")
        run = Path(data.summary.get("source_path") or data.source)
        kwargs = {**data.arguments, **overrides, "close_loop": True}
        closure = demodulate(run, **kwargs).closure
        assert closure is not None
        return closure
    if isinstance(data, BiasFit):
        if data.input is None:
            raise ValidationError("this BiasFit does not keep its input series")
        kwargs = {**data.arguments, **fit_options}
        series = data.input
    elif isinstance(data, AccSeries):
        kwargs, series = dict(fit_options), data
    else:
        raise ValidationError(
            f"close_loop takes an AccSeries, a BiasFit or a Demodulation, got {type(data)}"
        )
    kwargs.update(overrides, close_loop=True)
    fit = fit_bias(series, **kwargs)
    assert fit.closure is not None
    return fit.closure
