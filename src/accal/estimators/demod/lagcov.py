"""Covariance between periods of linear estimators (eq. 21 in the time domain).

``-W_i' T_D W_j`` from the spectra of the weights and the structure function D,
for σ per period and the lags of ``Rd[k]`` (eq. 23).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _fft_length(q: int) -> int:
    return 1 << int(np.ceil(np.log2(3 * q)))


def _lag_kernel(d: NDArray, q: int, k: int) -> NDArray:
    """Frequency kernel of ``T_k[a, b] = D[|k q + b - a|]`` for :func:`_lag_cov`.

    With ``h[j] = D[|kq - j|]`` (j = a - b), ``Σ_ab x_a T_k[a, b] y_b`` is a linear
    correlation of ``x`` with ``h ⊛ y``; by Parseval it is
    ``Σ_f w_f Re(conj(X_f) H_f Y_f)`` over the rfft bins (``w_f`` = 1 at 0 and
    Nyquist, 2 elsewhere), ``H = rfft(h)·exp(2πi f (q-1)/N)/N``.  No inverse FFT
    is needed, and the spectra of the weights are computed once per period.
    """
    nfft = _fft_length(q)
    j = np.arange(-(q - 1), q)
    g = d[np.abs(k * q - j)]
    f = np.arange(nfft // 2 + 1)
    wf = np.full(f.size, 2.0)
    wf[0] = 1.0
    if nfft % 2 == 0:
        wf[-1] = 1.0
    return np.fft.rfft(g, nfft) * np.exp(2j * np.pi * f * (q - 1) / nfft) * wf / nfft


def _weight_spectra(w: NDArray, q: int) -> NDArray:
    """rfft of each estimator's weights on each data axis: (P, 2q, r) → (P, r, 2, F)."""
    p, _, r = w.shape
    x = np.transpose(w.reshape(p, 2, q, r), (0, 3, 1, 2))
    return np.fft.rfft(x, _fft_length(q), axis=3)


def _lag_cov(xa: NDArray, xb: NDArray, kernel: NDArray) -> NDArray:
    """Σ over both data axes of ``-wa_i' T_k wb_i`` from weight spectra: (P, ra, rb).

    ``xa[i]`` belongs to a period ``k`` periods before ``xb[i]``'s (eq. 21 in the
    time domain, with the structure function D; see :func:`_lag_kernel`).
    """
    p, ra, nx, nf = xa.shape
    a = np.conj(xa).reshape(p, ra, nx * nf) * np.tile(kernel, nx)
    b = xb.reshape(p, xb.shape[1], nx * nf)
    return -np.matmul(a, np.transpose(b, (0, 2, 1))).real
