"""Close the loop: trace a fit's residual to effects the model lacks, add them, refit.

Layer 2 (see ``shared/STYLE.md`` §4): arrays in, findings out; only
:mod:`accal.closure.report` writes files, and only where its caller says.

>>> from accal.closure import close_loop                      # doctest: +SKIP
>>> res = close_loop(t, a_x, aux={"temp": temp}, orbit_period=5600.0)
>>> res.to_dict()["effects"]
"""

from accal.closure.blockbase import BlockBase
from accal.closure.candidates import Context, Proposal
from accal.closure.kinds import EFFECT_NAMES, Kind, effect_label, kind_of, kinds
from accal.closure.platform import PlatformInfo
from accal.closure.residual import ResidualStats, characterise
from accal.closure.results import BaseCoefficient, ClosureResult, Effect
from accal.closure.select import DEFAULT_CANDIDATES, close_loop

__all__ = [
    "DEFAULT_CANDIDATES",
    "EFFECT_NAMES",
    "BaseCoefficient",
    "BlockBase",
    "ClosureResult",
    "Context",
    "Effect",
    "Kind",
    "PlatformInfo",
    "Proposal",
    "ResidualStats",
    "characterise",
    "close_loop",
    "effect_label",
    "kind_of",
    "kinds",
]
