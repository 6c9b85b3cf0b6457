"""The declared base of :func:`accal.closure.close_loop`: a design block-diagonal over
contiguous sample blocks (:class:`BlockBase`).

A polynomial or any dense design is the special case of one block; the demodulation
model of the rotating platform (Lenoir et al. 2013, eqs. 17-19: per modulation period
the signal columns ``Λc Va``, ``Λs Va`` and the bias columns ``V̂b``) is the case that
needs it.  Its orthonormal basis on the used samples is
:class:`accal.closure.basis.Basis`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from accal.errors import ValidationError

__all__ = ["BlockBase"]


@dataclass(frozen=True)
class BlockBase:
    """A base design that is block-diagonal over contiguous sample blocks.

    Column ``j`` of block ``b`` is ``columns[:, j]`` on the samples with
    ``block == b`` and zero elsewhere; the coefficients are ordered block by block
    (``b·p + j``).

    Attributes
    ----------
    block : ndarray of int, shape (N,)
        Block of each sample, ``0 .. n_blocks-1``; ``-1``: no base column there.
        The samples of one block must be consecutive.
    columns : ndarray, shape (N, p)
        Per-sample values of the ``p`` column kinds.
    names : tuple of str
        Name of each column kind (``BaseCoefficient.name``; with several blocks
        ``f"{name}[{block_label}]"``).
    labels : tuple of str, optional
        Design labels of the column kinds (default ``names``); candidate builders
        look for them (e.g. ``"t^2"``: no quadratic proposal).
    scale : ndarray, shape (p,), optional
        Factor turning each coefficient into SI units (default 1).
    block_labels : tuple, optional
        Label of each block (default its index), e.g. the period number.
    signal : tuple of int, optional
        Indices of the column kinds that model the *signal* (the demodulated
        acceleration of the rotating platform) rather than the bias: closure tells a
        candidate from the signal by how much of it lies outside their span
        (:func:`accal.closure.validation.identifiability`).
    signal_extension : ndarray, shape (N, k), optional
        Per-sample values of further signal column kinds (same blocks) that the
        declared model leaves out but the signal may have, e.g. the signal's slope
        within a period under the per-period mean model: what a candidate shares with
        them is also the signal (a sideband of a signal that varies within a period).
    """

    block: NDArray[np.int64]
    columns: NDArray[np.float64]
    names: tuple[str, ...]
    labels: tuple[str, ...] | None = None
    scale: NDArray[np.float64] | None = None
    block_labels: tuple[Any, ...] | None = None
    signal: tuple[int, ...] = ()
    signal_extension: NDArray[np.float64] | None = None
    _n_blocks: int = field(default=0, repr=False)

    def __post_init__(self) -> None:
        block = np.asarray(self.block)
        cols = np.asarray(self.columns, dtype=np.float64)
        if cols.ndim == 1:
            cols = cols[:, None]
        if block.ndim != 1 or cols.ndim != 2 or cols.shape[0] != block.size:
            raise ValidationError(
                f"block must be (N,) and columns (N, p), got {block.shape} and {cols.shape}"
            )
        if not np.issubdtype(block.dtype, np.integer):
            raise ValidationError(f"block must hold integers, got dtype {block.dtype}")
        block = block.astype(np.int64)
        p = cols.shape[1]
        if len(self.names) != p:
            raise ValidationError(
                f"names must have {p} entries (one per column), got {len(self.names)}"
            )
        if self.labels is not None and len(self.labels) != p:
            raise ValidationError(f"labels must have {p} entries, got {len(self.labels)}")
        if np.any(block < -1):
            raise ValidationError("block indices must be >= -1")
        nb = int(block.max()) + 1 if block.size else 0
        ids = block[block >= 0]
        if ids.size:
            # each block one contiguous run
            starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]])
            run_ids = block[starts]
            run_ids = run_ids[run_ids >= 0]
            counts = np.bincount(run_ids)
            if np.any(counts > 1):
                dup = int(np.flatnonzero(counts > 1)[0])
                raise ValidationError(f"the samples of block {dup} are not consecutive")
        scale = np.ones(p) if self.scale is None else np.asarray(self.scale, dtype=np.float64)
        if scale.shape != (p,):
            raise ValidationError(f"scale must have shape ({p},), got {scale.shape}")
        if any(not 0 <= j < p for j in self.signal):
            raise ValidationError(f"signal column indices must be in 0 .. {p - 1}")
        if self.block_labels is not None and len(self.block_labels) != nb:
            raise ValidationError(
                f"block_labels must have {nb} entries (one per block), got {len(self.block_labels)}"
            )
        object.__setattr__(self, "block", block)
        object.__setattr__(self, "columns", cols)
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "_n_blocks", nb)

    # ------------------------------------------------------------------
    @classmethod
    def from_dense(
        cls,
        x: ArrayLike,
        names: Sequence[str] | None = None,
        labels: Sequence[str] | None = None,
        scale: ArrayLike | None = None,
    ) -> BlockBase:
        """One block holding a dense design ``x`` (N, p)."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim == 1:
            x = x[:, None]
        p = x.shape[1]
        names = tuple(names) if names is not None else tuple(f"b{j}" for j in range(p))
        return cls(
            np.zeros(x.shape[0], dtype=np.int64),
            x,
            names,
            None if labels is None else tuple(labels),
            None if scale is None else np.asarray(scale, dtype=np.float64),
        )

    @classmethod
    def from_slices(
        cls,
        n: int,
        blocks: Sequence[tuple[slice, ArrayLike]],
        names: Sequence[str],
        *,
        labels: Sequence[str] | None = None,
        scale: ArrayLike | None = None,
        block_labels: Sequence[Any] | None = None,
    ) -> BlockBase:
        """Build from ``[(slice, columns (len, p)), ...]`` over ``n`` samples.

        Slices must be disjoint and increasing; samples outside every slice have no
        base column.
        """
        p = len(names)
        block = np.full(n, -1, dtype=np.int64)
        cols = np.zeros((n, p))
        last = 0
        for b, (sl, c) in enumerate(blocks):
            start, stop, step = sl.indices(n)
            if step != 1 or start < last or stop <= start:
                raise ValidationError(
                    f"block {b}: slices must be increasing, disjoint and non-empty"
                )
            c = np.asarray(c, dtype=np.float64)
            if c.ndim == 1:
                c = c[:, None]
            if c.shape != (stop - start, p):
                raise ValidationError(
                    f"block {b}: columns must have shape ({stop - start}, {p}), got {c.shape}"
                )
            block[start:stop] = b
            cols[start:stop] = c
            last = stop
        return cls(
            block,
            cols,
            tuple(names),
            None if labels is None else tuple(labels),
            None if scale is None else np.asarray(scale, dtype=np.float64),
            None if block_labels is None else tuple(block_labels),
        )

    # ------------------------------------------------------------------
    @property
    def n_blocks(self) -> int:
        """Number of blocks."""
        return self._n_blocks

    @property
    def p(self) -> int:
        """Columns per block."""
        return int(self.columns.shape[1])

    @property
    def n_columns(self) -> int:
        """Columns of the full design, ``n_blocks · p``."""
        return self.n_blocks * self.p

    def _suffix(self, b: int) -> str:
        if self.n_blocks == 1:
            return ""
        lab = b if self.block_labels is None else self.block_labels[b]
        return f"[{lab}]"

    def column_names(self) -> tuple[str, ...]:
        """Names of all coefficients, block by block."""
        return tuple(f"{nm}{self._suffix(b)}" for b in range(self.n_blocks) for nm in self.names)

    def column_labels(self) -> tuple[str, ...]:
        """Design labels of all columns, block by block."""
        labs = self.labels if self.labels is not None else self.names
        return tuple(f"{lb}{self._suffix(b)}" for b in range(self.n_blocks) for lb in labs)

    def column_scale(self) -> NDArray[np.float64]:
        """SI factor of every coefficient, block by block."""
        return np.tile(self.scale, self.n_blocks)

    def matvec(self, coef: ArrayLike) -> NDArray[np.float64]:
        """``X @ coef`` without forming ``X`` (NaN coefficients propagate)."""
        c = np.asarray(coef, dtype=np.float64).reshape(self.n_blocks, self.p)
        out = np.zeros(self.block.size)
        inb = self.block >= 0
        cols = self.columns[inb]
        prod = cols * c[self.block[inb]]
        prod[cols == 0] = 0.0  # an undetermined coefficient does not spoil other samples
        out[inb] = prod.sum(axis=1)
        return out

    def dense(self) -> NDArray[np.float64]:
        """The full design ``(N, n_blocks·p)`` (for small cases and tests only)."""
        x = np.zeros((self.block.size, self.n_columns))
        for b in range(self.n_blocks):
            m = self.block == b
            x[m, b * self.p : (b + 1) * self.p] = self.columns[m]
        return x
