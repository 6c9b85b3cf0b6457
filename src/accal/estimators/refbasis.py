"""Temporal bases for an accelerometer bias: polynomials and cubic B-splines.

``poly0``/``poly1``/``poly2`` are Legendre polynomials on the arc mapped onto
[−1, 1] (the same space as 1, t, t², better conditioned); ``spline:6h`` (any
node spacing with a unit ``s``, ``min``, ``h`` or ``d``) is a cubic B-spline with
uniform nodes over the arc, continuous with two continuous derivatives across
the days of a multi-day arc, as GROOPS parametrises accelerometer biases
(``InstrumentAccelerometerEstimateBiasScale`` with a ``splines`` temporal
representation; de Boor, *A Practical Guide to Splines*, 2001, ch. IX).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from accal.errors import ValidationError

__all__ = ["BiasBasis", "parse_bias_basis"]

_UNITS = {"s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


@dataclass(frozen=True)
class BiasBasis:
    """A bias basis on the arc ``[t0, t1]``.

    Attributes
    ----------
    kind : str
        ``"poly"`` or ``"spline"``.
    degree : int
        Polynomial degree (poly) or 3 (cubic spline).
    node_step : float
        Node spacing of a spline [s] (NaN for poly).
    t0, t1 : float
        The arc [s, GPS].
    """

    kind: str
    degree: int
    node_step: float
    t0: float
    t1: float

    @property
    def knots(self) -> NDArray[np.float64]:
        """Spline knot vector (clamped: end knots repeated), or empty for poly."""
        if self.kind != "spline":
            return np.zeros(0)
        n_int = max(1, math.ceil((self.t1 - self.t0) / self.node_step - 1e-9))
        inner = self.t0 + self.node_step * np.arange(n_int + 1)
        k = self.degree
        return np.concatenate([[inner[0]] * k, inner, [inner[-1]] * k])

    @property
    def size(self) -> int:
        """Number of coefficients."""
        if self.kind == "poly":
            return self.degree + 1
        return self.knots.size - self.degree - 1

    def name(self) -> str:
        """The basis as given on the command line, e.g. ``poly1`` or ``spline:21600s``."""
        if self.kind == "poly":
            return f"poly{self.degree}"
        return f"spline:{self.node_step:g}s"

    def design(self, t: NDArray[np.float64], deriv: int = 0) -> tuple[NDArray[np.float64], int]:
        """Columns of the basis that are non-zero on ``t`` (sorted times in the arc).

        Returns
        -------
        cols : ndarray, shape (len(t), m)
            Values (``deriv=0``, [1]) or time derivatives (``deriv=1``, [1/s]).
        first : int
            Index of the first returned column among the ``size`` coefficients.
        """
        t = np.asarray(t, dtype=np.float64)
        if self.kind == "poly":
            half = 0.5 * (self.t1 - self.t0) or 1.0
            u = (t - 0.5 * (self.t0 + self.t1)) / half
            v = np.polynomial.legendre.legvander(u, self.degree)
            if deriv:
                dv = np.zeros_like(v)
                for j in range(1, self.degree + 1):
                    c = np.zeros(j + 1)
                    c[j] = 1.0
                    dv[:, j] = np.polynomial.legendre.legval(u, np.polynomial.legendre.legder(c))
                v = dv / half
            return v, 0
        knots = self.knots
        k = self.degree
        tc = np.clip(t, knots[k], knots[-k - 1])
        if t.size == 0:
            return np.zeros((0, 0)), 0
        lo = int(np.searchsorted(knots, tc[0], side="right")) - 1 - k
        hi = int(np.searchsorted(knots, tc[-1], side="right")) - 1
        lo = max(lo, 0)
        hi = min(hi, self.size - 1)
        m = hi - lo + 1
        eye = np.eye(self.size)[lo : hi + 1]
        cols = np.empty((t.size, m))
        for j in range(m):
            spl = BSpline(knots, eye[j], k, extrapolate=False)
            cols[:, j] = (spl.derivative(deriv) if deriv else spl)(tc)
        return np.nan_to_num(cols), lo


def parse_bias_basis(spec: str, t0: float, t1: float) -> BiasBasis:
    """Parse ``--bias-basis``: ``poly0|poly1|poly2|spline:STEP`` (e.g. ``spline:6h``).

    Raises
    ------
    ValidationError
        For anything else, or a spline step that is not positive.
    """
    s = spec.strip().lower()
    m = re.fullmatch(r"poly([0-3])", s)
    if m:
        return BiasBasis("poly", int(m.group(1)), float("nan"), t0, t1)
    m = re.fullmatch(r"spline:([0-9.eE+]+)\s*(s|min|h|d)?", s)
    if m:
        try:
            step = float(m.group(1)) * _UNITS[m.group(2) or "s"]
        except ValueError:
            step = float("nan")
        if not (math.isfinite(step) and step > 0):
            raise ValidationError(f"--bias-basis {spec!r}: the node step must be positive")
        return BiasBasis("spline", 3, step, t0, t1)
    raise ValidationError(
        f"--bias-basis {spec!r}: expected poly0, poly1, poly2, poly3 or spline:STEP "
        "(e.g. spline:6h; units s, min, h, d)"
    )
