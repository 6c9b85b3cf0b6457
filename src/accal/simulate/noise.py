"""Gaussian coloured noise with a given PSD, by FFT shaping of white noise.

One generator for both simulators: :mod:`accal.simulate.gap` (MicroSTAR noise of
eq. 1 of Lenoir et al. 2013, two-sided PSD) and :mod:`accal.simulate.grace`
(SuperSTAR-like white noise with a 1/f rise).  They differ only in how the
white noise is drawn (in the frequency domain or in time, see ``white``) and
whether the record is padded; both choices are kept so that a given seed gives
the same noise as before the two generators were merged.

References
----------
B. Lenoir, B. Christophe, S. Reynaud, Adv. Space Res. 51 (2013) 188-197,
doi:10.1016/j.asr.2012.08.001 (eq. 1).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import check_option

__all__ = ["coloured_noise"]


def coloured_noise(
    n: int,
    psd: Callable[[ArrayLike], ArrayLike],
    fs: float,
    rng: np.random.Generator,
    *,
    size: int = 1,
    pad: bool = True,
    white: str = "frequency",
) -> NDArray[np.float64]:
    """Gaussian noise with the two-sided PSD ``psd``, by FFT shaping of white noise.

    Each frequency bin of a white spectrum is multiplied by ``sqrt(fs·S(f)·m)``
    (``m`` the FFT length) and transformed back, so that the variance is
    ``∫ S df`` over [−fs/2, fs/2].  The zero-frequency bin (infinite for 1/f
    noise) is set to 0, which only removes the record mean.

    Parameters
    ----------
    n : int
        Samples.
    psd : callable
        Two-sided PSD ``S(f)`` [unit² Hz⁻¹] (e.g. :class:`accal.estimators.noise.MicroStarPSD`),
        evaluated on ``f >= 0``.
    fs : float
        Sampling frequency [Hz].
    rng : numpy.random.Generator
        Random source.
    size : int
        Independent series.
    pad : bool
        Synthesise a record of ``m = 2^ceil(log2 2n)`` samples and cut it, so
        that the circular wrap of the FFT is not visible; otherwise ``m = n``.
    white : {"frequency", "time"}
        Draw the white spectrum as complex normal bins ("frequency") or as the
        FFT of white samples in time ("time").

    Returns
    -------
    ndarray, shape (size, n)
        Noise [unit of ``sqrt(S·Hz)``].
    """
    check_option("white", white, ("frequency", "time"))
    m = 1 << int(np.ceil(np.log2(2 * n))) if pad else int(n)
    f = np.fft.rfftfreq(m, 1.0 / fs)
    with np.errstate(divide="ignore"):
        amp = np.sqrt(fs * np.asarray(psd(f), float) * m)
    amp[0] = 0.0
    if white == "frequency":
        z = rng.standard_normal((size, f.size)) + 1j * rng.standard_normal((size, f.size))
        z /= np.sqrt(2.0)
        if m % 2 == 0:
            z[:, -1] = z[:, -1].real * np.sqrt(2.0)
    else:
        z = np.fft.rfft(rng.standard_normal((size, m)), axis=1) / np.sqrt(m)
    x = np.fft.irfft(z * amp, m, axis=1)
    return x[:, :n]
