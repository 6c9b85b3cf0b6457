"""Streaming machinery: chunks → blocks of whole periods, and their bases.

The chunks of a source (:func:`_chunks_of`), cut into blocks of whole periods
with the rest mask of section 4.2 (:class:`_Periods`), what is common to every
block of a record (:class:`_Setup`), and a block's mask, cos/sin, ``Va`` and
``V̂b`` (eqs. 18-19, :func:`_block_basis`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ...errors import ValidationError
from ..design import rest_mask
from .records import DemodChunk


def _chunks_of(source: Callable[[], Iterable[DemodChunk]]) -> Iterator[DemodChunk]:
    """The chunks of ``source()``, the leading ones merged until there are 3 samples
    (enough for the median step)."""
    it = source()
    if isinstance(it, DemodChunk):
        raise ValidationError("source() must return an iterable of DemodChunk, got one chunk")
    head: list[DemodChunk] | None = []
    for ch in it:
        if head is None:
            yield ch
            continue
        head.append(ch)
        if sum(np.size(c.time) for c in head) >= 3:
            yield _concat_chunks(head)
            head = None
    if head:
        yield _concat_chunks(head)


def _concat_chunks(chunks: list[DemodChunk]) -> DemodChunk:
    if len(chunks) == 1:
        return chunks[0]

    def cat(xs):
        return np.concatenate([np.asarray(x, float) for x in xs])

    valid = None
    if any(c.valid is not None for c in chunks):
        valid = np.concatenate(
            [
                np.ones(np.size(c.time), bool) if c.valid is None else np.asarray(c.valid, bool)
                for c in chunks
            ]
        )
    return DemodChunk(
        cat(c.time for c in chunks),
        cat(c.m_y for c in chunks),
        cat(c.m_z for c in chunks),
        cat(c.theta for c in chunks),
        {k: cat(c.aux[k] for c in chunks) for k in chunks[0].aux},
        valid,
    )


@dataclass
class _Block:
    p0: int  # index of the first period
    arrs: dict[str, NDArray]  # (P, q) arrays
    rest: NDArray  # (P, q) bool: discrete θ̇ = θ̈ = 0 (section 4.2)


class _Periods:
    """Cut a stream of sample arrays into blocks of whole periods.

    The incomplete last period of a chunk is carried over to the next one; the
    rest mask (which looks ``settle + 1`` samples to each side) is computed with
    the neighbouring samples of the adjacent chunks, so it is the same as on the
    whole record.
    """

    def __init__(self, q: int, settle: int, rest_tol: float) -> None:
        self.q, self.settle, self.rest_tol = q, settle, rest_tol
        self.ctx = settle + 1
        self.buf: dict[str, NDArray] | None = None
        self.before = np.empty(0)
        self.p0 = 0

    def feed(self, arrs: dict[str, NDArray]) -> _Block | None:
        if self.buf is None:
            buf = arrs
        else:
            buf = {k: np.concatenate([self.buf[k], arrs[k]]) for k in arrs}
        n_per = max(0, buf["time"].size - self.ctx) // self.q
        return self._emit(buf, n_per)

    def finish(self) -> _Block | None:
        if self.buf is None:
            return None
        return self._emit(self.buf, self.buf["time"].size // self.q)

    @property
    def tail(self) -> int:
        """Samples waiting for the rest of their period."""
        return 0 if self.buf is None else int(self.buf["time"].size)

    def _emit(self, buf: dict[str, NDArray], n_per: int) -> _Block | None:
        q = self.q
        if n_per == 0:
            self.buf = buf
            return None
        nn = n_per * q
        th = buf["theta"]
        after = th[nn : nn + self.ctx]
        ext = np.concatenate([self.before, th[:nn], after])
        rest = rest_mask(ext, tol=self.rest_tol, settle=self.settle)
        rest = rest[self.before.size : self.before.size + nn]
        self.before = np.concatenate([self.before, th[:nn]])[-self.ctx :]
        blk = _Block(self.p0, {k: v[:nn].reshape(n_per, q) for k, v in buf.items()}, rest)
        blk.rest = rest.reshape(n_per, q)
        self.buf = {k: v[nn:] for k, v in buf.items()}
        self.p0 += n_per
        return blk


@dataclass
class _Setup:
    """Everything that is the same for every block of a record."""

    q: int
    fs: float
    tau: float
    mask: float
    method: str
    signal_model: str
    aux_names: tuple[str, ...]
    need: float
    d: NDArray
    r_reg: NDArray | None
    n_lags: int
    kernels: list[NDArray] = field(default_factory=list)
    kernel_other: NDArray | None = None  # lag-0 kernel of the other PSD (NoiseReport)

    @property
    def u(self) -> NDArray:
        # normalised time within the period, centred on the mean sample time:
        # u_k = (k - (q-1)/2)/q (t = u·τ), so intercepts are period means
        return (np.arange(self.q) - (self.q - 1) / 2) / self.q

    @property
    def pa(self) -> int:
        return 1 if self.signal_model == "mean" else 2


def _block_basis(st: _Setup, blk: _Block, with_aux: bool = True):
    """Mask, cos/sin, Va and V̂b of a block (eqs. 18-19; aux channels centred and scaled)."""
    a = blk.arrs
    ok = a["valid"].astype(bool)
    m = (blk.rest & ok).astype(float)
    th = np.where(ok, a["theta"], 0.0)
    c, s = np.cos(th), np.sin(th)
    n_per = m.shape[0]
    ones = np.ones((n_per, st.q))
    u = st.u
    va = ones[..., None] if st.pa == 1 else np.stack([ones, ones * u], axis=2)
    bcols = [ones, ones * u]
    scales = []
    if with_aux:
        n_m = np.maximum(m.sum(axis=1), 1)
        for k in st.aux_names:
            x = np.where(ok, a[k], 0.0)
            mean = np.sum(x * m, axis=1) / n_m
            x = x - mean[:, None]
            # per-period scale (conditioning only; divided out of the coefficients)
            sc = np.sqrt(np.sum(x * x * m, axis=1) / n_m)
            sc = np.where(sc > 0, sc, 1.0)
            bcols.append(x / sc[:, None])
            scales.append(sc)
    vb = np.stack(bcols, axis=2)
    return m, c, s, va, vb, scales
