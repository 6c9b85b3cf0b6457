"""Noise from the data (issue 20): the residual spectrum and the noise report.

The periodogram of the per-period residual grouped by rest-mask layout
(:class:`_ResidualSpectra`, pass 1), the PSD fitted to it and the choice between
it and the a-priori PSD (:func:`_noise_report`), and the σ ratio of the two
(:func:`_with_sigma_ratio`).
"""

from __future__ import annotations

import heapq
from collections import OrderedDict
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ..noise import PSD, ResidualSpectrum, fit_residual_psd, psd_nodes, residual_kernel
from .blocks import _Block, _block_basis, _Setup
from .records import NoiseReport
from .weights import _batched_solve, _design_joint

#: Fewest kept periods for σ from the data (``noise="data"``, ``accal demod --psd auto``):
#: a shorter run keeps the a-priori PSD.  With 24 periods (4 h at τ = 600 s) the σ from
#: the data scatters by ~6 % from run to run (docs/demod.md, "σ from the data").
MIN_PERIODS_DATA_PSD = 24
#: Distinct rest-mask layouts whose residual kernels are computed for the PSD estimate;
#: the periods of further layouts (gaps, jitter) are left out of it.
MAX_PSD_LAYOUTS = 24
#: A period whose residual power in the first four bins (``1/τ … 4/τ``, where σ is
#: set) is over this many times the median period's is left out of the noise estimate
#: (a feature of the data the model lacks: a 1e-9 m/s² step of the signal inside a
#: rotation made every period's σ 7.7× its true error, QA 2026-11-29), and its σ is
#: scaled by the root of its ratio.  For Gaussian noise the ratio is a χ² of 4-16
#: degrees of freedom over its median: above 25 with probability < 1e-16.
MISFIT_POWER = 25.0
#: Most periods left out so (the largest kept for it), and their largest share: a run
#: with more is not stationary, and its noise estimate keeps them all.
MISFIT_MAX = 256
MISFIT_SHARE = 0.05
#: Bytes of residual kernels kept (:func:`_layout_kernel`): a closure run demodulates
#: the same run again with its effects removed (same layouts, same kernels).
KERNEL_CACHE_BYTES = 64 * 2**20
_KERNELS: OrderedDict[bytes, tuple[NDArray, NDArray]] = OrderedDict()


def _layout_kernel(
    x: NDArray, m: NDArray, bins: NDArray, fs: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`accal.estimators.noise.residual_kernel` of one rest-mask layout, kept.

    The kernel depends on the layout's design and mask only, not on the data: the
    second demodulation of a closure run (its effects removed, ``close_run``) has the
    same layouts, and its ~0.15 s of FFTs per layout are saved (``make
    bench-closure``).  At most :data:`KERNEL_CACHE_BYTES` of kernels are kept (least
    recently used dropped; each ``len(bins) × 4·q`` floats), read-only.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    m = np.ascontiguousarray(m, dtype=np.float64)
    bins = np.ascontiguousarray(bins, dtype=np.int64)
    key = b"".join(
        (repr((x.shape, m.shape, bins.shape, float(fs))).encode(), x.tobytes(), m.tobytes(),
         bins.tobytes())
    )  # fmt: skip
    hit = _KERNELS.get(key)
    if hit is None:
        hit = residual_kernel(x, m, bins, fs)
        for a in hit:
            a.setflags(write=False)
        _KERNELS[key] = hit
        while (
            len(_KERNELS) > 1 and sum(k.nbytes for _, k in _KERNELS.values()) > KERNEL_CACHE_BYTES
        ):
            _KERNELS.popitem(last=False)
    else:
        _KERNELS.move_to_end(key)
    return hit


class _ResidualSpectra:
    """Periodogram of the per-period residual, grouped by rest-mask layout (pass 1).

    The residual is that of a least-squares fit, per period and on the unmasked
    samples, of eq. 17 with an affine signal (eq. 19) and the affine bias plus
    the auxiliary channels (``Va = V̂b = [1, u]``): a signal that varies within
    the period (a slope) does not enter the noise estimate, whatever
    ``signal_model``.  A quadratic term in either would take what is left of the
    noise around ``2/τ``, the band that sets σ (eq. 26): a period of ``q``
    unmasked samples has ~6 degrees of freedom per axis below ``4/τ``.  What the fit removes from the noise is in
    the kernel (:func:`accal.estimators.noise.residual_kernel`), computed once per
    layout (the first period of the layout stands for its auxiliary channels).
    """

    def __init__(self, q: int, fs: float) -> None:
        self.q, self.fs = q, fs
        top = q // 2
        low = np.arange(1, min(32, top) + 1)
        high = np.round(np.geomspace(33, top, 96)).astype(np.int64) if top > 33 else low[:0]
        self.bins = np.unique(np.concatenate([low, high]))
        self.groups: dict[bytes, list[Any]] = {}
        self.skipped = 0
        self.low = self.bins <= 4  # 1/τ … 4/τ
        self.band_power: list[float] = []  # every period added
        self.band_period: list[int] = []  # its period index
        self.top: list[tuple[float, int, bytes, NDArray]] = []  # the largest (heap)
        self.misfit: dict[int, float] = {}

    def add(self, st: _Setup, blk: _Block, keep: NDArray) -> None:
        m, c, s, _, vb, _ = _block_basis(st, blk)
        ones = np.ones_like(m)
        va = np.stack([ones, ones * st.u, ones * (st.u**2 - np.mean(st.u**2))], axis=2)
        x = _design_joint(va, vb, c, s, m)
        a = blk.arrs
        ok = a["valid"].astype(bool)
        data = np.concatenate([np.where(ok, a["m_y"], 0.0), np.where(ok, a["m_z"], 0.0)], axis=1)
        mm = np.concatenate([m, m], axis=1)
        data = data * mm
        n = np.einsum("pqa,pqb->pab", x, x)
        sol, good = _batched_solve(n, np.einsum("pqa,pq->pa", x, data)[..., None])
        use = keep & good
        if not use.any():
            return
        r = (data - np.einsum("pqa,pa->pq", x, np.nan_to_num(sol[..., 0]))) * mm
        q = st.q
        spec = np.fft.rfft(r[:, :q], axis=1)[:, self.bins]
        power = np.abs(spec) ** 2
        spec = np.fft.rfft(r[:, q:], axis=1)[:, self.bins]
        power += np.abs(spec) ** 2
        cm, sm = np.round(c * m, 6), np.round(s * m, 6)
        for i in np.flatnonzero(use):
            key = m[i].astype(bool).tobytes() + cm[i].tobytes() + sm[i].tobytes()
            g = self.groups.get(key)
            if g is None:
                if len(self.groups) >= MAX_PSD_LAYOUTS:
                    self.skipped += 1
                    continue
                g = self.groups[key] = [0, np.zeros(self.bins.size), x[i], m[i]]
            g[0] += 1
            g[1] += power[i]
            self._note(float(power[i][self.low].sum()), blk.p0 + int(i), key, power[i])

    def _note(self, band: float, period: int, key: bytes, power: NDArray) -> None:
        """Keep a period's band power, and its power while among the largest."""
        self.band_power.append(band)
        self.band_period.append(period)
        item = (band, period, key, power.copy())
        if len(self.top) < MISFIT_MAX:
            heapq.heappush(self.top, item)
        elif band > self.top[0][0]:
            heapq.heapreplace(self.top, item)

    def _drop_misfits(self) -> None:
        """Take the periods of :data:`MISFIT_POWER` times the median band power out of
        the groups (``self.misfit``: period → root of the ratio), unless there are more
        than :data:`MISFIT_MAX` or :data:`MISFIT_SHARE` of the periods."""
        if self.misfit or len(self.band_power) < 8:
            return
        med = float(np.median(self.band_power))
        if not med > 0:
            return
        big = [it for it in self.top if it[0] > MISFIT_POWER * med]
        n_big = sum(b > MISFIT_POWER * med for b in self.band_power)
        if not big or n_big > len(big) or n_big > MISFIT_SHARE * len(self.band_power):
            return
        for band, period, key, power in big:
            g = self.groups[key]
            g[0] -= 1
            g[1] = g[1] - power
            if g[0] == 0:
                del self.groups[key]
            self.misfit[period] = float(np.sqrt(band / med))

    @property
    def n_periods(self) -> int:
        return sum(g[0] for g in self.groups.values())

    def spectrum(self) -> ResidualSpectrum | None:
        self._drop_misfits()
        if not self.groups:
            return None
        f_grid, kern, power = None, 0.0, 0.0
        for count, pw, x, m in self.groups.values():
            f_grid, k = _layout_kernel(x, m, self.bins, self.fs)
            kern = kern + count * k
            power = power + pw
        return ResidualSpectrum(
            self.bins * self.fs / self.q, power, f_grid, kern, self.n_periods, n_axes=2
        )


#: Periods of a block of :func:`level_factors` (2 h at τ = 600 s).
LEVEL_BLOCK = 12
#: Degrees of freedom of one period's band power (bins 1-4, two axes, re and im: 16,
#: halved for the mask's correlation of neighbouring bins).
LEVEL_DOF = 8.0
#: Family-wise level of the test of one noise level over the run.
LEVEL_P = 1e-3


def level_factors(spectra: _ResidualSpectra) -> tuple[dict[int, float], float]:
    """Per period, the factor by which the run's noise level near ``2/τ`` differs there,
    and the ratio of the highest block level to the lowest (1 when the run is stationary).

    The PSD behind σ is the run's average.  A QA run whose noise was 3× larger in its
    first half had per-period z std 1.33 there (|z| > 3 on 2.6 %) and 0.45 in the second
    half, with the consistency check at 1.00.  The periods' band powers (their residual
    power over ``1/τ … 4/τ``, the misfits left out) are averaged in blocks of
    :data:`LEVEL_BLOCK`; when the blocks' means are not one level (χ² of their log
    ratios to the run's mean, each block's variance ``2/(LEVEL_DOF · n)``, above its
    :data:`LEVEL_P` quantile) each period's σ is scaled by the root of its block's mean
    over the run's (the noise's shape assumed the same, its level not).  Otherwise no
    period is scaled: a stationary run's σ are unchanged.
    """
    per = [
        (k, b)
        for k, b in zip(spectra.band_period, spectra.band_power, strict=True)
        if k not in spectra.misfit
    ]
    if len(per) < 3 * LEVEL_BLOCK:
        return {}, 1.0
    per.sort()
    keys = np.array([k for k, _ in per])
    band = np.array([b for _, b in per], dtype=np.float64)
    mean = float(band.mean())
    if not mean > 0:
        return {}, 1.0
    n_blocks = band.size // LEVEL_BLOCK
    edges = np.linspace(0, band.size, n_blocks + 1).round().astype(int)
    means = np.array([band[a:b].mean() for a, b in zip(edges[:-1], edges[1:], strict=True)])
    sizes = np.diff(edges)
    if not np.all(means > 0):
        return {}, 1.0
    stat = float(np.sum((np.log(means / mean)) ** 2 * LEVEL_DOF * sizes / 2.0))
    spread = float(means.max() / means.min())
    if chi2.sf(stat, n_blocks - 1) > LEVEL_P:
        return {}, spread
    out = {}
    for (a, b), m in zip(zip(edges[:-1], edges[1:], strict=True), means, strict=True):
        f = float(np.sqrt(m / mean))
        out.update({int(k): f for k in keys[a:b]})
    return out, spread


def _noise_report(
    spectra: _ResidualSpectra | None,
    apriori: PSD,
    noise: str,
    min_periods: int,
    tau: float,
    fs: float,
) -> NoiseReport | None:
    """Estimate the PSD from the residual spectrum and decide which PSD is used."""
    if spectra is None:
        return None
    spec = spectra.spectrum()
    n = 0 if spec is None else spec.n_segments
    fit = None
    reason = ""
    if spec is None or n < min_periods or spectra.q < 8:
        reason = f"{n} period(s) for the noise estimate, fewer than {min_periods}" + (
            f" ({spectra.skipped} in rest-mask layouts beyond the first {MAX_PSD_LAYOUTS})"
            if spectra.skipped
            else ""
        )
        if spectra.q < 8:
            reason = f"{spectra.q} samples per period are too few for a noise spectrum"
    else:
        fit = fit_residual_psd(spec, psd_nodes(tau, fs))
    use_data = noise == "data" and fit is not None
    used = fit.psd if use_data else apriori
    band = (1.0 / tau, 4.0 / tau)
    ratio = scatter = float("nan")
    if spec is not None:
        ratio = spec.power_ratio(used, band)
        nb = int(np.count_nonzero((spec.f_bins >= band[0]) & (spec.f_bins <= band[1])))
        scatter = float(np.sqrt(2.0 / max(spec.dof * nb, 1)))
    if noise == "report":
        reason = "a-priori PSD asked for"
    levels, spread = level_factors(spectra)
    return NoiseReport(
        source="data" if use_data else "apriori",
        reason=reason,
        fit=fit,
        apriori=apriori,
        used=used,
        check_ratio=ratio,
        check_scatter=scatter,
        band=band,
        n_periods=n,
        misfit=dict(spectra.misfit),
        level=levels,
        level_spread=spread,
    )


def _with_sigma_ratio(
    report: NoiseReport | None, rd_used: float, rd_other: float
) -> NoiseReport | None:
    """``report`` with ``sigma_ratio`` = σ(a-priori PSD)/σ(data PSD) for the same weights."""
    if report is None or report.fit is None or not (rd_used > 0 and rd_other > 0):
        return report
    r = rd_other / rd_used if report.source == "data" else rd_used / rd_other
    return replace(report, sigma_ratio=float(np.sqrt(r)))
