"""The band in which a scale error is measured against a reference.

A scale error multiplies everything the accelerometer measured, so the residual
``raw − reference`` holds ``δs · a`` at every frequency where the two agree.  They do
not agree where one of them is filtered and the other is not: Level-1B data are
low-passed by the processing's CRN filter, a modelled reference (drag from a density
model, solar pressure with a shadow function) is not, and a POD-derived one is
smoothed its own way.  Above the filter's passband the residual then holds
``LP(a) − a``, whose correlation with the reference ``a`` is ``−Σ |A(f)|² H(f)(1 −
H(f))``: a "scale error" that is not there.  QA (2026-11-29, an outside generator):
with the reference's 40 s eclipse ramps sharp and the data's filtered, clean days had
scale errors of −3.2 % (y), −0.44 % (z) and −0.34 % (x) removed, at 3-7σ, and the
bias moved by up to 7.4σ; with the reference filtered like the data, nothing.

So the scale candidate's regressor is the reference low-passed to :data:`CUTOFF`,
well inside any Level-1B filter's passband (the CRN filters of the GRACE and
GRACE-FO processing pass 0.1 Hz to within a few per cent; the orbit signal that pins
a scale lies at 0.18 mHz and its first harmonics), by an ideal low-pass: the Fourier
coefficients above the cut-off set to zero, on the record extended by its odd
reflection at both ends (no jump at the ends; the level and slope there are kept).
An ideal low-pass ``P`` is a projection (``P = Pᵀ = P²``), so the least-squares
coefficient of ``P·a`` in ``δs·a + e`` is ``δs`` plus the share of ``e`` in the band:
a gradual cut-off ``H`` biases it by ``Σ |A|² H(1 − H) / Σ |A|² H²`` (+0.85 % of δs
with a fourth-order Butterworth response at 1 mHz on a QA day: 1.0085e-2 ± 4e-5 for
a 1e-2 scale error, against 1.00e-2 ± 4e-5 with the ideal one).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["CUTOFF", "band_limited"]

#: Cut-off frequency of the scale's band [Hz] (about 5.6 cycles per GRACE orbit).
CUTOFF = 1e-3


def band_limited(
    t: NDArray[np.float64], x: NDArray[np.float64], step: float, cutoff: float = CUTOFF
) -> NDArray[np.float64]:
    """``x`` [any unit] at times ``t`` [s] low-passed to ``cutoff`` [Hz] (module notes).

    The samples are placed on their nominal grid of spacing ``step`` [s]; missing grid
    points and non-finite values are bridged linearly before filtering and not returned.
    A record shorter than four samples, or one that holds less than a cycle of the
    cut-off, is returned as it is.
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x) & np.isfinite(t)
    if ok.sum() < 4 or not step > 0:
        return x.copy()
    k = np.round((t - t[ok][0]) / step).astype(np.int64)
    n = int(k[ok].max()) + 1
    if n * step * cutoff < 1.0 or k[ok].min() < 0:
        return x.copy()
    grid = np.interp(np.arange(n), k[ok], x[ok])
    # odd reflection at both ends: 2·x[0] − x[m..1], x, 2·x[−1] − x[−2..−m−1]
    m = min(n - 1, int(np.ceil(4.0 / (cutoff * step))))
    ext = np.r_[2 * grid[0] - grid[m:0:-1], grid, 2 * grid[-1] - grid[-2 : -m - 2 : -1]]
    f = np.fft.rfftfreq(ext.size, step)
    spec = np.fft.rfft(ext)
    spec[f > cutoff] = 0.0
    y = np.fft.irfft(spec, n=ext.size)[m : m + n]
    out = x.copy()
    inside = (k >= 0) & (k < n)
    out[inside] = y[k[inside]]
    return out
