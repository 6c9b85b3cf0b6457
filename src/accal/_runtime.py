"""Process-level settings for batch runs: compute threads and the C allocator.

accal parallelises over inputs (``--workers`` processes, or dask workers).  Inside
one input the linear algebra is tall and skinny (``(p, n) @ (n, k)`` with p, k ≤ 3),
where a multi-threaded BLAS only adds thread hand-offs; with several worker
processes its threads would also compete with the other workers for the cores.

The second setting concerns glibc's ``malloc``.  Every per-day array is ~0.7 MB
(86,400 float64 samples).  By default glibc serves such blocks with a fresh
``mmap`` and returns them with ``munmap``, so each new array costs a page fault
per 4 KiB page when it is first written: on the 2-core CI machine keeping ten
such copies costs 3.8 ms instead of 0.13 ms.  :func:`tune_allocator` raises the
mmap and trim thresholds so that freed blocks are reused (measured: a whole
``grace-bias`` file 54 → 48 ms).  The process then keeps up to the trim
threshold of freed memory for reuse; its peak RSS is unchanged.

Neither setting changes any result.  A value the user set in the environment
(``OPENBLAS_NUM_THREADS``, ``MALLOC_MMAP_THRESHOLD_``, ...) is left alone.
"""

from __future__ import annotations

import ctypes
import functools
import os
import signal
import sys
from typing import Any

#: Thread-count variables of the BLAS / OpenMP runtimes numpy and scipy may load.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

# glibc mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD = 32 << 20  # glibc's maximum on 64-bit
_TRIM_THRESHOLD = 256 << 20
_TOP_PAD = 16 << 20
_ALLOCATOR_VARS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")


@functools.cache
def libc() -> Any:
    """glibc (``ctypes``, errno kept) on Linux, else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL("libc.so.6", use_errno=True)
    except OSError:
        return None


def single_threaded_blas() -> None:
    """Default the BLAS/OpenMP thread counts to 1 (only effective before numpy loads).

    Set in the environment, so worker processes inherit it.
    """
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")


def tune_allocator() -> bool:
    """Let glibc reuse freed per-day arrays instead of unmapping them.

    Returns
    -------
    bool
        True if the allocator was tuned (Linux with glibc, and no ``MALLOC_*_``
        variable set by the user); False otherwise (nothing changed).
    """
    if any(v in os.environ for v in _ALLOCATOR_VARS):
        return False
    mallopt = getattr(libc(), "mallopt", None)
    if mallopt is None:  # not Linux/glibc: leave it alone
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
        and mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
        and mallopt(_M_TOP_PAD, _TOP_PAD)
    )


def _ignore(signum: int, frame: object) -> None:
    """A signal that arrives once the run is already stopping: nothing more to do."""


_INTERRUPTED: list[bool] = [False]


def interrupted() -> bool:
    """Whether this process has received SIGINT/SIGTERM (:func:`ignore_late_signals`)."""
    return _INTERRUPTED[0]


def ignore_late_signals() -> None:
    """From now on SIGINT and SIGTERM do nothing: the run is already stopping.

    Called as soon as an interruption is being handled, so that a second delivery
    of the same Ctrl-C (see ``accal.__main__._exit_interrupted``) cannot turn the clean exit
    into Click's ``Aborted!`` or a death by signal.
    """
    _INTERRUPTED[0] = True
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _ignore)


def keep_signals_in_python() -> None:
    """Let Python, not pyarrow, receive SIGINT/SIGTERM during pyarrow's reads.

    pyarrow swaps in its own handler for each read (``pyarrow.lib.SignalStopHandler``)
    and re-sends the signal when the read was cancelled; a signal that arrived just
    as the read finished was lost (issue 23 finding 5: ``accal demod`` ignored Ctrl-C
    in 13 of 60 trials, grace-bias ``-j 1`` in 7 of ~300), and one that cancelled it
    could be delivered twice.  With pyarrow's handlers off, Python's handler trips
    and the interrupt is raised as soon as the read returns (reads take well under a
    second per input).  Imports pyarrow (~0.2 s), which every data command needs.
    """
    import pyarrow as pa

    pa.enable_signal_handlers(False)
