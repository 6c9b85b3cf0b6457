"""The two passes of :func:`demodulate_stream` over the blocks of a record.

Pass 1 (:func:`_first_pass`, :class:`_Scan`) checks every chunk, finds the usable
periods, the eq. 16 leakage, the rotation layouts and, when the noise is taken
from the data, the residual spectra.  Between the passes :func:`_noise_kernels`
sets the structure function, the lag kernels of eq. 21 and the GLS
autocovariance.  Pass 2 (:func:`_second_pass`, :class:`_Estimates`) estimates
and sums the lagged covariances of Rd[k] (eq. 23) across block borders.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import NDArray

from ...errors import ValidationError
from ..noise import PSD, regularised_autocov, structure_function
from .blocks import _Block, _chunks_of, _Periods, _Setup
from .checks import _Checker
from .estimate import _estimate_block, _scan_block
from .lagcov import _fft_length, _lag_cov, _lag_kernel
from .layout import LAYOUT_LAGS, _layout_shifts
from .records import DemodChunk, NoiseReport
from .residual import _ResidualSpectra


class _Scan:
    """Pass 1 over the blocks: usable periods, eq. 16 leakage, rotation layouts.

    With a :class:`_ResidualSpectra` (``noise`` other than ``"apriori"``), also the
    residual spectra of the kept periods.
    """

    def __init__(self, st: _Setup, spectra: _ResidualSpectra | None) -> None:
        self.st, self.spectra = st, spectra
        self.n_per, self.n_keep, self.best, self.leak_max = 0, 0, 0, 0.0
        self.shifts: dict[int, list[NDArray]] = {lag: [] for lag in range(1, LAYOUT_LAGS + 1)}
        self.last_spec: NDArray | None = None

    def __call__(self, blk: _Block | None) -> None:
        if blk is None:
            return
        st = self.st
        n_used, keep, leak = _scan_block(st, blk)
        if self.spectra is not None:
            self.spectra.add(st, blk, keep)
        sh, self.last_spec = _layout_shifts(blk.rest, self.last_spec)
        for lag, d in sh.items():
            self.shifts[lag].append(d)
        self.n_per += n_used.size
        self.n_keep += int(keep.sum())
        self.best = max(self.best, int(n_used.max()))
        if keep.any():
            self.leak_max = max(self.leak_max, float(np.max(leak[keep])))


def _new_setup(
    chk: _Checker,
    *,
    tau: float,
    mask: float,
    method: str,
    signal_model: str,
    aux_names: tuple[str, ...],
    min_fraction: float,
    n_lags: int,
) -> _Setup:
    """The :class:`_Setup` of a record, once its first chunk has been checked."""
    q = chk.q
    pa = 1 if signal_model == "mean" else 2
    return _Setup(
        q=q,
        fs=chk.fs,
        tau=tau,
        mask=mask,
        method=method,
        signal_model=signal_model,
        aux_names=aux_names,
        need=max(min_fraction * (q - mask * chk.fs), 2 * (pa + 2 + len(aux_names))),
        d=np.empty(0),
        r_reg=None,
        n_lags=int(n_lags),
    )


def _first_pass(
    source: Callable[[], Iterable[DemodChunk]],
    chk: _Checker,
    new_setup: Callable[[_Checker], _Setup],
    *,
    rest_tol: float,
    settle: float,
    noise: str,
) -> _Scan:
    """Pass 1: checks, rest masks, usable periods, eq. 16 leakage.

    ``new_setup`` makes the record's :class:`_Setup` once ``chk`` has checked the
    first chunk (:func:`_new_setup` with the options bound).

    Raises
    ------
    ValidationError
        A chunk fails a check of ``chk``, the record is shorter than one period,
        or no period has enough unmasked samples at both θ = 0 and π.
    """
    cutter: _Periods | None = None
    scan: _Scan | None = None
    for ch in _chunks_of(source):
        arrs = chk(ch)
        if cutter is None:
            q = chk.q
            cutter = _Periods(q, int(round(settle * chk.fs)), rest_tol)
            st = new_setup(chk)
            scan = _Scan(st, _ResidualSpectra(q, chk.fs) if noise != "apriori" else None)
        scan(cutter.feed(arrs))
    if cutter is None:
        raise ValidationError("need at least 3 samples, got 0")
    chk.finish()
    scan(cutter.finish())
    st = scan.st
    if scan.n_per < 1:
        raise ValidationError(f"record of {chk.n} samples is shorter than one period ({st.q})")
    if scan.n_keep == 0:
        raise ValidationError(
            f"no period has enough unmasked samples at both θ = 0 and π (need {st.need:g} of "
            f"{st.q}; best period has {scan.best}). A sample is at rest where θ's first and second "
            f"differences are within {rest_tol:g} rad (--rest-tol; raise it if θ is noisy at "
            "rest), and the rests must be at θ = 0 and π"
        )
    return scan


def _noise_kernels(st: _Setup, used_psd: PSD, report: NoiseReport | None, solver: str) -> None:
    """Set ``st.d``, the lag kernels of eq. 21 and, for GLS, the autocovariance ``st.r_reg``.

    ``st.kernel_other`` is the lag-0 kernel of the PSD not used (for the σ ratio
    of the :class:`NoiseReport`), when the PSD could be estimated from the data.
    """
    st.d = structure_function(used_psd, (st.n_lags + 2) * st.q, st.fs)
    st.kernels = [_lag_kernel(st.d, st.q, k) for k in range(st.n_lags + 1)]
    if report is not None and report.fit is not None:
        other = report.apriori if report.source == "data" else report.fit.psd
        st.kernel_other = _lag_kernel(structure_function(other, st.q + 1, st.fs), st.q, 0)
    if solver == "gls-eq17":
        st.r_reg, _ = regularised_autocov(st.d, st.q)


class _Estimates:
    """Pass 2 over the blocks: per-period rows, and Rd[k] summed across block borders."""

    def __init__(self, st: _Setup, solver: str) -> None:
        self.st, self.solver = st, solver
        self.rows: list[dict[str, NDArray]] = []
        self.rd_sum = np.zeros(st.n_lags + 1)
        self.rd_cnt = np.zeros(st.n_lags + 1, dtype=np.int64)
        self.rd_other = 0.0
        self.prev_w = np.zeros((0, 1, 2, _fft_length(st.q) // 2 + 1), complex)
        self.prev_keep = np.zeros(0, bool)
        self.n_masked, self.n_samples = 0.0, 0
        self.cache: dict = {}

    def __call__(self, blk: _Block | None) -> None:
        if blk is None:
            return
        r = _estimate_block(self.st, blk, self.solver, self.cache)
        self.rows.append(r["rows"])
        keep = r["keep"]
        self.rd_sum[0] += float(np.sum(r["rd0"][keep]))
        if r["rd0_other"] is not None:
            self.rd_other += float(np.sum(r["rd0_other"][keep]))
        self.rd_cnt[0] += int(keep.sum())
        self.n_masked += r["n_masked"]
        self.n_samples += r["n_samples"]
        self._add_lags(r["spec1"], keep)

    def _add_lags(self, spec1: NDArray, keep: NDArray) -> None:
        """Rd[k], k ≥ 1: pairs of kept periods ``k`` apart, the previous blocks' last included."""
        st = self.st
        w_ext = np.concatenate([self.prev_w, spec1])
        k_ext = np.concatenate([self.prev_keep, keep])
        lp = self.prev_w.shape[0]
        for k in range(1, st.n_lags + 1):
            i0, i1 = max(0, lp - k), w_ext.shape[0] - k
            if i1 <= i0:
                continue
            both = k_ext[i0:i1] & k_ext[i0 + k : i1 + k]
            if not both.any():
                continue
            ck = _lag_cov(w_ext[i0:i1][both], w_ext[i0 + k : i1 + k][both], st.kernels[k])
            self.rd_sum[k] += float(np.sum(ck[:, 0, 0]))
            self.rd_cnt[k] += int(both.sum())
        self.prev_w = w_ext[-st.n_lags :] if st.n_lags else w_ext[:0]
        self.prev_keep = k_ext[-st.n_lags :] if st.n_lags else k_ext[:0]


def _second_pass(
    source: Callable[[], Iterable[DemodChunk]],
    st: _Setup,
    solver: str,
    chk: _Checker,
    *,
    rest_tol: float,
    settle: float,
) -> _Estimates:
    """Pass 2: estimates, covariances, Rd[k] across block borders.

    Raises
    ------
    ValidationError
        The design is singular in every period.
    """
    acc = _Estimates(st, solver)
    cutter = _Periods(st.q, int(round(settle * st.fs)), rest_tol)
    for ch in _chunks_of(source):
        acc(cutter.feed(chk(ch)))
    acc(cutter.finish())
    if not any(r["period_index"].size for r in acc.rows):
        raise ValidationError(
            "the design is singular in every period (auxiliary channel constant?)"
        )
    return acc
