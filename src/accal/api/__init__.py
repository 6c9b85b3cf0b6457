"""The Python API: read, fit, close the loop and demodulate in a notebook (issue 21).

Thin wrappers over the functions the command line runs (:mod:`accal.pipeline`,
:mod:`accal.pipeline_closure`, :mod:`accal.pipeline_demod`): the same defaults and
the same numbers as ``accal grace-bias`` and ``accal demod``, in memory, nothing
written.  The results are dataclasses with ``to_dataframe()`` (pandas) and
``to_xarray()`` (units and provenance in the attributes, CF-style ``units`` and
``long_name``).  Everything is in SI units (m/s², m/s³, s); times are GPS seconds
since 2000-01-01 12:00:00 GPS, given as UTC instants beside them in the tables.

The names are exported lazily by :mod:`accal` (``accal.read``, ``accal.fit_bias``,
``accal.close_loop``, ``accal.demodulate``): ``import accal`` stays as fast as the
command line needs.

Modules: :mod:`accal.api.common` (:func:`read`, UTC and CF helpers),
:mod:`accal.api.bias` (:func:`fit_bias`, :class:`BiasFit`), :mod:`accal.api.demod`
(:func:`demodulate`, :class:`Demodulation`), :mod:`accal.api.loop` (:func:`close_loop`)
and :mod:`accal.api.closure_result` (:class:`Closure`).

Examples
--------
>>> import accal
>>> day = accal.read("data/samples/ACC1B_2003-09-14_A_00.asc")
>>> fit = accal.fit_bias(day, method="both")
>>> fit.table()[["axis", "method", "bias", "bias_sigma"]].shape
(6, 4)
>>> fit.to_dataframe().index.tz
datetime.timezone.utc
"""

from __future__ import annotations

from accal.api.bias import BiasFit, fit_bias
from accal.api.closure_result import Closure
from accal.api.common import (
    CALIBRATED_LONG_NAMES,
    CF_UNITS,
    ESTIMATE_VARIABLES,
    QUADRATIC_VARIABLES,
    READ_ENTRY,
    cf_dataset,
    gps_to_utc_index,
    read,
    source_of,
    utc_instants,
)
from accal.api.demod import Demodulation, demodulate, table_variables
from accal.api.loop import close_loop

__all__ = [
    "BiasFit",
    "Closure",
    "Demodulation",
    "close_loop",
    "demodulate",
    "fit_bias",
    "read",
    # helpers the products and tests share
    "CALIBRATED_LONG_NAMES",
    "CF_UNITS",
    "ESTIMATE_VARIABLES",
    "QUADRATIC_VARIABLES",
    "READ_ENTRY",
    "cf_dataset",
    "gps_to_utc_index",
    "source_of",
    "table_variables",
    "utc_instants",
]
