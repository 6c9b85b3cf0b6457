"""The null model of :func:`accal.closure.select.close_loop` for a set of used samples.

:class:`NullSetup` builds it (again after outliers are left out, after jumps are
taken out, and with the proxies orthogonal to the effects found): the declared base
(bias, drift), with no reference the orbit template
(:class:`accal.closure.nuisance.OrbitTemplate`) and the other axes' unexplained signal
(:func:`accal.closure.proxybasis.add_proxies`); :func:`null_fit` is its fit, leverage
spectrum and projection bias (:func:`accal.closure.residual.projection_bias`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.closure.basis import Basis
from accal.closure.inputs import base_design
from accal.closure.nuisance import OrbitTemplate, template_order
from accal.closure.period import estimate_period
from accal.closure.proxybasis import add_proxies
from accal.closure.residual import make_grid, projection_bias
from accal.closure.validation import SignalProxies
from accal.errors import ValidationError

__all__ = ["NullSetup", "null_fit"]


class NullSetup:
    """Builds the null model for a set of used samples (again after outliers are left out)."""

    def __init__(self, t_all, y_all, base, chan_all, names, signal_model, orbit_period, fixed):
        self.t_all, self.y_all, self.base = t_all, y_all, base
        self.y_all_given = y_all  # the data as given (y_all: less the jumps taken out)
        self.chan_all, self.names = chan_all, names
        self.signal_model, self.orbit_period = signal_model, orbit_period
        self.period_fixed = bool(fixed)
        self.t_first: float | None = None  # the first used sample of the first build
        #: the other axes' signal in the null model (an orbit template only: with_proxies)
        self.proxies: SignalProxies | None = None
        self.proxies_in_model: tuple[str, ...] = ()
        #: columns (all samples) the proxies are made orthogonal to (add_proxies)
        self.proxy_exclude: NDArray[np.float64] | None = None

    def build(self, use: NDArray[np.bool_]) -> dict[str, Any]:
        t_u, y_u = self.t_all[use], self.y_all[use]
        chan_u = None if self.chan_all is None else self.chan_all[use]
        t0 = float(t_u[0])
        if self.t_first is None:
            self.t_first = t0
        span = float(t_u[-1] - t_u[0]) or 1.0
        grid = make_grid(t_u, chan_u)
        bbase = base_design(self.base, self.t_all, t0, span, self.chan_all, self.names)
        plain = Basis(bbase.block[use], bbase.columns[use], n_blocks=bbase.n_blocks)
        if plain.rank_total + 10 > t_u.size:
            raise ValidationError(
                f"the base has rank {plain.rank_total} for {t_u.size} usable samples: "
                "nothing is left to test"
            )
        template, basis0, bias0, signal0 = None, plain, None, None
        if (
            self.signal_model == "orbit"
            and self.orbit_period
            and chan_u is None
            and bbase.n_blocks == 1
            and isinstance(self.base, str)
            and span >= 2.0 * self.orbit_period
        ):
            period = float(self.orbit_period)
            if not self.period_fixed:
                period = estimate_period(t_u, plain.fit(y_u).resid, period)
                # the second build (outliers left out) keeps it
                self.orbit_period, self.period_fixed = period, True
            degree = int(self.base[-1]) if isinstance(self.base, str) else -1
            template = OrbitTemplate(t_u, period, template_order(span / period), degree)
            if self.proxies is not None:
                exclude = None if self.proxy_exclude is None else self.proxy_exclude[use]
                used = add_proxies(template, self.proxies.columns[use], t_u - t0, y_u, exclude)
                self.proxies_in_model = tuple(self.proxies.names[j] for j in used)
            basis0 = Basis(bbase.block[use], bbase.columns[use], nuisance=template)
            # the smooth curve counts with the bias for identifiability: a sharp step is
            # told from the signal by its edge, however much of it the curve takes
            smooth = template.smooth_columns
            bias0 = plain.extend(smooth) if smooth.shape[1] else plain
        elif bbase.signal:
            keep = [j for j in range(bbase.p) if j not in bbase.signal]
            bias0 = Basis(bbase.block[use], bbase.columns[use][:, keep], n_blocks=bbase.n_blocks)
            if bbase.signal_extension is not None:
                ext = np.column_stack([bbase.columns, bbase.signal_extension])[use]
                signal0 = Basis(bbase.block[use], ext, n_blocks=bbase.n_blocks)
        fit0, lev0, beta = null_fit(basis0, grid, y_u)
        return {
            "t_u": t_u,
            "chan_u": chan_u,
            "t0": t0,
            "span": span,
            "grid": grid,
            "bbase": bbase,
            "basis0": basis0,
            "bias0": bias0,
            "signal0": signal0,
            "template": template,
            "fit0": fit0,
            "lev0": lev0,
            "beta": beta,
        }


def null_fit(basis0: Basis, grid, y_u):
    """The null model's fit, leverage spectrum and projection bias: (fit, lev, beta)."""
    fit0 = basis0.fit(y_u)
    lev_white = basis0.leverage(grid)
    beta = projection_bias(grid, basis0, fit0.resid, lev_white)
    nc = np.maximum(grid.counts, 1.0)[:, None]
    return fit0, nc - (nc - lev_white) * beta, beta
